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
   r is unique, Hoberock et al. §4.2); VE (v, e) by the point s ∈ [0, 1] on e. Each
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
5. *VE half-cells* (Hoberock et al. §4.1): the blocker pairs of the two V-cells on
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

Modules (in dependency order): :mod:`~viscx.skeleton.generators` (generator tables,
shared with the cells), :mod:`.kinds` (kinds, end codes, records), :mod:`.lines` (family
lines, judging samples), :mod:`.pencils` (touched planes), :mod:`.xpoints` (crossing
points as pseudo-vertices), :mod:`.events` (events of each family), :mod:`.stages` (the
family-stage API: intervals, samples, refinement, merging), :mod:`.halfcells`, :mod:`.xe`
(XE arcs) and :mod:`.builder` (:func:`build_arcs`).
"""

from viscx.skeleton.generators import (  # noqa: F401
    Crossings,
    Junctions,
    canonical_eee,
    edge_crossings,
    edge_geometry,
    edge_junctions,
    skew_edges,
    vertex_edges,
)
from viscx.skeleton.arcs.kinds import (  # noqa: F401
    Arcs,
    CHUNK,
    EEE,
    END_COPLANAR,
    END_CROSSING,
    END_EDGE,
    END_ENDPOINT,
    END_JUNCTION,
    END_NAMES,
    END_NODE,
    END_PLANAR,
    END_RANK,
    END_TRANSITION,
    HalfCells,
    KIND_NAMES,
    VE,
    XE,
)
from viscx.skeleton.arcs.lines import (  # noqa: F401
    PROBE_ANGLE,
    family_lines,
    judge_samples,
    side_blockers,
    vertex_side_backs,
)
from viscx.skeleton.arcs.pencils import (  # noqa: F401
    contact_pencils,
    edges_crossing_planes,
    first_pencil_pair,
    pairs_within_groups,
    pencil_crossings,
    pencil_events,
    pencil_plane_of,
    pencil_planes,
)
from viscx.skeleton.arcs.xpoints import (  # noqa: F401
    blocked_at_crossings,
    crossing_scene,
)
from viscx.skeleton.arcs.events import (  # noqa: F401
    ANGLE_MARGIN,
    PlanePoints,
    coplanar_candidates,
    coplanar_events,
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
    vertex_planes,
)
from viscx.skeleton.arcs.stages import (  # noqa: F401
    BISECT,
    Intervals,
    REFINE,
    SAMPLES,
    SNAP,
    arcs_of_pieces,
    arcs_on_intervals,
    by_family_and_s,
    concatenate_parts,
    edge_line_ends,
    family_intervals,
    first_pass,
    refine_intervals,
    sorted_arcs,
)
from viscx.skeleton.arcs.halfcells import (  # noqa: F401
    build_half_cells,
)
from viscx.skeleton.arcs.xe import (  # noqa: F401
    crossing_arcs,
)
from viscx.skeleton.arcs.builder import (  # noqa: F401
    FAMILY_CHUNK,
    build_arcs,
)
