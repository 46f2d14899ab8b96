"""V2: the EE-cells (2-cells of an edge pair) of the visibility complex (Hoberock et al. §6).

The square of an edge pair
--------------------------
For two generator edges e1 < e2 on skew lines, parameterised like every edge of
the skeleton (x = 0 at the smaller vertex id, 1 at the larger), a point
(x1, x2) of the square [0, 1]² is the line through e1(x1) and e2(x2), and its
*EE segment* σ(x1, x2) is the maximal free segment of that line through both
points, judged by :func:`viscx.skeleton.nodes.maximal_free_segments` with the
two edges as generators (the rule of every segment of the skeleton,
docs/skeleton.md): the piece between the two points must be free; at e1 the
line passes (tangent: both faces of e1 on one side of the plane of e1 and
e2(x2)) and σ goes on to the first face or the sky, or it is blocked there
and σ ends at e1 with the *edge* as blocker (BLOCK_EDGE); likewise at e2. The
blocker pair (back, front) is read from e1's point towards e2's. An *EE-cell*
is a maximal connected region of the square where the pair is constant; where
the piece between the points is not free the square holds no segment
(*hidden*), and no cell.

Lines that enter a solid at e1 (not tangent) are kept, as the V-cells keep
lines that enter the surface at their vertex (up = the vertex): they are the
segments from the edge into the free space on the other side, a 2-parameter
family with the edge as blocker. Pairs of edges on coplanar or meeting lines
(two edges of a face, two edges at a vertex) have no square: every line
through both lies in one plane, grazing (docs/skeleton.md) — no EE-cells.

What bounds the cells (which V1 arcs, and the pair on each side)
---------------------------------------------------------------
Inside the square the pair changes only where the line meets a third
generator: a third edge e3 (the EEE family (e1, e2, e3), a hyperbola arc
x2(x1), linear-fractional, Hoberock et al. §4.2), or a vertex (a VEE node: a point
of the square, where such arcs meet). Along an EEE arc:

* e3 beyond e2 (or before e1) on the line: one end of σ changes — e3 tangent:
  the face of e3 on one side, what lies beyond e3 on the other; e3 blocking
  (not a silhouette): e3's two faces. The arc's stored pair is the pair *on*
  the arc (edge e3 as blocker, or what lies beyond e3), the other end is
  common to both sides;
* e3 between e1 and e2: one side is hidden (e3's faces cut the piece between
  the points), the other is a cell with the arc's pair;
* e3 coplanar with e1 (another edge of one of e1's faces, or an edge at one of
  e1's endpoints): the EEE family is a *pencil* (V1 builds it): the lines in
  that plane through the point where e2 crosses it, the segment x2 = const of
  the square (Durand's face-edge event). Across it the plane of e1 and e2(x2)
  passes a face of e1: tangency at e1 flips, so the back blocker turns from
  the edge e1 to the face hit beyond e1. Likewise pencils of e2's faces are
  segments x1 = const.

The square's sides are the VE arcs (w, e2) through an endpoint w of e1
(x1 = 0 or 1, parameterised by x2 = s) and (w, e1) through an endpoint of e2
(x2 = 0 or 1); only their inner side bounds a cell. A VE arc has no event where
the lines through e1 *next to* w change but the lines through w do not (a pencil
of a face of e1 at w ends on the side there: tangency at e1 flips, while the
line through w only touches the surface at w), so VE arcs are cut into pieces
where other arcs of the square end on them (:func:`side_pieces`); EEE arcs need
no cut (their crossings are V0 nodes or V1's planar events). A vertex w lying
strictly inside e1 (a T-junction) adds the segment x1 = s_w, the VE arc (w, e2):
tangency at e1 changes across the lines through w (degenerate scenes;
:func:`arc_squares`).

Degenerate scenes have boundaries V1 has no arc for: a side whose own lines hold
no segment while the lines next to them do (two edges of one box: the side's lines
lie on a face, grazing, the lines through the box next to them are segments from
edge to edge), and pencils V1 did not build (the lines through the point where e1
crosses the plane of e2 and a coplanar edge). Where V1's arcs leave a square's loops
open, V2 adds these *segments* of its own (:func:`open_segments`,
:func:`segment_pieces`: exact cuts, the probes decide), boundary elements of their own
kinds (SIDE, PENCIL1, PENCIL2), and probes that square again 5 epsilon off its pieces
(FINE_PROBE; the Cornell light's slivers are thinner than PROBE), each probe stopping short
of the square's next piece but moving at least 1 epsilon, and where loops still stay open
0.1 epsilon (:func:`_finest_probes`: slivers thinner than epsilon between two arcs).

Which side gets which pair is found like the VE half-cells' (arcs/halfcells.py): the
arc's middle point of the square is moved off the arc, across it on each side,
by PROBE (or FINE_PROBE) epsilon along the edges, and that line is judged. A side whose line is
hidden bounds nothing (the hidden region is not a cell); an EEE arc whose two
sides have one pair bounds nothing.

A *boundary element* is one side of one arc in one square, a curve directed so
that its cell lies on its left in the (x1, x2) plane (x1 to the right, x2 up):
``+(a + 1)`` runs along arc a with s increasing (cell on its left), ``-(a + 1)``
with s decreasing (cell on the left of that, i.e. on the right of s
increasing); an element runs along an arc piece, ``element_interval`` in the
stored cells. A segment's element is ``±(id + 1)`` (id: the side's code k,
SIDE_CODES: 0 is x1 = 0, 1 is x1 = 1, 2 is x2 = 0, 3 is x2 = 1; a pencil's third
edge), its parameter t the coordinate that is not constant, + with t increasing (a
side is the VE family (w, e) with s = t, w the endpoint of the edge held constant).
Along an element each coordinate is a linear-fractional function
of the arc's parameter, stored as a rational linear Bézier curve: coordinate
c(u) = ((1 - u)(1 - w) c0 + u w c1) / ((1 - u)(1 - w) + u w) for u ∈ [0, 1]
with c0, c1 the element's ends and w fixed by the middle sample
(c(1/2) = (1 - w) c0 + w c1), exact for a projectivity and monotone in u.

Algorithm (Hoberock et al. §6 with the V-cells' Fig. 4)
-----------------------------------------------
Per edge pair and blocker pair (one *group*), :func:`loops.form_loops`
chains elements end to start where they meet in the square (within
``SQUARE_JOIN_EPSILONS`` times the square's epsilon, see below), choosing the first
element clockwise at a corner where several start. The points of the square
are embedded as (x1, x2, 1) and tangents as (t1, t2, 0), so that the sphere
helpers' signed angles about "the point" are the plane's angles about +z.

*Winding (Fig. 7).* A loop's winding is the sum of the turning angles at its
corners (from the end tangent of an element to the start tangent of the next)
plus the angle each element's tangent turns along it (a hyperbola arc turns by
less than π, so this is the signed angle from its start to its end tangent):
+2π for a loop running counter-clockwise around its cell (its *outer* loop),
−2π for a hole.

*Holes* (§5.4): a loop's reference point lies just left of its longest
element; a point p lies left of loop L iff the horizontal rays towards +x1 from
p and from L's reference point cross L equally often modulo 2 (each element's
x2 is monotone, so it crosses a ray at most once, found by inverting its
Bézier coordinate). Loops of one group bound one cell iff every loop of the
group sees their reference points on the same side (loops.cells_of_loops).

*Area*: Green's formula, exactly: along an element x2 is a linear-fractional
function of x1 (a composition of two), integrated in closed form.

Chains that do not close are kept as *open chains* (as for V-cells), and so are
loops whose winding is not ±2π (they closed only within the join tolerance, e.g.
one spurious V1 arc shorter than it); the cells of a pair with any open chain
are not ``complete``.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from viscx.arrays import expand_ranges, row_norms, unique_rows, unique_sorted
from viscx.parallel import row_chunks
from viscx.geometry.lines import segment_parameter
from viscx.progress import bar
from viscx.skeleton.arcs import EEE, VE, XE, edge_crossings, edge_junctions, family_lines
from viscx.skeleton.generators import edge_geometry, skew_edges
from viscx.skeleton.nodes import maximal_free_segments
from viscx.skeleton.loops import (
    TURNING_DECIMALS,
    cells_of_loops,
    chain_extents,
    corner_turns,
    form_loops,
    loop_successors,
    signed_angle,
    unique_elements,
)
from viscx.tolerances import (
    ANGLE_TOLERANCE,
    CUSP_ANGLE,
    CUSP_GAP,
    PARALLEL_TOLERANCE,
    SPIKE_ANGLE,
    SQUARE_COVER_TOLERANCE,
    SQUARE_JOIN_EPSILONS,
    SQUARE_SAME_POINT_EPSILONS,
    SQUARE_REFERENCE_OFFSET,
    WINDING_TOLERANCE,
)

#: Probes move the line this many epsilon along the edges off an arc (as the half-cells').
PROBE = 50
#: ... and this many in the squares whose loops stayed open with PROBE (:func:`squares_cells`).
FINE_PROBE = 5
#: Where along its element (Bézier u) a loop's reference point lies: the golden section.
REFERENCE_AT = (np.sqrt(5.0) - 1) / 2
#: Points judged per call of :func:`maximal_free_segments` by :func:`ee_blockers`: its
#: whole segments are ~200 bytes a line, the state kept 40.
BLOCKER_CHUNK = 1 << 20
#: Clamp of the Bézier weights (a coordinate constant along its element has w = 1/2).
_W_MIN = 1e-12
#: A coordinate whose ends lie closer than this (square units: rounding of the points computed
#: on the edges) is constant along its element.
_CONSTANT_SPAN = 1e-12
#: Kinds of boundary element: a piece of a V1 arc; V2's own segments of the square (a
#: side; a pencil x1 = c, the lines through e1(c) in the plane of e2 and a third edge;
#: a pencil x2 = c likewise), where V1 has no arc (:func:`segment_pieces`).
ARC, SIDE, PENCIL1, PENCIL2 = 0, 1, 2, 3
#: Sides of the square, code k = 2 * (coordinate held constant) + (its value):
#: x1 = 0, x1 = 1, x2 = 0, x2 = 1.
SIDE_CODES = {"x1=0": 0, "x1=1": 1, "x2=0": 2, "x2=1": 3}

# slot layout of an EE line for maximal_free_segments: two edges
_EE_SLOTS = np.array([[False] * 4])


@dataclass
class EECells:
    """EE-cells as flat arrays, sorted by (edge1, edge2, back, front, first boundary element).

    Attributes
    ----------
    edge1, edge2 : (c,) int
        The edge pair, edge1 < edge2: x1 runs along edge1, x2 along edge2.
    back_kind, front_kind : (c,) int8
        BLOCK_FACE, BLOCK_SKY or BLOCK_EDGE (back: edge1 itself; front: edge2).
    back, front : (c,) int
        Blocker beyond edge1's point and beyond edge2's (face id, -1 sky, edge id).
    area : (c,) float
        Area of the cell in the square [0, 1]².
    complete : (c,) bool
        Every boundary element of its pair lies on a closed loop.
    loop_offsets : (c + 1,) int
        Loops of cell i, the outer loop first; a cell covering the whole square
        without boundary has none.
    turning : (l,) float
        Winding of each loop (Fig. 7): +2π outer, −2π hole.
    element_offsets : (l + 1,) int
    element : (k,) int
        Signed arc id: +(a + 1) runs along V1 arc a with s increasing, the cell
        on its left in the (x1, x2) plane; -(a + 1) with s decreasing. For V2's own
        segments ±(id + 1) (id: side code, SIDE_CODES, or a pencil's third edge), +
        with the free coordinate increasing.
    element_kind : (k,) int8
        ARC, SIDE, PENCIL1 or PENCIL2.
    element_interval : (k, 2) float
        The piece [s0, s1] of the arc's interval the element runs along: the arc's
        own, but for a VE arc on the square's side cut where other arcs end on it;
        for a square side the piece [t0, t1] of its free coordinate.
    open_offsets : (o + 1,) int
    open_element : (m,) int
    open_element_kind : (m,) int8
    open_interval : (m, 2) float
    open_edge1, open_edge2, open_back_kind, open_back, open_front_kind, open_front : (o,) int
        The group of each chain that did not close.
    """

    edge1: np.ndarray
    edge2: np.ndarray
    back_kind: np.ndarray
    back: np.ndarray
    front_kind: np.ndarray
    front: np.ndarray
    area: np.ndarray
    complete: np.ndarray
    loop_offsets: np.ndarray
    turning: np.ndarray
    element_offsets: np.ndarray
    element: np.ndarray
    element_kind: np.ndarray
    element_interval: np.ndarray
    open_offsets: np.ndarray
    open_element: np.ndarray
    open_element_kind: np.ndarray
    open_interval: np.ndarray
    open_edge1: np.ndarray
    open_edge2: np.ndarray
    open_back_kind: np.ndarray
    open_back: np.ndarray
    open_front_kind: np.ndarray
    open_front: np.ndarray

    def __len__(self):
        return len(self.edge1)

    def counts(self):
        """Numbers of cells, with holes, of holes, of open chains, of edge pairs with cells
        or chains, of those complete and of complete pairs whose cells cover their square."""
        loops = np.diff(self.loop_offsets)
        pairs = unique_sorted(np.concatenate([self.edge1 * (1 << 32) + self.edge2,
                                          self.open_edge1 * (1 << 32) + self.open_edge2]))
        key = self.edge1 * (1 << 32) + self.edge2
        done = unique_sorted(key[self.complete])
        total = np.bincount(np.searchsorted(pairs, key), weights=self.area, minlength=len(pairs))
        covered = np.abs(total[np.searchsorted(pairs, done)] - 1) <= SQUARE_COVER_TOLERANCE
        return {
            "cells": len(self),
            "with_holes": int(np.count_nonzero(loops > 1)),
            "holes": int(np.sum(np.maximum(loops - 1, 0))),
            "open_chains": len(self.open_edge1),
            "pairs": len(pairs),
            "complete_pairs": len(done),
            "covered_pairs": int(np.count_nonzero(covered)),
        }


# --------------------------------------------------------------------------------------
# lines of the square


def ee_points(scene, e1, e2, x1, x2):
    """The points e1(x1) and e2(x2).

    Parameters
    ----------
    e1, e2 : (n,) int
    x1, x2 : (n,) float

    Returns
    -------
    p1, p2 : (n, 3) float
    """
    a1, b1 = edge_geometry(scene, np.asarray(e1, np.int64))
    a2, b2 = edge_geometry(scene, np.asarray(e2, np.int64))
    return a1 + np.asarray(x1)[:, None] * (b1 - a1), a2 + np.asarray(x2)[:, None] * (b2 - a2)


def ee_blockers(scene, e1, e2, x1, x2):
    """Blocker pair of the EE segment of each point of a square (module docstring).

    Parameters
    ----------
    e1, e2 : (n,) int
        Edge pairs (e1 < e2, skew).
    x1, x2 : (n,) float

    Returns
    -------
    state : (n, 5) int
        (valid, back kind, back, front kind, front), read from e1's point
        towards e2's; -1 blockers where not valid (hidden, grazing, or a point
        within epsilon of an edge's end).
    """
    e1, e2 = np.asarray(e1, np.int64), np.asarray(e2, np.int64)
    x1, x2 = np.asarray(x1, np.float64), np.asarray(x2, np.float64)
    if len(e1) > BLOCKER_CHUNK:
        # each point on its own: chunks keep only the state, not every whole segment
        return np.concatenate([ee_blockers(scene, e1[r], e2[r], x1[r], x2[r]) for r in row_chunks(len(e1), BLOCKER_CHUNK)])
    n = len(e1)
    p1, p2 = ee_points(scene, e1, e2, x1, x2)
    d = p2 - p1
    gens = np.full((n, 4), -1, np.int64)
    gens[:, 0], gens[:, 1] = e1, e2
    seg = maximal_free_segments(scene, np.broadcast_to(_EE_SLOTS, (n, 4)), np.full(n, 2), gens, p1,
                                np.where(row_norms(d)[:, None] > 0, d, 1.0))
    # maximal_free_segments orients canonically: turn each to run from e1's point to e2's
    flip = np.einsum("ij,ij->i", seg.direction, d) < 0
    kind = np.where(flip[:, None], seg.blocker_kind[:, ::-1], seg.blocker_kind).astype(np.int64)
    blocker = np.where(flip[:, None], seg.blocker[:, ::-1], seg.blocker)
    state = np.stack([seg.valid.astype(np.int64), kind[:, 0], blocker[:, 0], kind[:, 1], blocker[:, 1]], axis=1)
    state[~seg.valid, 1:] = -1
    return state


def skew_pairs(scene, e1, e2):
    """Whether edge pairs have a square: no shared vertex, lines neither parallel nor
    coplanar (farther than epsilon apart).

    Parameters
    ----------
    e1, e2 : (n,) int

    Returns
    -------
    (n,) bool
    """
    e1, e2 = np.asarray(e1, np.int64), np.asarray(e2, np.int64)
    if len(e1) == 0:
        return np.zeros(0, bool)
    return skew_edges(scene, e1, e2)


# --------------------------------------------------------------------------------------
# arcs in a square


def arc_squares(scene, arcs, part=None, blocks=False):
    """Every (arc, square) incidence: the squares each V1 arc bounds (of the arcs ``part``, a
    slice, when given).

    EEE (p, q, r): the squares of its skew pairs among (p, q), (p, r), (q, r). VE (w, e):
    the squares (e', e) of every generator edge e' at w skew to e (a side x' ∈ {0, 1}),
    and of every generator edge e' that w lies on strictly inside (a T-junction, V1's
    :class:`~viscx.skeleton.arcs.Junctions`): the segment x' = s_w across the square.
    Where the surface around e' changes at w, tangency at e' does for the lines through
    w, and the pair of the square changes across that segment (room_with_door: the inner
    wall's corners on the room's edges; boxes_on_floor: a box's corner on another box's
    edge). Without it those cells' loops stayed open. XE (a, e, b), the lines through
    the crossing point X of a and b: likewise the segment x' = s_X of the squares
    (a, e) and (b, e).

    Listed by kind of incidence (*block*: EEE by its pair, VE by edge at w or T-junction, XE
    by a or b), each block by arc.

    Returns
    -------
    arc : (k,) int
    e1, e2 : (k,) int
        The square's pair, e1 < e2.
    block : (k,) int8
        With ``blocks``: the block of each.
    """
    kind, g, first = arcs.kind, arcs.generators, 0
    if part is not None:
        kind, g, first = kind[part], g[part], part.start
    out_arc, out_a, out_b = [], [], []
    eee = np.flatnonzero(kind == EEE)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        out_arc.append(eee)
        out_a.append(g[eee, i])
        out_b.append(g[eee, j])
    ve = np.flatnonzero(kind == VE)
    if len(ve):
        ge = scene.generator_edges
        ev = scene.half_edges.edge_vertices[ge]
        owner = np.concatenate([ev[:, 0], ev[:, 1]])
        edges = np.concatenate([ge, ge])
        order = np.argsort(owner, kind="stable")
        owner, edges = owner[order], edges[order]
        w = g[ve, 0]
        lo, hi = np.searchsorted(owner, w, "left"), np.searchsorted(owner, w, "right")
        cnt = hi - lo
        rows = np.repeat(np.arange(len(ve)), cnt)
        at = np.repeat(lo, cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        out_arc.append(ve[rows])
        out_a.append(edges[at])
        out_b.append(g[ve[rows], 1])
        # the edges each vertex lies on (junctions with a vertex)
        junctions = edge_junctions(scene)
        has = junctions.vertex >= 0
        owner, edges = junctions.vertex[has], junctions.edge[has]
        order = np.argsort(owner, kind="stable")
        owner, edges = owner[order], edges[order]
        lo, hi = np.searchsorted(owner, w, "left"), np.searchsorted(owner, w, "right")
        cnt = hi - lo
        rows = np.repeat(np.arange(len(ve)), cnt)
        at = np.repeat(lo, cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        out_arc.append(ve[rows])
        out_a.append(edges[at])
        out_b.append(g[ve[rows], 1])
    else:  # (their two blocks empty: every block keeps its number)
        out_arc += [ve, ve]
        out_a += [ve, ve]
        out_b += [ve, ve]
    # XE (a, e, b): the segment x' = s_X of the squares (a, e) and (b, e) (crossing junctions)
    xe = np.flatnonzero(kind == XE)
    for slot in (0, 2):
        out_arc.append(xe)
        out_a.append(g[xe, slot])
        out_b.append(g[xe, 1])
    arc, a, b = np.concatenate(out_arc), np.concatenate(out_a), np.concatenate(out_b)
    keep = skew_pairs(scene, a, b)
    arc, a, b = arc[keep] + first, a[keep], b[keep]
    if blocks:
        block = np.repeat(np.arange(len(out_arc), dtype=np.int8), [len(x) for x in out_arc])[keep]
        return arc, np.minimum(a, b), np.maximum(a, b), block
    return arc, np.minimum(a, b), np.maximum(a, b)


def _coordinate(scene, arcs, arc, edge, s):
    """Parameter x on ``edge`` of the line of each arc's family at s.

    Parameters
    ----------
    arc, edge : (n,) int
    s : (n,) float

    Returns
    -------
    x : (n,) float
        s itself where the edge is the family's parameter edge; 0 or 1 where the edge ends
        at a VE arc's vertex, the vertex's parameter where it lies inside the edge (a
        junction); else where the family's line meets the edge.
    defined : (n,) bool
        False where the family's line is undefined (a pencil's parameter point at the
        vertex its edge shares with another generator).
    """
    kind, g = np.take(arcs.kind, arc), np.take(arcs.generators, arc, axis=0)
    x = np.empty(len(arc))
    defined = np.ones(len(arc), bool)
    param = np.where(kind == EEE, g[:, 0], g[:, 1]) == edge
    x[param] = s[param]
    # XE: the crossing's parameter on a or b
    cross = np.flatnonzero((kind == XE) & ~param)
    if len(cross):
        cr = edge_crossings(scene)
        on_b = (g[cross, 2] == edge[cross]).astype(np.int64)
        x[cross] = cr.s[cr.find(g[cross, 0], g[cross, 2]), on_b]
    ev = np.take(scene.half_edges.edge_vertices, edge, axis=0)
    at_vertex = (kind == VE) & ~param
    w = g[at_vertex, 0]
    a, b = edge_geometry(scene, edge[at_vertex])
    # a junction's parameter, by the formula of arcs.edge_junctions (its events on the sides)
    inside = np.einsum("ij,ij->i", scene.vertices[w] - a, b - a) / np.einsum("ij,ij->i", b - a, b - a)
    x[at_vertex] = np.where(ev[at_vertex, 0] == w, 0.0, np.where(ev[at_vertex, 1] == w, 1.0, inside))
    rest = np.flatnonzero(~param & ~at_vertex & (kind != XE))
    if len(rest):
        o, d = family_lines(scene, kind[rest], g[rest], s[rest])
        a, b = edge_geometry(scene, edge[rest])
        # p's point at a vertex p shares with q or r: the line through it meeting both is
        # undefined (its direction there is rounding noise, not always exactly zero)
        gr = g[rest]
        at_end = np.where(s[rest] <= 1e-12, 0, np.where(s[rest] >= 1 - 1e-12, 1, -1))
        ev_p = scene.half_edges.edge_vertices[gr[:, 0]]
        w = ev_p[np.arange(len(rest)), np.maximum(at_end, 0)]
        shared = (at_end >= 0) & np.any(scene.half_edges.edge_vertices[gr[:, 1:]] == w[:, None, None], axis=(1, 2))
        defined[rest] = (row_norms(d) > 0) & ~shared
        x[rest], _ = segment_parameter(o, np.where(defined[rest, None], d, 1.0), a, b)
    return x, defined


def _linear_fractional(u, x, at):
    """Evaluate at ``at`` the linear-fractional map through three samples per row.

    Parameters
    ----------
    u, x : (n, 3) float
    at : (n,) float

    Returns
    -------
    (n,) float
    """
    system = np.stack([u, np.ones_like(u), -x * u, -x], axis=2)
    const = np.ptp(x, axis=1) <= 1e-13
    coeff = np.linalg.svd(np.where(const[:, None, None], 1.0, system))[2][:, -1]
    a, b, c, d = coeff.T
    with np.errstate(divide="ignore", invalid="ignore"):
        value = (a * at + b) / (c * at + d)
    return np.where(const, x[:, 1], value)


@dataclass
class Elements:
    """Boundary elements: one side of one arc in one square, a curve of the square with
    its cell on the left (module docstring).

    Attributes
    ----------
    kind : (k,) int8
        ARC, or SIDE, PENCIL1, PENCIL2 (V2's own segments, :func:`segment_pieces`).
    arc : (k,) int
        The V1 arc, or the segment's id (side code or third edge, :func:`segment_lines`).
    side : (k,) int
        0: left of the arc run with s increasing (element +(a + 1)), 1: right (-(a + 1)).
    e1, e2 : (k,) int
    pair : (k, 4) int
        (back kind, back, front kind, front) of the cell on the element's left.
    interval : (k, 2) float
        The piece [s0, s1] of the arc's parameter interval it runs along (the whole
        interval but for VE arcs cut on the square's side, see :func:`side_pieces`).
    start, end : (k, 3) float
        (x1, x2, 1) where the element starts and ends.
    weight : (k, 2) float
        Bézier weight w of x1 and of x2 along the element.
    start_tangent, end_tangent : (k, 3) float
        Unit direction of travel (t1, t2, 0) there.
    """

    kind: np.ndarray
    arc: np.ndarray
    side: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    pair: np.ndarray
    interval: np.ndarray
    start: np.ndarray
    end: np.ndarray
    weight: np.ndarray
    start_tangent: np.ndarray
    end_tangent: np.ndarray

    def __len__(self):
        return len(self.arc)

    def take(self, index):
        index = np.asarray(index)
        index = np.flatnonzero(index) if index.dtype == bool else index
        # np.take: numpy's fancy indexing of (k, 3) rows is several times slower
        return Elements(**{name: np.take(getattr(self, name), index, axis=0) for name in self.__dataclass_fields__})

    @staticmethod
    def concatenate(parts):
        return Elements(**{name: np.concatenate([getattr(p, name) for p in parts]) for name in Elements.__dataclass_fields__})

    @property
    def signed(self):
        """(k,) int: +(a + 1) on the arc's left, -(a + 1) on its right."""
        return np.where(self.side == 0, 1, -1) * (self.arc + 1)


def _curves(scene, arcs, arc, e1, e2, interval, kind=None):
    """Each arc piece's curve in its square, run with s increasing.

    Parameters
    ----------
    arc, e1, e2 : (k,) int
        The arc, or for V2's own segments (kinds SIDE, PENCIL1, PENCIL2) its identity
        (:func:`segment_lines`).
    interval : (k, 2) float
        The piece [s0, s1] of each arc's interval (a segment's: of its free coordinate).
    kind : (k,) int, optional
        ARC (default) or a segment's kind.

    Returns
    -------
    start, middle, end : (k, 2) float
        (x1, x2) at s0, (s0 + s1) / 2 and s1.
    weight : (k, 2) float
        Bézier weight of each coordinate (module docstring).
    """
    if kind is None or np.all(kind == ARC):
        return _arc_curves(scene, arcs, arc, e1, e2, interval)
    seg, rest = np.flatnonzero(kind != ARC), np.flatnonzero(kind == ARC)
    axis, value = segment_lines(scene, kind[seg], arc[seg], e1[seg], e2[seg])
    out = [np.empty((len(arc), 2)) for _ in range(4)]
    for rows, part in ((seg, _segment_curves(axis, value, interval[seg])),
                       (rest, _arc_curves(scene, arcs, arc[rest], e1[rest], e2[rest], interval[rest]))):
        for o, p in zip(out, part):
            o[rows] = p
    return tuple(out)


def _segment_curves(axis, value, interval):
    """Segments x_axis = value of the square as :func:`_curves` gives arcs: the other
    coordinate runs from t0 to t1 (weights 1/2).

    Parameters
    ----------
    axis : (k,) int
        The coordinate held constant (0: x1, 1: x2).
    value : (k,) float
    interval : (k, 2) float
    """
    rows = np.arange(len(axis))
    pts = []
    for t in (interval[:, 0], 0.5 * (interval[:, 0] + interval[:, 1]), interval[:, 1]):
        p = np.empty((len(axis), 2))
        p[rows, axis], p[rows, 1 - axis] = value, t
        pts.append(p)
    return (*pts, np.full((len(axis), 2), 0.5))


def _arc_curves(scene, arcs, arc, e1, e2, interval):
    """:func:`_curves` of V1 arcs."""
    s0, s1 = interval[:, 0], interval[:, 1]
    pts = []
    for s in (s0, 0.5 * (s0 + s1), s1):
        (c1, ok1), (c2, ok2) = _coordinate(scene, arcs, arc, e1, s), _coordinate(scene, arcs, arc, e2, s)
        pts.append((np.stack([c1, c2], axis=1), np.stack([ok1, ok2], axis=1)))
    # an end where the family's line is undefined (a pencil at its edge's shared vertex):
    # the limit, from the map through three inner samples
    bad = np.flatnonzero(~(pts[0][1].all(axis=1) & pts[2][1].all(axis=1)))
    if len(bad):
        fr = np.array([0.25, 0.5, 0.75])
        s_in = (s0[bad, None] + fr * (s1 - s0)[bad, None]).reshape(-1)
        inner = [_coordinate(scene, arcs, np.repeat(arc[bad], 3), np.repeat(e[bad], 3), s_in)[0] for e in (e1, e2)]
        u = np.broadcast_to(fr, (len(bad), 3))
        for k, at in ((0, 0.0), (2, 1.0)):
            for c in (0, 1):
                value = _linear_fractional(u, inner[c].reshape(-1, 3), np.full(len(bad), at))
                broken = ~pts[k][1][bad, c]
                pts[k][0][bad[broken], c] = value[broken]
    pts = [p for p, _ in pts]
    start, middle, end = pts
    span = end - start
    with np.errstate(divide="ignore", invalid="ignore"):
        w = (middle - start) / span
    # a constant coordinate (or one whose middle is off its ends' range: rounding) is linear:
    # a pencil's x1 computed at its ends 4.5e-14 apart, its middle equal to one of them, had w
    # clamped to _W_MIN and an end tangent 0.045 along x1, a loop's corner wrong by 1.3 rad
    # (docs/skeleton.md "EE-cells", rule 18)
    w = np.where(np.isfinite(w) & (np.abs(span) > _CONSTANT_SPAN), w, 0.5)
    return start, middle, end, np.clip(w, _W_MIN, 1 - _W_MIN)


def _bezier_tangents(start, end, weight):
    """Derivatives d(x1, x2)/du at u = 0 and u = 1 of the curves ((k, 2) float each)."""
    span = end - start
    return span * weight / (1 - weight), span * (1 - weight) / weight


def _unit3(t):
    out = np.zeros((len(t), 3))
    size = row_norms(t)
    ok = size > 0
    out[ok, :2] = t[ok] / size[ok, None]
    out[~ok, 0] = 1.0
    return out


def _lift(p):
    return np.concatenate([p, np.ones((len(p), 1))], axis=1)


def element_geometry(scene, arcs, arc, side, e1, e2, pair, interval, kind=None, curves=None):
    """The boundary elements of the given arc sides in the given squares.

    Parameters
    ----------
    arc, side, e1, e2 : (k,) int
        The arc (a segment's id for the segments' kinds), which side of it.
    pair : (k, 4) int
    interval : (k, 2) float
        The piece of each arc's parameter interval the element runs along.
    kind : (k,) int, optional
        ARC (default) or a segment's kind.
    curves : tuple, optional
        Their :func:`_curves`, if known.

    Returns
    -------
    Elements
    """
    arc, side = np.asarray(arc, np.int64), np.asarray(side, np.int64)
    kind = np.full(len(arc), ARC, np.int8) if kind is None else np.asarray(kind, np.int8)
    interval = np.asarray(interval, np.float64).reshape(-1, 2)
    if curves is None:
        curves = _curves(scene, arcs, arc, np.asarray(e1, np.int64), np.asarray(e2, np.int64), interval, kind)
    start, _, end, w = curves
    t0, t1 = _bezier_tangents(start, end, w)
    rev = side == 1
    return Elements(
        kind=kind,
        arc=arc,
        side=side,
        e1=np.asarray(e1, np.int64),
        e2=np.asarray(e2, np.int64),
        pair=np.asarray(pair, np.int64).reshape(-1, 4),
        interval=interval,
        start=_lift(np.where(rev[:, None], end, start)),
        end=_lift(np.where(rev[:, None], start, end)),
        weight=np.where(rev[:, None], 1 - w, w),
        start_tangent=_unit3(np.where(rev[:, None], -t1, t0)),
        end_tangent=_unit3(np.where(rev[:, None], -t0, t1)),
    )


def side_pairs(scene, arcs, arc, e1, e2, interval, kind=None, probe=PROBE, curves=None, obstacles=None):
    """Blocker pairs of the cells on both sides of each arc in its square, by probes.

    The arc's middle point is moved across it, to each side along the curve's normal,
    by PROBE epsilon along the longer-moving edge (clamped into the square), and the
    probe's line judged (:func:`ee_blockers`).

    Parameters
    ----------
    arc, e1, e2 : (k,) int
    interval : (k, 2) float
    kind : (k,) int, optional
        ARC (default) or a segment's kind (``arc`` is then its identity).
    probe : float
        How many epsilon the probes move.
    curves : tuple, optional
        The pieces' :func:`_curves`, if known.
    obstacles : tuple, optional
        (key, start, middle, end, own, floor) of the square's boundary pieces and the probe's
        floor (:func:`probe_room`): each probe then stops halfway to the first of them it would
        cross, but moves at least ``floor`` of its step.

    Returns
    -------
    pairs : (k, 2, 4) int
        (back kind, back, front kind, front) on the left (0) and right (1) of the arc
        run with s increasing.
    bounds : (k, 2) bool
        Whether that side bounds a cell (its probe is valid, the other side's pair differs).
    """
    start, middle, end, w = _curves(scene, arcs, arc, e1, e2, interval, kind) if curves is None else curves
    t0, t1 = _bezier_tangents(start, end, w)
    # tangent at u = 1/2 of the Bézier curve: w0 w1 (c1 - c0) / (1/2)^2 up to a positive factor
    tangent = (end - start) * w * (1 - w)
    tangent = np.where(row_norms(tangent)[:, None] > 0, tangent, t0 + t1)
    tangent /= np.maximum(row_norms(tangent), 1e-300)[:, None]
    left = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    a1, b1 = edge_geometry(scene, e1)
    a2, b2 = edge_geometry(scene, e2)
    length = np.stack([row_norms(b1 - a1), row_norms(b2 - a2)], axis=1)
    # move by PROBE epsilon along the edge that moves most
    step = probe * scene.epsilon / np.max(np.abs(left) * length, axis=1)
    steps = np.stack([step, step])
    if obstacles is not None:
        key, o_start, o_middle, o_end, own, floor = obstacles
        for k, sign in enumerate((1.0, -1.0)):
            steps[k] = probe_room(key, o_start, o_middle, o_end, e1 * (1 << 32) + e2, middle, sign * left, step, own,
                                  floor)
    raw = np.concatenate([middle + steps[0][:, None] * left, middle - steps[1][:, None] * left])
    probes = np.clip(raw, 0.0, 1.0)
    k = len(arc)
    state = ee_blockers(scene, np.tile(e1, 2), np.tile(e2, 2), probes[:, 0], probes[:, 1]).reshape(2, k, 5)
    pairs = np.transpose(state[:, :, 1:], (1, 0, 2))
    valid = state[:, :, 0].T == 1
    # a side off the square (the outer side of a VE arc on the square's side) bounds nothing
    valid &= ~np.any((raw < 0) | (raw > 1), axis=1).reshape(2, k).T
    differ = np.any(pairs[:, 0] != pairs[:, 1], axis=1) | (valid[:, 0] != valid[:, 1])
    bounds = valid & differ[:, None]
    return pairs, bounds


#: A probe stopped by another boundary piece moves at least this fraction of its step (a
#: piece closer than that to the middle is the same curve given twice, or crosses there).
PROBE_ROOM_FLOOR = 0.2
#: The floor in the squares whose loops stay open with PROBE_ROOM_FLOOR (:func:`_finest_probes`).
FINEST_PROBE_FLOOR = 0.02
#: V2 segments of one square closer than this many epsilon along their edge are one line.
SEGMENT_MERGE_EPSILONS = 1


def probe_room(key, start, middle, end, at_key, at, direction, step, own, floor=None):
    """How far each probe may move from its piece's middle before it crosses another boundary
    piece of its square: half the distance to the first crossing, within [step · floor, step]
    (``floor`` PROBE_ROOM_FLOOR by default; FINEST_PROBE_FLOOR where loops stay open with it,
    :func:`_finest_probes`).

    A probe that crosses a boundary judges the cell beyond it. The probes move a fixed
    number of epsilon along the edge that moves most; a cell thinner than that across its
    boundary is jumped over. office(300), pair (0, 571): lines from the floor's edge through
    a cabinet's vertical edge graze a desk's front plane (0.5 degrees), so the desk's
    panels, 3 cm wide, are strips 9e-6 wide along x1 between pencils x1 = c (the planes of
    the panel's vertical edges and the cabinet's edge), and the 5-epsilon probe off the
    piece of the top's bottom edge above a panel (steep in the square, its normal along
    x1) landed beyond the pencil, on the far wall: the pair beside the piece was wrong and
    the loops stayed open. The other pieces are taken as their two chords (start to middle
    to end).

    Parameters
    ----------
    key : (m,) int
        Square (e1 << 32 | e2) of each obstacle piece, ascending.
    start, middle, end : (m, 2) float
    at_key : (k,) int
        Square of each probe.
    at, direction : (k, 2) float
        The piece's middle and the probe's unit direction.
    step : (k,) float
    own : (k,) int
        Each probe's own piece among the obstacles (skipped), -1 for none.
    floor : float, optional

    Returns
    -------
    (k,) float
    """
    floor = PROBE_ROOM_FLOOR if floor is None else floor
    lo = np.searchsorted(key, at_key, "left")
    hi = np.searchsorted(key, at_key, "right")
    return _probe_room(np.ascontiguousarray(start), np.ascontiguousarray(middle), np.ascontiguousarray(end),
                       lo, hi, np.ascontiguousarray(at), np.ascontiguousarray(direction),
                       np.ascontiguousarray(step, dtype=np.float64), np.ascontiguousarray(own, dtype=np.int64),
                       float(floor))


@njit(cache=True)
def _probe_room(start, middle, end, lo, hi, at, direction, step, own, floor):
    out = step.copy()
    for i in range(len(at)):
        px, py = at[i, 0], at[i, 1]
        dx, dy = direction[i, 0], direction[i, 1]
        near = 2.0 * step[i]  # no crossing within the step: the whole step
        for j in range(lo[i], hi[i]):
            if j == own[i]:
                continue
            for c in range(2):
                if c == 0:
                    ax, ay, bx, by = start[j, 0], start[j, 1], middle[j, 0], middle[j, 1]
                else:
                    ax, ay, bx, by = middle[j, 0], middle[j, 1], end[j, 0], end[j, 1]
                ex, ey = bx - ax, by - ay
                den = dx * ey - dy * ex  # cross(direction, chord)
                if den == 0.0:
                    continue
                # at + t direction = a + u (b - a)
                wx, wy = ax - px, ay - py
                t = (wx * ey - wy * ex) / den
                u = (wx * dy - wy * dx) / den
                if u >= 0.0 and u <= 1.0 and t > floor * step[i] and t < near:
                    near = t
        out[i] = max(min(step[i], 0.5 * near), floor * step[i])
    return out


def side_pieces(scene, arcs, arc, e1, e2, segments=None):
    """The arc pieces of each square: every arc whole, but VE arcs (the square's sides,
    and the segments x' = s_w of a junction vertex w) and XE arcs (the segments x' = s_X
    of a crossing point) cut where another arc of the square ends on them, and where
    V2's own segments of the square (if given) cross them.

    A VE arc (w, e2) has no event where the lines through e1 next to w change: e.g. a
    pencil of a face of e1 at w (tangency at e1 flips across it) ends on the side at
    the line through w in that face's plane, which only touches the surface at w, so
    the lines through w see nothing there. Only the side's pieces between such ends
    have one pair beside them. EEE arcs need no cut in general position: their crossings
    with other arcs of the square are V0 nodes or planar events (arcs end there). In the
    squares built again (``segments`` given) they are cut where another arc ends on them
    too (:func:`_eee_cuts`): V1's merged events let one run past such an end.

    Parameters
    ----------
    arc, e1, e2 : (k,) int
        Arc-square incidences (:func:`arc_squares`).
    segments : Segments, optional
        V2's segments of these squares (:func:`open_segments`).

    Returns
    -------
    arc, e1, e2 : (m,) int
    interval : (m, 2) float
    curves : tuple
        The pieces' :func:`_curves` (an EEE arc's whole, as computed for the cuts).
    """
    interval = arcs.interval[arc]
    curves = _curves(scene, arcs, arc, e1, e2, interval)
    start, _, end, _ = curves
    tol = join_tolerance(scene, e1, e2)
    pair_key = e1 * (1 << 32) + e2
    # each VE or XE row is a segment x1 = const (its edge is e2) or x2 = const; s runs along it
    ve = np.flatnonzero(arcs.kind[arc] != EEE)
    const = np.where(arcs.generators[arc[ve], 1] == e2[ve], 0, 1)
    value = start[ve, const]
    # ends of the other (EEE) rows of the same square lying on the segment: (row, position along it)
    eee = np.flatnonzero(arcs.kind[arc] == EEE)
    ends = np.concatenate([start[eee], end[eee]])
    owner = np.concatenate([eee, eee])
    order = np.argsort(pair_key[owner], kind="stable")
    ends, owner = ends[order], owner[order]
    rows, at = _same_square(pair_key[owner], pair_key[ve])
    c = const[rows]
    on = np.abs(ends[at, c] - value[rows]) <= tol[owner[at]]
    cut_row, cut_pos = [rows[on]], [ends[at[on], 1 - c[on]]]
    if segments is not None:
        # V2's segments of the other coordinate cross the row where their coordinate is theirs
        rows, at = _same_square(segments.e1 * (1 << 32) + segments.e2, pair_key[ve])
        across = segments.axis[at] != const[rows]
        cut_row.append(rows[across])
        cut_pos.append(segments.value[at[across]])
    piece_row, piece_interval = _cut_intervals(interval[ve], tol[ve], np.concatenate(cut_row), np.concatenate(cut_pos))
    cut = ve[piece_row]
    if segments is not None:
        # in the squares built again, EEE arcs too are cut where another arc ends on them
        eee_row, eee_interval = _eee_cuts(scene, arcs, eee, pair_key, start, end, curves[3], tol, interval)
        whole = eee[np.bincount(eee_row, minlength=len(eee)) == 1]
        split = np.bincount(eee_row, minlength=len(eee))[eee_row] > 1
        cut = np.concatenate([eee[eee_row[split]], cut])
        piece_interval = np.concatenate([eee_interval[split], piece_interval])
    else:
        whole = eee
    rows = np.concatenate([whole, cut])
    ivl = np.concatenate([interval[whole], piece_interval])
    order = np.lexsort([ivl[:, 0], arc[rows], e2[rows], e1[rows]])
    rows, ivl = rows[order], ivl[order]
    piece_curves = _curves(scene, arcs, arc[cut], e1[cut], e2[cut], piece_interval)
    curves = tuple(np.concatenate([c[whole], p])[order] for c, p in zip(curves, piece_curves))
    return arc[rows], e1[rows], e2[rows], ivl, curves


#: (EEE arc, end) candidates judged at once by :func:`_eee_cuts`.
EEE_CUT_CHUNK = 1 << 20


def _eee_cuts(scene, arcs, eee, pair_key, start, end, weight, tol, interval):
    """The pieces of EEE arcs cut where another arc of their square ends on them (rule 11 of
    docs/skeleton.md "Furnished buildings"): an end lying within the join tolerance of the
    curve, farther than it from the curve's ends. V1 merges events 4 epsilon apart along
    a family's edge, so an EEE arc may run on past a node at which the cell beside it ends
    (office(300), pair (3, 41): the arc EEE (3, 41, 238) runs 1.2e-4 of the square past the
    corner where the arcs bounding a thin cell beside it end).

    Returns
    -------
    piece_row : (p,) int
        Index into ``eee`` of each piece, ascending.
    piece_interval : (p, 2) float
    """
    ends = np.concatenate([start, end])
    owner = np.tile(np.arange(len(start)), 2)
    order = np.argsort(pair_key[owner], kind="stable")
    ends, owner = ends[order], owner[order]
    sorted_key = pair_key[owner]
    # per coordinate: SQUARE_JOIN_EPSILONS epsilon along its own edge (rule 8's reason: the
    # join tolerance, epsilon along the shorter edge, is 64 epsilon along a 12-long one)
    length = scene.cached("edge_lengths", _edge_lengths)
    key = pair_key[eee]
    tol_axis = SQUARE_JOIN_EPSILONS * scene.epsilon / np.stack([length[key >> 32], length[key & ((1 << 32) - 1)]], axis=1)
    # every (arc, end) of a square at once costs arcs x ends of the largest squares: in chunks
    count = np.searchsorted(sorted_key, key, "right") - np.searchsorted(sorted_key, key, "left")
    bounds = np.searchsorted(np.cumsum(count), np.arange(EEE_CUT_CHUNK, count.sum() + EEE_CUT_CHUNK, EEE_CUT_CHUNK))
    bounds = unique_sorted(np.r_[0, np.minimum(bounds + 1, len(eee)), len(eee)])
    cut_rows, cut_u = [np.zeros(0, np.int64)], [np.zeros(0)]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        part = np.arange(lo, hi)
        rows, at = _same_square(sorted_key, key[part])
        rows = part[rows]
        keep = owner[at] != eee[rows]
        rows, at = rows[keep], at[keep]
        r = eee[rows]
        span = end[r] - start[r]
        k = (np.abs(span[:, 1]) > np.abs(span[:, 0])).astype(np.int64)  # the coordinate varying more
        c0, c1, q = start[r, k], end[r, k], ends[at, k]
        t_k = tol_axis[rows, k]
        inside = (q - np.minimum(c0, c1) > t_k) & (np.maximum(c0, c1) - q > t_k)
        rows, at, r, k, c0, c1, q = rows[inside], at[inside], r[inside], k[inside], c0[inside], c1[inside], q[inside]
        w = weight[r, k]
        a, b = (1 - w) * (q - c0), w * (c1 - q)  # _bezier_inverse
        u = a / (a + b)
        wo = weight[r, 1 - k]
        p, m = (1 - u) * (1 - wo), u * wo  # _bezier
        other = (p * start[r, 1 - k] + m * end[r, 1 - k]) / (p + m)
        # on the curve: within one epsilon across it (rule 10: lines farther apart are two)
        on = np.abs(other - ends[at, 1 - k]) <= tol_axis[rows, 1 - k] * (SEGMENT_MERGE_EPSILONS / SQUARE_JOIN_EPSILONS)
        cut_rows.append(rows[on])
        cut_u.append(u[on])
    rows, u = np.concatenate(cut_rows), np.concatenate(cut_u)
    s0, s1 = interval[eee, 0], interval[eee, 1]
    # the tolerance in s: the join tolerance over the coordinate's change along the arc
    change = np.abs(end[eee] - start[eee]).max(axis=1)
    tol_s = tol[eee] * (s1 - s0) / np.maximum(change, 1e-300)
    return _cut_intervals(interval[eee], tol_s, rows, s0[rows] + u * (s1[rows] - s0[rows]))


def _same_square(sorted_key, key):
    """Every (i, j) with sorted_key[j] == key[i] ((m,) int each, sorted_key ascending)."""
    lo = np.searchsorted(sorted_key, key, "left")
    return expand_ranges(lo, np.searchsorted(sorted_key, key, "right") - lo)


def _cut_intervals(interval, tol, rows, pos):
    """Intervals cut at points: the pieces between consecutive cuts.

    Parameters
    ----------
    interval : (n, 2) float
        [s0, s1] each.
    tol : (n,) float
        Cuts closer than this to an end or to each other are one point (the end wins).
    rows, pos : (m,) int, (m,) float
        Cut points: the interval and the position in it.

    Returns
    -------
    piece_row : (p,) int
        The interval each piece comes from, in order of the intervals, then of s.
    piece_interval : (p, 2) float
    """
    s0, s1 = interval[:, 0], interval[:, 1]
    # the cuts strictly inside their interval (farther than tol from its ends)
    inner = (pos > s0[rows] + tol[rows]) & (pos < s1[rows] - tol[rows])
    rows, pos = rows[inner], pos[inner]
    # merge cuts closer than tol, then pieces between consecutive cut points
    rows_all = np.concatenate([np.arange(len(s0)), rows, np.arange(len(s0))])
    pos_all = np.concatenate([s0, pos, s1])
    order = np.lexsort([pos_all, rows_all])
    rows_all, pos_all = rows_all[order], pos_all[order]
    keep = np.ones(len(rows_all), bool)
    keep[1:] = (rows_all[1:] != rows_all[:-1]) | (pos_all[1:] - pos_all[:-1] > tol[rows_all[1:]])
    last = np.ones(len(rows_all), bool)
    last[:-1] = rows_all[1:] != rows_all[:-1]
    keep[last] = True  # always keep each row's s1
    rows_all, pos_all = rows_all[keep], pos_all[keep]
    nxt = np.flatnonzero(rows_all[1:] == rows_all[:-1])
    piece_interval = np.stack([pos_all[nxt], pos_all[nxt + 1]], axis=1)
    nonempty = piece_interval[:, 1] > piece_interval[:, 0]
    return rows_all[nxt][nonempty], piece_interval[nonempty]


# --------------------------------------------------------------------------------------
# V2's own segments: boundaries of a square that are no V1 arc (degenerate scenes)


@dataclass
class Segments:
    """Candidate boundaries of some squares that V1 may lack: segments x_axis = value right
    across the square (:func:`open_segments`), sorted by (e1, e2, axis, value).

    Attributes
    ----------
    kind : (n,) int8
        SIDE, PENCIL1 (x1 constant) or PENCIL2 (x2 constant).
    ident : (n,) int
        The side's code (SIDE_CODES), or the pencil's third edge.
    e1, e2 : (n,) int
        The square.
    axis : (n,) int
        The coordinate held constant: 0 (x1) or 1 (x2).
    value : (n,) float
        Its value (:func:`segment_lines`).
    """

    kind: np.ndarray
    ident: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    axis: np.ndarray
    value: np.ndarray

    def take(self, index):
        return Segments(**{name: getattr(self, name)[index] for name in self.__dataclass_fields__})


def segment_lines(scene, kind, ident, e1, e2):
    """The line of the square each of V2's segments lies on.

    A side k holds coordinate k // 2 at k % 2 (SIDE_CODES). A pencil is the lines through
    a point P of one edge of the square lying in the plane of the other edge and a third
    edge coplanar with it (PENCIL1: P = e1(c), the plane of e2 and the third edge, the
    segment x1 = c; PENCIL2: P = e2(c), x2 = c); c by :func:`pencil_value`.

    Parameters
    ----------
    kind : (k,) int
    ident : (k,) int
        Side code or third edge.
    e1, e2 : (k,) int

    Returns
    -------
    axis : (k,) int
    value : (k,) float
    """
    kind, ident = np.asarray(kind), np.asarray(ident, np.int64)
    side = kind == SIDE
    axis = np.where(side, ident // 2, kind - PENCIL1)
    value = (ident % 2).astype(np.float64)
    p = np.flatnonzero(~side)
    if len(p):
        on1 = axis[p] == 0
        value[p] = pencil_value(scene, np.where(on1, e1[p], e2[p]), np.where(on1, e2[p], e1[p]), ident[p])
    return axis, value


def pencil_value(scene, crossed, held, third):
    """Where the line of edge ``crossed`` crosses the plane of the coplanar edges ``held``
    and ``third``: its parameter on ``crossed``.

    The plane's normal is d_h × d_t, or d_h × (a_t - a_h) for parallel edges; the line
    a + x (b - a) meets it at x = n · (a_h - a) / n · (b - a).

    Parameters
    ----------
    crossed, held, third : (k,) int

    Returns
    -------
    (k,) float
        NaN where the line runs parallel to the plane or the two edges are collinear.
    """
    a, b = edge_geometry(scene, crossed)
    ah, bh = edge_geometry(scene, held)
    at, bt = edge_geometry(scene, third)
    dh, dt = bh - ah, bt - at
    n = np.cross(dh, dt)
    parallel = row_norms(n) <= ANGLE_TOLERANCE * row_norms(dh) * row_norms(dt)
    n = np.where(parallel[:, None], np.cross(dh, at - ah), n)
    den = np.einsum("ij,ij->i", n, b - a)
    ok = np.abs(den) > PARALLEL_TOLERANCE * row_norms(n) * row_norms(b - a)
    return np.where(ok, np.einsum("ij,ij->i", n, ah - a) / np.where(ok, den, 1.0), np.nan)


def _pencils_through(scene, crossed, held, x, tol):
    """The pencils whose segment passes each point: third edges t (generator edges coplanar
    with ``held``) whose plane with ``held`` crosses ``crossed`` within ``tol`` of x.

    Prefilter: both ends of t lie near the plane through held's line and q = crossed(x).
    Moving q by tol along ``crossed`` (|δ| = tol |crossed|) turns that plane about held's
    line by at most |δ| / r_q (r_q: q's distance from the line), which moves a point at
    distance r by that angle times r; four times that, plus epsilon, is the test. Then
    exactly: t not skew to ``held`` (coplanar, arcs' rule: ``generators.skew_edges``) and
    :func:`pencil_value` within tol of x, strictly inside the edge. One numba pass over
    the points and the generator edges (:func:`_pencil_kernel`): the candidates passing the
    prefilter are many (every edge of a floor for a point near the floor's plane), so they
    are judged where they are found, with the arithmetic of those two functions.

    Parameters
    ----------
    crossed, held : (n,) int
    x, tol : (n,) float

    Returns
    -------
    row : (m,) int
        The point.
    third : (m,) int
    value : (m,) float
        The pencil's parameter on ``crossed``.
    """
    ge = scene.generator_edges
    a, b = edge_geometry(scene, crossed)
    q = a + x[:, None] * (b - a)
    ah, bh = edge_geometry(scene, held)
    unit = (bh - ah) / row_norms(bh - ah)[:, None]
    normal = np.cross(unit, q - ah)
    r_q = row_norms(normal)
    normal /= np.maximum(r_q, 1e-300)[:, None]
    turn = 4 * tol * row_norms(b - a) / np.maximum(r_q, 1e-300)
    ta, tb = edge_geometry(scene, ge)
    ev = scene.half_edges.edge_vertices
    # x contiguous: a column of the caller's points is strided unless it holds one point, and
    # each layout is a signature of its own (compiled mid-build if the warm-up had the other)
    x = np.ascontiguousarray(x, dtype=np.float64)
    return _pencil_kernel(normal, unit, turn, scene.epsilon, a, b, ah, bh, ev[held], np.asarray(crossed, np.int64),
                          np.asarray(held, np.int64), x, tol, ta, tb, ev[ge], np.asarray(ge, np.int64),
                          ANGLE_TOLERANCE, PARALLEL_TOLERANCE)


@njit(cache=True)
def _pencil_kernel(normal, unit, turn, eps, a, b, ah, bh, held_v, crossed, held, x, tol, ta, tb, third_v, ge,
                   angle_tol, parallel_tol):
    """:func:`_pencils_through` for each point i and generator edge j: the prefilter (both ends
    of t within turn[i] r + eps of plane i, r their distance from held's line), then
    ``~skew_edges(held, t)`` and :func:`pencil_value` within tol[i] of x[i], each with the
    numpy functions' arithmetic (``tests/test_buildings.py`` checks they agree)."""
    cap = 1024
    out_row = np.empty(cap, np.int64)
    out_third = np.empty(cap, np.int64)
    out_value = np.empty(cap)
    m = 0
    for i in range(len(normal)):
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        u0, u1, u2 = unit[i, 0], unit[i, 1], unit[i, 2]
        dh0, dh1, dh2 = bh[i, 0] - ah[i, 0], bh[i, 1] - ah[i, 1], bh[i, 2] - ah[i, 2]
        dh_len = np.sqrt(dh0 * dh0 + dh1 * dh1 + dh2 * dh2)
        # skew_edges' unit vector of held
        h0, h1, h2 = dh0 / dh_len, dh1 / dh_len, dh2 / dh_len
        d0, d1, d2 = b[i, 0] - a[i, 0], b[i, 1] - a[i, 1], b[i, 2] - a[i, 2]
        d_len = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        for j in range(len(ta)):
            near = True
            for t in (ta, tb):
                r0, r1, r2 = t[j, 0] - ah[i, 0], t[j, 1] - ah[i, 1], t[j, 2] - ah[i, 2]
                off = abs(n0 * r0 + n1 * r1 + n2 * r2)
                c0, c1, c2 = u1 * r2 - u2 * r1, u2 * r0 - u0 * r2, u0 * r1 - u1 * r0
                near &= off <= turn[i] * np.sqrt(c0 * c0 + c1 * c1 + c2 * c2) + eps
            if not near or ge[j] == held[i] or ge[j] == crossed[i]:
                continue
            # generators.skew_edges(held, t): no shared vertex, not parallel, not coplanar
            share = False
            for p in range(2):
                for r in range(2):
                    share |= held_v[i, p] == third_v[j, r]
            dt0, dt1, dt2 = tb[j, 0] - ta[j, 0], tb[j, 1] - ta[j, 1], tb[j, 2] - ta[j, 2]
            dt_len = np.sqrt(dt0 * dt0 + dt1 * dt1 + dt2 * dt2)
            v0, v1, v2 = dt0 / dt_len, dt1 / dt_len, dt2 / dt_len
            c0, c1, c2 = h1 * v2 - h2 * v1, h2 * v0 - h0 * v2, h0 * v1 - h1 * v0
            size = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            w0, w1, w2 = ta[j, 0] - ah[i, 0], ta[j, 1] - ah[i, 1], ta[j, 2] - ah[i, 2]
            if not share and size > angle_tol and abs(w0 * c0 + w1 * c1 + w2 * c2) / size > eps:
                continue  # skew
            # pencil_value(crossed, held, t)
            p0, p1, p2 = dh1 * dt2 - dh2 * dt1, dh2 * dt0 - dh0 * dt2, dh0 * dt1 - dh1 * dt0
            if np.sqrt(p0 * p0 + p1 * p1 + p2 * p2) <= angle_tol * dh_len * dt_len:
                p0, p1, p2 = dh1 * w2 - dh2 * w1, dh2 * w0 - dh0 * w2, dh0 * w1 - dh1 * w0
            den = p0 * d0 + p1 * d1 + p2 * d2
            if not abs(den) > parallel_tol * np.sqrt(p0 * p0 + p1 * p1 + p2 * p2) * d_len:
                continue
            e0, e1, e2 = ah[i, 0] - a[i, 0], ah[i, 1] - a[i, 1], ah[i, 2] - a[i, 2]
            value = (p0 * e0 + p1 * e1 + p2 * e2) / den
            if not (abs(value - x[i]) <= tol[i] and value > tol[i] and value < 1 - tol[i]):
                continue
            if m == cap:
                cap *= 2
                out_row = np.concatenate((out_row, np.empty(cap - m, np.int64)))
                out_third = np.concatenate((out_third, np.empty(cap - m, np.int64)))
                out_value = np.concatenate((out_value, np.empty(cap - m)))
            out_row[m], out_third[m], out_value[m] = i, ge[j], value
            m += 1
    return out_row[:m], out_third[:m], out_value[:m]


def open_segments(scene, el, order, chain_offsets):
    """V2's candidate segments of the squares whose loops stayed open: the four sides, and
    the pencils through the open chains' ends.

    A chain stays open where V1 has no arc for a piece of its cell's boundary, and its
    ends lie on that piece. Two such boundaries of degenerate scenes are lines of the
    square x' = const, the lines through one point of e' and the other edge e:

    * a *side* (x1 = 0 or 1, x2 = 0 or 1) where the lines through the edge's end w hold no
      segment, yet the lines next to them do (boxes_on_floor, two edges of one box such
      as (6, 15): the side x1 = 1 is the lines from vertex 8 to edge 15, lying on the
      box's face x = 3, while the lines next to them run through the box from edge to
      edge), so V1 has no VE arc there;
    * a *pencil*: the lines through the point P where e' crosses the plane of e and a
      third edge t coplanar with e (a face of e: tangency at e flips across it, Durand's
      face-edge event; an edge parallel to e: every line through P and e meets t). V1
      builds a pencil only as the EEE family of an event V0 found on it; in degenerate
      scenes those are dropped (boxes_on_floor, pair (1, 12): edge 1 crosses the plane
      x = 3 of edge 12's face at x1 = 0.3, and V1 has that pencil only up to x2 = 0.5).

    Parameters
    ----------
    el : Elements
    order, chain_offsets : (k,) int, (o + 1,) int
        The open chains (:func:`loops.form_loops`).

    Returns
    -------
    Segments
        Every side of each square holding a chain, and every pencil whose segment passes
        within the join tolerance of a chain's end (strictly inside its edge); of pencils
        on one line (within the tolerance) the first by value.
    """
    first, last = order[chain_offsets[:-1]], order[chain_offsets[1:] - 1]
    e1 = np.concatenate([el.e1[first], el.e1[last]])
    e2 = np.concatenate([el.e2[first], el.e2[last]])
    point = np.concatenate([el.start[first, :2], el.end[last, :2]])
    tol = join_tolerance(scene, e1, e2)
    squares = unique_sorted(e1 * (1 << 32) + e2)
    parts = [(np.full(4 * len(squares), SIDE), np.tile(np.arange(4), len(squares)), np.repeat(squares, 4),
              np.tile([0, 0, 1, 1], len(squares)), np.tile([0.0, 1.0, 0.0, 1.0], len(squares)))]
    for axis, crossed, held in ((0, e1, e2), (1, e2, e1)):
        row, third, value = _pencils_through(scene, crossed, held, point[:, axis], tol)
        parts.append((np.full(len(row), PENCIL1 + axis), third, e1[row] * (1 << 32) + e2[row],
                      np.full(len(row), axis), value))
    kind, ident, key, axis, value = (np.concatenate(p) for p in zip(*parts))
    order = np.lexsort([ident, kind, value, axis, key])
    kind, ident, key, axis, value = kind[order], ident[order], key[order], axis[order], value[order]
    e1, e2 = key >> 32, key & ((1 << 32) - 1)
    # one segment per line of the square: the first of values closer than the tolerance
    tol = segment_tolerance(scene, e1, e2, axis)
    keep = np.ones(len(key), bool)
    keep[1:] = (key[1:] != key[:-1]) | (axis[1:] != axis[:-1]) | (value[1:] - value[:-1] > tol[1:])
    return Segments(kind[keep].astype(np.int8), ident[keep], e1[keep], e2[keep], axis[keep], value[keep])


def segment_tolerance(scene, e1, e2, axis):
    """(k,) float: how close two of V2's segments x_axis = c of one square are one line:
    SQUARE_JOIN_EPSILONS epsilon along the edge c runs on, in square units.

    Not the join tolerance (epsilon along the shorter edge of the pair, in both coordinates):
    office(300), pair (1, 242) (the floor's 12-long edge and a 0.03-long edge under a desk
    top) merged the pencils x1 = 0.83075 and x1 = 0.83184 of two planes 1.3 cm apart (4e-3 of
    the square is 5 cm along the floor's edge), and the one bounding the cell was lost.

    Parameters
    ----------
    e1, e2, axis : (k,) int
    """
    length = scene.cached("edge_lengths", _edge_lengths)
    return SEGMENT_MERGE_EPSILONS * scene.epsilon / length[np.where(axis == 0, e1, e2)]


def segment_pieces(scene, arcs, segments, pieces, el, curves=None):
    """The pieces of V2's segments that may bound a cell: the parts no V1 arc runs along,
    cut where the square's other boundaries meet them.

    Covered: the arc pieces lying on the segment's line (both ends within the join
    tolerance of it; each coordinate is monotone along an arc, so the whole piece is).
    Cuts of the rest: the elements' ends on the segment and their crossings of it (where
    the element's monotone Bézier coordinate takes the segment's value, inverted in
    closed form), the other segments of the square crossing it, and for a pencil the lines
    through its point and the ends of its third edge (where its lines stop meeting it).
    Each is a closed-form point of an element or an end of an arc piece: nothing is
    sampled. Between two cuts one pair lies on each side, found by the probes
    (:func:`side_pairs`) like every piece's; a side's outer probe is off the square.

    Parameters
    ----------
    segments : Segments
    pieces : tuple
        (arc, e1, e2, interval) of the squares' arcs (:func:`side_pieces`).
    el : Elements
        Their elements.
    curves : tuple, optional
        The pieces' :func:`_curves`, if known.

    Returns
    -------
    ident, e1, e2 : (m,) int
    interval : (m, 2) float
        The piece [t0, t1] of the segment's free coordinate.
    kind : (m,) int8
    """
    seg_key = segments.e1 * (1 << 32) + segments.e2
    tol = join_tolerance(scene, segments.e1, segments.e2)
    axis, value = segments.axis, segments.value
    arc, p_e1, p_e2, interval = pieces
    start, _, end, _ = _curves(scene, arcs, arc, p_e1, p_e2, interval) if curves is None else curves
    # arc pieces on a segment's line: the free coordinate's range
    row, seg = _same_square(seg_key, p_e1 * (1 << 32) + p_e2)
    a = axis[seg]
    on = (np.abs(start[row, a] - value[seg]) <= tol[seg]) & (np.abs(end[row, a] - value[seg]) <= tol[seg])
    row, seg, a = row[on], seg[on], a[on]
    lo, hi = np.minimum(start[row, 1 - a], end[row, 1 - a]), np.maximum(start[row, 1 - a], end[row, 1 - a])
    order = np.lexsort([lo, seg])
    gap_seg, gap_lo, gap_hi = _uncovered(seg[order], lo[order], hi[order], len(seg_key), tol)
    # cuts: each element's ends on the segment and its crossing of it
    cut_seg, cut_pos = [], []
    row, seg = _same_square(seg_key, el.e1 * (1 << 32) + el.e2)
    a, v = axis[seg], value[seg]
    for p in (el.start, el.end):
        near = np.abs(p[row, a] - v) <= tol[seg]
        cut_seg.append(seg[near])
        cut_pos.append(p[row[near], 1 - a[near]])
    c0, c1 = el.start[row, a], el.end[row, a]
    across = np.flatnonzero((c0 - v) * (c1 - v) < 0)
    r, a, v = row[across], a[across], v[across]
    w = el.weight[r, a]
    u = (1 - w) * (v - c0[across]) / ((1 - w) * (v - c0[across]) + w * (c1[across] - v))
    wo, o0, o1 = el.weight[r, 1 - a], el.start[r, 1 - a], el.end[r, 1 - a]
    cut_seg.append(seg[across])
    cut_pos.append(((1 - u) * (1 - wo) * o0 + u * wo * o1) / ((1 - u) * (1 - wo) + u * wo))
    # the other segments of the square crossing it
    row, seg = _same_square(seg_key, seg_key)
    across = axis[row] != axis[seg]
    cut_seg.append(row[across])
    cut_pos.append(value[seg[across]])
    # a pencil's lines through the ends of its third edge
    pencil = np.flatnonzero(segments.kind != SIDE)
    held = np.where(axis[pencil] == 0, segments.e2[pencil], segments.e1[pencil])
    crossed = np.where(axis[pencil] == 0, segments.e1[pencil], segments.e2[pencil])
    a, b = edge_geometry(scene, crossed)
    p = a + value[pencil, None] * (b - a)
    ah, bh = edge_geometry(scene, held)
    for t in edge_geometry(scene, segments.ident[pencil]):
        x, _ = segment_parameter(p, t - p, ah, bh)
        ok = np.isfinite(x)
        cut_seg.append(pencil[ok])
        cut_pos.append(x[ok])
    # the gaps of each segment cut there
    cut_seg, cut_pos = np.concatenate(cut_seg), np.concatenate(cut_pos)
    cut, gap = _same_square(gap_seg, cut_seg)
    piece, piece_interval = _cut_intervals(np.stack([gap_lo, gap_hi], axis=1), tol[gap_seg], gap, cut_pos[cut])
    s = gap_seg[piece]
    return segments.ident[s], segments.e1[s], segments.e2[s], piece_interval, segments.kind[s]


@njit(cache=True)
def _uncovered(seg, lo, hi, n, tol):
    """The parts of [0, 1] no interval covers, longer than tol, for each of n segments.

    Parameters
    ----------
    seg : (k,) int
        The segment of each covering interval, sorted (then by lo).
    lo, hi : (k,) float
    n : int
    tol : (n,) float

    Returns
    -------
    gap_seg : (g,) int
        Ascending.
    gap_lo, gap_hi : (g,) float
        Ends of the gaps: 0, 1, or ends of the covering intervals.
    """
    out_seg = np.empty(len(seg) + n, np.int64)
    out_lo = np.empty(len(seg) + n)
    out_hi = np.empty(len(seg) + n)
    g = 0
    k = 0
    for s in range(n):
        reach = 0.0
        while k < len(seg) and seg[k] == s:
            if lo[k] - reach > tol[s]:
                out_seg[g], out_lo[g], out_hi[g] = s, reach, lo[k]
                g += 1
            reach = max(reach, hi[k])
            k += 1
        if 1.0 - reach > tol[s]:
            out_seg[g], out_lo[g], out_hi[g] = s, reach, 1.0
            g += 1
    return out_seg[:g], out_lo[:g], out_hi[:g]


def boundary_elements(scene, arcs, squares=None, segments=None, floor=None):
    """Every boundary element of every square, sorted by (e1, e2, kind, arc, interval, side):
    the arcs' (:func:`side_pieces`), then V2's own segments' (:func:`segment_pieces`), each
    boundary given twice kept once (:func:`_unique`).

    Parameters
    ----------
    squares : tuple of (k,) int, optional
        (arc, e1, e2) incidences, every square whole: default all (:func:`arc_squares`).
    segments : Segments, optional
        V2's segments of these squares (:func:`open_segments`): none by default.
    floor : float, optional
        With segments, the least fraction of its step a fine probe moves (:func:`probe_room`):
        PROBE_ROOM_FLOOR by default.

    Returns
    -------
    Elements
    """
    *pieces, curves = side_pieces(scene, arcs, *(arc_squares(scene, arcs) if squares is None else squares), segments)
    kind = np.full(len(pieces[0]), ARC, np.int8)
    if segments is None:
        return _unique(scene, _bounding_elements(scene, arcs, *pieces, kind, PROBE, curves))
    # the fine probes stop short of the square's other pieces (:func:`probe_room`): first the
    # arcs' pieces among themselves, then V2's segment pieces among all of them
    key = pieces[1] * (1 << 32) + pieces[2]
    start, middle, end, _ = curves
    floor = PROBE_ROOM_FLOOR if floor is None else floor
    el = _bounding_elements(scene, arcs, *pieces, kind, FINE_PROBE, curves,
                            (key, start, middle, end, np.arange(len(key)), floor))
    seg = segment_pieces(scene, arcs, segments, pieces, el, curves)
    seg_curves = _curves(scene, arcs, *seg)
    all_key = np.concatenate([key, seg[1] * (1 << 32) + seg[2]])
    by_square = np.argsort(all_key, kind="stable")
    where = np.empty(len(all_key), np.int64)
    where[by_square] = np.arange(len(all_key))
    both = tuple(np.concatenate([c, s])[by_square] for c, s in zip(curves[:3], seg_curves[:3]))
    more = _bounding_elements(scene, arcs, *seg, FINE_PROBE, seg_curves,
                              (all_key[by_square], *both, where[len(key):], floor))
    el = Elements.concatenate([el, more])
    return _unique(scene, el.take(_element_order(el)))


def _unique(scene, el):
    """The elements with each boundary given twice kept once (:func:`loops.unique_elements`;
    two pencils of one plane through one point of the other edge, e.g. of two coplanar edges
    of a floor: docs/skeleton.md "Furnished buildings"). Elements sorted by square; squares
    are independent, so they are judged UNIQUE_CHUNK elements at a time (whole squares), which
    bounds the memory of the neighbour search."""
    key = el.e1 * (1 << 32) + el.e2
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    cuts = start[np.searchsorted(start, np.arange(UNIQUE_CHUNK, len(key), UNIQUE_CHUNK), "right") - 1]
    bounds = np.r_[0, unique_sorted(cuts[cuts > 0]), len(key)]
    tol = join_tolerance(scene, el.e1, el.e2)
    keep = []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        part = el.take(np.arange(lo, hi))
        keep.append(lo + unique_elements(part, _groups(part), tol[lo:hi], lambda i, j: one_curve(scene, part, i, j)))
    return el.take(np.concatenate(keep))


#: Elements judged at once by :func:`_unique` (whole squares).
UNIQUE_CHUNK = 1 << 18


def one_curve(scene, el, i, j):
    """Whether elements j, whose ends agree with i's within the join tolerance, lie on i's
    curve: j's middle (:func:`chord_middles`) within epsilon of the point of i's curve with
    the same value of the coordinate that changes more along i, across it (the other
    coordinate, in length along its edge), and the two overlapping along that coordinate by
    more than half the longer one.

    Two families whose lines coincide give one boundary twice, with one pair beside it;
    two curves closer than the join tolerance at both ends but more than epsilon apart
    between them are distinct boundaries (office(300), pair (41, 579): a pencil at x1 =
    0.99953 and the side x1 = 1, 7e-4 apart along the 1.5-long e1, bound a sliver cell).

    Parameters
    ----------
    el : Elements
    i, j : (m,) int

    Returns
    -------
    (m,) bool
    """
    middle = chord_middles(el.take(j))
    span = el.end[i, :2] - el.start[i, :2]
    k = (np.abs(span[:, 1]) > np.abs(span[:, 0])).astype(np.int64)
    rows = np.arange(len(i))
    c0, c1, w = el.start[i, k], el.end[i, k], el.weight[i, k]
    c = np.clip(middle[rows, k], np.minimum(c0, c1), np.maximum(c0, c1))
    a, b = (1 - w) * (c - c0), w * (c1 - c)  # _bezier_inverse: u = a / (a + b)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(a + b != 0, a / (a + b), 0.5)
    other = _bezier(el.start[i, 1 - k], el.end[i, 1 - k], el.weight[i, 1 - k], u)
    length = scene.cached("edge_lengths", _edge_lengths)[np.where(k == 0, el.e2[i], el.e1[i])]
    # and overlap along it by more than half the longer: consecutive pieces of one side shorter
    # than the join tolerance (cut at coplanar events 6e-5 apart) meet, they do not repeat
    lo_i, hi_i = np.minimum(c0, c1), np.maximum(c0, c1)
    d0, d1 = el.start[j, k], el.end[j, k]
    lo_j, hi_j = np.minimum(d0, d1), np.maximum(d0, d1)
    overlap = np.minimum(hi_i, hi_j) - np.maximum(lo_i, lo_j)
    return (np.abs(other - middle[rows, 1 - k]) * length <= scene.epsilon) & (
        overlap > 0.5 * np.maximum(hi_i - lo_i, hi_j - lo_j))


def chord_middles(el):
    """The point of each element's curve where the coordinate that changes more along it
    takes the middle value of its ends ((k, 2) float).

    It depends on the curve alone, not on its family's parameter: a VE arc through a
    junction vertex w of e1 (s is x2, linear) and a pencil through the same point of e1 (s
    runs along the pencil's third edge: x2 is linear-fractional in s) give one segment
    x1 = s_w of the square; the points at their parameters' middles differ (floor_plan((1,
    1)): 47 such segments, each left an open chain with its duplicate's pair), these do
    not. Each coordinate is monotone along an element, so the point is unique."""
    span = el.end[:, :2] - el.start[:, :2]
    k = (np.abs(span[:, 1]) > np.abs(span[:, 0])).astype(np.int64)
    rows = np.arange(len(k))
    c0, c1 = el.start[rows, k], el.end[rows, k]
    w = el.weight[rows, k]
    # _bezier_inverse at the middle value c = (c0 + c1) / 2: a / (a + b) with a = (1 - w)(c - c0),
    # b = w (c1 - c), both proportional to (c1 - c0) / 2
    u = 1 - w  # a point-like element (c0 = c1) takes the same value
    out = np.empty((len(k), 2))
    out[rows, k] = 0.5 * (c0 + c1)
    out[rows, 1 - k] = _bezier(el.start[rows, 1 - k], el.end[rows, 1 - k], el.weight[rows, 1 - k], u)
    return out


def _element_order(el):
    """(k,) int: the order of :func:`boundary_elements`: by (e1, e2, kind, arc, interval, side)."""
    return np.lexsort([el.side, el.interval[:, 0], el.arc, el.kind, el.e2, el.e1])


def _bounding_elements(scene, arcs, arc, e1, e2, interval, kind, probe, curves=None, obstacles=None):
    """The elements of the given pieces (arcs or segments): their sides that bound a cell,
    by the probes of :func:`side_pairs`, in the order of the pieces, left side first
    (``curves``: their :func:`_curves`, if known; ``obstacles``: as :func:`side_pairs`)."""
    if curves is None:
        curves = _curves(scene, arcs, arc, e1, e2, interval, kind)
    pairs, bounds = side_pairs(scene, arcs, arc, e1, e2, interval, kind, probe, curves, obstacles)
    row, side = np.nonzero(bounds)
    return element_geometry(scene, arcs, arc[row], side, e1[row], e2[row], pairs[row, side], interval[row], kind[row],
                            tuple(c[row] for c in curves))


# --------------------------------------------------------------------------------------
# loops in the square (elements of loop j contiguous: loop_offsets[j]:loop_offsets[j + 1])


def windings(el, loop_offsets, bridged=False):
    """Winding of each loop (Hoberock et al. Fig. 7): the turning angles at its corners plus the
    angle each element's tangent turns along it (left turns positive).

    With ``bridged``, a loop turns across the gap at a cusp (:func:`_cusp_turns`).

    Returns
    -------
    (l,) float
        +2π for a loop running counter-clockwise (an outer loop), −2π for a hole.
    """
    n = loop_offsets[-1]
    loop_of = np.repeat(np.arange(len(loop_offsets) - 1), np.diff(loop_offsets))
    along = signed_angle(el.start_tangent[:n], el.end_tangent[:n], el.end[:n])
    turn = _cusp_turns(el, loop_offsets) if bridged else corner_turns(el, loop_offsets)
    return np.bincount(loop_of, weights=turn + along, minlength=len(loop_offsets) - 1)


def _cusp_turns(el, loop_offsets):
    """:func:`loops.corner_turns`, but where a loop turns back at a corner (within CUSP_ANGLE
    of ±π) whose gap, closed by FormLoops within the join tolerance, is longer than CUSP_GAP,
    the turn runs along the gap, at both of its ends (as the V-cells' cusps,
    :func:`vcells.sphere_turning_sums`), unless the gap runs straight back along one of the
    two elements (within SPIKE_ANGLE).

    A sliver cell whose short side V1 merged away (two events 1.7 epsilon apart along one
    edge, the sliver 0.03 of the square long: random_boxes(300), pair (267, 494)) closes
    across that side's gap with its two long sides antiparallel: one turn between their
    tangents is ±π by the sign of their rounding, not by the side the gap lies on, and the
    loop wound by 0 (docs/skeleton.md "EE-cells", rule 19).

    Returns
    -------
    (n,) float
    """
    n = loop_offsets[-1]
    nxt, _ = loop_successors(loop_offsets)
    turn = corner_turns(el, loop_offsets)
    gap = el.start[nxt] - el.end[:n]
    cusp = np.flatnonzero((np.abs(turn) > np.pi - CUSP_ANGLE) & (row_norms(gap) > CUSP_GAP))
    if len(cusp):
        at = el.end[cusp]
        at_p = signed_angle(el.end_tangent[cusp], gap[cusp], at)
        at_q = signed_angle(gap[cusp], el.start_tangent[nxt[cusp]], at)
        spike = np.maximum(np.abs(at_p), np.abs(at_q)) > np.pi - SPIKE_ANGLE
        turn[cusp] = np.where(spike, turn[cusp], at_p + at_q)
    return turn


@njit(cache=True, inline="always")
def _bezier(c0, c1, w, u):
    """Coordinate at u of a rational linear Bézier curve (module docstring)."""
    a = (1.0 - u) * (1.0 - w)
    b = u * w
    return (a * c0 + b * c1) / (a + b)


@njit(cache=True, inline="always")
def _bezier_inverse(c0, c1, w, c):
    """The u at which the coordinate equals c (c between c0 and c1)."""
    a = (1.0 - w) * (c - c0)
    b = w * (c1 - c)
    return a / (a + b)


@njit(cache=True)
def _crossings(starts, ends, weights, lo, hi, x, y):
    """How often the ray {(t, y): t > x} crosses the loop of elements lo..hi-1 (x2 is
    monotone along each: at most once; half-open in x2 so that a ray through a corner
    counts once). Ends joined within the join tolerance are bridged by the straight
    segment to the next start: a ray through such a gap would otherwise leave the loop
    without crossing it (a sliver cell's reference point, 1e-9 off an element ending there,
    then saw the whole square as inside)."""
    count = 0
    for e in range(lo, hi):
        y0, y1 = starts[e, 1], ends[e, 1]
        if (y0 > y) != (y1 > y):
            u = _bezier_inverse(y0, y1, weights[e, 1], y)
            if _bezier(starts[e, 0], ends[e, 0], weights[e, 0], u) > x:
                count += 1
        nxt = e + 1 if e + 1 < hi else lo
        g0, g1 = ends[e, 1], starts[nxt, 1]
        if (g0 > y) != (g1 > y):
            a = (y - g0) / (g1 - g0)
            if ends[e, 0] + a * (starts[nxt, 0] - ends[e, 0]) > x:
                count += 1
    return count


@njit(cache=True)
def _inside_square(ref, loop_offsets, starts, ends, weights, pair_loop, targets):
    out = np.empty(len(pair_loop), np.bool_)
    for t in range(len(pair_loop)):
        L = pair_loop[t]
        lo, hi = loop_offsets[L], loop_offsets[L + 1]
        a = _crossings(starts, ends, weights, lo, hi, ref[L, 0], ref[L, 1])
        b = _crossings(starts, ends, weights, lo, hi, targets[t, 0], targets[t, 1])
        out[t] = (a - b) % 2 == 0
    return out


def inside_square_loops(el, loop_offsets, ref, loop, targets):
    """Whether each target point lies in the left region of a loop: the horizontal rays
    from it and from the loop's reference point cross the loop equally often mod 2.

    Parameters
    ----------
    el : Elements
    loop_offsets : (l + 1,) int
    ref : (l, 3) float
        Reference points (x1, x2, 1).
    loop : (m,) int
    targets : (m, 2 or 3) float
        Points (x1, x2, ...) of the square.

    Returns
    -------
    (m,) bool
    """
    return _inside_square(np.ascontiguousarray(ref[:, :2]), np.asarray(loop_offsets, np.int64),
                          np.ascontiguousarray(el.start[:, :2]), np.ascontiguousarray(el.end[:, :2]),
                          np.ascontiguousarray(el.weight), np.asarray(loop, np.int64),
                          np.ascontiguousarray(np.asarray(targets, np.float64)[:, :2]))


def reference_points(el, loop_offsets):
    """A point just left of each loop: SQUARE_REFERENCE_OFFSET (at most a thousandth of the
    element's chord) off its longest element, along the normal, at u = REFERENCE_AT (not
    the middle: in axis-aligned scenes the middle of a side is often level with a corner,
    and a ray through a corner joined within tolerance could count it twice).

    Returns
    -------
    (l, 3) float
    """
    n = loop_offsets[-1]
    chord = row_norms(el.end[:n, :2] - el.start[:n, :2])
    loop_of = np.repeat(np.arange(len(loop_offsets) - 1), np.diff(loop_offsets))
    pick = np.lexsort([-chord, loop_of])
    best = pick[np.searchsorted(loop_of[pick], np.arange(len(loop_offsets) - 1))]
    s, e, w = el.start[best, :2], el.end[best, :2], el.weight[best]
    u = REFERENCE_AT
    den = (1 - u) * (1 - w) + u * w
    point = ((1 - u) * (1 - w) * s + u * w * e) / den
    # d/du of each coordinate: w0 w1 (c1 - c0) / den² (w0 = 1 - w, w1 = w)
    tangent = (e - s) * w * (1 - w) / den**2
    tangent /= np.maximum(row_norms(tangent), 1e-300)[:, None]
    left = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    ref = point + np.minimum(SQUARE_REFERENCE_OFFSET, 1e-3 * chord[best])[:, None] * left
    return _lift(ref)


def _phi_psi(q):
    """φ(q) = log(1 + q) / q and ψ(q) = (1 - φ(q)) / q, by series near 0."""
    small = np.abs(q) < 1e-3
    qs = np.where(small, q, 0.0)
    phi_s = 1 - qs / 2 + qs**2 / 3 - qs**3 / 4 + qs**4 / 5 - qs**5 / 6
    psi_s = 0.5 - qs / 3 + qs**2 / 4 - qs**3 / 5 + qs**4 / 6 - qs**5 / 7
    ql = np.where(small, 1.0, q)
    phi_l = np.log1p(ql) / ql
    psi_l = (1 - phi_l) / ql
    return np.where(small, phi_s, phi_l), np.where(small, psi_s, psi_l)


def _integral(a0, a1, wa, b0, b1, wb):
    """∫ b da along elements whose coordinates a, b are rational linear Bézier curves
    ((k,) float each), exactly: b = g(a) is linear-fractional, g = B ∘ A⁻¹ (2 × 2
    matrices), and ∫ (P a + Q) / (R a + S) da over [a0, a1] is
    Δ [g(a0) φ(q) + P Δ ψ(q) / D0] with Δ = a1 - a0, D0 = R a0 + S, q = R Δ / D0."""
    # A⁻¹: a -> u = (1 - wa)(a - a0) / ((1 - wa)(a - a0) + wa (a1 - a))
    inv = np.empty((len(a0), 2, 2))
    inv[:, 0, 0], inv[:, 0, 1] = 1 - wa, -(1 - wa) * a0
    inv[:, 1, 0], inv[:, 1, 1] = 1 - 2 * wa, wa * a1 - (1 - wa) * a0
    # B: u -> (u (wb b1 - (1 - wb) b0) + (1 - wb) b0) / (u (2 wb - 1) + 1 - wb)
    fwd = np.empty((len(a0), 2, 2))
    fwd[:, 0, 0], fwd[:, 0, 1] = wb * b1 - (1 - wb) * b0, (1 - wb) * b0
    fwd[:, 1, 0], fwd[:, 1, 1] = 2 * wb - 1, 1 - wb
    g = fwd @ inv
    P, R, S = g[:, 0, 0], g[:, 1, 0], g[:, 1, 1]
    delta = a1 - a0
    d0 = R * a0 + S
    ok = (delta != 0) & (d0 != 0)
    d0 = np.where(ok, d0, 1.0)
    q = R * delta / d0
    phi, psi = _phi_psi(np.maximum(q, -1 + 1e-15))
    return np.where(ok, delta * (b0 * phi + P * delta * psi / d0), 0.0)


def loop_areas(el, loop_offsets):
    """Signed area of each loop's inside (Green: ½ ∮ x1 dx2 - x2 dx1), counter-clockwise
    positive, integrated exactly along each element in its better-conditioned coordinate.

    Returns
    -------
    (l,) float
    """
    n = loop_offsets[-1]
    x0, y0 = el.start[:n, 0], el.start[:n, 1]
    x1, y1 = el.end[:n, 0], el.end[:n, 1]
    wx, wy = el.weight[:n, 0], el.weight[:n, 1]
    over_x = np.abs(x1 - x0) >= np.abs(y1 - y0)
    # ∫ y dx directly, or from ∫ x dy by parts: ∫ y dx = [x y] - ∫ x dy
    y_dx = np.where(over_x, _integral(x0, x1, wx, y0, y1, wy), x1 * y1 - x0 * y0 - _integral(y0, y1, wy, x0, x1, wx))
    loop_of = np.repeat(np.arange(len(loop_offsets) - 1), np.diff(loop_offsets))
    # ½ ∮ (x dy - y dx) = ½ ∮ (d(xy) - 2 y dx) = -∮ y dx over a closed loop
    return -np.bincount(loop_of, weights=y_dx, minlength=len(loop_offsets) - 1)


# --------------------------------------------------------------------------------------
# the builder


def build_eecells(scene, arcs, quiet=True):
    """The EE-cells (V2) of every skew pair of generator edges that V1 gives boundaries.

    Squares are independent: they are built in chunks of about SQUARE_CHUNK arc-square
    incidences (each square whole, in (e1, e2) order), so that the elements, the largest
    intermediate arrays, exist for one chunk at a time; the cells are the same.

    Parameters
    ----------
    scene : Scene
    arcs : Arcs
    quiet : bool
        No progress bar.

    Returns
    -------
    EECells
    """
    chunks = list(square_chunks(scene, arcs))
    parts = []
    with bar(total=sum(len(c[0]) for c in chunks), desc="EE-cells", quiet=quiet, unit="incidence") as progress:
        for squares in chunks:
            parts.append(squares_cells(scene, arcs, squares))
            progress.update(len(squares[0]))
    return _concatenate_cells(parts)


def square_chunks(scene, arcs, size=None, carry=()):
    """The arc-square incidences (:func:`arc_squares`) in chunks of about ``size``
    (default SQUARE_CHUNK), each square whole, squares in (e1, e2) order, a square's
    incidences in the order :func:`arc_squares` lists them: what :func:`build_eecells`
    builds one at a time (:func:`squares_cells`) and joins (:func:`_concatenate_cells`);
    one chunk, maybe empty, at least. Made one at a time, never all of them at once:

    * the incidences are found for ARC_SLICE arcs at a time (their temporaries are some
      500 bytes per incidence), each slice's put in order of e1 (stably) and spilled to a
      temporary file with the number of each e1's (:class:`_SquareSpill`);
    * then whole e1's, consecutive, of together about SQUARE_GROUP incidences are read
      back from every slice, in the slices' order, and put in order by (square, block),
      a block's arcs ascending with the slices: the order of one call over every arc.

    The chunks are cut at the start of the square holding every size-th incidence of
    that whole order (the incidences after a group's last cut wait for the next group),
    so they do not depend on the slices or the groups.

    ``carry`` names per-arc arrays of ``arcs`` whose rows go along with each incidence
    (spilled with it): arcs read from a file (:func:`viscx.skeleton.chunks.stored_v2_arcs`)
    are then read one slice at a time and never whole, and a chunk has its arcs' rows.

    Yields
    ------
    arc, e1, e2 : (k,) int
        A chunk's incidences.
    *carried : (k, ...) arrays
        With ``carry``: the row of each incidence's arc in each array named.
    """
    size = size or SQUARE_CHUNK
    with _SquareSpill(scene) as spill:
        for rows in row_chunks(len(arcs), ARC_SLICE):
            arc, e1, e2, block = arc_squares(scene, arcs, rows, blocks=True)
            spill.add(arc, e1, e2, block, *(getattr(arcs, name)[rows][arc - rows.start] for name in carry))
            del arc, e1, e2, block
        done, waiting = 0, None  # incidences yielded; the sorted ones after the last cut
        for arc, e1, e2, block, *carried in spill.groups(SQUARE_GROUP):
            key = e1 * (1 << 32) + e2
            by_square = np.argsort(key * 8 + block, kind="stable")  # (blocks: fewer than 8; edges: fewer than 2^28)
            sorted_ = [x[by_square] for x in (arc, e1, e2, key, *carried)]
            del arc, e1, e2, block, key, by_square, carried
            if waiting is not None:  # (their squares come before the group's: smaller e1)
                sorted_ = [np.concatenate([w, x]) for w, x in zip(waiting, sorted_)]
            key = sorted_[3]
            square_start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
            # cut at the start of the square holding every size-th incidence (counted from the first)
            at = np.arange(-done % size or size, len(key), size)
            cuts = unique_sorted(square_start[np.searchsorted(square_start, at, "right") - 1])
            bounds = np.r_[0, cuts[cuts > 0]]
            for lo, hi in zip(bounds[:-1], bounds[1:]):
                yield tuple(x[lo:hi] for i, x in enumerate(sorted_) if i != 3)
            done += int(bounds[-1])
            waiting = [x[bounds[-1]:] for x in sorted_]
            del sorted_, key
        if waiting is None:  # no incidence: one empty chunk
            empty = np.zeros(0, np.int64)
            waiting = [empty] * 4 + [getattr(arcs, name)[:0] for name in carry]
        yield tuple(x for i, x in enumerate(waiting) if i != 3)


class _SquareSpill:
    """Arc-square incidences spilled to an unnamed temporary file slice by slice, each
    slice's rows in order of e1 (stably), and read back by groups of consecutive e1's:
    :func:`square_chunks` holds one slice's or one group's at a time (13 bytes an
    incidence on disk: arc ids int64, edges int32, blocks int8, and the rows carried with
    them in their own dtypes; read back in the dtypes :func:`arc_squares` gave).

    ``with _SquareSpill(scene) as spill``: :meth:`add` each slice's, then :meth:`groups`;
    the file is gone on exit.
    """

    _STORED = (np.int64, np.int32, np.int32, np.int8)  # arc, e1, e2, block

    def __init__(self, scene):
        self.n_edges = int(len(scene.half_edges.edge_vertices))
        self.records = []  # per slice: (its offset in the file, (n_edges + 1,) first row of each e1)
        self.counts = np.zeros(self.n_edges, np.int64)
        self.columns = None  # per column: (dtype given, dtype stored, shape of a row)

    def __enter__(self):
        import tempfile

        self.file = tempfile.TemporaryFile(prefix="viscx-squares-")
        return self

    def __exit__(self, *exc):
        self.file.close()

    def add(self, arc, e1, e2, block, *carried):
        """Spill one slice's incidences (:func:`arc_squares` with ``blocks``) and the rows
        ``carried`` with them (arrays of one row per incidence)."""
        values = (arc, e1, e2, block, *carried)
        self.columns = self.columns or [(x.dtype, stored, x.shape[1:])
                                        for x, stored in zip(values, self._STORED + tuple(x.dtype for x in carried))]
        order = np.argsort(e1, kind="stable")
        n = np.bincount(e1, minlength=self.n_edges)
        self.counts += n
        self.file.seek(0, 2)
        self.records.append((self.file.tell(), np.r_[0, np.cumsum(n)]))
        for (_, stored, _), x in zip(self.columns, values):
            x[order].astype(stored, copy=False).tofile(self.file)

    def groups(self, size):
        """Yield (arc, e1, e2, block, *carried) of whole consecutive e1's, about ``size``
        incidences each (an e1 with more on its own), each slice's after the slice before's."""
        ends = np.cumsum(self.counts)
        lo = first = 0
        while len(ends) and first < ends[-1]:
            hi = max(lo + 1, int(np.searchsorted(ends, first + size, "right")))
            parts = zip(*(self._read(record, lo, hi) for record in self.records))
            yield tuple(np.concatenate(p).astype(given, copy=False) for p, (given, _, _) in zip(parts, self.columns))
            lo, first = hi, int(ends[hi - 1])

    def _read(self, record, lo, hi):
        """One slice's columns, its rows of the e1's lo .. hi - 1."""
        start, offsets = record
        n, row, count = int(offsets[-1]), int(offsets[lo]), int(offsets[hi] - offsets[lo])
        columns = []
        for _, stored, shape in self.columns:
            item = np.dtype(stored).itemsize * int(np.prod(shape))
            self.file.seek(start + row * item)
            columns.append(np.fromfile(self.file, stored, count * int(np.prod(shape))).reshape(count, *shape))
            start += n * item
        return columns


#: Arcs whose squares :func:`square_chunks` finds at a time.
ARC_SLICE = 1 << 18

#: Incidences :func:`square_chunks` puts in order at a time: some 90 bytes each then, 180
#: with the arcs' rows V2 carries (:func:`viscx.skeleton.chunks.eecell_parts`), 0.38 GB.
SQUARE_GROUP = 1 << 21


#: Arc-square incidences per chunk of :func:`build_eecells` (random_boxes(1000): ~5 chunks).
SQUARE_CHUNK = 1 << 20


def squares_cells(scene, arcs, squares):
    """The EE-cells of some squares ((arc, e1, e2) incidences, every square whole) and the
    number of their open chains that are demoted loops (listed first)."""
    el = boundary_elements(scene, arcs, squares)
    loops = _open_loops(scene, el, _loops(scene, el))
    segments = open_segments(scene, el, loops[0], loops[2])
    if len(segments.e1):
        el, loops = _with_segments(scene, arcs, squares, segments, el, loops)
        el, loops = _finest_probes(scene, arcs, squares, segments, el, loops)
    group = _groups(el)
    (order, loop_offsets, chain_offsets), bad = _wound_loops(el, loops)
    walk = el.take(order)
    del el
    turning = windings(walk, loop_offsets, bridged=True)
    area = loop_areas(walk, loop_offsets)
    ref = reference_points(walk, loop_offsets)
    loop_group = group[order[loop_offsets[:-1]]]
    cell = cells_of_loops(walk, loop_offsets, loop_group, ref, inside=inside_square_loops)
    points = point_chains(scene, walk, chain_offsets)
    return _assemble(walk, order, loop_offsets, chain_offsets, turning, area, cell, points), int(np.count_nonzero(bad))


def _wound_loops(el, loops):
    """``loops`` (as :func:`loops.form_loops`) with the loops that do not wind by ±2π
    demoted to open chains, and the (l,) bool of those demoted: a closed boundary winds by
    ±2π (across the gaps of cusps: rule 19); anything else closed only within the join
    tolerance (e.g. one spurious arc shorter than it, meeting itself) and is an open chain."""
    order, loop_offsets, chain_offsets = loops
    turning = windings(el.take(order), loop_offsets, bridged=True)
    bad = np.abs(np.abs(turning) - 2 * np.pi) > WINDING_TOLERANCE
    return _demote(order, loop_offsets, chain_offsets, bad), bad


def _open_loops(scene, el, loops):
    """The loops of V1's elements (``loops`` as :func:`loops.form_loops`) that closed only within
    the join tolerance, their winding no ±2π, and are no point (:func:`point_chains`), demoted
    to open chains before V2's segments are sought, so that their squares are built again.

    A thin cell along a square's side whose side piece is shorter than the join tolerance
    (random_boxes(300), pair (2, 249): a triangle 3e-4 of the square wide on the side x2 = 1,
    9e-4 high, whose two EEE sides meet at a node) has no side element at the 50 epsilon
    probe, which jumps out of it; its two other sides' ends then join across the gap into a
    loop turning by less than 2π, and the square, seeming closed, was not probed again at 5
    epsilon, which finds the side (docs/skeleton.md, "EE-cells", loops closed across a gap).
    """
    order, loop_offsets, chain_offsets = loops
    walk = el.take(order)
    bad = np.abs(np.abs(windings(walk, loop_offsets)) - 2 * np.pi) > WINDING_TOLERANCE
    if bad.any():
        bad &= ~point_chains(scene, walk, loop_offsets)
    return _demote(order, loop_offsets, chain_offsets, bad)


def _finest_probes(scene, arcs, squares, segments, el, loops):
    """The squares still open after V2's segments built again with the fine probes' floor
    lowered to FINEST_PROBE_FLOOR of their step (docs/skeleton.md, "EE-cells", rule 20).

    A sliver cell thinner than the floor (one epsilon along the edge that moves most) between
    two arcs is jumped across: the fine probe off the near arc lands beyond the far one, so
    that side gets the pair of the cell beyond (random_boxes(300), pair (58, 353): a sliver
    1.5e-5 of the square high between two EEE arcs, the two sides' pairs then differing in
    the front blocker alone) and the sliver's loop stays open. Probes that close to a piece
    may also land between one boundary given twice by two families more than epsilon apart
    (lowered everywhere, the 997-polygon city lost 85 complete pairs so): hence only in the
    squares whose loops stay open anyway, whose elements are then replaced (:func:`_with_segments`
    with their segments). Arguments and returns as :func:`_with_segments`.
    """
    still = _open_squares(scene, el, loops)
    keep = np.isin(segments.e1 * (1 << 32) + segments.e2, still)
    if not keep.any():
        return el, loops
    return _with_segments(scene, arcs, squares, segments.take(keep), el, loops, FINEST_PROBE_FLOOR)


def _open_squares(scene, el, loops):
    """(q,) int: the squares (e1 << 32 | e2, ascending) that hold an open chain that is no
    point, or a loop whose winding is no ±2π (across cusps' gaps) and no point: the squares
    not complete with these loops (as :func:`squares_cells` finds them)."""
    (order, loop_offsets, chain_offsets), _ = _wound_loops(el, loops)
    chains = order[loop_offsets[-1]:]
    offsets = chain_offsets - loop_offsets[-1]
    points = point_chains(scene, el.take(chains), offsets)
    first = chains[offsets[:-1][~points]]
    return unique_sorted(el.e1[first] * (1 << 32) + el.e2[first])


def _groups(el):
    """(k,) int: the group (edge pair and blocker pair) of each element."""
    return unique_rows(np.concatenate([el.e1[:, None], el.e2[:, None], el.pair], axis=1))[1]


def _loops(scene, el):
    """:func:`loops.form_loops` of the elements: (order, loop_offsets, chain_offsets); a start
    at the same event as an end (within SQUARE_SAME_POINT_EPSILONS) is linked before one a
    merged event away (docs/skeleton.md, "EE-cells", rule 17)."""
    tol = join_tolerance(scene, el.e1, el.e2)
    return form_loops(el, _groups(el), tol, tol * (SQUARE_SAME_POINT_EPSILONS / SQUARE_JOIN_EPSILONS))


def _with_segments(scene, arcs, squares, segments, el, loops, floor=None):
    """The squares left open built again with V2's segments (:func:`open_segments`).

    Their elements (:func:`boundary_elements` with the segments, and the finer probe, whose
    floor is ``floor``: PROBE_ROOM_FLOOR by default) replace theirs; FormLoops runs on them
    alone, the other squares keep their loops and chains (groups never meet). Elements in the
    order of :func:`boundary_elements` and walks as one FormLoops over all of them gives:
    loops by their smallest element, each from it, then the chains by their first element.

    Returns
    -------
    el : Elements
    loops : tuple
        (order, loop_offsets, chain_offsets) as :func:`loops.form_loops`.
    """
    order, loop_offsets, chain_offsets = loops
    redo = unique_sorted(segments.e1 * (1 << 32) + segments.e2)
    square_key = squares[1] * (1 << 32) + squares[2]
    again = boundary_elements(scene, arcs, tuple(q[np.isin(square_key, redo)] for q in squares), segments, floor)
    again_order, again_loops, again_chains = _loops(scene, again)
    kept = np.flatnonzero(~np.isin(el.e1 * (1 << 32) + el.e2, redo))
    merged = Elements.concatenate([el.take(kept), again])
    sort = _element_order(merged)
    at = np.empty(len(sort), np.int64)
    at[sort] = np.arange(len(sort))  # position of each merged element in the sorted ones
    new_of_old = np.full(len(el), -1)
    new_of_old[kept] = at[: len(kept)]

    def walks(offsets, again_offsets):
        """The kept squares' walks (a walk lies in one square) and the new ones, by first element."""
        sizes = np.diff(offsets)
        mine = new_of_old[order[offsets[:-1]]] >= 0
        flat = np.concatenate([new_of_old[order[expand_ranges(offsets[:-1][mine], sizes[mine])[1]]],
                               at[len(kept) + again_order[again_offsets[0]:again_offsets[-1]]]])
        sizes = np.concatenate([sizes[mine], np.diff(again_offsets)])
        starts = np.cumsum(sizes) - sizes
        by_first = np.argsort(flat[starts], kind="stable")
        return flat[expand_ranges(starts[by_first], sizes[by_first])[1]], np.r_[0, np.cumsum(sizes[by_first])]

    loop_walks, loop_offsets = walks(loop_offsets, again_loops)
    chain_walks, chain_offsets = walks(chain_offsets, again_chains)
    new_order = np.concatenate([loop_walks, chain_walks])
    loop_offsets = loop_offsets.astype(np.int64)
    chain_offsets = (loop_offsets[-1] + chain_offsets).astype(np.int64)
    return merged.take(sort), (new_order, loop_offsets, chain_offsets)


def _concatenate_cells(parts):
    """One EECells from the cells of consecutive chunks of squares ((EECells, demoted)
    pairs): cells, loops and elements in chunk order, as one build gives them; open
    chains too, but the demoted loops of every chunk first (as :func:`_demote` puts them)."""
    if len(parts) == 1:
        return parts[0][0]
    cells = [p for p, _ in parts]

    def ragged(offsets, values):
        """Joined CSR lists: (offsets, each value array joined)."""
        sizes = np.concatenate([np.diff(o) for o in offsets])
        return np.r_[0, np.cumsum(sizes)].astype(np.int64), [np.concatenate(v) for v in zip(*values)]

    per_cell = ("edge1", "edge2", "back_kind", "back", "front_kind", "front", "area", "complete")
    out = {k: np.concatenate([getattr(c, k) for c in cells]) for k in per_cell}
    out["loop_offsets"], (out["turning"],) = ragged([c.loop_offsets for c in cells], [(c.turning,) for c in cells])
    out["element_offsets"], (out["element"], out["element_kind"], out["element_interval"]) = ragged(
        [c.element_offsets for c in cells], [(c.element, c.element_kind, c.element_interval) for c in cells])
    # open chains: every chunk's demoted loops, then every chunk's other chains
    per_chain = ("open_edge1", "open_edge2", "open_back_kind", "open_back", "open_front_kind", "open_front")
    chains = []
    for demoted in (True, False):
        for c, n in parts:
            rows = np.arange(n) if demoted else np.arange(n, len(c.open_edge1))
            lo, hi = c.open_offsets[rows], c.open_offsets[rows + 1]
            idx = expand_ranges(lo, hi - lo)[1]
            chains.append((np.r_[0, np.cumsum(hi - lo)], (c.open_element[idx], c.open_element_kind[idx],
                                                          c.open_interval[idx])
                           + tuple(getattr(c, k)[rows] for k in per_chain)))
    out["open_offsets"], joined = ragged([o for o, _ in chains], [v for _, v in chains])
    out["open_element"], out["open_element_kind"], out["open_interval"] = joined[:3]
    out.update(zip(per_chain, joined[3:]))
    return EECells(**out)


def _demote(order, loop_offsets, chain_offsets, bad):
    """Move the loops flagged ``bad`` ((l,) bool) to the open chains (before the others);
    returns (order, loop_offsets, chain_offsets) as :func:`loops.form_loops`."""
    if not bad.any():
        return order, loop_offsets, chain_offsets
    lens = np.diff(loop_offsets)
    n_el = loop_offsets[-1]
    keep = ~bad[np.repeat(np.arange(len(lens)), lens)]
    order = np.concatenate([order[:n_el][keep], order[:n_el][~keep], order[n_el:]])
    loop_offsets = np.concatenate([[0], np.cumsum(lens[~bad])]).astype(np.int64)
    demoted = loop_offsets[-1] + np.concatenate([[0], np.cumsum(lens[bad])])
    return order, loop_offsets, np.concatenate([demoted, chain_offsets[1:]]).astype(np.int64)


def join_tolerance(scene, e1, e2):
    """(k,) float: SQUARE_JOIN_EPSILONS epsilon along the shorter edge of each element's pair, in
    square units (events merged 4 epsilon apart along an edge end arcs there)."""
    length = scene.cached("edge_lengths", _edge_lengths)
    return SQUARE_JOIN_EPSILONS * scene.epsilon / np.minimum(length[e1], length[e2])


def _edge_lengths(scene):
    """(e,) float: the length of every edge (the scene's cache ``edge_lengths``)."""
    a, b = edge_geometry(scene, np.arange(len(scene.half_edges.edge_vertices)))
    return row_norms(b - a)


def point_chains(scene, walk, chain_offsets):
    """Open chains that are points at epsilon's resolution: every end of their elements lies
    within the join tolerance of the chain's start (as the V-cells' ``vcells.point_chains``).

    They are V1 arcs, or pieces of them, shorter than the join tolerance, between events
    merged by epsilon-visibility or a transition, which close on themselves within it: a
    loop whose winding is no ±2π (:func:`_demote`), or a chain beside a sliver whose other
    sides V1 merged away. They bound nothing at epsilon's resolution and do not keep their
    pair from being complete (office(300): 491 of the 497 demoted loops, the only open
    chains of 227 pairs; docs/skeleton.md "Furnished buildings"). ``walk`` and
    ``chain_offsets`` as :func:`loops.chain_extents` takes them; returns (o,) bool.
    """
    first = chain_offsets[:-1]
    return chain_extents(walk, chain_offsets) <= join_tolerance(scene, walk.e1[first], walk.e2[first])


def _assemble(walk, order, loop_offsets, chain_offsets, turning, area, cell, points):
    """Cells in canonical order with their loops (outer first) and areas; ``points`` ((o,)
    bool): the open chains that do not keep their pair from being complete
    (:func:`point_chains`)."""
    n_loops = len(loop_offsets) - 1
    n_cells = int(cell.max()) + 1 if n_loops else 0
    first = order[loop_offsets[:-1]]
    at_first = loop_offsets[:-1]
    pair = np.concatenate([walk.e1[at_first, None], walk.e2[at_first, None], walk.pair[at_first]], axis=1)
    # outer loop: the largest winding of the cell (+2π; holes -2π), equal windings tie
    rank_in_cell = np.lexsort([first, -np.round(turning, TURNING_DECIMALS), cell])
    outer = np.zeros(n_loops, bool)
    outer[rank_in_cell[np.searchsorted(cell[rank_in_cell], np.arange(n_cells))]] = True
    count = np.bincount(cell, minlength=n_cells)
    cell_area = np.bincount(cell, weights=area, minlength=n_cells)
    cell_pair = np.zeros((n_cells, 6), np.int64)
    cell_pair[cell] = pair
    cell_first = np.full(n_cells, np.iinfo(np.int64).max)
    np.minimum.at(cell_first, cell, first)
    cell_order = np.lexsort([cell_first, *cell_pair.T[::-1]])
    rank = np.empty(n_cells, np.int64)
    rank[cell_order] = np.arange(n_cells)
    loop_order = np.lexsort([first, ~outer, rank[cell]])
    lens = np.diff(loop_offsets)[loop_order]
    idx = np.repeat(loop_offsets[:-1][loop_order], lens) + np.arange(lens.sum()) - np.repeat(np.cumsum(lens) - lens, lens)
    n_el = loop_offsets[-1]
    cp = cell_pair[cell_order]
    chain = walk.take(np.arange(n_el, len(walk)))
    chain_first = chain_offsets[:-1] - n_el
    points = np.repeat(points, np.diff(chain_offsets))
    open_key = unique_sorted(chain.e1[~points] * (1 << 32) + chain.e2[~points])
    complete = ~np.isin(cp[:, 0] * (1 << 32) + cp[:, 1], open_key)
    return EECells(
        edge1=cp[:, 0],
        edge2=cp[:, 1],
        back_kind=cp[:, 2].astype(np.int8),
        back=cp[:, 3],
        front_kind=cp[:, 4].astype(np.int8),
        front=cp[:, 5],
        area=cell_area[cell_order],
        complete=complete,
        loop_offsets=np.concatenate([[0], np.cumsum(count[cell_order])]).astype(np.int64),
        turning=turning[loop_order],
        element_offsets=np.concatenate([[0], np.cumsum(lens)]).astype(np.int64),
        element=walk.signed[idx],
        element_kind=walk.kind[idx],
        element_interval=walk.interval[idx],
        open_offsets=(chain_offsets - n_el).astype(np.int64),
        open_element=chain.signed,
        open_element_kind=chain.kind,
        open_interval=chain.interval,
        open_edge1=chain.e1[chain_first],
        open_edge2=chain.e2[chain_first],
        open_back_kind=chain.pair[chain_first, 0].astype(np.int8),
        open_back=chain.pair[chain_first, 1],
        open_front_kind=chain.pair[chain_first, 2].astype(np.int8),
        open_front=chain.pair[chain_first, 3],
    )


# --------------------------------------------------------------------------------------
# queries


def cell_elements(scene, arcs, eecells, cells):
    """The boundary elements of the given cells, loop by loop.

    Parameters
    ----------
    cells : (c,) int
        Consecutive cell indices.

    Returns
    -------
    el : Elements
    offsets : (l + 1,) int
        Loop j of these cells is ``el[offsets[j]:offsets[j + 1]]``.
    loop_cell : (l,) int
        The cell of each loop.
    """
    ee = eecells
    first_loop, end_loop = ee.loop_offsets[cells[0]], ee.loop_offsets[cells[-1] + 1]
    lo, hi = ee.element_offsets[first_loop], ee.element_offsets[end_loop]
    signed = ee.element[lo:hi]
    loop_cell = np.repeat(cells, np.diff(ee.loop_offsets[cells[0]: cells[-1] + 2]))
    el_cell = np.repeat(loop_cell, np.diff(ee.element_offsets[first_loop: end_loop + 1]))
    pair = np.stack([ee.back_kind, ee.back, ee.front_kind, ee.front], axis=1)[el_cell]
    el = element_geometry(scene, arcs, np.abs(signed) - 1, (signed < 0).astype(np.int64), ee.edge1[el_cell],
                          ee.edge2[el_cell], pair, ee.element_interval[lo:hi], ee.element_kind[lo:hi])
    return el, ee.element_offsets[first_loop: end_loop + 1] - lo, loop_cell


def locate(scene, arcs, eecells, e1, e2, points):
    """The EE-cells of an edge pair holding each point of its square.

    Parameters
    ----------
    e1, e2 : int
        The pair, e1 < e2.
    points : (n, 2) float
        (x1, x2).

    Returns
    -------
    cell : (n,) int
        The cell (index into ``eecells``) holding each point, -1 where none (hidden, or
        loops V1 left open) or several do.
    holders : (n,) int
    """
    ee = eecells
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    cells = np.flatnonzero((ee.edge1 == e1) & (ee.edge2 == e2))
    nd = len(pts)
    if len(cells) == 0:
        return np.full(nd, -1), np.zeros(nd, np.int64)
    held = np.ones((len(cells), nd), bool)
    el, offsets, loop_cell = cell_elements(scene, arcs, ee, cells)
    nl = len(offsets) - 1
    if nl:
        ref = reference_points(el, offsets)
        inside = inside_square_loops(el, offsets, ref, np.repeat(np.arange(nl), nd), np.tile(pts, (nl, 1)))
        np.logical_and.at(held, np.searchsorted(cells, loop_cell), inside.reshape(nl, nd))
    holders = held.sum(axis=0)
    return np.where(holders == 1, cells[np.argmax(held, axis=0)], -1), holders
