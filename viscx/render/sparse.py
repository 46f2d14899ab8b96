"""Reconstruction of direct illumination from sparse samples, inside regions that never
mix (Hoberock et al. §7.5, Fig. 10).

Regions
-------
A pixel's *region* is the pair (what the camera sees there, where it is in the light's
discontinuity mesh): the face and side the primary ray hits — the camera point's V-cells,
Hoberock et al. §7.1, found per pixel by the ray caster — and the mesh region of that face the
hit point falls in (:func:`viscx.render.direct.regions_of`). Inside one region the
illumination is smooth (no visual event of the light crosses it); across a region's
boundary it may have a kink or a jump (a shadow's edge, a contact line, an object's
silhouette).

Samples
-------
Illumination is evaluated exactly (:class:`viscx.render.direct.DirectLighting`) at

* the corners of every region seen (its outer loop and holes, each corner moved by the
  mesh's snap distance into the region along the bisector of its two edges, so that it is
  evaluated as a point *of that region*: across a contact line the two sides differ), and
* ``N`` samples on seen pixels, shared out among the regions by largest remainder in
  proportion to ``pixels × (spread + 0.05 · scale)``, where ``spread`` is the range of the
  luminance at the region's corners and ``scale`` the largest corner luminance of the image:
  penumbrae get the samples, flat regions (lit or umbra) few. Within a region the samples
  are its pixels at evenly spaced ranks of their Morton order (deterministic, spread out).

Interpolation
-------------
Per region, in the face's plane: the Delaunay triangulation of its own points (corners and
samples), and each of its pixels gets the barycentric interpolation of the triangle it falls
in (the nearest of the region's points if none: pixels within the snap distance of the
boundary). A pixel's value is thus a convex combination of values of its own region: light
never bleeds across a region's boundary (tests/test_render.py checks this on a scene built
for it, against an image-space interpolation that does bleed).
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay, QhullError, cKDTree

from viscx.geometry.polygon import plane_basis
from viscx.render.direct import groups_of, regions_of

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: Weight of a region's pixels with no spread at its corners, relative to the image's scale.
FLAT_WEIGHT = 0.05


def _morton(rows, cols):
    """Interleaved bits of (row, col): a locality-preserving order of pixels."""
    code = np.zeros(len(rows), np.int64)
    for b in range(16):
        code |= ((cols >> b) & 1) << (2 * b)
        code |= ((rows >> b) & 1) << (2 * b + 1)
    return code


def inner_corners(loops, delta):
    """Every corner of a region's loops moved by ``delta`` into the region (left of both
    of its edges: outer loops counter-clockwise, holes clockwise).

    loops : list of (k, 2) float64. Returns (c, 2) float64.
    """
    out = []
    for loop in loops:
        loop = np.asarray(loop, dtype=np.float64)
        d_in = loop - np.roll(loop, 1, axis=0)
        d_out = np.roll(loop, -1, axis=0) - loop
        for d in (d_in, d_out):
            d /= np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
        left = np.stack([-d_in[:, 1], d_in[:, 0]], axis=1) + np.stack([-d_out[:, 1], d_out[:, 0]], axis=1)
        size = np.linalg.norm(left, axis=1)
        spike = size < 1e-6
        left[spike] = np.stack([-d_out[spike, 1], d_out[spike, 0]], axis=1)
        size[spike] = 1.0
        out.append(loop + delta * left / size[:, None])
    return np.concatenate(out) if out else np.zeros((0, 2))


def allocate(weights, n):
    """Integers summing to ``n``, proportional to ``weights`` (largest remainder, ties to the
    lower index)."""
    weights = np.asarray(weights, dtype=np.float64)
    if n <= 0 or weights.sum() <= 0:
        return np.zeros(len(weights), np.int64)
    share = weights / weights.sum() * n
    base = np.floor(share).astype(np.int64)
    rest = n - int(base.sum())
    order = np.lexsort((np.arange(len(share)), -(share - base)))
    base[order[:rest]] += 1
    return base


@dataclass
class Reconstruction:
    """A sparse-sample image and how it was made.

    Attributes
    ----------
    radiance : (n, 3) float64
        Per pixel (background zero).
    label : (n,) int64
        Region of each pixel (-1 background), numbered in sorted (face, side, mesh region) order.
    samples : (s, 3) float64
        The sample points (N of them), and ``corners`` (c, 3) the region corners evaluated.
    triangles : list of (t, 3, 3) float64
        Per region, its triangulation in 3-D (for drawing).
    bounds : (g, 2, 3) float64
        Per region, the least and greatest value evaluated in it (every pixel of the
        region lies between them: nothing bleeds in from elsewhere).
    """

    radiance: np.ndarray
    label: np.ndarray
    samples: np.ndarray
    corners: np.ndarray
    triangles: list
    bounds: np.ndarray

    @property
    def evaluations(self):
        return len(self.samples) + len(self.corners)


def _frame(lighting, face):
    """``(u, v)`` 2-D coordinates of a face's plane (the mesh receiver's, else a basis)."""
    rec = lighting.receivers.get(int(face))
    if rec is not None:
        return rec.frame[0], rec.frame[1]
    return plane_basis(lighting.scene.face_normal[face])


def reconstruct(lighting, hits, n_samples):
    """Sparse reconstruction of the direct illumination of an image (module docstring).

    Parameters
    ----------
    lighting : viscx.render.direct.DirectLighting
    hits : viscx.render.camera.Hits
    n_samples : int
        N, the samples shared out among the regions (corners come on top).

    Returns
    -------
    Reconstruction
    """
    face, side, points = hits.face, hits.side, hits.point
    h, w = hits.shape
    n = len(face)
    region = regions_of(lighting, face, points)
    hit = np.flatnonzero(face >= 0)
    # a pixel on a mesh line (in no region) joins the region of its nearest located pixel
    for f, s in {(int(a), int(b)) for a, b in zip(face[hit], side[hit])}:
        on = hit[(face[hit] == f) & (side[hit] == s)]
        lost = on[region[on] < 0]
        found = on[region[on] >= 0]
        if len(lost) and len(found) and f in lighting.receivers:
            u, v = _frame(lighting, f)
            tree = cKDTree(np.stack([points[found] @ u, points[found] @ v], axis=1))
            _, near = tree.query(np.stack([points[lost] @ u, points[lost] @ v], axis=1))
            region[lost] = region[found[near]]
    groups, members = groups_of(face[hit], side[hit], region[hit])
    label = np.full(n, -1, np.int64)
    delta = lighting.mesh.snap
    # corners first: their values decide where the samples go
    corner2, corner3, corner_val = [], [], []
    for g, ((f, s, r), rows) in enumerate(zip(groups, members)):
        label[hit[rows]] = g
        u, v = _frame(lighting, f)
        if r >= 0:
            rec = lighting.receivers[int(f)]
            reg = rec.regions[r]
            c2 = inner_corners([reg.outer] + list(reg.holes), delta)
            c3 = rec.to3(c2)
        else:  # a face outside the mesh (a light face): its outline's corners
            loops = lighting.scene.face_loops(int(f))
            c2 = inner_corners([np.stack([lp @ u, lp @ v], axis=1) for lp in loops], delta)
            offset = lighting.scene.face_normal[f] * lighting.scene.face_offset[f]
            c3 = offset + c2[:, :1] * u + c2[:, 1:] * v
        corner2.append(c2)
        corner3.append(c3)
        corner_val.append(lighting.radiance(f, s, r, c3) + lighting.emitted(f, s)[None, :])
    lum = [cv @ LUMINANCE for cv in corner_val]
    scale = max((float(x.max()) for x in lum if len(x)), default=0.0)
    spread = np.array([float(x.max() - x.min()) if len(x) else 0.0 for x in lum])
    weights = np.array([len(rows) for rows in members]) * (spread + FLAT_WEIGHT * max(scale, 1e-300))
    counts = np.minimum(allocate(weights, n_samples), [len(rows) for rows in members])
    out = np.zeros((n, 3))
    samples, triangles = [], []
    bounds = np.zeros((len(groups), 2, 3))
    for g, ((f, s, r), rows) in enumerate(zip(groups, members)):
        pix = hit[rows]
        u, v = _frame(lighting, f)
        k = int(counts[g])
        if k:
            order = np.argsort(_morton(pix // w, pix % w), kind="stable")
            pick = pix[order[((np.arange(k) + 0.5) * len(pix) / k).astype(np.int64)]]
            sp = points[pick]
            sv = lighting.radiance(f, s, r, sp) + lighting.emitted(f, s)[None, :]
            samples.append(sp)
        else:
            sp, sv = np.zeros((0, 3)), np.zeros((0, 3))
        p2 = np.concatenate([corner2[g], np.stack([sp @ u, sp @ v], axis=1)])
        p3 = np.concatenate([corner3[g], sp])
        val = np.concatenate([corner_val[g], sv])
        bounds[g] = val.min(axis=0), val.max(axis=0)
        q = np.stack([points[pix] @ u, points[pix] @ v], axis=1)
        out[pix], tri = _interpolate(p2, val, q)
        triangles.append(p3[tri] if len(tri) else np.zeros((0, 3, 3)))
    return Reconstruction(out, label, np.concatenate(samples) if samples else np.zeros((0, 3)),
                          np.concatenate(corner3) if corner3 else np.zeros((0, 3)), triangles, bounds)


def _interpolate(points, values, queries):
    """Barycentric interpolation in the Delaunay triangulation of ``points`` (nearest point
    outside it or when it is flat): ``(values at queries, triangles (t, 3) int)``."""
    try:
        tri = Delaunay(points)
    except (QhullError, ValueError):
        tri = None
    out = np.empty((len(queries), values.shape[1]))
    if tri is not None:
        simplex = tri.find_simplex(queries)
        inside = simplex >= 0
        t = tri.transform[simplex[inside]]
        b = np.einsum("ijk,ik->ij", t[:, :2], queries[inside] - t[:, 2])
        bary = np.concatenate([b, 1.0 - b.sum(axis=1, keepdims=True)], axis=1)
        # rounding can put a weight a hair below zero: clip, renormalise (convex combination)
        bary = np.maximum(bary, 0.0)
        bary /= bary.sum(axis=1, keepdims=True)
        out[inside] = np.einsum("ij,ijk->ik", bary, values[tri.simplices[simplex[inside]]])
        outside = ~inside
        simplices = tri.simplices
    else:
        outside = np.ones(len(queries), bool)
        simplices = np.zeros((0, 3), np.int64)
    if np.any(outside):
        _, near = cKDTree(points).query(queries[outside])
        out[outside] = values[near]
    return out, simplices
