"""Generator tables shared by the arcs and the cells: the generator edges at each vertex,
edge endpoints, skew pairs, the junctions and crossings of edges (degenerate scenes) and the
canonical order of EEE triples.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from viscx.arrays import row_norms
from viscx.grid import bin_boxes
from viscx.tolerances import ANGLE_TOLERANCE


def vertex_edges(scene):
    """Generator edges at each vertex as CSR: (offsets (n + 1,), edges (k,))."""
    ge = scene.generator_edges
    ev = scene.half_edges.edge_vertices[ge]
    owner = np.concatenate([ev[:, 0], ev[:, 1]])
    edges = np.concatenate([ge, ge])
    order = np.lexsort([edges, owner])
    owner, edges = owner[order], edges[order]
    return np.searchsorted(owner, np.arange(scene.n_vertices + 1)), edges


def edges_through_vertices(scene):
    """Generator edges passing through each vertex, the vertex a T-junction strictly inside
    them (:func:`edge_junctions`), as CSR: (offsets (n + 1,), edges (k,)). A line through
    the vertex meets them as it meets the vertex's own edges."""
    j = edge_junctions(scene)
    at = np.flatnonzero(j.vertex >= 0)
    order = at[np.lexsort([j.edge[at], j.vertex[at]])]
    return np.searchsorted(j.vertex[order], np.arange(scene.n_vertices + 1)), j.edge[order]


def edge_geometry(scene, edges):
    """The end points (a, b) of edges (any shape of ids): a at the smaller vertex id
    (s = 0), each (..., 3) float. Gathered from the scene's cached (E, 3) arrays of ends,
    one gather each (a hot path of V1 and V2: three gathers through the edge's vertex ids
    cost three times as much)."""
    a, b = scene.cached("edge_ends", _edge_ends)
    return np.take(a, edges, axis=0), np.take(b, edges, axis=0)


def _edge_ends(scene):
    ev = scene.half_edges.edge_vertices
    return scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]


def skew_edges(scene, e1, e2):
    """Whether pairs of edges lie on skew lines (no shared vertex, not coplanar, not parallel)."""
    ev = scene.half_edges.edge_vertices
    share = (ev[e1][:, :, None] == ev[e2][:, None, :]).any(axis=(1, 2))
    a1, b1 = edge_geometry(scene, e1)
    a2, b2 = edge_geometry(scene, e2)
    u1 = (b1 - a1) / row_norms(b1 - a1)[:, None]
    u2 = (b2 - a2) / row_norms(b2 - a2)[:, None]
    c = np.cross(u1, u2)
    size = row_norms(c)
    with np.errstate(invalid="ignore", divide="ignore"):
        gap = np.abs(np.einsum("ij,ij->i", a2 - a1, c)) / size
    return ~share & (size > ANGLE_TOLERANCE) & (gap > scene.epsilon)


@dataclass
class Junctions:
    """Points strictly inside generator edges where the surface around the edge changes
    although no vertex of the edge is there (degenerate scenes): another edge's vertex
    lies on the edge (a T-junction: the inner wall's corner on the room's edge), or
    another edge crosses it (two coplanar edges of touching boxes). Lines through such a
    point are events of every family meeting the edge there, like the edge's endpoints.

    Attributes
    ----------
    edge : (k,) int
        Generator edge.
    s : (k,) float
        Where on it (0 at its smaller vertex id), farther than the weld tolerance from
        both endpoints; sorted by (edge, s).
    vertex : (k,) int
        The vertex lying there, -1 where another edge crosses.
    """

    edge: np.ndarray
    s: np.ndarray
    vertex: np.ndarray

    def __len__(self):
        return len(self.edge)


@njit(cache=True)
def _contacts(a, b, ends, tol, offsets, items, out, fill):
    """(edge i, s on i, vertex or -1, crossing edge j or -1, t on j) for every contact
    strictly inside edge i, per grid cell and pair of edges listed there: an endpoint of
    edge j within ``tol`` of i, or a crossing of non-parallel i and j (closest points
    within ``tol``, strictly inside both). Edges sharing a vertex are skipped. Counts
    only unless ``fill``."""
    k = 0
    for c in range(len(offsets) - 1):
        for p in range(offsets[c], offsets[c + 1]):
            i = items[p]
            u = b[i] - a[i]
            uu = (u * u).sum()
            li = np.sqrt(uu)
            for q in range(offsets[c], offsets[c + 1]):
                j = items[q]
                if j == i or ends[i, 0] == ends[j, 0] or ends[i, 0] == ends[j, 1] or ends[i, 1] == ends[j, 0] \
                        or ends[i, 1] == ends[j, 1]:
                    continue
                # boxes farther apart than tol on an axis: no contact (most pairs of a dense cell)
                apart = False
                for d in range(3):
                    if min(a[j, d], b[j, d]) - max(a[i, d], b[i, d]) > tol \
                            or min(a[i, d], b[i, d]) - max(a[j, d], b[j, d]) > tol:
                        apart = True
                if apart:
                    continue
                for w in range(2):  # an endpoint of j on i
                    x = a[j] if w == 0 else b[j]
                    s = ((x - a[i]) * u).sum() / uu
                    if s * li <= tol or (1.0 - s) * li <= tol:
                        continue
                    gap = x - a[i] - s * u
                    if np.sqrt((gap * gap).sum()) <= tol:
                        if fill:
                            out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4] = i, s, ends[j, w], -1.0, 0.0
                        k += 1
                if j < i:
                    continue
                v = b[j] - a[j]
                vv = (v * v).sum()
                uv = (u * v).sum()
                den = uu * vv - uv * uv
                if den <= 1e-24 * uu * vv:  # parallel: contacts are endpoints (above)
                    continue
                r = a[i] - a[j]
                ur, vr = (u * r).sum(), (v * r).sum()
                s = (uv * vr - vv * ur) / den
                t = (uu * vr - uv * ur) / den
                lj = np.sqrt(vv)
                if s * li <= tol or (1.0 - s) * li <= tol or t * lj <= tol or (1.0 - t) * lj <= tol:
                    continue
                gap = a[i] + s * u - a[j] - t * v
                if np.sqrt((gap * gap).sum()) <= tol:
                    if fill:
                        out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4] = i, s, -1.0, j, t
                        out[k + 1, 0], out[k + 1, 1], out[k + 1, 2], out[k + 1, 3], out[k + 1, 4] = j, t, -1.0, i, s
                    k += 2
    return k


def edge_junctions(scene):
    """The junctions of every generator edge (:class:`Junctions`).

    Contacts are geometric within the weld tolerance, as tangency's
    (:mod:`viscx.scene.neighbourhood`). Broad phase: the edges' boxes, grown by the
    tolerance, binned in a uniform grid (about two cells per edge); each contact is
    found in every cell both edges share and kept once. Cached on the scene.
    """
    return scene.cached("edge_contacts", _edge_contacts)[0]


@dataclass
class Crossings:
    """X-junctions: pairs of generator edges crossing at a point strictly inside both
    (within the weld tolerance), sorted by (a, b).

    Attributes
    ----------
    edges : (k, 2) int
        (a, b), a < b.
    s : (k, 2) float
        The crossing's parameter on a and on b (as in :class:`Junctions`).
    point : (k, 3) float
        The crossing point X: the middle of the two edges' closest points.
    """

    edges: np.ndarray
    s: np.ndarray
    point: np.ndarray

    def __len__(self):
        return len(self.edges)

    def find(self, a, b):
        """Row of each crossing (a, b), a < b (they must exist)."""
        n = int(self.edges.max()) + 1 if len(self) else 1
        return np.searchsorted(self.edges[:, 0] * n + self.edges[:, 1], np.asarray(a) * n + np.asarray(b))


def edge_crossings(scene):
    """The X-junctions of the generator edges (:class:`Crossings`), found with
    :func:`edge_junctions` and cached on the scene."""
    return scene.cached("edge_contacts", _edge_contacts)[1]


def _crossings_of(scene, rows):
    """:class:`Crossings` from contact rows (i, s, -1, j, t) of generator indices."""
    ge = scene.generator_edges
    rows = rows[(rows[:, 2] < 0) & (rows[:, 3] > rows[:, 0])]
    ab = ge[rows[:, [0, 3]].astype(np.int64)].reshape(-1, 2)
    s = rows[:, [1, 4]].reshape(-1, 2)
    flip = ab[:, 0] > ab[:, 1]
    ab = np.where(flip[:, None], ab[:, ::-1], ab)
    s = np.where(flip[:, None], s[:, ::-1], s)
    order = np.lexsort([ab[:, 1], ab[:, 0]])
    ab, s = ab[order], s[order]
    ends = scene.half_edges.edge_vertices[ab]
    x, y = (scene.vertices[ends[:, k, 0]] + s[:, k, None] * (scene.vertices[ends[:, k, 1]] - scene.vertices[ends[:, k, 0]])
            for k in (0, 1))
    return Crossings(ab, s, 0.5 * (x + y))


def _edge_contacts(scene):
    tol = scene.weld_tolerance
    ge = scene.generator_edges
    if len(ge) < 2:
        return (Junctions(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)),
                Crossings(np.zeros((0, 2), np.int64), np.zeros((0, 2)), np.zeros((0, 3))))
    ends = np.ascontiguousarray(scene.half_edges.edge_vertices[ge])
    a, b = (np.ascontiguousarray(scene.vertices[ends[:, k]]) for k in (0, 1))
    lo = np.minimum(a, b).min(axis=0) - 2 * tol
    hi = np.maximum(a, b).max(axis=0) + 2 * tol
    size = hi - lo
    per_unit = (2 * len(ge) / np.prod(np.maximum(size, 1e-9 * size.max()))) ** (1 / 3)
    dims = np.clip(np.ceil(size * per_unit), 1, 256).astype(np.int64)
    offsets, items = bin_boxes(lo, size / dims, dims, np.minimum(a, b) - tol, np.maximum(a, b) + tol)
    n = _contacts(a, b, ends, tol, offsets, items, np.zeros((0, 3)), False)
    out = np.empty((n, 5))
    _contacts(a, b, ends, tol, offsets, items, out, True)
    rows = np.unique(out[:, :3], axis=0)  # sorted by (edge index, s); repeats from shared cells
    return (Junctions(ge[rows[:, 0].astype(np.int64)], rows[:, 1], rows[:, 2].astype(np.int64)),
            _crossings_of(scene, np.unique(out, axis=0)))


def canonical_eee(scene, triples):
    """Canonical (p, q, r) of EEE families, p the parameter edge.

    Parameters
    ----------
    triples : (m, 3) int
        Three distinct edge ids per family, any order.

    Returns
    -------
    (m, 3) int
        p is the smallest id whose two other edges are skew, q < r; rows of -1
        where no edge qualifies (the three lines are pairwise coplanar: no
        1-parameter family).
    """
    t = np.sort(np.asarray(triples, dtype=np.int64).reshape(-1, 3), axis=1)
    out = np.full_like(t, -1)
    left = np.ones(len(t), dtype=bool)
    for i, (j, k) in enumerate(((1, 2), (0, 2), (0, 1))):
        rows = np.flatnonzero(left)
        ok = skew_edges(scene, t[rows, j], t[rows, k])
        rows = rows[ok]
        out[rows] = np.stack([t[rows, i], t[rows, j], t[rows, k]], axis=1)
        left[rows] = False
    return out
