"""Exact point-to-polygon form factors (Lambert's formula).

The form factor from a differential area at x (unit normal n) to a polygon P is
the fraction of the energy x emits (cosine-weighted over the hemisphere) that
reaches P. For a polygon seen entirely on the front side of x, Lambert's contour
formula gives it exactly (Baum, Rushmeier & Winget 1989; Hoberock et al. §7.4):

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


# -- polygon to polygon, unoccluded ----------------------------------------------------------
#
# Stokes' theorem turns the double area integral into a double contour integral
# (Sparrow 1963):
#
#     A_i F_ij = (1 / 2π) ∮_i ∮_j ln r  dr_i · dr_j
#
# with both contours run counter-clockwise about their own polygon's normal (the
# normals facing each other). Per pair of edges a (of i) and b (of j), with unit
# directions u_a, u_b, the inner integral along b has a closed form: for a point
# x at height h from b's line and projection t0 on it,
#
#     ∫_0^L ln |x - b(t)| dt = G(L - t0) - G(-t0),
#     G(y) = ½ (y ln(y² + h²) - 2y) + h atan(y / h)        (G(y) = y ln|y| - y at h = 0),
#
# and the outer one along a is Gauss–Legendre on sub-intervals that shrink
# geometrically toward a's ends, where the integrand has its (integrable)
# logarithmic singularities when the polygons touch (a shared edge or vertex).

_GL = {n: np.polynomial.legendre.leggauss(n) for n in (6, 10)}


def _graded_nodes(length, levels=40, order=10, cuts=()):
    """Quadrature nodes and weights on [0, length], refined geometrically toward both ends
    and toward every interior cut (where the integrand may be singular)."""
    x_gl, w_gl = _GL[order]
    knots = np.unique(np.concatenate([[0.0, length], np.asarray(cuts, dtype=np.float64)]))
    grade = np.concatenate([[0.0], 0.5 ** np.arange(levels, 0, -1) / 2, [0.5], 1 - 0.5 ** np.arange(1, levels + 1) / 2, [1.0]])
    a0, b0 = knots[:-1], knots[1:]
    keep = b0 - a0 > 1e-14 * length
    a0, b0 = a0[keep], b0[keep]
    edges = a0[:, None] + (b0 - a0)[:, None] * grade[None, :]
    a, b = edges[:, :-1].ravel(), edges[:, 1:].ravel()
    half = (b - a) / 2
    nodes = (a + half)[:, None] + half[:, None] * x_gl[None, :]
    weights = half[:, None] * w_gl[None, :]
    return nodes.ravel(), weights.ravel()


def _near_cuts(a0, u_a, len_a, loops_j):
    """Parameters on edge a where the other polygon comes close (its vertices' projections
    and the closest points of its edges, within a quarter of a's length): the places
    where the inner integral's log kernel is (nearly) singular."""
    cuts = []
    for loop in loops_j:
        p = np.asarray(loop, dtype=np.float64)
        q = np.roll(p, -1, axis=0)
        # vertices
        t = (p - a0) @ u_a
        dist = np.linalg.norm(p - a0 - t[:, None] * u_a, axis=1)
        cuts.append(t[(dist < 0.25 * len_a) & (t > 0) & (t < len_a)])
        # closest points of the segments p-q to the line of a (sampled where they cross its neighbourhood)
        d = q - p
        w0 = p - a0
        b_ = d @ u_a
        c_ = np.einsum("ij,ij->i", d, d)
        d_ = w0 @ u_a
        e_ = np.einsum("ij,ij->i", d, w0)
        den = c_ - b_ * b_
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.clip(np.where(den > 1e-14 * c_, (b_ * d_ - e_) / den, 0.0), 0.0, 1.0)
        y = p + s[:, None] * d
        t = (y - a0) @ u_a
        dist = np.linalg.norm(y - a0 - t[:, None] * u_a, axis=1)
        cuts.append(t[(dist < 0.25 * len_a) & (t > 0) & (t < len_a)])
    return np.concatenate(cuts) if cuts else np.zeros(0)


def _log_distance_integral(x, start, direction, length):
    """∫_0^length ln |x - (start + t direction)| dt for points x, closed form.

    Parameters
    ----------
    x : (m, 3) float
    start, direction : (3,) float
        Segment start and unit direction.
    length : float
    """
    w = x - start
    t0 = w @ direction
    h = np.sqrt(np.maximum(np.einsum("ij,ij->i", w, w) - t0 * t0, 0.0))

    def G(y):
        with np.errstate(divide="ignore", invalid="ignore"):
            log_term = np.where(y * y + h * h > 0, y * np.log(y * y + h * h), 0.0)
            atan_term = np.where(h > 0, h * np.arctan(y / np.where(h > 0, h, 1.0)), 0.0)
        return 0.5 * log_term - y + atan_term

    return G(length - t0) - G(-t0)


def _edges(loops):
    """(start, unit direction, length) of every non-degenerate edge of some loops."""
    for loop in loops:
        for a, b in zip(loop, np.roll(loop, -1, axis=0)):
            length = np.linalg.norm(b - a)
            if length > 0:
                yield a, (b - a) / length, length


def polygon_to_polygon(loops_i, normal_i, loops_j, normal_j, order=10):
    """Unoccluded form factor F_ij between two planar polygons (holes allowed).

    Parameters
    ----------
    loops_i, loops_j : list of (k, 3) float
        Outer loop first, then holes (wound oppositely to the outer loop).
    normal_i, normal_j : (3,) float
        Unit normals; polygon j must lie in front of i and i in front of j
        (their planes may meet only along their boundary).
    order : int
        Gauss–Legendre points per panel (6 or 10); panels are graded toward the ends of
        every edge of i and toward where j comes close to it.

    Returns
    -------
    float
    """

    def oriented(loops, normal):
        # outer loop counter-clockwise about the normal, holes the other way round
        out = []
        for k, loop in enumerate(loops):
            loop = np.asarray(loop, dtype=np.float64)
            area = np.cross(loop, np.roll(loop, -1, axis=0)).sum(axis=0) @ normal
            if (area > 0) != (k == 0):
                loop = loop[::-1]
            out.append(loop)
        return out

    li = oriented(loops_i, np.asarray(normal_i, dtype=np.float64))
    lj = oriented(loops_j, np.asarray(normal_j, dtype=np.float64))
    area_i = sum(abs(np.cross(l, np.roll(l, -1, axis=0)).sum(axis=0) @ normal_i) / 2 * (1 if k == 0 else -1) for k, l in enumerate(li))
    total = 0.0
    for a0, u_a, len_a in _edges(li):
        s, w = _graded_nodes(len_a, order=order, cuts=_near_cuts(a0, u_a, len_a, lj))
        x = a0 + s[:, None] * u_a
        for b0, u_b, len_b in _edges(lj):
            cos_ab = u_a @ u_b
            if abs(cos_ab) > 1e-15:  # perpendicular edges contribute nothing
                total += cos_ab * (w @ _log_distance_integral(x, b0, u_b, len_b))
    return total / (2 * np.pi * area_i)
