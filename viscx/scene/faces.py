"""Polygon faces from triangles: coplanar merging and boundary loops.

A flat diagonal is never a visual event, so adjacent coplanar triangles of one
group become one polygon face. A face is a connected planar region: one outer
loop (counter-clockwise seen from the face normal) and any number of holes
(clockwise). Vertices that lie straight on a boundary between exactly two
neighbours (a T-free collinear vertex) are dropped from the loops: they are no
more an event than a flat diagonal is.
"""

import numpy as np
from numba import njit

from viscx.arrays import unique_rows, walk_cycle
from viscx.errors import ViscxError
from viscx.geometry.polygon import plane_basis
from viscx.scene.clean import triangle_normals


def _triangle_edges(triangles):
    """Directed edges of triangles: edge ``3 i + k`` runs from corner k to corner k+1 of triangle i."""
    a = triangles.reshape(-1)
    b = np.roll(triangles, -1, axis=1).reshape(-1)
    return a, b


def _undirected_ids(a, b, n_vertices):
    """Ids of the undirected edges {a, b}, sorted by (min, max); and their counts."""
    key = np.minimum(a, b) * n_vertices + np.maximum(a, b)
    _, edge, count = np.unique(key, return_inverse=True, return_counts=True)
    return edge.reshape(-1), count


def merge_coplanar(vertices, triangles, triangle_group, tolerance):
    """Group adjacent coplanar triangles of one group into faces.

    Two triangles join when they share an edge that no other triangle uses, are
    wound consistently across it, face the same way, and each one's far vertex
    lies within ``tolerance`` of the other's plane. A joined component is kept
    only if all its vertices lie within ``tolerance`` of its area-weighted plane
    (slowly curving surfaces would otherwise chain into one "face"); otherwise
    its triangles stay separate faces.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int
    triangle_group : (t,) int
    tolerance : float

    Returns
    -------
    triangle_face : (t,) int
        Face id of every triangle; faces are numbered by their first triangle.
    face_normal : (f, 3) float
        Unit normal of each face's plane.
    face_offset : (f,) float
        Plane offset: the plane is ``face_normal · x = face_offset``.
    face_area : (f,) float
    """
    t = len(triangles)
    # planes in coordinates relative to the scene's centre: offsets of far-away
    # scenes would otherwise swallow the tolerance in rounding
    center = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0)) if len(vertices) else np.zeros(3)
    vertices = vertices - center
    normals, areas = triangle_normals(vertices, triangles)
    a, b = _triangle_edges(triangles)
    edge, count = _undirected_ids(a, b, len(vertices))
    order = np.argsort(edge, kind="stable")
    first = np.searchsorted(edge[order], np.arange(len(count)))
    pair_edges = np.flatnonzero(count == 2)
    i1, i2 = order[first[pair_edges]], order[first[pair_edges] + 1]
    t1, t2 = i1 // 3, i2 // 3
    apex1 = triangles[t1, (i1 % 3 + 2) % 3]
    apex2 = triangles[t2, (i2 % 3 + 2) % 3]
    dist12 = np.abs(np.einsum("ij,ij->i", normals[t1], vertices[apex2] - vertices[triangles[t1, 0]]))
    dist21 = np.abs(np.einsum("ij,ij->i", normals[t2], vertices[apex1] - vertices[triangles[t2, 0]]))
    join = (
        (a[i1] == b[i2])  # consistent winding: the shared edge runs both ways
        & (triangle_group[t1] == triangle_group[t2])
        & (np.einsum("ij,ij->i", normals[t1], normals[t2]) > 0)
        & (dist12 <= tolerance)
        & (dist21 <= tolerance)
    )
    from scipy.sparse import coo_matrix  # here: a built file's loading never needs scipy (clean.weld)
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(join.sum()), (t1[join], t2[join])), shape=(t, t))
    _, label = connected_components(graph, directed=False)

    def planes(label):
        k = label.max() + 1 if t else 0
        weighted = np.zeros((k, 3))
        np.add.at(weighted, label, normals * areas[:, None])
        length = np.linalg.norm(weighted, axis=1)
        normal = weighted / np.where(length > 0, length, 1.0)[:, None]
        centroid = vertices[triangles].mean(axis=1)
        area = np.bincount(label, weights=areas, minlength=k)
        offset = np.bincount(label, weights=areas * np.einsum("ij,ij->i", centroid, normal[label]), minlength=k)
        offset /= np.where(area > 0, area, 1.0)
        return normal, offset, area

    normal, offset, _ = planes(label)
    # validate each component's planarity; split the ones that drift
    dist = np.abs(np.einsum("tkj,tj->tk", vertices[triangles], normal[label]) - offset[label][:, None]).max(axis=1)
    worst = np.zeros(label.max() + 1 if t else 0)
    np.maximum.at(worst, label, dist)
    bad = worst[label] > tolerance
    if bad.any():
        label = label.copy()
        label[bad] = label.max() + 1 + np.arange(bad.sum())
    # number faces by their first triangle
    first_tri = np.full(label.max() + 1 if t else 0, t, dtype=np.int64)
    np.minimum.at(first_tri, label, np.arange(t))
    used = np.unique(label)
    rank = np.empty(label.max() + 1 if t else 0, dtype=np.int64)
    rank[used[np.argsort(first_tri[used], kind="stable")]] = np.arange(len(used))
    triangle_face = rank[label]
    face_normal, face_offset, face_area = planes(triangle_face)
    face_offset = face_offset + face_normal @ center
    return triangle_face, face_normal, face_offset, face_area


@njit(cache=True)
def _cycles(successor):
    """Decompose a permutation into cycles, each started at its smallest element.

    Returns the elements in cycle order and the CSR offsets of the cycles.
    """
    n = successor.shape[0]
    seen = np.zeros(n, dtype=np.bool_)
    order = np.empty(n, dtype=np.int64)
    offsets = np.zeros(n + 1, dtype=np.int64)
    k = 0
    c = 0
    for s in range(n):
        if seen[s]:
            continue
        k = walk_cycle(successor, s, seen, order, k)
        c += 1
        offsets[c] = k
    return order, offsets[: c + 1]


def _resolve_pinches(vertices, face_normal, bh_face, bh_a, bh_b, ambiguous, cand_lo, cand_hi, sorted_ids):
    """Successors at pinch vertices, where a face's boundary visits a vertex twice.

    Walking a boundary with the face on the left, the loop continues along the
    first outgoing boundary edge met when turning clockwise from the edge we came
    along: that edge bounds the same wedge of the face.
    """
    successor = np.empty(len(ambiguous), dtype=np.int64)
    for k, h in enumerate(ambiguous):
        u, v = plane_basis(face_normal[bh_face[h]])
        pivot = vertices[bh_b[h]]
        back = vertices[bh_a[h]] - pivot
        best, best_angle = -1, np.inf
        for c in sorted_ids[cand_lo[h] : cand_hi[h]]:
            out = vertices[bh_b[c]] - pivot
            ccw = np.arctan2(back @ u * (out @ v) - back @ v * (out @ u), back @ u * (out @ u) + back @ v * (out @ v))
            clockwise = (-ccw) % (2 * np.pi)
            if 0 < clockwise < best_angle:
                best, best_angle = c, clockwise
        successor[k] = best
    return successor


def face_loops(vertices, triangles, triangle_face, face_normal):
    """Boundary loops of every face.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int
    triangle_face : (t,) int
    face_normal : (f, 3) float

    Returns
    -------
    face_loop_offsets : (f + 1,) int
        Loops of face i are ``face_loop_offsets[i]:face_loop_offsets[i + 1]``; the
        first is the outer loop, holes follow ordered by their smallest vertex.
    loop_offsets : (l + 1,) int
        Vertices of loop j are ``loop_vertices[loop_offsets[j]:loop_offsets[j + 1]]``.
    loop_vertices : (m,) int
        Each loop starts at its smallest vertex id; outer loops run
        counter-clockwise seen from the face normal, holes clockwise.
    """
    nv, nf = len(vertices), len(face_normal)
    a, b = _triangle_edges(triangles)
    tri_face = np.repeat(triangle_face, 3)
    edge, _ = _undirected_ids(a, b, nv)
    # a triangle edge is on its face's boundary when no other triangle of the face has it
    _, inverse, per_face = np.unique(tri_face * (edge.max() + 1) + edge, return_inverse=True, return_counts=True)
    boundary = np.flatnonzero(per_face[inverse.reshape(-1)] == 1)
    boundary = boundary[np.lexsort((boundary, tri_face[boundary]))]
    bh_face, bh_a, bh_b = tri_face[boundary], a[boundary], b[boundary]

    # successor: the boundary edge of the same face that starts where this one ends
    start_key = bh_face * nv + bh_a
    sorted_ids = np.argsort(start_key, kind="stable")
    sorted_keys = start_key[sorted_ids]
    end_key = bh_face * nv + bh_b
    lo = np.searchsorted(sorted_keys, end_key, "left")
    hi = np.searchsorted(sorted_keys, end_key, "right")
    if np.any(hi == lo):
        raise ViscxError("a face's boundary could not be traced (overlapping or inconsistently wound triangles)")
    successor = sorted_ids[np.minimum(lo, len(sorted_ids) - 1)]
    ambiguous = np.flatnonzero(hi - lo > 1)
    if len(ambiguous):
        successor[ambiguous] = _resolve_pinches(
            vertices, face_normal, bh_face, bh_a, bh_b, ambiguous, lo, hi, sorted_ids
        )
    order, offsets = _cycles(successor)
    n_loops = len(offsets) - 1
    length = np.diff(offsets)
    loop_of = np.repeat(np.arange(n_loops), length)
    verts = bh_a[order]
    loop_face = bh_face[order[offsets[:-1]]]

    # orientation: Newell area vector of each loop against its face normal
    nxt = np.where(np.arange(len(verts)) + 1 == offsets[1:][loop_of], offsets[:-1][loop_of], np.arange(len(verts)) + 1)
    newell = np.add.reduceat(np.cross(vertices[verts], vertices[verts[nxt]]), offsets[:-1], axis=0)
    hole = np.einsum("ij,ij->i", newell, face_normal[loop_face]) <= 0

    # canonical form: each loop starts at its smallest vertex id (first occurrence)
    by_vertex = np.lexsort((np.arange(len(verts)), verts, loop_of))
    first_min = by_vertex[offsets[:-1]]  # position of the smallest vertex of each loop
    shift = first_min - offsets[:-1]
    # loops ordered by face, outer before holes, then smallest vertex
    rank = np.lexsort((verts[first_min], hole, loop_face))
    new_length = length[rank]
    new_offsets = np.concatenate([[0], np.cumsum(new_length)]).astype(np.int64)
    k = np.arange(new_offsets[-1]) - np.repeat(new_offsets[:-1], new_length)
    src = offsets[:-1][rank]
    loop_vertices = verts[np.repeat(src, new_length) + (np.repeat(shift[rank], new_length) + k) % np.repeat(new_length, new_length)]
    face_loop_offsets = np.searchsorted(loop_face[rank], np.arange(nf + 1)).astype(np.int64)
    return face_loop_offsets, new_offsets, loop_vertices.astype(np.int64)


def drop_collinear_vertices(vertices, loop_offsets, loop_vertices, tolerance):
    """Remove loop vertices that lie straight between their only two neighbours.

    A vertex whose boundary edges (over all faces) go to exactly two other
    vertices is a *chain* vertex: every loop through it runs along the same chain
    of such vertices between two kept vertices A and B. A chain is replaced by
    the chord AB when every vertex of it lies within ``tolerance`` of AB;
    otherwise the farthest vertex is kept and both halves are tried again
    (Douglas–Peucker). Decisions are per vertex, so all loops agree; a loop that
    would fall below three vertices keeps all of its vertices, everywhere.

    Parameters
    ----------
    vertices : (n, 3) float
    loop_offsets : (l + 1,) int
    loop_vertices : (m,) int
    tolerance : float

    Returns
    -------
    loop_offsets : (l + 1,) int
    loop_vertices : (m',) int
    """
    nv = len(vertices)
    n_loops = len(loop_offsets) - 1
    loop_id = np.repeat(np.arange(n_loops), np.diff(loop_offsets))
    pos = np.arange(len(loop_vertices))
    nxt = np.where(pos + 1 == loop_offsets[loop_id + 1], loop_offsets[loop_id], pos + 1)
    a, b = loop_vertices, loop_vertices[nxt]
    pairs = unique_rows(np.concatenate([np.stack([a, b], 1), np.stack([b, a], 1)]))[0]
    degree = np.bincount(pairs[:, 0], minlength=nv)
    if not np.any(degree == 2):
        return loop_offsets, loop_vertices
    first = np.searchsorted(pairs[:, 0], np.arange(nv))
    neighbours = np.full((nv, 2), -1, dtype=np.int64)
    two = np.flatnonzero(degree == 2)
    neighbours[two] = np.stack([pairs[first[two], 1], pairs[first[two] + 1, 1]], axis=1)
    protected = np.zeros(nv, dtype=bool)
    while True:
        removed = _chain_vertices_to_drop(vertices, neighbours, degree == 2, protected, tolerance)
        keep = ~removed[loop_vertices]
        kept_per_loop = np.bincount(loop_id, weights=keep, minlength=n_loops).astype(np.int64)
        small = np.flatnonzero(kept_per_loop < 3)
        newly = np.unique(loop_vertices[np.isin(loop_id, small)])
        newly = newly[~protected[newly] & removed[newly]]
        if len(newly) == 0:
            break
        protected[newly] = True
    return np.concatenate([[0], np.cumsum(kept_per_loop)]).astype(np.int64), loop_vertices[keep]


def _chain_vertices_to_drop(vertices, neighbours, chain, protected, tolerance):
    """Walk every chain of degree-2 vertices and simplify it against its chord."""
    drop = np.zeros(len(vertices), dtype=bool)
    seen = np.zeros(len(vertices), dtype=bool)
    candidates = chain & ~protected
    for start in np.flatnonzero(candidates):
        if seen[start]:
            continue
        # walk both ways to the kept ends
        path = [start]
        seen[start] = True
        ends = []
        for direction in (0, 1):
            prev, cur = start, neighbours[start, direction]
            side = []
            while candidates[cur] and not seen[cur]:
                seen[cur] = True
                side.append(cur)
                n0, n1 = neighbours[cur]
                prev, cur = cur, (n1 if n0 == prev else n0)
            ends.append(cur)
            path = side[::-1] + path if direction == 0 else path + side
        if ends[0] == ends[1] and candidates[ends[0]]:
            continue  # a closed ring of chain vertices: keep it (nothing anchors a chord)
        chord = [ends[0], *path, ends[1]]
        _douglas_peucker(vertices, chord, 0, len(chord) - 1, tolerance, drop)
    return drop


def _douglas_peucker(vertices, chord, i, j, tolerance, drop):
    if j - i < 2:
        return
    a, b = vertices[chord[i]], vertices[chord[j]]
    inner = vertices[chord[i + 1 : j]]
    ab = b - a
    length2 = float(ab @ ab)
    s = np.clip((inner - a) @ ab / length2, 0.0, 1.0) if length2 > 0 else np.zeros(len(inner))
    dist = np.linalg.norm(inner - a - s[:, None] * ab, axis=1)
    k = int(np.argmax(dist))
    if dist[k] <= tolerance:
        drop[np.asarray(chord[i + 1 : j])] = True
        return
    _douglas_peucker(vertices, chord, i, i + 1 + k, tolerance, drop)
    _douglas_peucker(vertices, chord, i + 1 + k, j, tolerance, drop)
