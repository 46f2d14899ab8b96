"""XE arcs (degenerate scenes): lines through the crossing point X of two generator edges
meeting a third edge, built as VE families of X.
"""

import numpy as np

from viscx.skeleton.arcs.events import domain_ends, event_parameters
from viscx.skeleton.arcs.kinds import END_ENDPOINT, END_TRANSITION, VE, XE
from viscx.skeleton.arcs.stages import arcs_on_intervals, family_intervals, sorted_arcs
from viscx.skeleton.arcs.xpoints import blocked_at_crossings, crossing_scene
from viscx.skeleton.generators import edge_crossings, edge_junctions, skew_edges
from viscx.skeleton.point_nodes import point_node_incidences, point_nodes
from viscx.tolerances import PARAMETER_SLACK


def crossing_arcs(scene, workers=None, scope=None):
    """The XE arcs: for each X-junction (generator edges a < b crossing at X) and each
    generator edge e skew to a or b, the lines through X meeting e (a VE family whose
    vertex is the junction point), cut at events and sampled by the VE stages.

    Events: e's endpoints and junctions (as every VE family's), and the lines through X
    and a generator vertex (VV) or meeting two more generator edges (VEE), validated as
    nodes on :func:`crossing_scene`. V0 drops those (X is a point of two of their
    generators); an arc ending there has end type END_TRANSITION, end_node -1.

    With a ``scope`` (:class:`viscx.skeleton.scope.Scope`), only the families with a, e or
    b in it (each family's arcs are decided within it).

    Returns
    -------
    dict of arrays or None
        Rows as :func:`sorted_arcs` (kind XE, generators (a, e, b)), no ``sides``; None
        without X-junctions.
    """

    cr = edge_crossings(scene)
    if len(cr) == 0:
        return None
    xs, first = crossing_scene(scene)
    ids = first + np.arange(len(cr))
    ge = scene.generator_edges
    j, e = np.repeat(np.arange(len(cr)), len(ge)), np.tile(ge, len(cr))
    a, b = cr.edges[j, 0], cr.edges[j, 1]
    keep = (e != a) & (e != b)
    keep[keep] = skew_edges(scene, e[keep], a[keep]) | skew_edges(scene, e[keep], b[keep])
    if scope is not None:
        keep &= scope.families(np.full(len(e), XE), np.stack([a, e, b], axis=1))
    families = np.stack([ids[j[keep]], e[keep], np.full(np.count_nonzero(keep), -1)], axis=1)  # sorted by (X, e)
    fkind = np.full(len(families), VE)
    nf = len(families)
    nodes = point_nodes(xs, ids)
    # the families each node lies on, as a free point's
    inc, rows = point_node_incidences(xs, nodes)
    n_edges = len(scene.half_edges.edge_vertices)
    key = families[:, 0] * n_edges + families[:, 1]
    pos = np.minimum(np.searchsorted(key, inc[:, 0] * n_edges + inc[:, 1]), max(nf - 1, 0))
    on = key[pos] == inc[:, 0] * n_edges + inc[:, 1]
    fam_of, rows = pos[on], rows[on]
    ev_s = event_parameters(xs, fkind[fam_of], families[fam_of], nodes, rows)
    dom_f, dom_s, dom_kind, dom_vertex = domain_ends(xs, fkind, families, edge_junctions(scene))
    fam_of = np.concatenate([fam_of, dom_f, np.arange(nf), np.arange(nf)])
    ev_s = np.concatenate([ev_s, dom_s, np.zeros(nf), np.ones(nf)])
    ev_kind = np.concatenate([np.full(len(rows), END_TRANSITION), dom_kind, np.full(2 * nf, END_ENDPOINT)])
    ev_index = np.concatenate([np.full(len(rows), -1), dom_vertex, np.full(2 * nf, -1)])
    ev_s = np.nan_to_num(ev_s, nan=-1.0)
    inside = (ev_s >= -PARAMETER_SLACK) & (ev_s <= 1 + PARAMETER_SLACK)
    ev_s = np.clip(ev_s, 0.0, 1.0)
    intervals = family_intervals(xs, fkind, families, fam_of[inside], ev_s[inside], ev_kind[inside], ev_index[inside])
    built = arcs_on_intervals(xs, fkind, families, *intervals, workers=workers)
    del built["sides"]  # X's own sphere: no V-cells
    row = built["generators"][:, 0] - first
    kinds, ids = built["blocker_kind"].astype(np.int64), built["blocker"]
    blocked_at_crossings(kinds, ids, row, np.ones(len(row), bool), cr)
    built["blocker_kind"], built["blocker"] = kinds.astype(np.int8), ids
    built["kind"] = np.full(len(row), XE, np.int8)
    built["generators"] = np.stack([cr.edges[row, 0], built["generators"][:, 1], cr.edges[row, 1]], axis=1)
    built["generator_points"][:, 2] = built["generator_points"][:, 0]
    return sorted_arcs(built)
