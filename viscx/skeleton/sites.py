"""Epsilon-merging of nodes: one *site* per maximal free segment, whatever its generators.

In degenerate scenes one segment can satisfy several node descriptions (a T-junction: a
vertex lying on another object's edge makes a VEE node (v, e1, e2) and an E4 node through
that edge describe one segment). Under epsilon-visibility two nodes whose maximal free
segments have both ends within epsilon of each other are one node of the complex: each
keeps its descriptions (the families of V1 run through it by each of them), and they
share a site id, the smallest node id of their group (single linkage: chains of nodes
each within epsilon of the next are one site).
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


def node_sites(nodes, epsilon):
    """The site of each node: the smallest id among the nodes whose segment coincides with
    its own within ``epsilon`` (both ends, the segments oriented alike), transitively.

    Parameters
    ----------
    nodes : viscx.skeleton.nodes.Nodes
        Directions oriented canonically, so equal segments have equal (P, Q).
    epsilon : float

    Returns
    -------
    (n,) int64
        ``site[i] == i`` for the first node of each site.
    """
    n = len(nodes)
    if n == 0:
        return np.zeros(0, np.int64)
    ends = np.asarray(nodes.ends, dtype=np.float64).reshape(n, 6)
    # a segment to the sky ends at a far stand-in point: both still compare as points
    finite = np.all(np.isfinite(ends), axis=1)
    idx = np.flatnonzero(finite)
    pairs = cKDTree(ends[idx]).query_pairs(np.sqrt(2.0) * epsilon, output_type="ndarray")
    if len(pairs):
        a, b = idx[pairs[:, 0]], idx[pairs[:, 1]]
        gap = np.linalg.norm(nodes.ends[a] - nodes.ends[b], axis=2).max(axis=1)
        keep = gap <= epsilon
        a, b = a[keep], b[keep]
    else:
        a = b = np.zeros(0, np.int64)
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, n, np.int64)
    np.minimum.at(first, label, np.arange(n))
    return first[label]
