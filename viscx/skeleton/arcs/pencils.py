"""Pencils of touched planes: the planes of faces touched by foreign vertices or edges,
the families whose lines lie in them, and where those lines cross the plane's edges.
"""

import numpy as np
from numba import njit, prange

from viscx.arrays import unique_rows
from viscx.geometry.lines import segment_parameter
from viscx.geometry.polygon import plane_basis
from viscx.skeleton.arcs.kinds import EEE, END_COPLANAR
from viscx.skeleton.generators import canonical_eee, edge_crossings, edge_geometry
from viscx.skeleton.nodes import coplanar_partners, face_planes
from viscx.tolerances import ANGLE_TOLERANCE


def edges_crossing_planes(scene, normal, point):
    """The generator edges crossing each plane strictly (both ends farther than epsilon,
    on opposite sides), in chunks of planes × edges.

    Parameters
    ----------
    normal : (k, 3) float
        Unit normals.
    point : (k, 3) float
        A point of each plane.

    Returns
    -------
    plane : (m,) int
    edge : (m,) int
    crossing : (m, 3) float
        Where the edge crosses the plane.
    """
    ge = scene.generator_edges
    ga, gb = edge_geometry(scene, ge)
    eps = scene.epsilon
    planes, edges, points = [np.empty(0, np.int64)], [np.empty(0, np.int64)], [np.empty((0, 3))]
    chunk = plane_chunk(scene)
    for lo in range(0, len(normal), chunk):
        sl = slice(lo, lo + chunk)
        h0 = normal[sl] @ ga.T - np.einsum("ij,ij->i", normal[sl], point[sl])[:, None]
        h1 = normal[sl] @ gb.T - np.einsum("ij,ij->i", normal[sl], point[sl])[:, None]
        i, j = np.nonzero((h0 * h1 < 0) & (np.abs(h0) > eps) & (np.abs(h1) > eps))
        f = h0[i, j] / (h0[i, j] - h1[i, j])
        planes.append(i + lo)
        edges.append(ge[j])
        points.append(ga[j] + f[:, None] * (gb[j] - ga[j]))
    return np.concatenate(planes), np.concatenate(edges), np.concatenate(points)


#: Plane × edge tests per chunk of :func:`edges_crossing_planes`.
PLANE_EDGE_TESTS = 1 << 22


def plane_chunk(scene):
    """The planes :func:`edges_crossing_planes` tests at once: about PLANE_EDGE_TESTS
    plane × generator edge products (two float arrays of that size in flight)."""
    return max(1, PLANE_EDGE_TESTS // max(1, len(scene.generator_edges)))


def pairs_within_groups(group):
    """All index pairs i < j with group[i] == group[j], for a sorted group array."""
    group = np.asarray(group)
    ii, jj = [], []
    k = 1
    while k < len(group):
        i = np.flatnonzero(group[k:] == group[:-k])
        if len(i) == 0:
            break  # sorted: no longer runs
        ii.append(i)
        jj.append(i + k)
        k += 1
    if not ii:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(ii), np.concatenate(jj)


@njit(cache=True, parallel=True)
def _holds_foreign_vertex(normal, offset, face_loop_offsets, loop_offsets, loop_vertices, x, ids, tol):
    """(f,) bool: faces whose plane holds, within tol, a point x[k] that is not one of the
    face's vertices (``ids[k]`` not on its loops). Every face against every point, without
    (points × faces) temporaries: 30,732 triangles, 104 -> 1 s."""
    out = np.zeros(normal.shape[0], np.bool_)
    for f in prange(normal.shape[0]):
        n0, n1, n2, d = normal[f, 0], normal[f, 1], normal[f, 2], offset[f]
        h0, h1 = loop_offsets[face_loop_offsets[f]], loop_offsets[face_loop_offsets[f + 1]]
        for k in range(x.shape[0]):
            if abs(x[k, 0] * n0 + x[k, 1] * n1 + x[k, 2] * n2 - d) > tol:
                continue
            own = False
            for h in range(h0, h1):
                if loop_vertices[h] == ids[k]:
                    own = True
                    break
            if not own:
                out[f] = True
                break
    return out


def _touched_faces(scene):
    """(f,) bool: faces whose plane holds another face over the face's bounding box
    (:func:`viscx.skeleton.nodes.coplanar_partners`) or, anywhere, a generator vertex not
    on the face's outline (within the weld tolerance, as tangency's contacts)."""
    off, partner, _, _ = coplanar_partners(scene)
    touched = np.zeros(scene.n_faces, dtype=bool)
    touched[np.diff(off) > 0] = True
    touched[partner] = True
    gv = scene.generator_vertices
    touched |= _holds_foreign_vertex(scene.face_normal, scene.face_offset, scene.face_loop_offsets, scene.loop_offsets,
                                     scene.loop_vertices, np.ascontiguousarray(scene.vertices[gv]), gv,
                                     scene.weld_tolerance)
    return touched


def pencil_planes(scene):
    """The planes of touched faces (:func:`_touched_faces`) that a generator edge crosses,
    and which generator edges lie in each or cross it (cached on the scene).

    A line lying in such a plane P through the point H where an edge crosses it (a pencil
    of lines in P through H, :func:`contact_pencils`) passes the faces beside P that it
    touches on their outline (:func:`viscx.skeleton.nodes.first_triangles`): with two
    blocks touching face to face, the pencil across their contact crosses the outlines of
    both contact faces, four edges besides H's, and would be blocked by whichever two of
    them are not its generators (docs/queries.md, limitation 6).

    Returns
    -------
    face : (k,) int
        A face of each plane, by plane id (:func:`viscx.skeleton.nodes.face_planes`).
    role : (k, e) int8
        Per plane and edge: 1 a generator edge of a touched face of the plane (listed in
        ``incidence``), 2 a generator edge crossing the plane strictly, 0 otherwise.
    incidence : (m, 3) int
        (plane, region, edge), sorted: the generator edges of the plane's touched faces
        lying in it, by *region*, the touched faces of the plane joined across the flat
        edges they share (a face split in two of one plane), named by its lowest face id.
    """
    return scene.cached("pencil_planes", _pencil_planes)


def _pencil_planes(scene):
    he = scene.half_edges
    touched = np.flatnonzero(_touched_faces(scene))
    plane_of = face_planes(scene)
    _, first = np.unique(plane_of[touched], return_index=True)
    face = touched[first]  # one per plane, by plane id
    # planes a generator edge crosses strictly (in chunks of planes × edges)
    k, crossing, _ = edges_crossing_planes(scene, scene.face_normal[face],
                                            scene.face_normal[face] * scene.face_offset[face, None])
    keep = np.unique(k)
    face = face[keep]
    role = np.zeros((len(face), len(he.edge_vertices)), dtype=np.int8)
    role[np.searchsorted(keep, k), crossing] = 2
    # the touched faces of each plane, joined into regions across flat edges
    is_touched = np.zeros(scene.n_faces, dtype=bool)
    is_touched[touched] = True
    opp_face = np.where(he.opp >= 0, he.face[np.maximum(he.opp, 0)], -1)
    flat = np.flatnonzero(is_touched[he.face] & (he.opp >= 0) & ~he.edge_is_generator[he.edge])
    flat = flat[is_touched[opp_face[flat]] & (plane_of[opp_face[flat]] == plane_of[he.face[flat]])]
    from scipy.sparse import coo_matrix  # here: the queries import this module, and need no scipy
    from scipy.sparse.csgraph import connected_components

    n = scene.n_faces
    _, label = connected_components(coo_matrix((np.ones(len(flat)), (he.face[flat], opp_face[flat])), shape=(n, n)),
                                    directed=False)
    lowest = np.full(n, n)
    np.minimum.at(lowest, label, np.arange(n))
    region = lowest[label]  # named by its lowest face id
    h = np.flatnonzero(is_touched[he.face] & he.edge_is_generator[he.edge]) if len(face) else np.zeros(0, np.int64)
    k = np.minimum(np.searchsorted(plane_of[face], plane_of[he.face[h]]), max(len(face) - 1, 0))
    same = plane_of[face[k]] == plane_of[he.face[h]] if len(h) else np.zeros(0, bool)
    h, k = h[same], k[same]
    incidence = np.unique(np.stack([k, region[he.face[h]], he.edge[h]], axis=1), axis=0).reshape(-1, 3)
    role[incidence[:, 0], incidence[:, 2]] = 1
    return face, role, incidence


def pencil_plane_of(scene, kind, generators):
    """(m,) int: for EEE families whose lines lie in a plane of :func:`pencil_planes` (two
    generator edges in it, the third crossing it), a face of that plane; -1 elsewhere.

    Parameters
    ----------
    kind : (m,) int
    generators : (m, 3) int
    """
    out = np.full(len(kind), -1, dtype=np.int64)
    rows = np.flatnonzero(np.asarray(kind) == EEE)
    if not len(rows):  # VE lines lie in no pencil: the planes are not built for them
        return out
    face, role, incidence = pencil_planes(scene)
    if not len(face):
        return out
    g = np.asarray(generators)[rows]
    # A plane holding two of the three edges holds the first or the second: the candidate
    # planes of a family are those its first two edges lie in (role 1, few per edge), so
    # each family is judged against a handful of planes, not against every plane.
    lying, _ = unique_rows(incidence[:, [2, 0]])  # (edge, plane), by edge
    start = np.searchsorted(lying[:, 0], np.arange(role.shape[1] + 1))
    fam, plane = [], []
    for col in (0, 1):
        lo, n = start[g[:, col]], np.diff(start)[g[:, col]]
        fam.append(np.repeat(np.arange(len(g)), n))
        plane.append(lying[np.repeat(lo - np.cumsum(n) + n, n) + np.arange(n.sum()), 1])
    fam, plane = np.concatenate(fam), np.concatenate(plane)
    r = role[plane[:, None], g[fam]]  # (pairs, 3)
    ok = (np.count_nonzero(r == 1, axis=1) == 2) & (np.count_nonzero(r == 2, axis=1) == 1)
    # the lowest such plane of each family (as a loop over planes in order would keep)
    best = np.full(len(g), len(face), dtype=np.int64)
    np.minimum.at(best, fam[ok], plane[ok])
    hit = best < len(face)
    out[rows[hit]] = face[best[hit]]
    return out


def pencil_crossings(scene, plane_face, ends):
    """The edges of touched faces that the segments of pencils' lines cross.

    A line of a pencil of a touched plane (``plane_face`` >= 0, :func:`pencil_plane_of`)
    passes the faces beside its plane (:func:`pencil_planes`) and crosses, strictly inside
    (as node condition 5) and within its segment, two edges of each touched face of the
    plane it runs across.

    Parameters
    ----------
    plane_face : (m,) int
    ends : (m, 2, 3) float
        Each line's maximal free segment.

    Returns
    -------
    row : (c,) int
        Ascending.
    region, edge : (c,) int
        The crossed edge and its region of touched faces (:func:`pencil_planes`); by
        (row, region, edge).
    """
    face, role, incidence = pencil_planes(scene)
    eps = scene.epsilon
    out = [np.empty((0, 3), dtype=np.int64)]
    for k, pf in enumerate(face):
        inc = incidence[incidence[:, 0] == k]  # sorted by (region, edge)
        every = np.flatnonzero(plane_face == pf)
        if not len(every) or not len(inc):
            continue
        step = max(1, (1 << 20) // len(inc))  # rows × edges at a time: bounded temporaries
        for lo in range(0, len(every), step):
            out.append(_crossed(scene, every[lo:lo + step], inc, ends, eps))
    out = np.concatenate(out)
    out = out[np.lexsort([out[:, 2], out[:, 1], out[:, 0]])]
    return out[:, 0], out[:, 1], out[:, 2]


def _crossed(scene, rows, inc, ends, eps):
    """(c, 3) int: (row, region, edge) of :func:`pencil_crossings` for some rows of one plane."""
    a, b = edge_geometry(scene, inc[:, 2])
    r, j = np.nonzero(_crossed_mask(ends[rows, 0], ends[rows, 1], a, b, eps))
    return np.stack([rows[r], inc[j, 1], inc[j, 2]], axis=1)


@njit(cache=True, nogil=True)
def _crossed_mask(p0, p1, a, b, eps):
    """(r, k) bool: segment i (p0 → p1) crosses edge j (a → b) strictly inside the edge (as
    node condition 5: the lines' gap within eps, farther than eps from its ends) and within
    the segment (its ends may lie on the edge). The arithmetic of
    :func:`viscx.geometry.lines.segment_parameter`, pair by pair without temporaries."""
    out = np.zeros((len(p0), len(a)), dtype=np.bool_)
    for i in range(len(p0)):
        dx, dy, dz = p1[i, 0] - p0[i, 0], p1[i, 1] - p0[i, 1], p1[i, 2] - p0[i, 2]
        aa = dx * dx + dy * dy + dz * dz
        span = max(np.sqrt(aa), 1e-300)
        for j in range(len(a)):
            ex, ey, ez = b[j, 0] - a[j, 0], b[j, 1] - a[j, 1], b[j, 2] - a[j, 2]
            wx, wy, wz = a[j, 0] - p0[i, 0], a[j, 1] - p0[i, 1], a[j, 2] - p0[i, 2]
            bb = dx * ex + dy * ey + dz * ez
            cc = ex * ex + ey * ey + ez * ez
            dd = dx * wx + dy * wy + dz * wz
            ff = ex * wx + ey * wy + ez * wz
            den = aa * cc - bb * bb
            if not den > 1e-14 * aa * cc:  # parallel: no crossing point
                continue
            x = (bb * dd - aa * ff) / den
            length = np.sqrt(cc)
            if not (x * length > eps and (1 - x) * length > eps):
                continue
            s = (dd + bb * x) / aa
            gx, gy, gz = wx + x * ex - s * dx, wy + x * ey - s * dy, wz + x * ez - s * dz
            if not np.sqrt(gx * gx + gy * gy + gz * gz) <= eps:
                continue
            # along the segment, where it passes the edge's point
            t = ((wx + x * ex) * dx + (wy + x * ey) * dy + (wz + x * ez) * dz) / span
            out[i, j] = t >= -eps and t <= span + eps
    return out


def first_pencil_pair(scene, plane_face, generators, ends, valid):
    """(m,) bool: False for a pencil's line (``plane_face`` >= 0) whose two generator edges
    in the plane are not the crossed edges of the first region of touched faces it crosses
    (:func:`pencil_planes`); True elsewhere.

    Passing the faces beside the plane, one line of the pencil across several touched faces
    of the plane crosses two edges of each (:func:`pencil_crossings`), and every pair of
    them that node condition (4) admits (two edges of one face, or of faces of that plane)
    would give it an arc: one segment, several arcs over it. The first region it crosses
    (lowest face id) names it, by its two lowest crossed edges (a family of
    :func:`contact_pencils`); its arcs end where the crossed edges change
    (:func:`pencil_events`). A line crossing no region twice keeps its arcs."""
    ok = np.ones(len(plane_face), dtype=bool)
    pencil = valid & (plane_face >= 0)
    if not pencil.any():
        return ok
    row, face, edge = pencil_crossings(scene, np.where(pencil, plane_face, -1), ends)
    # each row's first (row, face) group of two crossed edges or more: its first two edges
    key = np.stack([row, face], axis=1)
    start = np.flatnonzero(np.r_[True, np.any(key[1:] != key[:-1], axis=1)])
    count = np.diff(np.r_[start, len(row)])
    start, count = start[count >= 2], count[count >= 2]
    first = start[np.r_[True, row[start[1:]] != row[start[:-1]]]] if len(start) else start
    r = row[first]
    big = np.iinfo(np.int64).max
    g = generators[r]
    face_of_plane, role, _ = pencil_planes(scene)
    by_face = np.argsort(face_of_plane)
    k = by_face[np.searchsorted(face_of_plane[by_face], plane_face[r])]
    own = np.sort(np.where(role[k[:, None], g] == 1, g, big), axis=1)[:, :2]
    # (a line crossing no region's outline twice, within its segment, keeps its arcs)
    ok[r] = (edge[first] == own[:, 0]) & (edge[first + 1] == own[:, 1])
    return ok


def pencil_events(scene, fkind, fgens):
    """The events of pencil families of touched planes (:func:`pencil_plane_of`): the
    lines through H and each vertex of the plane's touched faces or edge crossing lying
    in the plane P.

    Such a line passes its faces beside P without a stop (:func:`pencil_planes`), so the
    samples do not see where it starts or stops touching another face's outline in P
    (the pencil entering the crack between two blocks touching face to face, where its
    segments change nothing on a receiver: docs/queries.md, "Cracks"). The lines through
    the corners of P's outlines and their crossings are where that can happen; arcs end
    there (END_COPLANAR, the vertex or -1).

    Returns
    -------
    family, s, end_type, index : (k,) arrays
    """
    plane = pencil_plane_of(scene, fkind, fgens)
    fams, ss, idx = [np.empty(0, np.int64)], [np.empty(0)], [np.empty(0, np.int64)]
    face, role, incidence = pencil_planes(scene)
    tol = scene.weld_tolerance
    cr = edge_crossings(scene)
    for k, pf in enumerate(face):
        rows = np.flatnonzero(plane == pf)
        if not len(rows):
            continue
        n, off = scene.face_normal[pf], scene.face_offset[pf]
        vert = np.unique(scene.half_edges.edge_vertices[incidence[incidence[:, 0] == k, 2]])
        crossing = np.abs(cr.point @ n - off) <= tol
        w = np.concatenate([scene.vertices[vert], cr.point[crossing]])
        which = np.r_[vert, np.full(np.count_nonzero(crossing), -1)]
        g = fgens[rows]
        line = g[role[k][g] == 2]  # the one generator crossing P, row by row
        la, lb = edge_geometry(scene, line)
        h0, h1 = la @ n - off, lb @ n - off
        hit = la + (h0 / (h0 - h1))[:, None] * (lb - la)  # H
        r, j = (x.reshape(-1) for x in np.meshgrid(np.arange(len(rows)), np.arange(len(w)), indexing="ij"))
        a, b = edge_geometry(scene, g[r, 0])
        sv, _ = segment_parameter(hit[r], w[j] - hit[r], a, b)
        with np.errstate(invalid="ignore"):
            inside = np.isfinite(sv) & (sv > 0) & (sv < 1)
        fams.append(rows[r[inside]])
        ss.append(sv[inside])
        idx.append(which[j[inside]])
    family = np.concatenate(fams)
    return family, np.concatenate(ss), np.full(len(family), END_COPLANAR), np.concatenate(idx)


def contact_pencils(scene, scope=None):
    """EEE families (l, e1, e2) of the pencils of touched planes (:func:`pencil_planes`):
    e1, e2 two generator edges of touched faces (another face or a foreign vertex in their
    plane: two blocks touching face to face, a tetrahedron's corner on a box's side plane)
    lying in their plane P, l a generator edge crossing P strictly at H, where some line of
    P through H crosses both open edges.

    Such a family is the pencil of lines in P through H that cross e1 and e2 (lines
    meeting two coplanar edges lie in their plane or pass through their lines' common
    point; through a point of l they lie in P only at H). Its lines graze P's faces, and
    where they leave one (H seen across its corner) the visible part of l from a receiver
    point turns from one of its edges to the other. A lone face's pencil ends at nodes
    (VEE: lines through H and a vertex of the face), but with a foreign face or vertex in
    P those lines can pass the foreign vertex while grazing the face, which node
    condition (N2) rejects: the family may hold no node, like a same-plane VE family, and
    is seeded. Every pair of edges of one region (touched faces of P joined across flat
    edges) is seeded, not just a face's corners: a line across several regions crosses
    two edges of each, and its arcs are those of the first region's pair
    (:func:`first_pencil_pair`), which must be a family. (Two touching boxes, a box
    side with a tetrahedron's vertex in its plane: without them receiver regions in front
    of the face held both edges' labels, docs/queries.md.)

    Seen from H, edge e spans the directions of an interval of lines [a, a + w) modulo π
    (w < π); two edges' lines through H meet both open edges where their intervals
    overlap by more than an angle of 1e-9.

    With a ``scope`` (:class:`viscx.skeleton.scope.Scope`), only the pencils of planes
    holding a scope edge and those of scope edges crossing the others (a superset of the
    pencils in scope, which the caller keeps).

    Returns
    -------
    (m, 3) int
        Canonical EEE generators (:func:`canonical_eee`), unique, sorted.
    """
    face, role, incidence = pencil_planes(scene)
    gens = [np.empty((0, 3), dtype=np.int64)]
    for k, pf in enumerate(face):
        n, off = scene.face_normal[pf], scene.face_offset[pf]
        u, v = plane_basis(n)
        inc = incidence[incidence[:, 0] == k]
        ia, ib = pairs_within_groups(inc[:, 1])  # two edges of one face
        if not len(ia):
            continue
        inside = inc[:, 2]
        a, b = edge_geometry(scene, inside)
        lines = np.flatnonzero(role[k] == 2)
        if scope is not None and not scope.edges[inside].any():
            lines = lines[scope.edges[lines]]
        for line in lines:
            la, lb = edge_geometry(scene, np.array([line]))
            h0, h1 = la[0] @ n - off, lb[0] @ n - off
            hit = la[0] + h0 / (h0 - h1) * (lb[0] - la[0])
            ta = np.arctan2((a - hit) @ v, (a - hit) @ u)
            tb = np.arctan2((b - hit) @ v, (b - hit) @ u)
            sweep = np.mod(tb - ta + np.pi, 2 * np.pi) - np.pi  # signed, |sweep| < π off the edge's line
            start = np.mod(np.where(sweep >= 0, ta, tb), np.pi)
            width = np.abs(sweep)
            d = np.mod(start[ib] - start[ia], np.pi)
            wa, wb = width[ia], width[ib]
            overlap = (np.maximum(0.0, np.minimum(wa, d + wb) - d)
                       + np.maximum(0.0, np.minimum(wa, d - np.pi + wb) - np.maximum(0.0, d - np.pi)))
            ok = overlap > ANGLE_TOLERANCE
            gens.append(np.stack([np.full(np.count_nonzero(ok), line), inside[ia[ok]], inside[ib[ok]]], axis=1))
    gens = canonical_eee(scene, np.concatenate(gens))
    gens = gens[gens[:, 0] >= 0]
    return np.unique(gens, axis=0).reshape(-1, 3)
