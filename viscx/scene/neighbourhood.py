"""The surface around a point: every face touching it, as the wedge it makes there.

A face touching a point p is, in a small ball around p, a planar wedge with
apex p: a corner (p is one of its vertices), a half-plane (p lies on one of its
edges) or the whole plane (p lies inside it). This is found geometrically
(within the weld tolerance), so it sees faces the half-edge structure does not
connect: a block's bottom edge lying on a floor, a wall's corner on another
wall's edge (a T-junction).

A wedge is given by its first ray ``a`` (unit, in the face's plane), its face's
unit normal ``n`` and its angle ``span``: it sweeps counter-clockwise about n
from a by span (2π for the whole plane).

Generators are asked about again and again (every sample of every arc family),
so :class:`GeneratorContacts` finds the wedges once per scene: at every vertex,
and along every edge that no foreign face comes near (its wedges are then its
own faces' half-planes at every inner point). Points of the other edges (a block's
bottom edge on a floor) are tested each time, but only against the few triangles
found near their edge once.
"""

from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from viscx.arrays import row_norms
from viscx.geometry.tangency import tangent_in_wedges
from viscx.tolerances import ANGLE_TOLERANCE


@dataclass
class Wedges:
    """Wedges around query points, as a CSR list.

    Attributes
    ----------
    offsets : (q + 1,) int
        Wedges of point i are ``offsets[i]:offsets[i + 1]``.
    face : (k,) int
    first : (k, 3) float
        Unit first ray ``a``.
    normal : (k, 3) float
    span : (k,) float
        In (0, 2π]; 2π for a point inside the face.
    """

    offsets: np.ndarray
    face: np.ndarray
    first: np.ndarray
    normal: np.ndarray
    span: np.ndarray

    def ranges(self):
        """(lo, hi) : (q,) int, the rows of each point's wedges."""
        return self.offsets[:-1], self.offsets[1:]


@dataclass
class WedgeRanges:
    """Wedges around query points as row ranges of shared arrays, read in place: the
    wedges of point i are rows ``lo[i]:hi[i]`` of ``face``, ``first``, ``normal`` and
    ``span`` (as in :class:`Wedges`). The cached wedges of generators are asked about for
    millions of points: a CSR copy per point cost more than the tangency test itself.

    Attributes
    ----------
    lo, hi : (q,) int
    face : (k,) int
    first, normal : (k, 3) float
    span : (k,) float
    """

    lo: np.ndarray
    hi: np.ndarray
    face: np.ndarray
    first: np.ndarray
    normal: np.ndarray
    span: np.ndarray

    def ranges(self):
        """(lo, hi) : (q,) int, the rows of each point's wedges."""
        return self.lo, self.hi

    def take(self, index):
        """The wedges of the points ``index`` ((m,) int), as a CSR :class:`Wedges`."""
        index = np.asarray(index, dtype=np.int64)
        return _gather(self, self.lo[index], self.hi[index])


def _gather(w, lo, hi):
    """The :class:`Wedges` (CSR) holding rows lo[i]:hi[i] of ``w``'s arrays for each point i."""
    count = hi - lo
    offsets = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
    rows = np.repeat(lo, count) + np.arange(offsets[-1]) - np.repeat(offsets[:-1], count)
    return Wedges(offsets=offsets, face=w.face[rows], first=w.first[rows], normal=w.normal[rows], span=w.span[rows])


def incident_faces(scene):
    """Faces touching each vertex and each edge through the half-edge structure.

    Returns
    -------
    vertex_offsets : (n + 1,) int
    vertex_faces : (k,) int
    edge_offsets : (e + 1,) int
    edge_faces : (k',) int
    """
    he = scene.half_edges

    def table(owner, face, size):
        pairs = np.unique(np.stack([owner, face], axis=1), axis=0)
        return np.searchsorted(pairs[:, 0], np.arange(size + 1)), pairs[:, 1]

    vo, vf = table(he.start, he.face, scene.n_vertices)
    eo, ef = table(he.edge, he.face, len(he.edge_vertices))
    return vo, vf, eo, ef


def faces_near(scene, points, tol):
    """(point, face) pairs with the point within ``tol`` of the closed face, sorted."""
    point, tri = scene.ray_caster.exact.triangles_near(points, tol)
    return _unique_faces(point, scene.triangle_face[tri])


@njit(cache=True)
def _unique_faces(point, face):
    """The distinct (point, face) pairs of (point, face) pairs sorted by point, sorted by
    face within each point (runs are short: a few faces touch a point)."""
    out_point = np.empty(len(point), dtype=np.int64)
    out_face = np.empty(len(point), dtype=np.int64)
    k = 0
    i = 0
    while i < len(point):
        j = i
        run = k
        while j < len(point) and point[j] == point[i]:
            f = face[j]
            # insert f into the sorted run unless present
            q = k
            while q > run and out_face[q - 1] > f:
                q -= 1
            if not (q > run and out_face[q - 1] == f):
                for r in range(k, q, -1):
                    out_face[r] = out_face[r - 1]
                out_face[q] = f
                out_point[k] = point[i]
                k += 1
            j += 1
        i = j
    return out_point[:k], out_face[:k]


@njit(cache=True, nogil=True)
def _classify(points, owner, face, half_first, half_last, start, end, prev, nxt, vertices, normal, tol):
    """The wedge each face makes at its point: a whole plane (the point is inside it), a
    corner (at one of its vertices) or a half-plane (on one of its edges), judged by the
    face's nearest boundary half-edge (the first of equally near ones)."""
    k = len(face)
    first = np.empty((k, 3))
    span = np.empty(k)
    for i in range(k):
        p = points[owner[i]]
        f = face[i]
        best, best_d, best_s, best_len = -1, np.inf, 0.0, 0.0
        for h in range(half_first[f], half_last[f]):
            a, b = vertices[start[h]], vertices[end[h]]
            ab0, ab1, ab2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
            ll = ab0 * ab0 + ab1 * ab1 + ab2 * ab2
            s = ((p[0] - a[0]) * ab0 + (p[1] - a[1]) * ab1 + (p[2] - a[2]) * ab2) / ll
            s = min(max(s, 0.0), 1.0)
            dist = np.sqrt((p[0] - a[0] - s * ab0) ** 2 + (p[1] - a[1] - s * ab1) ** 2 + (p[2] - a[2] - s * ab2) ** 2)
            if dist < best_d:
                best, best_d, best_s, best_len = h, dist, s, np.sqrt(ll)
        n = normal[f]
        if best_d > tol:  # inside the face: the whole plane, any first ray in it
            m = np.argmin(np.abs(n))
            u = np.zeros(3)
            u[m] = 1.0
            r = np.cross(n, u)
            first[i] = r / np.sqrt((r * r).sum())
            span[i] = 2 * np.pi
            continue
        at_start = best_s * best_len <= tol
        at_end = not at_start and (1 - best_s) * best_len <= tol
        if at_start or at_end:  # a corner: between the edge leaving it and the one arriving
            ch = nxt[best] if at_end else best
            o = vertices[start[ch]]
            leave = vertices[end[ch]] - o
            leave /= np.sqrt((leave * leave).sum())
            arrive = vertices[start[prev[ch]]] - o
            arrive /= np.sqrt((arrive * arrive).sum())
            first[i] = leave
            span[i] = np.arctan2((arrive * np.cross(n, leave)).sum(), (arrive * leave).sum()) % (2 * np.pi)
        else:  # on an edge: the half-plane on the face's side (faces lie left of their half-edges)
            ab = vertices[end[best]] - vertices[start[best]]
            first[i] = ab / np.sqrt((ab * ab).sum())
            span[i] = np.pi
    return first, span


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def surface_wedges(scene, points):
    """Every face touching each point, as the wedge it makes there.

    Parameters
    ----------
    scene : Scene
    points : (q, 3) float

    Returns
    -------
    Wedges
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    return _wedges_of_contacts(scene, points, *faces_near(scene, points, scene.weld_tolerance))


def _wedges_of_contacts(scene, points, owner, face):
    """The wedges of the faces touching each point, given as (point, face) pairs sorted by
    point, then face."""
    he = scene.half_edges
    prev = np.empty_like(he.next)
    prev[he.next] = np.arange(len(he.next))
    # a face's half-edges are contiguous, loop after loop
    first_ray, span = _classify(
        points, owner, face, scene.loop_offsets[scene.face_loop_offsets[:-1]], scene.loop_offsets[scene.face_loop_offsets[1:]],
        he.start, he.end, prev, he.next, scene.vertices, scene.face_normal, scene.weld_tolerance,
    )
    n = scene.face_normal[face]
    offsets = np.searchsorted(owner, np.arange(len(points) + 1))
    return Wedges(offsets=offsets, face=face, first=first_ray, normal=n, span=span)


@dataclass
class GeneratorContacts:
    """The surface around every vertex and along every edge, found once per scene.

    Attributes
    ----------
    vertex : Wedges
        The wedges at each vertex (query point i = vertex i).
    edge : Wedges
        The half-planes of each edge's faces (query point i = edge i): first ray
        along the face's half-edge, span π.
    edge_clean : (e,) bool
        No face other than the edge's own comes within the weld tolerance of the
        edge shortened by ``shrink`` at both ends: there ``edge`` holds the wedges
        of every inner point.
    shrink : float
    near_offsets : (e + 1,) int
    near_triangles : (k,) int
        The triangles within twice the weld tolerance of each (whole) edge, as CSR: the
        only ones that can touch a point of it, so that points of unclean edges are
        searched among these instead of over the grid.
    """

    vertex: Wedges
    edge: Wedges
    edge_clean: np.ndarray
    shrink: float
    near_offsets: np.ndarray
    near_triangles: np.ndarray
    # vertex then edge wedges as one set of rows (:meth:`rows`); not copied by ``replace``
    _rows: tuple = field(default=None, init=False, repr=False, compare=False)

    def rows(self):
        """The wedges of every vertex, then of every edge, as one set of arrays (face, first,
        normal, span), and the first edge row: what :func:`generator_wedge_ranges` points into."""
        if self._rows is None:
            v, e = self.vertex, self.edge
            self._rows = (tuple(np.concatenate([getattr(v, k), getattr(e, k)]) for k in ("face", "first", "normal", "span")),
                          len(v.face))
        return self._rows

    def with_free_points(self, k):
        """The contacts after k free points (touching no face) are appended as vertices."""
        v = self.vertex
        offsets = np.concatenate([v.offsets, np.full(k, v.offsets[-1])])
        return replace(self, vertex=Wedges(offsets, v.face, v.first, v.normal, v.span))


def generator_contacts(scene):
    """Build :class:`GeneratorContacts` (use ``scene.contacts``, which caches it)."""
    he = scene.half_edges
    n_edges = len(he.edge_vertices)
    vertex = surface_wedges(scene, scene.vertices)

    # half-planes of the faces along each edge (faces lie left of their half-edges)
    order = np.lexsort((he.face, he.edge))
    h = order
    a, b = scene.vertices[he.start[h]], scene.vertices[he.end[h]]
    edge = Wedges(
        offsets=np.searchsorted(he.edge[h], np.arange(n_edges + 1)),
        face=he.face[h],
        first=_unit(b - a),
        normal=scene.face_normal[he.face[h]],
        span=np.full(len(h), np.pi),
    )

    # an edge is clean when the faces near its shortened segment are its own, each once
    shrink = scene.epsilon
    ev = he.edge_vertices
    p, q = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
    length = row_norms(q - p)
    u = (q - p) / np.maximum(length, 1e-300)[:, None]
    clean = length > 2 * shrink
    own_key = he.edge[h] * scene.n_faces + he.face[h]
    clean &= np.bincount(he.edge[h][1:][own_key[1:] == own_key[:-1]], minlength=n_edges) == 0
    seg, tri = scene.ray_caster.exact.triangles_near_segments(p + shrink * u, q - shrink * u, scene.weld_tolerance)
    key = seg * scene.n_faces + scene.triangle_face[tri]
    foreign = ~np.isin(key, own_key)
    clean[seg[foreign]] = False
    seg, tri = scene.ray_caster.exact.triangles_near_segments(p, q, 2 * scene.weld_tolerance)
    return GeneratorContacts(vertex=vertex, edge=edge, edge_clean=clean, shrink=shrink,
                             near_offsets=np.searchsorted(seg, np.arange(n_edges + 1)), near_triangles=tri)


def generator_wedges(scene, is_vertex, generator, points):
    """The wedges at points of generators (:func:`generator_wedge_ranges`) as a CSR :class:`Wedges`.

    Parameters
    ----------
    scene : Scene
    is_vertex : (q,) bool
    generator : (q,) int
        Vertex or edge id.
    points : (q, 3) float
        The vertex, or a point of the edge.

    Returns
    -------
    Wedges
    """
    w = generator_wedge_ranges(scene, is_vertex, generator, points)
    return w.take(np.arange(len(w.lo)))


def generator_wedge_ranges(scene, is_vertex, generator, points):
    """The wedges at points of generators: cached at vertices and inside clean edges (read
    in place), searched geometrically elsewhere (:func:`surface_wedges`).

    Parameters as :func:`generator_wedges`.

    Returns
    -------
    WedgeRanges
    """
    c = scene.contacts
    is_vertex = np.asarray(is_vertex, dtype=bool)
    generator = np.asarray(generator, dtype=np.int64)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    iv = np.flatnonzero(is_vertex)
    ie = np.flatnonzero(~is_vertex)
    ev = scene.half_edges.edge_vertices[generator[ie]]
    a, b = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
    # distance of the point from both ends, along the edge
    along = np.einsum("ij,ij->i", points[ie] - a, _unit(b - a))
    inner = (along >= c.shrink) & (along <= row_norms(b - a) - c.shrink)
    cached = inner & c.edge_clean[generator[ie]]
    # a point within the weld tolerance of its edge touches only faces near the edge
    off_edge = row_norms(points[ie] - a - along[:, None] * _unit(b - a))
    listed = ~cached & (off_edge <= scene.weld_tolerance) & (along >= -scene.weld_tolerance) & (
        along <= row_norms(b - a) + scene.weld_tolerance)
    ic, il, ig = ie[cached], ie[listed], ie[~cached & ~listed]
    arrays, edge_row = c.rows()
    lo, hi = np.empty(len(points), np.int64), np.empty(len(points), np.int64)
    lo[iv], hi[iv] = c.vertex.offsets[generator[iv]], c.vertex.offsets[generator[iv] + 1]
    lo[ic], hi[ic] = edge_row + c.edge.offsets[generator[ic]], edge_row + c.edge.offsets[generator[ic] + 1]
    # the points searched: their wedges appended after the cached ones
    fresh = []
    if len(il):
        row, tri = scene.ray_caster.exact.triangles_near_listed(points[il], generator[il], c.near_offsets,
                                                                c.near_triangles, scene.weld_tolerance)
        fresh.append((il, _wedges_of_contacts(scene, points[il], *_unique_faces(row, scene.triangle_face[tri]))))
    if len(ig):
        fresh.append((ig, surface_wedges(scene, points[ig])))
    base = len(arrays[0])
    for rows, w in fresh:
        lo[rows], hi[rows] = base + w.offsets[:-1], base + w.offsets[1:]
        base += len(w.face)
    if fresh:
        arrays = tuple(np.concatenate([a] + [getattr(w, k) for _, w in fresh])
                       for a, k in zip(arrays, ("face", "first", "normal", "span")))
    return WedgeRanges(lo, hi, *arrays)


# --------------------------------------------------------------------------------------
# tangency at the scene's points (viscx.geometry.tangency on their wedges)


def tangent_at_points(scene, points, directions, angle_tol=ANGLE_TOLERANCE):
    """:func:`~viscx.geometry.tangency.tangent_in_wedges` at any points of the surface (vertices, points of edges),
    their wedges searched geometrically.

    Parameters
    ----------
    scene : Scene
    points : (q, 3) float
    directions : (q, 3) float
    """
    return tangent_in_wedges(surface_wedges(scene, points), directions, angle_tol)


def tangent_at_vertices(scene, vertices, directions, angle_tol=ANGLE_TOLERANCE):
    """:func:`~viscx.geometry.tangency.tangent_in_wedges` at vertices (their wedges are cached per scene).

    Parameters
    ----------
    vertices : (q,) int
    directions : (q, 3) float
    """
    v = scene.contacts.vertex
    vertices = np.asarray(vertices, dtype=np.int64)
    return tangent_in_wedges(WedgeRanges(v.offsets[vertices], v.offsets[vertices + 1], v.face, v.first, v.normal, v.span),
                             directions, angle_tol)


def tangent_at_edges(scene, edges, directions, points=None, angle_tol=ANGLE_TOLERANCE):
    """:func:`tangent_at_points` at points of edges.

    Parameters
    ----------
    edges : (q,) int
        Undirected edge ids.
    directions : (q, 3) float
    points : (q, 3) float, optional
        Where each line meets its edge (default: the edge's midpoint). It
        matters where the edge runs partly across another face.
    """
    if points is None:
        ev = scene.half_edges.edge_vertices[np.asarray(edges, dtype=np.int64)]
        points = 0.5 * (scene.vertices[ev[:, 0]] + scene.vertices[ev[:, 1]])
    return tangent_at_points(scene, points, directions, angle_tol)
