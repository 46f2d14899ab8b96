"""The V1 builder: every family of a scene, built in chunks of consecutive families.
"""

from dataclasses import dataclass, replace

import numpy as np

from viscx.arrays import unique_rows
from viscx.memory import release_free_memory
from viscx.parallel import map_chunks, row_chunks
from viscx.progress import bar
from viscx.skeleton.arcs.events import (
    PlanePoints,
    coplanar_candidates,
    coplanar_join,
    coplanar_reach,
    domain_ends,
    event_parameters,
    face_plane_crossings,
    family_incidences,
    hidden_events,
    node_reach,
    planar_events,
    points_of_planes,
    row_blocks,
    same_plane_ve,
)
from viscx.skeleton.arcs.halfcells import build_half_cells
from viscx.skeleton.arcs.kinds import Arcs, CHUNK, HalfCells, EEE, END_ENDPOINT, END_NODE, END_PLANAR, VE
from viscx.skeleton.arcs.pencils import contact_pencils, pencil_events
from viscx.skeleton.arcs.stages import (
    arcs_of_pieces,
    concatenate_parts,
    edge_line_ends,
    family_intervals,
    first_pass,
    refine_intervals,
)
from viscx.skeleton.arcs.xe import crossing_arcs
from viscx.skeleton.generators import edge_junctions
from viscx.skeleton.nodes import Nodes
from viscx.tolerances import PARAMETER_SLACK


def build_arcs(scene, nodes, quiet=True, workers=None, scope=None):
    """The arcs (V1) and VE half-cells of a scene, from its nodes (V0).

    The families are found once for the whole scene (:func:`_families`,
    :func:`arc_families`). Then each chunk of consecutive families is built on its own
    (:func:`arcs_of_families`: its events, intervals and first samples, its few
    intervals whose samples disagree refined, its pieces merged into arcs, their
    half-cells): every stage of an arc is decided within its family, so the arcs do not
    depend on the chunks, and the chunks' arcs, each sorted, concatenate in the
    canonical order (:func:`join_arc_parts`). Memory holds the result and one chunk's
    events and pieces; a streamed build (:func:`viscx.pipeline.stream_arcs`) writes
    each chunk's arcs to the file instead and holds one chunk.

    Parameters
    ----------
    scene : Scene
    nodes : Nodes
        The V0 nodes (any builder's; ids refer to their order).
    quiet : bool
        No progress bar.
    workers : int, optional
        Threads judging a chunk's samples (default: the CPU count); the arcs do not depend on it.
    scope : viscx.skeleton.scope.Scope, optional
        Only the families with a generator in scope (:mod:`viscx.skeleton.scope`; ``nodes``
        then need only hold the nodes in scope) and the planar events with an edge in
        it: the full build's arcs of those families, in its order (their ``end_node`` ids
        refer to ``nodes`` and to the scoped ``planar``).

    Returns
    -------
    Arcs
    """
    planar, families = arc_families(scene, nodes, workers, scope, quiet)
    parts = []
    with bar(desc="arcs", quiet=quiet, unit="chunk", total=len(_family_chunks(families))) as progress:
        for part in family_parts(families):
            parts.append(arcs_of_families(scene, families.plane_points, *part, workers=workers))
            progress.update()
    del families
    release_free_memory()
    arcs, half_cells = join_arc_parts(parts)
    xe = crossing_arcs(scene, workers, scope)
    if xe is not None:  # after the VE arcs: the other arcs' ids do not change
        arcs = {k: np.concatenate([v, xe[k]]) for k, v in arcs.items()}
    return Arcs(**arcs, planar=planar, half_cells=half_cells)


def arc_families(scene, nodes, workers=None, scope=None, quiet=True):
    """The planar E4 events (:func:`planar_events`, a Nodes) and every arc family of the
    scene with its events (:class:`_Families`, :func:`_families`): what the chunks of
    families are cut from (:func:`family_parts`). Arguments as :func:`build_arcs`."""
    with bar(total=2, desc="arc families", quiet=quiet, unit="stage") as progress:
        progress.set_postfix_str("planar events")
        planar = planar_events(scene, scope)
        progress.update()
        progress.set_postfix_str("families")
        families = _families(scene, nodes, planar, workers, scope)
        progress.update()
    return planar, families


def family_parts(families):
    """The chunks of consecutive families (:func:`_family_chunks`), each as the arguments of
    :func:`arcs_of_families` after the scene and the plane points: a :class:`_Families` of
    the chunk's families alone (numbered from 0; without the plane points, which every
    chunk shares), made one at a time."""
    for chunk in _family_chunks(families):
        lo, hi = chunk.start, chunk.stop
        ev = slice(int(families.event_offsets[lo]), int(families.event_offsets[hi]))
        p = slice(*(int(i) for i in np.searchsorted(families.plane_family, [lo, hi])))
        yield (_Families(families.kind[chunk], families.generators[chunk],
                         families.event_offsets[lo: hi + 1] - families.event_offsets[lo], families.event_s[ev],
                         families.event_kind[ev], families.event_index[ev], families.event_reach[ev],
                         families.plane_family[p] - lo,
                         families.plane_ve[p], families.plane_of[p], None, families.weight[chunk]),)


def arcs_of_families(scene, plane_points, families, workers=None):
    """The arcs of a chunk of families (:func:`family_parts`), sorted as :func:`sorted_arcs`,
    and their half-cells (arc ids the chunk's, from 0): the chunk's first pass, its
    intervals whose samples disagree refined (each on its own, :func:`refine_intervals`),
    its pieces merged (:func:`_arcs_of_families`).

    Returns
    -------
    arcs : dict of arrays
        The per-arc fields of :class:`Arcs`.
    half_cells : HalfCells
    """
    families = replace(families, plane_points=plane_points)
    every = slice(0, len(families))
    parts, mixed = _first_pass_of_families(scene, families, every)
    refined = refine_intervals(scene, families.kind, families.generators, *mixed, workers=workers)
    arcs = _arcs_of_families(scene, families, every, parts + refined)
    half_cells = build_half_cells(scene, arcs)
    del arcs["sides"]
    return arcs, half_cells


def join_arc_parts(parts):
    """The arcs and half-cells of the chunks of :func:`arcs_of_families` (a list, emptied
    as it is joined), concatenated: the half-cells' arc ids shifted by the arcs of the
    chunks before."""
    shift = np.cumsum([0] + [len(arcs["kind"]) for arcs, _ in parts])
    half = [replace(hc, arc=hc.arc + s) for (_, hc), s in zip(parts, shift)]
    half_cells = HalfCells(**{name: np.concatenate([getattr(hc, name) for hc in half])
                              for name in HalfCells.__dataclass_fields__})
    del half
    arcs = concatenate_parts([p[0] for p in parts], release=True)
    parts.clear()
    return arcs, half_cells


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
        of ``event_s`` (float), ``event_kind`` (END_NODE or END_PLANAR), ``event_index``
        (the node, or the row of the planar events) and ``event_reach`` (float32: for a VE
        family, the distance from its vertex to the event's farthest generator point,
        :func:`node_reach`).
    plane_family : (m,) int
        The same-plane VE families (:func:`same_plane_ve`), ascending, with their (v, e)
        ``plane_ve`` (m, 2) and plane ``plane_of`` (m,).
    plane_points : PlanePoints
        The points of their planes (:func:`points_of_planes`).
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
    event_reach: np.ndarray
    plane_family: np.ndarray
    plane_ve: np.ndarray
    plane_of: np.ndarray
    plane_points: PlanePoints
    weight: np.ndarray

    def __len__(self):
        return len(self.kind)


def _families(scene, nodes, planar, workers=None, scope=None):
    """The families through the nodes and the planar events, every same-plane VE family
    and every pencil at a corner of a touched face (which may hold no node), with their
    node and planar events (:class:`_Families`); with a ``scope``, those in it only."""
    def incidences(chunk):
        code, events, rows = chunk
        part = Nodes(**{k: getattr(events, k)[rows] for k in Nodes.__dataclass_fields__})
        k, g, at, through = family_incidences(scene, part)
        seeds = g[through]
        k, g, at = k[~through], g[~through], at[~through]
        if scope is not None:
            seeds = seeds[scope.families(np.where(seeds[:, 2] < 0, VE, EEE), seeds)]
            mine = scope.families(k, g)
            k, g, at = k[mine], g[mine], at[mine]
        return (k.astype(np.int8), g, np.full(len(at), code, np.int8), at + rows.start, event_parameters(scene, k, g, part, at),
                seeds, node_reach(scene, k, g, part, at).astype(np.float32))

    # in chunks of events (each on its own, on threads): their temporaries stay bounded
    chunks = [(code, events, rows) for code, events in ((END_NODE, nodes), (END_PLANAR, planar))
              for rows in row_chunks(max(len(events), 1), CHUNK // 4)]
    fam_kind, fam_gens, ev_kind, ev_index, ev_s, seeds, ev_reach = (list(x) for x in zip(*map_chunks(incidences, chunks, workers)))
    n_events = sum(len(k) for k in fam_kind)
    # families through a node only by an edge passing through its vertex: seeds, no events
    seeds = np.concatenate(seeds).reshape(-1, 3)
    fam_kind.append(np.where(seeds[:, 2] < 0, VE, EEE).astype(np.int8))
    fam_gens.append(seeds)
    # VE families of a vertex and an edge in one face's plane may hold no node: seed them all
    plane_ve, plane_of, vp, ep = same_plane_ve(scene)
    if scope is not None:
        mine = scope.families(np.full(len(plane_ve), VE), np.c_[plane_ve, np.full(len(plane_ve), -1)])
        plane_ve, plane_of = plane_ve[mine], plane_of[mine]
    # the points of the families' planes only: a family's coplanar events are those of its
    # plane, in that plane's order (:func:`coplanar_join`), whatever other planes are listed
    planes = np.unique(plane_of)
    fam_kind.append(np.full(len(plane_ve), VE, np.int8))
    fam_gens.append(np.concatenate([plane_ve, np.full((len(plane_ve), 1), -1)], axis=1))
    # so may the pencils at the corners of faces in contact
    pencils = contact_pencils(scene, scope)
    if scope is not None:
        pencils = pencils[scope.families(np.full(len(pencils), EEE), pencils)]
    fam_kind.append(np.full(len(pencils), EEE, np.int8))
    fam_gens.append(pencils)
    keys = np.concatenate([np.concatenate(fam_kind).astype(np.int64)[:, None], np.concatenate(fam_gens)], axis=1)
    del fam_kind, fam_gens
    # (shifted by one, the -1 of VE rows included, the rows pack into one sortable int64)
    families, fam_of = unique_rows(keys.reshape(-1, 4) + 1)
    families -= 1
    del keys
    plane_family = fam_of[n_events + len(seeds): n_events + len(seeds) + len(plane_ve)]
    fam_of = fam_of[:n_events]
    # (plane_ve is sorted by (v, e) and families by (VE, v, e): plane_family ascends)
    order = np.argsort(fam_of, kind="stable")
    nf = len(families)
    count = np.bincount(fam_of, minlength=nf)
    points = points_of_planes(scene, planes, vp, ep, junctions=edge_junctions(scene))
    weight = count + np.where(families[:, 0] == EEE, 8, 2)
    for rows in row_chunks(len(plane_ve), CHUNK):
        fam, first, last = coplanar_candidates(scene, plane_ve[rows], plane_of[rows], points)
        weight += np.bincount(plane_family[rows][fam], weights=last - first, minlength=nf).astype(np.int64)
    return _Families(families[:, 0], families[:, 1:], np.r_[0, np.cumsum(count)], np.concatenate(ev_s)[order],
                     np.concatenate(ev_kind)[order], np.concatenate(ev_index)[order], np.concatenate(ev_reach)[order],
                     plane_family, plane_ve, plane_of, points, weight)


#: Events (known, see :class:`_Families`) per chunk of families built at once by
#: :func:`build_arcs`: a few hundred bytes each in flight.
FAMILY_CHUNK = 1 << 18


def _family_chunks(families):
    """Consecutive ranges of families (slices) of about FAMILY_CHUNK events each."""
    return row_blocks(families.weight, FAMILY_CHUNK)


def _first_pass_of_families(scene, families, chunk):
    """The events, intervals and first pass (:func:`first_pass`) of a chunk of
    consecutive families (a slice): their nodes and planar events, domain ends and
    junctions, coplanar events. Families are the chunk's (0 its first); the mixed
    intervals' are the scene's."""
    lo, hi = chunk.start, chunk.stop
    fkind, fgens = families.kind[chunk], families.generators[chunk]
    nf = hi - lo
    ev = slice(families.event_offsets[lo], families.event_offsets[hi])
    fam_of = np.repeat(np.arange(nf), np.diff(families.event_offsets[lo: hi + 1]))
    # the ends of each family's domain, and its junctions
    dom_f, dom_s, dom_kind, dom_vertex = domain_ends(scene, fkind, fgens, edge_junctions(scene))
    # the points of their plane same-plane VE families pass
    p0, p1 = np.searchsorted(families.plane_family, [lo, hi])
    plane_ve = families.plane_ve[p0:p1]
    cop_f, cop_s, cop_kind, cop_index = coplanar_join(scene, plane_ve, families.plane_of[p0:p1], families.plane_points)
    cop_hidden = hidden_events(scene, plane_ve[cop_f], cop_s)
    cop_reach = coplanar_reach(scene, plane_ve[cop_f], cop_s, cop_kind, cop_index)
    cop_f = families.plane_family[p0:p1][cop_f] - lo
    # the points of their plane pencils of touched planes pass
    pen_f, pen_s, pen_kind, pen_index = pencil_events(scene, fkind, fgens)
    # and where a VE family's edge crosses the plane of a face at its vertex, next to the
    # events above, where the first samples cannot see it (rule 16)
    known = (np.concatenate([fam_of, dom_f, cop_f, pen_f]), np.concatenate([families.event_s[ev], dom_s, cop_s, pen_s]))
    fpc = face_plane_crossings(scene, fkind, fgens, near=known)
    pen_f, pen_s, pen_kind, pen_index = (np.r_[x, y] for x, y in zip((pen_f, pen_s, pen_kind, pen_index), fpc))
    cop_f, cop_s = np.r_[cop_f, pen_f], np.r_[cop_s, pen_s]
    cop_kind, cop_index = np.r_[cop_kind, pen_kind], np.r_[cop_index, pen_index]
    cop_hidden = np.r_[cop_hidden, np.zeros(len(pen_f), dtype=bool)]
    cop_reach = np.r_[cop_reach, np.zeros(len(pen_f))]
    fam_of = np.concatenate([fam_of, dom_f, cop_f, np.arange(nf), np.arange(nf)])
    ev_s = np.concatenate([families.event_s[ev], dom_s, cop_s, np.zeros(nf), np.ones(nf)])
    ev_kind = np.concatenate([families.event_kind[ev], dom_kind, cop_kind, np.full(2 * nf, END_ENDPOINT)])
    ev_index = np.concatenate([families.event_index[ev], dom_vertex, cop_index, np.full(2 * nf, -1)])
    ev_hidden = np.zeros(len(ev_s), dtype=bool)
    ev_hidden[len(ev_s) - 2 * nf - len(cop_s): len(ev_s) - 2 * nf] = cop_hidden
    # how far beyond the vertex a VE family's event lines are fixed (rule 14); domain ends: on the edge
    ev_reach = np.concatenate([families.event_reach[ev], np.zeros(len(dom_s)), cop_reach, np.zeros(2 * nf)])
    # events on the family's edge (within rounding of its ends)
    ev_s = np.nan_to_num(ev_s, nan=-1.0)
    inside = (ev_s >= -PARAMETER_SLACK) & (ev_s <= 1 + PARAMETER_SLACK)
    ev_s = np.clip(ev_s, 0.0, 1.0)
    intervals = family_intervals(scene, fkind, fgens, *(x[inside] for x in (fam_of, ev_s, ev_kind, ev_index, ev_hidden, ev_reach)))
    del fam_of, ev_s, ev_kind, ev_index, ev_hidden, ev_reach
    parts, mixed = first_pass(scene, fkind, fgens, *intervals)
    return parts, mixed._replace(family=mixed.family + lo)


def _arcs_of_families(scene, families, chunk, parts):
    """The arcs of the chunk of families ``chunk`` (a slice), sorted as :func:`sorted_arcs`,
    with their samples' half-cell pairs (``sides``), from its pieces: its first pass's and
    its refined ones (dicts of arrays, family ids the chunk's)."""
    arcs = arcs_of_pieces(scene, families.kind[chunk], families.generators[chunk], parts)
    edge_line_ends(scene, arcs)
    # (already sorted: the merge orders the arcs by family, then s, and families are sorted
    # by kind and generators, the order of sorted_arcs)
    return arcs
