"""V1: the arcs (1-cells) of the visibility complex, EEE and VE, and the VE half-cells.

An arc is a maximal connected 1-parameter family of maximal free segments with
the same three generator conditions (EEE: meets three edges; VE: passes through
a vertex and meets an edge) and the same blocker pair (docs/skeleton.md, "Arcs").

Construction (Durand et al.'s skeleton: arcs are found from the nodes on them)
------------------------------------------------------------------------------
1. *Events.* The V0 nodes, plus the *planar E4 events*: lines in the plane of
   two generator edges sharing a vertex (Durand's FEE events when that plane
   is a face's) that meet two more edges. V0 leaves those out (node condition
   5), yet they end arcs: an EEE arc whose line turns into a face's plane at
   one of its edges stops there (the edge stops being passed, or the blocker
   becomes the edge). They are validated by the same definition as nodes.
2. *Families through each event.* An E4 event lies on the four EEE families
   obtained by dropping one edge; a VEE node (v, e1, e2) on VE (v, e1),
   VE (v, e2) and EEE (e_v, e1, e2) for each generator edge e_v at v; a VV
   node (u, v) on VE (u, e) for each generator edge e at v and VE (v, e) for
   each one at u. Besides, every *same-plane* VE family (a vertex and an edge
   in the plane of a face touching the vertex) and every *pencil at a corner
   of a touched face* (:func:`contact_pencils`), which may hold no node.
3. *Parameters.* EEE (p, q, r) by the point s ∈ [0, 1] of the line on its
   parameter edge p (the line through a point of p meeting the lines of q and
   r is unique, seed 000 §4.2); VE (v, e) by the point s ∈ [0, 1] on e. Each
   family's events are sorted along s, together with the ends of its domain
   (s = 0, 1 and, for EEE, where the line reaches an endpoint of q or r: a
   linear-fractional map, inverted exactly), the *junctions* of its edges
   (another edge's vertex on the edge, or another edge crossing it: degenerate
   scenes) and, for same-plane VE families, the *coplanar events* and
   *crossings*: where the line passes a vertex or junction of its plane, or an
   edge crossing the plane (the degenerate events of lines lying in a plane).
4. *Arcs.* Between consecutive events the family is sampled (s at the middle
   of the interval and 20 epsilon from each end) and every sample judged by
   :func:`viscx.skeleton.nodes.maximal_free_segments`, the nodes' own
   definition with three generator conditions, and (VE) by its half-cells.
   Agreeing valid samples make one arc whose ends are the two events (arcs
   meeting at a crossing where nothing changes are joined). Disagreeing
   samples mean an event V0 leaves out (a degenerate one, dropped by
   epsilon-visibility): the interval is resampled and each change located by
   bisection, then (VE) moved onto the vertex, junction or crossing that
   explains it; the arc ends there with end type ``END_TRANSITION``.
5. *VE half-cells* (seed 000 §4.1): the blocker pairs of the two V-cells on
   either side of each VE arc, found by turning the arc's sample line about
   its vertex off the plane of the vertex and the edge by PROBE_ANGLE.
6. *XE arcs* (degenerate scenes): where two generator edges cross at a point X
   inside both, the lines through X meeting a third edge, built as VE families
   of X (:func:`crossing_arcs`); they bound EE-cells, not V-cells, and follow
   the VE arcs.

All per-sample work is numpy over flat arrays (numba where a loop is unavoidable).
Large scenes are built in chunks of consecutive families on threads
(:func:`build_arcs`, :mod:`viscx.parallel`): every stage decides an arc within its
family, so the arcs depend neither on the chunks nor on the thread count; the only
Python loops run over stages, chunks, bisection steps and small constant counts.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from viscx.arrays import expand_ranges, first_of_rows, unique_rows, unique_sorted
from viscx.geometry.lines import line_through_point_and_two_lines, plucker, segment_parameter
from viscx.geometry.polygon import plane_basis
from viscx.grid import bin_boxes
from viscx.memory import release_free_memory
from viscx.parallel import default_workers, map_chunks, row_chunks
from viscx.progress import bar
from viscx.scene.neighbourhood import faces_near
from viscx.skeleton.nodes import (
    BLOCK_EDGE,
    BLOCK_VERTEX,
    E4,
    VEE,
    VV,
    Nodes,
    _coplanar_partners,
    face_planes,
    first_triangles,
    maximal_free_segments,
    validate_candidates,
    vertex_ray_blockers,
)

# Arc kinds.
# XE: lines through a crossing point X of two generator edges a < b and meeting a third edge
# e, generators (a, e, b), stored after the VE arcs (docs/skeleton.md, "Crossing junctions").
EEE, VE, XE = 0, 1, 2
KIND_NAMES = {EEE: "EEE", VE: "VE", XE: "XE"}

# How an arc ends (one code per end).
END_NODE = 0  # at a V0 node (end_node is its id)
END_PLANAR = 1  # at a planar E4 event, not a V0 node (end_node indexes Arcs.planar)
END_ENDPOINT = 2  # the family reaches an edge's endpoint and V0 has no node there
END_TRANSITION = 3  # the samples change there without a known event (a dropped, degenerate event)
END_EDGE = 4  # a VE arc reaches the line along an edge of its vertex (end_node is that edge)
END_JUNCTION = 5  # the line meets one of its edges where another edge touches it (end_node: the vertex, or -1)
END_COPLANAR = 6  # a VE line lying in a face's plane passes a vertex or a junction of that plane (end_node: the vertex, or -1)
END_CROSSING = 7  # a VE line lying in a face's plane passes where an edge crosses the plane (end_node: that edge)
END_NAMES = {END_NODE: "node", END_PLANAR: "planar", END_ENDPOINT: "endpoint", END_TRANSITION: "transition", END_EDGE: "edge",
             END_JUNCTION: "junction", END_COPLANAR: "coplanar", END_CROSSING: "crossing"}
#: Which event wins where events of one family merge (lower first): nodes, planar events,
#: domain ends (an edge's endpoint is the event there, whatever lies on the line), junctions,
#: coplanar events, crossings.
_END_RANK = np.array([0, 1, 2, 6, 7, 3, 4, 5])

#: Where each interval between consecutive events is sampled (fractions of it; the first is
#: the arc's sample), besides 20 epsilon from each end. Between events the state is constant;
#: the end samples and the middle see one change the events miss anywhere in the interval.
#: Samples at 1/4 and 3/4 as well found no other change on 186 test scenes nor on the
#: random_boxes cities of 300 and 1000 polygons, and cost 40 % more (on an axis-aligned scene
#: they can land on an exactly degenerate line, s = 1/4 on integer coordinates).
SAMPLES = (0.5,)
#: Samples of an interval whose samples disagree, before bisection.
REFINE = 48
#: Bisection steps locating a change inside such an interval.
BISECT = 40
#: Intervals judged per batch in the first pass (3 samples each), samples per batch when refining.
CHUNK = 100_000
#: Angle (radians) by which a VE line is turned about its vertex, off the plane of the vertex
#: and the edge, to find the V-cells on either side (half-cells): far above the rounding of
#: directions (1e-16) and tangency's angle tolerance (1e-9), far below the thinnest cells of
#: the samples (about 1e-4 rad between the Cornell light and the ceiling, seen from a wall).
PROBE_ANGLE = 1e-8
#: A transition of a VE family is moved onto the event that explains it (its line through a
#: vertex, a junction or an edge's crossing with the family's plane) when that event lies
#: within this many epsilon along the family's edge.
SNAP = 20
#: Margin (radians) of the direction ranges that pair a same-plane VE family with the points
#: of its plane its lines can pass (the exact parameter test decides): far above rounding.
ANGLE_MARGIN = 1e-6

# slot layout of the family lines for maximal_free_segments (EEE: three edges; VE: vertex, edge)
_SLOT_IS_VERTEX = np.array([[False] * 4, [True, False, False, False]])
_SLOT_COUNT = np.array([3, 2])


@dataclass
class HalfCells:
    """VE half-cells (seed 000 eq. 1-3), one row per VE arc.

    Row i is the half-cell ``(up[i, 0], vertex, edge, down[i, 0], start, end)``
    running along the edge from ``a`` to ``b`` (its vertices, smaller id first)
    with its V-cell on the side of ``n = (b - a) × (vertex - a)``; the opposite
    half-cell is ``(up[i, 1], vertex, edge reversed, down[i, 1], end, start)``,
    its V-cell on the side of ``-n``. "Up" is the vertex's side of the line,
    "down" the edge's (downstream from vertex to edge). Blockers are
    ``(kind, id)`` pairs as in :class:`viscx.skeleton.nodes.Nodes`: a face, the
    sky, or the vertex itself when the surface separates the line's rays there
    (only ever in ``up``).

    Attributes
    ----------
    arc : (h,) int
        The VE arc.
    vertex, edge : (h,) int
    up_kind, down_kind : (h, 2) int8
        Side +n, side -n.
    up, down : (h, 2) int
    start, end : (h,) int
        Ends of the arc at s = interval[0] and interval[1]: node ids when
        ``start_type``/``end_type`` is END_NODE, else as :class:`Arcs` ``end_node``.
    start_type, end_type : (h,) int8
    """

    arc: np.ndarray
    vertex: np.ndarray
    edge: np.ndarray
    up_kind: np.ndarray
    up: np.ndarray
    down_kind: np.ndarray
    down: np.ndarray
    start: np.ndarray
    end: np.ndarray
    start_type: np.ndarray
    end_type: np.ndarray

    def __len__(self):
        return len(self.arc)


@dataclass
class Arcs:
    """Arcs as flat arrays, sorted by (kind, generators, interval).

    Attributes
    ----------
    kind : (n,) int8
        EEE or VE.
    generators : (n, 3) int
        EEE: (p, q, r), p the parameter edge, q < r; p is the smallest id whose
        two other edges are skew (so that the line through a point of p meeting
        them is unique). VE: (v, e, -1).
    interval : (n, 2) float
        Parameter interval s0 < s1: the point of the line on edge p (EEE) or e
        (VE), 0 at the edge's smaller vertex id, 1 at the larger.
    end_type : (n, 2) int8
        END_NODE, END_PLANAR, END_ENDPOINT, END_TRANSITION, END_EDGE, END_JUNCTION,
        END_COPLANAR or END_CROSSING at s0 and s1.
    end_node : (n, 2) int
        V0 node id (END_NODE), ``planar`` row (END_PLANAR), the edge (END_EDGE), the
        vertex lying on the edge (END_JUNCTION; -1 where two edges cross), the vertex
        passed (END_COPLANAR; -1 for a junction), the edge crossing the plane
        (END_CROSSING), else -1.
    blocker_kind : (n, 2) int8
    blocker : (n, 2) int
        Blocker pair (as in Nodes) of the arc's segments, in the family's
        orientation: from p's point towards q's (EEE), from v towards e (VE).
    parameter : (n,) float
        s of the sample segment.
    direction : (n, 3) float
        Unit direction of the sample line, in the family's orientation.
    ends : (n, 2, 3) float
        The sample's maximal free segment, back end then front end.
    generator_points : (n, 3, 3) float
        Where the sample line meets each generator.
    planar : Nodes
        The planar E4 events (kind E4, four edges) arcs end at.
    half_cells : HalfCells
        One per VE arc.
    """

    kind: np.ndarray
    generators: np.ndarray
    interval: np.ndarray
    end_type: np.ndarray
    end_node: np.ndarray
    blocker_kind: np.ndarray
    blocker: np.ndarray
    parameter: np.ndarray
    direction: np.ndarray
    ends: np.ndarray
    generator_points: np.ndarray
    planar: Nodes
    half_cells: HalfCells

    def __len__(self):
        return len(self.kind)

    def counts(self):
        """Number of arcs per kind name (XE only where the scene has crossing junctions)."""
        out = {name: int(np.count_nonzero(self.kind == k)) for k, name in KIND_NAMES.items()}
        if out["XE"] == 0:
            del out["XE"]
        return out


# --------------------------------------------------------------------------------------
# generator tables


def _vertex_edges(scene):
    """Generator edges at each vertex as CSR: (offsets (n + 1,), edges (k,))."""
    ge = scene.generator_edges
    ev = scene.half_edges.edge_vertices[ge]
    owner = np.concatenate([ev[:, 0], ev[:, 1]])
    edges = np.concatenate([ge, ge])
    order = np.lexsort([edges, owner])
    owner, edges = owner[order], edges[order]
    return np.searchsorted(owner, np.arange(scene.n_vertices + 1)), edges


def _edge_geometry(scene, edges):
    ev = scene.half_edges.edge_vertices[edges]
    return scene.vertices[ev[..., 0]], scene.vertices[ev[..., 1]]


def _skew(scene, e1, e2):
    """Whether pairs of edges lie on skew lines (no shared vertex, not coplanar, not parallel)."""
    ev = scene.half_edges.edge_vertices
    share = (ev[e1][:, :, None] == ev[e2][:, None, :]).any(axis=(1, 2))
    a1, b1 = _edge_geometry(scene, e1)
    a2, b2 = _edge_geometry(scene, e2)
    u1 = (b1 - a1) / np.linalg.norm(b1 - a1, axis=1, keepdims=True)
    u2 = (b2 - a2) / np.linalg.norm(b2 - a2, axis=1, keepdims=True)
    c = np.cross(u1, u2)
    size = np.linalg.norm(c, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        gap = np.abs(np.einsum("ij,ij->i", a2 - a1, c)) / size
    return ~share & (size > 1e-9) & (gap > scene.epsilon)


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
    cached = getattr(scene, "_viscx_junctions", None)
    if cached is not None:
        return cached
    scene._viscx_junctions, scene._viscx_crossings = _edge_junctions(scene)
    return scene._viscx_junctions


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
    edge_junctions(scene)
    return scene._viscx_crossings


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


def _edge_junctions(scene):
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
        ok = _skew(scene, t[rows, j], t[rows, k])
        rows = rows[ok]
        out[rows] = np.stack([t[rows, i], t[rows, j], t[rows, k]], axis=1)
        left[rows] = False
    return out


# --------------------------------------------------------------------------------------
# family lines


def family_lines(scene, kind, generators, s):
    """A point and a direction of the line of each family at parameter s.

    Parameters
    ----------
    kind : (m,) int
        EEE or VE.
    generators : (m, 3) int
        Canonical (see :class:`Arcs`).
    s : (m,) float

    Returns
    -------
    origins, directions : (m, 3) float
        Directions are zero where the line is undefined (EEE: the point lies on
        the line of q or r).
    """
    kind = np.asarray(kind)
    generators = np.asarray(generators, dtype=np.int64)
    s = np.asarray(s, dtype=np.float64)
    origins = np.zeros((len(kind), 3))
    directions = np.zeros((len(kind), 3))
    e = np.flatnonzero(kind == EEE)
    if len(e):
        a, b = _edge_geometry(scene, generators[e, 0])
        p = a + s[e, None] * (b - a)
        aq, bq = _edge_geometry(scene, generators[e, 1])
        ar, br = _edge_geometry(scene, generators[e, 2])
        origins[e] = p
        directions[e] = line_through_point_and_two_lines(p, plucker(aq, bq - aq), plucker(ar, br - ar))
    v = np.flatnonzero(kind == VE)
    if len(v):
        a, b = _edge_geometry(scene, generators[v, 1])
        origins[v] = scene.vertices[generators[v, 0]]
        directions[v] = a + s[v, None] * (b - a) - origins[v]
    x = np.flatnonzero(kind == XE)
    if len(x):
        cr = edge_crossings(scene)
        a, b = _edge_geometry(scene, generators[x, 1])
        origins[x] = cr.point[cr.find(generators[x, 0], generators[x, 2])]
        directions[x] = a + s[x, None] * (b - a) - origins[x]
    return origins, directions


@dataclass
class _Samples:
    valid: np.ndarray
    state: np.ndarray  # (m, 5) int: valid, blocker kinds and ids in the family's orientation
    direction: np.ndarray
    ends: np.ndarray
    generator_points: np.ndarray
    sides: np.ndarray = None  # (m, 8) int: the VE half-cells' pairs (sides=True), -1 elsewhere


def side_blockers(scene, vertex, edge, s):
    """Blocker pairs of the V-cells on both sides of VE lines (the half-cells, seed 000 §4.1).

    The line from the vertex to the edge's point s is turned about the vertex by
    PROBE_ANGLE towards +n and -n (n = (b - a) × (v - a)) and judged by
    :func:`viscx.skeleton.nodes.vertex_ray_blockers`.

    Returns
    -------
    up_kind, up, down_kind, down : (m, 2) int
        Side +n, side -n.
    """
    x = scene.vertices[vertex]
    a, b = _edge_geometry(scene, edge)
    d0 = a + np.asarray(s, dtype=np.float64)[:, None] * (b - a) - x
    d0 /= np.linalg.norm(d0, axis=1, keepdims=True)
    n = np.cross(b - a, x - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    m = len(vertex)
    d = np.concatenate([d0 + PROBE_ANGLE * n, d0 - PROBE_ANGLE * n])
    up_kind, up, down_kind, down, _ = vertex_ray_blockers(scene, np.concatenate([vertex, vertex]), d)
    return tuple(np.stack([q[:m], q[m:]], axis=1).astype(np.int64) for q in (up_kind, up, down_kind, down))


def judge_samples(scene, kind, generators, s, sides=False):
    """The maximal free segment of each family's line at s, in the family's orientation.

    Parameters
    ----------
    kind : (m,) int
    generators : (m, 3) int
    s : (m,) float
    sides : bool
        Also judge the half-cells of valid VE samples (:func:`side_blockers`).

    Returns
    -------
    valid : (m,) bool
    state : (m, 5) int
        (valid, back blocker kind, back blocker, front blocker kind, front
        blocker); -1 for the blockers of invalid lines. Two samples of a family
        are on one arc only if their states (and sides) agree.
    sides : (m, 8) int or None
        (up kind, up, down kind, down) on side +n, then on side -n, as in
        :class:`HalfCells` (valid VE samples; -1 elsewhere).
    direction : (m, 3) float
    ends : (m, 2, 3) float
    generator_points : (m, 3, 3) float
    """
    kind = np.asarray(kind, dtype=np.int64)
    generators = np.asarray(generators, dtype=np.int64)
    if np.any(kind == XE):  # as VE families of the crossing points (crossing_scene)
        xs, first = crossing_scene(scene)
        x = kind == XE
        cr = edge_crossings(scene)
        generators = generators.copy()
        generators[x] = np.stack([first + cr.find(generators[x, 0], generators[x, 2]), generators[x, 1],
                                  np.full(np.count_nonzero(x), -1)], axis=1)
        out = judge_samples(xs, np.where(x, VE, kind), generators, s, sides)
        out.generator_points[x, 2] = out.generator_points[x, 0]
        _blocked_at_crossings(out.state[:, [1, 3]], out.state[:, [2, 4]], generators[:, 0] - first, x, cr, out.state)
        return out
    o, d = family_lines(scene, kind, generators, s)
    undefined = np.linalg.norm(d, axis=1) == 0
    d[undefined] = (1.0, 0.0, 0.0)
    gens = np.concatenate([generators, np.full((len(kind), 1), -1)], axis=1)
    plane = pencil_plane_of(scene, kind, generators)
    seg = maximal_free_segments(scene, _SLOT_IS_VERTEX[kind], _SLOT_COUNT[kind], gens, o, d, plane_face=plane)
    valid = seg.valid & ~undefined
    valid &= _first_pencil_pair(scene, plane, generators, seg.ends, valid)
    gp = seg.generator_points[:, :3]
    # the family's orientation: from the first generator's point towards the second's
    flip = valid & (np.einsum("ij,ij->i", seg.direction, gp[:, 1] - gp[:, 0]) < 0)
    direction = np.where(flip[:, None], -seg.direction, seg.direction)
    ends = np.where(flip[:, None, None], seg.ends[:, ::-1], seg.ends)
    bk = np.where(flip[:, None], seg.blocker_kind[:, ::-1], seg.blocker_kind).astype(np.int64)
    b = np.where(flip[:, None], seg.blocker[:, ::-1], seg.blocker)
    state = np.stack([valid.astype(np.int64), bk[:, 0], b[:, 0], bk[:, 1], b[:, 1]], axis=1)
    state[~valid, 1:] = -1
    side = None
    if sides:  # the V-cells beside valid VE lines: an arc's half-cells must hold all along it
        side = np.full((len(kind), 8), -1, dtype=np.int64)
        rows = np.flatnonzero(valid & (kind == VE))
        if len(rows):
            side[rows] = np.concatenate(side_blockers(scene, generators[rows, 0], generators[rows, 1], s[rows]), axis=1)
    return _Samples(valid, state, direction, ends, gp, side)


# --------------------------------------------------------------------------------------
# events


def planar_events(scene):
    """The planar E4 events: lines in the plane of two generator edges sharing a vertex
    that meet two more generator edges, validated as nodes.

    V0 leaves them out (two of the four edges share an endpoint); they end EEE
    arcs where the line turns into a face's plane at one of its edges (Durand's
    FEE events) or into the plane of two edges of one vertex.

    Returns
    -------
    Nodes
        Kind E4, generators the four edges increasing, one line per quadruple.
    """
    eps = scene.epsilon
    vo, ve = _vertex_edges(scene)
    # pairs of generator edges at one vertex
    owner = np.repeat(np.arange(scene.n_vertices), np.diff(vo))
    i, j = _pairs_within_groups(owner)
    if len(i) == 0:
        return _no_events(scene)
    pa, pb, pw = ve[i], ve[j], owner[i]
    w = scene.vertices[pw]
    other = lambda e: np.where(scene.half_edges.edge_vertices[e, 0] == pw, scene.half_edges.edge_vertices[e, 1], scene.half_edges.edge_vertices[e, 0])  # noqa: E731
    ua, ub = scene.vertices[other(pa)] - w, scene.vertices[other(pb)] - w
    normal = np.cross(ua, ub)
    size = np.linalg.norm(normal, axis=1)
    keep = size > 1e-9 * np.linalg.norm(ua, axis=1) * np.linalg.norm(ub, axis=1)
    pa, pb, pw, w, normal = pa[keep], pb[keep], pw[keep], w[keep], normal[keep] / size[keep, None]

    # generator edges crossing each pair's plane strictly inside
    cp, ce, cq = _edges_crossing_planes(scene, normal, w)
    # (the pair's own edges and the edges at w do not cross the plane strictly)
    # the crossings in the corner's affine frame: q - w = x ua + y ub
    ua, ub, rel = ua[keep][cp], ub[keep][cp], cq - w[cp]
    n = normal[cp]
    det = np.einsum("ij,ij->i", np.cross(ua, ub), n)
    x = np.einsum("ij,ij->i", np.cross(rel, ub), n) / det
    y = np.einsum("ij,ij->i", np.cross(ua, rel), n) / det
    ci, cj = _corner_cutting_pairs(x, y, cp)
    if len(ci) == 0:
        return _no_events(scene)
    pair = cp[ci]
    origin, direction = cq[ci], cq[cj] - cq[ci]
    fine = np.linalg.norm(direction, axis=1) > eps
    # the line must cross both edges of the pair (cut the corner at w) before it is worth judging
    for e in (pa, pb):
        a, b = _edge_geometry(scene, e[pair])
        x, _ = segment_parameter(origin, np.where(fine[:, None], direction, 1.0), a, b)
        with np.errstate(invalid="ignore"):
            fine &= (x > 0) & (x < 1)
    ci, cj, pair, origin, direction = ci[fine], cj[fine], pair[fine], origin[fine], direction[fine]
    gens = np.sort(np.stack([pa[pair], pb[pair], ce[ci], ce[cj]], axis=1), axis=1)
    distinct = np.all(np.diff(gens, axis=1) > 0, axis=1)
    gens, origin, direction = gens[distinct], origin[distinct], direction[distinct]
    # one line per quadruple (two adjacent pairs can propose it)
    first = first_of_rows(gens)
    events = validate_candidates(scene, np.full(len(first), E4, np.int8), gens[first], origin[first], direction[first])
    first = first_of_rows(events.generators)
    return Nodes(**{k: getattr(events, k)[first] for k in events.__dataclass_fields__})


def _edges_crossing_planes(scene, normal, point):
    """The generator edges crossing each plane strictly (both ends farther than epsilon,
    on opposite sides), in chunks of planes × edges.

    Parameters
    ----------
    normal : (k, 3) float
        Unit normals.
    point : (k, 3) float
        A point of each plane.

    Returns
    -------
    plane : (m,) int
    edge : (m,) int
    crossing : (m, 3) float
        Where the edge crosses the plane.
    """
    ge = scene.generator_edges
    ga, gb = _edge_geometry(scene, ge)
    eps = scene.epsilon
    planes, edges, points = [np.empty(0, np.int64)], [np.empty(0, np.int64)], [np.empty((0, 3))]
    chunk = max(1, (1 << 22) // max(1, len(ge)))
    for lo in range(0, len(normal), chunk):
        sl = slice(lo, lo + chunk)
        h0 = normal[sl] @ ga.T - np.einsum("ij,ij->i", normal[sl], point[sl])[:, None]
        h1 = normal[sl] @ gb.T - np.einsum("ij,ij->i", normal[sl], point[sl])[:, None]
        i, j = np.nonzero((h0 * h1 < 0) & (np.abs(h0) > eps) & (np.abs(h1) > eps))
        f = h0[i, j] / (h0[i, j] - h1[i, j])
        planes.append(i + lo)
        edges.append(ge[j])
        points.append(ga[j] + f[:, None] * (gb[j] - ga[j]))
    return np.concatenate(planes), np.concatenate(edges), np.concatenate(points)


def _corner_cutting_pairs(x, y, group, slack=1e-9):
    """Index pairs i < j within one group of points whose line may cross both open sides
    of the corner at the origin, (0, 0)-(1, 0) and (0, 0)-(0, 1): a superset of those
    whose line crosses them farther than ``slack`` from their ends (nearer, the line is
    degenerate and validation, which wants epsilon, rejects it), in the order of
    :func:`_pairs_within_groups`.

    Output-sensitive, by duality: the line through (α, 0) and (0, β) holds P = (x, y)
    iff x a + y b = 1 with (a, b) = (1/α, 1/β), so the lines crossing both sides are
    the points of the region R = {a > 1, b > 1}, each point P is a line L_P, and two
    points lie on a corner-cutting line iff L_P and L_Q meet inside R. R is convex:
    two lines meet inside it iff their chords' ends interleave along its boundary,
    walked from the corner (1, 1) along b = 1 (τ = 1 - α), over the line at infinity
    (τ = 1 + |x| / (|x| + |y|), the chord's direction there) and back along a = 1
    (τ = 2 + β). Sorting the chords by their first end, each chord's partners are
    those starting within it and ending beyond it.

    Parameters
    ----------
    x, y : (k,) float
        The points in the corner's affine frame.
    group : (k,) int
        Sorted; pairs are formed within a group only.

    Returns
    -------
    i, j : (p,) int
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = x / (1 - y)  # where L_P meets b = 1
        beta = y / (1 - x)  # and a = 1
        at_inf = 1 + np.abs(x) / (np.abs(x) + np.abs(y))
    loose = lambda t: np.isfinite(t) & (t >= -slack) & (t <= 1 + slack)  # noqa: E731
    margin = 10 * slack
    ends = np.stack([np.where(loose(alpha), 1 - alpha, np.nan), np.where(loose(beta), 2 + beta, np.nan),
                     np.where(x * y <= 0, at_inf, np.nan)], axis=1)
    # a line through the corner (1, 1) meets both sides there: one end (τ = 0, also 3)
    ends[(ends[:, 0] <= margin) & (ends[:, 1] >= 3 - margin), 1] = np.nan
    has = np.sum(np.isfinite(ends), axis=1) >= 2  # the other lines miss R
    idx = np.flatnonzero(has)
    s0, s1 = np.nanmin(ends[idx], axis=1), np.nanmax(ends[idx], axis=1)
    order = np.lexsort([s0, group[idx]])
    idx, s0, s1 = idx[order], s0[order], s1[order]
    key = group[idx] * 4.0 + s0  # τ < 3 < 4: one sorted key per group
    lo = np.searchsorted(key, group[idx] * 4.0 + s0 - margin, "left")
    hi = np.searchsorted(key, group[idx] * 4.0 + s1 + margin, "right")
    count = _interleaving(idx, s1, lo, hi, margin, np.zeros((0, 2), np.int64))
    pairs = np.empty((count, 2), np.int64)
    _interleaving(idx, s1, lo, hi, margin, pairs)
    pairs, _ = unique_rows(pairs)
    i, j = pairs[:, 0], pairs[:, 1]
    order = np.lexsort([i, j - i])
    return i[order], j[order]


@njit(cache=True, nogil=True)
def _interleaving(idx, s1, lo, hi, margin, out):
    """(min, max) of idx[a], idx[b] for every chord a and chord b starting within it
    (lo[a] <= b < hi[a], b != a) that ends beyond it (s1[b] >= s1[a] - margin), into
    ``out`` when it has room: how many there are."""
    k = 0
    for a in range(len(lo)):
        for b in range(lo[a], hi[a]):
            if b != a and s1[b] >= s1[a] - margin:
                if k < len(out):
                    out[k, 0], out[k, 1] = min(idx[a], idx[b]), max(idx[a], idx[b])
                k += 1
    return k


def _pairs_within_groups(group):
    """All index pairs i < j with group[i] == group[j], for a sorted group array."""
    group = np.asarray(group)
    ii, jj = [], []
    k = 1
    while k < len(group):
        i = np.flatnonzero(group[k:] == group[:-k])
        if len(i) == 0:
            break  # sorted: no longer runs
        ii.append(i)
        jj.append(i + k)
        k += 1
    if not ii:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(ii), np.concatenate(jj)


def _no_events(scene):
    return validate_candidates(scene, np.zeros(0, np.int8), np.zeros((0, 4), np.int64), np.zeros((0, 3)), np.zeros((0, 3)))


def _incidences(scene, events):
    """The families each event lies on.

    Returns
    -------
    kind : (k,) int
    generators : (k, 3) int
        Canonical family generators.
    event : (k,) int
        Row of ``events``.
    """
    vo, ve = _vertex_edges(scene)
    is_gen_vertex = np.diff(vo) > 0
    kinds, gens, rows = [], [], []

    e4 = np.flatnonzero(events.kind == E4)
    for drop in range(4):
        keep = [j for j in range(4) if j != drop]
        kinds.append(np.full(len(e4), EEE))
        gens.append(canonical_eee(scene, events.generators[e4][:, keep]))
        rows.append(e4)

    vee = np.flatnonzero(events.kind == VEE)
    g = events.generators[vee]
    for slot in (1, 2):
        kinds.append(np.full(len(vee), VE))
        gens.append(np.stack([g[:, 0], g[:, slot], np.full(len(vee), -1)], axis=1))
        rows.append(vee)
    # EEE (e_v, e1, e2) for every generator edge e_v at v
    r, k = expand_ranges(vo[g[:, 0]], np.diff(vo)[g[:, 0]])
    e_v = ve[k]
    kinds.append(np.full(len(r), EEE))
    gens.append(canonical_eee(scene, np.stack([e_v, g[r, 1], g[r, 2]], axis=1)))
    rows.append(vee[r])

    # a VEE line lying in the plane of two edges at v (v and e1 on one face) also ends the
    # pencil of lines in that plane through the other edge's point: EEE (e_v, e_v', e2)
    owner = np.repeat(np.arange(scene.n_vertices), np.diff(vo))
    pi, pj = _pairs_within_groups(owner)
    pair_offsets = np.searchsorted(owner[pi], np.arange(scene.n_vertices + 1))
    r, pr = expand_ranges(pair_offsets[g[:, 0]], np.diff(pair_offsets)[g[:, 0]])
    ea, eb = ve[pi[pr]], ve[pj[pr]]
    x = scene.vertices[g[r, 0]]
    a1, b1 = _edge_geometry(scene, ea)
    a2, b2 = _edge_geometry(scene, eb)
    normal = np.cross(b1 - a1, b2 - a2)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    in_plane = np.abs(np.einsum("ij,ij->i", normal, events.direction[vee[r]])) <= 1e-9
    for held, free in ((1, 2), (2, 1)):
        ah, bh = _edge_geometry(scene, g[r, held])
        holds = in_plane.copy()
        for q in (ah, bh):
            holds &= np.abs(np.einsum("ij,ij->i", normal, q - x)) <= scene.epsilon
        kinds.append(np.full(np.count_nonzero(holds), EEE))
        gens.append(canonical_eee(scene, np.stack([ea[holds], eb[holds], g[r[holds], free]], axis=1)))
        rows.append(vee[r[holds]])

    vv = np.flatnonzero(events.kind == VV)
    g = events.generators[vv]
    for own, other in ((0, 1), (1, 0)):
        r, k = expand_ranges(vo[g[:, other]], np.diff(vo)[g[:, other]])
        e = ve[k]
        kinds.append(np.full(len(r), VE))
        gens.append(np.stack([g[r, own], e, np.full(len(r), -1)], axis=1))
        rows.append(vv[r])

    kind = np.concatenate(kinds)
    gens = np.concatenate(gens).reshape(-1, 3)
    rows = np.concatenate(rows)
    ok = gens[:, 0] >= 0
    ok[kind == VE] &= is_gen_vertex[gens[kind == VE, 0]]
    return kind[ok], gens[ok], rows[ok]


def _same_plane_ve(scene):
    """(v, e, -1) for every generator vertex v and generator edge e lying in the plane of a
    face touching v, e not at v and v not on e's line.

    Such families hold no node in general position when the face is a triangle (they
    run between the lines along the vertex's two edges), and in degenerate scenes
    their arcs often end only at dropped events (a block's corner on the floor and
    another block's bottom edge: every line of the family lies on the floor). Contacts
    are geometric (within the weld tolerance, as tangency's): v touches the face (a
    block's bottom corner touches the floor) and e bounds a face of the plane or lies
    on one (a block's bottom edge on the floor: its ends and middle touch it).
    """
    he = scene.half_edges
    tol = scene.weld_tolerance
    plane = face_planes(scene)
    gv, ge = scene.generator_vertices, scene.generator_edges
    # (vertex, plane): the planes of the faces touching each generator vertex
    pos, face = faces_near(scene, scene.vertices[gv], tol)
    vp = np.unique(np.stack([gv[pos], plane[face]], axis=1), axis=0).reshape(-1, 2)
    # (edge, plane): the planes of its own faces, and of faces it lies on
    own = he.edge_is_generator[he.edge]
    ep = [np.stack([he.edge[own], plane[he.face[own]]], axis=1)]
    ev = he.edge_vertices[ge]
    a, b = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
    for point in (a, 0.5 * (a + b), b):
        pos, face = faces_near(scene, point, tol)
        n, off = scene.face_normal[face], scene.face_offset[face]
        inside = (np.abs(np.einsum("ij,ij->i", n, a[pos]) - off) <= tol) & (np.abs(np.einsum("ij,ij->i", n, b[pos]) - off) <= tol)
        ep.append(np.stack([ge[pos[inside]], plane[face[inside]]], axis=1))
    ep = np.unique(np.concatenate(ep), axis=0).reshape(-1, 2)
    # join on the plane
    order = np.argsort(ep[:, 1], kind="stable")
    first = np.searchsorted(ep[order, 1], vp[:, 1], "left")
    r, k = expand_ranges(first, np.searchsorted(ep[order, 1], vp[:, 1], "right") - first)
    k = order[k]
    v, e = vp[r, 0], ep[k, 0]
    ends = he.edge_vertices[e]
    x, a, b = scene.vertices[v], scene.vertices[ends[:, 0]], scene.vertices[ends[:, 1]]
    u = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    off_line = np.linalg.norm(np.cross(x - a, u), axis=1) > tol
    ok = (ends != v[:, None]).all(axis=1) & off_line
    fam = np.unique(np.stack([v[ok], e[ok], ep[k[ok], 1]], axis=1), axis=0).reshape(-1, 3)
    return fam[:, :2], fam[:, 2], vp, ep


def _touched_faces(scene):
    """(f,) bool: faces whose plane holds another face over the face's bounding box
    (:func:`viscx.skeleton.nodes._coplanar_partners`) or, anywhere, a generator vertex not
    on the face's outline (within the weld tolerance, as tangency's contacts)."""
    off, partner, _, _ = _coplanar_partners(scene)
    touched = np.zeros(scene.n_faces, dtype=bool)
    touched[np.diff(off) > 0] = True
    touched[partner] = True
    he = scene.half_edges
    gv = scene.generator_vertices
    x = scene.vertices[gv]
    tol = scene.weld_tolerance
    own = np.unique(he.face.astype(np.int64) * scene.n_vertices + he.start)
    chunk = max(1, (1 << 22) // max(1, len(gv)))
    for first in range(0, scene.n_faces, chunk):
        f = np.arange(first, min(first + chunk, scene.n_faces))
        near = np.abs(x @ scene.face_normal[f].T - scene.face_offset[f]) <= tol  # (v, f)
        v, k = np.nonzero(near)
        foreign = ~np.isin(f[k] * scene.n_vertices + gv[v], own)
        touched[f[k[foreign]]] = True
    return touched


def pencil_planes(scene):
    """The planes of touched faces (:func:`_touched_faces`) that a generator edge crosses,
    and which generator edges lie in each or cross it (cached on the scene).

    A line lying in such a plane P through the point H where an edge crosses it (a pencil
    of lines in P through H, :func:`contact_pencils`) passes the faces beside P that it
    touches on their outline (:func:`viscx.skeleton.nodes.first_triangles`): with two
    blocks touching face to face, the pencil across their contact crosses the outlines of
    both contact faces, four edges besides H's, and would be blocked by whichever two of
    them are not its generators (docs/queries.md, limitation 6).

    Returns
    -------
    face : (k,) int
        A face of each plane, by plane id (:func:`viscx.skeleton.nodes.face_planes`).
    role : (k, e) int8
        Per plane and edge: 1 a generator edge of a touched face of the plane (listed in
        ``incidence``), 2 a generator edge crossing the plane strictly, 0 otherwise.
    incidence : (m, 3) int
        (plane, region, edge), sorted: the generator edges of the plane's touched faces
        lying in it, by *region*, the touched faces of the plane joined across the flat
        edges they share (a face split in two of one plane), named by its lowest face id.
    """
    cached = getattr(scene, "_viscx_pencil_planes", None)
    if cached is not None:
        return cached
    he = scene.half_edges
    touched = np.flatnonzero(_touched_faces(scene))
    plane_of = face_planes(scene)
    _, first = np.unique(plane_of[touched], return_index=True)
    face = touched[first]  # one per plane, by plane id
    # planes a generator edge crosses strictly (in chunks of planes × edges)
    k, crossing, _ = _edges_crossing_planes(scene, scene.face_normal[face],
                                            scene.face_normal[face] * scene.face_offset[face, None])
    keep = np.unique(k)
    face = face[keep]
    role = np.zeros((len(face), len(he.edge_vertices)), dtype=np.int8)
    role[np.searchsorted(keep, k), crossing] = 2
    # the touched faces of each plane, joined into regions across flat edges
    is_touched = np.zeros(scene.n_faces, dtype=bool)
    is_touched[touched] = True
    opp_face = np.where(he.opp >= 0, he.face[np.maximum(he.opp, 0)], -1)
    flat = np.flatnonzero(is_touched[he.face] & (he.opp >= 0) & ~he.edge_is_generator[he.edge])
    flat = flat[is_touched[opp_face[flat]] & (plane_of[opp_face[flat]] == plane_of[he.face[flat]])]
    n = scene.n_faces
    _, label = connected_components(coo_matrix((np.ones(len(flat)), (he.face[flat], opp_face[flat])), shape=(n, n)),
                                    directed=False)
    lowest = np.full(n, n)
    np.minimum.at(lowest, label, np.arange(n))
    region = lowest[label]  # named by its lowest face id
    h = np.flatnonzero(is_touched[he.face] & he.edge_is_generator[he.edge]) if len(face) else np.zeros(0, np.int64)
    k = np.minimum(np.searchsorted(plane_of[face], plane_of[he.face[h]]), max(len(face) - 1, 0))
    same = plane_of[face[k]] == plane_of[he.face[h]] if len(h) else np.zeros(0, bool)
    h, k = h[same], k[same]
    incidence = np.unique(np.stack([k, region[he.face[h]], he.edge[h]], axis=1), axis=0).reshape(-1, 3)
    role[incidence[:, 0], incidence[:, 2]] = 1
    scene._viscx_pencil_planes = face, role, incidence
    return scene._viscx_pencil_planes


def pencil_plane_of(scene, kind, generators):
    """(m,) int: for EEE families whose lines lie in a plane of :func:`pencil_planes` (two
    generator edges in it, the third crossing it), a face of that plane; -1 elsewhere.

    Parameters
    ----------
    kind : (m,) int
    generators : (m, 3) int
    """
    out = np.full(len(kind), -1, dtype=np.int64)
    face, role, _ = pencil_planes(scene)
    rows = np.flatnonzero(np.asarray(kind) == EEE)
    for k in range(len(face)):  # few planes: a touched plane that an edge crosses
        r = role[k][np.asarray(generators)[rows]]
        hit = rows[(np.count_nonzero(r == 1, axis=1) == 2) & (np.count_nonzero(r == 2, axis=1) == 1)]
        out[hit[out[hit] < 0]] = face[k]
    return out


def pencil_crossings(scene, plane_face, ends):
    """The edges of touched faces that the segments of pencils' lines cross.

    A line of a pencil of a touched plane (``plane_face`` >= 0, :func:`pencil_plane_of`)
    passes the faces beside its plane (:func:`pencil_planes`) and crosses, strictly inside
    (as node condition 5) and within its segment, two edges of each touched face of the
    plane it runs across.

    Parameters
    ----------
    plane_face : (m,) int
    ends : (m, 2, 3) float
        Each line's maximal free segment.

    Returns
    -------
    row : (c,) int
        Ascending.
    region, edge : (c,) int
        The crossed edge and its region of touched faces (:func:`pencil_planes`); by
        (row, region, edge).
    """
    face, role, incidence = pencil_planes(scene)
    eps = scene.epsilon
    out = [np.empty((0, 3), dtype=np.int64)]
    for k, pf in enumerate(face):
        inc = incidence[incidence[:, 0] == k]  # sorted by (region, edge)
        every = np.flatnonzero(plane_face == pf)
        if not len(every) or not len(inc):
            continue
        step = max(1, (1 << 20) // len(inc))  # rows × edges at a time: bounded temporaries
        for lo in range(0, len(every), step):
            out.append(_crossed(scene, every[lo:lo + step], inc, ends, eps))
    out = np.concatenate(out)
    out = out[np.lexsort([out[:, 2], out[:, 1], out[:, 0]])]
    return out[:, 0], out[:, 1], out[:, 2]


def _crossed(scene, rows, inc, ends, eps):
    """(c, 3) int: (row, region, edge) of :func:`pencil_crossings` for some rows of one plane."""
    r, j = (x.reshape(-1) for x in np.meshgrid(np.arange(len(rows)), np.arange(len(inc)), indexing="ij"))
    p0, p1 = ends[rows[r], 0], ends[rows[r], 1]
    a, b = _edge_geometry(scene, inc[j, 2])
    x, dist = segment_parameter(p0, p1 - p0, a, b)
    length = np.linalg.norm(b - a, axis=1)
    q = a + np.nan_to_num(x)[:, None] * (b - a)
    span = np.maximum(np.linalg.norm(p1 - p0, axis=1), 1e-300)
    t = np.einsum("ij,ij->i", q - p0, p1 - p0) / span  # along the segment; its ends may be on the edges
    with np.errstate(invalid="ignore"):
        crossed = (dist <= eps) & (x * length > eps) & ((1 - x) * length > eps) & (t >= -eps) & (t <= span + eps)
    return np.stack([rows[r[crossed]], inc[j[crossed], 1], inc[j[crossed], 2]], axis=1)


def _first_pencil_pair(scene, plane_face, generators, ends, valid):
    """(m,) bool: False for a pencil's line (``plane_face`` >= 0) whose two generator edges
    in the plane are not the crossed edges of the first region of touched faces it crosses
    (:func:`pencil_planes`); True elsewhere.

    Passing the faces beside the plane, one line of the pencil across several touched faces
    of the plane crosses two edges of each (:func:`pencil_crossings`), and every pair of
    them that node condition (4) admits (two edges of one face, or of faces of that plane)
    would give it an arc: one segment, several arcs over it. The first region it crosses
    (lowest face id) names it, by its two lowest crossed edges (a family of
    :func:`contact_pencils`); its arcs end where the crossed edges change
    (:func:`_pencil_events`). A line crossing no region twice keeps its arcs."""
    ok = np.ones(len(plane_face), dtype=bool)
    pencil = valid & (plane_face >= 0)
    if not pencil.any():
        return ok
    row, face, edge = pencil_crossings(scene, np.where(pencil, plane_face, -1), ends)
    # each row's first (row, face) group of two crossed edges or more: its first two edges
    key = np.stack([row, face], axis=1)
    start = np.flatnonzero(np.r_[True, np.any(key[1:] != key[:-1], axis=1)])
    count = np.diff(np.r_[start, len(row)])
    start, count = start[count >= 2], count[count >= 2]
    first = start[np.r_[True, row[start[1:]] != row[start[:-1]]]] if len(start) else start
    r = row[first]
    big = np.iinfo(np.int64).max
    g = generators[r]
    face_of_plane, role, _ = pencil_planes(scene)
    by_face = np.argsort(face_of_plane)
    k = by_face[np.searchsorted(face_of_plane[by_face], plane_face[r])]
    own = np.sort(np.where(role[k[:, None], g] == 1, g, big), axis=1)[:, :2]
    # (a line crossing no region's outline twice, within its segment, keeps its arcs)
    ok[r] = (edge[first] == own[:, 0]) & (edge[first + 1] == own[:, 1])
    return ok


def _pencil_events(scene, fkind, fgens):
    """The events of pencil families of touched planes (:func:`pencil_plane_of`): the
    lines through H and each vertex of the plane's touched faces or edge crossing lying
    in the plane P.

    Such a line passes its faces beside P without a stop (:func:`pencil_planes`), so the
    samples do not see where it starts or stops touching another face's outline in P
    (the pencil entering the crack between two blocks touching face to face, where its
    segments change nothing on a receiver: docs/queries.md, "Cracks"). The lines through
    the corners of P's outlines and their crossings are where that can happen; arcs end
    there (END_COPLANAR, the vertex or -1).

    Returns
    -------
    family, s, end_type, index : (k,) arrays
    """
    plane = pencil_plane_of(scene, fkind, fgens)
    fams, ss, idx = [np.empty(0, np.int64)], [np.empty(0)], [np.empty(0, np.int64)]
    face, role, incidence = pencil_planes(scene)
    tol = scene.weld_tolerance
    cr = edge_crossings(scene)
    for k, pf in enumerate(face):
        rows = np.flatnonzero(plane == pf)
        if not len(rows):
            continue
        n, off = scene.face_normal[pf], scene.face_offset[pf]
        vert = np.unique(scene.half_edges.edge_vertices[incidence[incidence[:, 0] == k, 2]])
        crossing = np.abs(cr.point @ n - off) <= tol
        w = np.concatenate([scene.vertices[vert], cr.point[crossing]])
        which = np.r_[vert, np.full(np.count_nonzero(crossing), -1)]
        g = fgens[rows]
        line = g[role[k][g] == 2]  # the one generator crossing P, row by row
        la, lb = _edge_geometry(scene, line)
        h0, h1 = la @ n - off, lb @ n - off
        hit = la + (h0 / (h0 - h1))[:, None] * (lb - la)  # H
        r, j = (x.reshape(-1) for x in np.meshgrid(np.arange(len(rows)), np.arange(len(w)), indexing="ij"))
        a, b = _edge_geometry(scene, g[r, 0])
        sv, _ = segment_parameter(hit[r], w[j] - hit[r], a, b)
        with np.errstate(invalid="ignore"):
            inside = np.isfinite(sv) & (sv > 0) & (sv < 1)
        fams.append(rows[r[inside]])
        ss.append(sv[inside])
        idx.append(which[j[inside]])
    family = np.concatenate(fams)
    return family, np.concatenate(ss), np.full(len(family), END_COPLANAR), np.concatenate(idx)


def contact_pencils(scene):
    """EEE families (l, e1, e2) of the pencils of touched planes (:func:`pencil_planes`):
    e1, e2 two generator edges of touched faces (another face or a foreign vertex in their
    plane: two blocks touching face to face, a tetrahedron's corner on a box's side plane)
    lying in their plane P, l a generator edge crossing P strictly at H, where some line of
    P through H crosses both open edges.

    Such a family is the pencil of lines in P through H that cross e1 and e2 (lines
    meeting two coplanar edges lie in their plane or pass through their lines' common
    point; through a point of l they lie in P only at H). Its lines graze P's faces, and
    where they leave one (H seen across its corner) the visible part of l from a receiver
    point turns from one of its edges to the other. A lone face's pencil ends at nodes
    (VEE: lines through H and a vertex of the face), but with a foreign face or vertex in
    P those lines can pass the foreign vertex while grazing the face, which node
    condition (N2) rejects: the family may hold no node, like a same-plane VE family, and
    is seeded. Every pair of edges of one region (touched faces of P joined across flat
    edges) is seeded, not just a face's corners: a line across several regions crosses
    two edges of each, and its arcs are those of the first region's pair
    (:func:`_first_pencil_pair`), which must be a family. (Two touching boxes, a box
    side with a tetrahedron's vertex in its plane: without them receiver regions in front
    of the face held both edges' labels, docs/queries.md.)

    Seen from H, edge e spans the directions of an interval of lines [a, a + w) modulo π
    (w < π); two edges' lines through H meet both open edges where their intervals
    overlap by more than an angle of 1e-9.

    Returns
    -------
    (m, 3) int
        Canonical EEE generators (:func:`canonical_eee`), unique, sorted.
    """
    face, role, incidence = pencil_planes(scene)
    gens = [np.empty((0, 3), dtype=np.int64)]
    for k, pf in enumerate(face):
        n, off = scene.face_normal[pf], scene.face_offset[pf]
        u, v = plane_basis(n)
        inc = incidence[incidence[:, 0] == k]
        ia, ib = _pairs_within_groups(inc[:, 1])  # two edges of one face
        if not len(ia):
            continue
        inside = inc[:, 2]
        a, b = _edge_geometry(scene, inside)
        for line in np.flatnonzero(role[k] == 2):
            la, lb = _edge_geometry(scene, np.array([line]))
            h0, h1 = la[0] @ n - off, lb[0] @ n - off
            hit = la[0] + h0 / (h0 - h1) * (lb[0] - la[0])
            ta = np.arctan2((a - hit) @ v, (a - hit) @ u)
            tb = np.arctan2((b - hit) @ v, (b - hit) @ u)
            sweep = np.mod(tb - ta + np.pi, 2 * np.pi) - np.pi  # signed, |sweep| < π off the edge's line
            start = np.mod(np.where(sweep >= 0, ta, tb), np.pi)
            width = np.abs(sweep)
            d = np.mod(start[ib] - start[ia], np.pi)
            wa, wb = width[ia], width[ib]
            overlap = (np.maximum(0.0, np.minimum(wa, d + wb) - d)
                       + np.maximum(0.0, np.minimum(wa, d - np.pi + wb) - np.maximum(0.0, d - np.pi)))
            ok = overlap > 1e-9
            gens.append(np.stack([np.full(np.count_nonzero(ok), line), inside[ia[ok]], inside[ib[ok]]], axis=1))
    gens = canonical_eee(scene, np.concatenate(gens))
    gens = gens[gens[:, 0] >= 0]
    return np.unique(gens, axis=0).reshape(-1, 3)


@dataclass
class _PlanePoints:
    """The points of each plane where lines lying in it can change (:func:`_plane_points`),
    sorted by direction around each (vertex, plane) row of ``vp``.

    Attributes
    ----------
    vp : (k, 2) int
        (vertex, plane) rows, sorted and unique.
    point : (p, 3) float
        The points; ``vertex`` (p,) names each: the vertex, -1 for a junction, -2 - edge
        for an edge crossing the plane; ``rank`` (p,) is its position in plane order,
        ``order`` (p,) the inverse permutation.
    key : (j,) float
        ``row * 4 + angle`` of every (vp row, point of its plane) pair, sorted (angle
        mod π in [0, π) of the line from the row's vertex to the point), with ``point_of``
        (j,) the point.
    """

    vp: np.ndarray
    point: np.ndarray
    vertex: np.ndarray
    rank: np.ndarray
    order: np.ndarray
    key: np.ndarray
    point_of: np.ndarray


def _plane_points(scene, planes, vp, ep, junctions):
    """The points of the given planes (:func:`face_planes` ids) at which the lines of a
    same-plane VE family can change: a generator vertex touching the plane, a junction of
    an edge lying in it, a generator edge crossing it; sorted by direction around every
    (vertex, plane) row of ``vp`` (:class:`_PlanePoints`), for :func:`_coplanar_join`."""
    tol = scene.weld_tolerance
    # the points of each plane: (plane, point, vertex)
    pts_plane = [vp[:, 1]]
    pts = [scene.vertices[vp[:, 0]]]
    pts_vertex = [vp[:, 0]]  # the vertex, -1 for a junction, -2 - edge for a crossing
    lo = np.searchsorted(ep[:, 0], junctions.edge, "left")  # ep is sorted by edge
    r, k = expand_ranges(lo, np.searchsorted(ep[:, 0], junctions.edge, "right") - lo)
    a, b = _edge_geometry(scene, junctions.edge[r])
    pts_plane.append(ep[k, 1])
    pts.append(a + junctions.s[r, None] * (b - a))
    pts_vertex.append(junctions.vertex[r])
    # generator edges crossing each plane strictly (chunked: planes × edges)
    plane_of_face = face_planes(scene)
    face_of = np.zeros(plane_of_face.max() + 1, np.int64)
    face_of[plane_of_face] = np.arange(scene.n_faces)
    normal, offset = scene.face_normal[face_of[planes]], scene.face_offset[face_of[planes]]
    ge = scene.generator_edges
    ga, gb = _edge_geometry(scene, ge)
    chunk = max(1, (1 << 22) // max(1, len(ge)))
    for c in range(0, len(planes), chunk):
        sl = slice(c, c + chunk)
        h0 = normal[sl] @ ga.T - offset[sl, None]
        h1 = normal[sl] @ gb.T - offset[sl, None]
        i, j = np.nonzero((h0 * h1 < 0) & (np.abs(h0) > tol) & (np.abs(h1) > tol))
        f = h0[i, j] / (h0[i, j] - h1[i, j])
        pts_plane.append(planes[sl][i])
        pts.append(ga[j] + f[:, None] * (gb[j] - ga[j]))
        pts_vertex.append(-2 - ge[j])
    pts_plane, pts, pts_vertex = np.concatenate(pts_plane), np.concatenate(pts), np.concatenate(pts_vertex)
    order = np.argsort(pts_plane, kind="stable")
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    # around each (vertex, plane) the plane's points sorted by the direction of their line
    # (in blocks of rows: the keys of a row lie in [4 row, 4 row + π), blocks never interleave)
    first = np.searchsorted(pts_plane[order], vp[:, 1], "left")  # vp: sorted, unique rows
    count = np.searchsorted(pts_plane[order], vp[:, 1], "right") - first
    keys, point_of = [], []
    for rows in _row_blocks(count, CHUNK * 10):
        r, k = expand_ranges(first[rows], count[rows])
        r += rows.start
        w = order[k]
        x = scene.vertices[vp[r, 0]]
        direction = pts[w] - x
        far = np.linalg.norm(direction, axis=1) > tol  # the family's own vertex
        r, w, direction = r[far], w[far], direction[far]
        eu, ev = _plane_bases(scene, vp[r, 1])
        angle = np.mod(np.arctan2(np.einsum("ij,ij->i", direction, ev), np.einsum("ij,ij->i", direction, eu)), np.pi)
        key = r * 4.0 + angle  # angles < π < 4: one sorted key per (vertex, plane) block
        by_key = np.argsort(key, kind="stable")
        keys.append(key[by_key])
        point_of.append(w[by_key])
    return _PlanePoints(vp, pts, pts_vertex, rank, order, np.concatenate(keys), np.concatenate(point_of))


def _row_blocks(count, size):
    """Consecutive slices of rows whose counts sum to about ``size`` (at least one row
    each; one empty slice for no rows)."""
    end = np.cumsum(count)
    cuts = np.searchsorted(end, np.arange(size, int(end[-1]) if len(end) else 0, size), "right")
    bounds = unique_sorted(np.r_[0, cuts, len(count)])
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])] or [slice(0, 0)]


def _coplanar_candidates(scene, ve, ve_plane, points):
    """The range of :class:`_PlanePoints` ``key`` each same-plane VE family's edge spans
    seen from its vertex (with ANGLE_MARGIN), as up to three pieces of its (vertex, plane)
    block (a span crossing the angle 0 = π wraps).

    Returns
    -------
    family, first, last : (q,) int
        Row of ``ve`` and the key range [first, last) of each piece.
    """
    vp = points.vp
    row = np.searchsorted(vp[:, 0] * (vp[:, 1].max() + 1) + vp[:, 1], ve[:, 0] * (vp[:, 1].max() + 1) + ve_plane)
    x = scene.vertices[ve[:, 0]]
    a, b = _edge_geometry(scene, ve[:, 1])
    eu, ev = _plane_bases(scene, ve_plane)
    da = np.stack([np.einsum("ij,ij->i", a - x, eu), np.einsum("ij,ij->i", a - x, ev)], axis=1)
    db = np.stack([np.einsum("ij,ij->i", b - x, eu), np.einsum("ij,ij->i", b - x, ev)], axis=1)
    cross = da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]
    span = np.arctan2(np.abs(cross), np.einsum("ij,ij->i", da, db))  # in [0, π)
    start = np.mod(np.arctan2(np.where(cross >= 0, da[:, 1], db[:, 1]), np.where(cross >= 0, da[:, 0], db[:, 0])), np.pi)
    # a margin far above rounding: the exact test of _coplanar_events decides
    lo, hi = start - ANGLE_MARGIN, start + span + ANGLE_MARGIN
    pieces = [(lo, np.minimum(hi, np.pi)), (np.full_like(lo, 0.0), hi - np.pi), (lo + np.pi, np.full_like(lo, np.pi))]
    fams, firsts, lasts = [], [], []
    for p_lo, p_hi in pieces:
        f = np.flatnonzero(p_hi > np.maximum(p_lo, 0.0))
        i0 = np.searchsorted(points.key, row[f] * 4.0 + np.maximum(p_lo[f], 0.0), "left")
        i1 = np.searchsorted(points.key, row[f] * 4.0 + np.minimum(p_hi[f], np.pi), "right")
        fams.append(f)
        firsts.append(i0)
        lasts.append(np.maximum(i1, i0))
    return np.concatenate(fams), np.concatenate(firsts), np.concatenate(lasts)


def _coplanar_events(scene, ve, ve_plane, vp, ep, junctions):
    """Where each same-plane VE family's line passes a point of its plane at which the lines
    of the plane can change: a generator vertex touching the plane, a junction of an edge
    lying in it, a generator edge crossing it. Every line of such a family lies in the
    plane (degenerate events V0 does not keep: a floor corner, a block's bottom corner
    and a far edge of the floor in one line); so the family's state can change only
    there, or at an event out of the plane (its nodes).

    Parameters
    ----------
    ve : (m, 2) int
        (v, e) of the families; ``ve_plane`` (m,) their plane (:func:`face_planes`).
    vp, ep : (k, 2) int
        (vertex, plane) and (edge, plane) incidences (:func:`_same_plane_ve`).

    Returns
    -------
    family : (q,) int
        Row of ``ve``.
    s : (q,) float
    kind : (q,) int
        END_COPLANAR (a vertex or a junction) or END_CROSSING (an edge crossing the plane).
    index : (q,) int
        The vertex (-1 for a junction) or the crossing edge.
    """
    return _coplanar_join(scene, ve, ve_plane, _plane_points(scene, np.unique(ve_plane), vp, ep, junctions))


def _coplanar_join(scene, ve, ve_plane, points):
    """:func:`_coplanar_events` with the points of the families' planes found
    (:func:`_plane_points`): each family and the points in the range of directions its
    edge spans (output-sensitive: a family and a point of its plane pair up only when the
    line through the family's vertex and the point meets the family's edge)."""
    fam, first, last = _coplanar_candidates(scene, ve, ve_plane, points)
    r, k = expand_ranges(first, last - first)
    fam, w = fam[r], points.point_of[k]
    # the ranges overlap only within the margin; the order is (family, point in plane order)
    n = len(points.point)
    fam_w = unique_sorted(fam * n + points.rank[w])
    fam, w = fam_w // n, points.order[fam_w % n]
    x = scene.vertices[ve[fam, 0]]
    a, b = _edge_geometry(scene, ve[fam, 1])
    s, _ = segment_parameter(x, points.point[w] - x, a, b)
    with np.errstate(invalid="ignore"):
        inside = np.isfinite(s) & (s > 0) & (s < 1)
    which = points.vertex[w[inside]]
    crossing = which <= -2
    return (fam[inside], s[inside], np.where(crossing, END_CROSSING, END_COPLANAR),
            np.where(crossing, -2 - which, which))


def _hidden_events(scene, ve, s):
    """Whether each coplanar event of a same-plane VE family is hidden: the family's line
    there is blocked between its vertex and its edge, and stays blocked nearby.

    Such an event cannot change the family's state (its lines are invalid on both
    sides), so dropping it only joins two intervals that hold no arc. Most coplanar
    events are hidden (a block's corner on the floor seen from another block's corner
    through a third block): the intervals they would make grow as the cube of the
    blocks on the floor, the visible ones as the output.

    Blocked nearby: the piece from v to the edge (trimmed by epsilon, as
    :func:`viscx.skeleton.nodes.free_pieces` trims it) meets a face farther than
    epsilon from its trimmed ends and from the face's corners, and where it passes
    within epsilon of the face's boundary that edge is closed (a second face there:
    a block's side face and its bottom, which a line lying on the floor meets at
    their common edge). Lines near it then meet that face or the one beyond the edge.

    Parameters
    ----------
    ve : (m, 2) int
        (v, e) of each event's family.
    s : (m,) float
        The event's parameter on e.

    Returns
    -------
    (m,) bool
    """
    # each event on its own: in chunks on threads
    parts = map_chunks(lambda r: _hidden_events_chunk(scene, ve[r], s[r]), row_chunks(len(s), CHUNK))
    return np.concatenate(parts) if parts else np.zeros(0, dtype=bool)


def _hidden_events_chunk(scene, ve, s):
    """:func:`_hidden_events` on one chunk of events."""
    eps = scene.epsilon
    x = scene.vertices[ve[:, 0]]
    a, b = _edge_geometry(scene, ve[:, 1])
    vec = a + s[:, None] * (b - a) - x
    length = np.linalg.norm(vec, axis=1)
    long = np.flatnonzero(length > 4 * eps)
    tri, t = first_triangles(scene, x[long], vec[long] / length[long, None], 2 * eps, length[long] - 2 * eps)
    rows = long[tri >= 0]
    face, t = scene.triangle_face[tri[tri >= 0]], t[tri >= 0]
    hit = x[rows] + (t / length[rows])[:, None] * vec[rows]
    he = scene.half_edges
    hidden = np.zeros(len(s), dtype=bool)
    hidden[rows] = ~_near_doubtful_boundary(hit, scene.loop_offsets[scene.face_loop_offsets[face]],
                                            scene.loop_offsets[scene.face_loop_offsets[face + 1]], he.start, he.end, he.opp,
                                            scene.vertices, eps)
    return hidden


@njit(cache=True, nogil=True)
def _near_doubtful_boundary(hit, first, last, start, end, opp, vertices, eps):
    """Whether each hit point lies within eps of a corner of its face, or of an open edge
    of it (no second face there), over the face's boundary half-edges first..last - 1.

    Returns
    -------
    (k,) bool
    """
    out = np.zeros(hit.shape[0], dtype=np.bool_)
    for i in range(hit.shape[0]):
        for h in range(first[i], last[i]):
            a, b = vertices[start[h]], vertices[end[h]]
            u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
            d0, d1, d2 = hit[i, 0] - a[0], hit[i, 1] - a[1], hit[i, 2] - a[2]
            # the closest point of the edge, at w along it; sums in numpy einsum's order
            w = min(max(((d0 * u0 + d2 * u2) + d1 * u1) / ((u0 * u0 + u2 * u2) + u1 * u1), 0.0), 1.0)
            e0, e1, e2 = d0 - w * u0, d1 - w * u1, d2 - w * u2
            to_edge = np.sqrt((e0 * e0 + e1 * e1) + e2 * e2)
            to_corner = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
            if to_corner <= eps or (to_edge <= eps and opp[h] < 0):
                out[i] = True
    return out


def _plane_bases(scene, planes):
    """(u, v): two unit vectors spanning each plane (:func:`face_planes` ids), (n, 3) each."""
    plane_of_face = face_planes(scene)
    face_of = np.zeros(plane_of_face.max() + 1, np.int64)
    face_of[plane_of_face] = np.arange(scene.n_faces)
    n = scene.face_normal[face_of[planes]]
    helper = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    u = np.cross(helper, n)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(n, u)


def _event_parameters(scene, kind, generators, events, rows):
    """Parameter s of each event's line on the family's parameter edge."""
    param_edge = np.where(kind == EEE, generators[:, 0], generators[:, 1])
    a, b = _edge_geometry(scene, param_edge)
    s, _ = segment_parameter(events.ends[rows, 0], events.direction[rows], a, b)
    return s


def _domain_ends(scene, fam_kind, fam_gens, junctions):
    """Parameters where each family's line reaches an endpoint or a junction of one of its
    edges, or (EEE) q's or r's line at infinity (the linear-fractional map's pole), within
    (0, 1) (s = 0 and 1, the parameter edge's endpoints, are added by the caller).

    VE (v, e): the junctions of e. EEE (p, q, r): those of p, and where the line
    reaches an endpoint or a junction of q or r. The map s -> x (x the line's point
    on q or r) is linear-fractional (a projectivity between two lines of a regulus, or
    a central projection for a pencil of lines in a plane), fixed by three samples; a
    pencil through a point of the edge gives a constant map and no end.

    Returns
    -------
    family : (k,) int
    s : (k,) float
    kind : (k,) int
        END_ENDPOINT or END_JUNCTION.
    vertex : (k,) int
        The junction's vertex (-1 for a crossing and for endpoints).
    """
    fams, ss, kinds, verts = [], [], [], []
    # junctions on the parameter edge (VE: e, EEE: p): s directly
    param_edge = np.where(fam_kind == EEE, fam_gens[:, 0], fam_gens[:, 1])
    f, k = _junctions_of(junctions, param_edge)
    fams.append(f)
    ss.append(junctions.s[k])
    kinds.append(np.full(len(f), END_JUNCTION))
    verts.append(junctions.vertex[k])
    e = np.flatnonzero(fam_kind == EEE)
    probes = np.array([0.2, 0.5, 0.8])
    o, d = family_lines(scene, np.full(3 * len(e), EEE), np.repeat(fam_gens[e], 3, axis=0), np.tile(probes, len(e)))
    for slot in (1, 2):
        a, b = _edge_geometry(scene, np.repeat(fam_gens[e, slot], 3))
        x, _ = segment_parameter(o, np.where(np.linalg.norm(d, axis=1)[:, None] > 0, d, 1.0), a, b)
        x = x.reshape(-1, 3)
        s = np.broadcast_to(probes, x.shape)
        # x = (α s + β) / (γ s + δ): (α, β, γ, δ) is the null vector of [s, 1, -x s, -x]
        system = np.stack([s, np.ones_like(s), -x * s, -x], axis=2)
        # a constant map (a pencil through a point of this edge) has no ends to find
        fine = np.all(np.isfinite(system), axis=(1, 2)) & (np.ptp(x, axis=1) > 1e-9)
        coeff = np.full((len(e), 4), np.nan)
        if fine.any():
            coeff[fine] = np.linalg.svd(system[fine])[2][:, -1]
        # the values of x to reach: the edge's endpoints, its junctions
        rows, k = _junctions_of(junctions, fam_gens[e, slot])
        fam = np.concatenate([np.arange(len(e)), np.arange(len(e)), rows])
        value = np.concatenate([np.zeros(len(e)), np.ones(len(e)), junctions.s[k]])
        al, be, ga, de = coeff[fam].T
        with np.errstate(divide="ignore", invalid="ignore"):
            fams += [e[fam], e]
            ss += [(be - value * de) / (value * ga - al), -de[: len(e)] / ga[: len(e)]]
        kinds += [np.where(np.arange(len(fam)) < 2 * len(e), END_ENDPOINT, END_JUNCTION), np.full(len(e), END_ENDPOINT)]
        verts += [np.concatenate([np.full(2 * len(e), -1), junctions.vertex[k]]), np.full(len(e), -1)]
    fam, s, kind, vertex = (np.concatenate(x) for x in (fams, ss, kinds, verts))
    keep = np.isfinite(s) & (s > 0) & (s < 1)
    return fam[keep].astype(np.int64), s[keep], kind[keep], vertex[keep].astype(np.int64)


def _junctions_of(junctions, edges):
    """(row of ``edges``, junction) for every junction of each edge."""
    lo = np.searchsorted(junctions.edge, edges, "left")
    rows, k = expand_ranges(lo, np.searchsorted(junctions.edge, edges, "right") - lo)
    return rows, k


# --------------------------------------------------------------------------------------
# the builder


def build_arcs(scene, nodes, quiet=True, workers=None):
    """The arcs (V1) and VE half-cells of a scene, from its nodes (V0).

    The families are found once for the whole scene (:func:`_families`). Their events,
    intervals and first samples are made in chunks of consecutive families
    (:func:`_first_pass_of_families`, on threads); the few intervals whose samples
    disagree are refined all together (:func:`_refine`: its bisection is a sequence of
    small batches); then each chunk's pieces are merged into its arcs
    (:func:`_arcs_of_families`). Every stage of an arc is decided within its family, so
    the arcs do not depend on the chunks; memory holds the result, the first pass's
    pieces (about as large, freed chunk by chunk) and a chunk's events per thread; the
    chunks' arcs, each sorted, concatenate in the canonical order.

    Parameters
    ----------
    scene : Scene
    nodes : Nodes
        The V0 nodes (any builder's; ids refer to their order).
    quiet : bool
        No progress bar.
    workers : int, optional
        Threads building the chunks (default: the CPU count); the arcs do not depend on it.

    Returns
    -------
    Arcs
    """
    with bar(total=5, desc="arcs", quiet=quiet, unit="stage") as progress:
        progress.set_postfix_str("planar events")
        planar = planar_events(scene)
        progress.update()

        progress.set_postfix_str("families")
        families = _families(scene, nodes, planar, workers)
        progress.update()

        chunks = _family_chunks(families)
        done = []

        def chunk_done(_):
            done.append(1)
            progress.set_postfix_str(f"samples: {len(done)}/{len(chunks)} chunks of families")

        progress.set_postfix_str(f"samples: 0/{len(chunks)} chunks of families")
        first = map_chunks(lambda c: _first_pass_of_families(scene, families, c), chunks, workers, progress=chunk_done)
        # the intervals whose samples disagree, of all chunks at once (few: in batches)
        progress.set_postfix_str("refining")
        release_free_memory()
        mixed = [np.concatenate(x) for x in zip(*(m for _, m in first))]
        refined = _refine(scene, families.kind, families.generators, *mixed, workers=workers)
        refined = _concatenate_parts(refined) if refined else None
        progress.set_postfix_str("merging")
        release_free_memory()
        parts = map_chunks(lambda i: _arcs_of_families(scene, families, chunks, i, first, refined), range(len(chunks)), workers)
        del families, first, refined
        release_free_memory()
        arcs = _concatenate_parts(parts, release=True)
        progress.update()

        progress.set_postfix_str("half-cells")
        half_cells = _half_cells(scene, arcs)
        del arcs["sides"]
        progress.update()

        progress.set_postfix_str("crossing junctions")
        xe = crossing_arcs(scene, workers)
        if xe is not None:  # after the VE arcs: the other arcs' ids do not change
            arcs = {k: np.concatenate([v, xe[k]]) for k, v in arcs.items()}
        progress.update()
    return Arcs(**arcs, planar=planar, half_cells=half_cells)


@dataclass
class _Families:
    """Every arc family of a scene, sorted by (kind, generators), with the events found
    for all of them at once: the V0 nodes and planar events on each, as CSR.

    Attributes
    ----------
    kind : (f,) int
    generators : (f, 3) int
        Canonical (:class:`Arcs`).
    event_offsets : (f + 1,) int
        Family i's node and planar events are rows ``event_offsets[i]:event_offsets[i + 1]``
        of ``event_s`` (float), ``event_kind`` (END_NODE or END_PLANAR) and ``event_index``
        (the node, or the row of the planar events).
    plane_family : (m,) int
        The same-plane VE families (:func:`_same_plane_ve`), ascending, with their (v, e)
        ``plane_ve`` (m, 2) and plane ``plane_of`` (m,).
    plane_points : _PlanePoints
        The points of their planes (:func:`_plane_points`).
    weight : (f,) int
        The events each family is known to hold (nodes, planar events, coplanar
        candidates) plus a few for its domain's ends: what sizes the chunks.
    """

    kind: np.ndarray
    generators: np.ndarray
    event_offsets: np.ndarray
    event_s: np.ndarray
    event_kind: np.ndarray
    event_index: np.ndarray
    plane_family: np.ndarray
    plane_ve: np.ndarray
    plane_of: np.ndarray
    plane_points: _PlanePoints
    weight: np.ndarray

    def __len__(self):
        return len(self.kind)


def _families(scene, nodes, planar, workers=None):
    """The families through the nodes and the planar events, every same-plane VE family
    and every pencil at a corner of a touched face (which may hold no node), with their
    node and planar events (:class:`_Families`)."""
    def incidences(chunk):
        code, events, rows = chunk
        part = Nodes(**{k: getattr(events, k)[rows] for k in Nodes.__dataclass_fields__})
        k, g, at = _incidences(scene, part)
        return k.astype(np.int8), g, np.full(len(at), code, np.int8), at + rows.start, _event_parameters(scene, k, g, part, at)

    # in chunks of events (each on its own, on threads): their temporaries stay bounded
    chunks = [(code, events, rows) for code, events in ((END_NODE, nodes), (END_PLANAR, planar))
              for rows in row_chunks(max(len(events), 1), CHUNK // 4)]
    fam_kind, fam_gens, ev_kind, ev_index, ev_s = (list(x) for x in zip(*map_chunks(incidences, chunks, workers)))
    # VE families of a vertex and an edge in one face's plane may hold no node: seed them all
    plane_ve, plane_of, vp, ep = _same_plane_ve(scene)
    fam_kind.append(np.full(len(plane_ve), VE, np.int8))
    fam_gens.append(np.concatenate([plane_ve, np.full((len(plane_ve), 1), -1)], axis=1))
    # so may the pencils at the corners of faces in contact
    pencils = contact_pencils(scene)
    fam_kind.append(np.full(len(pencils), EEE, np.int8))
    fam_gens.append(pencils)
    keys = np.concatenate([np.concatenate(fam_kind).astype(np.int64)[:, None], np.concatenate(fam_gens)], axis=1)
    del fam_kind, fam_gens
    # (shifted by one, the -1 of VE rows included, the rows pack into one sortable int64)
    families, fam_of = unique_rows(keys.reshape(-1, 4) + 1)
    families -= 1
    del keys
    n_events = len(fam_of) - len(plane_ve) - len(pencils)
    plane_family, fam_of = fam_of[n_events: n_events + len(plane_ve)], fam_of[:n_events]
    # (plane_ve is sorted by (v, e) and families by (VE, v, e): plane_family ascends)
    order = np.argsort(fam_of, kind="stable")
    nf = len(families)
    count = np.bincount(fam_of, minlength=nf)
    points = _plane_points(scene, np.unique(plane_of), vp, ep, junctions=edge_junctions(scene))
    weight = count + np.where(families[:, 0] == EEE, 8, 2)
    for rows in row_chunks(len(plane_ve), CHUNK):
        fam, first, last = _coplanar_candidates(scene, plane_ve[rows], plane_of[rows], points)
        weight += np.bincount(plane_family[rows][fam], weights=last - first, minlength=nf).astype(np.int64)
    return _Families(families[:, 0], families[:, 1:], np.r_[0, np.cumsum(count)], np.concatenate(ev_s)[order],
                     np.concatenate(ev_kind)[order], np.concatenate(ev_index)[order], plane_family, plane_ve, plane_of,
                     points, weight)


#: Events (known, see :class:`_Families`) per chunk of families built at once by
#: :func:`build_arcs`: a few hundred bytes each in flight.
FAMILY_CHUNK = 1 << 18


def _family_chunks(families):
    """Consecutive ranges of families (slices) of about FAMILY_CHUNK events each."""
    return _row_blocks(families.weight, FAMILY_CHUNK)


def _first_pass_of_families(scene, families, chunk):
    """The events, intervals and first pass (:func:`_first_pass`) of a chunk of
    consecutive families (a slice): their nodes and planar events, domain ends and
    junctions, coplanar events. Families are the chunk's (0 its first); the mixed
    intervals' are the scene's."""
    lo, hi = chunk.start, chunk.stop
    fkind, fgens = families.kind[chunk], families.generators[chunk]
    nf = hi - lo
    ev = slice(families.event_offsets[lo], families.event_offsets[hi])
    fam_of = np.repeat(np.arange(nf), np.diff(families.event_offsets[lo: hi + 1]))
    # the ends of each family's domain, and its junctions
    dom_f, dom_s, dom_kind, dom_vertex = _domain_ends(scene, fkind, fgens, edge_junctions(scene))
    # the points of their plane same-plane VE families pass
    p0, p1 = np.searchsorted(families.plane_family, [lo, hi])
    plane_ve = families.plane_ve[p0:p1]
    cop_f, cop_s, cop_kind, cop_index = _coplanar_join(scene, plane_ve, families.plane_of[p0:p1], families.plane_points)
    cop_hidden = _hidden_events(scene, plane_ve[cop_f], cop_s)
    cop_f = families.plane_family[p0:p1][cop_f] - lo
    # the points of their plane pencils of touched planes pass
    pen_f, pen_s, pen_kind, pen_index = _pencil_events(scene, fkind, fgens)
    cop_f, cop_s = np.r_[cop_f, pen_f], np.r_[cop_s, pen_s]
    cop_kind, cop_index = np.r_[cop_kind, pen_kind], np.r_[cop_index, pen_index]
    cop_hidden = np.r_[cop_hidden, np.zeros(len(pen_f), dtype=bool)]
    fam_of = np.concatenate([fam_of, dom_f, cop_f, np.arange(nf), np.arange(nf)])
    ev_s = np.concatenate([families.event_s[ev], dom_s, cop_s, np.zeros(nf), np.ones(nf)])
    ev_kind = np.concatenate([families.event_kind[ev], dom_kind, cop_kind, np.full(2 * nf, END_ENDPOINT)])
    ev_index = np.concatenate([families.event_index[ev], dom_vertex, cop_index, np.full(2 * nf, -1)])
    ev_hidden = np.zeros(len(ev_s), dtype=bool)
    ev_hidden[len(ev_s) - 2 * nf - len(cop_s): len(ev_s) - 2 * nf] = cop_hidden
    # events on the family's edge (within rounding of its ends)
    ev_s = np.nan_to_num(ev_s, nan=-1.0)
    inside = (ev_s >= -1e-9) & (ev_s <= 1 + 1e-9)
    ev_s = np.clip(ev_s, 0.0, 1.0)
    intervals = _intervals(scene, fkind, fgens, *(x[inside] for x in (fam_of, ev_s, ev_kind, ev_index, ev_hidden)))
    del fam_of, ev_s, ev_kind, ev_index, ev_hidden
    parts, mixed = _first_pass(scene, fkind, fgens, *intervals)
    return parts, (mixed[0] + lo,) + mixed[1:]


def _arcs_of_families(scene, families, chunks, i, first, refined):
    """The arcs of the chunk of families ``chunks[i]``, sorted as :func:`_sorted`, with
    their samples' half-cell pairs (``sides``), from its first pass (``first[i]``, taken
    out of the list: the first pass is freed as the arcs are made) and its families'
    refined pieces (``refined``: of all chunks, by ascending family; or None)."""
    chunk = chunks[i]
    parts, _ = first[i]
    first[i] = None
    if refined is not None:
        a, b = np.searchsorted(refined["family"], [chunk.start, chunk.stop])
        mine = {k: v[a:b] for k, v in refined.items()}
        mine["family"] = mine["family"] - chunk.start
        parts = parts + [mine]
    arcs = _arcs_of_pieces(scene, families.kind[chunk], families.generators[chunk], parts)
    _edge_line_ends(scene, arcs)
    # (already sorted: the merge orders the arcs by family, then s, and families are sorted
    # by kind and generators, the order of _sorted)
    return arcs


def _param_scale(scene, fkind, fgens):
    """Length of each family's parameter edge."""
    a, b = _edge_geometry(scene, np.where(fkind == EEE, fgens[:, 0], fgens[:, 1]))
    return np.linalg.norm(b - a, axis=1)


def _intervals(scene, fkind, fgens, fam_of, ev_s, ev_kind, ev_index, ev_hidden=None):
    """Merge each family's events closer than 4 epsilon along its edge (by _END_RANK: a node
    beats a planar event beats a domain end beats a junction beats a coplanar event),
    leave out the groups of hidden events alone (:func:`_hidden_events`) and return the
    intervals between consecutive ones."""
    # by (family, s) only: events at one (family, s) fall in one group whatever their order
    order = _by_family_and_s(fam_of, ev_s)
    f, s, k, i = fam_of[order], ev_s[order], ev_kind[order], ev_index[order]
    tol = 4 * scene.epsilon / _param_scale(scene, fkind, fgens)[f]
    new_group = np.ones(len(f), dtype=bool)
    new_group[1:] = (f[1:] != f[:-1]) | (s[1:] - s[:-1] > tol[1:])
    group = np.cumsum(new_group) - 1
    hidden = np.zeros(len(f), bool) if ev_hidden is None else ev_hidden[order]
    seen = np.bincount(group, weights=~hidden) > 0
    # within a group (a run), the best event: lowest rank, then lowest id, then lowest s
    if len(f) == 0:
        first = np.zeros(0, np.int64)
    else:
        merit = _END_RANK[k].astype(np.int64) * (int(i.max()) - int(i.min()) + 1) + (i - i.min())
        start = np.flatnonzero(new_group)
        at_best = merit == np.repeat(np.minimum.reduceat(merit, start), np.diff(np.r_[start, len(f)]))
        first = np.flatnonzero(at_best)
        first = first[np.r_[True, group[first][1:] != group[first][:-1]]]
        first = first[seen[group[first]]]
    gf, gs, gk, gi = f[first], s[first], k[first], i[first]
    nxt = np.flatnonzero(gf[1:] == gf[:-1])
    return gf[nxt], gs[nxt], gk[nxt], gi[nxt], gs[nxt + 1], gk[nxt + 1], gi[nxt + 1]


def _by_family_and_s(family, s):
    """``np.lexsort([s, family])``, 2.5 times faster: a stable sort of the complex numbers
    family + i s, which numpy orders lexicographically (family < 2^53 is exact in float64)."""
    return np.argsort(family + 1j * s, kind="stable")


def _end_fraction(scene, fkind, fgens, f, s0, s1):
    """Fraction of each interval that is 20 epsilon along the parameter edge (at most 0.1):
    where the samples next to the interval's events are taken, so that a short piece next
    to an event is seen even when the event closing it is missing."""
    length = _param_scale(scene, fkind[f], fgens[f]) * (s1 - s0)  # (f: a few of the families)
    return np.minimum(0.1, 20 * scene.epsilon / np.maximum(length, 1e-300))


def _arcs_on_intervals(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1, workers=None):
    """The arcs on the intervals between consecutive events of families (``f`` the family
    of each, s0 < s1 its ends, t and i their end types and ids): the samples of every
    interval (:func:`_first_pass`), the intervals whose samples disagree refined
    (:func:`_refine`), the pieces merged (:func:`_arcs_of_pieces`).

    Returns
    -------
    dict of arrays
        The fields of :class:`Arcs` (not sorted) and ``sides`` (m, 8), the half-cells'
        pairs of each arc's sample.
    """
    parts, mixed = _first_pass(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1, workers)
    return _arcs_of_pieces(scene, fkind, fgens, parts + _refine(scene, fkind, fgens, *mixed, workers=workers))


def _first_pass(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1, workers=None):
    """Every interval judged at its samples (SAMPLES and 20 epsilon from each end).

    Returns
    -------
    parts : list of dict
        The intervals whose samples agree and are valid, one arc piece each (its sample
        the first, at 1/2), in pieces as :func:`_refine_batch`'s.
    mixed : tuple
        ``(f, s0, t0, i0, s1, t1, i1)`` of the intervals whose samples disagree.
    """
    n = len(f)
    near = _end_fraction(scene, fkind, fgens, f, s0, s1)
    fr = np.concatenate([np.broadcast_to(np.asarray(SAMPLES), (n, len(SAMPLES))), near[:, None], 1 - near[:, None]], axis=1)
    ss = s0[:, None] + fr * (s1 - s0)[:, None]
    # judged in chunks of intervals (on threads), keeping the whole segment only for the
    # sample that stands for an arc (the first, at 1/2): memory stays bounded on large scenes
    uniform = np.zeros(n, dtype=bool)

    def judge_chunk(c):
        smp = judge_samples(scene, np.repeat(fkind[f[c]], fr.shape[1]), np.repeat(fgens[f[c]], fr.shape[1], axis=0),
                            ss[c].reshape(-1), sides=True)
        state = _full_state(smp).reshape(len(c), fr.shape[1], -1)
        uniform[c] = np.all(state == state[:, :1], axis=(1, 2))
        whole = np.flatnonzero(uniform[c] & (state[:, 0, 0] == 1))
        mid = whole * fr.shape[1]
        return c[whole], smp.state[mid], smp.sides[mid], smp.direction[mid], smp.ends[mid], smp.generator_points[mid]

    step = CHUNK // 4  # several chunks per thread: the threads finish together
    chunks = [np.arange(lo, min(lo + step, n)) for lo in range(0, n, step)]
    parts = [
        {  # (narrow where the values allow: the pieces of every chunk wait for the refinement)
            "family": f[w].astype(np.int32),
            "interval": np.stack([s0[w], s1[w]], axis=1),
            "end_type": np.stack([t0[w], t1[w]], axis=1).astype(np.int8),
            "end_node": np.stack([i0[w], i1[w]], axis=1),
            "parameter": ss[w, 0],
            "state": state.astype(np.int32),
            "sides": sides.astype(np.int32),
            "direction": direction,
            "ends": ends,
            "generator_points": points,
            "loose": np.zeros((len(w), 2), dtype=bool),
        }
        for w, state, sides, direction, ends, points in map_chunks(judge_chunk, chunks, workers)
    ]
    mixed = np.flatnonzero(~uniform)
    return parts, tuple(x[mixed] for x in (f, s0, t0, i0, s1, t1, i1))


def _arcs_of_pieces(scene, fkind, fgens, parts):
    """The arcs (as :func:`_arcs_on_intervals`) from the pieces of the first pass and the
    refinement (dicts of arrays, all of the families' pieces): merged where nothing
    changes (:func:`_merge_across_possible_events`)."""
    pieces = _merge_across_possible_events(scene, fkind, fgens, _concatenate_parts(parts))
    del pieces["loose"]
    fam = pieces.pop("family")
    state = pieces.pop("state")
    sides = pieces.pop("sides")
    return {
        "kind": fkind[fam].astype(np.int8),
        "generators": fgens[fam],
        **{k: pieces[k] for k in ("interval",)},
        "end_type": pieces["end_type"].astype(np.int8),
        "end_node": pieces["end_node"],
        "blocker_kind": state[:, [1, 3]].astype(np.int8),
        "blocker": state[:, [2, 4]].astype(np.int64),
        "parameter": pieces["parameter"],
        "direction": pieces["direction"],
        "ends": pieces["ends"],
        "generator_points": pieces["generator_points"],
        "sides": sides.astype(np.int64),
    }


def _merge_across_possible_events(scene, fkind, fgens, pieces):
    """Join consecutive arcs of a family that meet at an edge crossing its plane where
    nothing changes (the same blockers and half-cells on both sides): a line passing such
    a point can change (a degenerate event), but in general position it changes only at
    a node (a VEE line) and the arcs would otherwise end at every crossing. Every other
    event ends its arcs (junctions and coplanar vertices: where collinear or coplanar
    boundaries of other families begin and end, so that duplicates stay identical).

    Also joined: VE arcs meeting at a *loose* transition, where only the half-cells'
    pairs changed and no event explains it (``pieces["loose"]``, :func:`_refine_batch`).
    The V-cell beside a VE line of v changes only where another boundary of v's sphere
    meets the line, i.e. where the line passes a vertex or an edge: an event the snap
    would have found. A loose change is the probe's: near a corner of a cell thinner
    than PROBE_ANGLE (random scene 161, vertex 3: a face seen 2e-4 off edge-on, whose
    sliver narrows below 1e-8 rad within 8e-4 of its corners) the probe jumps over it.

    A joined arc's sample is taken again at the middle of its interval, as for an arc
    between two events (the first piece's stands where that sample's line disagrees or,
    with no loose transition joined, its half-cells disagree)."""
    order = _by_family_and_s(pieces["family"], pieces["interval"][:, 0])
    # the join is decided on the sorted keys; every other field is gathered once, at the end
    p = {k: pieces[k][order] for k in ("family", "interval", "end_type", "end_node", "loose", "state", "sides")}
    same_full = np.all(p["state"][1:] == p["state"][:-1], axis=1)
    join = (p["family"][1:] == p["family"][:-1]) & (p["interval"][1:, 0] == p["interval"][:-1, 1])
    loose = join & (p["end_type"][:-1, 1] == END_TRANSITION) & p["loose"][:-1, 1] & p["loose"][1:, 0] & same_full
    same_full &= np.all(p["sides"][1:] == p["sides"][:-1], axis=1)
    join &= (p["end_type"][:-1, 1] == END_CROSSING) & same_full
    join |= loose
    first = np.flatnonzero(np.r_[True, ~join]) if len(order) else np.zeros(0, np.int64)
    last = np.r_[first[1:] - 1, len(order) - 1] if len(order) else first
    out = {k: v[first] for k, v in p.items()}
    for k in ("interval", "end_type", "end_node", "loose"):
        out[k] = np.stack([p[k][first, 0], p[k][last, 1]], axis=1)
    del p
    kept = order[first]
    for k in ("parameter", "direction", "ends", "generator_points"):
        out[k] = pieces.pop(k)[kept]
    joined = np.flatnonzero(last > first)
    # arcs joined across a loose transition take the middle sample's half-cells
    had_loose = np.add.reduceat(np.r_[loose, False].astype(np.int64), first)[joined] > 0
    for c in row_chunks(len(joined), CHUNK):
        rows = joined[c]
        f = out["family"][rows]
        s = 0.5 * (out["interval"][rows, 0] + out["interval"][rows, 1])
        smp = judge_samples(scene, fkind[f], fgens[f], s, sides=True)
        same = np.all(smp.state == out["state"][rows], axis=1)
        same &= had_loose[c] | np.all(smp.sides == out["sides"][rows], axis=1)
        rows = rows[same]
        out["parameter"][rows] = s[same]
        for k in ("state", "sides", "direction", "ends", "generator_points"):
            out[k][rows] = getattr(smp, k)[same]
    return out


def _concatenate_parts(parts, release=False):
    """One dict of arrays from a list of dicts with the same keys, each key's pieces
    freed once joined (the parts are emptied): peak memory one copy, not two. With
    ``release``, the freed pieces' pages go back to the system after each key
    (:func:`viscx.memory.release_free_memory`): pieces of a few MB live in the heap,
    the joined arrays are mapped afresh, and the heap would keep a second copy
    (random_boxes(3001): resident peak 7.9 GB where the arcs take 3.9 GB)."""
    out = {}
    for key in list(parts[0]):
        out[key] = np.concatenate([p.pop(key) for p in parts])
        if release:
            release_free_memory()
    return out


def _full_state(smp):
    """(m, 13) int: a sample's state and its half-cells' pairs (what must hold along an arc)."""
    return np.concatenate([smp.state, smp.sides], axis=1)


def _refine(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1, workers=None):
    """Intervals whose samples disagree: resample, locate each change by bisection and
    cut the interval there (end type END_TRANSITION). In batches of intervals (each is
    refined on its own, so the result does not depend on them; on threads): memory stays
    bounded. Returns the batches' pieces, a dict of arrays each, in the intervals' order."""
    # batches of at most CHUNK samples, as many as a multiple of the threads (they finish together)
    workers = default_workers(workers)
    batches = workers * -(-len(f) // (workers * max(CHUNK // REFINE, 1)))
    step = max(1, -(-len(f) // max(batches, 1)))
    return map_chunks(lambda r: _refine_batch(scene, fkind, fgens, *(a[r] for a in (f, s0, t0, i0, s1, t1, i1))),
                      row_chunks(len(f), step), workers)


def _refine_batch(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1):
    """:func:`_refine` on one batch of intervals (at most CHUNK samples)."""
    n = len(f)
    near = _end_fraction(scene, fkind, fgens, f, s0, s1)
    grid = np.broadcast_to((np.arange(REFINE - 2) + 0.5) / (REFINE - 2), (n, REFINE - 2))
    fr = np.concatenate([near[:, None], near[:, None] + grid * (1 - 2 * near[:, None]), 1 - near[:, None]], axis=1)
    ss = s0[:, None] + fr * (s1 - s0)[:, None]
    smp = judge_samples(scene, np.repeat(fkind[f], REFINE), np.repeat(fgens[f], REFINE, axis=0), ss.reshape(-1), sides=True)
    state = _full_state(smp).reshape(n, REFINE, -1)
    change = np.any(state[:, 1:] != state[:, :-1], axis=2)  # (n, REFINE - 1)
    ci, cj = np.nonzero(change)
    lo, hi = ss[ci, cj], ss[ci, cj + 1]
    left = state[ci, cj]
    for _ in range(BISECT):
        m = 0.5 * (lo + hi)
        st = _full_state(judge_samples(scene, fkind[f[ci]], fgens[f[ci]], m, sides=True))
        same = np.all(st == left, axis=1)
        lo, hi = np.where(same, m, lo), np.where(same, hi, m)
    cut = _snap_cuts(scene, fkind[f[ci]], fgens[f[ci]], 0.5 * (lo + hi), ss[ci, cj], ss[ci, cj + 1])
    # loose: only the half-cells changed and no event explains it (see _merge_across_possible_events)
    loose = (fkind[f[ci]] == VE) & (cut == 0.5 * (lo + hi)) & np.all(state[ci, cj, :5] == state[ci, cj + 1, :5], axis=1)
    # runs of equal state between cuts; keep the valid ones
    run_start = np.ones((n, REFINE), dtype=bool)
    run_start[:, 1:] = change
    ri, rj = np.nonzero(run_start)
    run_id = np.cumsum(run_start.reshape(-1)).reshape(n, REFINE) - 1
    nrun = len(ri)
    # each run's ends: its interval's end or the cut before / after it
    start_s, start_t, start_i = s0[ri].copy(), t0[ri].copy(), i0[ri].copy()
    end_s, end_t, end_i = s1[ri].copy(), t1[ri].copy(), i1[ri].copy()
    after = run_id[ci, cj]  # the run ending at this cut
    end_s[after], end_t[after], end_i[after] = cut, END_TRANSITION, -1
    before = run_id[ci, cj + 1]
    start_s[before], start_t[before], start_i[before] = cut, END_TRANSITION, -1
    run_loose = np.zeros((nrun, 2), dtype=bool)
    run_loose[after, 1], run_loose[before, 0] = loose, loose
    # each run's middle sample stands for it
    last = np.r_[ri[1:] != ri[:-1], True] if nrun else np.zeros(0, bool)
    run_len = np.empty(nrun, dtype=np.int64)
    run_len[:-1] = np.where(last[:-1], REFINE - rj[:-1], rj[1:] - rj[:-1])
    if nrun:
        run_len[-1] = REFINE - rj[-1]
    pick = ri * REFINE + rj + run_len // 2
    ok = smp.valid[pick] & (end_s > start_s)
    return {
        "family": f[ri][ok],
        "interval": np.stack([start_s, end_s], axis=1)[ok],
        "end_type": np.stack([start_t, end_t], axis=1)[ok],
        "end_node": np.stack([start_i, end_i], axis=1)[ok],
        "parameter": ss.reshape(-1)[pick][ok],
        "state": smp.state[pick][ok],
        "sides": smp.sides[pick][ok],
        "direction": smp.direction[pick][ok],
        "ends": smp.ends[pick][ok],
        "generator_points": smp.generator_points[pick][ok],
        "loose": run_loose[ok],
    }


def _snap_cuts(scene, kind, gens, cut, lo, hi):
    """Move each VE transition onto the event that explains it, when one lies within SNAP
    epsilon along the edge and strictly between the samples bracketing it.

    A transition is an event V0 leaves out (degenerate), found by bisection; the
    judging rules' tolerances (epsilon, the weld tolerance) and the half-cells' probe
    angle put it slightly off the event, so the arcs meeting there on a vertex's
    sphere would not meet. The events a VE (v, e) line can pass: through a generator
    vertex or a junction lying in the plane of v and e, or through an edge crossing
    that plane; each fixes s exactly (the line through v and the point, met with e).

    Parameters
    ----------
    kind, gens : (c,) int, (c, 3) int
        The family of each cut.
    cut, lo, hi : (c,) float
        The bisected parameter and the samples bracketing it.

    Returns
    -------
    (c,) float
    """
    cut = cut.copy()
    rows = np.flatnonzero(kind == VE)
    if len(rows) == 0:
        return cut
    eps, tol = scene.epsilon, scene.weld_tolerance
    v, e = gens[rows, 0], gens[rows, 1]
    x = scene.vertices[v]
    a, b = _edge_geometry(scene, e)
    n = np.cross(b - a, x - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    length = np.linalg.norm(b - a, axis=1)
    # candidate points: generator vertices, junctions, points of generator edges
    junctions = edge_junctions(scene)
    ja, jb = _edge_geometry(scene, junctions.edge)
    points = np.concatenate([scene.vertices[scene.generator_vertices], ja + junctions.s[:, None] * (jb - ja)])
    ga, gb = _edge_geometry(scene, scene.generator_edges)
    best = np.full(len(rows), np.inf)
    snapped = cut[rows].copy()
    chunk = max(1, (1 << 22) // max(1, len(points) + len(ga)))
    for c0 in range(0, len(rows), chunk):
        r = np.arange(c0, min(len(rows), c0 + chunk))
        # points in the plane of v and e
        h = np.einsum("rk,pk->rp", n[r], points) - np.einsum("rk,rk->r", n[r], x[r])[:, None]
        ri, pi = np.nonzero(np.abs(h) <= tol)
        cand_r, cand_p = [r[ri]], [points[pi]]
        # edges crossing it
        h0 = np.einsum("rk,pk->rp", n[r], ga) - np.einsum("rk,rk->r", n[r], x[r])[:, None]
        h1 = np.einsum("rk,pk->rp", n[r], gb) - np.einsum("rk,rk->r", n[r], x[r])[:, None]
        ri, gi = np.nonzero((h0 * h1 < 0) & (np.abs(h0) > tol) & (np.abs(h1) > tol))
        fr = h0[ri, gi] / (h0[ri, gi] - h1[ri, gi])
        cand_r.append(r[ri])
        cand_p.append(ga[gi] + fr[:, None] * (gb[gi] - ga[gi]))
        cr, cp = np.concatenate(cand_r), np.concatenate(cand_p)
        direction = cp - x[cr]
        fine = np.linalg.norm(direction, axis=1) > tol
        cr, direction = cr[fine], direction[fine]
        s, _ = segment_parameter(x[cr], direction, a[cr], b[cr])
        k = rows[cr]
        with np.errstate(invalid="ignore"):
            dist = np.abs(s - cut[k]) * length[cr]
            ok = np.isfinite(s) & (s > lo[k]) & (s < hi[k]) & (dist <= SNAP * eps)
        cr, s, dist = cr[ok], s[ok], dist[ok]
        order = np.lexsort([dist, cr])
        first = order[np.r_[True, cr[order][1:] != cr[order][:-1]]] if len(order) else order
        better = dist[first] < best[cr[first]]
        best[cr[first][better]] = dist[first][better]
        snapped[cr[first][better]] = s[first][better]
    cut[rows] = snapped
    return cut


def _edge_line_ends(scene, arcs):
    """A VE arc (v, e) whose domain ends at an endpoint w of e joined to v by an edge ends
    on the line along that edge (v and e lie on one face): end type END_EDGE, end_node
    the edge (V0 has no VV there: the line holds the edge)."""
    ev = scene.half_edges.edge_vertices
    nv = scene.n_vertices
    key = ev[:, 0] * nv + ev[:, 1]
    order = np.argsort(key)
    for side in (0, 1):
        rows = np.flatnonzero((arcs["kind"] == VE) & (arcs["end_type"][:, side] == END_ENDPOINT))
        s = arcs["interval"][rows, side]
        at_end = (s == 0.0) | (s == 1.0)
        rows, s = rows[at_end], s[at_end]
        v = arcs["generators"][rows, 0]
        w = ev[arcs["generators"][rows, 1], (s == 1.0).astype(np.int64)]
        k = np.minimum(v, w) * nv + np.maximum(v, w)
        pos = np.clip(np.searchsorted(key[order], k), 0, len(key) - 1)
        joined = key[order][pos] == k
        arcs["end_type"][rows[joined], side] = END_EDGE
        arcs["end_node"][rows[joined], side] = order[pos[joined]]


def _sorted(arcs):
    """Canonical order: kind, generators, then interval start."""
    g = arcs["generators"]
    order = np.lexsort([arcs["interval"][:, 0], g[:, 2], g[:, 1], g[:, 0], arcs["kind"]])
    return {k: v[order] for k, v in arcs.items()}


# --------------------------------------------------------------------------------------
# crossing junctions (XE families)


def crossing_scene(scene):
    """The scene with the crossing points X of its X-junctions (:func:`edge_crossings`)
    appended as generator vertices n, n + 1, … (n its vertex count), so that the VE
    machinery judges the lines through them; tangency at X from the faces touching it,
    found geometrically like a vertex's. Cached on the scene.

    Returns
    -------
    xs : Scene
        Shares the faces, half-edges (but ``vertex_is_generator``) and the ray caster.
    first : int
        Id of the first crossing point (n).
    """
    cached = getattr(scene, "_viscx_crossing_scene", None)
    if cached is not None:
        return cached
    import dataclasses

    from viscx.scene.neighbourhood import Wedges, surface_wedges

    cr = edge_crossings(scene)
    he = dataclasses.replace(scene.half_edges, vertex_is_generator=np.concatenate(
        [scene.half_edges.vertex_is_generator, np.ones(len(cr), bool)]))
    xs = dataclasses.replace(scene, vertices=np.concatenate([scene.vertices, cr.point]), half_edges=he)
    xs._caster = scene.ray_caster  # X lies on the scene's faces: nothing to add
    c, w = scene.contacts, surface_wedges(scene, cr.point)
    v = c.vertex
    xs._contacts = dataclasses.replace(c, vertex=Wedges(
        np.concatenate([v.offsets, v.offsets[-1] + w.offsets[1:]]), np.concatenate([v.face, w.face]),
        np.concatenate([v.first, w.first]), np.concatenate([v.normal, w.normal]), np.concatenate([v.span, w.span])))
    xs._viscx_junctions, xs._viscx_crossings = edge_junctions(scene), cr
    # the scene's pencils: X points are not foreign vertices touching a face
    xs._viscx_pencil_planes, xs._viscx_face_planes = pencil_planes(scene), face_planes(scene)
    scene._viscx_crossing_scene = xs, scene.n_vertices
    return scene._viscx_crossing_scene


def _blocked_at_crossings(kinds, ids, row, xe, cr, state=None):
    """Where an XE line is blocked at its crossing point (judged as the pseudo-vertex of
    :func:`crossing_scene`), name the blocker as the edge a (kind BLOCK_EDGE): X is no
    vertex of the scene. ``kinds``, ``ids`` (m, 2) are changed in place (or ``state``'s
    columns 1-4 when given); ``row`` is each line's crossing, used where ``xe``."""
    at_x = xe[:, None] & (kinds == BLOCK_VERTEX)
    kinds[at_x] = BLOCK_EDGE
    ids[at_x] = np.broadcast_to(cr.edges[np.where(xe, row, 0), 0][:, None], ids.shape)[at_x]
    if state is not None:
        state[:, [1, 3]], state[:, [2, 4]] = kinds, ids


def crossing_arcs(scene, workers=None):
    """The XE arcs: for each X-junction (generator edges a < b crossing at X) and each
    generator edge e skew to a or b, the lines through X meeting e (a VE family whose
    vertex is the junction point), cut at events and sampled by the VE stages.

    Events: e's endpoints and junctions (as every VE family's), and the lines through X
    and a generator vertex (VV) or meeting two more generator edges (VEE), validated as
    nodes on :func:`crossing_scene`. V0 drops those (X is a point of two of their
    generators); an arc ending there has end type END_TRANSITION, end_node -1.

    Returns
    -------
    dict of arrays or None
        Rows as :func:`_sorted` (kind XE, generators (a, e, b)), no ``sides``; None
        without X-junctions.
    """
    from viscx.skeleton import points  # (imports this module)

    cr = edge_crossings(scene)
    if len(cr) == 0:
        return None
    xs, first = crossing_scene(scene)
    ids = first + np.arange(len(cr))
    ge = scene.generator_edges
    j, e = np.repeat(np.arange(len(cr)), len(ge)), np.tile(ge, len(cr))
    a, b = cr.edges[j, 0], cr.edges[j, 1]
    keep = (e != a) & (e != b)
    keep[keep] = _skew(scene, e[keep], a[keep]) | _skew(scene, e[keep], b[keep])
    families = np.stack([ids[j[keep]], e[keep], np.full(np.count_nonzero(keep), -1)], axis=1)  # sorted by (X, e)
    fkind = np.full(len(families), VE)
    nf = len(families)
    nodes = points.point_nodes(xs, ids)
    # the families each node lies on, as a free point's
    inc, rows = points.point_node_incidences(xs, nodes)
    n_edges = len(scene.half_edges.edge_vertices)
    key = families[:, 0] * n_edges + families[:, 1]
    pos = np.minimum(np.searchsorted(key, inc[:, 0] * n_edges + inc[:, 1]), max(nf - 1, 0))
    on = key[pos] == inc[:, 0] * n_edges + inc[:, 1]
    fam_of, rows = pos[on], rows[on]
    ev_s = _event_parameters(xs, fkind[fam_of], families[fam_of], nodes, rows)
    dom_f, dom_s, dom_kind, dom_vertex = _domain_ends(xs, fkind, families, edge_junctions(scene))
    fam_of = np.concatenate([fam_of, dom_f, np.arange(nf), np.arange(nf)])
    ev_s = np.concatenate([ev_s, dom_s, np.zeros(nf), np.ones(nf)])
    ev_kind = np.concatenate([np.full(len(rows), END_TRANSITION), dom_kind, np.full(2 * nf, END_ENDPOINT)])
    ev_index = np.concatenate([np.full(len(rows), -1), dom_vertex, np.full(2 * nf, -1)])
    ev_s = np.nan_to_num(ev_s, nan=-1.0)
    inside = (ev_s >= -1e-9) & (ev_s <= 1 + 1e-9)
    ev_s = np.clip(ev_s, 0.0, 1.0)
    intervals = _intervals(xs, fkind, families, fam_of[inside], ev_s[inside], ev_kind[inside], ev_index[inside])
    built = _arcs_on_intervals(xs, fkind, families, *intervals, workers=workers)
    del built["sides"]  # X's own sphere: no V-cells
    row = built["generators"][:, 0] - first
    kinds, ids = built["blocker_kind"].astype(np.int64), built["blocker"]
    _blocked_at_crossings(kinds, ids, row, np.ones(len(row), bool), cr)
    built["blocker_kind"], built["blocker"] = kinds.astype(np.int8), ids
    built["kind"] = np.full(len(row), XE, np.int8)
    built["generators"] = np.stack([cr.edges[row, 0], built["generators"][:, 1], cr.edges[row, 1]], axis=1)
    built["generator_points"][:, 2] = built["generator_points"][:, 0]
    return _sorted(built)


# --------------------------------------------------------------------------------------
# VE half-cells


def _half_cells(scene, arcs):
    """Blocker pairs of the V-cells on both sides of each VE arc (seed 000 §4.1).

    The arc's sample line turned about its vertex by PROBE_ANGLE, towards +n and
    -n (n = (b - a) × (v - a)): :func:`side_blockers`, judged with every sample,
    so that they hold all along the arc. Up: the vertex's side, the vertex itself
    where the surface separates the turned line's rays there; down: the edge's side.
    """
    ve = np.flatnonzero(arcs["kind"] == VE)
    v, e = arcs["generators"][ve, 0], arcs["generators"][ve, 1]
    sides = arcs["sides"][ve]  # the arc's sample's (side_blockers), equal all along the arc
    up_kind, up, down_kind, down = (sides[:, 2 * k: 2 * k + 2] for k in range(4))
    up_kind, down_kind = up_kind.astype(np.int8), down_kind.astype(np.int8)
    return HalfCells(
        arc=ve,
        vertex=v,
        edge=e,
        up_kind=up_kind,
        up=up,
        down_kind=down_kind,
        down=down,
        start=arcs["end_node"][ve, 0],
        end=arcs["end_node"][ve, 1],
        start_type=arcs["end_type"][ve, 0],
        end_type=arcs["end_type"][ve, 1],
    )
