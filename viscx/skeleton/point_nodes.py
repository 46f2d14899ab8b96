"""V0 of free points (lights, viewpoints) and the VE families their nodes lie on.

A free point is a generator vertex with no incident edges or faces
(:mod:`viscx.skeleton.points`); its nodes are VV (u, p) and VEE (p, e1, e2), judged
by :func:`viscx.skeleton.nodes.validate_candidates` like every node. The crossing points
of X-junctions are judged the same way (:mod:`viscx.skeleton.arcs.xe`).
"""

import numpy as np
from numba import njit

from viscx.arrays import expand_ranges, unique_rows
from viscx.geometry.lines import line_through_point_and_two_lines, segment_parameter
from viscx.grid import overlapping_box_pairs
from viscx.scene.neighbourhood import faces_near
from viscx.skeleton.generators import vertex_edges
from viscx.skeleton.nodes import VEE, VV, validate_candidates
from viscx.skeleton.reference import edge_lines
from viscx.tolerances import ANGLE_TOLERANCE, PARALLEL_TOLERANCE


def _arc_frames(p, a, b):
    """Unit directions from p to the segments' ends and the unit normals of their great
    circles on p's direction sphere (zero where p lies on a segment's line)."""
    ua = a - p
    ub = b - p
    ua = ua / np.linalg.norm(ua, axis=1)[:, None]
    ub = ub / np.linalg.norm(ub, axis=1)[:, None]
    c = np.cross(ua, ub)
    nrm = c / np.maximum(np.linalg.norm(c, axis=1), 1e-300)[:, None]
    return ua, ub, nrm


@njit(cache=True)
def _seen_together(i, j, ua, ub, nrm, slack):
    """Whether one line through p meets segments i and j (their great-circle arcs cross,
    or one crosses the other's antipode), with an angular slack."""
    # both ends of j on one side of i's great circle (beyond the slack): no crossing
    si = (nrm[i] * ua[j]).sum()
    ti = (nrm[i] * ub[j]).sum()
    if (si > slack[i] and ti > slack[i]) or (si < -slack[i] and ti < -slack[i]):
        return False
    sj = (nrm[j] * ua[i]).sum()
    tj = (nrm[j] * ub[i]).sum()
    if (sj > slack[j] and tj > slack[j]) or (sj < -slack[j] and tj < -slack[j]):
        return False
    # the great circles meet at ±x; x must lie on arc i (or its antipode) and on arc j
    x = np.cross(nrm[i], nrm[j])
    size = np.sqrt((x * x).sum())
    if size <= PARALLEL_TOLERANCE:  # one great circle: leave it to validation
        return True
    x /= size
    for sign in (1.0, -1.0):
        y = sign * x
        on_i = (np.cross(ua[i], y) * nrm[i]).sum() >= -slack[i] and (np.cross(y, ub[i]) * nrm[i]).sum() >= -slack[i]
        on_j = (np.cross(ua[j], y) * nrm[j]).sum() >= -slack[j] and (np.cross(y, ub[j]) * nrm[j]).sum() >= -slack[j]
        on_jr = (np.cross(ua[j], -y) * nrm[j]).sum() >= -slack[j] and (np.cross(-y, ub[j]) * nrm[j]).sum() >= -slack[j]
        if on_i and (on_j or on_jr):
            return True
    return False


@njit(cache=True)
def _seen_together_mask(pairs, ua, ub, nrm, slack):
    keep = np.zeros(pairs.shape[0], np.bool_)
    for k in range(pairs.shape[0]):
        keep[k] = _seen_together(pairs[k, 0], pairs[k, 1], ua, ub, nrm, slack)
    return keep


def seen_together(p, a, b, slack, pairs):
    """Which candidate pairs (i, j) of segments a_i b_i, a_j b_j one line through p meets:
    their great-circle arcs on p's direction sphere cross, or one crosses the other's
    antipode (p between the edges), with an angular slack.

    Parameters
    ----------
    p : (3,) float
    a, b : (n, 3) float
    slack : (n,) float
        Angular slack of each segment (radians).
    pairs : (m, 2) int

    Returns
    -------
    (m,) bool
    """
    ua, ub, nrm = _arc_frames(p, a, b)
    return _seen_together_mask(np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2), ua, ub, nrm,
                               np.ascontiguousarray(slack, dtype=np.float64))


def _arc_boxes(ua, nrm, t0, t1):
    """Axis-aligned boxes of the great-circle arcs x(t) = cos t ua + sin t w, t in [t0, t1]
    (w = nrm × ua, t1 - t0 < π): the ends, and the circle's extreme points
    x_k = ±|(ua_k, w_k)| where they fall on the arc."""
    w = np.cross(nrm, ua)
    x0 = np.cos(t0)[:, None] * ua + np.sin(t0)[:, None] * w
    x1 = np.cos(t1)[:, None] * ua + np.sin(t1)[:, None] * w
    lo, hi = np.minimum(x0, x1), np.maximum(x0, x1)
    r = np.hypot(ua, w)
    t_max = np.arctan2(w, ua)  # where x_k = +r, then every 2π
    for t_ext, value in ((t_max, r), (t_max + np.pi, -r)):
        t_ext = t0[:, None] + np.mod(t_ext - t0[:, None], 2 * np.pi)
        on = t_ext <= t1[:, None]
        hi = np.where(on & (value > 0), value, hi)
        lo = np.where(on & (value < 0), value, lo)
    return lo, hi


def edge_pairs_seen_together(p, a, b, slack):
    """Pairs (i, j), i < j, of segments a_i b_i, a_j b_j met by one line through p
    (:func:`seen_together`), without testing every pair: only pairs whose arcs' boxes
    on p's direction sphere overlap (arc with arc, or arc with the other's antipode), or
    whose great circles are one (their normals' boxes overlap) are tested.

    Parameters
    ----------
    p : (3,) float
    a, b : (n, 3) float
    slack : (n,) float

    Returns
    -------
    (m, 2) int64
        Sorted by (i, j).
    """
    n = len(a)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    slack = np.ascontiguousarray(slack, dtype=np.float64)
    ua, ub, nrm = _arc_frames(p, a, b)
    # p on a segment's line: its arc is a whole great circle, tested with every segment
    degenerate = np.linalg.norm(nrm, axis=1) < 0.5
    length = np.arctan2(np.linalg.norm(np.cross(ua, ub), axis=1), np.einsum("ij,ij->i", ua, ub))
    # arcs longer than a grid cell are cut into pieces about a cell long (one box each), so
    # that a long arc lists the cells along it, not those of its whole box
    cell = min(max(float(np.median(length + 4 * slack)), 2.0 / 256), 0.5)
    arcs = np.flatnonzero(~degenerate)
    pieces = np.ceil(length[arcs] / cell).astype(np.int64).clip(1)
    owner = np.repeat(np.arange(len(arcs)), pieces)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    step = length[arcs][owner] / pieces[owner]
    lo, hi = _arc_boxes(ua[arcs][owner], nrm[arcs][owner], k * step, (k + 1) * step)
    grow = (2 * slack[arcs][owner] + 1e-12)[:, None]  # a chord is at most its angle
    lo, hi = lo - grow, hi + grow
    parts = []
    if len(arcs) > 1:
        m = len(owner)
        # arc pieces (side 0) and their antipodes (side 1)
        parts.append(arcs[overlapping_box_pairs(np.concatenate([lo, -hi]), np.concatenate([hi, -lo]),
                                                np.tile(owner, 2), np.repeat([0, 1], m), cell)])
        # one great circle: normals (and their negatives) within the parallel tolerance
        t = 2 * PARALLEL_TOLERANCE
        n_arcs = len(arcs)
        parts.append(arcs[overlapping_box_pairs(np.concatenate([nrm[arcs] - t, -nrm[arcs] - t]),
                                                np.concatenate([nrm[arcs] + t, -nrm[arcs] + t]),
                                                np.tile(np.arange(n_arcs), 2), np.repeat([0, 1], n_arcs), 2.0 / 64)])
    for i in np.flatnonzero(degenerate):
        j = np.delete(np.arange(n), i)
        parts.append(np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1))
    pairs = unique_rows(np.concatenate(parts).reshape(-1, 2))[0] if parts else np.zeros((0, 2), np.int64)
    return pairs[_seen_together_mask(pairs, ua, ub, nrm, slack)]


def point_candidates(scene, point_ids):
    """Candidate node lines of free points, in the reference's form (same generator
    tuples, same line constructions: :mod:`viscx.skeleton.reference`).

    Parameters
    ----------
    scene : Scene
        With the points appended (:func:`viscx.skeleton.points.with_points`).
    point_ids : (k,) int

    Returns
    -------
    kind : (m,) int8
    generators : (m, 4) int64
    origins, directions : (m, 3) float64
    """
    gv = np.setdiff1d(scene.generator_vertices, point_ids)
    ge = scene.generator_edges
    ev = scene.half_edges.edge_vertices[ge]
    lines = edge_lines(scene, ge)
    kinds, gens, origins, dirs = [], [], [], []
    for p in np.asarray(point_ids, dtype=np.int64):
        x = scene.vertices[p]
        # VV (u, p): u < p always (points come after the mesh vertices)
        kinds.append(np.full(len(gv), VV))
        gens.append(np.stack([gv, np.full_like(gv, p), np.full_like(gv, -1), np.full_like(gv, -1)], axis=1))
        origins.append(scene.vertices[gv])
        dirs.append(x - scene.vertices[gv])
        # VEE (p, e1, e2): edge pairs one line through p meets (edges sharing a vertex never
        # are two generators of one node)
        a, b = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
        dist = np.minimum(np.linalg.norm(a - x, axis=1), np.linalg.norm(b - x, axis=1))
        slack = 4 * scene.epsilon / np.maximum(dist, 1e-300) + ANGLE_TOLERANCE
        pairs = edge_pairs_seen_together(x, a, b, slack)
        i, j = pairs[:, 0], pairs[:, 1]
        shared = (ev[i][:, :, None] == ev[j][:, None, :]).any(axis=(1, 2))
        i, j = i[~shared], j[~shared]
        d = line_through_point_and_two_lines(np.tile(x, (len(i), 1)), lines[i], lines[j])
        fine = np.linalg.norm(d, axis=1) > 0
        i, j, d = i[fine], j[fine], d[fine]
        fine = ~inner_edge_blocks(scene, x, ge[i], ge[j], d)
        i, j, d = i[fine], j[fine], d[fine]
        kinds.append(np.full(len(i), VEE))
        gens.append(np.stack([np.full_like(i, p), ge[i], ge[j], np.full_like(i, -1)], axis=1))
        origins.append(np.tile(x, (len(i), 1)))
        dirs.append(d)
    if not kinds:
        return np.zeros(0, np.int8), np.zeros((0, 4), np.int64), np.zeros((0, 3)), np.zeros((0, 3))
    return (np.concatenate(kinds).astype(np.int8), np.concatenate(gens).astype(np.int64).reshape(-1, 4),
            np.concatenate(origins).reshape(-1, 3), np.concatenate(dirs).reshape(-1, 3))


#: Angle (radians) by which both faces of an edge must stand off the line for
#: :func:`inner_edge_blocks` to decide without the tangency test: far above the rounding
#: of the wedges' projections (1e-15 / this) and the tangency's angle tolerance (1e-9).
BLOCK_MARGIN = 1e-4


def inner_edge_blocks(scene, p, e1, e2, d):
    """Which VEE candidates (p, e1, e2) of a free point p are no node because the line meets
    the nearer edge first and is blocked there.

    With p at one end of the line (both edge points on one side of it), the nearer edge
    point is an inner generator and must be passed (node condition 2). The line lies in the
    plane Π of p and that edge; the edge's two faces are half-planes along it, and when
    they lie strictly on opposite sides of Π (an edge seen from p between a face turned
    towards p and one turned away) their projections along the line cover its
    surroundings: the surface separates the line's rays there, whatever else touches the
    point, so validation (:func:`viscx.skeleton.nodes.maximal_free_segments`) would drop
    the candidate. Decided only where both faces stand off the line by BLOCK_MARGIN and
    the point lies inside the edge, farther than twice the epsilon and the weld tolerance
    from its ends (elsewhere the candidate is left to validation). Most of a large mesh's
    candidates are such pairs (122,892 triangles: all but a few hundred).

    Parameters
    ----------
    p : (3,) float
    e1, e2 : (m,) int
        Generator edge ids.
    d : (m, 3) float
        Direction of each candidate's line.

    Returns
    -------
    (m,) bool
    """
    he = scene.half_edges
    if len(d) == 0:
        return np.zeros(0, bool)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    ev = he.edge_vertices
    # the point of each edge on the line, and its signed place along it
    where, t = [], []
    for e in (e1, e2):
        a, b = scene.vertices[ev[e, 0]], scene.vertices[ev[e, 1]]
        s, _ = segment_parameter(np.broadcast_to(p, a.shape), d, a, b)
        where.append(s)
        t.append(np.einsum("ij,ij->i", a + np.nan_to_num(s)[:, None] * (b - a) - p, d))
    first = np.abs(t[0]) <= np.abs(t[1])
    inner = np.where(first, e1, e2)
    s = np.where(first, where[0], where[1])
    one_side = t[0] * t[1] > 0
    a, b = scene.vertices[ev[inner, 0]], scene.vertices[ev[inner, 1]]
    length = np.linalg.norm(b - a, axis=1)
    keep_off = 2 * max(scene.epsilon, scene.weld_tolerance)
    with np.errstate(invalid="ignore"):
        inside = (s * length > keep_off) & ((1 - s) * length > keep_off)
    # the edge's faces: (half-edge, face) pairs of edges with exactly two
    count = np.bincount(he.edge, minlength=len(ev))
    order = np.argsort(he.edge, kind="stable")
    at = np.searchsorted(he.edge[order], inner)
    two = count[inner] == 2
    h0, h1 = order[np.minimum(at, len(order) - 1)], order[np.minimum(at + 1, len(order) - 1)]
    plane = np.cross(a - p, b - p)
    plane /= np.maximum(np.linalg.norm(plane, axis=1), 1e-300)[:, None]
    side, off = [], []
    for h in (h0, h1):
        n = scene.face_normal[he.face[h]]
        run = scene.vertices[he.end[h]] - scene.vertices[he.start[h]]
        into = np.cross(n, run / np.linalg.norm(run, axis=1, keepdims=True))  # faces lie left of their half-edges
        side.append(np.einsum("ij,ij->i", plane, into))
        off.append(np.abs(np.einsum("ij,ij->i", n, d)))  # the line's angle with the face's plane
    apart = (side[0] * side[1] < 0) & (off[0] > BLOCK_MARGIN) & (off[1] > BLOCK_MARGIN)
    return one_side & inside & two & apart


def point_nodes(scene, point_ids):
    """The nodes (VV and VEE) of free points, validated like every node.

    Parameters
    ----------
    scene : Scene
        With the points appended (:func:`viscx.skeleton.points.with_points`).
    point_ids : (k,) int

    Returns
    -------
    Nodes
        In canonical order (:func:`viscx.skeleton.nodes.sort_nodes`).
    """
    return validate_candidates(scene, *point_candidates(scene, point_ids))


def point_node_incidences(scene, nodes):
    """The families (p, e) of points p that each node of theirs lies on: VEE (p, e1, e2) on
    (p, e1) and (p, e2); VV (u, p) on (p, e) for every generator edge e at u, and for every
    generator edge passing through u (a T-junction: the half-edges do not join u to e, yet
    the family's lines turn the corner there).

    Parameters
    ----------
    scene : Scene
        Holding the points as vertices.
    nodes : Nodes
        The points' nodes (:func:`point_nodes`: the point last in VV, first in VEE).

    Returns
    -------
    families : (m, 2) int
        (p, e) of each incidence.
    rows : (m,) int
        The node's row.
    """
    fam_rows, node_rows = [], []
    vee = np.flatnonzero(nodes.kind == VEE)
    for slot in (1, 2):
        fam_rows.append(nodes.generators[vee][:, [0, slot]])
        node_rows.append(vee)
    vv = np.flatnonzero(nodes.kind == VV)
    u, p = nodes.generators[vv, 0], nodes.generators[vv, 1]
    vo, ve = vertex_edges(scene)
    r, k = expand_ranges(vo[u], np.diff(vo)[u])
    fam_rows.append(np.stack([p[r], ve[k]], axis=1))
    node_rows.append(vv[r])
    r, through = edges_through(scene, u)
    fam_rows.append(np.stack([p[r], through], axis=1))
    node_rows.append(vv[r])
    return np.concatenate(fam_rows).reshape(-1, 2), np.concatenate(node_rows).astype(np.int64)


def edges_through(scene, vertices):
    """Generator edges whose interior passes within the weld tolerance of each vertex
    (T-junctions), found among the edges of the faces touching it.

    Parameters
    ----------
    vertices : (q,) int

    Returns
    -------
    row : (k,) int
        Index into ``vertices``.
    edge : (k,) int
    """
    tol = scene.weld_tolerance
    uniq, inv = np.unique(np.asarray(vertices, dtype=np.int64), return_inverse=True)
    owner, face = faces_near(scene, scene.vertices[uniq], tol)
    he = scene.half_edges
    by_face = np.argsort(he.face, kind="stable")
    first = np.searchsorted(he.face[by_face], face)
    k, h = expand_ranges(first, np.searchsorted(he.face[by_face], face, "right") - first)
    h = by_face[h]
    e = he.edge[h]
    a, b = scene.vertices[he.start[h]], scene.vertices[he.end[h]]
    x = scene.vertices[uniq[owner[k]]]
    ab = b - a
    t = np.einsum("ij,ij->i", x - a, ab) / np.einsum("ij,ij->i", ab, ab)
    dist = np.linalg.norm(x - a - np.clip(t, 0, 1)[:, None] * ab, axis=1)
    length = np.linalg.norm(ab, axis=1)
    ok = (dist <= tol) & (t * length > tol) & ((1 - t) * length > tol) & he.edge_is_generator[e]
    pairs = np.unique(np.stack([owner[k][ok], e[ok]], axis=1), axis=0)
    # back to the (repeated) query rows
    rows, edges = [], []
    for q, edge in pairs:
        hit = np.flatnonzero(inv.reshape(-1) == q)
        rows.append(hit)
        edges.append(np.full(len(hit), edge))
    if not rows:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(rows), np.concatenate(edges)
