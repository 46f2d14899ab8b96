"""Batched ray casting: embree (float32) as the filter, float64 for every decision.

The only module that talks to embree. Every query is a *first hit on a parameter
interval*: along ``o + t d`` (``d`` unit), the first face whose triangle meets
the ray at ``t ∈ [tmin, tmax]`` (closed), with its float64 ``t``.

How float32 is kept honest
--------------------------
Embree works in float32 (coordinates relative to the scene centre). Its answer
is only a proposal:

* embree searches ``[tmin - band, tmax + band]``, ``band`` being 8 float32 ulps of
  the scene's half-extent (about 5e-7 of the diagonal, below the default
  epsilon, so a ray leaving a surface does not re-find it), so hits that float32
  puts just outside the interval are still seen;
* every hit it reports is re-decided in float64 (Möller–Trumbore, numba) on
  that triangle, and, when float64 says the ray passes just outside it, on every
  triangle sharing a vertex with it (where a watertight float32 hit really is);
* a hit that float64 rejects makes the ray be cast again just past it, with a
  step that starts at ``band / 16`` and doubles at each retry (a grazing ray can
  stay within float32 noise of a plane for a long way).

So every reported hit is a float64 hit. What float32 can still get wrong is a
*miss*: a ray passing within float32 noise of a silhouette edge, or grazing a
plane so that float32 keeps it on one side: the degenerate configurations that
epsilon-visibility exists for.
"""

import numpy as np
from embreex import rtcore_scene
from numba import njit
from embreex.mesh_construction import TriangleMesh

#: Margin of embree's search interval, in float32 ulps of the scene's half-extent.
FLOAT32_ULPS = 8
#: Rays per embree call (bounds temporary memory).
CHUNK = 1 << 20
#: Enlargement of the bounding box where sky ends are placed (design notes §4).
SKY_MARGIN = 0.01
# Barycentric slack of the float64 test: points on a triangle's edge are on it.
_BARY_SLACK = 1e-12
_MAX_RECASTS = 64


@njit(cache=True)
def _intersect_pairs(origins, directions, vertices, triangles, tri):
    """Float64 Möller–Trumbore of ray i against triangle tri[i] (see intersect_triangles)."""
    n = tri.shape[0]
    t = np.empty(n)
    inside = np.empty(n, dtype=np.bool_)
    for i in range(n):
        ia, ib, ic = triangles[tri[i], 0], triangles[tri[i], 1], triangles[tri[i], 2]
        ax, ay, az = vertices[ia, 0], vertices[ia, 1], vertices[ia, 2]
        e1x, e1y, e1z = vertices[ib, 0] - ax, vertices[ib, 1] - ay, vertices[ib, 2] - az
        e2x, e2y, e2z = vertices[ic, 0] - ax, vertices[ic, 1] - ay, vertices[ic, 2] - az
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        # p = d × e2, det = e1 · p
        px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
        det = e1x * px + e1y * py + e1z * pz
        scale = np.sqrt((e1x * e1x + e1y * e1y + e1z * e1z) * (e2x * e2x + e2y * e2y + e2z * e2z) * (dx * dx + dy * dy + dz * dz))
        if abs(det) <= 1e-14 * scale:  # ray parallel to the triangle's plane
            t[i] = np.inf
            inside[i] = False
            continue
        inv = 1.0 / det
        sx, sy, sz = origins[i, 0] - ax, origins[i, 1] - ay, origins[i, 2] - az
        u = (sx * px + sy * py + sz * pz) * inv
        # q = s × e1
        qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
        v = (dx * qx + dy * qy + dz * qz) * inv
        t[i] = (e2x * qx + e2y * qy + e2z * qz) * inv
        inside[i] = u >= -_BARY_SLACK and v >= -_BARY_SLACK and u + v <= 1.0 + _BARY_SLACK
    return t, inside


def intersect_triangles(origins, directions, vertices, triangles, tri):
    """Float64 Möller–Trumbore for paired rays and triangles.

    Parameters
    ----------
    origins, directions : (n, 3) float
    vertices : (v, 3) float
    triangles : (t, 3) int
    tri : (n,) int
        The triangle tested against each ray.

    Returns
    -------
    t : (n,) float
        Ray parameter of the hit with the triangle's plane (inf when parallel).
    inside : (n,) bool
        Whether that point is in the closed triangle.
    """
    return _intersect_pairs(
        np.ascontiguousarray(origins, dtype=np.float64),
        np.ascontiguousarray(directions, dtype=np.float64),
        vertices,
        triangles,
        np.ascontiguousarray(tri, dtype=np.int64),
    )


def _unit(directions):
    d = np.asarray(directions, dtype=np.float64)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    if np.any(n == 0) or not np.all(np.isfinite(d)):
        raise ValueError("directions must be finite and non-zero")
    return d / n


class RayCaster:
    """Batched first-hit, free-segment and maximal-segment queries on a scene.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int
    triangle_face : (t,) int
        Face id reported for each triangle.
    epsilon : float
        Default trimming at segment ends (scene units).
    band : float, optional
        Margin of embree's search interval (scene units); default
        ``FLOAT32_ULPS`` float32 ulps of the scene's half-extent.
    """

    def __init__(self, vertices, triangles, triangle_face, epsilon, band=None):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.triangle_face = np.asarray(triangle_face, dtype=np.int64)
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.center = 0.5 * (lo + hi)
        self.diagonal = float(np.linalg.norm(hi - lo))
        margin = SKY_MARGIN * 0.5 * (hi - lo) + SKY_MARGIN * self.diagonal * 1e-3
        self.sky_box = np.stack([lo - margin, hi + margin])
        self.epsilon = float(epsilon)
        half_extent = float(np.abs(self.vertices - self.center).max())
        ulp = float(np.finfo(np.float32).eps) * half_extent
        self.band = float(band) if band is not None else FLOAT32_ULPS * ulp
        self._embree = rtcore_scene.EmbreeScene(robust=True)
        corners = (self.vertices[self.triangles] - self.center).astype(np.float32)
        self._mesh = TriangleMesh(self._embree, corners)  # keep a reference alive
        # vertex -> triangles (CSR), for the one-ring float64 re-decision
        flat = self.triangles.reshape(-1)
        order = np.argsort(flat, kind="stable")
        self._ring_tris = order // 3
        self._ring_offsets = np.searchsorted(flat[order], np.arange(len(self.vertices) + 1))
        self.stats = {"rays": 0, "float64_checks": 0, "recasts": 0}

    # -- the one primitive -------------------------------------------------------------
    def first_hit(self, origins, directions, tmin=0.0, tmax=np.inf):
        """First face met on ``[tmin, tmax]`` along each ray.

        Parameters
        ----------
        origins : (n, 3) float
        directions : (n, 3) float
            Need not be unit; ``t`` is measured in scene units along them.
        tmin, tmax : float or (n,) float

        Returns
        -------
        face : (n,) int
            Face id, -1 when nothing is hit.
        t : (n,) float
            Distance of the hit (inf when nothing is hit).
        """
        origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        directions = _unit(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
        n = len(origins)
        tmin = np.broadcast_to(np.asarray(tmin, dtype=np.float64), (n,)).copy()
        tmax = np.broadcast_to(np.asarray(tmax, dtype=np.float64), (n,)).copy()
        face = np.full(n, -1, dtype=np.int64)
        t = np.full(n, np.inf)
        for lo in range(0, n, CHUNK):
            sl = slice(lo, min(n, lo + CHUNK))
            face[sl], t[sl] = self._first_hit(origins[sl], directions[sl], tmin[sl], tmax[sl])
        self.stats["rays"] += n
        return face, t

    def _embree_hits(self, origins, directions, start, stop):
        """Float32 first hit on ``[start, stop]``: (triangle or -1, approximate t)."""
        o32 = (origins + start[:, None] * directions - self.center).astype(np.float32)
        length = np.where(np.isfinite(stop), stop - start, np.inf).astype(np.float32)
        out = self._embree.run(o32, directions.astype(np.float32), dists=length, output=1)
        return out["primID"].astype(np.int64), start + out["tfar"].astype(np.float64)

    def _first_hit(self, origins, directions, tmin, tmax):
        n = len(origins)
        face = np.full(n, -1, dtype=np.int64)
        t_out = np.full(n, np.inf)
        start = tmin - self.band
        stop = tmax + self.band
        step = np.full(n, self.band / 16)
        todo = np.arange(n)
        for _ in range(_MAX_RECASTS):
            if len(todo) == 0:
                break
            prim, _ = self._embree_hits(origins[todo], directions[todo], start[todo], stop[todo])
            hit = prim >= 0
            rays, tri = todo[hit], prim[hit]
            if len(rays) == 0:
                break
            self.stats["float64_checks"] += len(rays)
            best_t, best_tri, passed = self._decide64(origins[rays], directions[rays], tmin[rays], tmax[rays], tri)
            found = np.isfinite(best_t)
            face[rays[found]] = self.triangle_face[best_tri[found]]
            t_out[rays[found]] = best_t[found]
            # rejected in float64: cast again past the rejected hit, if before tmax
            again = ~found & (passed < tmax[rays])
            todo = rays[again]
            start[todo] = np.maximum(start[todo] + step[todo], passed[again] + step[todo])
            step[todo] *= 2
            self.stats["recasts"] += len(todo)
        return face, t_out

    def _decide64(self, origins, directions, tmin, tmax, tri):
        """Float64 decision of the hits embree proposed.

        Returns the smallest valid ``t`` in ``[tmin, tmax]`` (inf if none), its
        triangle, and the float64 ``t`` of the proposed hit (where to recast from).
        """
        t64, inside = intersect_triangles(origins, directions, self.vertices, self.triangles, tri)
        valid = inside & (t64 >= tmin) & (t64 <= tmax)
        best_t = np.where(valid, t64, np.inf)
        best_tri = tri.copy()
        # passing just outside the triangle: the true hit may be on a neighbour
        outside = np.flatnonzero(~inside)
        if len(outside):
            corners = self.triangles[tri[outside]]  # (k, 3)
            lo = self._ring_offsets[corners]
            hi = self._ring_offsets[corners + 1]
            counts = (hi - lo).reshape(-1)
            owner = np.repeat(np.repeat(outside, 3), counts)
            starts = np.repeat(lo.reshape(-1), counts)
            within = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
            cand = self._ring_tris[starts + within]
            ct, cin = intersect_triangles(origins[owner], directions[owner], self.vertices, self.triangles, cand)
            ok = cin & (ct >= tmin[owner]) & (ct <= tmax[owner])
            ct_ok = np.where(ok, ct, np.inf)
            order = np.lexsort((ct_ok, owner))
            first = np.unique(owner[order], return_index=True)[1]
            sel = order[first]
            best_t[owner[sel]] = ct_ok[sel]
            best_tri[owner[sel]] = cand[sel]
        # parallel to the triangle's plane: float64 has no crossing, and the ray
        # cannot meet the triangle beyond its farthest corner along the ray
        corners = self.vertices[self.triangles[tri]]
        farthest = np.einsum("ikj,ij->ik", corners - origins[:, None, :], directions).max(axis=1)
        passed = np.where(np.isfinite(t64), t64, farthest)
        return best_t, best_tri, passed

    # -- the queries built on it ---------------------------------------------------------
    def free_segments(self, starts, ends, trim=None):
        """Whether each segment is free, its ends trimmed by ``trim``.

        Parameters
        ----------
        starts, ends : (n, 3) float
        trim : float, optional
            Length cut from both ends before testing (default: the epsilon).
            A segment not longer than ``2 trim`` is free.

        Returns
        -------
        (n,) bool
        """
        starts = np.asarray(starts, dtype=np.float64).reshape(-1, 3)
        ends = np.asarray(ends, dtype=np.float64).reshape(-1, 3)
        trim = self.epsilon if trim is None else float(trim)
        vec = ends - starts
        length = np.linalg.norm(vec, axis=1)
        free = length <= 2 * trim
        rays = np.flatnonzero(~free)
        if len(rays):
            face, _ = self.first_hit(starts[rays], vec[rays], tmin=trim, tmax=length[rays] - trim)
            free[rays] = face < 0
        return free

    def sky_points(self, origins, directions):
        """Where rays leave the enlarged bounding box (the sky's stand-in end).

        Parameters
        ----------
        origins : (n, 3) float
            Inside the box.
        directions : (n, 3) float

        Returns
        -------
        (n, 3) float
        """
        d = _unit(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = np.where(d > 0, self.sky_box[1], self.sky_box[0])
            t = np.where(d != 0, (bound - o) / d, np.inf)
        return o + np.min(t, axis=1)[:, None] * d

    def maximal_segments(self, points, directions, tmin=None):
        """The maximal free segment through each point along each direction.

        Parameters
        ----------
        points : (n, 3) float
        directions : (n, 3) float
        tmin : float, optional
            Clearance around the point before faces count (default: the
            epsilon), so that a point on a surface does not block itself.

        Returns
        -------
        dict
            ``front_face``, ``back_face`` : (n,) int (-1 for the sky);
            ``front_point``, ``back_point`` : (n, 3) float, the segment's ends along
            ``+direction`` and ``-direction`` (on the enlarged box for the sky).
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        d = _unit(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
        tmin = self.epsilon if tmin is None else float(tmin)
        both_o = np.concatenate([p, p])
        both_d = np.concatenate([d, -d])
        face, t = self.first_hit(both_o, both_d, tmin=tmin)
        sky = face < 0
        ends = both_o + np.where(sky, 0.0, t)[:, None] * both_d
        if sky.any():
            ends[sky] = self.sky_points(both_o[sky], both_d[sky])
        n = len(p)
        return {
            "front_face": face[:n],
            "front_point": ends[:n],
            "back_face": face[n:],
            "back_point": ends[n:],
        }
