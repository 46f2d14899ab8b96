"""Exact point-to-polygon form factors (Lambert's formula).

The form factor from a differential area at x (unit normal n) to a polygon P is
the fraction of the energy x emits (cosine-weighted over the hemisphere) that
reaches P. For a polygon seen entirely on the front side of x, Lambert's contour
formula gives it exactly (Baum, Rushmeier & Winget 1989; seed 000 §7.4):

    F = (1 / 2π) Σ_i  Γ_i · n,     Γ_i = θ_i (r_i × r_{i+1}) / |r_i × r_{i+1}|

with r_i the polygon's vertices relative to x, θ_i the angle between r_i and
r_{i+1}, the loop running counter-clockwise as seen from x. It is Stokes'
theorem on the unit sphere: the projected solid angle of the spherical polygon.
A polygon with holes sums its loops with their orientations (holes run the
other way), which is also how the visible part of a light (outer loops and
holes, from the visibility complex) is integrated.

The orientation of the loops does not have to be known: the sum is computed
for the loop as given and its absolute value taken, since the projected solid
angle of a polygon in front of x is positive. Polygons that cross the plane of
x must be clipped to its front half-space first (:func:`clip_to_hemisphere`).
"""

import numpy as np


def loop_contour_sum(points, normals, loop):
    """Σ Γ_i · n of one closed loop for many receiver points.

    Parameters
    ----------
    points : (m, 3) float
    normals : (m, 3) float
        Unit normals at the points.
    loop : (k, 3) float
        Loop vertices in order.

    Returns
    -------
    (m,) float
        Signed: the loop's orientation seen from each point decides the sign.
    """
    r = loop[None, :, :] - points[:, None, :]  # (m, k, 3)
    r_next = np.roll(r, -1, axis=1)
    cross = np.cross(r, r_next)
    size = np.linalg.norm(cross, axis=2)
    dot = np.einsum("mkj,mkj->mk", r, r_next)
    theta = np.arctan2(size, dot)  # angle between r_i and r_i+1, stable at both ends
    with np.errstate(invalid="ignore", divide="ignore"):
        gamma = np.where(size[..., None] > 0, cross * (theta / size)[..., None], 0.0)
    return np.einsum("mkj,mj->m", gamma, normals)


def point_to_polygon(points, normals, loops):
    """Form factor from differential areas to a polygon with holes, unoccluded.

    Parameters
    ----------
    points : (m, 3) float
    normals : (m, 3) float
        Unit normals.
    loops : list of (k, 3) float
        The outer loop first, then the holes, wound oppositely (as viscx stores
        faces). The polygon must lie in front of every point (see
        :func:`clip_to_hemisphere`).

    Returns
    -------
    (m,) float
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    total = sum(loop_contour_sum(points, normals, np.asarray(loop, dtype=np.float64)) for loop in loops)
    return np.abs(total) / (2 * np.pi)


def clip_to_hemisphere(loop, point, normal):
    """The part of a planar loop in front of the plane through ``point`` (Sutherland–Hodgman).

    Parameters
    ----------
    loop : (k, 3) float
    point, normal : (3,) float

    Returns
    -------
    (k', 3) float
        Possibly empty.
    """
    loop = np.asarray(loop, dtype=np.float64)
    height = (loop - point) @ normal
    out = []
    for i in range(len(loop)):
        j = (i + 1) % len(loop)
        a, b, ha, hb = loop[i], loop[j], height[i], height[j]
        if ha >= 0:
            out.append(a)
        if (ha >= 0) != (hb >= 0):
            out.append(a + (b - a) * (ha / (ha - hb)))
    return np.asarray(out).reshape(-1, 3)
