"""The family stages of V1: events sorted into intervals, intervals sampled and
judged, mixed intervals refined by bisection, pieces merged into arcs.

The public functions here are the stage API used by :func:`viscx.skeleton.arcs.build_arcs`,
the XE arcs (:mod:`viscx.skeleton.arcs.xe`) and free points (:mod:`viscx.skeleton.points`).
"""

from typing import NamedTuple

import numpy as np

from viscx.arrays import row_norms
from viscx.geometry.lines import segment_parameter
from viscx.memory import release_free_memory
from viscx.parallel import default_workers, map_chunks, row_chunks
from viscx.skeleton.arcs.kinds import CHUNK, EEE, END_CROSSING, END_EDGE, END_ENDPOINT, END_RANK, END_TRANSITION, VE
from viscx.skeleton.arcs.lines import family_lines, judge_samples, judge_sides
from viscx.skeleton.arcs.pencils import pencil_planes
from viscx.skeleton.generators import edge_geometry, edge_junctions
from viscx.tolerances import END_SAMPLE_EPSILONS, ENDPOINT_ZONE, MERGE_EPSILONS, SNAP


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



class Intervals(NamedTuple):
    """Intervals of arc families between consecutive events (one row per interval; a tuple,
    so that ``*intervals`` passes them to the stages positionally).

    Attributes
    ----------
    family : (m,) int
        Row of the family (in the caller's family arrays).
    s0, s1 : (m,) float
        Parameters of the interval's ends, s0 < s1.
    kind0, kind1 : (m,) int
        End type (END_*) of the event at each end.
    index0, index1 : (m,) int
        The event's ``end_node`` (as :class:`~viscx.skeleton.arcs.kinds.Arcs`).
    """

    family: np.ndarray
    s0: np.ndarray
    kind0: np.ndarray
    index0: np.ndarray
    s1: np.ndarray
    kind1: np.ndarray
    index1: np.ndarray

    def take(self, rows):
        """The intervals at ``rows`` (an index or mask array)."""
        return Intervals(*(x[rows] for x in self))


def _param_scale(scene, fkind, fgens):
    """Length of each family's parameter edge."""
    a, b = edge_geometry(scene, np.where(fkind == EEE, fgens[:, 0], fgens[:, 1]))
    return row_norms(b - a)


def family_intervals(scene, fkind, fgens, fam_of, ev_s, ev_kind, ev_index, ev_hidden=None, ev_reach=None):
    """Merge each family's events closer than 4 epsilon along its edge (by END_RANK: a node
    beats a planar event beats a domain end beats a junction beats a coplanar event),
    except two events of an EEE family whose lines meet one of its other two edges farther
    than 4 epsilon apart (:func:`_apart_along_edges`: they are two lines, docs/skeleton.md
    "Furnished buildings" rule 13) and, given ``ev_reach`` (the distance from a VE family's
    vertex to the farthest point its event's line is fixed by), two events of a VE family
    whose lines lie farther than 4 epsilon apart there (:func:`_apart_at_reach`, rule 14),
    leave out the groups of hidden events alone (:func:`hidden_events`) and return the
    intervals between consecutive ones (:class:`Intervals`)."""
    # by (family, s) only: events at one (family, s) fall in one group whatever their order
    order = by_family_and_s(fam_of, ev_s)
    f, s, k, i = fam_of[order], ev_s[order], ev_kind[order], ev_index[order]
    tol = MERGE_EPSILONS * scene.epsilon / _param_scale(scene, fkind, fgens)[f]
    new_group = np.ones(len(f), dtype=bool)
    new_group[1:] = (f[1:] != f[:-1]) | (s[1:] - s[:-1] > tol[1:])
    # two events close along the parameter edge of an EEE family can be far apart along its
    # other edges (lines on a long floor edge sweeping a 3 cm edge of a desk): two events
    pair = np.flatnonzero(~new_group[1:] & (fkind[f[1:]] == EEE))
    new_group[1 + pair[_apart_along_edges(scene, fgens[f[pair]], s[pair], s[pair + 1], MERGE_EPSILONS * scene.epsilon)]] = True
    if ev_reach is not None:  # likewise a VE family's lines seen along a short edge near its vertex
        reach = ev_reach[order]
        pair = np.flatnonzero(~new_group[1:] & (fkind[f[1:]] == VE))
        far = np.maximum(reach[pair], reach[pair + 1])
        new_group[1 + pair[_apart_at_reach(scene, fgens[f[pair]], s[pair], s[pair + 1], far)]] = True
    group = np.cumsum(new_group) - 1
    hidden = np.zeros(len(f), bool) if ev_hidden is None else ev_hidden[order]
    seen = np.bincount(group, weights=~hidden) > 0
    # within a group (a run), the best event: lowest rank, then lowest id, then lowest s
    if len(f) == 0:
        first = np.zeros(0, np.int64)
    else:
        merit = END_RANK[k].astype(np.int64) * (int(i.max()) - int(i.min()) + 1) + (i - i.min())
        start = np.flatnonzero(new_group)
        at_best = merit == np.repeat(np.minimum.reduceat(merit, start), np.diff(np.r_[start, len(f)]))
        first = np.flatnonzero(at_best)
        first = first[np.r_[True, group[first][1:] != group[first][:-1]]]
        first = first[seen[group[first]]]
    gf, gs, gk, gi = f[first], s[first], k[first], i[first]
    nxt = np.flatnonzero(gf[1:] == gf[:-1])
    return Intervals(gf[nxt], gs[nxt], gk[nxt], gi[nxt], gs[nxt + 1], gk[nxt + 1], gi[nxt + 1])


def _apart_along_edges(scene, gens, s0, s1, tol):
    """Whether the lines of EEE families (``gens`` (m, 3)) at s0 and s1 meet one of their
    two other edges (q, r) farther than ``tol`` (length) apart: the points where each
    line passes closest to the edge's line, compared along the edge."""
    if len(gens) == 0:
        return np.zeros(0, bool)
    kind = np.full(len(gens), EEE)
    o0, d0 = family_lines(scene, kind, gens, s0)
    o1, d1 = family_lines(scene, kind, gens, s1)
    # (where p's point lies on the line of q or r the line is undefined, its direction zero:
    # at a domain's end; not apart)
    defined = (row_norms(d0) > 0) & (row_norms(d1) > 0)
    apart = np.zeros(len(gens), bool)
    for slot in (1, 2):
        a, b = edge_geometry(scene, gens[:, slot])
        u = b - a
        t0, t1 = (_closest_parameter(o, d, a, u) for o, d in ((o0, d0), (o1, d1)))
        apart |= np.abs(t1 - t0) * row_norms(u) > tol
    return apart & defined


def _apart_at_reach(scene, gens, s0, s1, reach):
    """Whether the lines of VE families (``gens`` (m, 3)) at s0 and s1 lie farther than
    MERGE_EPSILONS epsilon apart at ``reach`` (m,) from the vertex: reach times the sine of
    the angle between them (the distance from one line's point there to the other line).

    Both lines pass the vertex, so along the family's edge they are as close as the merge
    asks; but an event's line is fixed by points beyond it (a node's edge point, a vertex or
    an edge's crossing of the plane passed), and seen along an edge 3 cm from the vertex (a
    desk panel's thickness) two events 4 epsilon apart there are two lines 8 mm apart at a
    cabinet 8 m away: merged, the arc between them was lost, or its change of side pairs
    moved by 1e-3 rad (docs/skeleton.md "Furnished buildings", rule 14)."""
    if len(gens) == 0:
        return np.zeros(0, bool)
    kind = np.full(len(gens), VE)
    _, d0 = family_lines(scene, kind, gens, s0)
    _, d1 = family_lines(scene, kind, gens, s1)
    size = row_norms(d0) * row_norms(d1)
    sine = row_norms(np.cross(d0, d1)) / np.where(size > 0, size, 1.0)
    return reach * sine > MERGE_EPSILONS * scene.epsilon


def _closest_parameter(o, d, a, u):
    """Parameter t of the point a + t u of each line (a, u) closest to the line (o, d)."""
    w = o - a
    dd, du, uu = (np.einsum("ij,ij->i", x, y) for x, y in ((d, d), (d, u), (u, u)))
    dw, uw = np.einsum("ij,ij->i", d, w), np.einsum("ij,ij->i", u, w)
    den = dd * uu - du * du
    return np.where(den > 0, (dd * uw - du * dw) / np.where(den > 0, den, 1.0), 0.0)


def by_family_and_s(family, s):
    """``np.lexsort([s, family])``, 2.5 times faster: a stable sort of the complex numbers
    family + i s, which numpy orders lexicographically (family < 2^53 is exact in float64)."""
    return np.argsort(family + 1j * s, kind="stable")


def _end_fraction(scene, fkind, fgens, f, s0, s1):
    """Fraction of each interval that is 20 epsilon along the parameter edge (at most 0.1):
    where the samples next to the interval's events are taken, so that a short piece next
    to an event is seen even when the event closing it is missing."""
    length = _param_scale(scene, fkind[f], fgens[f]) * (s1 - s0)  # (f: a few of the families)
    return np.minimum(0.1, END_SAMPLE_EPSILONS * scene.epsilon / np.maximum(length, 1e-300))


def arcs_on_intervals(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1, workers=None):
    """The arcs on the intervals between consecutive events of families (``f`` the family
    of each, s0 < s1 its ends, t and i their end types and ids): the samples of every
    interval (:func:`first_pass`), the intervals whose samples disagree refined
    (:func:`refine_intervals`), the pieces merged (:func:`arcs_of_pieces`).

    Returns
    -------
    dict of arrays
        The fields of :class:`Arcs` (not sorted) and ``sides`` (m, 8), the half-cells'
        pairs of each arc's sample.
    """
    if np.any(fkind[f] == EEE):  # the samples' threads read it: built here once, not in each of them
        pencil_planes(scene)  # (VE lines lie in no pencil: a free point's arcs never need it)
    parts, mixed = first_pass(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1, workers)
    return arcs_of_pieces(scene, fkind, fgens, parts + refine_intervals(scene, fkind, fgens, *mixed, workers=workers))


def first_pass(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1, workers=None):
    """Every interval judged at its samples (SAMPLES and 20 epsilon from each end).

    Returns
    -------
    parts : list of dict
        The intervals whose samples agree and are valid, one arc piece each (its sample
        the first, at 1/2), in pieces as :func:`_refine_batch`'s.
    mixed : Intervals
        The intervals whose samples disagree.
    """
    n = len(f)
    near = _end_fraction(scene, fkind, fgens, f, s0, s1)
    fr = np.concatenate([np.broadcast_to(np.asarray(SAMPLES), (n, len(SAMPLES))), near[:, None], 1 - near[:, None]], axis=1)
    ss = s0[:, None] + fr * (s1 - s0)[:, None]
    # judged in chunks of intervals (on threads), keeping the whole segment only for the
    # sample that stands for an arc (the first, at 1/2): memory stays bounded on large scenes
    uniform = np.zeros(n, dtype=bool)

    def judge_chunk(c):
        kinds, gens, s = np.repeat(fkind[f[c]], fr.shape[1]), np.repeat(fgens[f[c]], fr.shape[1], axis=0), ss[c].reshape(-1)
        smp = judge_samples(scene, kinds, gens, s)
        # the half-cells only where the lines agree: an interval whose lines differ is refined anyway
        lines = smp.state.reshape(len(c), fr.shape[1], -1)
        agree = np.repeat(np.all(lines == lines[:, :1], axis=(1, 2)), fr.shape[1])
        smp.sides = np.full((len(s), 12), -1, dtype=np.int64)
        smp.sides[agree] = judge_sides(scene, kinds[agree], gens[agree], s[agree], smp.valid[agree])
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
    return parts, Intervals(f, s0, t0, i0, s1, t1, i1).take(mixed)


def arcs_of_pieces(scene, fkind, fgens, parts):
    """The arcs (as :func:`arcs_on_intervals`) from the pieces of the first pass and the
    refinement (dicts of arrays, all of the families' pieces): merged where nothing
    changes (:func:`_merge_across_possible_events`)."""
    pieces = _merge_across_possible_events(scene, fkind, fgens, concatenate_parts(parts))
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
    order = by_family_and_s(pieces["family"], pieces["interval"][:, 0])
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


def concatenate_parts(parts, release=False):
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


def refine_intervals(scene, fkind, fgens, f, s0, t0, i0, s1, t1, i1, workers=None):
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
    """:func:`refine_intervals` on one batch of intervals (at most CHUNK samples)."""
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
    kinds, gens = fkind[f[ci]], fgens[f[ci]]
    for _ in range(BISECT):
        m = 0.5 * (lo + hi)
        at = judge_samples(scene, kinds, gens, m)
        # the half-cells only where the line's state is left's (elsewhere the sample differs anyway)
        same = np.all(at.state == left[:, :5], axis=1)
        same[same] = np.all(judge_sides(scene, kinds[same], gens[same], m[same], at.valid[same]) == left[same, 5:], axis=1)
        lo, hi = np.where(same, m, lo), np.where(same, hi, m)
    cut = _snap_cuts(scene, fkind[f[ci]], fgens[f[ci]], 0.5 * (lo + hi), ss[ci, cj], ss[ci, cj + 1])
    # an EEE cut that is node condition 5's at an endpoint of q or r, next to the interval's
    # end at that endpoint (its node or domain end) with nothing valid between: cut there
    at_end = _endpoint_cuts(scene, fkind[f[ci]], fgens[f[ci]], cut, s0[ci], s1[ci])
    first_cut = np.r_[True, ci[1:] != ci[:-1]] if len(ci) else np.zeros(0, bool)
    last_cut = np.r_[ci[1:] != ci[:-1], True] if len(ci) else np.zeros(0, bool)
    to_start = (at_end == 0) & first_cut & (state[ci, cj, 0] == 0)
    to_end = (at_end == 1) & last_cut & (state[ci, cj + 1, 0] == 0)
    cut = np.where(to_start, s0[ci], np.where(to_end, s1[ci], cut))
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
    end_s[after], end_t[after], end_i[after] = cut, np.where(to_end, t1[ci], END_TRANSITION), np.where(to_end, i1[ci], -1)
    before = run_id[ci, cj + 1]
    start_s[before], start_t[before], start_i[before] = (cut, np.where(to_start, t0[ci], END_TRANSITION),
                                                         np.where(to_start, i0[ci], -1))
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


def _endpoint_cuts(scene, kind, gens, cut, s0, s1):
    """Which EEE transitions are node condition 5's at an endpoint w of one of the family's
    edges, and on which side of their interval (s0, s1) that endpoint's event lies.

    An EEE (p, q, r) line meeting q within epsilon of its endpoint w is judged invalid
    (condition 5: the event there is the vertex's, a VEE node through w, or a domain end
    V0 dropped), so the lines of the family next to the line through w form an invalid
    stretch whose length along p is epsilon times the ratio of the two points' speeds:
    longer than the 20 epsilon end samples where q's point moves slowly (a box's vertical
    edge seen from a far floor edge), and the arc then ended at a transition bisected
    epsilon along q off w, while the family of w's other edge, sampled beyond its shorter
    stretch, reached the node: the corner of the EE-cells' boundary at w did not close
    (docs/skeleton.md, "Arcs", condition 5's stretch). At an endpoint of p itself the
    stretch is epsilon along p, but an interval shorter than 200 epsilon is sampled a tenth
    of its length from its ends, within it. Such a cut is recognised by its line meeting p,
    q or r within ENDPOINT_ZONE epsilon (length) of an endpoint w while the line at the
    interval's end s0 or s1 meets that edge within it as well (that end is the event at w).

    Parameters
    ----------
    kind, gens : (c,) int, (c, 3) int
        The family of each cut.
    cut, s0, s1 : (c,) float
        The cut and its interval's ends.

    Returns
    -------
    (c,) int8
        0: the event at w is s0, 1: it is s1, -1: not such a cut (or not EEE).
    """
    side = np.full(len(cut), -1, np.int8)
    rows = np.flatnonzero(kind == EEE)
    if len(rows) == 0:
        return side
    g = gens[rows]
    kinds = np.full(len(rows), EEE)
    lines = [family_lines(scene, kinds, g, s[rows]) for s in (cut, s0, s1)]
    zone = ENDPOINT_ZONE * scene.epsilon
    for slot in (0, 1, 2):
        a, b = edge_geometry(scene, g[:, slot])
        length = row_norms(b - a)
        x = []
        for o, d in lines:
            defined = row_norms(d) > 0
            xi, _ = segment_parameter(o, np.where(defined[:, None], d, 1.0), a, b)
            x.append(np.where(defined, xi, np.nan))
        with np.errstate(invalid="ignore"):
            for w in (0.0, 1.0):
                near = [np.abs(xi - w) * length <= zone for xi in x]
                for end in (0, 1):
                    hit = near[0] & near[1 + end] & (side[rows] < 0)
                    side[rows[hit]] = end
    return side


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
    a, b = edge_geometry(scene, e)
    n = np.cross(b - a, x - a)
    n /= row_norms(n)[:, None]
    length = row_norms(b - a)
    # candidate points: generator vertices, junctions, points of generator edges
    junctions = edge_junctions(scene)
    ja, jb = edge_geometry(scene, junctions.edge)
    points = np.concatenate([scene.vertices[scene.generator_vertices], ja + junctions.s[:, None] * (jb - ja)])
    ga, gb = edge_geometry(scene, scene.generator_edges)
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
        fine = row_norms(direction) > tol
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


def edge_line_ends(scene, arcs):
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


def sorted_arcs(arcs):
    """Canonical order: kind, generators, then interval start."""
    g = arcs["generators"]
    order = np.lexsort([arcs["interval"][:, 0], g[:, 2], g[:, 1], g[:, 0], arcs["kind"]])
    return {k: v[order] for k, v in arcs.items()}
