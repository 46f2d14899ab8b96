"""Arc kinds, end codes and the V1 records (:class:`Arcs`, :class:`HalfCells`).
"""

from dataclasses import dataclass, field

import numpy as np

from viscx.cache import Cached
from viscx.skeleton.nodes import Nodes


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
END_RANK = np.array([0, 1, 2, 6, 7, 3, 4, 5])

#: Intervals judged per batch in the first pass (3 samples each), samples per batch when refining.
CHUNK = 100_000


@dataclass
class HalfCells:
    """VE half-cells (Hoberock et al. eq. 1-3), one row per VE arc.

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
class Arcs(Cached):
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
    cache : dict
        Data derived from these arcs and the scene they were built on, computed once on
        first use (:meth:`cached`), keyed by the name of the function computing it
        (``"vertex_backs"``). Not an argument: :func:`dataclasses.replace` and every
        reader give new arcs an empty cache.
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
    cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __len__(self):
        return len(self.kind)

    def counts(self):
        """Number of arcs per kind name (XE only where the scene has crossing junctions)."""
        out = {name: int(np.count_nonzero(self.kind == k)) for k, name in KIND_NAMES.items()}
        if out["XE"] == 0:
            del out["XE"]
        return out
