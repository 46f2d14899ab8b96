"""V0: the nodes (0-cells) of the visibility complex: E4, VEE and VV.

A node is a maximal free segment fixed by four conditions on generators
(docs/skeleton.md). Whatever proposes the candidate lines (the O(n⁴) reference
in :mod:`viscx.skeleton.reference`, or the output-sensitive builder), this module
decides which candidates are nodes and builds their segments, so every builder
shares one definition.
"""

from dataclasses import dataclass

import numpy as np

from viscx.arrays import expand_ranges, row_norms, unique_sorted
from viscx.geometry.lines import segment_parameter
from viscx.geometry.tangency import tangent_in_wedges
from viscx.parallel import map_chunks, row_chunks
from viscx.raycast import intersect_triangles
from viscx.scene.neighbourhood import faces_near, generator_wedge_ranges, tangent_at_vertices
from viscx.tolerances import ANGLE_TOLERANCE, GRAZE_COSINE, TIE_MARGIN, TIE_SLACK

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
    d = d / row_norms(d)[:, None]
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
    return sort_nodes(nodes_among(scene, kind, generators, origins, directions))


def nodes_among(scene, kind, generators, origins, directions):
    """:func:`validate_candidates` in the candidates' order, not sorted (for callers
    that judge candidates in chunks and sort once). Parameters as there."""
    kind = np.asarray(kind, dtype=np.int8)
    if len(kind) == 0:
        return _empty()
    seg = maximal_free_segments(scene, SLOT_IS_VERTEX[kind], SLOT_COUNT[kind], generators, origins, directions)
    nodes = np.flatnonzero(seg.valid)
    return Nodes(
        kind=kind[nodes],
        generators=np.asarray(generators, dtype=np.int64)[nodes],
        direction=seg.direction[nodes],
        ends=seg.ends[nodes],
        blocker_kind=seg.blocker_kind[nodes],
        blocker=seg.blocker[nodes],
        generator_points=seg.generator_points[nodes],
    )


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
        Whether the line passes at each generator slot (False for unused slots). Read it
        on valid lines: a line rejected before its ends are judged holds False.
    """

    valid: np.ndarray
    direction: np.ndarray
    ends: np.ndarray
    blocker_kind: np.ndarray
    blocker: np.ndarray
    generator_points: np.ndarray
    tangent: np.ndarray


#: Lines judged per chunk by :func:`maximal_free_segments` (chunks run on threads).
SEGMENT_CHUNK = 1 << 16


def maximal_free_segments(scene, slot_is_vertex, slot_count, generators, origins, directions, workers=None,
                          plane_face=None):
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

    workers : int, optional
        Threads (default: the CPU count); each line is judged on its own, so the
        result does not depend on them.
    plane_face : (m,) int, optional
        A face in whose plane the line lies (a pencil of a touched plane), -1 for
        none: the line passes faces beside that plane (:func:`first_triangles`).

    Returns
    -------
    LineSegments
    """
    slot_is_vertex, slot_count, generators, origins, directions = (
        np.asarray(a) for a in (slot_is_vertex, slot_count, generators, origins, directions))
    m = len(slot_count)
    if plane_face is not None:
        plane_face = np.asarray(plane_face, dtype=np.int64)
        if not np.any(plane_face >= 0):
            plane_face = None
    if m > SEGMENT_CHUNK:
        parts = map_chunks(lambda r: _maximal_free_segments(
            scene, slot_is_vertex[r], slot_count[r], generators[r], origins[r], directions[r],
            None if plane_face is None else plane_face[r]), row_chunks(m, SEGMENT_CHUNK), workers)
        return LineSegments(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in LineSegments.__dataclass_fields__})
    return _maximal_free_segments(scene, slot_is_vertex, slot_count, generators, origins, directions, plane_face)


def _maximal_free_segments(scene, slot_is_vertex, slot_count, generators, origins, directions, plane_face=None):
    """:func:`maximal_free_segments` on one chunk of lines.

    Rows are gathered with ``np.take`` and masks with ``np.compress``: numpy's fancy
    indexing of (n, 3) rows by millions of indices is ten times slower (the same copies)."""
    eps = scene.epsilon
    slot_is_vertex = np.asarray(slot_is_vertex, dtype=bool)
    count = np.asarray(slot_count, dtype=np.int64)
    generators = np.asarray(generators, dtype=np.int64)
    d = canonical_directions(directions)
    o = np.asarray(origins, dtype=np.float64)
    m = len(count)

    # one row per (candidate, generator slot): flat = 4 cand + slot
    used = np.arange(4)[None, :] < count[:, None]
    flat = np.flatnonzero(used)
    cand = flat >> 2
    gid = np.take(generators, flat)
    is_vertex = np.take(slot_is_vertex, flat)
    oc, dc = np.take(o, cand, axis=0), np.take(d, cand, axis=0)
    point = np.empty((len(cand), 3))
    ok = np.ones(len(cand), dtype=bool)
    tangent = np.zeros(len(cand), dtype=bool)
    degenerate = np.zeros(len(cand), dtype=bool)

    iv = np.flatnonzero(is_vertex)
    x_v = np.take(scene.vertices, np.take(gid, iv), axis=0)
    ok[iv] = row_norms(np.cross(x_v - np.take(oc, iv, axis=0), np.take(dc, iv, axis=0))) <= eps
    point[iv] = x_v

    ie = np.flatnonzero(~is_vertex)
    ev = np.take(scene.half_edges.edge_vertices, np.take(gid, ie), axis=0)
    a, b = np.take(scene.vertices, ev[:, 0], axis=0), np.take(scene.vertices, ev[:, 1], axis=0)
    x, dist = segment_parameter(np.take(oc, ie, axis=0), np.take(dc, ie, axis=0), a, b)
    length = row_norms(b - a)
    # the line meets the edge strictly inside: at an endpoint the event is the vertex's
    with np.errstate(invalid="ignore"):
        ok[ie] = (dist <= eps) & (x * length > eps) & ((1 - x) * length > eps)
    point[ie] = a + np.nan_to_num(x)[:, None] * (b - a)

    keep = np.ones(m, dtype=bool)
    keep &= _all_of(cand, ok, m)

    # generators sorted along the line
    t = np.full((m, 4), np.inf)
    t.reshape(-1)[flat] = np.einsum("ij,ij->i", point - oc, dc)
    order = np.argsort(t, axis=1, kind="stable")
    sorted_flat = order + 4 * np.arange(m)[:, None]
    t_sorted = np.take(t, sorted_flat)
    row_of = np.full((m, 4), -1)
    row_of.reshape(-1)[flat] = np.arange(len(cand))
    row_sorted = np.take(row_of, sorted_flat)
    for j in range(3):  # distinct points along the line
        has = j + 1 < count
        gap = np.where(has, t_sorted[:, j + 1] - np.where(has, t_sorted[:, j], 0.0), np.inf)
        keep &= ~has | (gap > eps)

    # The tests are one conjunction, so their order is free: cheapest first.
    # Inner generators are passed (a wedge look-up each, no ray): on a closed mesh most
    # lines cross their middle edge (the bunny decimated to 1,000 triangles: 18.5 % of its
    # V1 samples are segments; the pieces cast fall from 1.51 to 0.88 million, but the
    # pieces left are the long ones: V1 CPU 2-3 % less). These rows are judged again below
    # with the ends, so the lines kept and what they hold do not change.
    inner = np.concatenate([np.take(row_sorted[:, j], np.flatnonzero(keep & (j < count - 1))) for j in (1, 2)])
    if len(inner):
        passed = _passed(scene, np.take(is_vertex, inner), np.take(gid, inner), np.take(point, inner, axis=0),
                         np.take(dc, inner, axis=0))
        keep &= _all_of(np.take(cand, inner), passed, m)

    # Consecutive generators see each other (batched rays) ...
    pieces_a, pieces_b, piece_cand = [], [], []
    for j in range(3):
        has = keep & (j + 1 < count)
        c = np.flatnonzero(has)
        pieces_a.append(np.take(point, np.take(row_sorted[:, j], c), axis=0))
        pieces_b.append(np.take(point, np.take(row_sorted[:, j + 1], c), axis=0))
        piece_cand.append(c)
    piece_cand = np.concatenate(piece_cand)
    if len(piece_cand):
        free = free_pieces(scene, np.concatenate(pieces_a), np.concatenate(pieces_b),
                           None if plane_face is None else np.take(plane_face, piece_cand))
        keep &= _all_of(piece_cand, free, m)

    # ... then tangency, the costly test, on the lines still standing
    rows = np.flatnonzero(np.take(keep, cand))
    d_rows = np.take(dc, rows, axis=0)
    wedges = generator_wedge_ranges(scene, np.take(is_vertex, rows), np.take(gid, rows), np.take(point, rows, axis=0))
    tangent[rows], degenerate[rows] = tangent_in_wedges(wedges, d_rows)
    # grazing is the rule, not a degeneracy, at a face holding two of the node's
    # generators (v and e on one face, two edges of one face): Hoberock et al. §4.1
    grazing = np.flatnonzero(np.take(degenerate, rows))
    if len(grazing):
        excused = _grazes_shared_face(scene, np.take(cand, rows), wedges, np.take(oc, rows, axis=0), d_rows, grazing)
        degenerate[rows[grazing[excused]]] = False
    keep &= _all_of(cand, ~degenerate, m)
    for j in range(1, 3):  # inner generators must be passed
        inner = j < count - 1
        r = np.where(inner, row_sorted[:, j], 0)
        keep &= ~inner | np.take(tangent, r)

    nodes = np.flatnonzero(keep)
    n = len(nodes)
    first_row = np.take(row_sorted[:, 0], nodes)
    last_row = np.take(row_sorted, 4 * nodes + np.take(count, nodes) - 1)
    ends = np.empty((n, 2, 3))
    blocker_kind = np.empty((n, 2), dtype=np.int8)
    blocker = np.empty((n, 2), dtype=np.int64)
    for side, row, sign in ((0, first_row, -1.0), (1, last_row, 1.0)):
        feature_kind = np.where(np.take(is_vertex, row), BLOCK_VERTEX, BLOCK_EDGE)
        ends[:, side] = np.take(point, row, axis=0)
        blocker_kind[:, side] = feature_kind
        blocker[:, side] = np.take(gid, row)
        go_on = np.flatnonzero(np.take(tangent, row))  # passing: the segment ends farther on
        if len(go_on):
            start = np.take(point, np.take(row, go_on), axis=0)
            direction = sign * np.take(d, np.take(nodes, go_on), axis=0)
            face, dist_hit = first_faces(scene, start, direction, tmin=eps,
                                         plane_face=None if plane_face is None else np.take(plane_face, np.take(nodes, go_on)))
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
    # every used slot's row, in order: point and tangent rows are the used slots'
    gen_points = np.full((m, 4, 3), np.nan)
    gen_points.reshape(-1, 3)[flat] = point
    slot_tangent = np.zeros((m, 4), dtype=bool)
    slot_tangent.reshape(-1)[flat] = tangent
    return LineSegments(keep, d, all_ends, all_kind, all_blocker, gen_points, slot_tangent)


def _passed(scene, is_vertex, generator, points, directions):
    """(k,) bool: whether each line (``directions`` (k, 3) float) passes the generator
    (vertex or edge id, ``is_vertex`` (k,) bool) at its point (``points`` (k, 3) float):
    the tangency of :func:`maximal_free_segments`, without the degeneracy."""
    return tangent_in_wedges(generator_wedge_ranges(scene, is_vertex, generator, points), directions)[0]


def vertex_ray_blockers(scene, vertices, directions):
    """Blocker pair of the maximal free segment through each vertex whose part beyond
    the vertex runs along each direction (V-cells, docs/skeleton.md).

    The rule of :func:`maximal_free_segments` for one vertex: where the line is
    tangent at the vertex the segment runs from the first hit along -d (up) to
    the first hit along d (down); where the surface separates its rays there,
    up is the vertex itself. Hits by :func:`first_faces` (float64, ties to the lowest
    face): the half-cells' probes pass 1e-8 rad beside the cells' boundaries.

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
    d = d / row_norms(d)[:, None]
    x = np.take(scene.vertices, vertices, axis=0)
    tangent, degenerate = tangent_at_vertices(scene, vertices, d)
    # the ray back along -d matters only where the line passes the vertex
    passing = np.flatnonzero(tangent)
    face, _ = first_faces(scene, np.concatenate([np.take(x, passing, axis=0), x]),
                          np.concatenate([-np.take(d, passing, axis=0), d]), tmin=scene.epsilon)
    back = np.full(len(d), -1, dtype=face.dtype)
    back[passing], front = face[: len(passing)], face[len(passing):]
    up_kind = np.where(~tangent, BLOCK_VERTEX, np.where(back < 0, BLOCK_SKY, BLOCK_FACE)).astype(np.int8)
    up = np.where(~tangent, vertices, back)
    down_kind = np.where(front < 0, BLOCK_SKY, BLOCK_FACE).astype(np.int8)
    return up_kind, up, down_kind, front, degenerate


#: Bound on the faces a ray lying in their plane skips in one query of :func:`first_faces`.
MAX_GRAZED = 8
#: The same for a pencil's line of a touched plane (``plane_face``), which also passes the
#: faces beside the plane it touches: several per block along a row of touching blocks.
MAX_PASSED = 4096


def first_faces(scene, origins, directions, tmin, tmax=np.inf, plane_face=None):
    """The first face hit along each ray on [tmin, tmax], deterministic where the hit point
    lies on several faces: then the lowest id of those faces.

    Cast in float64 alone (:class:`viscx.grid.TriangleGrid`, the ray caster's exact
    stage), not with embree's float32 filter first: the filter may order two hits
    closer than its band (about 2.4e-7 of the scene's diagonal) wrongly, so a ray
    passing just beside an edge where two faces meet (a half-cell's probe) could
    name the farther face.

    Ties. A ray through an edge where faces meet (a line of a degenerate family
    hitting the floor exactly at a box's bottom edge) or onto faces of one plane
    that overlap (a box's bottom on the floor, two boxes' faces along their contact)
    meets several faces at one distance, and float64 rounding alone would pick one:
    rays of one region could name different faces (a V-cell split into pieces, an
    arc into flickering samples). The faces holding the hit point are those within
    TIE_SLACK of it, or, for faces of the hit face's plane (:func:`face_planes`:
    offsets within the weld tolerance), those holding its projection onto their
    plane within TIE_SLACK. Only hits within TIE_MARGIN of their triangle's boundary
    or inside the bounding box of a coplanar face of lower id are examined.

    Grazing. A ray lying in a face's plane (GRAZE_COSINE, the weld tolerance) does not
    hit that face: the caster treats it as parallel only below 1e-12, and a line built
    in a plane (a pencil of an EEE family, a VE line of a same-plane family) lies in
    it only to rounding, so it would cross it at a point chosen by rounding. Such a hit
    is skipped (the ray goes on from the weld tolerance beyond, up to MAX_GRAZED
    times), as embree's float32 filter never saw it.

    Returns
    -------
    face : (n,) int
        -1 for the sky (nothing on [tmin, tmax]).
    t : (n,) float
        inf for the sky.
    """
    o = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(d / row_norms(d)[:, None])
    tri, t = first_triangles(scene, o, d, tmin, tmax, plane_face)
    margin = np.full(len(o), np.inf)
    rows = np.flatnonzero(tri >= 0)
    o_rows, d_rows = np.take(o, rows, axis=0), np.take(d, rows, axis=0)
    _, margin[rows], _ = intersect_triangles(o_rows, d_rows, scene.ray_caster.vertices, scene.ray_caster.triangles,
                                             np.take(tri, rows))
    t[tri < 0] = np.inf
    face = np.where(tri >= 0, np.take(scene.triangle_face, np.maximum(tri, 0)), -1)
    hit = o_rows + np.take(t, rows)[:, None] * d_rows
    examine = margin[rows] * _triangle_sizes(scene)[tri[rows]] <= TIE_MARGIN * scene.diagonal
    # on a face with coplanar partners: only where a partner's bounding box holds the hit
    p_off, p_face, lo_box, hi_box = coplanar_partners(scene)
    on = np.flatnonzero(~examine & (p_off[face[rows] + 1] > p_off[face[rows]]))
    count = (p_off[face[rows[on]] + 1] - p_off[face[rows[on]]])
    which = np.repeat(on, count)
    partner = p_face[np.repeat(p_off[face[rows[on]]], count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)]
    tol = 2 * scene.weld_tolerance
    hit_which = np.take(hit, which, axis=0)
    inside = np.all((hit_which >= np.take(lo_box, partner, axis=0) - tol) & (hit_which <= np.take(hi_box, partner, axis=0) + tol),
                    axis=1)
    slack = TIE_SLACK * scene.diagonal
    # hits on a triangle's boundary: the faces holding the hit point
    edge_rows = np.flatnonzero(examine)
    pos_e, near_e = faces_near(scene, np.take(hit, edge_rows, axis=0), slack)
    pos_e = edge_rows[pos_e]
    # hits inside a coplanar partner's box: the partners holding the hit's projection onto their plane
    pos_p, near_p = which[inside], partner[inside]
    n, off = np.take(scene.face_normal, near_p, axis=0), scene.face_offset[near_p]
    hit_p = np.take(hit, pos_p, axis=0)
    gap = np.einsum("ij,ij->i", n, hit_p) - off
    q, tri_face = faces_near(scene, hit_p - gap[:, None] * n, slack)
    holds = np.zeros(len(pos_p), dtype=bool)
    holds[q[tri_face == near_p[q]]] = True
    pos = np.concatenate([pos_e, pos_p[holds]])
    near = np.concatenate([near_e, near_p[holds]])
    if len(pos) == 0:
        return face, t
    best = face[rows].copy()
    np.minimum.at(best, pos, near)
    face = face.copy()
    face[rows] = best
    return face, t


def first_triangles(scene, origins, directions, tmin, tmax, plane_face=None):
    """The first triangle each ray hits on [tmin, tmax] that it does not graze (the rule
    of :func:`first_faces`, before its ties): the float64 caster's answer, going on
    past triangles in whose plane the ray lies (up to MAX_GRAZED of them).

    A ray given a ``plane_face`` that lies in that face's plane P (as grazing is judged;
    a pencil of a touched plane, :func:`viscx.skeleton.arcs.pencil_planes`) also goes on
    past faces lying on one side of P. Such a face meets P only on its outline, so the ray touches it
    there, tangent (a block's top face at the edge it shares with its face in P), and
    passes, as it passes a generator it is tangent to. Where the ray enters a solid
    there (a reflex edge), the solid's other faces still stop it.

    Parameters
    ----------
    origins, directions : (n, 3) float
        Unit directions.
    tmin, tmax : float or (n,) float
    plane_face : (n,) int, optional
        A face in whose plane the ray lies, -1 for none.

    Returns
    -------
    triangle : (n,) int
        -1 for the sky.
    t : (n,) float
    """
    o, d = origins, directions
    lo = np.broadcast_to(np.asarray(tmin, dtype=np.float64), (len(o),)).copy()
    hi = np.broadcast_to(np.asarray(tmax, dtype=np.float64), (len(o),)).copy()
    # rays in no pencil's plane: the grazing rule alone, in one kernel
    plain = np.arange(len(o)) if plane_face is None else np.flatnonzero(plane_face < 0)
    if len(plain) == len(o):
        return _first_ungrazed(scene, o, d, lo, hi)
    tri = np.full(len(o), -1, dtype=np.int64)
    t = np.full(len(o), np.inf)
    tri[plain], t[plain] = _first_ungrazed(scene, o[plain], d[plain], lo[plain], hi[plain])
    todo = np.flatnonzero(plane_face >= 0)
    for _ in range(MAX_PASSED + 1):
        tri[todo], t[todo] = scene.ray_caster.exact.first_hit(o[todo], d[todo], lo[todo], hi[todo])
        todo = todo[tri[todo] >= 0]
        f = scene.triangle_face[tri[todo]]
        grazing = _in_face_plane(scene, f, o[todo], d[todo])
        r = np.flatnonzero(~grazing)
        g = plane_face[todo[r]]
        grazing[r] = _in_face_plane(scene, g, o[todo[r]], d[todo[r]]) & faces_beside_planes(scene, f[r], g)
        todo = todo[grazing]
        if len(todo) == 0:
            break
        lo[todo] = t[todo] + scene.weld_tolerance
    return tri, t


def _first_ungrazed(scene, origins, directions, tmin, tmax):
    """:func:`first_triangles` of rays in no pencil's plane: a hit on a face whose plane holds
    the ray (:func:`_in_face_plane`) is passed, at most MAX_GRAZED times."""
    return scene.ray_caster.exact.first_hit_off_planes(origins, directions, tmin, tmax, scene.triangle_face,
                                                       scene.face_normal, scene.face_offset, GRAZE_COSINE,
                                                       scene.weld_tolerance, MAX_GRAZED + 1)


def _in_face_plane(scene, faces, origins, directions):
    """(n,) bool: whether each ray lies in its face's plane, as grazing is judged
    (GRAZE_COSINE, the weld tolerance)."""
    n = scene.face_normal[faces]
    return (np.abs(np.einsum("ij,ij->i", n, directions)) <= GRAZE_COSINE) & (
        np.abs(np.einsum("ij,ij->i", n, origins) - scene.face_offset[faces]) <= scene.weld_tolerance)


def faces_beside_planes(scene, faces, plane_faces):
    """Whether each face lies on one side of the plane of the paired face, touching it at
    most (every vertex of the face within the weld tolerance of that side).

    Parameters
    ----------
    faces, plane_faces : (n,) int

    Returns
    -------
    (n,) bool
    """
    faces = np.asarray(faces, dtype=np.int64)
    plane_faces = np.asarray(plane_faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    # a face's vertices, all its loops, are one run of loop_vertices
    lo = scene.loop_offsets[scene.face_loop_offsets[faces]]
    count = scene.loop_offsets[scene.face_loop_offsets[faces + 1]] - lo
    row, at = expand_ranges(lo, count)
    vertex = scene.loop_vertices[at]
    dist = np.einsum("ij,ij->i", scene.vertices[vertex], scene.face_normal[plane_faces[row]]) - scene.face_offset[plane_faces[row]]
    starts = np.cumsum(count) - count
    tol = scene.weld_tolerance
    return (np.minimum.reduceat(dist, starts) >= -tol) | (np.maximum.reduceat(dist, starts) <= tol)


def free_pieces(scene, starts, ends, plane_face=None):
    """Whether each segment, trimmed by epsilon at both ends, is free: no closed triangle
    met but those it grazes (:func:`first_triangles`, float64 alone: embree's float32
    filter may miss a segment touching an edge, so a family of lines all touching one
    edge, in a degenerate scene, would be free at random samples; which face is met,
    :func:`first_faces`' ties, does not matter here). The freeness rule of
    :func:`maximal_free_segments` (and of builders that prefilter candidates by it).

    Parameters
    ----------
    starts, ends : (n, 3) float
    plane_face : (n,) int, optional
        As in :func:`first_triangles`.

    Returns
    -------
    (n,) bool
    """
    starts = np.asarray(starts, dtype=np.float64).reshape(-1, 3)
    vec = np.asarray(ends, dtype=np.float64).reshape(-1, 3) - starts
    length = row_norms(vec)
    eps = scene.epsilon
    free = length <= 2 * eps
    rays = np.flatnonzero(~free)
    if len(rays):
        length_rays = np.take(length, rays)
        tri, _ = first_triangles(scene, np.take(starts, rays, axis=0), np.take(vec, rays, axis=0) / length_rays[:, None], eps,
                                 length_rays - eps,
                                 None if plane_face is None else np.asarray(plane_face)[rays])
        free[rays] = tri < 0
    return free


def face_planes(scene):
    """(f,) int: a plane id per face, equal for faces lying in one plane (cached on the scene).

    Planes are oriented (largest normal component positive), grouped by their normal
    rounded to 1e-9, then sorted by offset: consecutive offsets within the weld
    tolerance are one plane (a chain, so a plane is never split at a rounding
    boundary of its offset).
    """
    return scene.cached("face_planes", _face_planes)


def _face_planes(scene):
    nf = scene.n_faces
    n = scene.face_normal.copy()
    off = scene.face_offset.copy()
    k = np.argmax(np.abs(n), axis=1)
    flip = n[np.arange(nf), k] < 0
    n[flip] *= -1
    off[flip] *= -1
    key_n = np.round(n / ANGLE_TOLERANCE).astype(np.int64)
    order = np.lexsort([off, key_n[:, 2], key_n[:, 1], key_n[:, 0]])
    new = np.ones(nf, dtype=bool)
    new[1:] = np.any(key_n[order][1:] != key_n[order][:-1], axis=1) | (np.diff(off[order]) > scene.weld_tolerance)
    plane = np.empty(nf, dtype=np.int64)
    plane[order] = np.cumsum(new) - 1
    return plane


def _triangle_sizes(scene):
    """(t,) float: the longest side of each triangle (cached on the scene)."""
    def longest_sides(scene):
        c = scene.vertices[scene.triangles]
        return np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).max(axis=1)

    return scene.cached("triangle_sizes", longest_sides)


def coplanar_partners(scene):
    """Faces of lower id sharing each face's plane (:func:`face_planes`) whose bounding
    boxes meet its own (grown by the weld tolerance), as CSR, with every face's bounding
    box (cached on the scene).

    Returns
    -------
    offsets : (f + 1,) int
    partners : (k,) int
    lo, hi : (f, 3) float
    """
    return scene.cached("coplanar_partners", _coplanar_partners)


def _coplanar_partners(scene):
    nf = scene.n_faces
    tol = scene.weld_tolerance
    lo = np.full((nf, 3), np.inf)
    hi = np.full((nf, 3), -np.inf)
    corners = scene.vertices[scene.triangles]
    np.minimum.at(lo, scene.triangle_face, corners.min(axis=1))
    np.maximum.at(hi, scene.triangle_face, corners.max(axis=1))
    plane = face_planes(scene)
    order = np.argsort(plane, kind="stable")
    first = np.searchsorted(plane[order], plane, "left")
    count = np.searchsorted(plane[order], plane, "right") - first
    i = np.repeat(np.arange(nf), count)
    j = order[np.repeat(first, count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)]
    # (only lower ids: a tie goes to the lowest face, so a higher partner never wins)
    ok = (j < i) & np.all((lo[i] <= hi[j] + tol) & (lo[j] <= hi[i] + tol), axis=1)
    i, j = i[ok], j[ok]  # sorted by i
    return np.searchsorted(i, np.arange(nf + 1)), j, lo, hi


def _grazes_shared_face(scene, cand, wedges, origins, directions, rows, angle_tol=ANGLE_TOLERANCE):
    """For each generator row in ``rows``, whether its line lies in the plane of a face
    touching this generator's point, and a face of that plane (the same face or a
    coplanar one, :func:`face_planes`) touches another generator point of the same
    candidate.

    Contacts are the geometric ones tangency uses (``wedges``, within the weld
    tolerance): a block's bottom edge lying on a floor is on the floor's face
    although no half-edge joins them. Coplanar faces count
    as one: two boxes touching face to face make one plane, and a line of that
    plane through a corner of one box and an edge of the other grazes both faces.

    cand : (k,) int
        Candidate of every generator row; every row of a candidate in ``rows``
        is among the k.
    wedges : WedgeRanges
        The surface around each row's generator point.
    origins, directions : (k, 3) float
    rows : (r,) int
        The rows to judge, ascending.

    Returns
    -------
    (r,) bool
    """
    # only the rows of the candidates judged matter (the same answer, on fewer wedges)
    sub = np.flatnonzero(np.isin(cand, cand[rows]))
    cand, wedges, origins, directions = cand[sub], wedges.take(sub), origins[sub], directions[sub]
    rows = np.searchsorted(sub, rows)
    plane = face_planes(scene)
    n_planes = int(plane.max()) + 1
    row_of_wedge = np.repeat(np.arange(len(cand)), np.diff(wedges.offsets))
    here = np.isin(row_of_wedge, rows)
    pos = np.searchsorted(rows, row_of_wedge[here])
    face = wedges.face[here]
    # a plane is shared when another generator row of the candidate touches it too
    # (the row itself is among its candidate's rows, hence "at least two" distinct rows)
    sib = np.isin(cand[row_of_wedge], cand[rows])
    row_plane = unique_sorted(row_of_wedge[sib] * n_planes + plane[wedges.face[sib]])  # distinct (row, plane)
    key_other = np.sort(cand[row_plane // n_planes] * n_planes + row_plane % n_planes)
    key_here = cand[rows[pos]] * n_planes + plane[face]
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
