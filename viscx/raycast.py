"""Batched ray casting: embree (float32) as the filter, float64 for every decision.

The only module that talks to embree. Every query is a *first hit on a parameter
interval*: along ``o + t d`` (``d`` unit), the first face whose triangle meets
the ray at ``t ∈ [tmin, tmax]`` (closed), with its float64 ``t``.

How float32 is kept honest
--------------------------
Embree (coordinates relative to the scene centre) searches
``[tmin - band, tmax + band]``, ``band`` being 8 float32 ulps of the scene's
half-extent (about 5e-7 of the diagonal: below the default epsilon, so a ray
leaving a surface does not re-find it). Its first hit is accepted only when it
is clear-cut in float64 on its triangle:

* float64 puts the ray inside the triangle with a barycentric margin of at least
  ``1e-6`` (not near an edge, where the true first hit may be a neighbour),
* the ray is not grazing (|cos| to the triangle's plane at least ``1e-4``),
* float64 and float32 agree on where (within ``band``), and the hit is farther
  than ``band`` from both interval ends.

Under those conditions float32 cannot have ordered two hits wrongly, except for
surfaces closer than ``band`` to each other. Every other ray embree hit is
decided by :class:`viscx.grid.TriangleGrid`, an exact float64 first-hit
caster. What float32 can still get wrong is a crossing it does not see at all:
a ray passing within float32 rounding of a silhouette edge, or crossing a plane
so obliquely (below about 1e-7 rad, float32 rounding over the scene's size)
that it stays within rounding of the plane: such a ray may be reported as
passing that face. These are the degenerate configurations epsilon-visibility
exists for; a reported hit is never beyond the true first hit of a clearly
crossed face (tests/test_raycast.py, the hard configurations).
"""

import numpy as np
from embreex import rtcore_scene
from numba import njit

from viscx.arrays import row_norms
from viscx.grid import TriangleGrid, moller_trumbore
from viscx.tolerances import CLEAR_COSINE, CLEAR_MARGIN, SKY_MARGIN
from embreex.mesh_construction import TriangleMesh

#: Margin of embree's search interval, in float32 ulps of the scene's half-extent.
FLOAT32_ULPS = 8
#: Rays per embree call (bounds temporary memory).
CHUNK = 1 << 20


@njit(cache=True, nogil=True)
def _intersect_pairs(origins, directions, vertices, triangles, tri):
    n = tri.shape[0]
    t = np.empty(n)
    margin = np.empty(n)
    cosine = np.empty(n)
    for i in range(n):
        t[i], margin[i], cosine[i] = moller_trumbore(origins[i], directions[i], vertices, triangles, tri[i])
    return t, margin, cosine


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
    margin : (n,) float
        Smallest barycentric coordinate of that point: ≥ 0 inside the closed
        triangle, its distance from the nearest edge relative to the triangle.
    cosine : (n,) float
        |cos| of the angle between the ray and the triangle's normal (0: grazing).
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
    # scale by the largest component first: 1e160 would overflow the norm, 1e-170 underflow it
    big = np.abs(d).max(axis=1, keepdims=True) if len(d) else np.ones((0, 1))
    if np.any(big == 0) or not np.all(np.isfinite(d)):
        raise ValueError("directions must be finite and non-zero")
    d = d / big
    return d / row_norms(d)[:, None]


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
        self.exact = TriangleGrid(self.vertices, self.triangles)
        self.stats = {"rays": 0, "float64_checks": 0, "exact": 0}

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
        prim, t32 = self._embree_hits(origins, directions, tmin - self.band, tmax + self.band)
        rays = np.flatnonzero(prim >= 0)
        tri = prim[rays]
        self.stats["float64_checks"] += len(rays)
        t64, margin, cosine = intersect_triangles(origins[rays], directions[rays], self.vertices, self.triangles, tri)
        clear = (
            (margin >= CLEAR_MARGIN)
            & (cosine >= CLEAR_COSINE)
            & (np.abs(t64 - t32[rays]) <= self.band)
            & (t64 >= tmin[rays] + self.band)
            & (t64 <= tmax[rays] - self.band)
        )
        face[rays[clear]] = self.triangle_face[tri[clear]]
        t_out[rays[clear]] = t64[clear]
        doubt = rays[~clear]
        if len(doubt):
            self.stats["exact"] += len(doubt)
            tri_exact, t_exact = self.exact.first_hit(origins[doubt], directions[doubt], tmin[doubt], tmax[doubt])
            found = tri_exact >= 0
            face[doubt[found]] = self.triangle_face[tri_exact[found]]
            t_out[doubt[found]] = t_exact[found]
        return face, t_out

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
        length = row_norms(vec)
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
        # a point outside the box (in the sky already) is its own sky end
        return o + np.maximum(np.min(t, axis=1), 0.0)[:, None] * d

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
