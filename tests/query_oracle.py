"""The ray oracle of the point queries: random surface points, lit (or seen) per the
query's polygons versus an embree shadow ray to the point (viscx.raycast).

Independent of the complex: it only uses the polygons a query returns, the scene's
triangles and the ray caster.
"""

import numpy as np
from oracles import sample_on_triangles

from viscx.geometry.polygon import plane_basis
from viscx.queries.visibility import face_areas

#: Samples per chunk of the point-in-polygon and distance tests.
CHUNK = 1 << 14


def _in_loops_and_distance(q, segs_a, segs_b):
    """Even-odd parity of each 2-D point against segments (closed loops), and its distance
    to the nearest segment. q : (m, 2); segs_a, segs_b : (k, 2)."""
    inside = np.zeros(len(q), bool)
    dist = np.full(len(q), np.inf)
    if len(segs_a) == 0:
        return inside, dist
    for lo in range(0, len(q), CHUNK):
        x = q[lo:lo + CHUNK, None, :]
        a, b = segs_a[None], segs_b[None]
        # crossing parity of the ray +x from each point
        cond = (a[..., 1] > x[..., 1]) != (b[..., 1] > x[..., 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = a[..., 0] + (x[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
        inside[lo:lo + CHUNK] = np.count_nonzero(cond & (x[..., 0] < xc), axis=1) % 2 == 1
        ab = b - a
        t = np.clip(np.einsum("mkj,mkj->mk", x - a, np.broadcast_to(ab, (x.shape[0],) + ab.shape[1:]))
                    / np.maximum(np.einsum("mkj,mkj->mk", ab, ab), 1e-300), 0, 1)
        dist[lo:lo + CHUNK] = np.linalg.norm(x - a - t[..., None] * ab, axis=2).min(axis=1)
    return inside, dist


def judge(scene, view, point, n, rng, band):
    """Compare a PointView (or any per-face loop lists) with shadow rays.

    Parameters
    ----------
    scene : Scene
    view : viscx.queries.visibility.PointView
    point : (3,) float64
    n : int
        Area-uniform samples over the whole scene.
    band : float
        Samples closer than this (scene units, in the face plane) to a loop of the
        query's polygons are not judged.

    Returns
    -------
    dict
        ``samples``, ``judged``, ``agree`` (count), ``agreement`` (fraction of judged),
        ``lit_area`` (the query's), ``mc_area`` (lit fraction of the samples times the
        scene's area), ``area_error`` (relative), ``disagree_faces``.
    """
    pts, tri = sample_on_triangles(scene.vertices, scene.triangles, n, rng)
    face = scene.triangle_face[tri]
    lit_ray = scene.ray_caster.free_segments(pts, np.broadcast_to(point, pts.shape))
    lit_json = np.zeros(n, bool)
    near = np.zeros(n, bool)
    by_face = np.argsort(face, kind="stable")  # the samples of each face, ascending
    start = np.searchsorted(face[by_face], np.arange(len(view.faces) + 1))
    for f in np.unique(face).tolist():
        fv = view.faces[f]
        rows = by_face[start[f]:start[f + 1]]
        loops = fv.loops
        if len(rows) == 0 or not loops:
            continue
        u, v = plane_basis(scene.face_normal[f])
        to2 = lambda x: np.stack([x @ u, x @ v], axis=-1)  # noqa: E731
        a = np.concatenate([to2(loop) for loop in loops])
        b = np.concatenate([to2(np.roll(loop, -1, axis=0)) for loop in loops])
        if len(fv.boundary):
            # open chains leave boundary pieces that are no loop: keep them out of the parity
            ba, bb = to2(fv.boundary[:, 0]), to2(fv.boundary[:, 1])
            _, dist_b = _in_loops_and_distance(to2(pts[rows]), ba, bb)
        else:
            dist_b = np.full(len(rows), np.inf)
        inside, dist = _in_loops_and_distance(to2(pts[rows]), a, b)
        lit_json[rows] = inside
        near[rows] = (dist <= band) | (dist_b <= band)
    judged = ~near
    agree = np.count_nonzero((lit_json == lit_ray) & judged)
    lit_area = float(face_areas(view.faces).sum())
    mc_area = float(np.mean(lit_ray)) * float(scene.face_area.sum())
    bad = np.flatnonzero((lit_json != lit_ray) & judged)
    return {
        "samples": n,
        "judged": int(judged.sum()),
        "agree": int(agree),
        "agreement": agree / max(1, int(judged.sum())),
        "lit_area": float(lit_area),
        "mc_area": mc_area,
        "area_error": abs(lit_area - mc_area) / max(mc_area, 1e-300),
        "disagree_faces": sorted(set(face[bad].tolist())),
    }
