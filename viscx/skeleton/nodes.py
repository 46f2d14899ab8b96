"""V0: the nodes (0-cells) of the visibility complex: E4, VEE and VV.

A node is a maximal free segment fixed by four conditions on generators
(docs/skeleton.md). Whatever proposes the candidate lines (the O(n⁴) reference
in :mod:`viscx.skeleton.reference`, or the output-sensitive builder), this module
decides which candidates are nodes and builds their segments, so every builder
shares one definition.
"""

from dataclasses import dataclass

import numpy as np

from viscx.geometry.lines import segment_parameter
from viscx.geometry.tangency import tangent_at_vertices, tangent_in_wedges
from viscx.scene.neighbourhood import generator_wedges

# Node kinds.
E4, VEE, VV = 0, 1, 2
KIND_NAMES = {E4: "E4", VEE: "VEE", VV: "VV"}
# Which generator slots hold vertices, per kind (the rest hold edges).
SLOT_IS_VERTEX = np.array([[False] * 4, [True, False, False, False], [True, True, False, False]])
SLOT_COUNT = np.array([4, 3, 2])

# Blocker kinds of a segment end.
BLOCK_FACE, BLOCK_SKY, BLOCK_EDGE, BLOCK_VERTEX = 0, 1, 2, 3


@dataclass
class Nodes:
    """Nodes as flat arrays, sorted by (kind, generators, direction).

    Attributes
    ----------
    kind : (n,) int8
        E4, VEE or VV.
    generators : (n, 4) int
        VV: (u, v, -1, -1) with u < v; VEE: (v, e1, e2, -1) with e1 < e2;
        E4: four edges, increasing. Vertex and edge ids of the scene.
    direction : (n, 3) float
        Unit direction of the line, oriented canonically.
    ends : (n, 2, 3) float
        Back end P and front end Q of the maximal free segment (P + t d, t ↑).
    blocker_kind : (n, 2) int8
        BLOCK_FACE, BLOCK_SKY, BLOCK_EDGE or BLOCK_VERTEX for P and Q.
    blocker : (n, 2) int
        Face, edge or vertex id (-1 for the sky).
    generator_points : (n, 4, 3) float
        Where the segment meets each generator (nan for unused slots).
    """

    kind: np.ndarray
    generators: np.ndarray
    direction: np.ndarray
    ends: np.ndarray
    blocker_kind: np.ndarray
    blocker: np.ndarray
    generator_points: np.ndarray

    def __len__(self):
        return len(self.kind)

    def counts(self):
        """Number of nodes per kind name."""
        return {name: int(np.count_nonzero(self.kind == k)) for k, name in KIND_NAMES.items()}


def canonical_directions(directions):
    """Unit directions, flipped so that d · (1, 1e-3, 1e-6) > 0 (a fixed orientation)."""
    d = np.asarray(directions, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    flip = d @ np.array([1.0, 1e-3, 1e-6]) < 0
    d[flip] *= -1
    return d


def validate_candidates(scene, kind, generators, origins, directions):
    """Keep the candidate lines that are nodes and build their segments.

    Parameters
    ----------
    scene : Scene
    kind : (m,) int
    generators : (m, 4) int
        Canonical generator tuples (see :class:`Nodes`).
    origins : (m, 3) float
        A point of each candidate line.
    directions : (m, 3) float

    Returns
    -------
    Nodes
    """
    kind = np.asarray(kind, dtype=np.int8)
    if len(kind) == 0:
        return _empty()
    seg = maximal_free_segments(scene, SLOT_IS_VERTEX[kind], SLOT_COUNT[kind], generators, origins, directions)
    nodes = np.flatnonzero(seg.valid)
    result = Nodes(
        kind=kind[nodes],
        generators=np.asarray(generators, dtype=np.int64)[nodes],
        direction=seg.direction[nodes],
        ends=seg.ends[nodes],
        blocker_kind=seg.blocker_kind[nodes],
        blocker=seg.blocker[nodes],
        generator_points=seg.generator_points[nodes],
    )
    return sort_nodes(result)


@dataclass
class LineSegments:
    """The maximal free segment of each line through k generators (or why there is none).

    Attributes
    ----------
    valid : (m,) bool
        The line meets its generators as the node definition demands
        (docs/skeleton.md, conditions 1-5 with k generators).
    direction : (m, 3) float
        Unit direction, oriented canonically (:func:`canonical_directions`).
    ends : (m, 2, 3) float
        Back end P and front end Q (NaN where not valid).
    blocker_kind, blocker : (m, 2) int8, int
        As in :class:`Nodes` (-1 where not valid).
    generator_points : (m, 4, 3) float
        Where the line meets each generator slot (NaN for unused slots).
    tangent : (m, 4) bool
        Whether the line passes at each generator slot (False for unused slots).
    """

    valid: np.ndarray
    direction: np.ndarray
    ends: np.ndarray
    blocker_kind: np.ndarray
    blocker: np.ndarray
    generator_points: np.ndarray
    tangent: np.ndarray


def maximal_free_segments(scene, slot_is_vertex, slot_count, generators, origins, directions):
    """The one definition of "a maximal free segment through these generators".

    Nodes use it with four conditions (k = 4, 3, 2 generator points), arcs
    (:mod:`viscx.skeleton.arcs`) with three (EEE: three edges, VE: a vertex and
    an edge), so that an arc's end and the node there are judged alike.

    Parameters
    ----------
    scene : Scene
    slot_is_vertex : (m, 4) bool
        Which generator slots hold vertices (the others hold edges).
    slot_count : (m,) int
        Number of used slots (the first ``slot_count`` slots).
    generators : (m, 4) int
        Vertex or edge id per slot.
    origins, directions : (m, 3) float
        A point and a direction of each line.

    Returns
    -------
    LineSegments
    """
    eps = scene.epsilon
    slot_is_vertex = np.asarray(slot_is_vertex, dtype=bool)
    count = np.asarray(slot_count, dtype=np.int64)
    generators = np.asarray(generators, dtype=np.int64)
    d = canonical_directions(directions)
    o = np.asarray(origins, dtype=np.float64)
    m = len(count)

    # one row per (candidate, generator slot)
    used = np.arange(4)[None, :] < count[:, None]
    cand, slot = np.nonzero(used)
    gid = generators[cand, slot]
    is_vertex = slot_is_vertex[cand, slot]
    oc, dc = o[cand], d[cand]
    point = np.empty((len(cand), 3))
    ok = np.ones(len(cand), dtype=bool)
    tangent = np.zeros(len(cand), dtype=bool)
    degenerate = np.zeros(len(cand), dtype=bool)

    iv = np.flatnonzero(is_vertex)
    x_v = scene.vertices[gid[iv]]
    ok[iv] = np.linalg.norm(np.cross(x_v - oc[iv], dc[iv]), axis=1) <= eps
    point[iv] = x_v

    ie = np.flatnonzero(~is_vertex)
    ev = scene.half_edges.edge_vertices[gid[ie]]
    a, b = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
    x, dist = segment_parameter(oc[ie], dc[ie], a, b)
    length = np.linalg.norm(b - a, axis=1)
    # the line meets the edge strictly inside: at an endpoint the event is the vertex's
    with np.errstate(invalid="ignore"):
        ok[ie] = (dist <= eps) & (x * length > eps) & ((1 - x) * length > eps)
    point[ie] = a + np.nan_to_num(x)[:, None] * (b - a)

    keep = np.ones(m, dtype=bool)
    keep &= _all_of(cand, ok, m)

    # generators sorted along the line
    t = np.full((m, 4), np.inf)
    t[cand, slot] = np.einsum("ij,ij->i", point - oc, dc)
    order = np.argsort(t, axis=1, kind="stable")
    t_sorted = np.take_along_axis(t, order, axis=1)
    row_of = np.full((m, 4), -1)
    row_of[cand, slot] = np.arange(len(cand))
    row_sorted = np.take_along_axis(row_of, order, axis=1)
    for j in range(3):  # distinct points along the line
        has = j + 1 < count
        gap = np.where(has, t_sorted[:, j + 1] - np.where(has, t_sorted[:, j], 0.0), np.inf)
        keep &= ~has | (gap > eps)

    # The tests are one conjunction, so their order is free: cheapest first.
    # Consecutive generators see each other (batched rays) ...
    pieces_a, pieces_b, piece_cand = [], [], []
    for j in range(3):
        has = keep & (j + 1 < count)
        c = np.flatnonzero(has)
        pieces_a.append(point[row_sorted[c, j]])
        pieces_b.append(point[row_sorted[c, j + 1]])
        piece_cand.append(c)
    piece_cand = np.concatenate(piece_cand)
    if len(piece_cand):
        free = scene.ray_caster.free_segments(np.concatenate(pieces_a), np.concatenate(pieces_b))
        keep &= _all_of(piece_cand, free, m)

    # ... then tangency, the costly test, on the lines still standing
    rows = np.flatnonzero(keep[cand])
    wedges = generator_wedges(scene, is_vertex[rows], gid[rows], point[rows])
    tangent[rows], degenerate[rows] = tangent_in_wedges(wedges, dc[rows])
    # grazing is the rule, not a degeneracy, at a face holding two of the node's
    # generators (v and e on one face, two edges of one face): seed 000 §4.1
    grazing = np.flatnonzero(degenerate[rows])
    if len(grazing):
        excused = _grazes_shared_face(scene, cand[rows], wedges, oc[rows], dc[rows], grazing)
        degenerate[rows[grazing[excused]]] = False
    keep &= _all_of(cand, ~degenerate, m)
    for j in range(1, 3):  # inner generators must be passed
        inner = j < count - 1
        r = np.where(inner, row_sorted[:, j], 0)
        keep &= ~inner | tangent[r]

    nodes = np.flatnonzero(keep)
    n = len(nodes)
    first_row = row_sorted[nodes, 0]
    last_row = row_sorted[nodes, count[nodes] - 1]
    ends = np.empty((n, 2, 3))
    blocker_kind = np.empty((n, 2), dtype=np.int8)
    blocker = np.empty((n, 2), dtype=np.int64)
    for side, row, sign in ((0, first_row, -1.0), (1, last_row, 1.0)):
        feature_kind = np.where(is_vertex[row], BLOCK_VERTEX, BLOCK_EDGE)
        ends[:, side] = point[row]
        blocker_kind[:, side] = feature_kind
        blocker[:, side] = gid[row]
        go_on = np.flatnonzero(tangent[row])  # passing: the segment ends farther on
        if len(go_on):
            start = point[row[go_on]]
            direction = sign * d[nodes[go_on]]
            face, dist_hit = scene.ray_caster.first_hit(start, direction, tmin=eps)
            sky = face < 0
            end = start + np.where(sky, 0.0, dist_hit)[:, None] * direction
            if sky.any():
                end[sky] = scene.ray_caster.sky_points(start[sky], direction[sky])
            ends[go_on, side] = end
            blocker_kind[go_on, side] = np.where(sky, BLOCK_SKY, BLOCK_FACE)
            blocker[go_on, side] = face

    all_ends = np.full((m, 2, 3), np.nan)
    all_ends[nodes] = ends
    all_kind = np.full((m, 2), -1, dtype=np.int8)
    all_kind[nodes] = blocker_kind
    all_blocker = np.full((m, 2), -1, dtype=np.int64)
    all_blocker[nodes] = blocker
    gen_points = np.full((m, 4, 3), np.nan)
    has = row_of >= 0
    gen_points[has] = point[row_of[has]]
    slot_tangent = np.zeros((m, 4), dtype=bool)
    slot_tangent[has] = tangent[row_of[has]]
    return LineSegments(keep, d, all_ends, all_kind, all_blocker, gen_points, slot_tangent)


def vertex_ray_blockers(scene, vertices, directions):
    """Blocker pair of the maximal free segment through each vertex whose part beyond
    the vertex runs along each direction (V-cells, docs/skeleton.md).

    The rule of :func:`maximal_free_segments` for one vertex: where the line is
    tangent at the vertex the segment runs from the first hit along -d (up) to
    the first hit along d (down); where the surface separates its rays there,
    up is the vertex itself.

    Parameters
    ----------
    scene : Scene
    vertices : (q,) int
    directions : (q, 3) float

    Returns
    -------
    up_kind, up, down_kind, down : (q,) int8, int, int8, int
        BLOCK_FACE, BLOCK_SKY (id -1) or BLOCK_VERTEX (up only, id the vertex).
    degenerate : (q,) bool
        The line lies on a face at the vertex or along an edge there (grazing).
    """
    vertices = np.asarray(vertices, dtype=np.int64)
    d = np.asarray(directions, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    x = scene.vertices[vertices]
    tangent, degenerate = tangent_at_vertices(scene, vertices, d)
    face, _ = scene.ray_caster.first_hit(np.concatenate([x, x]), np.concatenate([-d, d]), tmin=scene.epsilon)
    back, front = face[: len(d)], face[len(d):]
    up_kind = np.where(~tangent, BLOCK_VERTEX, np.where(back < 0, BLOCK_SKY, BLOCK_FACE)).astype(np.int8)
    up = np.where(~tangent, vertices, back)
    down_kind = np.where(front < 0, BLOCK_SKY, BLOCK_FACE).astype(np.int8)
    return up_kind, up, down_kind, front, degenerate


def _grazes_shared_face(scene, cand, wedges, origins, directions, rows, angle_tol=1e-9):
    """For each generator row in ``rows``, whether its line lies in the plane of a
    face that touches this generator's point and another generator point of the
    same candidate.

    Contacts are the geometric ones tangency uses (``wedges``): a block's bottom
    edge lying on a floor is on the floor's face although no half-edge joins them.

    cand : (k,) int
        Candidate of every generator row; every row of a candidate in ``rows``
        is among the k.
    wedges : Wedges
        The surface around each row's generator point.
    origins, directions : (k, 3) float
    rows : (r,) int
        The rows to judge.

    Returns
    -------
    (r,) bool
    """
    row_of_wedge = np.repeat(np.arange(len(cand)), np.diff(wedges.offsets))
    here = np.isin(row_of_wedge, rows)
    pos = np.searchsorted(rows, row_of_wedge[here])
    face = wedges.face[here]
    # a face is shared when another generator row of the candidate touches it too
    # (the row itself is among its candidate's rows, hence "at least two")
    sib = np.isin(cand[row_of_wedge], cand[rows])
    key_other = np.sort(cand[row_of_wedge[sib]] * scene.n_faces + wedges.face[sib])
    key_here = cand[rows[pos]] * scene.n_faces + face
    shared = np.searchsorted(key_other, key_here, "right") - np.searchsorted(key_other, key_here, "left") >= 2
    n, off = scene.face_normal[face], scene.face_offset[face]
    r = rows[pos]
    in_plane = (np.abs(np.einsum("ij,ij->i", n, directions[r])) <= angle_tol) & (
        np.abs(np.einsum("ij,ij->i", n, origins[r]) - off) <= scene.epsilon
    )
    return ~_all_of(pos, ~(shared & in_plane), len(rows))


def _all_of(owner, flag, n):
    """(n,) bool: whether every flag of each owner is set (owners without rows: True).
    A bincount, because ``np.logical_and.at`` is slow on millions of rows."""
    return np.bincount(owner, weights=~np.asarray(flag, dtype=bool), minlength=n) == 0


def sort_nodes(nodes):
    """Nodes in canonical order: kind, generators, then direction (two E4 solutions)."""
    keys = [nodes.direction[:, 2], nodes.direction[:, 1], nodes.direction[:, 0]]
    keys += [nodes.generators[:, k] for k in (3, 2, 1, 0)] + [nodes.kind]
    order = np.lexsort(keys)
    return Nodes(**{name: getattr(nodes, name)[order] for name in nodes.__dataclass_fields__})


def _empty():
    return Nodes(
        kind=np.zeros(0, dtype=np.int8),
        generators=np.zeros((0, 4), dtype=np.int64),
        direction=np.zeros((0, 3)),
        ends=np.zeros((0, 2, 3)),
        blocker_kind=np.zeros((0, 2), dtype=np.int8),
        blocker=np.zeros((0, 2), dtype=np.int64),
        generator_points=np.zeros((0, 4, 3)),
    )
