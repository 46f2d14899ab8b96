"""V1 events: planar E4 events, the families through each node, the ends of each
family's domain, junctions, and the coplanar events of same-plane VE families.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from viscx.arrays import expand_ranges, first_of_rows, row_norms, unique_rows, unique_sorted
from viscx.geometry.lines import segment_parameter
from viscx.parallel import map_chunks, row_chunks
from viscx.scene.neighbourhood import faces_near
from viscx.skeleton.arcs.kinds import CHUNK, EEE, END_COPLANAR, END_CROSSING, END_ENDPOINT, END_JUNCTION, VE
from viscx.skeleton.arcs.lines import family_lines, judge_samples
from viscx.skeleton.arcs.pencils import edges_crossing_planes, pairs_within_groups, plane_chunk
from viscx.skeleton.generators import canonical_eee, edge_geometry, edges_through_vertices, vertex_edges
from viscx.skeleton.nodes import E4, Nodes, VEE, VV, face_planes, first_triangles, nodes_among, sort_nodes, validate_candidates
from viscx.tolerances import ANGLE_MARGIN, ANGLE_TOLERANCE, END_SAMPLE_EPSILONS




def planar_events(scene, scope=None):
    """The planar E4 events: lines in the plane of two generator edges sharing a vertex
    that meet two more generator edges, validated as nodes (with a ``scope``, those with
    an edge in it: :meth:`viscx.skeleton.scope.Scope.nodes`).

    V0 leaves them out (two of the four edges share an endpoint); they end EEE
    arcs where the line turns into a face's plane at one of its edges (Durand's
    FEE events) or into the plane of two edges of one vertex.

    The edges crossing the pairs' planes (tens of millions on a 3001-polygon city) are
    found for blocks of pairs at a time (:func:`_planar_candidates`): memory holds one
    block's crossings and the candidate lines, not every crossing at once.

    Returns
    -------
    Nodes
        Kind E4, generators the four edges increasing, one line per quadruple.
    """
    vo, ve = vertex_edges(scene)
    # pairs of generator edges at one vertex
    owner = np.repeat(np.arange(scene.n_vertices), np.diff(vo))
    i, j = pairs_within_groups(owner)
    if len(i) == 0:
        return _no_events(scene)
    pa, pb, pw = ve[i], ve[j], owner[i]
    w = scene.vertices[pw]
    other = lambda e: np.where(scene.half_edges.edge_vertices[e, 0] == pw, scene.half_edges.edge_vertices[e, 1], scene.half_edges.edge_vertices[e, 0])  # noqa: E731
    ua, ub = scene.vertices[other(pa)] - w, scene.vertices[other(pb)] - w
    normal = np.cross(ua, ub)
    size = row_norms(normal)
    keep = size > ANGLE_TOLERANCE * row_norms(ua) * row_norms(ub)
    if scope is not None:  # an event in scope has a scope edge in the pair or crossing its plane
        keep &= scope.edges[pa] | scope.edges[pb] | scope.crosses_planes(scene, normal / np.maximum(size, 1e-300)[:, None], w)
    corner = _Corners(pa[keep], pb[keep], w[keep], normal[keep] / size[keep, None], ua[keep], ub[keep])
    del i, j, pa, pb, pw, w, ua, ub, normal, size, keep
    if scope is None:
        gens, origin, direction = _planar_candidates(scene, corner)
    else:
        gens, origin, direction = _scoped_planar_candidates(scene, scope, corner)
    if len(gens) == 0:
        return _no_events(scene)
    # validated in chunks of candidates (each line on its own), sorted once
    parts = [nodes_among(scene, np.full(r.stop - r.start, E4, np.int8), gens[r], origin[r], direction[r])
             for r in row_chunks(len(gens), CHUNK)]
    events = sort_nodes(Nodes(**{k: np.concatenate([getattr(n, k) for n in parts])
                                 for k in Nodes.__dataclass_fields__}))
    first = first_of_rows(events.generators)
    return Nodes(**{k: getattr(events, k)[first] for k in events.__dataclass_fields__})


@dataclass
class _Corners:
    """The pairs of generator edges (``pa``, ``pb``: (k,) int) at one vertex ``w`` ((k, 3)
    float) that span a plane: its unit ``normal`` and the edges' vectors from w, ``ua``
    and ``ub`` ((k, 3) float)."""

    pa: np.ndarray
    pb: np.ndarray
    w: np.ndarray
    normal: np.ndarray
    ua: np.ndarray
    ub: np.ndarray

    def __len__(self):
        return len(self.pa)


#: Corner pairs whose crossing edges :func:`_planar_candidates` finds at once (rounded to
#: whole chunks of :func:`viscx.skeleton.arcs.pencils.edges_crossing_planes`).
PLANAR_BLOCK = 1 << 13


def _planar_blocks(scene, n):
    """Consecutive slices of ``range(n)`` corner pairs, each about PLANAR_BLOCK pairs and a
    whole number of :func:`edges_crossing_planes`'s chunks of planes (so that each plane
    is tested in the same chunk as when all are passed at once: the same products)."""
    inner = plane_chunk(scene)
    return row_chunks(n, inner * max(1, PLANAR_BLOCK // inner))


def _planar_candidates(scene, corner):
    """The candidate lines of the planar events, one per quadruple of generator edges:
    for each corner pair, the lines through two edges crossing its plane that cut the
    corner (:func:`_corner_cutting_pairs`) and cross both of its edges, in blocks of
    pairs (:func:`_planar_blocks`).

    A quadruple can be proposed by two corner pairs; its line is the one the whole scene's
    pass meets first: candidates ordered by (j - i, i) over every crossing (i < j the
    crossings' rows, as :func:`_corner_cutting_pairs` orders one block's), which a block
    gives with i shifted by the crossings of the blocks before.

    Returns
    -------
    gens : (c, 4) int64
        Increasing, distinct rows.
    origin, direction : (c, 3) float
    """
    gens, origin, direction, span, at = [], [], [], [], []
    shift = 0
    for rows in _planar_blocks(scene, len(corner)):
        cp, ce, cq = edges_crossing_planes(scene, corner.normal[rows], corner.w[rows])
        cp += rows.start
        ci, cj, g, o, d = _corner_lines(scene, corner, cp, ce, cq)
        # a quadruple's first line in this block (the block's order is the whole pass's)
        first = first_of_rows(g)
        gens.append(g[first])
        origin.append(o[first])
        direction.append(d[first])
        span.append((cj - ci)[first])
        at.append(ci[first] + shift)
        shift += len(cp)
        del cp, ce, cq, ci, cj, g, o, d, first
    gens, origin, direction = np.concatenate(gens), np.concatenate(origin), np.concatenate(direction)
    order = np.lexsort([np.concatenate(at), np.concatenate(span)])
    first = order[first_of_rows(gens[order])]
    return gens[first], origin[first], direction[first]


def _scoped_planar_candidates(scene, scope, corner):
    """:func:`_planar_candidates` of a scoped build: the crossings that can make an event
    in scope (:func:`viscx.skeleton.scope.planar_crossings`), a quadruple's line the
    full build's (:func:`viscx.skeleton.scope.full_build_order`)."""
    from viscx.skeleton.scope import full_build_order, planar_crossings

    cp, ce, cq, rank = planar_crossings(scene, scope, scope.edges[corner.pa] | scope.edges[corner.pb], corner.normal,
                                        corner.w, corner.ua, corner.ub)
    ci, cj, gens, origin, direction = _corner_lines(scene, corner, cp, ce, cq)
    # (a quadruple's rows are all kept or all dropped: the same first line)
    mine = scope.nodes(np.full(len(gens), E4), gens)
    ci, cj, gens, origin, direction = ci[mine], cj[mine], gens[mine], origin[mine], direction[mine]
    # a quadruple proposed twice keeps the full build's row
    order = full_build_order(scene, gens, cp, ci, cj, rank, ce, corner.normal, corner.w)
    gens, origin, direction = gens[order], origin[order], direction[order]
    first = first_of_rows(gens)
    return gens[first], origin[first], direction[first]


def _corner_lines(scene, corner, cp, ce, cq):
    """The lines through two edges crossing a corner pair's plane (the pair ``cp``, the
    edge ``ce``, where it crosses ``cq``; grouped by pair, ascending) that cut the
    corner and cross both of the pair's edges, with four distinct edges, in the order
    of :func:`_corner_cutting_pairs`.

    Returns
    -------
    ci, cj : (c,) int
        The two crossings' rows.
    gens : (c, 4) int64
        The quadruple, increasing.
    origin, direction : (c, 3) float
        The line from crossing ci to crossing cj.
    """
    # (the pair's own edges and the edges at w do not cross the plane strictly)
    # the crossings in the corner's affine frame: q - w = x ua + y ub
    ua, ub, rel = corner.ua[cp], corner.ub[cp], cq - corner.w[cp]
    n = corner.normal[cp]
    det = np.einsum("ij,ij->i", np.cross(ua, ub), n)
    x = np.einsum("ij,ij->i", np.cross(rel, ub), n) / det
    y = np.einsum("ij,ij->i", np.cross(ua, rel), n) / det
    del ua, ub, rel, n, det
    ci, cj = _corner_cutting_pairs(x, y, cp)
    pair = cp[ci]
    origin, direction = cq[ci], cq[cj] - cq[ci]
    fine = row_norms(direction) > scene.epsilon
    # the line must cross both edges of the pair (cut the corner at w) before it is worth judging
    for e in (corner.pa, corner.pb):
        a, b = edge_geometry(scene, e[pair])
        x, _ = segment_parameter(origin, np.where(fine[:, None], direction, 1.0), a, b)
        with np.errstate(invalid="ignore"):
            fine &= (x > 0) & (x < 1)
    ci, cj, pair, origin, direction = ci[fine], cj[fine], pair[fine], origin[fine], direction[fine]
    gens = np.sort(np.stack([corner.pa[pair], corner.pb[pair], ce[ci], ce[cj]], axis=1), axis=1)
    distinct = np.all(np.diff(gens, axis=1) > 0, axis=1)
    return ci[distinct], cj[distinct], gens[distinct], origin[distinct], direction[distinct]


def _corner_cutting_pairs(x, y, group, slack=1e-9):
    """Index pairs i < j within one group of points whose line may cross both open sides
    of the corner at the origin, (0, 0)-(1, 0) and (0, 0)-(0, 1): a superset of those
    whose line crosses them farther than ``slack`` from their ends (nearer, the line is
    degenerate and validation, which wants epsilon, rejects it), in the order of
    :func:`pairs_within_groups`.

    Output-sensitive, by duality: the line through (α, 0) and (0, β) holds P = (x, y)
    iff x a + y b = 1 with (a, b) = (1/α, 1/β), so the lines crossing both sides are
    the points of the region R = {a > 1, b > 1}, each point P is a line L_P, and two
    points lie on a corner-cutting line iff L_P and L_Q meet inside R. R is convex:
    two lines meet inside it iff their chords' ends interleave along its boundary,
    walked from the corner (1, 1) along b = 1 (τ = 1 - α), over the line at infinity
    (τ = 1 + |x| / (|x| + |y|), the chord's direction there) and back along a = 1
    (τ = 2 + β). Sorting the chords by their first end, each chord's partners are
    those starting within it and ending beyond it.

    Parameters
    ----------
    x, y : (k,) float
        The points in the corner's affine frame.
    group : (k,) int
        Sorted; pairs are formed within a group only.

    Returns
    -------
    i, j : (p,) int
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = x / (1 - y)  # where L_P meets b = 1
        beta = y / (1 - x)  # and a = 1
        at_inf = 1 + np.abs(x) / (np.abs(x) + np.abs(y))
    loose = lambda t: np.isfinite(t) & (t >= -slack) & (t <= 1 + slack)  # noqa: E731
    margin = 10 * slack
    ends = np.stack([np.where(loose(alpha), 1 - alpha, np.nan), np.where(loose(beta), 2 + beta, np.nan),
                     np.where(x * y <= 0, at_inf, np.nan)], axis=1)
    # a line through the corner (1, 1) meets both sides there: one end (τ = 0, also 3)
    ends[(ends[:, 0] <= margin) & (ends[:, 1] >= 3 - margin), 1] = np.nan
    has = np.sum(np.isfinite(ends), axis=1) >= 2  # the other lines miss R
    idx = np.flatnonzero(has)
    s0, s1 = np.nanmin(ends[idx], axis=1), np.nanmax(ends[idx], axis=1)
    order = np.lexsort([s0, group[idx]])
    idx, s0, s1 = idx[order], s0[order], s1[order]
    key = group[idx] * 4.0 + s0  # τ < 3 < 4: one sorted key per group
    lo = np.searchsorted(key, group[idx] * 4.0 + s0 - margin, "left")
    hi = np.searchsorted(key, group[idx] * 4.0 + s1 + margin, "right")
    count = _interleaving(idx, s1, lo, hi, margin, np.zeros((0, 2), np.int64))
    pairs = np.empty((count, 2), np.int64)
    _interleaving(idx, s1, lo, hi, margin, pairs)
    pairs, _ = unique_rows(pairs)
    i, j = pairs[:, 0], pairs[:, 1]
    order = np.lexsort([i, j - i])
    return i[order], j[order]


@njit(cache=True, nogil=True)
def _interleaving(idx, s1, lo, hi, margin, out):
    """(min, max) of idx[a], idx[b] for every chord a and chord b starting within it
    (lo[a] <= b < hi[a], b != a) that ends beyond it (s1[b] >= s1[a] - margin), into
    ``out`` when it has room: how many there are."""
    k = 0
    for a in range(len(lo)):
        for b in range(lo[a], hi[a]):
            if b != a and s1[b] >= s1[a] - margin:
                if k < len(out):
                    out[k, 0], out[k, 1] = min(idx[a], idx[b]), max(idx[a], idx[b])
                k += 1
    return k


def _no_events(scene):
    return validate_candidates(scene, np.zeros(0, np.int8), np.zeros((0, 4), np.int64), np.zeros((0, 3)), np.zeros((0, 3)))


def family_incidences(scene, events):
    """The families each event lies on.

    A node's line through a vertex w also meets the edges passing through w (w a
    T-junction inside them: a lintel's corner on a jamb's edge, a desk panel's corner on
    the top's edge): VE (u, E) for a VV node (u, w) and EEE (E, e1, e2) for a VEE node
    (w, e1, e2) lie on the node too. Those families may hold no other event (the lines
    from a window's corner through the far window's jamb between its sill and lintel,
    floor_plan((1, 1))), so they are seeded here; the node is their junction event
    (:func:`domain_ends`), so they are returned apart, without it.

    Returns
    -------
    kind : (k,) int
    generators : (k, 3) int
        Canonical family generators.
    event : (k,) int
        Row of ``events``.
    through : (k,) bool
        Found through an edge passing through the node's vertex: a family to seed, not
        an event to add.
    """
    vo, ve = vertex_edges(scene)
    is_gen_vertex = np.diff(vo) > 0
    kind, gens_, rows_ = _incidences(scene, events, vo, ve, is_gen_vertex)
    jo, je = edges_through_vertices(scene)
    tkind, tgens, trows = _incidences(scene, events, jo, je, is_gen_vertex, through=True)
    return (np.r_[kind, tkind], np.concatenate([gens_, tgens]), np.r_[rows_, trows],
            np.r_[np.zeros(len(kind), bool), np.ones(len(tkind), bool)])


def _incidences(scene, events, vo, ve, is_gen_vertex, through=False):
    """:func:`family_incidences` with the edges at each vertex given (CSR ``vo``, ``ve``):
    the vertex's own edges, or (``through``) those passing through it, for which only
    the families of a vertex's edges are found (not those the node's own generators give)."""
    kinds, gens, rows = [], [], []

    e4 = np.flatnonzero(events.kind == E4) if not through else np.zeros(0, np.int64)
    for drop in range(4):
        keep = [j for j in range(4) if j != drop]
        kinds.append(np.full(len(e4), EEE))
        gens.append(canonical_eee(scene, events.generators[e4][:, keep]))
        rows.append(e4)

    vee = np.flatnonzero(events.kind == VEE)
    g = events.generators[vee]
    for slot in (1, 2) if not through else ():
        kinds.append(np.full(len(vee), VE))
        gens.append(np.stack([g[:, 0], g[:, slot], np.full(len(vee), -1)], axis=1))
        rows.append(vee)
    # EEE (e_v, e1, e2) for every generator edge e_v at v
    r, k = expand_ranges(vo[g[:, 0]], np.diff(vo)[g[:, 0]])
    e_v = ve[k]
    kinds.append(np.full(len(r), EEE))
    gens.append(canonical_eee(scene, np.stack([e_v, g[r, 1], g[r, 2]], axis=1)))
    rows.append(vee[r])

    # a VEE line lying in the plane of two edges at v (v and e1 on one face) also ends the
    # pencil of lines in that plane through the other edge's point: EEE (e_v, e_v', e2)
    owner = np.repeat(np.arange(scene.n_vertices), np.diff(vo))
    pi, pj = pairs_within_groups(owner)
    pair_offsets = np.searchsorted(owner[pi], np.arange(scene.n_vertices + 1))
    r, pr = expand_ranges(pair_offsets[g[:, 0]], np.diff(pair_offsets)[g[:, 0]])
    ea, eb = ve[pi[pr]], ve[pj[pr]]
    x = scene.vertices[g[r, 0]]
    a1, b1 = edge_geometry(scene, ea)
    a2, b2 = edge_geometry(scene, eb)
    normal = np.cross(b1 - a1, b2 - a2)
    normal /= np.maximum(row_norms(normal)[:, None], 1e-300)
    in_plane = np.abs(np.einsum("ij,ij->i", normal, events.direction[vee[r]])) <= ANGLE_TOLERANCE
    in_plane &= not through
    for held, free in ((1, 2), (2, 1)):
        ah, bh = edge_geometry(scene, g[r, held])
        holds = in_plane.copy()
        for q in (ah, bh):
            holds &= np.abs(np.einsum("ij,ij->i", normal, q - x)) <= scene.epsilon
        kinds.append(np.full(np.count_nonzero(holds), EEE))
        gens.append(canonical_eee(scene, np.stack([ea[holds], eb[holds], g[r[holds], free]], axis=1)))
        rows.append(vee[r[holds]])

    vv = np.flatnonzero(events.kind == VV)
    g = events.generators[vv]
    for own, other in ((0, 1), (1, 0)):
        r, k = expand_ranges(vo[g[:, other]], np.diff(vo)[g[:, other]])
        e = ve[k]
        if through:  # not along an edge through both vertices: its lines all lie on that edge
            a, b = edge_geometry(scene, e)
            off = row_norms(np.cross(b - a, scene.vertices[g[r, own]] - a)) / row_norms(b - a)
            r, e = r[off > scene.weld_tolerance], e[off > scene.weld_tolerance]
        kinds.append(np.full(len(r), VE))
        gens.append(np.stack([g[r, own], e, np.full(len(r), -1)], axis=1))
        rows.append(vv[r])

    kind = np.concatenate(kinds)
    gens = np.concatenate(gens).reshape(-1, 3)
    rows = np.concatenate(rows)
    ok = gens[:, 0] >= 0
    ok[kind == VE] &= is_gen_vertex[gens[kind == VE, 0]]
    return kind[ok], gens[ok], rows[ok]


def vertex_planes(scene):
    """(k, 2) int: (vertex, plane) rows, sorted and unique: the planes (:func:`face_planes`)
    of the faces touching each generator vertex, contacts geometric (within the weld
    tolerance, as tangency's). Cached on the scene."""
    return scene.cached("vertex_planes", _vertex_planes)


def _vertex_planes(scene):
    gv = scene.generator_vertices
    pos, face = faces_near(scene, scene.vertices[gv], scene.weld_tolerance)
    return np.unique(np.stack([gv[pos], face_planes(scene)[face]], axis=1), axis=0).reshape(-1, 2)


def face_plane_crossings(scene, fkind, fgens, near=None):
    """Where the edge e of each VE family (v, e) crosses the plane P of a face touching v,
    strictly inside e: the family's line there lies in P (rule 16); given ``near`` (the
    family (k,) int and s (k,) float of other events, the domain's ends 0 and 1 always
    among them), only those within END_SAMPLE_EPSILONS epsilon of one along e.

    Lines of the family on either side of it pass P's faces on either side, so its state
    can change there: the line grazes a face of P at v, or (P holding other faces, a desk's
    front plane through its two panels and its top) passes or meets another face of P.
    V0 drops such lines unless they meet one more generator where grazing is excused. The
    first samples of an interval, 20 epsilon from its ends, see a change farther than that
    from both (they disagree, the change is bisected), but miss one closer to an event:
    office(120, 103), vertex 91, a desk panel's floor corner in the desk's front plane, and
    the top edge of another desk whose front lies 8 epsilon behind that plane (its arc ran
    on through the other panel to the edge's end, 8 epsilon too far). Only those are
    events, and only where the lines one epsilon before and after them differ: the others
    would only move the samples of arcs already found, or cut a short interval next to an
    edge's end whose samples fall within epsilon of it (no valid line: office(120, 103), VE
    (68, e132), whose arc then ended at a transition there, not at the node at the end).

    Returns
    -------
    family, s, kind, index : (q,)
        Row of the families, parameter on e, END_CROSSING, and e (the edge crossing P).
    """
    f = np.flatnonzero(fkind == VE)
    vp = vertex_planes(scene)
    lo = np.searchsorted(vp[:, 0], fgens[f, 0], "left")
    r, k = expand_ranges(lo, np.searchsorted(vp[:, 0], fgens[f, 0], "right") - lo)
    plane_of_face = face_planes(scene)
    face_of = np.zeros(plane_of_face.max() + 1, np.int64)
    face_of[plane_of_face] = np.arange(scene.n_faces)
    face = face_of[vp[k, 1]]
    normal, offset = scene.face_normal[face], scene.face_offset[face]
    a, b = edge_geometry(scene, fgens[f[r], 1])
    h0 = np.einsum("ij,ij->i", normal, a) - offset
    h1 = np.einsum("ij,ij->i", normal, b) - offset
    tol = scene.weld_tolerance
    cross = (h0 * h1 < 0) & (np.abs(h0) > tol) & (np.abs(h1) > tol)
    fam, s = f[r[cross]], h0[cross] / (h0[cross] - h1[cross])
    if near is not None:
        a, b = edge_geometry(scene, fgens[fam, 1])
        tol = END_SAMPLE_EPSILONS * scene.epsilon / row_norms(b - a)
        close = (s <= tol) | (s >= 1 - tol)  # the domain's ends
        key = np.sort(near[0] + 1j * np.clip(np.nan_to_num(near[1], nan=-1.0), 0.0, 1.0))  # (family, s) sorted
        at = np.searchsorted(key, fam + 1j * s)
        for k in (at - 1, at) if len(key) else ():  # the events just before and after
            k = np.clip(k, 0, len(key) - 1)
            close |= (key.real[k] == fam) & (np.abs(key.imag[k] - s) <= tol)
        fam, s = fam[close], s[close]
        # ... where something changes: the lines one epsilon before and after differ (a short
        # interval next to an edge's end cut where nothing changes would be sampled within
        # epsilon of that end, where no line is valid, and its arc end there, not at the node)
        step = scene.epsilon / row_norms(b - a)[close]
        if len(fam) == 0:
            return fam, s, np.full(0, END_CROSSING), fam
        gens = np.repeat(fgens[fam], 2, axis=0)
        smp = judge_samples(scene, np.full(len(gens), VE), gens, np.clip(np.c_[s - step, s + step].ravel(), 0.0, 1.0),
                            sides=True)
        state = np.concatenate([smp.state, smp.sides], axis=1).reshape(len(fam), 2, -1)
        change = np.any(state[:, 0] != state[:, 1], axis=1)
        fam, s = fam[change], s[change]
    return fam, s, np.full(len(fam), END_CROSSING), fgens[fam, 1]


def same_plane_ve(scene):
    """(v, e, -1) for every generator vertex v and generator edge e lying in the plane of a
    face touching v, e not at v and v not on e's line.

    Such families hold no node in general position when the face is a triangle (they
    run between the lines along the vertex's two edges), and in degenerate scenes
    their arcs often end only at dropped events (a block's corner on the floor and
    another block's bottom edge: every line of the family lies on the floor). Contacts
    are geometric (within the weld tolerance, as tangency's): v touches the face (a
    block's bottom corner touches the floor) and e bounds a face of the plane or lies
    on one (a block's bottom edge on the floor: its ends and middle touch it).
    """
    he = scene.half_edges
    tol = scene.weld_tolerance
    plane = face_planes(scene)
    ge = scene.generator_edges
    vp = vertex_planes(scene)
    # (edge, plane): the planes of its own faces, and of faces it lies on
    own = he.edge_is_generator[he.edge]
    ep = [np.stack([he.edge[own], plane[he.face[own]]], axis=1)]
    ev = he.edge_vertices[ge]
    a, b = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
    for point in (a, 0.5 * (a + b), b):
        pos, face = faces_near(scene, point, tol)
        n, off = scene.face_normal[face], scene.face_offset[face]
        inside = (np.abs(np.einsum("ij,ij->i", n, a[pos]) - off) <= tol) & (np.abs(np.einsum("ij,ij->i", n, b[pos]) - off) <= tol)
        ep.append(np.stack([ge[pos[inside]], plane[face[inside]]], axis=1))
    ep = np.unique(np.concatenate(ep), axis=0).reshape(-1, 2)
    # join on the plane, in blocks of (vertex, plane) rows: a city's floor alone joins
    # millions of its vertices with its edges, each pair some 200 bytes of temporaries
    order = np.argsort(ep[:, 1], kind="stable")
    first = np.searchsorted(ep[order, 1], vp[:, 1], "left")
    count = np.searchsorted(ep[order, 1], vp[:, 1], "right") - first
    fam = []
    for rows in row_blocks(count, CHUNK * 10):
        r, k = expand_ranges(first[rows], count[rows])
        r += rows.start
        k = order[k]
        v, e = vp[r, 0], ep[k, 0]
        ends = he.edge_vertices[e]
        x, a, b = scene.vertices[v], scene.vertices[ends[:, 0]], scene.vertices[ends[:, 1]]
        u = (b - a) / row_norms(b - a)[:, None]
        off_line = row_norms(np.cross(x - a, u)) > tol
        ok = (ends != v[:, None]).all(axis=1) & off_line
        fam.append(np.stack([v[ok], e[ok], ep[k[ok], 1]], axis=1))
    # (ids are non-negative: unique_rows' order is np.unique's, lexicographic)
    fam, _ = unique_rows(np.concatenate(fam).reshape(-1, 3))
    return fam[:, :2], fam[:, 2], vp, ep


@dataclass
class PlanePoints:
    """The points of each plane where lines lying in it can change (:func:`points_of_planes`),
    sorted by direction around each (vertex, plane) row of ``vp``.

    Attributes
    ----------
    vp : (k, 2) int
        (vertex, plane) rows, sorted and unique.
    point : (p, 3) float
        The points; ``vertex`` (p,) names each: the vertex, -1 for a junction, -2 - edge
        for an edge crossing the plane; ``rank`` (p,) is its position in plane order,
        ``order`` (p,) the inverse permutation.
    key : (j,) float
        ``row * 4 + angle`` of every (vp row, point of its plane) pair, sorted (angle
        mod π in [0, π) of the line from the row's vertex to the point), with ``point_of``
        (j,) the point.
    """

    vp: np.ndarray
    point: np.ndarray
    vertex: np.ndarray
    rank: np.ndarray
    order: np.ndarray
    key: np.ndarray
    point_of: np.ndarray


def points_of_planes(scene, planes, vp, ep, junctions):
    """The points of the given planes (:func:`face_planes` ids) at which the lines of a
    same-plane VE family can change: a generator vertex touching the plane, a junction of
    an edge lying in it, a generator edge crossing it; sorted by direction around every
    (vertex, plane) row of ``vp`` (:class:`PlanePoints`), for :func:`coplanar_join`."""
    tol = scene.weld_tolerance
    # the points of each plane: (plane, point, vertex)
    pts_plane = [vp[:, 1]]
    pts = [scene.vertices[vp[:, 0]]]
    pts_vertex = [vp[:, 0]]  # the vertex, -1 for a junction, -2 - edge for a crossing
    lo = np.searchsorted(ep[:, 0], junctions.edge, "left")  # ep is sorted by edge
    r, k = expand_ranges(lo, np.searchsorted(ep[:, 0], junctions.edge, "right") - lo)
    a, b = edge_geometry(scene, junctions.edge[r])
    pts_plane.append(ep[k, 1])
    pts.append(a + junctions.s[r, None] * (b - a))
    pts_vertex.append(junctions.vertex[r])
    # generator edges crossing each plane strictly (chunked: planes × edges)
    plane_of_face = face_planes(scene)
    face_of = np.zeros(plane_of_face.max() + 1, np.int64)
    face_of[plane_of_face] = np.arange(scene.n_faces)
    normal, offset = scene.face_normal[face_of[planes]], scene.face_offset[face_of[planes]]
    ge = scene.generator_edges
    ga, gb = edge_geometry(scene, ge)
    chunk = max(1, (1 << 22) // max(1, len(ge)))
    for c in range(0, len(planes), chunk):
        sl = slice(c, c + chunk)
        h0 = normal[sl] @ ga.T - offset[sl, None]
        h1 = normal[sl] @ gb.T - offset[sl, None]
        i, j = np.nonzero((h0 * h1 < 0) & (np.abs(h0) > tol) & (np.abs(h1) > tol))
        f = h0[i, j] / (h0[i, j] - h1[i, j])
        pts_plane.append(planes[sl][i])
        pts.append(ga[j] + f[:, None] * (gb[j] - ga[j]))
        pts_vertex.append(-2 - ge[j])
    pts_plane, pts, pts_vertex = np.concatenate(pts_plane), np.concatenate(pts), np.concatenate(pts_vertex)
    order = np.argsort(pts_plane, kind="stable")
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    # around each (vertex, plane) the plane's points sorted by the direction of their line
    # (in blocks of rows: the keys of a row lie in [4 row, 4 row + π), blocks never interleave)
    first = np.searchsorted(pts_plane[order], vp[:, 1], "left")  # vp: sorted, unique rows
    count = np.searchsorted(pts_plane[order], vp[:, 1], "right") - first
    keys, point_of = [], []
    for rows in row_blocks(count, CHUNK * 10):
        r, k = expand_ranges(first[rows], count[rows])
        r += rows.start
        w = order[k]
        x = scene.vertices[vp[r, 0]]
        direction = pts[w] - x
        far = row_norms(direction) > tol  # the family's own vertex
        r, w, direction = r[far], w[far], direction[far]
        eu, ev = _plane_bases(scene, vp[r, 1])
        angle = np.mod(np.arctan2(np.einsum("ij,ij->i", direction, ev), np.einsum("ij,ij->i", direction, eu)), np.pi)
        key = r * 4.0 + angle  # angles < π < 4: one sorted key per (vertex, plane) block
        by_key = np.argsort(key, kind="stable")
        keys.append(key[by_key])
        point_of.append(w[by_key])
    return PlanePoints(vp, pts, pts_vertex, rank, order, np.concatenate(keys), np.concatenate(point_of))


def row_blocks(count, size):
    """Consecutive slices of rows whose counts sum to about ``size`` (at least one row
    each; one empty slice for no rows)."""
    end = np.cumsum(count)
    cuts = np.searchsorted(end, np.arange(size, int(end[-1]) if len(end) else 0, size), "right")
    bounds = unique_sorted(np.r_[0, cuts, len(count)])
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])] or [slice(0, 0)]


def coplanar_candidates(scene, ve, ve_plane, points):
    """The range of :class:`PlanePoints` ``key`` each same-plane VE family's edge spans
    seen from its vertex (with ANGLE_MARGIN), as up to three pieces of its (vertex, plane)
    block (a span crossing the angle 0 = π wraps).

    Returns
    -------
    family, first, last : (q,) int
        Row of ``ve`` and the key range [first, last) of each piece.
    """
    vp = points.vp
    row = np.searchsorted(vp[:, 0] * (vp[:, 1].max() + 1) + vp[:, 1], ve[:, 0] * (vp[:, 1].max() + 1) + ve_plane)
    x = scene.vertices[ve[:, 0]]
    a, b = edge_geometry(scene, ve[:, 1])
    eu, ev = _plane_bases(scene, ve_plane)
    da = np.stack([np.einsum("ij,ij->i", a - x, eu), np.einsum("ij,ij->i", a - x, ev)], axis=1)
    db = np.stack([np.einsum("ij,ij->i", b - x, eu), np.einsum("ij,ij->i", b - x, ev)], axis=1)
    cross = da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]
    span = np.arctan2(np.abs(cross), np.einsum("ij,ij->i", da, db))  # in [0, π)
    start = np.mod(np.arctan2(np.where(cross >= 0, da[:, 1], db[:, 1]), np.where(cross >= 0, da[:, 0], db[:, 0])), np.pi)
    # a margin far above rounding: the exact test of coplanar_events decides
    lo, hi = start - ANGLE_MARGIN, start + span + ANGLE_MARGIN
    pieces = [(lo, np.minimum(hi, np.pi)), (np.full_like(lo, 0.0), hi - np.pi), (lo + np.pi, np.full_like(lo, np.pi))]
    fams, firsts, lasts = [], [], []
    for p_lo, p_hi in pieces:
        f = np.flatnonzero(p_hi > np.maximum(p_lo, 0.0))
        i0 = np.searchsorted(points.key, row[f] * 4.0 + np.maximum(p_lo[f], 0.0), "left")
        i1 = np.searchsorted(points.key, row[f] * 4.0 + np.minimum(p_hi[f], np.pi), "right")
        fams.append(f)
        firsts.append(i0)
        lasts.append(np.maximum(i1, i0))
    return np.concatenate(fams), np.concatenate(firsts), np.concatenate(lasts)


def coplanar_events(scene, ve, ve_plane, vp, ep, junctions):
    """Where each same-plane VE family's line passes a point of its plane at which the lines
    of the plane can change: a generator vertex touching the plane, a junction of an edge
    lying in it, a generator edge crossing it. Every line of such a family lies in the
    plane (degenerate events V0 does not keep: a floor corner, a block's bottom corner
    and a far edge of the floor in one line); so the family's state can change only
    there, or at an event out of the plane (its nodes).

    Parameters
    ----------
    ve : (m, 2) int
        (v, e) of the families; ``ve_plane`` (m,) their plane (:func:`face_planes`).
    vp, ep : (k, 2) int
        (vertex, plane) and (edge, plane) incidences (:func:`same_plane_ve`).

    Returns
    -------
    family : (q,) int
        Row of ``ve``.
    s : (q,) float
    kind : (q,) int
        END_COPLANAR (a vertex or a junction) or END_CROSSING (an edge crossing the plane).
    index : (q,) int
        The vertex (-1 for a junction) or the crossing edge.
    """
    return coplanar_join(scene, ve, ve_plane, points_of_planes(scene, np.unique(ve_plane), vp, ep, junctions))


def coplanar_join(scene, ve, ve_plane, points):
    """:func:`coplanar_events` with the points of the families' planes found
    (:func:`points_of_planes`): each family and the points in the range of directions its
    edge spans (output-sensitive: a family and a point of its plane pair up only when the
    line through the family's vertex and the point meets the family's edge)."""
    fam, first, last = coplanar_candidates(scene, ve, ve_plane, points)
    r, k = expand_ranges(first, last - first)
    fam, w = fam[r], points.point_of[k]
    # the ranges overlap only within the margin; the order is (family, point in plane order)
    n = len(points.point)
    fam_w = unique_sorted(fam * n + points.rank[w])
    fam, w = fam_w // n, points.order[fam_w % n]
    x = scene.vertices[ve[fam, 0]]
    a, b = edge_geometry(scene, ve[fam, 1])
    s, _ = segment_parameter(x, points.point[w] - x, a, b)
    with np.errstate(invalid="ignore"):
        inside = np.isfinite(s) & (s > 0) & (s < 1)
    which = points.vertex[w[inside]]
    crossing = which <= -2
    return (fam[inside], s[inside], np.where(crossing, END_CROSSING, END_COPLANAR),
            np.where(crossing, -2 - which, which))


def node_reach(scene, kind, generators, events, rows):
    """Distance from a VE family's vertex to the farthest generator point of each event on
    it (the points the event's line is fixed by: a VEE node's edge points, a VV node's other
    vertex); 0 for EEE families (:func:`viscx.skeleton.arcs.stages.family_intervals`, rule 14).

    Parameters
    ----------
    kind : (k,) int
    generators : (k, 3) int
    events : Nodes
    rows : (k,) int
        The event of each family incidence.

    Returns
    -------
    (k,) float
    """
    out = np.zeros(len(kind))
    v = np.flatnonzero(kind == VE)
    if len(v):
        gp = events.generator_points[rows[v]]  # (m, 4, 3), nan in unused slots
        dist = np.linalg.norm(gp - scene.vertices[generators[v, 0]][:, None], axis=2)
        out[v] = np.max(np.where(np.isfinite(dist), dist, 0.0), axis=1)
    return out


def coplanar_reach(scene, ve, s, kind, index):
    """Distance from a same-plane VE family's vertex to the point of its plane each of its
    coplanar events passes (:func:`coplanar_events`): the vertex passed, or where the crossing
    edge meets the line; 0 for a junction (a point of an edge of the plane, not named).

    Parameters
    ----------
    ve : (q, 2) int
        (v, e) of each event's family.
    s, kind, index : (q,)
        As :func:`coplanar_events` returns them.

    Returns
    -------
    (q,) float
    """
    x = scene.vertices[ve[:, 0]]
    out = np.zeros(len(s))
    w = np.flatnonzero((kind == END_COPLANAR) & (index >= 0))
    out[w] = row_norms(scene.vertices[index[w]] - x[w])
    c = np.flatnonzero(kind == END_CROSSING)
    if len(c):
        o, d = family_lines(scene, np.full(len(c), VE), np.c_[ve[c], np.full(len(c), -1)], s[c])
        a, b = edge_geometry(scene, index[c])
        t, _ = segment_parameter(a, b - a, o, o + d)  # the crossing point's parameter on the line
        out[c] = np.abs(np.nan_to_num(t)) * row_norms(d)
    return out


def hidden_events(scene, ve, s):
    """Whether each coplanar event of a same-plane VE family is hidden: the family's line
    there is blocked between its vertex and its edge, and stays blocked nearby.

    Such an event cannot change the family's state (its lines are invalid on both
    sides), so dropping it only joins two intervals that hold no arc. Most coplanar
    events are hidden (a block's corner on the floor seen from another block's corner
    through a third block): the intervals they would make grow as the cube of the
    blocks on the floor, the visible ones as the output.

    Blocked nearby: the piece from v to the edge (trimmed by epsilon, as
    :func:`viscx.skeleton.nodes.free_pieces` trims it) meets a face farther than
    epsilon from its trimmed ends and from the face's corners, and where it passes
    within epsilon of the face's boundary that edge is closed (a second face there:
    a block's side face and its bottom, which a line lying on the floor meets at
    their common edge). Lines near it then meet that face or the one beyond the edge.

    Parameters
    ----------
    ve : (m, 2) int
        (v, e) of each event's family.
    s : (m,) float
        The event's parameter on e.

    Returns
    -------
    (m,) bool
    """
    # each event on its own: in chunks on threads
    parts = map_chunks(lambda r: _hidden_events_chunk(scene, ve[r], s[r]), row_chunks(len(s), CHUNK))
    return np.concatenate(parts) if parts else np.zeros(0, dtype=bool)


def _hidden_events_chunk(scene, ve, s):
    """:func:`hidden_events` on one chunk of events."""
    eps = scene.epsilon
    x = scene.vertices[ve[:, 0]]
    a, b = edge_geometry(scene, ve[:, 1])
    vec = a + s[:, None] * (b - a) - x
    length = row_norms(vec)
    long = np.flatnonzero(length > 4 * eps)
    tri, t = first_triangles(scene, x[long], vec[long] / length[long, None], 2 * eps, length[long] - 2 * eps)
    rows = long[tri >= 0]
    face, t = scene.triangle_face[tri[tri >= 0]], t[tri >= 0]
    hit = x[rows] + (t / length[rows])[:, None] * vec[rows]
    he = scene.half_edges
    hidden = np.zeros(len(s), dtype=bool)
    hidden[rows] = ~_near_doubtful_boundary(hit, scene.loop_offsets[scene.face_loop_offsets[face]],
                                            scene.loop_offsets[scene.face_loop_offsets[face + 1]], he.start, he.end, he.opp,
                                            scene.vertices, eps)
    return hidden


@njit(cache=True, nogil=True)
def _near_doubtful_boundary(hit, first, last, start, end, opp, vertices, eps):
    """Whether each hit point lies within eps of a corner of its face, or of an open edge
    of it (no second face there), over the face's boundary half-edges first..last - 1.

    Returns
    -------
    (k,) bool
    """
    out = np.zeros(hit.shape[0], dtype=np.bool_)
    for i in range(hit.shape[0]):
        for h in range(first[i], last[i]):
            a, b = vertices[start[h]], vertices[end[h]]
            u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
            d0, d1, d2 = hit[i, 0] - a[0], hit[i, 1] - a[1], hit[i, 2] - a[2]
            # the closest point of the edge, at w along it; sums in numpy einsum's order
            w = min(max(((d0 * u0 + d2 * u2) + d1 * u1) / ((u0 * u0 + u2 * u2) + u1 * u1), 0.0), 1.0)
            e0, e1, e2 = d0 - w * u0, d1 - w * u1, d2 - w * u2
            to_edge = np.sqrt((e0 * e0 + e1 * e1) + e2 * e2)
            to_corner = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
            if to_corner <= eps or (to_edge <= eps and opp[h] < 0):
                out[i] = True
    return out


def _plane_bases(scene, planes):
    """(u, v): two unit vectors spanning each plane (:func:`face_planes` ids), (n, 3) each."""
    plane_of_face = face_planes(scene)
    face_of = np.zeros(plane_of_face.max() + 1, np.int64)
    face_of[plane_of_face] = np.arange(scene.n_faces)
    n = scene.face_normal[face_of[planes]]
    helper = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    u = np.cross(helper, n)
    u /= row_norms(u)[:, None]
    return u, np.cross(n, u)


def event_parameters(scene, kind, generators, events, rows):
    """Parameter s of each event's line on the family's parameter edge."""
    param_edge = np.where(kind == EEE, generators[:, 0], generators[:, 1])
    a, b = edge_geometry(scene, param_edge)
    s, _ = segment_parameter(events.ends[rows, 0], events.direction[rows], a, b)
    return s


def domain_ends(scene, fam_kind, fam_gens, junctions):
    """Parameters where each family's line reaches an endpoint or a junction of one of its
    edges, or (EEE) q's or r's line at infinity (the linear-fractional map's pole), within
    (0, 1) (s = 0 and 1, the parameter edge's endpoints, are added by the caller).

    VE (v, e): the junctions of e. EEE (p, q, r): those of p, and where the line
    reaches an endpoint or a junction of q or r. The map s -> x (x the line's point
    on q or r) is linear-fractional (a projectivity between two lines of a regulus, or
    a central projection for a pencil of lines in a plane), fixed by three samples; a
    pencil through a point of the edge gives a constant map and no end.

    Returns
    -------
    family : (k,) int
    s : (k,) float
    kind : (k,) int
        END_ENDPOINT or END_JUNCTION.
    vertex : (k,) int
        The junction's vertex (-1 for a crossing and for endpoints).
    """
    fams, ss, kinds, verts = [], [], [], []
    # junctions on the parameter edge (VE: e, EEE: p): s directly
    param_edge = np.where(fam_kind == EEE, fam_gens[:, 0], fam_gens[:, 1])
    f, k = _junctions_of(junctions, param_edge)
    fams.append(f)
    ss.append(junctions.s[k])
    kinds.append(np.full(len(f), END_JUNCTION))
    verts.append(junctions.vertex[k])
    e = np.flatnonzero(fam_kind == EEE)
    probes = np.array([0.2, 0.5, 0.8])
    o, d = family_lines(scene, np.full(3 * len(e), EEE), np.repeat(fam_gens[e], 3, axis=0), np.tile(probes, len(e)))
    for slot in (1, 2):
        a, b = edge_geometry(scene, np.repeat(fam_gens[e, slot], 3))
        x, _ = segment_parameter(o, np.where(row_norms(d)[:, None] > 0, d, 1.0), a, b)
        x = x.reshape(-1, 3)
        s = np.broadcast_to(probes, x.shape)
        # x = (α s + β) / (γ s + δ): (α, β, γ, δ) is the null vector of [s, 1, -x s, -x]
        system = np.stack([s, np.ones_like(s), -x * s, -x], axis=2)
        # a constant map (a pencil through a point of this edge) has no ends to find
        fine = np.all(np.isfinite(system), axis=(1, 2)) & (np.ptp(x, axis=1) > 1e-9)
        coeff = np.full((len(e), 4), np.nan)
        if fine.any():
            coeff[fine] = np.linalg.svd(system[fine])[2][:, -1]
        # the values of x to reach: the edge's endpoints, its junctions
        rows, k = _junctions_of(junctions, fam_gens[e, slot])
        fam = np.concatenate([np.arange(len(e)), np.arange(len(e)), rows])
        value = np.concatenate([np.zeros(len(e)), np.ones(len(e)), junctions.s[k]])
        al, be, ga, de = coeff[fam].T
        with np.errstate(divide="ignore", invalid="ignore"):
            fams += [e[fam], e]
            ss += [(be - value * de) / (value * ga - al), -de[: len(e)] / ga[: len(e)]]
        kinds += [np.where(np.arange(len(fam)) < 2 * len(e), END_ENDPOINT, END_JUNCTION), np.full(len(e), END_ENDPOINT)]
        verts += [np.concatenate([np.full(2 * len(e), -1), junctions.vertex[k]]), np.full(len(e), -1)]
    fam, s, kind, vertex = (np.concatenate(x) for x in (fams, ss, kinds, verts))
    keep = np.isfinite(s) & (s > 0) & (s < 1)
    return fam[keep].astype(np.int64), s[keep], kind[keep], vertex[keep].astype(np.int64)


def _junctions_of(junctions, edges):
    """(row of ``edges``, junction) for every junction of each edge."""
    lo = np.searchsorted(junctions.edge, edges, "left")
    rows, k = expand_ranges(lo, np.searchsorted(junctions.edge, edges, "right") - lo)
    return rows, k
