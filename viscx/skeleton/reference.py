"""The O(n⁴) reference enumeration of nodes, for small scenes (the ground truth).

Every combination of generators is a candidate: all pairs of generator vertices
not joined by an edge (VV), every generator vertex with every pair of generator edges not incident to
it (VEE), every quadruple of pairwise non-adjacent generator edges (E4, 0–2
lines each). :func:`viscx.skeleton.nodes.validate_candidates` keeps the nodes.
Fast builders must produce exactly the same node set.
"""

from itertools import combinations

import numpy as np

from viscx.geometry.lines import line_through_point_and_two_lines, lines_through_four_lines, plucker
from viscx.skeleton.nodes import E4, VEE, VV, validate_candidates


def edge_lines(scene, edges):
    """Plücker lines of edges (direction = end - start)."""
    ev = scene.half_edges.edge_vertices[edges]
    a, b = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
    return plucker(a, b - a)


def reference_candidates(scene):
    """All candidate lines of the reference enumeration.

    Returns
    -------
    kind : (m,) int8
    generators : (m, 4) int
    origins, directions : (m, 3) float
    """
    gv = scene.generator_vertices
    ge = scene.generator_edges
    ev = scene.half_edges.edge_vertices
    out = []

    # VV: every pair of generator vertices not joined by an edge (that line holds the edge)
    if len(gv) >= 2:
        i, j = np.triu_indices(len(gv), 1)
        u, v = gv[i], gv[j]
        nv = scene.n_vertices
        joined = np.isin(u * nv + v, ev[:, 0] * nv + ev[:, 1])
        u, v = u[~joined], v[~joined]
        gens = np.stack([u, v, np.full_like(u, -1), np.full_like(u, -1)], axis=1)
        out.append((np.full(len(u), VV), gens, scene.vertices[u], scene.vertices[v] - scene.vertices[u]))

    # VEE: a vertex and two edges, neither incident to it
    if len(ge) >= 2 and len(gv):
        i, j = np.triu_indices(len(ge), 1)
        e1, e2 = ge[i], ge[j]
        v = np.repeat(gv, len(e1))
        e1, e2 = np.tile(e1, len(gv)), np.tile(e2, len(gv))
        incident = (ev[e1] == v[:, None]).any(1) | (ev[e2] == v[:, None]).any(1)
        v, e1, e2 = v[~incident], e1[~incident], e2[~incident]
        d = line_through_point_and_two_lines(scene.vertices[v], edge_lines(scene, e1), edge_lines(scene, e2))
        fine = np.linalg.norm(d, axis=1) > 0
        gens = np.stack([v, e1, e2, np.full_like(v, -1)], axis=1)[fine]
        out.append((np.full(fine.sum(), VEE), gens, scene.vertices[v[fine]], d[fine]))

    # E4: four pairwise non-adjacent edges
    if len(ge) >= 4:
        quads = np.array(list(combinations(range(len(ge)), 4)), dtype=np.int64).reshape(-1, 4)
        quads = ge[quads]
        share = np.zeros(len(quads), dtype=bool)
        for p, q in combinations(range(4), 2):
            a, b = ev[quads[:, p]], ev[quads[:, q]]
            share |= (a[:, :1] == b).any(1) | (a[:, 1:] == b).any(1)
        quads = quads[~share]
        lines = edge_lines(scene, quads.reshape(-1)).reshape(-1, 4, 6)
        sol, valid, _ = lines_through_four_lines(lines)
        q_idx, s_idx = np.nonzero(valid)
        d, m = sol[q_idx, s_idx, :3], sol[q_idx, s_idx, 3:]
        origins = np.cross(d, m) / np.einsum("ij,ij->i", d, d)[:, None]
        out.append((np.full(len(q_idx), E4), quads[q_idx], origins, d))

    if not out:
        return np.zeros(0, np.int8), np.zeros((0, 4), np.int64), np.zeros((0, 3)), np.zeros((0, 3))
    kind, gens, origins, dirs = (np.concatenate(x) for x in zip(*out))
    return kind.astype(np.int8), gens.astype(np.int64), origins, dirs


def reference_nodes(scene):
    """All nodes of a small scene by exhaustive enumeration."""
    return validate_candidates(scene, *reference_candidates(scene))
