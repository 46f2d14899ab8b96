"""The half-edge structure of a polygonal scene, and its generators.

Half-edge ``h`` of face ``f`` runs from ``start[h]`` to ``end[h]`` with ``f`` on
its left (seen from the face normal). ``next[h]`` follows it around its loop.
``opp[h]`` is the other half-edge of the same undirected edge when exactly two
faces share that edge, else -1 (a boundary edge has one face, a non-manifold
edge three or more; ``edge[h]`` groups them all). Faces are two-sided.

Generators (design decisions, Vocabulary: docs/references.md): an edge is a *generator edge* unless it is shared
by exactly two faces that are coplanar and lie on opposite sides of it (a flat
edge, never a visual event); boundary and non-manifold edges always are.
Coplanar means what merging means (:func:`viscx.scene.faces.merge_coplanar`):
every vertex of each face within the tolerance of the other's plane.
*Generator vertices* are the endpoints of generator edges.
"""

from dataclasses import dataclass

import numpy as np



@dataclass
class HalfEdges:
    """Flat arrays of the half-edge structure (see module docstring).

    Attributes
    ----------
    start, end, face, next, opp, edge, loop : (h,) int
    edge_vertices : (e, 2) int
        Undirected edges as (smaller, larger) vertex id, sorted.
    edge_is_generator : (e,) bool
    vertex_is_generator : (n,) bool
    """

    start: np.ndarray
    end: np.ndarray
    face: np.ndarray
    next: np.ndarray
    opp: np.ndarray
    edge: np.ndarray
    loop: np.ndarray
    edge_vertices: np.ndarray
    edge_is_generator: np.ndarray
    vertex_is_generator: np.ndarray


def build_half_edges(vertices, face_normal, face_loop_offsets, loop_offsets, loop_vertices, tolerance):
    """Half-edges of polygon faces given as loops.

    Parameters
    ----------
    vertices : (n, 3) float
    face_normal : (f, 3) float
    face_loop_offsets : (f + 1,) int
    loop_offsets : (l + 1,) int
    loop_vertices : (m,) int
    tolerance : float
        Coplanarity tolerance (the weld tolerance).

    Returns
    -------
    HalfEdges
        Half-edge ``h`` is the edge leaving ``loop_vertices[h]``.
    """
    nv = len(vertices)
    n_loops = len(loop_offsets) - 1
    loop = np.repeat(np.arange(n_loops), np.diff(loop_offsets))
    face = np.repeat(np.arange(len(face_loop_offsets) - 1), np.diff(face_loop_offsets))[loop]
    pos = np.arange(len(loop_vertices))
    nxt = np.where(pos + 1 == loop_offsets[loop + 1], loop_offsets[loop], pos + 1)
    start, end = loop_vertices, loop_vertices[nxt]

    key = np.minimum(start, end) * nv + np.maximum(start, end)
    uniq, edge, count = np.unique(key, return_inverse=True, return_counts=True)
    edge = edge.reshape(-1)
    edge_vertices = np.stack([uniq // nv, uniq % nv], axis=1).astype(np.int64)

    order = np.argsort(edge, kind="stable")
    first = np.searchsorted(edge[order], np.arange(len(uniq)))
    opp = np.full(len(start), -1, dtype=np.int64)
    two = np.flatnonzero(count == 2)
    h1, h2 = order[first[two]], order[first[two] + 1]
    opp[h1], opp[h2] = h2, h1

    # in-plane direction from the edge into each face: n × (end - start)
    inward = np.cross(face_normal[face], vertices[end] - vertices[start])
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    opposite = np.einsum("ij,ij->i", inward[h1], inward[h2]) < 0
    flat = opposite & _coplanar(vertices, face_normal, face, face_loop_offsets, loop_offsets, loop_vertices, h1, h2, start, tolerance)
    edge_is_generator = np.ones(len(uniq), dtype=bool)
    edge_is_generator[two[flat]] = False
    vertex_is_generator = np.zeros(nv, dtype=bool)
    vertex_is_generator[edge_vertices[edge_is_generator].reshape(-1)] = True
    return HalfEdges(
        start=start.astype(np.int64),
        end=end.astype(np.int64),
        face=face.astype(np.int64),
        next=nxt.astype(np.int64),
        opp=opp,
        edge=edge.astype(np.int64),
        loop=loop.astype(np.int64),
        edge_vertices=edge_vertices,
        edge_is_generator=edge_is_generator,
        vertex_is_generator=vertex_is_generator,
    )


def _coplanar(vertices, face_normal, face, face_loop_offsets, loop_offsets, loop_vertices, h1, h2, start, tolerance):
    """Whether the faces of half-edge pairs (h1, h2) are coplanar within ``tolerance``:
    every vertex of each face lies that close to the other's plane through the
    shared edge (measured from the edge's start, so far-away scenes lose nothing)."""
    ok = np.ones(len(h1), dtype=bool)
    vertex_start = loop_offsets[face_loop_offsets[:-1]]
    vertex_end = loop_offsets[face_loop_offsets[1:]]
    for this, other in ((h1, h2), (h2, h1)):
        f_other = face[other]
        counts = vertex_end[f_other] - vertex_start[f_other]
        owner = np.repeat(np.arange(len(this)), counts)
        at = np.repeat(vertex_start[f_other], counts) + np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        points = vertices[loop_vertices[at]] - vertices[start[this]][owner]
        dist = np.abs(np.einsum("ij,ij->i", points, face_normal[face[this]][owner]))
        worst = np.zeros(len(this))
        np.maximum.at(worst, owner, dist)
        ok &= worst <= tolerance
    return ok
