"""Scoped builds: the part of V0 and V1 that holds given generators (an area light's
outline vertices and edges), with the full build's definitions.

An arc family (EEE, VE, XE) is *in scope* when one of its generators is a scope vertex
or a scope edge. The arcs of a family are decided within it (events, samples,
refinement, merging: :mod:`viscx.skeleton.arcs`), so the scoped build gives exactly
the full build's arcs of those families once it has every event on them. Their node
events are the nodes whose generators hold the family's (docs/skeleton.md, "Which
families"):

* VEE (v, e1, e2) lies on VE (v, e1), VE (v, e2) and EEE (e_v, e1, e2) for the edges
  e_v at v; E4 on the EEE families of three of its edges; VV (u, v) on VE (u, e) for
  the edges e at v. With the scope's vertices closed over its edges' endpoints, a node
  on a family in scope holds a scope vertex or edge.
* A node whose vertex w is a T-junction inside an edge E also seeds the families
  through E (:func:`viscx.skeleton.arcs.family_incidences`, ``through``): nodes at the
  vertices lying inside a scope edge are kept too.

So V0 in scope is the nodes with a generator in :attr:`Scope.node_vertices` or
:attr:`Scope.edges`, judged by the one node definition
(:func:`viscx.skeleton.nodes.validate_candidates`) on the full builder's candidates
for those tuples (the same floats): a subset of the full V0, in its order. The
families of V1 in scope come from them, the seeded families (same-plane VE, pencils of
touched planes, XE) filtered to the scope.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from viscx.arrays import unique_rows
from viscx.skeleton.generators import edge_geometry, edges_through_vertices


@dataclass
class Scope:
    """Generators a scoped build keeps.

    Attributes
    ----------
    vertices : (n_vertices,) bool
        Scope vertices (the edges' endpoints included).
    edges : (n_edges,) bool
        Scope edges.
    node_vertices : (n_vertices,) bool
        ``vertices`` and the vertices lying strictly inside a scope edge.
    """

    vertices: np.ndarray
    edges: np.ndarray
    node_vertices: np.ndarray

    @staticmethod
    def of(scene, vertices=(), edges=()):
        """The scope of the given vertex and edge ids of ``scene``."""
        ev = scene.half_edges.edge_vertices
        edges = np.asarray(edges, np.int64)
        vmask = np.zeros(scene.n_vertices, bool)
        vmask[np.asarray(vertices, np.int64)] = True
        vmask[ev[edges].ravel()] = True
        emask = np.zeros(len(ev), bool)
        emask[edges] = True
        jo, je = edges_through_vertices(scene)
        owner = np.repeat(np.arange(scene.n_vertices), np.diff(jo))
        nmask = vmask.copy()
        nmask[owner[emask[je]]] = True
        return Scope(vmask, emask, nmask)

    def _vertex(self, ids, mask):
        ids = np.asarray(ids, np.int64)
        ok = (ids >= 0) & (ids < len(mask))
        return ok & mask[np.where(ok, ids, 0)]

    def _edge(self, ids):
        ids = np.asarray(ids, np.int64)
        ok = ids >= 0
        return ok & self.edges[np.where(ok, ids, 0)]

    def nodes(self, kind, generators):
        """(m,) bool: node tuples (kind E4, VEE or VV; generators (m, 4) as
        :class:`viscx.skeleton.nodes.Nodes`) with a generator in scope."""
        from viscx.skeleton.nodes import SLOT_IS_VERTEX

        g = np.asarray(generators, np.int64).reshape(-1, 4)
        vertex_slot = SLOT_IS_VERTEX[np.asarray(kind, np.int64)]
        hit = np.where(vertex_slot, self._vertex(g, self.node_vertices), self._edge(g))
        return hit.any(axis=1)

    def crosses_planes(self, scene, normal, point):
        """(k,) bool: planes (unit ``normal`` (k, 3), a ``point`` (k, 3) of each) that a scope
        edge may cross strictly: its ends farther than half epsilon on opposite sides.

        A superset of :func:`viscx.skeleton.arcs.pencils.edges_crossing_planes`'s (both
        ends farther than epsilon): with the planes kept, that exact test decides as on
        every plane, so a scoped scan visits only the planes the scope's events lie in
        (k planes × the few scope edges, not × every generator edge)."""
        a, b = edge_geometry(scene, np.flatnonzero(self.edges))
        offset = np.einsum("ij,ij->i", normal, point)[:, None]
        h0, h1 = normal @ a.T - offset, normal @ b.T - offset
        half = 0.5 * scene.epsilon
        return ((np.minimum(h0, h1) < -half) & (np.maximum(h0, h1) > half)).any(axis=1)

    def families(self, kind, generators):
        """(m,) bool: arc families (kind EEE, VE or XE; generators (m, 3) as
        :class:`viscx.skeleton.arcs.Arcs`) with a generator in scope."""
        from viscx.skeleton.arcs.kinds import VE

        g = np.asarray(generators, np.int64).reshape(-1, 3)
        ve = np.asarray(kind) == VE
        first = np.where(ve, self._vertex(g[:, 0], self.vertices), self._edge(g[:, 0]))
        return first | self._edge(g[:, 1]) | self._edge(g[:, 2])


def _side_codes(lo, hi, x_lo, x_hi):
    """(n,) int: per axis 0 when a box (lo, hi (n, 3)) lies below [x_lo, x_hi], 2 above,
    1 across, as the base-3 digits of one code (0..26)."""
    side = np.where(hi < x_lo, 0, np.where(lo > x_hi, 2, 1))
    return side @ np.array([9, 3, 1])


def _compatible_codes():
    """(27, 27) bool: two side codes whose joint box meets the box on every axis (not
    both below, not both above)."""
    digits = np.array([[c // 9, c // 3 % 3, c % 3] for c in range(27)])
    a, b = digits[:, None, :], digits[None, :, :]
    return (~(((a == 0) & (b == 0)) | ((a == 2) & (b == 2)))).all(axis=2)


def pairs_near(s_lo, s_hi, lo1, hi1, lo2, hi2, same=False):
    """The outer pairs a scoped scan visits (:func:`viscx.skeleton.candidates.fast_candidates`):
    pairs (i, j) of an item of set 1 and one of set 2 whose joint bounding box meets the
    box of a scope generator.

    A node in scope has a scope generator on its line between (or at) its two outer
    generators, so inside their hull and so inside their joint box. The pairs are found
    light-centred, per scope generator, by the side of its box each item lies on along
    each axis (below, across, above): a joint box misses it only when both items lie
    below, or both above, on some axis. So items far from the light pair only with the
    few reaching it (the light's own edges, a wall across its height), and no pair of
    the scene's generators is visited otherwise.

    Parameters
    ----------
    s_lo, s_hi : (k, 3) float
        Boxes of the scope generators (padded by the scans' tolerance).
    lo1, hi1 : (n1, 3) float
    lo2, hi2 : (n2, 3) float
        Boxes of the items.
    same : bool
        One set (set 2 is set 1): pairs i < j.

    Returns
    -------
    first : (m,) int64
        The items of set 1 with a pair, increasing.
    (offsets, partners) : (n1 + 1,) int64, (p,) int64
        Item i's partners, increasing, at ``partners[offsets[i]:offsets[i + 1]]``.
    """
    ok = _compatible_codes()
    parts_i, parts_j = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for x_lo, x_hi in zip(s_lo, s_hi):
        groups = []
        for lo, hi in ((lo1, hi1), (lo2, hi2)):
            code = _side_codes(lo, hi, x_lo, x_hi)
            order = np.argsort(code, kind="stable")
            groups.append((order, np.searchsorted(code[order], np.arange(28))))
        (o1, b1), (o2, b2) = groups
        for p, q in zip(*np.nonzero(ok)):
            g1, g2 = o1[b1[p] : b1[p + 1]], o2[b2[q] : b2[q + 1]]
            if len(g1) and len(g2):
                parts_i.append(np.repeat(g1, len(g2)))
                parts_j.append(np.tile(g2, len(g1)))
    i, j = np.concatenate(parts_i), np.concatenate(parts_j)
    if same:
        i, j = np.minimum(i, j), np.maximum(i, j)
        i, j = i[i < j], j[i < j]
    pairs = unique_rows(np.stack([i, j], axis=1).astype(np.int64))[0].reshape(-1, 2)
    offsets = np.searchsorted(pairs[:, 0], np.arange(len(lo1) + 1)).astype(np.int64)
    return np.unique(pairs[:, 0]), (offsets, np.ascontiguousarray(pairs[:, 1]))


#: Edges per box of :func:`planar_crossings`'s scan (consecutive in Morton order).
_BOX_EDGES = 32

#: Slack on the corner frame's intercepts in :func:`planar_crossings` (a superset test:
#: the exact one of :func:`viscx.skeleton.arcs.events.planar_events` decides).
_CORNER_SLACK = 1e-3


def planar_crossings(scene, scope, whole, normal, point, ua, ub):
    """The generator edges crossing the corner planes of a scoped
    :func:`viscx.skeleton.arcs.events.planar_events`, as
    :func:`viscx.skeleton.arcs.pencils.edges_crossing_planes` gives them (the same floats,
    in its order), but only those that can make an event in scope.

    A planar event (a, b, c, d) lies in the plane of a corner (a, b at a vertex w) and
    passes where c and d cross it. In scope it holds a scope edge: a or b (a *whole*
    plane: every crossing is kept), or c (its crossing q_s), and then d crosses the
    plane on a line through q_s that cuts the corner (crosses its two edges). So on the
    other planes only the scope edges' crossings are kept, and the edges whose crossing
    lies on such a line (by its intercepts with the corner's sides in the corner's frame,
    with slack). The scan (:func:`_corner_candidates`, numba) skips boxes of edges the
    plane misses; the floats of the kept crossings are then computed as
    edges_crossing_planes computes them (a product of the planes' normals and the edges'
    ends, on blocks of two rows and two columns or more: BLAS gives each entry the same
    value whatever the block).

    Parameters
    ----------
    whole : (k,) bool
        Planes whose corner holds a scope edge.
    normal, point : (k, 3) float
        Unit normals, the corner vertex.
    ua, ub : (k, 3) float
        The corner's edges from its vertex.

    Returns
    -------
    plane, edge : (m,) int
    crossing : (m, 3) float
    rank : (m,) int
        Position of each crossing among its plane's in edges_crossing_planes's list
        (exact on whole planes; -1 elsewhere, see :func:`full_ranks`).
    """
    ge = scene.generator_edges
    ga, gb = edge_geometry(scene, ge)
    eps = scene.epsilon
    # boxes of consecutive edges in Morton order of their midpoints
    mid = 0.5 * (ga + gb)
    lo, hi = mid.min(axis=0), mid.max(axis=0)
    cell = np.clip(((mid - lo) / np.maximum(hi - lo, 1e-300) * 1023).astype(np.int64), 0, 1023)
    code = np.zeros(len(ge), np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((cell[:, axis] >> bit) & 1) << (3 * bit + axis)
    by_box = np.argsort(code, kind="stable")
    starts = np.arange(0, len(ge) + _BOX_EDGES, _BOX_EDGES).clip(max=len(ge))
    starts = np.unique(starts)
    ba, bb = ga[by_box], gb[by_box]
    both = np.minimum(ba, bb), np.maximum(ba, bb)
    box_lo = np.minimum.reduceat(both[0], starts[:-1], axis=0) if len(ge) else np.zeros((0, 3))
    box_hi = np.maximum.reduceat(both[1], starts[:-1], axis=0) if len(ge) else np.zeros((0, 3))
    # and boxes of _BOX_EDGES boxes: a plane skips most of the scene at once
    groups = np.arange(0, len(box_lo) + _BOX_EDGES, _BOX_EDGES).clip(max=len(box_lo))
    groups = np.unique(groups)
    group_lo = np.minimum.reduceat(box_lo, groups[:-1], axis=0) if len(box_lo) else np.zeros((0, 3))
    group_hi = np.maximum.reduceat(box_hi, groups[:-1], axis=0) if len(box_lo) else np.zeros((0, 3))
    is_scope = scope.edges[ge]
    scope_pos = np.flatnonzero(is_scope)
    args = (np.ascontiguousarray(normal), np.ascontiguousarray(point), np.ascontiguousarray(ua), np.ascontiguousarray(ub),
            whole.astype(np.bool_), ba, bb, by_box, starts, box_lo, box_hi, groups, group_lo, group_hi, ga[scope_pos], gb[scope_pos], is_scope, eps,
            _CORNER_SLACK)
    count = np.zeros(len(normal) + 1, np.int64)
    _corner_candidates(*args, count[1:], np.zeros(0, np.int64), np.zeros(1, np.int64))
    offsets = np.cumsum(count)
    out = np.empty(offsets[-1], np.int64)
    _corner_candidates(*args, count[1:], out, offsets)
    plane = np.repeat(np.arange(len(normal)), np.diff(offsets))
    # (per plane by edge position: edges_crossing_planes's order)
    key = plane * len(ge) + out
    key = np.unique(key)
    plane, pos = key // max(len(ge), 1), key % max(len(ge), 1)
    plane, pos, crossing = _exact_crossings(scene, normal, point, plane, pos, ga, gb)
    rank = np.full(len(plane), -1, np.int64)
    w = whole[plane]
    first = np.searchsorted(plane[w], plane[w])
    rank[w] = np.arange(np.count_nonzero(w)) - first
    return plane, ge[pos], crossing, rank


def _exact_crossings(scene, normal, point, plane, pos, ga, gb):
    """The (plane, edge position) pairs that cross strictly, with the crossing points, by
    the arithmetic of :func:`viscx.skeleton.arcs.pencils.edges_crossing_planes` (in
    blocks of planes against the union of their candidate edges)."""
    eps = scene.epsilon
    keep, points = np.zeros(len(plane), bool), np.zeros((len(plane), 3))
    bounds = np.searchsorted(plane, np.arange(0, len(normal) + 64, 64))
    for r0, r1 in zip(bounds[:-1], bounds[1:]):
        if r1 == r0:
            continue
        rows = np.unique(plane[r0:r1])
        cols = np.unique(pos[r0:r1])
        # (a single row or column takes BLAS's matrix-vector path, whose sums round otherwise)
        rows_m = rows if len(rows) > 1 else np.r_[rows, rows]
        cols_m = cols if len(cols) > 1 else np.r_[cols, cols]
        n = normal[rows_m]
        offset = np.einsum("ij,ij->i", n, point[rows_m])[:, None]
        h0 = n @ ga[cols_m].T - offset
        h1 = n @ gb[cols_m].T - offset
        i, j = np.searchsorted(rows, plane[r0:r1]), np.searchsorted(cols, pos[r0:r1])
        a0, a1 = h0[i, j], h1[i, j]
        ok = (a0 * a1 < 0) & (np.abs(a0) > eps) & (np.abs(a1) > eps)
        f = a0 / np.where(ok, a0 - a1, 1.0)
        e = pos[r0:r1]
        keep[r0:r1] = ok
        points[r0:r1] = ga[e] + f[:, None] * (gb[e] - ga[e])
    return plane[keep], pos[keep], points[keep]


@njit(cache=True, parallel=True)
def _corner_candidates(normal, point, ua, ub, whole, ba, bb, by_box, starts, box_lo, box_hi, groups, group_lo, group_hi,
                       sa, sb, is_scope, eps, slack, count, out, offsets):
    """:func:`planar_crossings`'s scan, plane by plane: the edge positions (into the
    generator edges) that may cross each plane strictly (ends beyond half epsilon on
    opposite sides) and, on planes not ``whole``, are scope edges or cross it on a line
    through a scope edge's crossing that cuts the corner (its intercepts with the lines
    of the corner's sides within [-slack, 1 + slack] of them, in the frame
    q = w + x ua + y ub). Boxes of edges (``starts``, edges ``ba``/``bb`` in box order,
    ``by_box`` their positions) the plane misses by half epsilon are skipped, and groups
    of boxes (``groups``) likewise. First call
    (``out`` empty): the count of each plane into ``count``; second: the positions into
    ``out`` from ``offsets``."""
    half = 0.5 * eps
    fill = out.shape[0] > 0
    for p in prange(normal.shape[0]):
        n0, n1, n2 = normal[p, 0], normal[p, 1], normal[p, 2]
        d = n0 * point[p, 0] + n1 * point[p, 1] + n2 * point[p, 2]
        # the corner frame: x = (r x ub).n / det, y = (ua x r).n / det
        c0 = ua[p, 1] * ub[p, 2] - ua[p, 2] * ub[p, 1]
        c1 = ua[p, 2] * ub[p, 0] - ua[p, 0] * ub[p, 2]
        c2 = ua[p, 0] * ub[p, 1] - ua[p, 1] * ub[p, 0]
        det = c0 * n0 + c1 * n1 + c2 * n2
        # ub x n and n x ua: x = r.(ub x n) / det, y = r.(n x ua) / det
        bx0, bx1, bx2 = ub[p, 1] * n2 - ub[p, 2] * n1, ub[p, 2] * n0 - ub[p, 0] * n2, ub[p, 0] * n1 - ub[p, 1] * n0
        ax0, ax1, ax2 = n1 * ua[p, 2] - n2 * ua[p, 1], n2 * ua[p, 0] - n0 * ua[p, 2], n0 * ua[p, 1] - n1 * ua[p, 0]
        w0, w1, w2 = point[p, 0], point[p, 1], point[p, 2]
        # the scope edges' crossings, in the frame
        ns = 0
        sx = np.empty(sa.shape[0])
        sy = np.empty(sa.shape[0])
        sq = np.empty((sa.shape[0], 3))
        for k in range(sa.shape[0]):
            h0 = n0 * sa[k, 0] + n1 * sa[k, 1] + n2 * sa[k, 2] - d
            h1 = n0 * sb[k, 0] + n1 * sb[k, 1] + n2 * sb[k, 2] - d
            if min(h0, h1) < -half and max(h0, h1) > half:
                f = h0 / (h0 - h1)
                q0 = sa[k, 0] + f * (sb[k, 0] - sa[k, 0]) - w0
                q1 = sa[k, 1] + f * (sb[k, 1] - sa[k, 1]) - w1
                q2 = sa[k, 2] + f * (sb[k, 2] - sa[k, 2]) - w2
                sq[ns, 0], sq[ns, 1], sq[ns, 2] = q0, q1, q2
                sx[ns] = (q0 * bx0 + q1 * bx1 + q2 * bx2) / det
                sy[ns] = (q0 * ax0 + q1 * ax1 + q2 * ax2) / det
                ns += 1
        k_out = 0
        if not (whole[p] or ns > 0):
            continue
        for g in range(groups.shape[0] - 1):
            if _box_side(n0, n1, n2, d, group_lo[g], group_hi[g], half):
                continue  # every end of the group's edges on one side
            for b in range(groups[g], groups[g + 1]):
                if _box_side(n0, n1, n2, d, box_lo[b], box_hi[b], half):
                    continue
                for k in range(starts[b], starts[b + 1]):
                    h0 = n0 * ba[k, 0] + n1 * ba[k, 1] + n2 * ba[k, 2] - d
                    h1 = n0 * bb[k, 0] + n1 * bb[k, 1] + n2 * bb[k, 2] - d
                    if not (min(h0, h1) < -half and max(h0, h1) > half):
                        continue
                    e = by_box[k]
                    take = whole[p] or is_scope[e]
                    if not take:
                        f = h0 / (h0 - h1)
                        q0 = ba[k, 0] + f * (bb[k, 0] - ba[k, 0]) - w0
                        q1 = ba[k, 1] + f * (bb[k, 1] - ba[k, 1]) - w1
                        q2 = ba[k, 2] + f * (bb[k, 2] - ba[k, 2]) - w2
                        x = (q0 * bx0 + q1 * bx1 + q2 * bx2) / det
                        y = (q0 * ax0 + q1 * ax1 + q2 * ax2) / det
                        for j in range(ns):
                            g0, g1, g2 = q0 - sq[j, 0], q1 - sq[j, 1], q2 - sq[j, 2]
                            if np.sqrt(g0 * g0 + g1 * g1 + g2 * g2) <= 4 * eps:
                                take = True
                                break
                            # intercepts of the line through the two points with y = 0 and x = 0
                            dx, dy = x - sx[j], y - sy[j]
                            if dy == 0.0 or dx == 0.0:
                                continue
                            alpha = sx[j] - sy[j] * dx / dy
                            beta = sy[j] - sx[j] * dy / dx
                            if -slack <= alpha <= 1 + slack and -slack <= beta <= 1 + slack:
                                take = True
                                break
                    if take:
                        if fill:
                            out[offsets[p] + k_out] = e
                        k_out += 1
        if not fill:
            count[p] = k_out


@njit(cache=True, inline="always")
def _box_side(n0, n1, n2, d, lo, hi, half):
    """Whether a box lies on one side of the plane n.x = d, farther than ``half``."""
    e0, e1, e2 = 0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1]), 0.5 * (hi[2] - lo[2])
    hc = n0 * (lo[0] + e0) + n1 * (lo[1] + e1) + n2 * (lo[2] + e2) - d
    r = abs(n0) * e0 + abs(n1) * e1 + abs(n2) * e2
    return hc + r <= half or hc - r >= -half


def full_build_order(scene, gens, plane, ci, cj, rank, edge, normal, point):
    """The order of a scoped :func:`viscx.skeleton.arcs.events.planar_events`'s rows (pairs
    ci < cj of :func:`planar_crossings`'s crossings on one plane, quadruples ``gens``)
    that picks, for a quadruple proposed by two rows, the full build's row: the full
    build orders its rows by (j - i, i), i and j the crossings' positions in the list of
    every plane's crossings, i.e. by (rank_j - rank_i, plane, rank_i). Ranks missing on
    planes not whole (-1) are found, for those rows only, on the plane's full list of
    crossings (:func:`viscx.skeleton.arcs.pencils.edges_crossing_planes`).

    Returns
    -------
    (r,) int
        A permutation of the rows.
    """
    from viscx.skeleton.arcs.pencils import edges_crossing_planes

    if len(gens) == 0:
        return np.zeros(0, np.int64)
    _, inverse, counts = np.unique(gens, axis=0, return_inverse=True, return_counts=True)
    twice = counts[inverse.reshape(-1)] > 1
    rank = rank.copy()
    need = np.unique(np.r_[ci[twice], cj[twice]])
    need = need[rank[need] < 0]
    if len(need):
        planes = np.unique(plane[need])
        fp, fe, _ = edges_crossing_planes(scene, normal[planes], point[planes])
        first = np.searchsorted(fp, np.arange(len(planes)))
        k = np.searchsorted(planes, plane[need])
        # (a plane's list ascends by edge: the generator edges ascend)
        n = len(scene.half_edges.edge_vertices)
        rank[need] = np.searchsorted(fp * n + fe, k * n + edge[need]) - first[k]
    return np.lexsort([rank[ci], plane[ci], rank[cj] - rank[ci]])
