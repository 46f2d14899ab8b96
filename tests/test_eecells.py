"""V2 EE-cells: every edge pair's cells checked against the ray caster at random points
of its square, windings (seed Fig. 7), areas, holes, HDF5, determinism and the plot command."""

import json

import numpy as np
import pytest
from conftest import SAMPLES, soup
from random_scenes import general_position_scene

from viscx.geometry.lines import segment_parameter
from viscx.scene import build_scene, load_scene
from viscx.skeleton.arcs import build_arcs, family_lines
from viscx.skeleton.candidates import build_nodes
from viscx.skeleton.eecells import PENCIL1, PENCIL2, SIDE, SIDE_CODES, build_eecells, ee_blockers, locate, segment_lines
from viscx.skeleton.nodes import BLOCK_EDGE, BLOCK_FACE, BLOCK_SKY

GENERAL = ["two_triangles.obj", "occluder_over_plane.ply", "tetrahedra.obj"]
DEGENERATE = ["boxes_on_floor.obj", "cornell_box.obj", "room_with_door.obj"]
#: Random points per edge pair's square for the ray oracle.
POINTS = 400
#: Points closer than this (square units) to a cell boundary are not judged: the ray
#: caster and the 50-epsilon probes decide them within rounding.
BAND = 1e-4
#: Points whose lines meet an edge closer than this many epsilon (in length) to its end are
#: not judged: the caster's condition 5 rejects them at epsilon; the rest is its rounding.
END_MARGIN = 1.01
#: Required agreement with the ray caster outside the band.
AGREEMENT = 0.999
#: Samples per boundary element when measuring distances to it.
CURVE_SAMPLES = 200

_CACHE = {}


def built(name):
    """(scene, arcs, eecells) of a sample scene or a random scene ("rand:seed")."""
    if name not in _CACHE:
        scene = general_position_scene(int(name.split(":")[1])) if name.startswith("rand:") else load_scene(SAMPLES / name)
        arcs = build_arcs(scene, build_nodes(scene))
        _CACHE[name] = scene, arcs, build_eecells(scene, arcs)
    return _CACHE[name]


def build_all(scene):
    arcs = build_arcs(scene, build_nodes(scene))
    return arcs, build_eecells(scene, arcs)


def pairs_of(ee):
    """Every edge pair with cells or open chains, (p, 2) int."""
    both = np.concatenate([np.stack([ee.edge1, ee.edge2], 1), np.stack([ee.open_edge1, ee.open_edge2], 1)])
    return np.unique(both, axis=0)


def complete_pairs(ee):
    return np.unique(np.stack([ee.edge1, ee.edge2], 1)[ee.complete], axis=0)


def edge_point_parameter(scene, edge, o, d):
    """Parameter on each edge of the point its line meets (closest point), recomputed."""
    ev = scene.half_edges.edge_vertices[edge]
    x, _ = segment_parameter(o, d, scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]])
    return x


def element_polylines(scene, arcs, e1, e2, signed, interval, kind):
    """Each stored element of a pair as a polyline of the square, sampled along its arc's
    own family lines (independent of the builder's Bézier form), or along its side of the
    square (kind SIDE): (k, CURVE_SAMPLES - 2, 2)."""
    u = np.linspace(0.0, 1.0, CURVE_SAMPLES)[1:-1]  # family lines can be undefined at the ends
    s = interval[:, :1] + u * (interval[:, 1:] - interval[:, :1])
    out = np.empty((len(signed), len(u), 2))
    side = kind == SIDE
    code = np.abs(signed[side]) - 1
    out[side, :, 0] = np.where((code < 2)[:, None], code[:, None] % 2, s[side])
    out[side, :, 1] = np.where((code < 2)[:, None], s[side], code[:, None] % 2)
    out[~side] = arc_polylines(scene, arcs, e1, e2, np.abs(signed[~side]) - 1, s[~side])
    return out


def arc_polylines(scene, arcs, e1, e2, arc, s):
    """The points of arcs at parameters s ((k, m) float) in the square of (e1, e2)."""
    k, m = s.shape
    kind = np.repeat(arcs.kind[arc], m)
    gens = np.repeat(arcs.generators[arc], m, axis=0)
    o, d = family_lines(scene, kind, gens, s.reshape(-1))
    out = np.empty((k * m, 2))
    for c, edge in enumerate((e1, e2)):
        x = edge_point_parameter(scene, np.full(len(o), edge), o, np.where(np.linalg.norm(d, axis=1)[:, None] > 0, d, 1.0))
        # VE arcs: the vertex is an end of this edge (a side of the square) or lies on it
        # (a junction: the segment x = const through it), at its nearest point
        ve = kind == 1
        ev = scene.half_edges.edge_vertices[edge]
        other = ve & (gens[:, 1] != edge)
        a, b = scene.vertices[ev[0]], scene.vertices[ev[1]]
        x[other] = np.clip((scene.vertices[gens[other, 0]] - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
        x[ve & (gens[:, 1] == edge)] = s.reshape(-1)[ve & (gens[:, 1] == edge)]
        out[:, c] = x
    return out.reshape(k, m, 2)


def near_polylines(points, lines, band):
    """Whether each point ((n, 2) float) lies within ``band`` of a polyline segment
    ((k, m, 2) float): exact point-segment distances, computed only for the points whose
    x lies within ``band`` of the segment's x-range (farther ones are farther than band;
    the points sorted by x, the segments short). A polyline with an undefined point
    (NaN) puts every point near it: nothing is judged beside a boundary not drawn."""
    a = lines[:, :-1].reshape(-1, 2)
    b = lines[:, 1:].reshape(-1, 2)
    if not np.isfinite(a).all() or not np.isfinite(b).all():
        return np.ones(len(points), bool)
    order = np.argsort(points[:, 0])
    lo = np.searchsorted(points[order, 0], np.minimum(a[:, 0], b[:, 0]) - band, "left")
    hi = np.searchsorted(points[order, 0], np.maximum(a[:, 0], b[:, 0]) + band, "right")
    count = hi - lo
    segment = np.repeat(np.arange(len(a)), count)
    point = order[np.arange(count.sum()) - np.repeat(np.cumsum(count) - count - lo, count)]
    ab = b[segment] - a[segment]
    ap = points[point] - a[segment]
    t = np.clip(np.sum(ap * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0.0, 1.0)
    near = np.zeros(len(points), bool)
    near[point[np.sum((ap - t[:, None] * ab) ** 2, axis=1) <= band * band]] = True
    return near


def pair_boundaries(scene, arcs, ee, e1, e2):
    """Polylines of every element (loops and open chains) of a pair."""
    signed, interval, kind = [], [], []
    for c in np.flatnonzero((ee.edge1 == e1) & (ee.edge2 == e2)):
        lo, hi = ee.element_offsets[ee.loop_offsets[c]], ee.element_offsets[ee.loop_offsets[c + 1]]
        signed.append(ee.element[lo:hi])
        interval.append(ee.element_interval[lo:hi])
        kind.append(ee.element_kind[lo:hi])
    for c in np.flatnonzero((ee.open_edge1 == e1) & (ee.open_edge2 == e2)):
        lo, hi = ee.open_offsets[c], ee.open_offsets[c + 1]
        signed.append(ee.open_element[lo:hi])
        interval.append(ee.open_interval[lo:hi])
        kind.append(ee.open_element_kind[lo:hi])
    if not signed:
        return np.zeros((0, CURVE_SAMPLES - 2, 2))
    return element_polylines(scene, arcs, e1, e2, np.concatenate(signed), np.concatenate(interval), np.concatenate(kind))


def blocker_name(kind, index):
    return {BLOCK_FACE: f"face {index}", BLOCK_SKY: "sky", BLOCK_EDGE: f"edge {index}"}.get(int(kind), f"{kind}:{index}")


def judged_by_caster(scene, e1, e2, x):
    """Whether the caster judges each point ((n, 2) float) of the square of (e1, e2): its
    lines meet both edges farther than epsilon (in length, times ``END_MARGIN``) from their
    ends, and farther than ``BAND`` of the square. Closer, node condition 5 makes every line
    invalid (``ee_blockers`` returns no segment), which is no hidden piece: on a 0.03-long
    desk panel edge epsilon is 5e-4 of the square, and the band alone judged those lines
    hidden (docs/skeleton.md, "EE-cells", ray oracle)."""
    ev = scene.half_edges.edge_vertices[[e1, e2]]
    length = np.linalg.norm(scene.vertices[ev[:, 1]] - scene.vertices[ev[:, 0]], axis=1)
    end = np.maximum(BAND, END_MARGIN * scene.epsilon / length)
    return np.all((x > end) & (x < 1 - end), axis=1)


def ray_oracle(scene, arcs, ee, pairs, n=POINTS, seed=0):
    """Locate random points of each pair's square among its cells and compare the cell's
    blocker pair with the ray caster's (the EE segment judged by maximal_free_segments).

    Returns
    -------
    judged, agreed : int
        Points judged (outside the band) and agreeing: in no cell where the segment is
        hidden, in the one cell with the caster's pair where it is not.
    covered : (p,) float
        Fraction of each pair's judged points with a valid segment (the covered area).
    disagreements : list of str
    """
    rng = np.random.default_rng(seed)
    judged = agreed = 0
    covered = []
    wrong = []
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    points = rng.random((len(pairs), n, 2))
    states = ee_blockers(scene, np.repeat(pairs[:, 0], n), np.repeat(pairs[:, 1], n), points[..., 0].reshape(-1),
                         points[..., 1].reshape(-1)).reshape(len(pairs), n, 5)
    for (e1, e2), x, state in zip(pairs, points, states):
        cell, holders = locate(scene, arcs, ee, e1, e2, x)
        away = ~near_polylines(x, pair_boundaries(scene, arcs, ee, e1, e2), BAND) & judged_by_caster(scene, e1, e2, x)
        c = np.maximum(cell, 0)
        mine = np.stack([ee.back_kind[c], ee.back[c], ee.front_kind[c], ee.front[c]], axis=1)
        valid = state[:, 0] == 1
        agree = np.where(valid, (cell >= 0) & np.all(mine == state[:, 1:], axis=1), holders == 0)
        judged += int(away.sum())
        agreed += int((agree & away).sum())
        covered.append(valid[away].mean() if away.any() else np.nan)
        for i in np.flatnonzero(away & ~agree)[:3]:
            where = (f"cell {cell[i]} ({blocker_name(*mine[i, :2])} -> {blocker_name(*mine[i, 2:])})"
                     if cell[i] >= 0 else f"{holders[i]} cells")
            caster = f"{blocker_name(*state[i, 1:3])} -> {blocker_name(*state[i, 3:])}" if valid[i] else "hidden"
            wrong.append(f"pair ({e1}, {e2}) at (x1, x2) = {np.round(x[i], 6).tolist()}: {where}, rays: {caster}")
    return judged, agreed, np.array(covered), wrong


def assert_oracle(scene, arcs, ee, pairs, seed=0):
    judged, agreed, covered, wrong = ray_oracle(scene, arcs, ee, pairs, seed=seed)
    assert judged >= 0.95 * POINTS * len(pairs)
    assert agreed >= AGREEMENT * judged, (
        f"{judged - agreed} of {judged} points disagree with the ray caster "
        f"({agreed / judged:.5f}); e.g.:\n" + "\n".join(wrong[:20]))
    return judged, agreed, covered


def covered_fraction_matches(ee, pairs, covered, n=POINTS):
    """Σ area of each pair's cells against the caster's fraction of points with a segment
    (binomial, 4σ plus the band's share); returns the pairs fully covered by the caster."""
    full = []
    for (e1, e2), frac in zip(pairs, covered):
        mine = (ee.edge1 == e1) & (ee.edge2 == e2)
        total = ee.area[mine].sum()
        sigma = np.sqrt(max(total * (1 - total), 1.0 / n) / n)
        assert abs(total - frac) <= 4 * sigma + 0.01, (e1, e2, total, frac)
        if frac == 1.0:
            full.append((e1, e2, total))
    return full


# ---------------------------------------------------------------------------------------
# ray oracle


@pytest.mark.parametrize("name", GENERAL)
def test_ray_oracle_on_every_pair(name):
    """General position: every pair's loops close, and its cells carry the blocker pair the
    ray caster finds at random points of the square (none where it finds no segment)."""
    scene, arcs, ee = built(name)
    assert len(ee.open_edge1) == 0 and np.all(ee.complete) and len(ee) > 0
    pairs = pairs_of(ee)
    _, _, covered = assert_oracle(scene, arcs, ee, pairs)
    covered_fraction_matches(ee, pairs, covered)


@pytest.mark.slow
@pytest.mark.parametrize("name", DEGENERATE)
def test_ray_oracle_on_complete_pairs_of_degenerate_samples(name):
    """Degenerate samples: pairs whose loops all close pass the oracle (40 of them here,
    all with ``test_ray_oracle_on_all_complete_pairs_of_degenerate_samples``); the others
    are V1's gaps (docs/skeleton.md, "EE-cells"). Under slow while every pair of the three
    is complete (``test_measured_gaps_of_degenerate_samples``): then
    ``test_ray_oracle_on_every_pair_of_degenerate_samples`` judges all of them."""
    scene, arcs, ee = built(name)
    assert_oracle(scene, arcs, ee, complete_pairs(ee)[::max(1, len(complete_pairs(ee)) // 40)])


@pytest.mark.slow
@pytest.mark.parametrize("name", DEGENERATE)
def test_ray_oracle_on_all_complete_pairs_of_degenerate_samples(name):
    scene, arcs, ee = built(name)
    assert_oracle(scene, arcs, ee, complete_pairs(ee))


#: Measured on the degenerate samples (docs/skeleton.md, "EE-cells"): complete pairs, pairs,
#: open chains (before the junction segments: 187/244/83, 390/398/8, 100/124/26; before V2's
#: segments and the finer probe: 213/244/35, 390/398/8, 124/124/0). A change means V1 or
#: the squares' boundaries changed: update the docs.
MEASURED_GAPS = {
    "boxes_on_floor.obj": (244, 244, 0),
    "cornell_box.obj": (398, 398, 0),
    "room_with_door.obj": (124, 124, 0),
}


@pytest.mark.parametrize("name", DEGENERATE)
def test_measured_gaps_of_degenerate_samples(name):
    _, _, ee = built(name)
    assert (len(complete_pairs(ee)), len(pairs_of(ee)), len(ee.open_edge1)) == MEASURED_GAPS[name]


@pytest.mark.parametrize("name", DEGENERATE)
def test_ray_oracle_on_every_pair_of_degenerate_samples(name):
    """Issue #4's acceptance on the degenerate samples: over all pairs (complete or not), at
    least 99.9 % of the random points outside the band lie in the one cell with the ray
    caster's pair (before V2's segments and the finer probe: boxes_on_floor 89.1 %,
    cornell_box 98.2 %; now 100 % on all three)."""
    scene, arcs, ee = built(name)
    judged, agreed, covered = assert_oracle(scene, arcs, ee, pairs_of(ee))
    covered_fraction_matches(ee, pairs_of(ee), covered)


def elements_of_pair(ee, e1, e2):
    """(signed element, kind, interval) of every loop element of a pair's cells."""
    rows = [np.arange(ee.element_offsets[ee.loop_offsets[c]], ee.element_offsets[ee.loop_offsets[c + 1]])
            for c in np.flatnonzero((ee.edge1 == e1) & (ee.edge2 == e2))]
    rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    return ee.element[rows], ee.element_kind[rows], ee.element_interval[rows]


def test_square_side_closes_two_edges_of_one_box():
    """boxes_on_floor, edges 6 ((1, 0, 1)-(3, 0, 1)) and 15 ((3, 2, 3)-(3, 0, 3)) of box 0: every
    line from edge 6 to edge 15 runs through the box, edge to edge (the caster: one pair at
    every random point, so the cell is the whole square, area 1). Its side x1 = 1, the lines
    from vertex 8 to edge 15, lies on the face x = 3 (grazing: V1 has no VE arc there), so
    the cell's loop closes only with a square-side element running up that side."""
    scene, arcs, ee = built("boxes_on_floor.obj")
    mine = np.flatnonzero((ee.edge1 == 6) & (ee.edge2 == 15))
    assert len(mine) == 1 and ee.complete[mine[0]]
    c = mine[0]
    assert (ee.back_kind[c], ee.back[c], ee.front_kind[c], ee.front[c]) == (BLOCK_EDGE, 6, BLOCK_EDGE, 15)
    assert ee.area[c] == pytest.approx(1.0, abs=1e-9)
    signed, kind, interval = elements_of_pair(ee, 6, 15)
    side = kind == SIDE
    # side code 1 is x1 = 1, run with x2 increasing (+): from x2 = 0 up to x2 = 1
    assert np.array_equal(signed[side], [SIDE_CODES["x1=1"] + 1])
    assert np.allclose(interval[side], [[0.0, 1.0]])
    judged, agreed, covered = assert_oracle(scene, arcs, ee, [(6, 15)])
    assert agreed == judged and covered[0] == 1.0


def test_pencil_segments_close_boxes_on_floor():
    """boxes_on_floor: pencils V1 lacks, and V1's own pencils of the touched plane x = 3.
    Pairs (15, 22) and (22, 29): vertical edges 15 (x = 3, z = 3) and 29 (x = 6, z = 5) are
    parallel, and their plane crosses edge 22 ((3, 1.5, 3.5)-(4.5, 1.5, 3.5)) at x = 3.75,
    x = 1/2 on it: every line through that point and edge 15 (or 29) meets the other one;
    V2 adds that pencil (no face lies in their plane). Pairs (2, 15) and (1, 12): floor edges
    2 ((0, 0, 10)-(10, 0, 10)) and 1 ((0, 0, 0)-(10, 0, 0)) cross the plane x = 3 of boxes
    0 and 1's contact at x1 = 3/10, where tangency at 15 (12) flips. That plane is touched,
    so V1 builds its pencils, one arc per line named by the first touched face it crosses
    (``arcs.first_pencil_pair``): (12, 1, 15) up to x2 = 1/3 on edge 12 (lines
    across box 0's face from side to side), (12, 1, 14) above; V2 adds no pencil there. The
    side x2 = 1 of (1, 12) (V1's VE arc (9, 1), whole) is cut where the pencil ends on it."""
    scene, arcs, ee = built("boxes_on_floor.obj")
    for (e1, e2), kind, third, value in (((15, 22), PENCIL2, 29, 0.5), ((22, 29), PENCIL1, 15, 0.5)):
        signed, kinds, interval = elements_of_pair(ee, e1, e2)
        pencil = kinds == kind
        assert pencil.any(), (e1, e2)
        ident = np.abs(signed[pencil]) - 1
        assert np.all(ident == third)
        axis, c = segment_lines(scene, kinds[pencil], ident, np.full(len(ident), e1), np.full(len(ident), e2))
        assert np.all(axis == kind - PENCIL1) and np.allclose(c, value, atol=1e-12), (e1, e2, c)
    for e1, e2 in ((1, 12), (2, 15)):
        signed, kinds, interval = elements_of_pair(ee, e1, e2)
        assert not np.any(kinds == PENCIL1), (e1, e2)
    for gens, span in (((12, 1, 15), (0.0, 1 / 3)), ((12, 1, 14), (1 / 3, 1.0))):
        rows = np.flatnonzero(np.all(arcs.generators == gens, axis=1) & (arcs.kind == 0))
        assert len(rows) and np.isclose(arcs.interval[rows, 0].min(), span[0]) and np.isclose(
            arcs.interval[rows, 1].max(), span[1]), gens
        assert np.allclose(np.sort(arcs.interval[rows], axis=0)[1:, 0], np.sort(arcs.interval[rows], axis=0)[:-1, 1])
    signed, kinds, interval = elements_of_pair(ee, 1, 12)
    side = (kinds == 0) & (arcs.kind[np.abs(signed) - 1] == 1) & (arcs.generators[np.abs(signed) - 1, 0] == 9)
    assert np.allclose(np.unique(interval[side]), [0.0, 0.3, 1.0])
    pairs = [(1, 12), (2, 15), (15, 22), (22, 29)]
    assert all(np.all(ee.complete[(ee.edge1 == a) & (ee.edge2 == b)]) for a, b in pairs)
    assert_oracle(scene, arcs, ee, pairs)


def test_one_arc_per_pencil_line(monkeypatch):
    """A line of a touched plane's pencil crossing several of the plane's edges has one arc:
    without ``arcs.first_pencil_pair`` boxes_on_floor's pencils through floor edges 1 and 2
    get several arcs over the same lines (one per pair of the faces' edges they cross that
    node condition (4) admits). The EE-squares they run in did not close; since V2 keeps a
    boundary given twice once when the two are one curve (``eecells.one_curve``, compared
    as curves, not at their parameters' middles) they close either way, so the repeated
    arcs are counted here: the same pencil lines (EEE families with one third edge and one
    interval) in several families."""
    from viscx.skeleton.arcs import EEE
    from viscx.skeleton.arcs import lines as arcs_lines

    def repeated(arcs):
        """EEE arcs of pencils (p, q, r) whose lines another family's arc also runs along:
        same parameter edge p and interval, another pair (q, r)."""
        eee = arcs.kind == EEE
        key = np.concatenate([arcs.generators[eee][:, :1], np.round(arcs.interval[eee], 9)], axis=1)
        _, count = np.unique(key, axis=0, return_counts=True)
        return int(np.sum(count[count > 1]))

    scene, arcs, ee = built("boxes_on_floor.obj")
    assert ee.complete.all()
    monkeypatch.setattr(arcs_lines, "first_pencil_pair", lambda scene, plane, gens, ends, valid: np.ones(len(plane), bool))
    scene = load_scene(SAMPLES / "boxes_on_floor.obj")
    knocked, _ = build_all(scene)
    assert repeated(knocked) > repeated(arcs), (repeated(knocked), repeated(arcs))


def test_pencil_blocked_at_its_last_edge(tmp_path):
    """Two blocks touching with partly overlapping faces (``contact_scene_obj`` 20 of the
    discontinuity tests): the pencil of light edge 7 across the short block's face, from
    its top edge 25 down to its bottom edge 20 on the floor, is blocked at edge 20, where
    its segment ends. That crossing counts (``arcs.pencil_crossings``: within epsilon of the
    segment's ends); when it did not, rounding made some lines' first face pair a single
    edge, their samples flickered invalid and the square (7, 25) stayed open."""
    from test_discontinuities import contact_scene_obj

    scene = load_scene(contact_scene_obj(tmp_path / "c.obj", 20))
    arcs, ee = build_all(scene)
    rows = np.flatnonzero(np.all(arcs.generators == [20, 7, 25], axis=1))
    assert len(rows) and np.all(arcs.end_type[rows[1:], 0] != 3)  # no transition inside
    square = (ee.edge1 == 7) & (ee.edge2 == 25)
    assert square.sum() >= 2 and np.all(ee.complete[square])
    judged, agreed, _ = assert_oracle(scene, arcs, ee, [(7, 25)])
    assert judged > 0 and agreed == judged


def test_finer_probe_closes_the_cornell_light_slivers():
    """cornell_box: the lines from the room's vertical edges' top ends to the far ceiling edges
    pass the light (0.1 below the ceiling) within slivers about 1e-4 of the square wide,
    thinner than the 50 epsilon probes (8.7e-5 of it): their EEE arcs seemed to bound
    nothing, and 8 pairs stayed open. Probed again at 5 epsilon (the squares left open),
    they close and agree with the ray caster."""
    scene, arcs, ee = built("cornell_box.obj")
    pairs = [(2, 10), (2, 11), (4, 8), (4, 10), (6, 8), (6, 9), (7, 9), (7, 11)]
    for e1, e2 in pairs:
        mine = (ee.edge1 == e1) & (ee.edge2 == e2)
        assert mine.any() and np.all(ee.complete[mine]), (e1, e2)
    # the sliver of pair (2, 10): a hidden region between x1 = 0.99952 and 0.99970
    cell, holders = locate(scene, arcs, ee, 2, 10, np.array([[0.9996, 0.85], [0.9993, 0.85], [0.99985, 0.85]]))
    state = ee_blockers(scene, np.full(3, 2), np.full(3, 10), np.array([0.9996, 0.9993, 0.99985]), np.full(3, 0.85))
    assert state[:, 0].tolist() == [0, 1, 1] and holders.tolist() == [0, 1, 1]
    assert_oracle(scene, arcs, ee, pairs)


def test_segments_keep_the_loops_of_one_form_loops():
    """The squares left open are built again with V2's segments and FormLoops runs on them
    alone; the merged walks are those of one FormLoops over all the elements."""
    from viscx.skeleton import eecells as E

    scene, arcs, _ = built("boxes_on_floor.obj")
    squares = E.arc_squares(scene, arcs)
    order = np.argsort(squares[1] * (1 << 32) + squares[2], kind="stable")
    squares = tuple(q[order] for q in squares)
    el = E.boundary_elements(scene, arcs, squares)
    loops = E._loops(scene, el)
    segments = E.open_segments(scene, el, loops[0], loops[2])
    assert len(segments.e1) and np.any(segments.kind != SIDE)
    merged, walks = E._with_segments(scene, arcs, squares, segments, el, loops)
    for a, b in zip(walks, E._loops(scene, merged)):
        assert np.array_equal(a, b)


def test_a_ray_through_a_joined_corner_still_crosses_the_loop():
    """A sliver loop (cornered at a gap joined within the join tolerance) with its longest
    element along x2 = 1: its reference point lies 1e-9 below that element, and the
    horizontal ray from it passes the gap between the corner's two ends. The bridged gap
    counts as crossed, so a point far from the sliver is outside it (without the bridge
    the whole square was: random_boxes(300), pair (140, 149))."""
    from viscx.skeleton.eecells import Elements, inside_square_loops, reference_points

    a, b, c, d = [0.7279, 1.0], [0.7283, 0.9997], [0.7380, 0.99999], [0.7380, 1.0]
    start = np.array([a, b, d], float)
    end = np.array([b, c, a], float)
    lift = lambda p: np.concatenate([p, np.ones((len(p), 1))], axis=1)  # noqa: E731
    t = end - start
    t = lift(t / np.linalg.norm(t, axis=1)[:, None]) - [0, 0, 1]
    el = Elements(kind=np.zeros(3, np.int8), arc=np.arange(3), side=np.zeros(3, np.int64), e1=np.zeros(3, np.int64),
                  e2=np.ones(3, np.int64), pair=np.zeros((3, 4), np.int64), interval=np.zeros((3, 2)),
                  start=lift(start), end=lift(end), weight=np.full((3, 2), 0.5), start_tangent=t, end_tangent=t)
    offsets = np.array([0, 3])
    ref = reference_points(el, offsets)
    assert ref[0, 1] < 1.0 and ref[0, 1] > c[1]  # below the longest element, above the gap's lower end
    inside = inside_square_loops(el, offsets, ref, np.zeros(3, np.int64), np.array([[0.5, 0.5], [0.9, 0.99999], [0.733, 0.9999]]))
    assert inside.tolist() == [False, False, True]


def test_junction_segments_close_the_room():
    """room_with_door: the inner wall's corners lie inside the room's edges (T-junctions).
    In the square of such an edge e' and an edge e, the lines through the corner w and e
    (V1's VE arc (w, e)) are the segment x' = s_w: tangency at e' changes across it, and
    so does the pair. With those segments every pair of the room closes (before: 26 open
    chains, all ending on them), and the pairs holding one agree with the ray caster."""
    from viscx.skeleton.arcs import VE, edge_junctions

    scene, arcs, ee = built("room_with_door.obj")
    j = edge_junctions(scene)
    on = j.edge[j.vertex >= 0]
    assert len(on) >= 4
    ev = scene.half_edges.edge_vertices
    # elements on a junction segment: VE arcs whose vertex is no end of either edge of the square
    cells = np.repeat(np.arange(len(ee)), np.diff(ee.element_offsets[ee.loop_offsets]))
    arc = np.abs(ee.element) - 1
    w = arcs.generators[arc, 0]
    inner = (arcs.kind[arc] == VE) & ~np.any(ev[ee.edge1[cells]] == w[:, None], axis=1) \
        & ~np.any(ev[ee.edge2[cells]] == w[:, None], axis=1)
    pairs = np.unique(np.stack([ee.edge1[cells[inner]], ee.edge2[cells[inner]]], axis=1), axis=0)
    assert len(pairs) >= 10 and np.all(np.isin(pairs, on).any(axis=1))
    assert len(ee.open_edge1) == 0 and np.all(ee.complete)
    assert_oracle(scene, arcs, ee, pairs)


def test_crossing_junction_segments_close_boxes_on_floor():
    """boxes_on_floor: box 0's edge 15 and box 1's edge 21 cross at X = (3, 1.5, 3) on
    their contact plane x = 3 (an X-junction). In the squares (e, 15) and (e, 21) the
    lines through X and e (V1's XE arcs) are the segment x' = s_X: tangency at 15 and 21
    changes across it, and so does the pair. With those segments 18 more pairs close
    (before: open chains ending on them), and they agree with the ray caster."""
    from viscx.skeleton.arcs import XE, edge_crossings

    scene, arcs, ee = built("boxes_on_floor.obj")
    cr = edge_crossings(scene)
    assert cr.edges.tolist() == [[15, 21]] and np.allclose(cr.point, [[3.0, 1.5, 3.0]])
    assert np.all(arcs.kind[-np.count_nonzero(arcs.kind == XE):] == XE)  # after the VE arcs
    # XE arcs run through X: generators (15, e, 21), the line at s through X and e(s)
    xe = np.flatnonzero(arcs.kind == XE)
    assert len(xe) and np.all(arcs.generators[xe][:, [0, 2]] == [15, 21]) and arcs.counts()["XE"] == len(xe)
    assert "XE" not in built("room_with_door.obj")[1].counts()  # T-junctions only
    o, d = family_lines(scene, arcs.kind[xe], arcs.generators[xe], arcs.parameter[xe])
    assert np.allclose(o, cr.point[0])
    # pairs whose complete cells are bounded by a crossing segment
    cells = np.repeat(np.arange(len(ee)), np.diff(ee.element_offsets[ee.loop_offsets]))
    on = arcs.kind[np.abs(ee.element) - 1] == XE
    bounded = np.unique(np.stack([ee.edge1[cells[on]], ee.edge2[cells[on]]], axis=1), axis=0)
    done = {tuple(p) for p in complete_pairs(ee).tolist()}
    closed = np.array([p for p in bounded.tolist() if tuple(p) in done])
    assert {(0, 15), (15, 18), (15, 23), (2, 21), (8, 21), (21, 29)} <= {tuple(p) for p in closed.tolist()}
    assert np.all(np.isin(closed, [15, 21]).any(axis=1))
    assert_oracle(scene, arcs, ee, closed)


def test_eee_arcs_reach_their_node_across_condition_5s_stretch(monkeypatch):
    """Two boxes of the 100-polygon city on its floor (random_boxes(100, keep=[7, 14]),
    docs/skeleton.md "Arcs", condition 5's stretch). In the square of the floor's edge 0 and
    box 14's top edge 21, the boundary between the cells whose front blocker is box 7's face
    and the sky turns a corner at box 7's top vertex w = 7: the VEE node (7, 0, 21), where the EEE arcs
    (0, 9, 21) along the box's top edge 9 and (0, 7, 21) along its vertical edge 7 meet.
    The lines of the family (0, 7, 21) within epsilon of w along edge 7 are invalid (node
    condition 5), a stretch 20.3 epsilon long along the floor's edge, which the end sample
    (20 epsilon) saw: the arc ended at a transition bisected there, 3e-5 of the square off the
    corner, and the pair stayed open. The arc now ends at the node, every pair is complete and
    the squares of the arc's edges agree with the ray caster (every pair of the scene did, 59 158
    of 59 158 points, when measured); knocked out, the pair is open again."""
    import sys
    from pathlib import Path

    import viscx.skeleton.arcs.stages as stages
    from viscx.skeleton.arcs import EEE, END_NODE, END_TRANSITION

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from scenes import random_boxes

    scene = random_boxes(100, keep=[7, 14])
    nodes = build_nodes(scene)
    arcs = build_arcs(scene, nodes)
    ee = build_eecells(scene, arcs)

    def corner_arc(arcs):
        a = np.flatnonzero((arcs.kind == EEE) & np.all(arcs.generators == [0, 7, 21], axis=1))
        assert len(a) == 1
        return a[0]

    a = corner_arc(arcs)
    assert arcs.end_type[a].tolist() == [END_NODE, END_NODE]
    node = arcs.end_node[a, 0]
    w = np.intersect1d(scene.half_edges.edge_vertices[7], nodes.generators[node, :1])
    assert nodes.generators[node, 1:3].tolist() == [0, 21] and len(w) == 1  # VEE (w, 0, 21), w on edge 7
    assert ee.complete.all() and len(ee.open_edge1) == 0
    # the squares the arc bounds (its edges' skew pairs)
    judged, agreed, _, wrong = ray_oracle(scene, arcs, ee, [[0, 7], [0, 21], [7, 21]], n=2000)
    assert judged >= 5700 and agreed == judged, wrong[:5]
    monkeypatch.setattr(stages, "_endpoint_cuts", lambda scene, kind, gens, cut, s0, s1: np.full(len(cut), -1, np.int8))
    knocked = build_arcs(scene, nodes)
    assert knocked.end_type[corner_arc(knocked), 0] == END_TRANSITION
    knocked_ee = build_eecells(scene, knocked)
    assert {(0, 21)} == set(zip(knocked_ee.open_edge1.tolist(), knocked_ee.open_edge2.tolist()))


def test_loops_closed_across_a_gap_are_probed_again(monkeypatch):
    """Three boxes of the 300-polygon city (random_boxes(300, keep=[20, 23, 41]),
    docs/skeleton.md "EE-cells", loops closed across a gap). In the square of the floor's edge
    2 and box 20's top edge 9, a sky -> sky triangle 3e-4 of the square wide and 9e-4 high
    stands on the side x2 = 1, between two EEE arcs meeting at an E4 node, in a hidden
    region. The side piece (V1's VE arc from edge 9's end to the floor's edge, shorter than the
    join tolerance) has no element at the 50 epsilon probe, which jumps out of the triangle;
    the two other sides' ends joined across the gap into a loop winding by less than 2π, so
    the square seemed closed, was not probed again at 5 epsilon, and the loop was demoted to
    an open chain. Such loops (no point) now send their square to be built again: the side is
    found, the pair is complete and agrees with the ray caster; knocked out, it is open."""
    import sys
    from pathlib import Path

    import viscx.skeleton.eecells as eecells

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from scenes import random_boxes

    scene = random_boxes(300, keep=[20, 23, 41])
    arcs = build_arcs(scene, build_nodes(scene))
    ee = build_eecells(scene, arcs)
    assert (2, 9) in {tuple(p) for p in complete_pairs(ee).tolist()}
    assert not np.any((ee.open_edge1 == 2) & (ee.open_edge2 == 9))
    judged, agreed, _, wrong = ray_oracle(scene, arcs, ee, [[2, 9]], n=2000)
    assert judged >= 1900 and agreed == judged, wrong[:5]
    monkeypatch.setattr(eecells, "_open_loops", lambda scene, el, loops: loops)
    knocked = build_eecells(scene, arcs)
    assert np.any((knocked.open_edge1 == 2) & (knocked.open_edge2 == 9))
    assert (2, 9) not in {tuple(p) for p in complete_pairs(knocked).tolist()}



def test_starts_at_the_same_event_are_linked_first(monkeypatch):
    """Three boxes of the 300-polygon city (random_boxes(300, keep=[32, 39, 45]),
    docs/skeleton.md "EE-cells", rule 17). In the square of the floor's edge 3 and box 39's edge
    19, a triangle 2.5e-4 of the square wide (front faces 272 and 276 of box 45, split by an
    EEE arc of box 45's edge) hangs below a sky -> sky cell whose boundary runs along its two
    upper sides, from the base's left corner R up to the apex and down to its right corner Q,
    then on along the base's line. R and Q lie 2.8e-4 apart, within the join tolerance
    (4.5e-4), so from Q FormLoops could go on at R as well as along the base's line (the
    element starting at Q itself); R's element turns back by 0.34 rad only, clockwise first, and
    took the link: a loop of the triangle's two sides winding by 0 (an open chain that is no
    point), and the outer loop jumped from R to Q. A start at the same event as an end (within
    SQUARE_SAME_POINT_EPSILONS) is now linked before one a merged event away: the pair is
    complete and agrees with the ray caster; knocked out, it is open."""
    import sys
    from pathlib import Path

    import viscx.skeleton.eecells as eecells

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from scenes import random_boxes

    scene = random_boxes(300, keep=[32, 39, 45])
    arcs = build_arcs(scene, build_nodes(scene))
    ee = build_eecells(scene, arcs)
    assert (3, 19) in {tuple(p) for p in complete_pairs(ee).tolist()}
    judged, agreed, _, wrong = ray_oracle(scene, arcs, ee, [[3, 19]], n=1000)
    assert judged >= 950 and agreed == judged, wrong[:5]
    form_loops = eecells.form_loops
    monkeypatch.setattr(eecells, "form_loops", lambda el, group, tolerance, near=None: form_loops(el, group, tolerance))
    knocked = build_eecells(scene, arcs)
    assert (3, 19) not in {tuple(p) for p in complete_pairs(knocked).tolist()}


def test_constant_coordinates_and_cusps_close_their_loops(monkeypatch):
    """Six boxes of the 300-polygon city (random_boxes(300, keep=[17, 18, 21, 31, 40, 47]),
    docs/skeleton.md "EE-cells", rules 18 and 19).

    Rule 18: in the squares of box 21's edge 35 and box 47's edges 64 and 65 (two edges at one
    corner: V1's pencil through the point where edge 35 crosses their plane, x1 constant) a
    triangle is bounded by that pencil, whose x1 at its two ends differs by 4.5e-14 with its
    middle equal to one of them: its Bézier weight was clamped to 1e-12 and its end tangent ran
    0.045 along x1, against 0.03 along x2, so the loop's winding was 0. Such a coordinate is
    now constant (weight 1/2).

    Rule 19: in the square of box 21's edge 39 and box 40's edge 62, a sliver 0.03 of the
    square long and 3e-5 high (face 4 of box 17 in front, two EEE arcs of box 17's edges
    nearly antiparallel) lost its short side: V1 merged the two events 1.7 epsilon apart
    along edge 62 that end it. Its loop closes across that gap, within the join tolerance,
    where one turn between the antiparallel tangents is ±π by their rounding, and it wound by
    0; it now turns along the gap at such a cusp. All three pairs are complete and agree with
    the ray caster; each rule knocked out leaves its pairs open."""
    import sys
    from pathlib import Path

    import viscx.skeleton.eecells as eecells

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from scenes import random_boxes

    scene = random_boxes(300, keep=[17, 18, 21, 31, 40, 47])
    arcs = build_arcs(scene, build_nodes(scene))
    pairs = {(35, 64), (35, 65), (39, 62)}
    ee = build_eecells(scene, arcs)
    assert pairs <= {tuple(p) for p in complete_pairs(ee).tolist()}
    judged, agreed, _, wrong = ray_oracle(scene, arcs, ee, sorted(pairs), n=500)
    assert judged >= 1400 and agreed == judged, wrong[:5]
    monkeypatch.setattr(eecells, "_CONSTANT_SPAN", 1e-14)
    knocked = {tuple(p) for p in complete_pairs(build_eecells(scene, arcs)).tolist()}
    assert pairs - knocked == {(35, 64), (35, 65)}
    monkeypatch.undo()
    windings = eecells.windings
    monkeypatch.setattr(eecells, "windings", lambda el, loop_offsets, bridged=False: windings(el, loop_offsets))
    knocked = {tuple(p) for p in complete_pairs(build_eecells(scene, arcs)).tolist()}
    assert pairs - knocked == {(39, 62)}

def test_finest_probes_close_slivers_thinner_than_epsilon(monkeypatch):
    """Four boxes of the 300-polygon city (random_boxes(300, keep=[4, 20, 29, 32]),
    docs/skeleton.md "EE-cells", rule 20). In the square of box 4's top edge 10 and box 29's
    vertical edge 29 (the city's pair (58, 353)) a sliver between two EEE arcs is thinner than
    one epsilon along the edge that moves most: the fine probe off the near arc, moving at
    least PROBE_ROOM_FLOOR (1 epsilon) of its step, lands beyond the far arc, so that arc's two
    sides differ in the front blocker alone and the sliver's loop stays open. The squares still
    open after V2's segments are built again with the floor at FINEST_PROBE_FLOOR (0.1
    epsilon): the pair is complete and agrees with the ray caster; knocked out, it is open."""
    import sys
    from pathlib import Path

    import viscx.skeleton.eecells as eecells

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from scenes import random_boxes

    scene = random_boxes(300, keep=[4, 20, 29, 32])
    arcs = build_arcs(scene, build_nodes(scene))
    arc, e1, e2 = eecells.arc_squares(scene, arcs)
    mine = (e1 == 10) & (e2 == 29)
    square = (arc[mine], e1[mine], e2[mine])
    ee = eecells.squares_cells(scene, arcs, square)[0]
    assert ee.complete.all() and len(ee.open_edge1) == 0
    judged, agreed, _, wrong = ray_oracle(scene, arcs, ee, [[10, 29]], n=1000)
    assert judged >= 950 and agreed == judged, wrong[:5]
    monkeypatch.setattr(eecells, "FINEST_PROBE_FLOOR", eecells.PROBE_ROOM_FLOOR)
    knocked = eecells.squares_cells(scene, arcs, square)[0]
    assert not knocked.complete.any() and len(knocked.open_edge1) > 0


def check_random_scene(seed, points_seed=0):
    scene, arcs, ee = built(f"rand:{seed}")
    done = complete_pairs(ee)
    judged = agreed = 0
    if len(done):
        judged, agreed, covered = assert_oracle(scene, arcs, ee, done, seed=points_seed)
        covered_fraction_matches(ee, done, covered)
    return len(done), len(pairs_of(ee)), judged, agreed


@pytest.mark.parametrize("seed", range(3))
def test_random_scenes(seed):
    check_random_scene(seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3, 6))
def test_random_scenes_more(seed):
    """Random scenes 3-5 (0-2 run by default)."""
    check_random_scene(seed)


@pytest.mark.slow
@pytest.mark.parametrize("block", range(10))
def test_many_random_scenes(block):
    """100 more random scenes (10 per test); at least 90 % of their pairs complete."""
    done = total = 0
    for seed in range(100 + 10 * block, 110 + 10 * block):
        d, t, _, _ = check_random_scene(seed)
        done, total = done + d, total + t
    assert done >= 0.9 * total, f"only {done} of {total} pairs have closed loops"


def test_most_random_pairs_are_complete():
    done = total = 0
    for seed in range(6):
        _, _, ee = built(f"rand:{seed}")
        done += len(complete_pairs(ee))
        total += len(pairs_of(ee))
    assert done >= 0.9 * total, f"only {done} of {total} pairs have closed loops"


# ---------------------------------------------------------------------------------------
# windings, areas


@pytest.mark.parametrize("name", GENERAL + DEGENERATE + ["rand:1", "rand:2"])
def test_windings(name):
    """Seed Fig. 7: the summed corner and arc angles of every loop are +2π for its cell's
    outer loop (stored first) and -2π for each hole."""
    _, _, ee = built(name)
    assert len(ee.turning) > 0
    for c in range(len(ee)):
        t = ee.turning[ee.loop_offsets[c]: ee.loop_offsets[c + 1]]
        assert t[0] == pytest.approx(2 * np.pi, abs=1e-6), c
        assert np.allclose(t[1:], -2 * np.pi, atol=1e-6), c


@pytest.mark.parametrize("name", GENERAL + ["rand:2", "rand:4"])
def test_areas_sum_to_one_where_the_square_is_covered(name):
    """Where the caster finds a segment at every point of the square, the pair's cell areas
    sum to 1 (exactly: the areas are integrated in closed form); elsewhere they sum to the
    covered fraction (checked by the oracle tests). Every area lies in (0, 1]."""
    scene, arcs, ee = built(name)
    pairs = complete_pairs(ee)
    _, _, covered, _ = ray_oracle(scene, arcs, ee, pairs, n=200)
    full = covered_fraction_matches(ee, pairs, covered, n=200)
    assert len(full) > 0
    for e1, e2, total in full:
        assert total == pytest.approx(1.0, abs=1e-9), (e1, e2)
    assert np.all(ee.area > 0) and np.all(ee.area <= 1 + 1e-12)


# ---------------------------------------------------------------------------------------
# holes


def hole_scene(tilt=0.0):
    """Edge e1 along x (z = 0) of a triangle below it, edge e2 along y (z = 2) of a triangle
    above it, and a small triangle T near z = 1 between them (tilted about x by ``tilt``).
    The line through e1(x1) = (2 x1 - 1, 0, 0) and e2(x2) = (0, 2 x2 - 1, 2) passes z = 1 at
    (x1 - 1/2, x2 - 1/2): untilted, T's shadow in the square is T itself, moved."""
    small = np.array([[-0.12, -0.1, 1.0], [0.15, -0.05, 1.0], [0.02, 0.13, 1.0]])
    c, s = np.cos(tilt), np.sin(tilt)
    small[:, 1:] = (small[:, 1:] - [0, 1]) @ np.array([[c, s], [-s, c]]) + [0, 1]
    vertices = [[-1, 0, 0], [1, 0, 0], [0.2, -0.3, -1], [0, -1, 2], [0, 1, 2], [0.3, 0.2, 3], *small.tolist()]
    return build_scene(soup(vertices, [[0, 1, 2], [3, 4, 5], [6, 7, 8]], [0, 1, 2])), small


def edge_between(scene, p, q):
    ev = scene.half_edges.edge_vertices
    vp = int(np.flatnonzero(np.all(scene.vertices == p, axis=1))[0])
    vq = int(np.flatnonzero(np.all(scene.vertices == q, axis=1))[0])
    return int(np.flatnonzero(np.all(np.sort(ev, axis=1) == sorted((vp, vq)), axis=1))[0])


@pytest.mark.parametrize("tilt", [0.0, 0.6])
def test_an_occluder_between_two_edges_makes_a_hole(tilt):
    """The sky -> sky cell of the pair (e1, e2) has one hole: the lines stabbing T, hidden.
    Its hole's elements are the EEE arcs of e1, e2 and T's edges, its area is 1 - area(T)
    untilted (an independent formula), and the ray oracle agrees (tilted: curved arcs)."""
    scene, small = hole_scene(tilt)
    arcs, ee = build_all(scene)
    e1, e2 = sorted((edge_between(scene, [-1, 0, 0], [1, 0, 0]), edge_between(scene, [0, -1, 2], [0, 1, 2])))
    mine = np.flatnonzero((ee.edge1 == e1) & (ee.edge2 == e2))
    assert len(mine) == 1 and ee.complete[mine[0]]
    c = mine[0]
    assert ee.back_kind[c] == BLOCK_SKY and ee.front_kind[c] == BLOCK_SKY
    assert ee.loop_offsets[c + 1] - ee.loop_offsets[c] == 2
    hole = ee.loop_offsets[c] + 1
    lo, hi = ee.element_offsets[hole], ee.element_offsets[hole + 1]
    t_edges = {edge_between(scene, small[i], small[(i + 1) % 3]) for i in range(3)}
    for a in np.abs(ee.element[lo:hi]) - 1:
        assert arcs.kind[a] == 0 and {e1, e2} < set(arcs.generators[a].tolist())
        assert (set(arcs.generators[a].tolist()) - {e1, e2}) <= t_edges
    if tilt == 0.0:
        a, b, d = small
        area_t = 0.5 * abs(np.cross(b - a, d - a)[2])
        assert ee.area[c] == pytest.approx(1 - area_t, abs=1e-12)
    judged, agreed, covered = assert_oracle(scene, arcs, ee, [(e1, e2)])
    assert judged > 0.95 * POINTS and covered[0] < 1.0


# ---------------------------------------------------------------------------------------
# HDF5, determinism, CLI


@pytest.mark.parametrize("name", ["boxes_on_floor.obj", "rand:1"])
def test_hdf5_round_trip(name, tmp_path):
    from oracles import assert_cells_round_trip

    from viscx.formats.hdf5 import read_eecells, write_eecells

    scene, _, ee = built(name)  # V2's segments; open chains
    assert np.any(ee.element_kind != 0) or len(ee.open_edge1) > 0
    assert_cells_round_trip(tmp_path, scene, ee, write_eecells, read_eecells, lambda h5: h5["V2"])


def test_files_without_element_kinds_hold_arcs(tmp_path):
    """A V2 level written before V2's segments has no element_kind: read as arcs (kind 0)."""
    import h5py

    from viscx.formats.hdf5 import read_eecells, write_eecells

    _, _, ee = built("tetrahedra.obj")
    with h5py.File(tmp_path / "x.h5", "w") as f:
        g = f.create_group("V2")
        write_eecells(g, ee)
        assert json.loads(g["ee"].attrs["element_kinds"]) == {"arc": 0, "side": 1, "pencil1": 2, "pencil2": 3}
        del g["ee/element_kind"], g["ee/open/element_kind"]
        back = read_eecells(g)
    assert back.element_kind.dtype == np.int8 and np.all(back.element_kind == 0) and len(back.element_kind) == len(ee.element)
    assert np.array_equal(back.element, ee.element) and len(back.open_element_kind) == len(ee.open_element)


def test_damaged_ee_is_refused(tmp_path):
    import h5py

    from viscx.errors import ViscxError
    from viscx.formats.hdf5 import read_eecells, write_eecells

    _, _, ee = built("two_triangles.obj")
    with h5py.File(tmp_path / "x.h5", "w") as f:
        g = f.create_group("V2")
        with pytest.raises(ViscxError, match="no EE-cells"):
            read_eecells(g)
        write_eecells(g, ee)
        del f["V2/ee/area"]
        with pytest.raises(ViscxError, match="missing"):
            read_eecells(g)
        del f["V2/ee"]
        write_eecells(g, ee)
        del f["V2/ee/element_offsets"]
        f["V2/ee/element_offsets"] = np.zeros(len(ee.turning) + 1, np.int64)
        with pytest.raises(ViscxError, match="CSR"):
            read_eecells(g)


def test_ee_bytes_are_deterministic():
    """Two builds of one scene (fresh scene objects) give identical EE-cells."""
    a = build_all(load_scene(SAMPLES / "tetrahedra.obj"))[1]
    b = build_all(load_scene(SAMPLES / "tetrahedra.obj"))[1]
    for field in a.__dataclass_fields__:
        assert getattr(a, field).tobytes() == getattr(b, field).tobytes(), field


def run(argv, capsys):
    from viscx.cli import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return exc.value.code, out, err


@pytest.fixture(scope="module")
def tetra_h5(tmp_path_factory):
    from viscx.pipeline import build_file

    path = tmp_path_factory.mktemp("ee") / "t.h5"
    build_file(SAMPLES / "tetrahedra.obj", path, quiet=True)
    return path


def test_plot_eecell(tetra_h5, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    png = tmp_path / "e.png"
    code, out, err = run(["plot", "eecell", str(tetra_h5), "--edges", "7", "2", "-o", str(png), "--size", "60"], capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "EE-cells of edges 2 and 7" in out


@pytest.mark.parametrize("args, message", [
    (["--edges", "0", "99"], "not a generator edge"),
    (["--edges", "-1", "3"], "not a generator edge"),
    (["--edges", "0", "2"], "share a vertex or a plane"),
    (["--edges", "3", "3"], "share a vertex or a plane"),
    (["--edges", "0"], "not a valid integer"),
])
def test_plot_eecell_bad_edges(args, message, tetra_h5, tmp_path, capsys):
    code, _, err = run(["plot", "eecell", str(tetra_h5), *args, "-o", str(tmp_path / "x.png")], capsys)
    assert code == 2 and err.count("\n") == 1 and message in err


def test_plot_eecell_needs_v2(tmp_path, capsys):
    h5 = tmp_path / "t.h5"
    assert run(["--quiet", "build", str(SAMPLES / "two_triangles.obj"), "--levels", "1", "-o", str(h5)], capsys)[0] == 0
    code, _, err = run(["plot", "eecell", str(h5), "--edges", "0", "4", "-o", str(tmp_path / "x.png")], capsys)
    assert code == 2 and err.count("\n") == 1 and "--levels 2" in err


def test_a_lone_polygon_has_no_ee_cells():
    """A lone triangle's edges pairwise share a vertex: no square, no cell, no chain."""
    scene = build_scene(soup([[0, 0, 0], [1, 0, 0], [0.2, 1, 0.1]], [[0, 1, 2]]))
    _, ee = build_all(scene)
    assert len(ee) == 0 and len(ee.open_edge1) == 0 and ee.counts()["pairs"] == 0


def test_ee_blockers_in_chunks(monkeypatch):
    """ee_blockers judges large batches chunk by chunk: the same states as one call."""
    import viscx.skeleton.eecells as eecells

    scene, arcs, ee = built("cornell_box.obj")
    rng = np.random.default_rng(3)
    e1, e2 = ee.edge1[rng.integers(0, len(ee), 5000)], ee.edge2[rng.integers(0, len(ee), 5000)]
    e1, e2 = np.minimum(e1, e2), np.maximum(e1, e2)
    x1, x2 = rng.random(5000), rng.random(5000)
    whole = ee_blockers(scene, e1, e2, x1, x2)
    monkeypatch.setattr(eecells, "BLOCKER_CHUNK", 777)
    assert np.array_equal(ee_blockers(scene, e1, e2, x1, x2), whole)
    assert len(np.unique(whole[:, 2])) > 5  # varied blockers, not a trivial answer


@pytest.mark.parametrize("name", ["cornell_box.obj", "boxes_on_floor.obj", "rand:173"])
def test_chunks_of_squares_give_the_same_cells(name, monkeypatch):
    """build_eecells in chunks of a few squares: every array equal to the one-chunk build
    (the samples' squares left open are built again with V2's segments, chunk by chunk;
    random scene 173 has loops demoted to open chains, which every chunk lists first)."""
    import viscx.skeleton.eecells as eecells

    scene, arcs, whole = built(name)
    monkeypatch.setattr(eecells, "SQUARE_CHUNK", 40)
    chunked = build_eecells(scene, arcs)
    for field in whole.__dataclass_fields__:
        a, b = getattr(whole, field), getattr(chunked, field)
        assert a.dtype == b.dtype and np.array_equal(a, b), field
    if name == "rand:173":
        assert len(whole.open_edge1) > 0
    if name == "boxes_on_floor.obj":
        assert np.any(whole.element_kind != 0)
