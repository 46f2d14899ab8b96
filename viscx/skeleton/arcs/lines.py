"""The lines of an arc family at parameter s, and the judging of sample lines (blocker
pairs, generator conditions and, for VE, the two half-cells' blockers).
"""

from dataclasses import dataclass

import numpy as np

from viscx.arrays import row_norms
from viscx.geometry.lines import line_through_point_and_two_lines, plucker
from viscx.skeleton.arcs.kinds import EEE, VE, XE
from viscx.skeleton.arcs.pencils import first_pencil_pair, pencil_plane_of
from viscx.skeleton.arcs.xpoints import blocked_at_crossings, crossing_scene
from viscx.skeleton.generators import edge_crossings, edge_geometry
from viscx.skeleton.nodes import BLOCK_FACE, BLOCK_SKY, BLOCK_VERTEX, first_faces, maximal_free_segments, vertex_ray_blockers
from viscx.tolerances import PROBE_ANGLE




# slot layout of the family lines for maximal_free_segments (EEE: three edges; VE: vertex, edge)
_SLOT_IS_VERTEX = np.array([[False] * 4, [True, False, False, False]])

_SLOT_COUNT = np.array([3, 2])


def family_lines(scene, kind, generators, s):
    """A point and a direction of the line of each family at parameter s.

    Parameters
    ----------
    kind : (m,) int
        EEE or VE.
    generators : (m, 3) int
        Canonical (see :class:`Arcs`).
    s : (m,) float

    Returns
    -------
    origins, directions : (m, 3) float
        Directions are zero where the line is undefined (EEE: the point lies on
        the line of q or r).
    """
    kind = np.asarray(kind)
    generators = np.asarray(generators, dtype=np.int64)
    s = np.asarray(s, dtype=np.float64)
    origins = np.zeros((len(kind), 3))
    directions = np.zeros((len(kind), 3))
    e = np.flatnonzero(kind == EEE)
    if len(e):
        a, b = edge_geometry(scene, generators[e, 0])
        p = a + s[e, None] * (b - a)
        aq, bq = edge_geometry(scene, generators[e, 1])
        ar, br = edge_geometry(scene, generators[e, 2])
        origins[e] = p
        directions[e] = line_through_point_and_two_lines(p, plucker(aq, bq - aq), plucker(ar, br - ar))
    v = np.flatnonzero(kind == VE)
    if len(v):
        a, b = edge_geometry(scene, generators[v, 1])
        origins[v] = scene.vertices[generators[v, 0]]
        directions[v] = a + s[v, None] * (b - a) - origins[v]
    x = np.flatnonzero(kind == XE)
    if len(x):
        cr = edge_crossings(scene)
        a, b = edge_geometry(scene, generators[x, 1])
        origins[x] = cr.point[cr.find(generators[x, 0], generators[x, 2])]
        directions[x] = a + s[x, None] * (b - a) - origins[x]
    return origins, directions


@dataclass
class _Samples:
    valid: np.ndarray
    state: np.ndarray  # (m, 5) int: valid, blocker kinds and ids in the family's orientation
    direction: np.ndarray
    ends: np.ndarray
    generator_points: np.ndarray
    sides: np.ndarray = None  # (m, 12) int: the VE half-cells' pairs and backs (sides=True), -1 elsewhere


def _probe_directions(scene, vertex, edge, s):
    """The VE lines from each vertex to its edge's point s turned about the vertex by
    PROBE_ANGLE towards +n, then towards -n (n = (b - a) × (v - a)): (2m, 3) float."""
    x = scene.vertices[vertex]
    a, b = edge_geometry(scene, edge)
    d0 = a + np.asarray(s, dtype=np.float64)[:, None] * (b - a) - x
    d0 /= row_norms(d0)[:, None]
    n = np.cross(b - a, x - a)
    n /= row_norms(n)[:, None]
    return np.concatenate([d0 + PROBE_ANGLE * n, d0 - PROBE_ANGLE * n])


def side_blockers(scene, vertex, edge, s):
    """Blocker pairs of the V-cells on both sides of VE lines (the half-cells, Hoberock et al. §4.1),
    and what each side's probe meets behind the vertex.

    The line from the vertex to the edge's point s is turned about the vertex by
    PROBE_ANGLE towards +n and -n (n = (b - a) × (v - a)) and judged by
    :func:`viscx.skeleton.nodes.vertex_ray_blockers`. *Behind*: the first hit along the
    probe's -d: its up where the probe passes the vertex; where the surface separates its
    rays there (up the vertex) and not on the other side, it is cast apart
    (:func:`vertex_side_backs`); -1 where both sides' up is the vertex.

    Returns
    -------
    up_kind, up, down_kind, down, back_kind, back : (m, 2) int
        Side +n, side -n.
    """
    m = len(vertex)
    both = np.concatenate([vertex, vertex])
    d = _probe_directions(scene, vertex, edge, s)
    up_kind, up, down_kind, down, _ = vertex_ray_blockers(scene, both, d)
    back_kind, back = up_kind.astype(np.int64), up.astype(np.int64)
    at_vertex = _bounding_vertex_sides(up_kind)
    back_kind[up_kind == BLOCK_VERTEX] = back[up_kind == BLOCK_VERTEX] = -1
    back_kind[at_vertex], back[at_vertex] = _backs(scene, both[at_vertex], d[at_vertex])
    return tuple(np.stack([q[:m], q[m:]], axis=1).astype(np.int64) for q in (up_kind, up, down_kind, down, back_kind, back))


def _bounding_vertex_sides(up_kind):
    """Rows (of the 2m probes, side +n then side -n) whose up is the vertex while the other
    side's is not: only there does the antipodal image bound a cell on the vertex's side
    (where both sides enter the surface at the vertex, -d sees no event)."""
    m = len(up_kind) // 2
    vert = up_kind == BLOCK_VERTEX
    return np.flatnonzero(vert & ~np.r_[vert[m:], vert[:m]])


def _backs(scene, vertex, d):
    """(kind, id) of the first face (or the sky) along -d from each vertex."""
    face, _ = first_faces(scene, scene.vertices[vertex], -d, tmin=scene.epsilon)
    return np.where(face < 0, BLOCK_SKY, BLOCK_FACE), face


def vertex_side_backs(scene, half_cells, s):
    """What the half-cells' probes meet behind their vertex, on the sides whose up is the
    vertex (the antipodal image's cell there, docs/skeleton.md "V-cells").

    Elsewhere in general position it is the other side's up (the same ray -d, no event
    between), but where the VE line lies in the plane of a face at the vertex, the rays
    -d on the two sides pass on either side of that plane (a desk panel's inner top
    corner: one runs behind the other panel's front face, one in front of it). V1 keeps
    it constant along each arc (:func:`side_blockers`); recast here at the arc's sample.

    Parameters
    ----------
    half_cells : HalfCells
    s : (h,) float
        Each half-cell's arc's sample parameter.

    Returns
    -------
    back_kind, back : (h, 2) int
        -1 on sides whose up is not the vertex, or is on both sides.
    """
    hc = half_cells
    m = len(hc.vertex)
    rows = _bounding_vertex_sides(np.concatenate([hc.up_kind[:, 0], hc.up_kind[:, 1]]))
    back_kind, back = np.full(2 * m, -1, np.int64), np.full(2 * m, -1, np.int64)
    if len(rows):
        h = rows % m
        d = _probe_directions(scene, hc.vertex[h], hc.edge[h], np.asarray(s)[h]).reshape(2, -1, 3)
        d = np.where((rows < m)[:, None], d[0], d[1])  # side +n: the first half, side -n: the second
        back_kind[rows], back[rows] = _backs(scene, hc.vertex[h], d)
    return np.stack([back_kind[:m], back_kind[m:]], axis=1), np.stack([back[:m], back[m:]], axis=1)


def judge_samples(scene, kind, generators, s, sides=False):
    """The maximal free segment of each family's line at s, in the family's orientation.

    Parameters
    ----------
    kind : (m,) int
    generators : (m, 3) int
    s : (m,) float
    sides : bool
        Also judge the half-cells of valid VE samples (:func:`side_blockers`).

    Returns
    -------
    valid : (m,) bool
    state : (m, 5) int
        (valid, back blocker kind, back blocker, front blocker kind, front
        blocker); -1 for the blockers of invalid lines. Two samples of a family
        are on one arc only if their states (and sides) agree.
    sides : (m, 12) int or None
        (up kind, up, down kind, down, back kind, back) on side +n, then on side -n
        interleaved as :func:`side_blockers` returns them (valid VE samples; -1
        elsewhere): the half-cells of :class:`HalfCells`, and behind the vertex.
    direction : (m, 3) float
    ends : (m, 2, 3) float
    generator_points : (m, 3, 3) float
    """
    kind = np.asarray(kind, dtype=np.int64)
    generators = np.asarray(generators, dtype=np.int64)
    if np.any(kind == XE):  # as VE families of the crossing points (crossing_scene)
        xs, first, x, cr, generators = _as_crossing_families(scene, kind, generators)
        out = judge_samples(xs, np.where(x, VE, kind), generators, s, sides)
        out.generator_points[x, 2] = out.generator_points[x, 0]
        blocked_at_crossings(out.state[:, [1, 3]], out.state[:, [2, 4]], generators[:, 0] - first, x, cr, out.state)
        return out
    o, d = family_lines(scene, kind, generators, s)
    undefined = row_norms(d) == 0
    d[undefined] = (1.0, 0.0, 0.0)
    gens = np.concatenate([generators, np.full((len(kind), 1), -1)], axis=1)
    plane = pencil_plane_of(scene, kind, generators)
    seg = maximal_free_segments(scene, _SLOT_IS_VERTEX[kind], _SLOT_COUNT[kind], gens, o, d, plane_face=plane)
    valid = seg.valid & ~undefined
    valid &= first_pencil_pair(scene, plane, generators, seg.ends, valid)
    gp = seg.generator_points[:, :3]
    # the family's orientation: from the first generator's point towards the second's
    flip = valid & (np.einsum("ij,ij->i", seg.direction, gp[:, 1] - gp[:, 0]) < 0)
    direction = np.where(flip[:, None], -seg.direction, seg.direction)
    ends = np.where(flip[:, None, None], seg.ends[:, ::-1], seg.ends)
    bk = np.where(flip[:, None], seg.blocker_kind[:, ::-1], seg.blocker_kind).astype(np.int64)
    b = np.where(flip[:, None], seg.blocker[:, ::-1], seg.blocker)
    state = np.stack([valid.astype(np.int64), bk[:, 0], b[:, 0], bk[:, 1], b[:, 1]], axis=1)
    state[~valid, 1:] = -1
    # the V-cells beside valid VE lines: an arc's half-cells must hold all along it
    side = judge_sides(scene, kind, generators, s, valid) if sides else None
    return _Samples(valid, state, direction, ends, gp, side)


def judge_sides(scene, kind, generators, s, valid):
    """The ``sides`` of :func:`judge_samples` (the half-cells of the valid VE and XE samples,
    -1 elsewhere), for samples already judged (``valid`` : (m,) bool, theirs): where the
    lines' states alone settle a question (two samples on different arcs), the half-cells
    are not asked for. Parameters as :func:`judge_samples`; returns (m, 12) int."""
    kind = np.asarray(kind, dtype=np.int64)
    generators = np.asarray(generators, dtype=np.int64)
    if np.any(kind == XE):
        xs, _, x, _, generators = _as_crossing_families(scene, kind, generators)
        return judge_sides(xs, np.where(x, VE, kind), generators, s, valid)
    side = np.full((len(kind), 12), -1, dtype=np.int64)
    rows = np.flatnonzero(valid & (kind == VE))
    if len(rows):
        side[rows] = np.concatenate(side_blockers(scene, generators[rows, 0], generators[rows, 1], np.asarray(s)[rows]), axis=1)
    return side


def _as_crossing_families(scene, kind, generators):
    """XE families (a, e, b) as the VE families (X, e) of their crossing points X in
    :func:`crossing_scene`: (that scene, its first crossing vertex, the XE rows (m,) bool,
    the crossings, the (m, 3) generators with the XE rows rewritten)."""
    xs, first = crossing_scene(scene)
    x = kind == XE
    cr = edge_crossings(scene)
    generators = generators.copy()
    generators[x] = np.stack([first + cr.find(generators[x, 0], generators[x, 2]), generators[x, 1],
                              np.full(np.count_nonzero(x), -1)], axis=1)
    return xs, first, x, cr, generators
