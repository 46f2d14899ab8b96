"""V2: the V-cells (2-cells of a vertex) of the visibility complex (Hoberock et al. §5).

The direction sphere of a vertex
--------------------------------
For a generator vertex v and a direction d (unit), the *downstream segment*
σ(v, d) is the maximal free segment through v whose part beyond v runs along
d, judged like every segment of the skeleton (docs/skeleton.md): if the line
through v along d is tangent (passing) at v, σ runs from the first hit along
-d to the first hit along d and its blocker pair is ``(up, down) = (hit(-d),
hit(d))``; otherwise the surface separates the two rays at v, σ = [v, hit(d)]
and ``up`` is the vertex itself. A *V-cell* is a maximal connected region of
the sphere S² of directions d where ``(up(d), down(d))`` is constant. The
V-cells of v tile S² (their solid angles sum to 4π).

A tangent line through v is one segment seen from both of its ends: d and -d
give the same segment with up and down swapped. So a V-cell whose up is not
the vertex has an antipodal *twin* (the region -R with the pair swapped), the
same set of maximal free segments: the seed's V-cell "with up and down in
either order" is a cell together with its twin (a sky-sky region may be its
own twin). Cells whose up is the vertex have no twin (-d gives the other
segment of that line). Both lifts are kept: the downstream view of v (what v
sees along each d) is then a plain lookup.

Boundaries: VE half-cells on the sphere
---------------------------------------
A VE arc (v, e) over s ∈ [s0, s1] is, on v's sphere, the great-circle arc of
directions d(s) = (e(s) - v)/|e(s) - v| (its *forward image*) and the arc of
-d(s) (its *antipodal image*). Its half-cells (V1) give the blocker pairs of
the cells on either side of the forward image: side +n = (b - a) × (v - a)
(half-cell ``+(h+1)``) and side -n (the opposite half-cell, ``-(h+1)``). On
the antipodal image the same lines are seen from the other end:

* where a side's up is not the vertex, the cell there is ``(down, up)``;
* where a side's up is the vertex (the line enters the surface at v on that
  side) the cell at -d is ``(v, hit(-d))``; it is bounded by the antipodal
  image only when the other side is tangent, and its down blocker is that
  side's up (the same ray -d, no event between them);
* a side whose pair equals the other side's pair bounds nothing.

A *boundary element* is one side of one image: a directed great-circle arc
with its cell on the left (seen from outside the sphere): the forward image of
half-cell +(h+1) runs from s0 to s1 (the seed's "ve"), the forward image of
-(h+1) from s1 to s0 ("ve.opp"); antipodal images run the other way.

Algorithm (Hoberock et al. Fig. 4, §5.2-5.5)
-------------------------------------
Per vertex and blocker pair (one *group*), FormLoops chains the group's
elements end to start. Ends meet where they coincide on the sphere (within
``JOIN_CHORD``, not by end ids: transition ends carry none). Where several
elements of a group start at one point (a degenerate 0-cell, §5.5, or a cell
touching itself) the next element is the first one clockwise from the
incoming element's reversed tangent, which makes the loops the boundaries of
the faces of the arrangement (they never cross); exact ties go to the smaller
element id (the sorted-unique-id rule of §5.5). Elements that cannot lie on
any loop (nothing of their group meets their start or end) choose last, so a
spurious V1 arc cannot take a closing element's successor.

Each loop L has a turning-angle sum T (left turns positive, summed over its
corners: great-circle arcs have no geodesic curvature) and, by Gauss-Bonnet,
its left region has solid angle 2π - T. Loops of one group are grouped into
cells by ray-crossing parity on the sphere (§5.4): a reference point just left
of each loop is located against every other loop of the group, and two loops
bound one cell exactly when every loop of the group sees them on the same side
(and each lies left of the other). A cell's *outer* loop is its loop of largest
turning sum: a cell with a face blocker lies in the open hemisphere of
directions towards that face's plane, where the seed's gnomonic projection
onto the plane (which maps great-circle arcs to segments) turns the outer loop
by +2π and holes by -2π; on the sphere exactly one of its loops has T > 0 and
it is that outer loop. The cell's solid angle is Σ (2π - T) - 4π (k - 1) over
its k loops.

Chains that do not close (a V1 end with no partner on the sphere) are joined across
the few-epsilon gaps V1's merged events leave (:func:`join_open_chains`); those left
are kept as *open chains* and reported; they form no cell, and the cells of their
vertex are not ``complete`` unless the chain is a point at epsilon's resolution
(:func:`point_chains`; docs/skeleton.md, "V-cells", for how often and why).
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from viscx.arrays import expand_ranges, row_norms, unique_rows, unique_sorted
from viscx.progress import bar
from viscx.skeleton.arcs import VE, family_lines, vertex_side_backs
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
from viscx.skeleton.nodes import BLOCK_VERTEX, vertex_ray_blockers
from viscx.tolerances import (
    CORNER_REACH,
    CUSP_ANGLE,
    CUSP_GAP,
    JOIN_CHORD,
    JOIN_EPSILONS,
    JOIN_LIMIT,
    PARALLEL_TOLERANCE,
    SPHERE_COVER_TOLERANCE,
    SPHERE_REFERENCE_OFFSET,
    SPIKE_ANGLE,
)

FOUR_PI = 4 * np.pi
#: Fewest elements of a loop closed across gaps: one element closed onto itself bounds nothing.
JOIN_MIN_ELEMENTS = 2
#: Cosine between the tangents of elements running one way along one great circle
#: (:func:`point_loops`): within 1.4e-3 rad, where a point loop's elements, a few epsilon
#: long, turn by about their length (4.5e-5 rad) and a lune's run back (cosine -1).
STRAIGHT_COSINE = 1 - 1e-6
#: (loop, direction) pairs per call of the point-location kernel.
LOCATE_CHUNK = 1 << 21


@dataclass
class VCells:
    """V-cells as flat arrays, sorted by (vertex, up, down, first boundary element).

    Attributes
    ----------
    vertex : (c,) int
    up_kind, down_kind : (c,) int8
        BLOCK_FACE, BLOCK_SKY or BLOCK_VERTEX (up only: the vertex itself).
    up, down : (c,) int
        Face id, -1 for the sky, the vertex id for BLOCK_VERTEX.
    solid_angle : (c,) float
        Area of the cell on the unit sphere of directions.
    twin : (c,) int
        The antipodal cell (same segments, up and down swapped); itself for a
        cell that is its own antipode; -1 when up is the vertex.
    complete : (c,) bool
        Every boundary element of its vertex lies on a closed loop and the
        vertex's cells cover its sphere (solid angles summing to 4π within
        SPHERE_COVER_TOLERANCE). Elsewhere V1 left loops open (docs/skeleton.md,
        "V-cells") and cells built from the closed loops may be wrong.
    loop_offsets : (c + 1,) int
        Loops of cell i: ``loop_offsets[i]:loop_offsets[i + 1]``, the outer loop first.
    turning : (l,) float
        Turning-angle sum of each loop on the sphere (2π minus its left region's area).
    element_offsets : (l + 1,) int
        Elements of loop j: ``element_offsets[j]:element_offsets[j + 1]``, in order.
    element : (k,) int
        Signed half-cell id: +(h + 1) for half-cell h of ``Arcs.half_cells``
        (its cell on side +n), -(h + 1) for its opposite (side -n).
    antipodal : (k,) bool
        The element runs along the antipodal image (directions from the edge
        through the vertex) instead of the forward image.
    open_offsets : (o + 1,) int
        Chains that did not close, as ``element_offsets``.
    open_element : (m,) int
    open_antipodal : (m,) bool
    open_vertex, open_up_kind, open_up, open_down_kind, open_down : (o,) int
        The group of each open chain.
    """

    vertex: np.ndarray
    up_kind: np.ndarray
    up: np.ndarray
    down_kind: np.ndarray
    down: np.ndarray
    solid_angle: np.ndarray
    twin: np.ndarray
    complete: np.ndarray
    loop_offsets: np.ndarray
    turning: np.ndarray
    element_offsets: np.ndarray
    element: np.ndarray
    antipodal: np.ndarray
    open_offsets: np.ndarray
    open_element: np.ndarray
    open_antipodal: np.ndarray
    open_vertex: np.ndarray
    open_up_kind: np.ndarray
    open_up: np.ndarray
    open_down_kind: np.ndarray
    open_down: np.ndarray

    def __len__(self):
        return len(self.vertex)

    def counts(self):
        """Numbers of cells, of cells counting twins once (the seed's V-cells), of cells whose
        up is the vertex, with holes, of holes, of open chains, of vertices with cells and
        of those whose cells cover the sphere."""
        loops = np.diff(self.loop_offsets)
        return {
            "cells": len(self),
            "seed_cells": int(np.count_nonzero((self.twin < 0) | (self.twin >= np.arange(len(self))))),
            "vertex_up": int(np.count_nonzero(self.up_kind == BLOCK_VERTEX)),
            "with_holes": int(np.count_nonzero(loops > 1)),
            "holes": int(np.sum(np.maximum(loops - 1, 0))),
            "open_chains": len(self.open_vertex),
            "vertices": len(unique_sorted(np.concatenate([self.vertex, self.open_vertex]))),
            "complete_vertices": len(unique_sorted(self.vertex[self.complete])),
        }


# --------------------------------------------------------------------------------------
# boundary elements


@dataclass
class Elements:
    """Boundary elements: one side of one image of a VE half-cell, a directed
    great-circle arc of a vertex's direction sphere with its cell on the left.

    Attributes
    ----------
    half_cell : (k,) int
    side : (k,) int
        0: the half-cell's own side (+n), 1: its opposite's (-n).
    antipodal : (k,) bool
    vertex : (k,) int
    pair : (k, 4) int
        (up kind, up, down kind, down) of the cell on the element's left.
    start, end : (k, 3) float
        Unit directions where the element starts and ends.
    start_tangent, end_tangent : (k, 3) float
        Unit direction of travel there (tangent to the sphere).
    end_reach : (k,) float
        Distance from the vertex to the edge's point where the element ends.
    """

    half_cell: np.ndarray
    side: np.ndarray
    antipodal: np.ndarray
    vertex: np.ndarray
    pair: np.ndarray
    start: np.ndarray
    end: np.ndarray
    start_tangent: np.ndarray
    end_tangent: np.ndarray
    end_reach: np.ndarray

    def __len__(self):
        return len(self.half_cell)

    def take(self, index):
        return Elements(**{name: getattr(self, name)[index] for name in self.__dataclass_fields__})

    @property
    def signed(self):
        """(k,) int: +(h + 1) on the half-cell's side, -(h + 1) on its opposite's."""
        return np.where(self.side == 0, 1, -1) * (self.half_cell + 1)


def side_pairs(half_cells, backs=None):
    """Blocker pairs of the cells beside both images of every VE arc.

    Parameters
    ----------
    half_cells : HalfCells
    backs : ((h, 2) int, (h, 2) int), optional
        What each side's probe meets behind the vertex where its up is the vertex
        (:func:`vertex_backs`): the antipodal image's cell on that side is (v, back).
        Without it, (v, the other side's up), which fails where the VE line lies in the
        plane of a face at the vertex.

    Returns
    -------
    pairs : (h, 2, 2, 4) int
        ``pairs[i, image, side]`` = (up kind, up, down kind, down) of the cell
        on ``side`` (0: +n, 1: -n) of the forward (image 0) or antipodal
        (image 1) image of VE arc i.
    bounds : (h, 2, 2) bool
        Whether that side of that image bounds a cell (rules in the module docstring).
    """
    hc = half_cells
    fwd = np.stack([hc.up_kind, hc.up, hc.down_kind, hc.down], axis=2).astype(np.int64)  # (h, side, 4)
    vert = hc.up_kind == BLOCK_VERTEX  # (h, side)
    other = fwd[:, ::-1]
    # the vertex's side of the antipodal image: (v, what its probe meets behind v)
    back_kind, back = (other[:, :, 0], other[:, :, 1]) if backs is None else backs
    vertex_side = np.stack([np.full(vert.shape, BLOCK_VERTEX), np.broadcast_to(hc.vertex[:, None], vert.shape),
                            back_kind, back], axis=2)
    anti = np.where(vert[:, :, None], vertex_side, fwd[:, :, [2, 3, 0, 1]])
    pairs = np.stack([fwd, anti], axis=1)
    bounds = np.ones(pairs.shape[:3], dtype=bool)
    bounds[:, 1] &= ~(vert & vert[:, ::-1])  # both sides enter the surface at v: -d sees no event
    bounds &= np.any(pairs[:, :, 0] != pairs[:, :, 1], axis=2)[:, :, None]
    return pairs, bounds


def vertex_backs(scene, arcs):
    """:func:`viscx.skeleton.arcs.vertex_side_backs` of every half-cell at its arc's sample,
    kept in the arcs' cache (point location asks again and again)."""
    return arcs.cached("vertex_backs", lambda a: vertex_side_backs(scene, a.half_cells, a.parameter[a.half_cells.arc]))


def half_cell_pairs(scene, arcs):
    """:func:`side_pairs` of every half-cell with its :func:`vertex_backs`, kept in the
    arcs' cache: point location asks for a few elements of one vertex again and again
    (the city of 300 boxes, 64 vertices located: 7 of 17 s went to recomputing them)."""
    return arcs.cached("half_cell_pairs", lambda a: side_pairs(a.half_cells, vertex_backs(scene, a)))


def element_geometry(scene, arcs, half_cell, side, antipodal):
    """The boundary elements of the given half-cell sides and images.

    Parameters
    ----------
    scene : Scene
    arcs : Arcs
    half_cell, side : (k,) int
    antipodal : (k,) bool

    Returns
    -------
    Elements
    """
    hc = arcs.half_cells
    h, side, anti = np.asarray(half_cell, np.int64), np.asarray(side, np.int64), np.asarray(antipodal, bool)
    pairs, _ = half_cell_pairs(scene, arcs)
    interval = arcs.interval[hc.arc[h]]
    # the forward image's -n side and the antipodal image's +n side run from s1 to s0
    rev = (side == 1) != anti
    s_start = np.where(rev, interval[:, 1], interval[:, 0])
    s_end = np.where(rev, interval[:, 0], interval[:, 1])
    sign = np.where(anti, -1.0, 1.0)[:, None]
    travel = sign * np.where(rev, -1.0, 1.0)[:, None]
    start, t_start, _ = _image_point(scene, hc.vertex[h], hc.edge[h], s_start)
    end, t_end, reach = _image_point(scene, hc.vertex[h], hc.edge[h], s_end)
    return Elements(
        half_cell=h,
        side=side,
        antipodal=anti,
        vertex=hc.vertex[h],
        pair=pairs[h, anti.astype(np.int64), side],
        start=sign * start,
        end=sign * end,
        start_tangent=travel * t_start,
        end_tangent=travel * t_end,
        end_reach=reach,
    )


def boundary_elements(scene, arcs):
    """Every boundary element of every vertex's direction sphere, sorted by
    (half-cell, antipodal, side).

    Returns
    -------
    Elements
    """
    _, bounds = half_cell_pairs(scene, arcs)
    h, image, side = np.nonzero(bounds)
    return element_geometry(scene, arcs, h, side, image == 1)


def _image_point(scene, vertex, edge, s):
    """Direction from each vertex to its edge's point s, the direction in which it
    moves as s grows (unit, tangent to the sphere), and the point's distance."""
    gens = np.stack([vertex, edge, np.full(len(vertex), -1)], axis=1)
    _, d = family_lines(scene, np.full(len(vertex), VE), gens, s)
    r = row_norms(d)
    d /= r[:, None]
    ev = scene.half_edges.edge_vertices[edge]
    along = scene.vertices[ev[:, 1]] - scene.vertices[ev[:, 0]]
    t = along - np.einsum("ij,ij->i", along, d)[:, None] * d
    return d, t / row_norms(t)[:, None], r


# --------------------------------------------------------------------------------------
# FormLoops


def sphere_loops(scene, el, group):
    """:func:`form_loops` on a vertex's sphere, then :func:`join_open_chains`.

    Returns
    -------
    order, loop_offsets, chain_offsets
        As :func:`form_loops`.
    """
    return join_open_chains(scene, el, group, *form_loops(el, group, JOIN_CHORD))


def join_open_chains(scene, el, group, order, loop_offsets, chain_offsets):
    """Open chains of one group joined end to start into loops across gaps of up to
    JOIN_EPSILONS epsilon along their edges, seen from the vertex.

    V1 merges runs of a family's events each closer than 4 epsilon to the next along its
    edge into one (the best by rank): where the two families meeting at a corner of a cell keep different
    events of such a group, the cell's boundary jumps there (random boxes cities: the
    chains' ends lie a median 1.2e-5 rad, up to 1.6e-4, from the next start of their cell,
    a few epsilon along the edge; a sixth of the 300-polygon city's vertices kept open
    chains). Features closer than epsilon are one (epsilon-visibility), so such ends
    are one corner. Only chains are joined (FormLoops' loops stay as they are), by the
    rules of :func:`form_loops` over whole chains, each chain's end tolerance
    JOIN_EPSILONS epsilon over the distance from the vertex to the nearest edge its line
    meets (:func:`line_reach`: the events may have merged on that edge's family, nearer
    than the end's own edge), between JOIN_CHORD and JOIN_LIMIT. A loop of fewer than
    JOIN_MIN_ELEMENTS elements so joined stays open, and so does a point (:func:`point_loops`). A joined loop starts at its smallest
    element; the loops keep their order, the new ones after them.

    Returns
    -------
    order, loop_offsets, chain_offsets
        As :func:`form_loops`.
    """
    n_chains = len(chain_offsets) - 1
    if n_chains < 1:
        return order, loop_offsets, chain_offsets
    first, last = order[chain_offsets[:-1]], order[chain_offsets[1:] - 1]
    ends = el.take(first)  # a chain as one element: its first's start, its last's end
    ends.end, ends.end_tangent, ends.end_reach = el.end[last], el.end_tangent[last], el.end_reach[last]
    walk, joined, _ = form_loops(ends, group[first], end_tolerance(scene, el, last))
    sizes = np.diff(chain_offsets)
    # one element closed onto itself across a gap bounds nothing, nor does a point
    few = np.bincount(np.repeat(np.arange(len(joined) - 1), np.diff(joined)), weights=sizes[walk[: joined[-1]]],
                      minlength=len(joined) - 1) < JOIN_MIN_ELEMENTS
    few |= point_loops(scene, el, order, chain_offsets, walk[: joined[-1]], joined)
    if few.any():
        lens = np.diff(joined)
        keep = ~np.repeat(few, lens)
        walk = np.concatenate([walk[: joined[-1]][keep], walk[: joined[-1]][~keep], walk[joined[-1]:]])
        joined = np.r_[0, np.cumsum(lens[~few])].astype(np.int64)
    if len(joined) == 1:
        return order, loop_offsets, chain_offsets
    # the elements of each joined loop, chain after chain, turned to start at the smallest
    chains = walk[: joined[-1]]
    rows, idx = expand_ranges(chain_offsets[chains], sizes[chains])
    loop_of = np.repeat(np.arange(len(joined) - 1), np.diff(joined))[rows]
    elements = order[idx]
    lengths = np.bincount(loop_of, minlength=len(joined) - 1)
    start = np.r_[0, np.cumsum(lengths)[:-1]]
    pos = np.arange(len(elements)) - start[loop_of]
    smallest = np.full(len(lengths), np.iinfo(np.int64).max)
    np.minimum.at(smallest, loop_of, elements)
    at_smallest = elements == smallest[loop_of]
    shift = np.zeros(len(lengths), np.int64)
    shift[loop_of[at_smallest]] = pos[at_smallest]
    turned = np.empty_like(elements)
    turned[start[loop_of] + (pos - shift[loop_of]) % lengths[loop_of]] = elements
    rest = walk[joined[-1]:]
    _, r_idx = expand_ranges(chain_offsets[rest], sizes[rest])
    n_loop = loop_offsets[-1]
    new_order = np.concatenate([order[:n_loop], turned, order[r_idx]])
    new_loops = np.concatenate([loop_offsets, n_loop + np.cumsum(lengths)])
    new_chains = new_loops[-1] + np.r_[0, np.cumsum(sizes[rest])]
    return new_order, new_loops.astype(np.int64), new_chains.astype(np.int64)


def point_loops(scene, el, order, chain_offsets, chains, joined):
    """Which loops joined by :func:`join_open_chains` are points at epsilon's resolution
    (:func:`point_chains` of the loop as one chain) whose elements all run one way along
    one great circle (tangents within STRAIGHT_COSINE): chains a few epsilon long running
    out and straight back across the gap, bounding nothing. (A lune of two elements
    running there and back, random_boxes(300) vertex 98, is a sliver cell and stays.) Their
    turning sum, 0 across a gap running back, would make them a hemisphere's outline
    (office(120, 103), a desk top's corner, vertex 87: two pieces of one VE arc 4.5e-5 rad
    long split at a transition, a hole of 2π in cells of 3e-3 sr, the vertex's cells
    summing to -4π).

    Parameters
    ----------
    el : Elements
    order, chain_offsets : as :func:`form_loops`
    chains : (c,) int
        The chains of the joined loops, loop after loop.
    joined : (j + 1,) int
        Loop i is ``chains[joined[i]:joined[i + 1]]``.

    Returns
    -------
    (j,) bool
    """
    sizes = np.diff(chain_offsets)[chains]
    _, idx = expand_ranges(chain_offsets[chains], sizes)
    per_loop = np.bincount(np.repeat(np.arange(len(joined) - 1), np.diff(joined)), weights=sizes,
                           minlength=len(joined) - 1).astype(np.int64)
    offsets = np.r_[0, np.cumsum(per_loop)].astype(np.int64)
    walk = el.take(order[idx])
    loop_of = np.repeat(np.arange(len(per_loop)), per_loop)
    first = walk.start_tangent[offsets[:-1]][loop_of]
    bent = np.minimum(np.einsum("ij,ij->i", walk.start_tangent, first), np.einsum("ij,ij->i", walk.end_tangent, first))
    straight = np.ones(len(per_loop), bool)
    np.logical_and.at(straight, loop_of, bent >= STRAIGHT_COSINE)
    return straight & point_chains(scene, walk, offsets)


def end_tolerance(scene, el, index):
    """The join tolerance at the end of each element ``index`` of ``el``: JOIN_EPSILONS
    epsilon seen from the nearest edge the end's line meets (:func:`line_reach`), between
    JOIN_CHORD and JOIN_LIMIT (:func:`join_open_chains`).

    The merged events lie on the family of the edge nearest the vertex that the end's line
    meets (a VEE node (v, e, e') seen along e, merged on VE (v, e')), not always on e itself.

    Returns
    -------
    (k,) float
    """
    reach = line_reach(scene, el.vertex[index], el.end[index], el.end_reach[index])
    return np.clip(JOIN_EPSILONS * scene.epsilon / np.maximum(reach, 1e-300), JOIN_CHORD, JOIN_LIMIT)


def line_reach(scene, vertex, direction, reach):
    """Distance from each vertex to the nearest generator edge its line meets (within
    epsilon, on either side of the vertex), at most ``reach``.

    Edges at the vertex are left out (they meet every line through it there).

    Parameters
    ----------
    scene : Scene
    vertex : (m,) int
    direction : (m, 3) float
        Unit directions of the lines.
    reach : (m,) float
        Distance to the edge point of each line's own family (an upper bound).

    Returns
    -------
    (m,) float
    """
    ge = scene.generator_edges
    ev = scene.half_edges.edge_vertices[ge]
    return _line_reach(np.ascontiguousarray(scene.vertices[vertex], dtype=np.float64),
                       np.ascontiguousarray(direction, dtype=np.float64), np.asarray(vertex, np.int64),
                       np.asarray(reach, np.float64), np.ascontiguousarray(scene.vertices[ev[:, 0]]),
                       np.ascontiguousarray(scene.vertices[ev[:, 1]]), ev[:, 0].astype(np.int64),
                       ev[:, 1].astype(np.int64), float(scene.epsilon))


@njit(cache=True)
def _line_reach(origin, direction, vertex, reach, a, b, va, vb, tol):
    """:func:`line_reach` over every (line, edge) pair: lines only at the open chains' ends."""
    out = reach.copy()
    for i in range(len(origin)):
        o, d = origin[i], direction[i]
        for k in range(len(a)):
            if va[k] == vertex[i] or vb[k] == vertex[i]:
                continue
            e0, e1, e2 = b[k, 0] - a[k, 0], b[k, 1] - a[k, 1], b[k, 2] - a[k, 2]
            w0, w1, w2 = o[0] - a[k, 0], o[1] - a[k, 1], o[2] - a[k, 2]
            dd = d[0] * e0 + d[1] * e1 + d[2] * e2
            ee = e0 * e0 + e1 * e1 + e2 * e2
            dw = d[0] * w0 + d[1] * w1 + d[2] * w2
            ew = e0 * w0 + e1 * w1 + e2 * w2
            den = ee - dd * dd
            if den <= PARALLEL_TOLERANCE * ee:  # the edge runs along the line
                continue
            t = (dd * ew - ee * dw) / den  # closest point of the line to the edge's line
            if abs(t) >= out[i] or t == 0.0:
                continue
            u = min(max((ew + t * dd) / ee, 0.0), 1.0)
            p0 = w0 + t * d[0] - u * e0
            p1 = w1 + t * d[1] - u * e1
            p2 = w2 + t * d[2] - u * e2
            if p0 * p0 + p1 * p1 + p2 * p2 <= tol * tol:
                out[i] = abs(t)
    return out


# --------------------------------------------------------------------------------------
# loops on the sphere (elements of loop j contiguous: loop_offsets[j]:loop_offsets[j + 1])


@dataclass
class Gaps:
    """Where the loops' elements do not meet end to start (:func:`loop_gaps`).

    Attributes
    ----------
    index, next : (g,) int
        The element ending at each gap and the element starting after it.
    at_p, at_q : (g,) float
        The turns from the element's end tangent to the gap's great circle at its end p,
        and from the gap's circle to the next element's start tangent at its start q.
    corner : (g,) bool
        The loop turns once there, at the corner where the two elements' great circles
        meet (a spike or a crossing by the gap); elsewhere it runs along the gap.
    placed : (g,) bool
        Corners that are one point of both elements (:attr:`meet`): the incoming element
        cut or lengthened to end there, the next one to start there, each keeping its
        direction.
    meet : (g, 3) float
        That point, unit, where ``placed``.
    """

    index: np.ndarray
    next: np.ndarray
    at_p: np.ndarray
    at_q: np.ndarray
    corner: np.ndarray
    placed: np.ndarray
    meet: np.ndarray


def loop_gaps(el, loop_offsets):
    """The gaps of loops on a vertex's sphere and how the loops run across them.

    A gap is an element ending farther than JOIN_CHORD from the next one's start
    (:func:`join_open_chains`), or farther than CUSP_GAP at a cusp (a corner turning back
    within CUSP_ANGLE of ±π). The loop runs along the great circle between its ends,
    turning at both, unless the two elements' great circles meet next to the gap (within
    CORNER_REACH chords of both its ends), or the gap runs straight back along either
    element (a spike, within SPIKE_ANGLE of ±π at an end): the corner is then where the
    circles meet, and the loop turns there once (:func:`sphere_turning_sums`).

    Returns
    -------
    Gaps
    """
    n = loop_offsets[-1]
    nxt, _ = loop_successors(loop_offsets)
    turn = corner_turns(el, loop_offsets)
    p, q = el.end[:n], el.start[nxt]
    chord = row_norms(q - p)
    # at a cusp (the loop turns back, e.g. the base of a sliver triangle whose base is
    # below JOIN_CHORD) the turn is π plus the apex angle: one turn between the
    # tangents, in (-π, π], wraps it to -π plus that angle; the gap's side decides
    cusp = (np.abs(turn) > np.pi - CUSP_ANGLE) & (chord > CUSP_GAP)
    gap = np.flatnonzero((chord > JOIN_CHORD) | cusp)
    p, q, chord, after = p[gap], q[gap], chord[gap], nxt[gap]
    a, b = el.start[gap], el.end[after]  # the incoming element's start, the next one's end
    cos = np.einsum("ij,ij->i", p, q)[:, None]
    leave, arrive = q - cos * p, cos * q - p  # the great circle's tangents at p and at q
    at_p = signed_angle(el.end_tangent[gap], leave, p)
    at_q = signed_angle(arrive, el.start_tangent[after], q)
    # where the two elements' great circles meet by the gap (the incoming element
    # overshoots the corner, or the outgoing one starts before it: their families kept
    # different events of a merged group) the corner is that meeting point and the loop
    # turns there once, from the incoming to the outgoing tangent; bridging would add a
    # loop of no area around it (a full turn). So where the gap runs straight back along
    # either element (a spike: one great circle, or a corner on that element, whose ±π
    # rounding decides). Elsewhere the gap is a side V1 lost, and the loop runs along it.
    spike = np.maximum(np.abs(at_p), np.abs(at_q)) > np.pi - SPIKE_ANGLE
    n_in, n_out = np.cross(a, p), np.cross(q, b)
    meet = np.cross(n_in, n_out)
    size = row_norms(meet)
    ok = size > PARALLEL_TOLERANCE  # circles crossing at more than ~1e-12 rad
    meet[ok] /= size[ok, None]
    meet *= np.where(np.einsum("ij,ij->i", meet, p) < 0, -1.0, 1.0)[:, None]
    from_p, from_q = row_norms(meet - p), row_norms(meet - q)
    # ... next to the gap, and not at the elements' other ends (a loop of two elements
    # and a gap, all about as long: their circles meet at its third corner)
    near = (ok & (np.maximum(from_p, from_q) <= CORNER_REACH * chord)
            & (2 * from_p < row_norms(a - p)) & (2 * from_q < row_norms(b - q)))
    # The corner as a point of both elements: next to the gap (a spike's circles meet by
    # the end the gap runs back to, possibly beyond the incoming element's middle), and
    # each element keeping its direction when cut or lengthened to it. Point location
    # needs it (:func:`loop_segments`): a spike's element runs on past the corner, and
    # a reference point beside that part lies outside the loop's region.
    placed = (ok & (np.minimum(from_p, from_q) <= CORNER_REACH * chord)
              & (np.einsum("ij,ij->i", np.cross(a, meet), n_in) > 0)
              & (np.einsum("ij,ij->i", np.cross(meet, b), n_out) > 0))
    corner = spike | near
    return Gaps(gap, after, at_p, at_q, corner, corner & placed, meet)


def sphere_turning_sums(el, loop_offsets):
    """:func:`viscx.skeleton.loops.turning_sums` of loops on a vertex's sphere, bridging gaps.

    Across a gap (:func:`loop_gaps`) the loop runs along the great circle between its
    ends, turning at both of them: turning once from the incoming to the outgoing tangent
    would miss a full turn where the gap runs back (a turn beyond ±π). Where the gap has
    a corner (the two elements' circles meet next to it, or it runs back along one of
    them) the loop turns once, there.

    Returns
    -------
    (l,) float
        2π minus the solid angle of the loop's left region (Gauss-Bonnet).
    """
    _, loop_of = loop_successors(loop_offsets)
    turn = corner_turns(el, loop_offsets)
    g = loop_gaps(el, loop_offsets)
    turn[g.index] = np.where(g.corner, turn[g.index], g.at_p + g.at_q)
    return np.bincount(loop_of, weights=turn, minlength=len(loop_offsets) - 1)


def reference_points(el, loop_offsets):
    """A point just left of each loop: SPHERE_REFERENCE_OFFSET (at most a thousandth of the
    arc) off the middle of its longest arc (:func:`loop_segments`: elements cut at the
    corners of their gaps, and the gaps' arcs).

    Returns
    -------
    (l, 3) float
    """
    starts, ends, offsets = loop_segments(el, loop_offsets)
    length = np.arccos(np.clip(np.einsum("ij,ij->i", starts, ends), -1.0, 1.0))
    loop_of = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    pick = np.lexsort([-length, loop_of])
    best = pick[np.searchsorted(loop_of[pick], np.arange(len(offsets) - 1))]
    mid = starts[best] + ends[best]
    mid /= row_norms(mid)[:, None]
    left = np.cross(mid, ends[best] - starts[best])
    left /= row_norms(left)[:, None]
    ref = mid + np.minimum(SPHERE_REFERENCE_OFFSET, 1e-3 * length[best])[:, None] * left
    return ref / row_norms(ref)[:, None]


@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def _crosses(a, b, c, d):
    """Whether the minor great-circle arcs a-b and c-d cross ((3,) float each)."""
    n1 = _cross(a[0], a[1], a[2], b[0], b[1], b[2])
    if (n1[0] * c[0] + n1[1] * c[1] + n1[2] * c[2] > 0) == (n1[0] * d[0] + n1[1] * d[1] + n1[2] * d[2] > 0):
        return False
    n2 = _cross(c[0], c[1], c[2], d[0], d[1], d[2])
    if (n2[0] * a[0] + n2[1] * a[1] + n2[2] * a[2] > 0) == (n2[0] * b[0] + n2[1] * b[1] + n2[2] * b[2] > 0):
        return False
    # the two great circles meet at ±x: the arcs cross iff both hold the same one
    x = _cross(n1[0], n1[1], n1[2], n2[0], n2[1], n2[2])
    on_ab = x[0] * (a[0] + b[0]) + x[1] * (a[1] + b[1]) + x[2] * (a[2] + b[2]) > 0
    on_cd = x[0] * (c[0] + d[0]) + x[1] * (c[1] + d[1]) + x[2] * (c[2] + d[2]) > 0
    return on_ab == on_cd


@njit(cache=True)
def _inside(ref, loop_offsets, starts, ends, pair_loop, targets):
    out = np.empty(len(pair_loop), np.bool_)
    mid = np.empty(3)
    for t in range(len(pair_loop)):
        L = pair_loop[t]
        r = ref[L]
        p = targets[t]
        c = r[0] * p[0] + r[1] * p[1] + r[2] * p[2]
        two_legs = c <= -0.5
        if two_legs:  # through a point at right angles to r: both legs are minor arcs
            for k in range(3):
                mid[k] = p[k] - c * r[k]
            size = np.sqrt(mid[0] ** 2 + mid[1] ** 2 + mid[2] ** 2)
            if size < 1e-3:
                k = np.argmin(np.abs(r))
                h0, h1, h2 = 0.0, 0.0, 0.0
                if k == 0:
                    h0 = 1.0
                elif k == 1:
                    h1 = 1.0
                else:
                    h2 = 1.0
                mid[0], mid[1], mid[2] = _cross(r[0], r[1], r[2], h0, h1, h2)
                size = np.sqrt(mid[0] ** 2 + mid[1] ** 2 + mid[2] ** 2)
            for k in range(3):
                mid[k] /= size
        count = 0
        for e in range(loop_offsets[L], loop_offsets[L + 1]):
            if two_legs:
                count += _crosses(r, mid, starts[e], ends[e]) + _crosses(mid, p, starts[e], ends[e])
            else:
                count += _crosses(r, p, starts[e], ends[e])
        out[t] = count % 2 == 0
    return out


def inside_loops(el, loop_offsets, ref, loop, targets):
    """Whether each target direction lies in the left region of a loop: the path from
    the loop's reference point crosses the loop an even number of times (§5.4).

    Parameters
    ----------
    el : Elements
        Loop j's elements are ``loop_offsets[j]:loop_offsets[j + 1]``.
    loop_offsets : (l + 1,) int
    ref : (l, 3) float
        Reference points (:func:`reference_points`).
    loop : (m,) int
    targets : (m, 3) float
        Unit directions.

    Returns
    -------
    (m,) bool
    """
    starts, ends, offsets = loop_segments(el, loop_offsets)
    return _inside(ref, offsets, starts, ends, np.asarray(loop, np.int64), np.ascontiguousarray(targets, dtype=np.float64))


def loop_segments(el, loop_offsets):
    """The great-circle arcs each loop consists of, as the turning sums run along it
    (:func:`sphere_turning_sums`): its elements, each cut or lengthened to the corner of
    a gap where the loop turns once there (:attr:`Gaps.meet`), and the minor arc across
    every other gap (a path through the gap crosses the loop there).

    Returns
    -------
    starts, ends : (k', 3) float
        Loop j's arcs are ``offsets[j]:offsets[j + 1]``, its elements first.
    offsets : (l + 1,) int
    """
    n = loop_offsets[-1]
    g = loop_gaps(el, loop_offsets)
    starts, ends = np.array(el.start[:n], dtype=np.float64), np.array(el.end[:n], dtype=np.float64)
    placed = g.placed
    ends[g.index[placed]] = g.meet[placed]
    starts[g.next[placed]] = g.meet[placed]
    bridge = ~placed
    if not bridge.any():
        return starts, ends, np.asarray(loop_offsets, np.int64)
    _, loop_of = loop_successors(loop_offsets)
    owner = np.concatenate([loop_of, loop_of[g.index[bridge]]])
    order = np.argsort(owner, kind="stable")  # each loop's elements, then its gaps
    starts = np.concatenate([starts, el.end[g.index[bridge]]])[order]
    ends = np.concatenate([ends, el.start[g.next[bridge]]])[order]
    offsets = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=len(loop_offsets) - 1))])
    return np.ascontiguousarray(starts), np.ascontiguousarray(ends), offsets.astype(np.int64)


# --------------------------------------------------------------------------------------
# the builder


def build_vcells(scene, arcs, quiet=True, vertices=None):
    """The V-cells (V2) of every generator vertex, from the VE half-cells (V1).

    Parameters
    ----------
    scene : Scene
    arcs : Arcs
    quiet : bool
        No progress bar.
    vertices : (k,) int, optional
        The generator vertices whose half-cells ``arcs`` holds (default: all);
        only these get a whole-sphere cell when they have no boundary element
        (free points built on their own, :mod:`viscx.skeleton.points`).

    Returns
    -------
    VCells
    """
    with bar(total=3, desc="V-cells", quiet=quiet, unit="stage") as progress:
        progress.set_postfix_str("elements")
        el = boundary_elements(scene, arcs)
        key = np.concatenate([el.vertex[:, None], el.pair], axis=1)
        _, group = unique_rows(key)
        keep = unique_elements(el, group, JOIN_CHORD)
        el, group = el.take(keep), group[keep]
        progress.update()

        progress.set_postfix_str("loops")
        order, loop_offsets, chain_offsets = sphere_loops(scene, el, group)
        walk = el.take(order)  # loops and chains contiguous
        turning = sphere_turning_sums(walk, loop_offsets)
        ref = reference_points(walk, loop_offsets)
        progress.update()

        progress.set_postfix_str("cells")
        loop_group = group[order[loop_offsets[:-1]]]
        cell = cells_of_loops(walk, loop_offsets, loop_group, ref, inside_loops)
        points = point_chains(scene, walk, chain_offsets) | covered_chains(scene, walk, group[order], loop_offsets, chain_offsets)
        result = _assemble(walk, order, loop_offsets, chain_offsets, turning, cell, whole_sphere_cells(scene, el, vertices),
                           points)
        progress.update()
    return result


#: Directions tried, in order, for the pair of a vertex whose sphere is one cell.
_PROBES = np.array([[0.267, 0.534, 0.802], [-0.577, 0.211, 0.789], [0.432, -0.898, 0.083]])


def whole_sphere_cells(scene, el, vertices=None):
    """Generator vertices (of ``vertices``, default all) without boundary elements (nothing
    on their sphere changes the blocker pair, e.g. a lone polygon's corners) and the pair
    of their one cell, cast along the first non-grazing probe direction.

    Returns
    -------
    (w, 5) int
        (vertex, up kind, up, down kind, down).
    """
    lone = np.setdiff1d(scene.generator_vertices if vertices is None else vertices, el.vertex)
    rows = np.zeros((len(lone), 5), np.int64)
    rows[:, 0] = lone
    todo = np.ones(len(lone), bool)
    for probe in _PROBES:
        k = np.flatnonzero(todo)
        if len(k) == 0:
            break
        up_kind, up, down_kind, down, grazing = vertex_ray_blockers(scene, lone[k], np.tile(probe, (len(k), 1)))
        rows[k, 1:] = np.stack([up_kind, up, down_kind, down], axis=1)
        todo[k] = grazing
    return rows


def point_chains(scene, walk, chain_offsets):
    """Open chains that are points at epsilon's resolution: every end of their elements lies
    within the join tolerance of :func:`join_open_chains` (JOIN_EPSILONS epsilon over the
    distance to the nearest edge the last end's line meets) of the chain's start.

    They are V1 arcs shorter than a few epsilon (between two events or an event and a
    transition merged by epsilon-visibility) beside a sliver cell whose other sides V1
    merged away: they bound nothing, and do not keep their vertex from being complete.

    Parameters
    ----------
    scene : Scene
    walk : Elements
        Loops then chains, contiguous (chain j is ``chain_offsets[j]:chain_offsets[j + 1]``).
    chain_offsets : (o + 1,) int

    Returns
    -------
    (o,) bool
    """
    if len(chain_offsets) == 1:
        return np.zeros(0, bool)
    return chain_extents(walk, chain_offsets) <= end_tolerance(scene, walk, chain_offsets[1:] - 1)


#: Points at which an open chain's elements are tested against its group's loops
#: (:func:`covered_chains`): both ends and inner points at these fractions of the chord.
COVER_SAMPLES = (0.0, 0.25, 0.5, 0.75, 1.0)


def cover_tolerance(scene, walk, chain_offsets):
    """(o,) float: how far an open chain may stray from a closed loop of its group and still
    lie on it (:func:`covered_chains`): its :func:`end_tolerance`, the join's."""
    return end_tolerance(scene, walk, chain_offsets[1:] - 1)


def covered_chains(scene, walk, group, loop_offsets, chain_offsets):
    """Open chains lying on loops of their own group: every element runs, at its ends and
    inner points (COVER_SAMPLES), along an element of a closed loop of its group (same
    great circle and direction, within the chain's join tolerance, :func:`end_tolerance`).

    From a vertex v every edge lying in a plane P through v (a desk top's underside under
    which v sits, the floor) is seen along one great circle, and the cells just above
    and just below P change along it only where something off P changes. Several VE
    families of v then give pieces of that one boundary, each family cut at its own
    coplanar events (the points of P its lines pass): partial overlaps, which the
    duplicates' rule of FormLoops (one boundary given twice between the same two points)
    does not see. The loop follows one family's pieces; another's dangle, open chains of
    one element on a cell boundary already closed. They bound nothing new, and do not
    keep their vertex from being complete (office(300): 9 of its 13 incomplete vertices,
    docs/skeleton.md "Furnished buildings", rule 12). The families keep different events of
    a merged run where such a piece ends, so a dangling piece can end a few epsilon past
    the loop's corner (office(271, 113), vertex 252: 7e-6 rad, 0.15 epsilon at the edge):
    within the join tolerance it is the same boundary (rule 15).

    Parameters
    ----------
    walk : Elements
        Loops then chains, contiguous (as :func:`point_chains`).
    group : (n,) int
        The group (vertex, pair) of each element of ``walk``.
    loop_offsets, chain_offsets : (l + 1,) int, (o + 1,) int

    Returns
    -------
    (o,) bool
    """
    n_chains = len(chain_offsets) - 1
    n_loop = loop_offsets[-1]
    if n_chains == 0 or n_loop == 0:
        return np.zeros(n_chains, bool)
    # the loops' elements by group, and their circles (unit normal: start x end)
    by_group = np.argsort(group[:n_loop], kind="stable")
    normal = np.cross(walk.start[by_group], walk.end[by_group])
    size = row_norms(normal)
    normal /= np.maximum(size, 1e-300)[:, None]
    chained = np.arange(n_loop, len(walk))
    chain_of = np.repeat(np.arange(n_chains), np.diff(chain_offsets))
    tolerance = cover_tolerance(scene, walk, chain_offsets)[chain_of]
    # sample points of every chain element, and its own circle's normal
    t = np.asarray(COVER_SAMPLES)
    pts = (1 - t)[None, :, None] * walk.start[chained, None] + t[None, :, None] * walk.end[chained, None]
    pts /= np.linalg.norm(pts, axis=2, keepdims=True)
    own = np.cross(walk.start[chained], walk.end[chained])
    own /= np.maximum(row_norms(own), 1e-300)[:, None]
    first = np.searchsorted(group[by_group], group[chained], "left")
    rows, cand = expand_ranges(first, np.searchsorted(group[by_group], group[chained], "right") - first)
    p = pts[rows]  # (pairs, samples, 3)
    n, a, b = normal[cand], walk.start[by_group][cand], walk.end[by_group][cand]
    tol = tolerance[rows][:, None]
    on = (np.abs(np.einsum("psk,pk->ps", p, n)) <= tol)
    on &= np.einsum("psk,pk->ps", np.cross(a[:, None], p), n) >= -tol
    on &= np.einsum("psk,pk->ps", np.cross(p, b[:, None]), n) >= -tol
    on &= (size[cand] > JOIN_CHORD)[:, None] & (np.einsum("pk,pk->p", n, own[rows]) > 0)[:, None]
    covered = np.zeros((len(chained), len(t)), bool)
    np.logical_or.at(covered, rows, on)
    return np.bincount(chain_of, weights=~covered.all(axis=1), minlength=n_chains) == 0


def _assemble(walk, order, loop_offsets, chain_offsets, turning, cell, whole, points):
    """Cells in canonical order with their loops (outer first), twins and solid angles;
    ``whole`` (vertex, pair) rows are cells without loops covering their sphere; ``points``
    ((o,) bool) the open chains that do not keep their vertex from being complete."""
    n_loops = len(loop_offsets) - 1
    n_bounded = int(cell.max()) + 1 if n_loops else 0
    n_cells = n_bounded + len(whole)
    first = order[loop_offsets[:-1]]  # each loop's smallest element (ids of the sorted table)
    at_first = loop_offsets[:-1]
    pair = np.concatenate([walk.vertex[at_first, None], walk.pair[at_first]], axis=1)
    # the outer loop: the largest turning sum of the cell. Sums equal but for rounding tie
    # and go to the smallest element (two loops along one great circle: a cell of zero
    # area in a degenerate scene): the last bits differ between CPUs' vector units.
    rank_in_cell = np.lexsort([first, -np.round(turning, TURNING_DECIMALS), cell])
    outer = np.zeros(n_loops, bool)
    outer[rank_in_cell[np.searchsorted(cell[rank_in_cell], np.arange(n_bounded))]] = True
    count = np.bincount(cell, minlength=n_cells)
    solid = np.bincount(cell, weights=2 * np.pi - turning, minlength=n_cells) - FOUR_PI * (count - 1)
    # canonical order: vertex, pair, smallest element
    cell_pair = np.zeros((n_cells, 5), np.int64)
    cell_pair[cell] = pair
    cell_pair[n_bounded:] = whole
    cell_first = np.full(n_cells, np.iinfo(np.int64).max)
    cell_first[n_bounded:] = -1
    np.minimum.at(cell_first, cell, first)
    cell_order = np.lexsort([cell_first, *cell_pair.T[::-1]])
    rank = np.empty(n_cells, np.int64)
    rank[cell_order] = np.arange(n_cells)
    loop_order = np.lexsort([first, ~outer, rank[cell]])
    lens = np.diff(loop_offsets)[loop_order]
    idx = np.repeat(loop_offsets[:-1][loop_order], lens) + np.arange(lens.sum()) - np.repeat(np.cumsum(lens) - lens, lens)
    # twin: the cell holding the antipodal image of the outer loop's first element
    n_el = loop_offsets[-1]
    code = walk.half_cell[:n_el] * 4 + walk.antipodal[:n_el] * 2 + walk.side[:n_el]
    loop_of = np.repeat(np.arange(n_loops), np.diff(loop_offsets))
    by_code = np.argsort(code)
    o = at_first[outer]
    mirror = walk.half_cell[o] * 4 + (~walk.antipodal[o]) * 2 + walk.side[o]
    at = np.clip(np.searchsorted(code[by_code], mirror), 0, max(n_el - 1, 0))
    found = (code[by_code][at] == mirror) if n_el else np.zeros(0, bool)
    twin_cell = np.full(n_cells, -1)
    twin_cell[cell[outer]] = np.where(found, cell[loop_of[by_code[at]]] if n_el else -1, -1)
    twin_cell[n_bounded:] = np.arange(n_bounded, n_cells)  # the whole sphere is its own antipode
    twin_cell[cell_pair[:, 1] == BLOCK_VERTEX] = -1
    twin = np.where(twin_cell >= 0, rank[np.maximum(twin_cell, 0)], -1)[cell_order]
    cp = cell_pair[cell_order]
    chain = walk.take(np.arange(n_el, len(walk)))
    chain_first = chain_offsets[:-1] - n_el
    _, vertex_of = np.unique(cp[:, 0], return_inverse=True)
    vertex_of = vertex_of.reshape(-1)
    total = np.bincount(vertex_of, weights=solid[cell_order])
    complete = (np.abs(total - FOUR_PI)[vertex_of] <= SPHERE_COVER_TOLERANCE) & ~np.isin(cp[:, 0], chain.vertex[chain_first[~points]])
    return VCells(
        vertex=cp[:, 0],
        up_kind=cp[:, 1].astype(np.int8),
        up=cp[:, 2],
        down_kind=cp[:, 3].astype(np.int8),
        down=cp[:, 4],
        solid_angle=solid[cell_order],
        twin=twin,
        complete=complete,
        loop_offsets=np.concatenate([[0], np.cumsum(count[cell_order])]).astype(np.int64),
        turning=turning[loop_order],
        element_offsets=np.concatenate([[0], np.cumsum(lens)]).astype(np.int64),
        element=walk.signed[idx],
        antipodal=walk.antipodal[idx],
        open_offsets=(chain_offsets - n_el).astype(np.int64),
        open_element=chain.signed,
        open_antipodal=chain.antipodal,
        open_vertex=chain.vertex[chain_first],
        open_up_kind=chain.pair[chain_first, 0].astype(np.int8),
        open_up=chain.pair[chain_first, 1],
        open_down_kind=chain.pair[chain_first, 2].astype(np.int8),
        open_down=chain.pair[chain_first, 3],
    )


# --------------------------------------------------------------------------------------
# queries


def stored_elements(scene, arcs, signed, antipodal):
    """Elements of stored signed half-cell ids ((k,) int, (k,) bool), in that order."""
    signed = np.asarray(signed, np.int64)
    return element_geometry(scene, arcs, np.abs(signed) - 1, (signed < 0).astype(np.int64), antipodal)


def locate(scene, arcs, vcells, vertex, directions):
    """The V-cells of a vertex holding each direction (point location on its sphere).

    Parameters
    ----------
    scene : Scene
    arcs : Arcs
    vcells : VCells
    vertex : int
    directions : (n, 3) float

    Returns
    -------
    cell : (n,) int
        The cell (index into ``vcells``) holding each direction, -1 where none
        or several do.
    holders : (n,) int
        How many cells hold it (1 where the cells tile the sphere).
    """
    d = np.asarray(directions, dtype=np.float64)
    d = d / row_norms(d)[:, None]
    cells = np.flatnonzero(vcells.vertex == vertex)
    if len(cells) == 0:
        return np.full(len(d), -1), np.zeros(len(d), np.int64)
    first_loop, end_loop = vcells.loop_offsets[cells[0]], vcells.loop_offsets[cells[-1] + 1]
    nl, nd = end_loop - first_loop, len(d)
    held = np.ones((len(cells), nd), bool)
    if nl:
        lo, hi = vcells.element_offsets[first_loop], vcells.element_offsets[end_loop]
        el = stored_elements(scene, arcs, vcells.element[lo:hi], vcells.antipodal[lo:hi])
        offsets = vcells.element_offsets[first_loop: end_loop + 1] - lo
        ref = reference_points(el, offsets)
        cell_of_loop = np.repeat(np.arange(len(cells)), np.diff(vcells.loop_offsets[cells[0]: cells[-1] + 2]))
        step = max(1, LOCATE_CHUNK // nl)
        for k in range(0, nd, step):  # bounded memory: (loop, direction) pairs per call
            part = d[k: k + step]
            inside = inside_loops(el, offsets, ref, np.repeat(np.arange(nl), len(part)), np.tile(part, (nl, 1)))
            np.logical_and.at(held[:, k: k + step], cell_of_loop, inside.reshape(nl, len(part)))
    holders = held.sum(axis=0)
    return np.where(holders == 1, cells[np.argmax(held, axis=0)], -1), holders
