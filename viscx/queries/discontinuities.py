"""The discontinuity mesh of an area light (Hoberock et al. §7.5): on every receiver face, the
traces of the families of maximal free segments that involve a vertex or an edge of the
light, and the regions they cut the receiver into.

Events (which arcs of V1 are traced)
------------------------------------
An *area light* is a set of faces (``--light-face`` or ``--light-group``); its *light
vertices* and *light edges* are the vertices and edges of its outline (edges shared by
two light faces are inside the light and do not count). A point x of a receiver sees
part of the light; that visible part changes combinatorially where x crosses the trace
of one of these one-parameter families (the V-cells of the light's vertices and the
EE-cells of its edges, Hoberock et al. §7.5):

* **VE (light vertex v, occluder edge e)**: the lines through v grazing e (x stops
  seeing v behind e). Receiver end: the *front* end (the family is oriented from v
  towards e).
* **VE (occluder vertex w, light edge e)**: the lines through w meeting e (w's image
  crosses the light's edge e). Receiver end: the *back* end (oriented from w towards e,
  the receiver is behind w).
  The families of a free point (``viscx build --point``, generator vertex
  ``n_vertices + k``) are left out: a point blocks nothing.
* **XE (crossing point X of occluder edges a and b, light edge e)**: the lines through X
  meeting e (degenerate scenes: touching objects whose edges cross; X's image, a corner
  of the occluders' outline, crosses e, and the occluder edge bounding e's hidden part
  turns from a to b). Receiver end: the back end, as for an occluder vertex.
* **EEE with exactly one light edge** (two occluder edges' images cross on the light
  edge). Receiver end: the end on the side of the two occluder edges, away from the
  light edge: kept only when the light edge's generator point is the first or the last
  of the three along the segment (else the occluders are on both sides of the light
  and x, at one end, sees the light past one of them only: no event for x).

Families with two light generators lie in the light's plane and are left out: the light
is one-sided (it emits from the front of its faces, as in ``viscx render``), so their
trace is the line where a receiver crosses the light's plane, the boundary of the part
that sees the light's front; the traces behind it are dropped
(:mod:`viscx.queries.plane_events`, which also finds the *receiver-plane events*: an
occluder edge's image crossing a receiver's horizon on a light edge, or the image of
an occluder vertex lying in the receiver's plane crossing a light edge, whose critical
lines lie in the receiver's plane and are not arcs of V1). An arc is traced on face f when its blocker at the receiver end is face f, f is not a
light face, and no occluder generator of the arc is an edge or a vertex of f (such a
trace runs along f's own outline or is a point). A *planar* EEE family (two of its edges
in one plane: :func:`pencil_points`) is left out where both of those edges have all
their faces in that plane (a lone panel: :func:`panel_pencils`, nothing changes across
its trace).

V1 merges a family's events closer than MERGE_EPSILONS epsilon into one; the lines
between them that end on a face neither neighbouring arc ends on (a receiver seen nearly
edge-on) are traced as events of their own, arc -1 (:func:`merged_windows`).

Traces
------
Every segment of an arc ends on f, so the trace is {line(s) ∩ plane(f) : s in the arc's
parameter interval}; line(s) is :func:`viscx.skeleton.arcs.family_lines` (per-arc
evaluation, nothing rebuilt). A VE family's lines lie in the plane of its vertex and
edge, so its trace is the straight segment between the images of the interval's ends.
An EEE family's lines rule a quadric; its trace is a conic arc, written as a polyline
refined until each chord's middle parameter is within ``CHORD_TOLERANCE`` × epsilon of
the chord; a planar EEE family is a pencil of lines through one point, its trace
straight. Inner joints closer than the snap distance to the joint before or to
the end are dropped (:func:`thin_polylines`). The traces lie in f (every trace point
is where a segment ending on f meets f), so clipping to the receiver only snaps ends
that are within the snap distance of its outline. A trace ending where V1 ended its arc at a transition, and meeting no
other line there, is continued to the first line it meets
(:func:`continue_transitions`).

Regions
-------
Per receiver, in the face's 2-D coordinates (:func:`viscx.geometry.polygon.plane_basis`
of its normal): the outline edges and the trace chords are split at their crossings
(and where an end lies on another chord), split points closer than ``SPLIT_SNAP`` × epsilon
are merged, dangling edges pruned, and the faces of the planar subdivision traced on
half-edges (faces on the left). Counter-clockwise cycles are the regions' outer loops,
clockwise cycles their holes (each inside the smallest outer loop of another component
that contains it) or the outside.
"""

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from viscx.arrays import expand_ranges, walk_cycle
from viscx.geometry.lines import segment_parameter
from viscx.geometry.polygon import plane_basis
from viscx.grid import overlapping_box_pairs
from viscx.queries.cracks import through_cracks
from viscx.queries.plane_events import (LIGHT_PLANE, RP_EDGE, RP_VERTEX, triangle_edge_ids, clip_to_front,
                                        light_plane_lines, light_planes, receiver_plane_events)
from viscx.scene.light import Light, light_of
from viscx.skeleton.arcs import EEE, END_TRANSITION, VE, XE, KIND_NAMES, family_lines, judge_samples
from viscx.skeleton.nodes import BLOCK_FACE, face_planes
from viscx.tolerances import CHORD_TOLERANCE, MERGE_EPSILONS, PARALLEL_TOLERANCE, SPLIT_SNAP

#: Chords per EEE trace before refinement, and refinement rounds at most.
EEE_START, EEE_ROUNDS = 8, 16
#: Lines judged across a merged event's window (MERGE_EPSILONS epsilon on each side: a
#: quarter epsilon apart), and bisection steps locating a lost window's ends
#: (:func:`merged_windows`).
WINDOW_SAMPLES, WINDOW_BISECT = 33, 30
#: Segment sets up to this size are split by testing every pair (:func:`_near_segment_pairs`).
SMALL_SEGMENT_SET = 64
# which light feature an event involves
LIGHT_VERTEX, LIGHT_EDGE, LIGHT_FACE = 0, 1, 2
#: Names of the event kinds: V1's arcs, receiver-plane events (C on an occluder edge or an
#: occluder vertex in the receiver's plane) and the light's plane.
EVENT_KINDS = {**KIND_NAMES, RP_EDGE: "RPE", RP_VERTEX: "RPV", LIGHT_PLANE: "LP"}


def light_plane_count(scene, light):
    """The number of planes the light's faces lie in (:func:`viscx.skeleton.nodes.face_planes`):
    the mesh is exact for one (docs/queries.md, "What the mesh leaves out" (3))."""
    return len(np.unique(face_planes(scene)[np.asarray(light.faces)]))


@dataclass
class Events:
    """The events traced on receivers: pieces of arcs of V1 (in front of the light), then
    the events in a face's plane (:mod:`viscx.queries.plane_events`).

    Attributes
    ----------
    arc : (m,) int64
        Arc ids (-1 for the events in a face's plane).
    end : (m,) int64
        Receiver end (0 back, 1 front, in the family's orientation; -1 not an arc).
    face : (m,) int64
        Receiver face.
    light_kind : (m,) int8
        LIGHT_VERTEX, LIGHT_EDGE or LIGHT_FACE.
    light_feature : (m,) int64
        The light vertex, edge or face id.
    kind : (m,) int64
        EEE or VE (of the arc), RP_EDGE, RP_VERTEX or LIGHT_PLANE (:data:`EVENT_KINDS`).
    generators : (m, 3) int64
        The arc's generators; (occluder edge or vertex, light edge, -1) for a
        receiver-plane event, (light face, -1, -1) for the light's plane.
    interval : (m, 2) float64
        The family parameters traced: the arc's interval, or the window of lines
        between two events V1 merged (arc -1: :func:`merged_windows`); NaN for the
        events in a face's plane.
    """

    arc: np.ndarray
    end: np.ndarray
    face: np.ndarray
    light_kind: np.ndarray
    light_feature: np.ndarray
    kind: np.ndarray
    generators: np.ndarray
    interval: np.ndarray

    def take(self, rows):
        """The events of the given rows (repeats allowed): Events."""
        return Events(*(getattr(self, k)[rows] for k in self.__dataclass_fields__))

    @staticmethod
    def concat(parts):
        """One Events of several, rows in order."""
        return Events(*(np.concatenate([getattr(p, k) for p in parts]) for k in Events.__dataclass_fields__))


def _plane_rows(face, kind, light_kind, light_feature, generators):
    """Events (arc -1) of events lying in a face's plane; arguments (m,) arrays, generators (m, 3)."""
    m = len(face)
    return Events(np.full(m, -1, np.int64), np.full(m, -1, np.int64), np.asarray(face, np.int64),
                  np.asarray(light_kind, np.int8), np.asarray(light_feature, np.int64), np.asarray(kind, np.int64),
                  np.asarray(generators, np.int64).reshape(m, 3), np.full((m, 2), np.nan))


def select_events(scene, arcs, light):
    """The arcs whose segments involve the light and end on a receiver (module docstring).

    Returns
    -------
    Events
    """
    nv, ne = scene.n_vertices, len(scene.half_edges.edge_vertices)
    lv = np.zeros(nv, bool)
    lv[light.vertices] = True
    le = np.zeros(ne + 1, bool)
    le[light.edges] = True
    kind = np.asarray(arcs.kind, np.int64)
    g = np.asarray(arcs.generators, np.int64)
    n = len(kind)
    end = np.full(n, -1, np.int64)
    lkind = np.full(n, -1, np.int8)
    lfeat = np.full(n, -1, np.int64)
    # a free point of `viscx build --point` (generator vertex nv + k) blocks nothing and is
    # no part of the light: its VE families are no visual events of the light
    ve = (kind == VE) & (g[:, 0] < nv)
    gv, ge = np.where(ve, g[:, 0], 0), np.where(ve, g[:, 1], ne)
    a = ve & lv[gv] & ~le[ge]
    b = ve & ~lv[gv] & le[ge]
    end[a], lkind[a], lfeat[a] = 1, LIGHT_VERTEX, gv[a]
    end[b], lkind[b], lfeat[b] = 0, LIGHT_EDGE, ge[b]
    # XE (a, e, b): the crossing of occluder edges a and b plays an occluder vertex
    gx = np.where((kind == XE)[:, None], g, ne)
    x = (kind == XE) & le[gx[:, 1]] & ~le[gx[:, 0]] & ~le[gx[:, 2]]
    end[x], lkind[x], lfeat[x] = 0, LIGHT_EDGE, g[x, 1]
    eee = kind == EEE
    ge3 = np.where(eee[:, None], g, ne)
    lit = le[ge3]
    one = eee & (lit.sum(axis=1) == 1)
    slot = np.argmax(lit, axis=1)
    gp = arcs.generator_points
    t = np.einsum("nkj,nj->nk", gp - arcs.ends[:, :1], arcs.direction)
    tl = t[np.arange(n), slot]
    first = one & (tl <= t.min(axis=1))
    last = one & ~first & (tl >= t.max(axis=1))
    end[first], end[last] = 1, 0
    ok = first | last
    lkind[ok], lfeat[ok] = LIGHT_EDGE, ge3[ok, slot[ok]]
    sel = np.flatnonzero(end >= 0)
    e = end[sel]
    # the arcs', then the windows' candidates: (arc, end, blocker kind and id at that end,
    # interval, segment ends, direction)
    win = merged_windows(scene, arcs, end)
    cand = [np.r_[sel, np.full(len(win["row"]), -1)], np.r_[e, end[win["row"]]],
            np.r_[arcs.blocker_kind[sel, e], win["blocker_kind"]], np.r_[arcs.blocker[sel, e], win["blocker"]],
            np.concatenate([arcs.interval[sel], win["interval"]]), np.concatenate([arcs.ends[sel], win["ends"]]),
            np.concatenate([arcs.direction[sel], win["direction"]])]
    src = np.r_[sel, win["row"]]  # the arc each candidate's family, light feature and kind are read from
    in_light = np.zeros(scene.n_faces, bool)
    in_light[light.faces] = True
    keep = (cand[2] == BLOCK_FACE) & (cand[3] >= 0)
    keep[keep] &= ~in_light[cand[3][keep]]
    arc_id, e, _, face, interval, seg_ends, direction = (x[keep] for x in cand)
    sel = src[keep]
    # no trace along the receiver's own outline
    he = scene.half_edges
    own_edge = np.unique(he.face.astype(np.int64) * (ne + 1) + he.edge)
    own_vertex = np.unique(he.face.astype(np.int64) * nv + he.start)
    gs = g[sel]
    bad = np.zeros(len(sel), bool)
    k = kind[sel]
    for slot_ in range(3):
        is_edge = (k == EEE) | (k == XE) | ((k == VE) & (slot_ == 1))
        is_vert = (k == VE) & (slot_ == 0)
        x = gs[:, slot_]
        code_e = face * (ne + 1) + np.where(is_edge, x, ne)
        bad |= is_edge & ~le[np.where(is_edge, x, ne)] & np.isin(code_e, own_edge)
        code_v = face * nv + np.where(is_vert, x, 0)
        bad |= is_vert & ~lv[np.where(is_vert, x, 0)] & np.isin(code_v, own_vertex)
    # degenerate families: every line through a generator vertex lying in f's plane meets
    # f there (the trace is a point); a generator edge lying in f's plane is f's outline or
    # a contact
    snap = SPLIT_SNAP * scene.epsilon
    n_f, c_f = scene.face_normal[face], scene.face_offset[face]
    ev_ = he.edge_vertices
    for slot_ in range(3):
        x = gs[:, slot_]
        is_vert = (k == VE) & (slot_ == 0)
        is_edge = ((k == EEE) | (k == XE) | ((k == VE) & (slot_ == 1))) & (x >= 0)
        pv = scene.vertices[np.where(is_vert, x, 0)]
        bad |= is_vert & (np.abs(np.einsum("ij,ij->i", pv, n_f) - c_f) <= snap)
        xe = np.where(is_edge, x, 0)
        da = np.abs(np.einsum("ij,ij->i", scene.vertices[ev_[xe, 0]], n_f) - c_f)
        db = np.abs(np.einsum("ij,ij->i", scene.vertices[ev_[xe, 1]], n_f) - c_f)
        bad |= is_edge & (da <= snap) & (db <= snap)
    # a lone panel's planar families, and segments through a crack between two blocks in
    # contact: nothing changes across their trace
    bad |= panel_pencils(scene, k, gs, snap)
    bad |= through_cracks(scene, seg_ends[:, 0], seg_ends[:, 1])
    # segments reaching their receiver from the far side of its closed solid
    towards = np.where((e == 1)[:, None], direction, -direction)
    bad |= across_solid(scene, light, face, towards)
    sel, arc_id, e, face, interval = sel[~bad], arc_id[~bad], e[~bad], face[~bad], interval[~bad]
    # by receiver, then arc (the windows, arc -1, first: by their family and interval)
    order = np.lexsort([interval[:, 0], sel, arc_id, face])
    sel, arc_id, e, face, interval = sel[order], arc_id[order], e[order], face[order], interval[order]
    return Events(arc_id, e, face, lkind[sel], lfeat[sel], kind[sel], g[sel], interval)


def merged_windows(scene, arcs, end, samples=WINDOW_SAMPLES, steps=WINDOW_BISECT):
    """The lines V1 lost between two events of a family it merged, where they end on a
    face that neither neighbouring arc ends on.

    V1 takes a family's events closer than MERGE_EPSILONS epsilon along its parameter edge
    (and whose lines stay that close: docs/skeleton.md, "Furnished buildings" rule 14) as
    one event, as epsilon-visibility asks: the lines between them are one line of the
    complex, and the arcs on either side meet at it. On a receiver seen nearly edge-on
    from the family's lines those few epsilons of line space are a long trace: the VE
    family of the 250-triangle bunny's vertex 99 and light edge 13 meets face 213 at
    0.08° over 4.6e-5 of its parameter (the nodes of edges 322 and 316, 3.9 epsilon apart
    along the light edge, merged), a 0.071 trace 150 epsilon wide on the face, and the
    exact labels differ across it. So at each junction of two arcs of a family, the
    lines within MERGE_EPSILONS epsilon (along the edge) on each side, inside the two arcs'
    intervals, are judged at ``samples`` parameters by V1's own rule
    (:func:`viscx.skeleton.arcs.judge_samples`); each run of valid lines ending on a face
    neither arc ends on is a window, its ends bisected ``steps`` times.

    Parameters
    ----------
    end : (n,) int64
        Each arc's receiver end (0 back, 1 front), -1 for arcs that are not the light's.

    Returns
    -------
    dict of arrays: ``row`` (w,) the arc before each window's junction (its family and
    light feature), ``interval`` (w, 2), ``blocker_kind``, ``blocker`` (w,) at the
    receiver end, ``ends`` (w, 2, 3) and ``direction`` (w, 3) of a line of the window.
    """
    kind = np.asarray(arcs.kind, np.int64)
    g = np.asarray(arcs.generators, np.int64)
    same = np.all(g[1:] == g[:-1], axis=1) & (kind[1:] == kind[:-1]) & (arcs.interval[1:, 0] == arcs.interval[:-1, 1])
    j = np.flatnonzero(same & (end[:-1] >= 0))
    e = end[j]
    bk = np.stack([arcs.blocker_kind[j, e], arcs.blocker_kind[j + 1, e]], axis=1)
    bl = np.stack([arcs.blocker[j, e], arcs.blocker[j + 1, e]], axis=1)
    out = {"row": np.zeros(0, np.int64), "interval": np.zeros((0, 2)), "blocker_kind": np.zeros(0, np.int8),
           "blocker": np.zeros(0, np.int64), "ends": np.zeros((0, 2, 3)), "direction": np.zeros((0, 3))}
    if not len(j):
        return out
    ev = scene.half_edges.edge_vertices
    edge = np.where(kind[j] == EEE, g[j, 0], g[j, 1])
    length = np.linalg.norm(scene.vertices[ev[edge, 1]] - scene.vertices[ev[edge, 0]], axis=1)
    width = MERGE_EPSILONS * scene.epsilon / length  # the merge's reach, as a parameter
    s = np.clip(arcs.interval[j, 1][:, None] + width[:, None] * np.linspace(-1.0, 1.0, samples)[None],
                arcs.interval[j, :1], arcs.interval[j + 1, 1:])  # (within the two arcs)

    def judge(rows, s):  # receiver-end blocker (kind, id) and validity of lines s of junctions rows
        smp = judge_samples(scene, kind[j[rows]], g[j[rows]], s)
        er = e[rows]
        return smp.valid, smp.state[np.arange(len(rows)), 1 + 2 * er], smp.state[np.arange(len(rows)), 2 + 2 * er], smp

    rows = np.repeat(np.arange(len(j)), samples)
    valid, k_, b_, smp = judge(rows, s.ravel())
    theirs = ((k_[:, None] == bk[rows]) & (b_[:, None] == bl[rows])).any(axis=1)  # a neighbouring arc's blocker
    lost = (valid & (k_ == BLOCK_FACE) & (b_ >= 0) & ~theirs).reshape(-1, samples)
    b_ = b_.reshape(-1, samples)
    # runs of lost samples on one face
    start = lost & ~np.c_[np.zeros((len(j), 1), bool), lost[:, :-1] & (b_[:, :-1] == b_[:, 1:])]
    ri, ci = np.nonzero(start)
    if not len(ri):
        return out
    stop = ci.copy()
    while True:  # (runs are a few samples long)
        more = (stop + 1 < samples)
        nxt = np.minimum(stop + 1, samples - 1)
        more &= lost[ri, nxt] & (b_[ri, nxt] == b_[ri, ci])
        if not more.any():
            break
        stop[more] += 1
    face = b_[ri, ci]
    # each end bisected between the run's last sample and the next one out (or the window's end)
    ends = []
    for inner, outer in ((ci, np.maximum(ci - 1, 0)), (stop, np.minimum(stop + 1, samples - 1))):
        a, b = s[ri, inner], s[ri, outer]
        for _ in range(steps):
            m = 0.5 * (a + b)
            ok, km, bm, _ = judge(ri, m)
            on = ok & (km == BLOCK_FACE) & (bm == face)
            a, b = np.where(on, m, a), np.where(on, b, m)
        ends.append(a)
    mid = ri * samples + (ci + stop) // 2
    out["row"] = j[ri]
    out["interval"] = np.sort(np.stack(ends, axis=1), axis=1)
    out["blocker_kind"] = np.full(len(ri), BLOCK_FACE, np.int8)
    out["blocker"] = face.astype(np.int64)
    out["ends"], out["direction"] = smp.ends[mid], smp.direction[mid]
    return out


def light_inside_solids(scene, light):
    """Which closed solids (:func:`viscx.queries.formfactor.closed_solids`) hold the light:
    (s,) bool, the winding number of each solid's surface about a point just in front of
    the light (the first light triangle's centroid, 1e-6 of the diagonal along its face's
    normal, where the light emits into free space) is not zero. The winding number is the
    sum of the signed solid angles of the solid's triangles, oriented by their faces'
    normals (Van Oosterom and Strackee's formula), over 4π: ±1 inside, 0 outside."""
    from viscx.queries.formfactor import closed_solids

    face_solid, outward, _ = closed_solids(scene)
    if not len(outward):
        return np.zeros(0, bool)
    lt = np.flatnonzero(np.isin(scene.triangle_face, light.faces))[0]
    lf = scene.triangle_face[lt]
    p = scene.vertices[scene.triangles[lt]].mean(axis=0) + 1e-6 * scene.diagonal * scene.face_normal[lf]
    rows = np.flatnonzero(face_solid[scene.triangle_face] >= 0)
    a, b, c = (scene.vertices[scene.triangles[rows, i]] - p for i in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb
           + np.einsum("ij,ij->i", b, c) * la)
    # each triangle as its face is oriented (the solids' orientation is their faces')
    turn = np.sign(np.einsum("ij,ij->i", np.cross(b - a, c - a), scene.face_normal[scene.triangle_face[rows]]))
    omega = 2.0 * np.arctan2(det, den) * turn
    winding = np.bincount(face_solid[scene.triangle_face[rows]], weights=omega, minlength=len(outward)) / (4 * np.pi)
    return np.abs(winding) > 0.5


def across_solid(scene, light, face, towards):
    """Segments from the light reaching receiver ``face`` from the other side of the closed
    solid it bounds than the light: (m,) bool.

    A closed surface S (a scanned statue, a room) cuts space in two, and faces are
    two-sided: the complex's free segments run on either side. One from the light that
    reaches a face of S from the side the light is not on has crossed S, at an edge or a
    vertex it grazes: a segment lying in the plane of a face g of S crosses g and leaves it
    through an edge where the next face turns away on the light's side (a concave edge),
    into the solid. Such segments are free (the limit of segments over g on one side,
    inside the solid on the other), and V1 has their families, but a receiver point there
    sees the light through that edge only, along lines of measure zero: the light is
    hidden by S on both sides of the trace, and nothing changes across it (on the decimated
    bunny, 68 planar EEE traces on its faces, crossed without a change and most of them
    dangling: tests/test_discontinuities.py::test_saddle_at_the_receivers_vertex).

    Parameters
    ----------
    face : (m,) int64
        The receivers (faces outside any closed solid are never across one).
    towards : (m, 3) float64
        Each segment's direction at its receiver end, travelling away from the light.

    Returns
    -------
    (m,) bool
    """
    # arriving from the unlit side: travelling the way the lit side's normal points
    lit = lit_sides(scene, light)[face]
    return np.einsum("ij,ij->i", towards, scene.face_normal[face]) * lit > 0


def lit_sides(scene, light):
    """The side of each face from which segments from the light can reach it: (f,) int8,
    +1 the side its normal points to, -1 the other, 0 both (a face of no closed solid).

    A face of a closed solid S (:func:`viscx.queries.formfactor.closed_solids`) is reached
    from the light only on the side of S the light is on (:func:`light_inside_solids`):
    a segment from a point of the face into the other side stays in that side of S until
    it crosses S again, which blocks it (the faces are two-sided), so it never reaches
    the light. Segments arriving from that side (:func:`across_solid`) and receiver-plane
    events judged from it (:func:`viscx.queries.plane_events.receiver_plane_events`,
    ``sides``) change nothing on the face."""
    from viscx.queries.formfactor import closed_solids

    face_solid, outward, _ = closed_solids(scene)
    out = np.zeros(scene.n_faces, np.int8)
    k = np.flatnonzero(face_solid >= 0)
    if len(k):
        s = face_solid[k]
        # outward normals point to the outside: the lit side unless the light is inside S
        out[k] = np.where(light_inside_solids(scene, light)[s], -outward[s], outward[s]).astype(np.int8)
    return out


def pencil_points(scene, kind, generators):
    """The point every line of a *planar* EEE family passes through.

    When p's line and that of q or r lie in one plane (within epsilon: two edges of one
    face), the line through a point of p meeting the other one's line lies in that plane,
    so it meets the third edge where that edge crosses the plane: the family is the
    pencil of lines through that point X and the points of p. Its trace on a receiver is
    straight, and its line is defined at the end of p on the other edge's line too (the
    limit :func:`viscx.skeleton.arcs.family_lines` cannot evaluate).

    Returns
    -------
    planar : (m,) bool
    partner : (m,) int64
        Slot (1 or 2) of the edge coplanar with p (0 elsewhere).
    x : (m, 3) float64
        X (NaN elsewhere).
    normal : (m, 3) float64
        Unit normal of the plane (NaN elsewhere).
    """
    kind = np.asarray(kind)
    g = np.asarray(generators, np.int64)
    m = len(kind)
    partner = np.zeros(m, np.int64)
    x = np.full((m, 3), np.nan)
    normal = np.full((m, 3), np.nan)
    e = np.flatnonzero(kind == EEE)
    if not len(e):
        return partner > 0, partner, x, normal
    V, ev = scene.vertices, scene.half_edges.edge_vertices
    a = V[ev[g[e]][..., 0]]  # (k, 3 slots, 3)
    b = V[ev[g[e]][..., 1]]
    dp = b[:, 0] - a[:, 0]
    up = dp / np.linalg.norm(dp, axis=1, keepdims=True)
    eps = scene.epsilon
    for j in (1, 2):
        # the plane of p and the end of edge j farther from p's line; the other end within eps
        ra, rb = a[:, j] - a[:, 0], b[:, j] - a[:, 0]
        oa = ra - np.einsum("ij,ij->i", ra, up)[:, None] * up
        ob = rb - np.einsum("ij,ij->i", rb, up)[:, None] * up
        la, lb = np.linalg.norm(oa, axis=1), np.linalg.norm(ob, axis=1)
        far = np.where((la >= lb)[:, None], oa, ob)
        near = np.where((la >= lb)[:, None], ob, oa)
        with np.errstate(divide="ignore", invalid="ignore"):
            n = np.cross(up, far / np.maximum(np.maximum(la, lb), 1e-300)[:, None])
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            flat = (np.maximum(la, lb) > eps) & (np.abs(np.einsum("ij,ij->i", near, n)) <= eps)
            t = 3 - j
            dt = b[:, t] - a[:, t]
            den = np.einsum("ij,ij->i", n, dt)
            xt = a[:, t] + (np.einsum("ij,ij->i", n, a[:, 0] - a[:, t]) / den)[:, None] * dt
        ok = flat & (np.abs(den) > PARALLEL_TOLERANCE * np.linalg.norm(dt, axis=1)) & (partner[e] == 0)
        partner[e[ok]] = j
        x[e[ok]] = xt[ok]
        normal[e[ok]] = n[ok]
    return partner > 0, partner, x, normal


def panel_pencils(scene, kind, generators, snap):
    """Planar EEE families (:func:`pencil_points`) across whose trace nothing changes: both
    coplanar generator edges have all their faces in the family's plane P (a lone panel
    standing in the light, its plane cutting the light).

    Why: x crossing P turns over every face lying in P and no other face near the
    family's lines (a face off P through an edge in P keeps x on one side: the lines meet
    its plane only on that edge). An edge with a face off P is a contour edge from one
    side of P only, so crossing P changes which edges bound the light's hidden part (a
    tetrahedron's face edge-on: its outline passes from one edge to the other two). An
    edge whose faces all lie in P is a contour edge from both sides: two such edges
    bound the same thin hidden interval of the light edge on both sides (the panel seen
    almost edge-on, then from its back): no label changes.

    Returns
    -------
    (m,) bool
    """
    planar, partner, _, normal = pencil_points(scene, kind, generators)
    out = np.zeros(len(planar), bool)
    rows = np.flatnonzero(planar)
    if not len(rows):
        return out
    g = np.asarray(generators, np.int64)
    he = scene.half_edges
    order = np.argsort(he.edge, kind="stable")
    first = np.searchsorted(he.edge[order], np.arange(len(he.edge_vertices) + 1))
    pair = np.stack([g[rows, 0], g[rows, partner[rows]]], axis=1).ravel()
    row, h = expand_ranges(first[pair], first[pair + 1] - first[pair])
    face = he.face[order[h]]
    c = rows[row // 2]
    # the face lies in P: its normal within snap / diagonal (radians) of P's
    off = np.linalg.norm(np.cross(scene.face_normal[face], normal[c]), axis=1) > snap / scene.diagonal
    out[rows] = np.bincount(row // 2, weights=off, minlength=len(rows)) == 0
    return out


def _family_lines(scene, kind, generators, s, pencil=None):
    """:func:`viscx.skeleton.arcs.family_lines`, planar EEE families exactly (through their
    pencil point). ``pencil``: (planar, x) of :func:`pencil_points` for these rows."""
    o, d = family_lines(scene, kind, generators, s)
    if pencil is None:
        planar, _, x, _ = pencil_points(scene, kind, generators)
    else:
        planar, x = pencil
    if planar.any():
        ev = scene.half_edges.edge_vertices[np.asarray(generators, np.int64)[planar, 0]]
        a, b = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
        o[planar] = a + np.asarray(s, np.float64)[planar, None] * (b - a)
        d[planar] = o[planar] - x[planar]
    return o, d


def _trace_points(scene, kind, generators, s, face, pencil=None):
    """line(s) ∩ plane(face): (m, 3) float64 (NaN where the line is parallel to it)."""
    o, d = _family_lines(scene, kind, generators, s, pencil)
    n, c = scene.face_normal[face], scene.face_offset[face]
    den = np.einsum("ij,ij->i", n, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (c - np.einsum("ij,ij->i", n, o)) / den
        return o + t[:, None] * d


def trace_events(scene, arcs, events, tolerance, interval=None):
    """The trace of each event on its receiver as a polyline.

    Parameters
    ----------
    tolerance : float
        Chordal tolerance (scene units) of the EEE conic arcs.
    interval : (m, 2) float64, optional
        The family parameters to trace (default: each arc's interval).

    Returns
    -------
    offsets : (m + 1,) int64
    points : (p, 3) float64
        Polyline of event k: ``points[offsets[k]:offsets[k + 1]]``, in increasing s.
    params : (p,) float64
        The family parameter s of each point.
    """
    m = len(events.arc)
    kind = events.kind.astype(np.int64)
    gens = events.generators
    if interval is None:
        interval = events.interval
    s0, s1 = interval[:, 0], interval[:, 1]
    # chords: (event, sa, sb); VE and XE (lines through a point) one chord, EEE EEE_START refined
    planar, _, x, _ = pencil_points(scene, kind, gens)
    counts = np.where((kind == VE) | (kind == XE) | planar, 1, EEE_START)
    ev = np.repeat(np.arange(m), counts)
    j = np.arange(len(ev)) - np.repeat(np.cumsum(counts) - counts, counts)
    cn = counts[ev]
    sa = s0[ev] + (s1[ev] - s0[ev]) * j / cn
    sb = s0[ev] + (s1[ev] - s0[ev]) * (j + 1) / cn
    done_ev, done_s = [], []
    for _ in range(EEE_ROUNDS):
        if not len(ev):
            break
        k = kind[ev]
        fa = events.face[ev]
        pen = (planar[ev], x[ev])
        pa = _trace_points(scene, k, gens[ev], sa, fa, pen)
        pb = _trace_points(scene, k, gens[ev], sb, fa, pen)
        pm = _trace_points(scene, k, gens[ev], 0.5 * (sa + sb), fa, pen)
        ab = pb - pa
        w = np.clip(np.einsum("ij,ij->i", pm - pa, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0, 1)
        dev = np.linalg.norm(pm - (pa + w[:, None] * ab), axis=1)
        split = (k == EEE) & (dev > tolerance)
        done_ev.append(ev[~split])
        done_s.append(np.stack([sa[~split], sb[~split]], axis=1))
        mid = 0.5 * (sa[split] + sb[split])
        ev = np.concatenate([ev[split], ev[split]])
        sa, sb = np.concatenate([sa[split], mid]), np.concatenate([mid, sb[split]])
    done_ev.append(ev)
    done_s.append(np.stack([sa, sb], axis=1))
    ev, sab = np.concatenate(done_ev), np.concatenate(done_s)
    order = np.lexsort([sab[:, 0], ev])
    ev, sab = ev[order], sab[order]
    # each event's points: every chord's start, then its last chord's end
    last = np.r_[ev[1:] != ev[:-1], True] if len(ev) else np.zeros(0, bool)
    counts = np.bincount(ev, minlength=m) + 1
    counts[np.bincount(ev, minlength=m) == 0] = 0
    offsets = np.r_[0, np.cumsum(counts)].astype(np.int64)
    pev = np.concatenate([ev, ev[last]])
    ps = np.concatenate([sab[:, 0], sab[last, 1]])
    order = np.lexsort([ps, pev])
    pev, ps = pev[order], ps[order]
    pts = _trace_points(scene, kind[pev], gens[pev], ps, events.face[pev], (planar[pev], x[pev]))
    return thin_polylines(offsets, pts, ps, SPLIT_SNAP * scene.epsilon)


def thin_polylines(offsets, points, params, gap):
    """Polylines without inner points closer than ``gap`` to the point kept before them or
    to their last point (their ends kept): :func:`subdivide` merges points within the snap
    distance by single linkage, so the joints of a short EEE trace (``EEE_START`` chords of
    a trace 7 snap long: the whole bunny's face 2549) chained into one vertex with the
    trace's ends, 2.2e-3 inside the face, and the wedge between the trace and the outline
    was lost. A joint is dropped only where its neighbours are within a few snap, so the
    chord replacing two stays within the conic's chordal tolerance unless the conic turns
    at the epsilon scale. Polylines with a non-finite point are left as they are (the
    caller drops them).

    Parameters
    ----------
    offsets : (m + 1,) int64
    points : (p, 3) float64
    params : (p,) float64
    gap : float

    Returns
    -------
    offsets, points, params
    """
    n = np.diff(offsets)
    owner = np.repeat(np.arange(len(n)), n)
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    inner = owner[1:] == owner[:-1]
    close = np.zeros(len(n), bool)
    close[owner[1:][inner & (step < gap)]] = True
    bad = np.zeros(len(n), bool)
    bad[owner[~np.isfinite(points).all(axis=1)]] = True
    todo = np.flatnonzero(close & ~bad & (n > 2))
    if not len(todo):
        return offsets, points, params
    keep = np.ones(len(points), bool)
    for k in todo:  # (short EEE traces only: a few per receiver at most)
        p = points[offsets[k]:offsets[k + 1]]
        last, mine = 0, keep[offsets[k]:offsets[k + 1]]
        for i in range(1, len(p) - 1):
            mine[i] = np.linalg.norm(p[i] - p[last]) >= gap and np.linalg.norm(p[-1] - p[i]) >= gap
            last = i if mine[i] else last
    counts = np.bincount(owner[keep], minlength=len(n))
    return np.r_[0, np.cumsum(counts)].astype(np.int64), points[keep], params[keep]


def _in_domain(scene, kind, generators, s):
    """(m,) bool: the family's line at s meets the segments of its generator edges (p's and
    a VE's edge by construction, for s in [0, 1]; an EEE's q and r within epsilon of their
    ends)."""
    ok = (s >= 0) & (s <= 1)
    e = np.flatnonzero(kind == EEE)
    if len(e):
        o, d = _family_lines(scene, kind[e], generators[e], s[e])
        ev = scene.half_edges.edge_vertices
        for j in (1, 2):
            a, b = scene.vertices[ev[generators[e, j], 0]], scene.vertices[ev[generators[e, j], 1]]
            x, _ = segment_parameter(o, d, a, b)
            slack = scene.epsilon / np.linalg.norm(b - a, axis=1)
            ok[e] &= (x >= -slack) & (x <= 1 + slack)
    return ok


def _domain_end(scene, arcs, arc, face, s_in, s_out, steps=60):
    """The trace point where the arc's family leaves its domain (:func:`_in_domain`), by
    bisection between a parameter inside it and one outside: (3,) float64.

    A family continued past a transition (an EEE arc ending epsilons short of the line
    through an endpoint of one of its edges, as epsilon-visibility judges) reaches the
    other traces exactly there, between two trace samples that may lie far apart."""
    kind = arcs.kind[[arc]].astype(np.int64)
    gens = arcs.generators[[arc]]
    for _ in range(steps):
        mid = 0.5 * (s_in + s_out)
        if _in_domain(scene, kind, gens, np.array([mid]))[0]:
            s_in = mid
        else:
            s_out = mid
    return _trace_points(scene, kind, gens, np.array([s_in]), np.array([face]))[0]


def _first_hit(line, segs, snap):
    """Where a 2-D polyline first meets segments: crossing one, or passing within ``snap``
    of one's end, or ending within ``snap`` of one.

    line : (k, 2) float64; segs : (n, 2, 2) float64. Returns (chord index, parameter on
    it) or None.
    """
    a, b = line[:-1, None], line[1:, None]
    d = b - a
    c, e = segs[None, :, 0], segs[None, :, 1] - segs[None, :, 0]
    li = np.maximum(np.linalg.norm(d, axis=-1), 1e-300)
    lj = np.maximum(np.linalg.norm(e, axis=-1), 1e-300)
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    r = c - a
    with np.errstate(divide="ignore", invalid="ignore"):
        ti = (r[..., 0] * e[..., 1] - r[..., 1] * e[..., 0]) / den
        tj = (r[..., 0] * d[..., 1] - r[..., 1] * d[..., 0]) / den
    cross = ((np.abs(den) > PARALLEL_TOLERANCE * li * lj) & (ti >= 0) & (ti <= 1 + snap / li)
             & (tj >= -snap / lj) & (tj <= 1 + snap / lj))
    t = np.where(cross, np.minimum(ti, 1.0), np.inf)
    for p in (segs[None, :, 0], segs[None, :, 1]):  # a segment's end on the line
        w = np.einsum("ijk,ijk->ij", p - a, d) / li ** 2
        q = a + np.clip(w, 0, 1)[..., None] * d
        t = np.where((w >= 0) & (w <= 1) & (np.linalg.norm(p - q, axis=-1) <= snap), np.minimum(t, w), t)
    # the line's last point on a segment
    w = np.clip(np.einsum("ijk,ijk->ij", b - c, e) / lj ** 2, 0, 1)
    on = np.linalg.norm(b - c - w[..., None] * e, axis=-1) <= snap
    t = np.where(on, np.minimum(t, 1.0), t)
    best = t.min(axis=1)
    hit = np.flatnonzero(np.isfinite(best))
    if not len(hit):
        return None
    return int(hit[0]), float(best[hit[0]])


def continue_transitions(scene, arcs, events, offsets, points, lines, tolerance, snap):
    """Traces that stop short at a transition, continued to the first line they meet.

    V1 ends an arc at a *transition* (END_TRANSITION) where its samples change with no
    event to explain it: epsilon-visibility judging features closer than epsilon as
    touching (random scene 29: a sliver tetrahedron's edge runs within the weld tolerance
    of another of its faces for 15 epsilons from their common vertex, so V1 judges the
    family's lines there to cross that face and ends the arc 21 epsilons along its edge
    short of the vertex). An exact family stops only at a node, on other families' lines,
    so its trace ends on another trace; a transition end that meets no other line within
    ``snap`` stopped short. Its family is traced on from there towards the end of its
    parameter domain (s = 0 or 1, while its lines meet its generator segments) and kept
    up to the first line of the receiver it meets (nothing is added where it meets none).

    Parameters
    ----------
    lines : dict
        Receiver face -> (frame (u, v, o), (c, 2, 2) 2-D segments of its outline and
        contacts).

    Returns
    -------
    offsets, points
        The polylines, continued ones lengthened at that end.
    """
    has_arc = np.flatnonzero(events.arc >= 0)
    row = np.repeat(has_arc, 2)
    side = np.tile([0, 1], len(has_arc))
    sel = (arcs.end_type[events.arc[row], side] == END_TRANSITION) & np.isin(events.face[row], list(lines))
    row, side = row[sel], side[sel]
    if not len(row):
        return offsets, points
    end = np.where(side == 0, offsets[row], offsets[row + 1] - 1)
    s_t = arcs.interval[events.arc[row], side]
    at = _trace_points(scene, arcs.kind[events.arc[row]].astype(np.int64), arcs.generators[events.arc[row]], s_t,
                       events.face[row])
    row, side, end, s_t = (x[np.linalg.norm(points[end] - at, axis=1) <= snap] for x in (row, side, end, s_t))
    pieces = np.split(points, offsets[1:-1])
    for f in np.unique(events.face[row]):
        (u, v, _), segs = lines[f]
        mine = np.flatnonzero(events.face == f)
        chords, owner = [segs], [np.full(len(segs), -1)]
        for k in mine:
            q = np.stack([pieces[k] @ u, pieces[k] @ v], axis=1)
            chords.append(np.stack([q[:-1], q[1:]], axis=1))
            owner.append(np.full(len(q) - 1, k))
        chords, owner = np.concatenate(chords), np.concatenate(owner)
        here = np.flatnonzero(events.face[row] == f)
        p2 = np.stack([points[end[here]] @ u, points[end[here]] @ v], axis=1)
        a, d = chords[None, :, 0], chords[None, :, 1] - chords[None, :, 0]
        dd = np.maximum(np.einsum("ijk,ijk->ij", d, d), 1e-300)
        w = np.clip(np.einsum("ijk,ijk->ij", p2[:, None] - a, d) / dd, 0, 1)
        dist = np.linalg.norm(p2[:, None] - a - w[..., None] * d, axis=-1)
        dist[owner[None, :] == row[here][:, None]] = np.inf
        here = here[dist.min(axis=1) > snap]
        if not len(here):
            continue
        s_e = side[here].astype(np.float64)
        span = np.stack([np.minimum(s_t[here], s_e), np.maximum(s_t[here], s_e)], axis=1)
        ext_off, ext_pts, ext_s = trace_events(scene, arcs, events.take(row[here]), tolerance, span)
        a_ = events.arc[np.repeat(row[here], np.diff(ext_off))]
        domain = _in_domain(scene, arcs.kind[a_].astype(np.int64), arcs.generators[a_], ext_s)
        valid = domain & np.isfinite(ext_pts).all(axis=1)
        for i, h in enumerate(here):
            sl = slice(ext_off[i], ext_off[i + 1])
            e3, ok, es, dom = ext_pts[sl], valid[sl], ext_s[sl], domain[sl]
            if side[h] == 0:
                e3, ok, es, dom = e3[::-1], ok[::-1], es[::-1], dom[::-1]  # from the transition outwards
            if not ok.all():  # up to where the family ends, found between samples
                stop = int(np.argmin(ok))
                if stop == 0:
                    continue
                e3 = e3[:stop]
                if not dom[stop]:  # (not where the line turns parallel to the receiver)
                    e3 = np.concatenate([e3, _domain_end(scene, arcs, events.arc[row[h]], events.face[row[h]],
                                                         es[stop - 1], es[stop])[None]])
            if len(e3) < 2:
                continue
            e2 = np.stack([e3 @ u, e3 @ v], axis=1)
            hit = _first_hit(e2, chords[owner != row[h]], snap)
            if hit is None:
                continue
            k, t = hit
            tail = np.concatenate([e3[1:k + 1], (e3[k] + t * (e3[k + 1] - e3[k]))[None]])
            r = row[h]
            pieces[r] = np.concatenate([tail[::-1], pieces[r]]) if side[h] == 0 else np.concatenate([pieces[r], tail])
    counts = np.array([len(p) for p in pieces], np.int64)
    return np.r_[0, np.cumsum(counts)].astype(np.int64), np.concatenate(pieces)


# --------------------------------------------------------------------------------------
# the planar subdivision of one receiver


def _face_frame(scene, f):
    n = scene.face_normal[f]
    u, v = plane_basis(n)
    return u, v, n * scene.face_offset[f]


def _near_segment_pairs(segs, pad):
    """Pairs (i, j), i < j, of 2-D segments some point lies within ``pad`` of both: a
    superset, found on a uniform grid (:func:`viscx.grid.overlapping_box_pairs`) over the
    boxes, grown by ``pad``, of pieces about a cell long (a long chord lists the cells
    along it, not those of its whole box). A point within pad of a segment is within pad
    of one of its pieces, so in that piece's grown box.

    segs : (m, 2, 2) float64. Returns (q, 2) int64, sorted.
    """
    m = len(segs)
    if m <= SMALL_SEGMENT_SET:  # every pair: the grid costs more than it saves
        i, j = np.triu_indices(m, 1)
        return np.stack([i, j], axis=1).astype(np.int64)
    a, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    length = np.linalg.norm(d, axis=1)
    extent = float(np.max(segs.reshape(-1, 2).max(axis=0) - segs.reshape(-1, 2).min(axis=0)))
    # cells about the median chord (at most 256 per axis over the receiver's extent)
    cell = max(float(np.median(length)), extent / 256, 2 * pad, 1e-300)
    pieces = np.ceil(length / cell).astype(np.int64).clip(1)
    owner = np.repeat(np.arange(m), pieces)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    t0, t1 = k / pieces[owner], (k + 1) / pieces[owner]
    p0 = a[owner] + t0[:, None] * d[owner]
    p1 = a[owner] + t1[:, None] * d[owner]
    lo = np.zeros((len(owner), 3))
    hi = np.zeros((len(owner), 3))
    lo[:, :2] = np.minimum(p0, p1) - pad
    hi[:, :2] = np.maximum(p0, p1) + pad
    return overlapping_box_pairs(lo, hi, owner, np.zeros(len(owner), np.int64), cell)


def _split_params(segs, snap):
    """Where each 2-D segment is cut by the others.

    A cut of segment i by segment j is where their lines cross with both parameters
    within ``snap`` (in length) of the segments, or where an end of j lies within snap of
    i (T-junctions, collinear overlaps): either way some point lies within snap of both,
    so only the pairs :func:`_near_segment_pairs` finds (with twice snap: the crossing's
    parameters are rounded) are tested, each in both orders, by the same arithmetic as
    a test of every pair: the cost follows the crossings, not m².

    Parameters
    ----------
    segs : (m, 2, 2) float64
    snap : float

    Returns
    -------
    seg : (q,) int64, t : (q,) float64
        Segment id and parameter of every cut (ends included).
    """
    pairs = _near_segment_pairs(segs, 2 * snap)
    return _cuts(segs, np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]]), snap)


def _cuts(segs, i, j, snap):
    """The cuts of segment i by segment j, for ordered pairs (i, j), i != j: where their
    lines cross with both parameters within ``snap`` (in length) of the segments, and
    where an end of j lies within snap of i; plus both ends of every segment.

    segs : (m, 2, 2) float64; i, j : (q,) int64. Returns (segment, parameter) as
    :func:`_split_params`.
    """
    m = len(segs)
    a, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    length = np.maximum(np.linalg.norm(d, axis=1), 1e-300)
    out_s = [np.arange(m), np.arange(m)]
    out_t = [np.zeros(m), np.ones(m)]
    di, dj = d[i], d[j]
    den = di[:, 0] * dj[:, 1] - di[:, 1] * dj[:, 0]
    r = a[j] - a[i]
    with np.errstate(divide="ignore", invalid="ignore"):
        ti = (r[:, 0] * dj[:, 1] - r[:, 1] * dj[:, 0]) / den
        tj = (r[:, 0] * di[:, 1] - r[:, 1] * di[:, 0]) / den
    ei, ej = snap / length[i], snap / length[j]
    cross = (np.abs(den) > PARALLEL_TOLERANCE * length[i] * length[j]) & (ti >= -ei) & (ti <= 1 + ei) & (tj >= -ej) & (tj <= 1 + ej)
    out_s.append(i[cross])
    out_t.append(np.clip(ti[cross], 0, 1))
    # ends of segment j within snap of segment i (T-junctions, collinear overlaps)
    for k in (0, 1):
        p = segs[j, k]
        w = ((p[:, 0] - a[i][:, 0]) * di[:, 0] + (p[:, 1] - a[i][:, 1]) * di[:, 1]) / length[i] ** 2
        q = a[i] + np.clip(w, 0, 1)[:, None] * di
        near = (w > 0) & (w < 1) & (np.linalg.norm(p - q, axis=-1) <= snap)
        out_s.append(i[near])
        out_t.append(w[near])
    return np.concatenate(out_s), np.concatenate(out_t)


@njit(cache=True)
def _cycles(nxt):
    """Cycles of a permutation: (cycle id per element, elements in walk order, offsets)."""
    h = len(nxt)
    cid = np.full(h, -1, np.int64)
    seen = np.zeros(h, np.bool_)
    walk = np.empty(h, np.int64)
    offsets = [0]
    k = 0
    c = 0
    for s in range(h):
        if seen[s]:
            continue
        k = walk_cycle(nxt, s, seen, walk, k)
        for t in range(offsets[-1], k):
            cid[walk[t]] = c
        offsets.append(k)
        c += 1
    return cid, walk, np.array(offsets, dtype=np.int64)


def _inside(points, loops_a, loops_b, loop_of, n_loops):
    """Even-odd containment of each point in each loop: (p, n_loops) bool.

    loops_a, loops_b : (h, 2) float64 edges; loop_of : (h,) int64.
    """
    return _inside_kernel(np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2),
                          np.ascontiguousarray(loops_a, dtype=np.float64), np.ascontiguousarray(loops_b, dtype=np.float64),
                          np.ascontiguousarray(loop_of, dtype=np.int64), int(n_loops))


@njit(cache=True)
def _inside_kernel(points, loops_a, loops_b, loop_of, n_loops):
    # crossings of the ray from each point towards +x, counted per loop
    res = np.zeros((points.shape[0], n_loops), np.bool_)
    for k in range(points.shape[0]):
        px, py = points[k, 0], points[k, 1]
        for e in range(loops_a.shape[0]):
            ay, by = loops_a[e, 1], loops_b[e, 1]
            if (ay > py) != (by > py):
                x = loops_a[e, 0] + (py - ay) * (loops_b[e, 0] - loops_a[e, 0]) / (by - ay)
                if x > px:
                    res[k, loop_of[e]] = not res[k, loop_of[e]]
    return res


@njit(cache=True)
def _components(n, a, b):
    """Connected components of the graph on n nodes with edges (a, b): (n,) int64 labels,
    numbered in the order of each component's smallest node (union-find)."""
    parent = np.arange(n)
    for e in range(a.shape[0]):
        x, y = a[e], b[e]
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        while parent[y] != y:
            parent[y] = parent[parent[y]]
            y = parent[y]
        if x < y:
            parent[y] = x
        elif y < x:
            parent[x] = y
    label = np.full(n, -1, np.int64)
    out = np.empty(n, np.int64)
    k = 0
    for i in range(n):
        r = i
        while parent[r] != r:
            r = parent[r]
        if label[r] < 0:
            label[r] = k
            k += 1
        out[i] = label[r]
    return out


@njit(cache=True)
def _interior_points(a, b, offsets):
    """:func:`interior_point` of many polygons: polygon g has the edges a[i] -> b[i],
    i in offsets[g]:offsets[g + 1]. Returns (g, 2) float64 and (g,) bool: the polygons
    with fewer than two vertex heights or crossings, whose point is their vertices' mean
    (left to the caller)."""
    n = offsets.shape[0] - 1
    out = np.zeros((n, 2))
    degenerate = np.zeros(n, np.bool_)
    for g in range(n):
        lo, hi = offsets[g], offsets[g + 1]
        ys = np.sort(a[lo:hi, 1])
        # the largest gap between consecutive distinct heights (the first one if tied)
        best, lower, upper = -1.0, 0.0, 0.0
        prev = ys[0]
        for i in range(1, hi - lo):
            if ys[i] != prev:
                if ys[i] - prev > best:
                    best, lower, upper = ys[i] - prev, prev, ys[i]
                prev = ys[i]
        if best < 0:
            degenerate[g] = True
            continue
        y = 0.5 * (lower + upper)
        xs = np.empty(hi - lo)
        m = 0
        for i in range(lo, hi):
            if (a[i, 1] > y) != (b[i, 1] > y):
                xs[m] = a[i, 0] + (y - a[i, 1]) * (b[i, 0] - a[i, 0]) / (b[i, 1] - a[i, 1])
                m += 1
        if m < 2:
            degenerate[g] = True
            continue
        xs = np.sort(xs[:m])
        k, w = 0, -np.inf
        for j in range(m // 2):
            if xs[2 * j + 1] - xs[2 * j] > w:
                k, w = j, xs[2 * j + 1] - xs[2 * j]
        out[g, 0] = 0.5 * (xs[2 * k] + xs[2 * k + 1])
        out[g, 1] = y
    return out, degenerate


def interior_points(polygons):
    """:func:`interior_point` of each polygon: (g, 2) float64.

    polygons : list of lists of (k, 2) float64 loops.
    """
    loops = [lp for poly in polygons for lp in poly]
    if not loops:
        return np.zeros((0, 2))
    a = np.concatenate(loops)
    b = np.concatenate([np.roll(lp, -1, axis=0) for lp in loops])
    sizes = np.array([sum(len(lp) for lp in poly) for poly in polygons], np.int64)
    offsets = np.r_[0, np.cumsum(sizes)].astype(np.int64)
    out, degenerate = _interior_points(np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64), offsets)
    for g in np.flatnonzero(degenerate):
        out[g] = a[offsets[g]:offsets[g + 1]].mean(axis=0)
    return out


def interior_point(loops):
    """A point strictly inside a polygon with holes: the middle of the widest interval of
    a horizontal line through the largest gap between vertex heights.

    loops : list of (k, 2) float64. Returns (2,) float64.
    """
    return interior_points([loops])[0]


@dataclass
class Region:
    """One face of a receiver's subdivision.

    Attributes
    ----------
    outer : (k, 2) float64
        Counter-clockwise about the receiver's normal (face 2-D coordinates).
    holes : list of (m, 2) float64
        Clockwise.
    area : float
    point : (2,) float64
        A point strictly inside.
    events : (b,) int64
        Rows of :class:`Events` whose trace bounds the region.
    """

    outer: np.ndarray
    holes: list = field(default_factory=list)
    area: float = 0.0
    point: np.ndarray = None
    events: np.ndarray = None


def subdivide(outline, chords, chord_event, snap):
    """The regions a set of chords cuts a polygon into.

    Parameters
    ----------
    outline : list of (k, 2) float64
        The receiver's loops (outer first).
    chords : (m, 2, 2) float64
        Trace chords.
    chord_event : (m,) int64
        Event row of each chord.
    snap : float

    Returns
    -------
    list of Region
    """
    oa = np.concatenate(outline)
    ob = np.concatenate([np.roll(lp, -1, axis=0) for lp in outline])
    segs = np.concatenate([np.stack([oa, ob], axis=1), chords.reshape(-1, 2, 2)])
    label = np.concatenate([np.full(len(oa), -1, np.int64), chord_event])
    keep = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) > 0
    segs, label = segs[keep], label[keep]
    sid, t = _split_params(segs, snap)
    order = np.lexsort([t, sid])
    sid, t = sid[order], t[order]
    pts = segs[sid, 0] + t[:, None] * (segs[sid, 1] - segs[sid, 0])
    # merge points within snap
    from scipy.spatial import cKDTree

    pairs = cKDTree(pts).query_pairs(snap, output_type="ndarray")
    vid = _components(len(pts), pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64))
    nvert = vid.max() + 1
    vpos = np.zeros((nvert, 2))
    np.add.at(vpos, vid, pts)
    vpos /= np.bincount(vid, minlength=nvert)[:, None]
    same = sid[1:] == sid[:-1]
    ea, eb, el = vid[:-1][same], vid[1:][same], label[sid[:-1][same]]
    ok = ea != eb
    ea, eb, el = ea[ok], eb[ok], el[ok]
    lo, hi = np.minimum(ea, eb), np.maximum(ea, eb)
    _, first = np.unique(lo * nvert + hi, return_index=True)
    ea, eb, el = lo[first], hi[first], el[first]
    # prune dangling edges
    alive = np.ones(len(ea), bool)
    while True:
        deg = np.bincount(ea[alive], minlength=nvert) + np.bincount(eb[alive], minlength=nvert)
        dead = alive & ((deg[ea] == 1) | (deg[eb] == 1))
        if not dead.any():
            break
        alive &= ~dead
    ea, eb, el = ea[alive], eb[alive], el[alive]
    if not len(ea):
        return []
    # half-edges: 2k is ea->eb, 2k+1 is eb->ea
    org = np.stack([ea, eb], axis=1).ravel()
    dst = np.stack([eb, ea], axis=1).ravel()
    hlab = np.repeat(el, 2)
    vec = vpos[dst] - vpos[org]
    ang = np.arctan2(vec[:, 1], vec[:, 0])
    order = np.lexsort([ang, org])
    pos = np.empty(len(org), np.int64)
    pos[order] = np.arange(len(org))
    start = np.searchsorted(org[order], np.arange(nvert))
    deg = np.bincount(org, minlength=nvert)
    twin = np.arange(len(org)) ^ 1
    # next(h): at h's head, the outgoing half-edge just clockwise of twin(h)
    tw = twin
    head = dst
    k = pos[tw] - start[head]
    nxt = order[start[head] + (k - 1) % deg[head]]
    cid, walk, offs = _cycles(nxt)
    nc = len(offs) - 1
    a, b = vpos[org[walk]], vpos[dst[walk]]
    cyc = np.repeat(np.arange(nc), np.diff(offs))
    area = 0.5 * np.bincount(cyc, weights=a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1], minlength=nc)
    # components of the graph
    comp = _components(nvert, ea.astype(np.int64), eb.astype(np.int64))
    ccomp = comp[org[walk[offs[:-1]]]]
    loops = [vpos[org[walk[offs[c]:offs[c + 1]]]] for c in range(nc)]
    pos_c = np.flatnonzero(area > 0)
    neg_c = np.flatnonzero(area <= 0)
    # outer loops inside the receiver (not in a hole of it)
    reps = interior_points([[loops[c]] for c in pos_c]).reshape(-1, 2)
    fa = np.concatenate(outline)
    fb = np.concatenate([np.roll(lp, -1, axis=0) for lp in outline])
    in_face = _inside(reps, fa, fb, np.zeros(len(fa), np.int64), 1)[:, 0] if len(reps) else np.zeros(0, bool)
    pos_c = pos_c[in_face]
    holes = {int(c): [] for c in pos_c}
    if len(pos_c) and len(neg_c):
        sel = np.isin(cyc, pos_c)
        remap = np.full(nc, -1, np.int64)
        remap[pos_c] = np.arange(len(pos_c))
        probes = np.array([loops[c][0] for c in neg_c])
        inside = _inside(probes, a[sel], b[sel], remap[cyc[sel]], len(pos_c))
        inside &= ccomp[pos_c][None, :] != ccomp[neg_c][:, None]
        for r, c in enumerate(neg_c):
            cand = np.flatnonzero(inside[r])
            if len(cand):
                best = cand[np.argmin(area[pos_c[cand]])]
                holes[int(pos_c[best])].append(int(c))
    # each region's events: the labels of its cycles' half-edges (outer loop and holes)
    region_of = np.full(nc, -1, np.int64)
    for r, c in enumerate(pos_c):
        region_of[c] = r
        region_of[holes[int(c)]] = r
    rc = region_of[cyc]
    span = int(hlab.max()) + 2  # (labels are event rows, or -1 on the outline)
    key = np.unique(rc[rc >= 0] * span + (hlab[walk][rc >= 0] + 1))
    kr, kl = key // span, key % span - 1
    bounds = np.searchsorted(kr, np.arange(len(pos_c) + 1))
    polys = [[loops[c]] + [loops[h] for h in holes[int(c)]] for c in pos_c]
    points = interior_points(polys)
    regions = []
    for r, c in enumerate(pos_c):
        hs = holes[int(c)]
        ev = kl[bounds[r]:bounds[r + 1]]
        regions.append(Region(outer=loops[c], holes=[loops[h] for h in hs],
                              area=float(area[c] + sum(area[h] for h in hs)), point=points[r],
                              events=ev[ev >= 0]))
    return regions


def contact_edges(scene, f, outline, basis, snap, light):
    """Edges of other faces lying on receiver f (an occluder standing on it): the D0
    discontinuities. Their VE families with a light vertex end *at* the edge (blocked by
    it), so V1 has no arc ending on f there; the trace is the edge itself.

    Parameters
    ----------
    outline : list of (k, 2) float64
        f's loops in 2-D.
    basis : (u, v), (3,) float64 each

    Returns
    -------
    (c,) int64 edge ids: both ends within ``snap`` of f's plane and the middle inside f
    (not an edge of f, not a light edge).
    """
    he = scene.half_edges
    ev = he.edge_vertices
    dist = np.abs(scene.vertices @ scene.face_normal[f] - scene.face_offset[f]) <= snap
    cand = np.flatnonzero(dist[ev[:, 0]] & dist[ev[:, 1]])
    own = np.unique(he.edge[he.face == f])
    cand = cand[~np.isin(cand, own) & ~np.isin(cand, light.edges)]
    if not len(cand):
        return cand.astype(np.int64)
    u, v = basis
    mid = 0.5 * (scene.vertices[ev[cand, 0]] + scene.vertices[ev[cand, 1]])
    q = np.stack([mid @ u, mid @ v], axis=1)
    a = np.concatenate(outline)
    b = np.concatenate([np.roll(lp, -1, axis=0) for lp in outline])
    inside = _inside(q, a, b, np.zeros(len(a), np.int64), 1)[:, 0]
    return cand[inside].astype(np.int64)


def faces_with_contacts(scene, snap, light):
    """(n_faces,) bool: the faces :func:`contact_edges` may find an edge on, for all faces
    at once: an edge lying on f has its middle inside f and within ``snap`` of its plane,
    so within snap of the closed face (:func:`viscx.scene.neighbourhood.faces_near`, with
    a margin); f's own edges and the light's left out. contact_edges, O(vertices + edges)
    per face, then runs on these faces only."""
    from viscx.scene.neighbourhood import faces_near

    he = scene.half_edges
    ev = he.edge_vertices
    mid = 0.5 * (scene.vertices[ev[:, 0]] + scene.vertices[ev[:, 1]])
    edge, face = faces_near(scene, mid, 2 * snap)
    nf = scene.n_faces
    own = np.isin(edge * nf + face, he.edge.astype(np.int64) * nf + he.face)
    other = ~own & ~np.isin(edge, light.edges)
    out = np.zeros(nf, bool)
    out[face[other]] = True
    return out


# --------------------------------------------------------------------------------------
# the query


@dataclass
class ReceiverMesh:
    """The discontinuity mesh on one receiver face.

    Attributes
    ----------
    face : int
    events : (m,) int64
        Rows of :class:`Events` traced on this face.
    regions : list of Region
    frame : tuple of (3,) float64
        ``(u, v, origin)``: 2-D coordinates (x @ u, x @ v); 3-D point origin + a u + b v.
    contacts : (c,) int64
        Edges of other faces lying on this receiver (:func:`contact_edges`).
    """

    face: int
    events: np.ndarray
    regions: list
    frame: tuple
    contacts: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def to3(self, q):
        u, v, o = self.frame
        q = np.asarray(q, dtype=np.float64)
        return o + q[..., :1] * u + q[..., 1:] * v


@dataclass
class DiscontinuityMesh:
    """Everything the query reports.

    Attributes
    ----------
    light : Light
    events : Events
    offsets : (m + 1,) int64
    points : (p, 3) float64
        Trace polylines (:func:`trace_events`).
    receivers : list of ReceiverMesh
        Every face that is not a light face, in face order.
    tolerance, snap : float
        Chordal tolerance and snap distance (scene units).
    """

    light: Light
    events: Events
    offsets: np.ndarray
    points: np.ndarray
    receivers: list
    tolerance: float
    snap: float


def discontinuity_mesh(scene, arcs, light, faces=None):
    """The discontinuity mesh of an area light on every receiver (module docstring).

    Parameters
    ----------
    scene : Scene
    arcs : Arcs
        V1 of the scene, as stored.
    light : Light
    faces : sequence of int, optional
        Receivers to subdivide (default: every face that is not a light face).

    Returns
    -------
    DiscontinuityMesh
    """
    tol = CHORD_TOLERANCE * scene.epsilon
    snap = SPLIT_SNAP * scene.epsilon
    events = select_events(scene, arcs, light)
    offsets, points, _ = trace_events(scene, arcs, events, tol)
    finite = np.isfinite(points).all(axis=1)
    bad_ev = np.unique(np.searchsorted(offsets, np.flatnonzero(~finite), side="right") - 1)
    good = np.ones(len(events.arc), bool)
    good[bad_ev] = False
    in_light = np.zeros(scene.n_faces, bool)
    in_light[light.faces] = True
    wanted = [f for f in (range(scene.n_faces) if not faces else sorted(set(int(f) for f in faces))) if not in_light[f]]
    frames = {f: _face_frame(scene, f) for f in wanted}
    outlines = {f: [np.stack([lp @ frames[f][0], lp @ frames[f][1]], axis=1) for lp in scene.face_loops(f)] for f in wanted}
    # receiver-plane events (straight traces in the receiver's plane)
    tri_edge = triangle_edge_ids(scene)
    lit = lit_sides(scene, light)
    rp_rows, rp_pts = [], []
    for f in wanted:
        u, v, o = frames[f]
        sides = (1.0, -1.0) if lit[f] == 0 else (float(lit[f]),)
        kind, occ, ledge, ends = receiver_plane_events(scene, light, f, (u, v), outlines[f], snap, tri_edge, sides)
        m = len(kind)
        rp_rows.append(_plane_rows(np.full(m, f), kind, np.full(m, LIGHT_EDGE), ledge,
                                   np.stack([occ, ledge, np.full(m, -1)], axis=1)))
        rp_pts.append(o + ends[..., :1] * u + ends[..., 1:] * v)
    # one-sided light: only what is in front of it (the traces behind change nothing)
    keep = np.flatnonzero(good)
    counts = np.r_[np.diff(offsets)[keep], np.full(sum(len(r.arc) for r in rp_rows), 2)]
    all_pts = np.concatenate([points[np.repeat(good, np.diff(offsets))], *[p.reshape(-1, 3) for p in rp_pts]])
    all_ev = Events.concat([events.take(keep), *rp_rows])
    planes = light_planes(scene, light, snap)
    row, offsets, points = clip_to_front(np.r_[0, np.cumsum(counts)].astype(np.int64), all_pts, planes, snap)
    parts, lp_pts = [all_ev.take(row)], []
    # the light's plane: where receivers stop seeing its front
    for f in wanted:
        u, v, o = frames[f]
        lface, ends = light_plane_lines(scene, planes, f, (u, v), o, outlines[f], snap)
        m = len(lface)
        parts.append(_plane_rows(np.full(m, f), np.full(m, LIGHT_PLANE), np.full(m, LIGHT_FACE), lface,
                                 np.stack([lface, np.full(m, -1), np.full(m, -1)], axis=1)))
        lp_pts.append((o + ends[..., :1] * u + ends[..., 1:] * v).reshape(-1, 3))
    events = Events.concat(parts)
    n_lp = len(events.arc) - len(row)
    offsets = np.r_[offsets, offsets[-1] + 2 * np.arange(1, n_lp + 1)].astype(np.int64)
    points = np.concatenate([points, *lp_pts])
    # traces that stop short of every line (V1's transitions) go on to the first one
    contacts, lines = {}, {}
    touching = faces_with_contacts(scene, snap, light)
    traced = np.zeros(scene.n_faces, bool)
    traced[events.face] = True
    for f in wanted:
        u, v, o = frames[f]
        contacts[f] = contact_edges(scene, f, outlines[f], (u, v), snap, light) if touching[f] else np.zeros(0, np.int64)
        if not traced[f]:  # (no trace to continue on f)
            continue
        ends = scene.vertices[scene.half_edges.edge_vertices[contacts[f]]]
        oa = np.concatenate(outlines[f])
        ob = np.concatenate([np.roll(lp, -1, axis=0) for lp in outlines[f]])
        lines[f] = (frames[f], np.concatenate([np.stack([oa, ob], axis=1),
                                               np.stack([ends @ u, ends @ v], axis=-1).reshape(-1, 2, 2)]))
    offsets, points = continue_transitions(scene, arcs, events, offsets, points, lines, tol, snap)
    receivers = []
    for f in wanted:
        u, v, o = frames[f]
        mine = np.flatnonzero(events.face == f)
        outline = outlines[f]
        contact = contacts[f]
        ends = scene.vertices[scene.half_edges.edge_vertices[contact]]
        chords = [np.stack([ends @ u, ends @ v], axis=-1).reshape(-1, 2, 2)]
        cev = [np.full(len(contact), -1, np.int64)]
        for k in mine:
            p = points[offsets[k]:offsets[k + 1]]
            q = np.stack([p @ u, p @ v], axis=1)
            chords.append(np.stack([q[:-1], q[1:]], axis=1))
            cev.append(np.full(len(q) - 1, k))
        regions = subdivide(outline, np.concatenate(chords), np.concatenate(cev), snap)
        receivers.append(ReceiverMesh(f, mine, regions, (u, v, o), contact))
    return DiscontinuityMesh(light, events, offsets, points, receivers, tol, snap)


def light_mesh(query, light_face=None, light_group=None, faces=()):
    """The discontinuity mesh of a light (one face, or the faces of a group) from a
    complex's arcs (V1; read from its file when it was opened from one).

    Parameters
    ----------
    query : viscx.pipeline.BuiltComplex
    light_face : int, optional
    light_group : str, optional
        Exactly one of the two.
    faces : sequence of int
        Receivers to report (default every face); ViscxError when out of range.

    Returns
    -------
    DiscontinuityMesh
    """
    scene = query.scene
    scene.face_ids(faces)
    light = light_of(scene, light_face, light_group)
    return discontinuity_mesh(scene, query.arcs, light, faces)


def open_light_query(path, light_face=None, light_group=None, check=None, scene_only=False, **scene_options):
    """The complex a light's queries (discontinuity mesh, render) read: a viscx file's V1
    (a full build, which must hold V2, or a build scoped to this light: ``viscx build
    --light-group``), or for a scene file (OBJ, PLY, …) the *scoped* build of the light
    (:func:`viscx.pipeline.build_complex` with the light: the nodes and arcs of its
    families only, the full build's, nothing written).

    Parameters
    ----------
    path : str or Path
    light_face : int, optional
    light_group : str, optional
    check : callable, optional
        ``check(scene, light)`` raises for a query that cannot be answered (a light that
        emits nothing), called before anything is built.
    scene_only : bool
        The query needs the scene only (the exact render, :mod:`viscx.render.tiles`):
        nothing is built from a scene file, and any viscx file's scene will do.
    **scene_options
        ``weld``, ``epsilon``, ``relative_epsilon`` for a scene file; a viscx file keeps
        the ones it was built with.

    Returns
    -------
    viscx.pipeline.BuiltComplex

    Raises ViscxError (one line) for a viscx file without what the query needs, a file
    scoped to another light, scene options with a viscx file, or an unknown light.
    """
    from pathlib import Path

    import h5py

    from viscx.errors import ParameterError, ViscxError, literal
    from viscx.pipeline import build_complex, light_option, open_complex, require_level, scene_of

    if (light_face is None) == (light_group is None):
        raise ParameterError("give exactly one of {light_face} and {light_group}")
    check = check or (lambda scene, light: None)
    given = {k: v for k, v in scene_options.items() if v is not None}
    if not (Path(path).is_file() and h5py.is_hdf5(path)):
        scene = scene_of(path, **given)
        check(scene, light_of(scene, light_face, light_group))
        if scene_only:
            return build_complex(scene, quiet=True, levels=-1)
        return build_complex(scene, quiet=True, light_face=light_face, light_group=light_group)
    if given:
        names = ", ".join("{" + k + "}" for k in sorted(given))
        raise ParameterError(f"{literal(path)} is a viscx file, built with its own scene options: {names} apply to "
                             "scene files only")
    cx = open_complex(path)
    scoped = light_option(cx.options)
    check(cx.scene, light_of(cx.scene, light_face, light_group))
    if scene_only:
        return cx
    if scoped is None:  # (the file opened once: its scene read and its structure checked once)
        return require_level(cx, "V2", path, hint=", or query the scene file itself")
    asked = {"light_face": int(light_face)} if light_face is not None else {"light_group": light_group}
    if scoped != asked:
        (key, value), = scoped.items()
        raise ViscxError(f"{path} was built for one light ({key.replace('_', ' ')} {value}) only; query that light, "
                         "or the scene file itself")
    return require_level(cx, "V1", path)


def open_discontinuities(path, light_face=None, light_group=None, faces=(), **scene_options):
    """The mesh (:func:`light_mesh`) from a viscx file or, scoped, from a scene file
    (:func:`open_light_query`).

    Returns
    -------
    scene : Scene
    mesh : DiscontinuityMesh
    """
    cx = open_light_query(path, light_face, light_group, **scene_options)
    return cx.scene, light_mesh(cx, light_face, light_group, faces)


def mesh_result(scene, mesh):
    """The mesh as a plain dict (the JSON schema of docs/queries.md)."""
    ev = mesh.events
    faces = []
    for r in mesh.receivers:
        segs = []
        for k in r.events:
            segs.append({
                "event": int(k),
                "arc": int(ev.arc[k]),
                "kind": EVENT_KINDS[int(ev.kind[k])],
                "generators": [int(x) for x in ev.generators[k] if x >= 0],
                "light": ["vertex", "edge", "face"][int(ev.light_kind[k])],
                "light_feature": int(ev.light_feature[k]),
                "points": mesh.points[mesh.offsets[k]:mesh.offsets[k + 1]].tolist(),
            })
        ends = scene.vertices[scene.half_edges.edge_vertices[r.contacts]]
        faces.append({
            "face": r.face,
            "group": scene.group_names[scene.face_group[r.face]],
            "segments": segs,
            "contacts": [{"edge": int(e), "points": p.tolist()} for e, p in zip(r.contacts, ends)],
            "regions": [{
                "outer": r.to3(g.outer).tolist(),
                "holes": [r.to3(h).tolist() for h in g.holes],
                "area": g.area,
                "point": r.to3(g.point).tolist(),
                "events": g.events.tolist(),
            } for g in r.regions],
        })
    return {
        "light": {"name": mesh.light.name, "faces": mesh.light.faces.tolist(), "vertices": mesh.light.vertices.tolist(),
                  "edges": mesh.light.edges.tolist()},
        "tolerance": mesh.tolerance,
        "snap": mesh.snap,
        "events": int(len(ev.arc)),
        "faces": faces,
    }
