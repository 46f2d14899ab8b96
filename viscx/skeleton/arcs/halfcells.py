"""VE half-cells: the blocker pairs of the two V-cells on either side of each VE arc.
"""

import numpy as np

from viscx.skeleton.arcs.kinds import HalfCells, VE


def build_half_cells(scene, arcs):
    """Blocker pairs of the V-cells on both sides of each VE arc (Hoberock et al. §4.1).

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
