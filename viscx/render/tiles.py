"""Exact direct illumination without the discontinuity mesh: pixels grouped by (face, side,
screen tile), each group's occluders culled by its shaft to the light.

Why it is exact
---------------
The radiance of a pixel's point x is ρ · Σ_l Le_l F_l(x) (:mod:`viscx.render.direct`), with
F_l(x) Lambert's contour sum over the part of light face l that x sees: the exact polygon
past the occluders (:func:`viscx.geometry.occlusion.visible_form_factors`). Any set of
occluders that holds every face meeting a segment from x to the light gives the same
polygon. The discontinuity mesh is one way to find short such sets (its regions); any
grouping of the points does as well, as long as a group's occluders are those meeting the
*shaft* of its points, the convex hull of a convex patch containing them and J' (light
face l clipped to the front of the receiver's plane): every segment from a point of the
patch to J' lies in it. Here a group is the pixels of one screen tile (:data:`TILE` ×
:data:`TILE`) that see one face from one side, the patch is the rectangle bounding their
points in the face's plane, and the occluders are culled exactly as the mesh path culls a
region's (:func:`viscx.geometry.occlusion.shaft_meets`, then the back faces of closed
convex boxes the whole patch is outside of, :func:`viscx.queries.formfactor.back_faces`;
faces crossing the receiver's or the light's plane clipped to their front as
:func:`viscx.queries.formfactor.pair_occluders` clips them). Nothing is built: no V0, V1
or mesh, so a scene of 10⁵ triangles renders in the time of its primary rays, the culling
and the per-pixel kernels. The image equals the mesh path's up to rounding (the same
kernel, other occluder sets: tests/test_render_tiles.py, 1e-12).

Finding the shaft's occluders
-----------------------------
Every direction gives a plane bounding the shaft (its support value over the patch's and
J''s corners); the planes through an edge of one polygon and a corner of the other, and the
two polygons' own planes, are its facets (:func:`_support_planes`). A box of faces lying
wholly beyond one of them cannot meet the shaft. The faces' boxes are kept in Morton order
in leaves of :data:`CLUSTER` faces and nodes of :data:`CLUSTER` leaves
(:func:`face_tree`), visited from the top (:func:`_shaft_candidates`); the faces left are
judged by :func:`shaft_meets`, whose axes include those planes' normals (so the two passes
keep what :func:`shaft_meets` alone keeps).

Where it differs from the mesh path (documented, below rounding elsewhere): a receiver's
sliver in front of the light's plane whose area is below (1e-9 · diagonal)² is lit here and
black there (the mesh path's pair is "empty").
"""

import numpy as np
from numba import njit, prange

from viscx.geometry.occlusion import shaft_meets, visible_form_factors
from viscx.geometry.polygon import newell_normal
from viscx.queries.formfactor import (clip_loops, closed_boxes, face_boxes, face_outlines, loops_area,
                                      oriented_loops, target_frame)

#: Pixels per side of a screen tile (a group is the pixels of a tile that see one face from one side).
TILE = 8
#: Faces per leaf of the culling tree (consecutive in Morton order), leaves per node.
CLUSTER = 32
#: Margin (fraction of the scene's diagonal) by which a patch is grown for the cones from it
#: to the light's corners (:meth:`TileShading._box_faces`): the ray from a point on the
#: patch's border is then inside the cone, not on its side.
GROWN = 1e-7


# --------------------------------------------------------------------------------------
# the scene's faces as occluders, and their tree


def occluder_pool(scene):
    """Every face's loops oriented about its normal (outer counter-clockwise, holes
    clockwise, as :func:`viscx.queries.formfactor.oriented_loops`), as flat arrays (cached).

    Returns
    -------
    dict
        ``occ`` (m, 3) float64 the loops' vertices, ``occ_loop`` (l + 1,) int64 loop offsets,
        ``loop_ptr`` (f + 1,) int64 face f's loops ``loop_ptr[f]:loop_ptr[f + 1]``,
        ``first``/``last`` (f, 3) float64 the first and last vertex of each outer loop (the
        first vertex about the normal and about its opposite), ``usable`` (f,) bool the
        faces whose area is above (1e-9 · diagonal)² (the others hide nothing:
        :func:`viscx.queries.formfactor.pair_occluders` drops them).
    """

    def build(scene):
        flo = scene.face_loop_offsets.astype(np.int64)
        lo = scene.loop_offsets.astype(np.int64)
        n_loops = len(lo) - 1
        p = scene.vertices[scene.loop_vertices].astype(np.float64)
        idx = np.arange(len(p))
        loop_of = np.repeat(np.arange(n_loops), np.diff(lo))
        start, end = lo[:-1][loop_of], lo[1:][loop_of]
        q = p[np.where(idx + 1 < end, idx + 1, start)]
        c = np.empty_like(p)  # Newell's area vector, term by term (as newell_normal)
        c[:, 0] = p[:, 1] * q[:, 2] - p[:, 2] * q[:, 1]
        c[:, 1] = p[:, 2] * q[:, 0] - p[:, 0] * q[:, 2]
        c[:, 2] = p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]
        newell = np.add.reduceat(c, lo[:-1], axis=0)
        loop_face = np.repeat(np.arange(scene.n_faces), np.diff(flo))
        normal = scene.face_normal.astype(np.float64)
        s = np.einsum("ij,ij->i", newell, normal[loop_face])
        tol = 1e-9 * scene.diagonal
        for L in np.flatnonzero(np.abs(s) <= tol * tol):  # (near zero: the sign as oriented_loops finds it)
            s[L] = newell_normal(p[lo[L]:lo[L + 1]]) @ normal[loop_face[L]]
        outer = np.zeros(n_loops, bool)
        outer[flo[:-1][np.diff(flo) > 0]] = True
        flip = (s > 0) != outer
        occ = np.ascontiguousarray(p[np.where(flip[loop_of], start + end - 1 - idx, idx)])
        area = 0.5 * np.bincount(loop_face, weights=np.where(flip, -s, s), minlength=scene.n_faces)
        return dict(occ=occ, occ_loop=lo, loop_ptr=flo, first=occ[lo[flo[:-1]]], last=occ[lo[flo[:-1] + 1] - 1],
                    usable=np.abs(area) > tol * tol)

    return scene.cached("occluder_pool", build)


def _spread_bits(x):
    """The 10 low bits of x (int64) moved to every third bit (Morton order)."""
    x = x & 0x3FF
    x = (x | (x << 16)) & 0x30000FF
    x = (x | (x << 8)) & 0x300F00F
    x = (x | (x << 4)) & 0x30C30C3
    return (x | (x << 2)) & 0x9249249


def face_tree(scene):
    """The faces' boxes in Morton order of their centres, grouped in leaves of
    :data:`CLUSTER` faces and nodes of :data:`CLUSTER` leaves (cached).

    Returns
    -------
    order : (f,) int64
        The faces in Morton order; leaf k holds ``order[k * CLUSTER:(k + 1) * CLUSTER]``.
    leaf_lo, leaf_hi, node_lo, node_hi : (k, 3) float64
        The leaves' and nodes' boxes.
    """

    def build(scene):
        lo, hi = face_boxes(scene)
        s_lo, s_hi = scene.bbox
        cell = np.clip(((0.5 * (lo + hi) - s_lo) / np.maximum(s_hi - s_lo, 1e-300) * 1023).astype(np.int64), 0, 1023)
        code = _spread_bits(cell[:, 0]) | (_spread_bits(cell[:, 1]) << 1) | (_spread_bits(cell[:, 2]) << 2)
        order = np.argsort(code, kind="stable").astype(np.int64)
        starts = np.arange(0, len(order), CLUSTER)
        leaf_lo, leaf_hi = np.minimum.reduceat(lo[order], starts), np.maximum.reduceat(hi[order], starts)
        starts = np.arange(0, len(leaf_lo), CLUSTER)
        return (order, leaf_lo, leaf_hi, np.minimum.reduceat(leaf_lo, starts), np.maximum.reduceat(leaf_hi, starts))

    return scene.cached("face_tree", build)


# --------------------------------------------------------------------------------------
# shafts


@njit(cache=True)
def _support_planes(cells, cell_normal, t_pts, t_ptr, cell_target, target_normal, tol):
    """Planes bounding the shaft of each cell (the convex hull of the cell and its target,
    ``t_pts[t_ptr[t]:t_ptr[t + 1]]`` for t = ``cell_target[i]``): ``(planes (g, m, 4), count
    (g,))``, the first ``count[i]`` rows ``(n, c)`` of cell i with n · y <= c on the whole
    shaft (c is n's support value over the corners, so the bound holds for any n). The
    directions are the candidates for the hull's facets: the two polygons' normals and
    the planes through an edge of one and a corner of the other, each kept, oriented
    outwards, where the corners all lie within ``tol`` on one side of its plane (a facet
    or nearly)."""
    g, kc = cells.shape[0], cells.shape[1]
    kt_max = 1
    for t in range(t_ptr.shape[0] - 1):
        kt_max = max(kt_max, t_ptr[t + 1] - t_ptr[t])
    planes = np.zeros((g, 2 + 2 * kc * kt_max, 4))
    count = np.zeros(g, np.int64)
    for i in range(g):
        pa = cells[i]
        target = t_pts[t_ptr[cell_target[i]]:t_ptr[cell_target[i] + 1]]
        kt = target.shape[0]
        k = 0
        for j in range(2 + 2 * kc * kt):
            if j == 0:
                nx, ny, nz = cell_normal[i, 0], cell_normal[i, 1], cell_normal[i, 2]
                ax, ay, az = pa[0, 0], pa[0, 1], pa[0, 2]
            elif j == 1:
                nx, ny, nz = target_normal[0], target_normal[1], target_normal[2]
                ax, ay, az = target[0, 0], target[0, 1], target[0, 2]
            else:
                r = j - 2
                if r < kc * kt:  # an edge of the cell, a corner of the target
                    e, v = r // kt, r % kt
                    a, b, w = pa[e], pa[(e + 1) % kc], target[v]
                else:
                    r -= kc * kt
                    e, v = r // kc, r % kc
                    a, b, w = target[e], target[(e + 1) % kt], pa[v]
                ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
                wx, wy, wz = w[0] - a[0], w[1] - a[1], w[2] - a[2]
                nx, ny, nz = ey * wz - ez * wy, ez * wx - ex * wz, ex * wy - ey * wx
                ax, ay, az = a[0], a[1], a[2]
            size = np.sqrt(nx * nx + ny * ny + nz * nz)
            if size == 0.0:
                continue
            nx, ny, nz = nx / size, ny / size, nz / size
            c0 = nx * ax + ny * ay + nz * az
            s_hi, s_lo = -np.inf, np.inf
            for q in range(kc + kt):
                p = pa[q] if q < kc else target[q - kc]
                d = nx * p[0] + ny * p[1] + nz * p[2]
                s_hi, s_lo = max(s_hi, d), min(s_lo, d)
            if s_hi - c0 <= tol:
                planes[i, k, 0], planes[i, k, 1], planes[i, k, 2], planes[i, k, 3] = nx, ny, nz, s_hi
            elif c0 - s_lo <= tol:
                planes[i, k, 0], planes[i, k, 1], planes[i, k, 2], planes[i, k, 3] = -nx, -ny, -nz, -s_lo
            else:
                continue
            k += 1
        count[i] = k
    return planes, count


@njit(cache=True)
def _meets_by_target(cells, cell_normal, t_pts, t_ptr, cand_target, target_normal, cand_cell, cand_poly, poly_pts,
                     poly_lo, poly_hi, poly_normal, tol):
    """:func:`shaft_meets` of candidate pairs whose cells have targets of their own
    (``t_pts[t_ptr[t]:t_ptr[t + 1]]``, t = ``cand_target[c]``; the pairs sorted by it): one
    call per run of pairs with one target."""
    out = np.zeros(cand_cell.shape[0], np.bool_)
    a = 0
    while a < cand_cell.shape[0]:
        t = cand_target[a]
        b = a
        while b < cand_cell.shape[0] and cand_target[b] == t:
            b += 1
        out[a:b] = shaft_meets(cells, cell_normal, t_pts[t_ptr[t]:t_ptr[t + 1]], target_normal, cand_cell[a:b],
                               cand_poly[a:b], poly_pts, poly_lo, poly_hi, poly_normal, tol)
        a = b
    return out


@njit(cache=True)
def _beyond(lo, hi, planes, n):
    """Whether the box (lo, hi) lies wholly beyond one of the first n planes (n · y > c)."""
    for j in range(n):
        s = 0.0
        for d in range(3):
            s += planes[j, d] * (lo[d] if planes[j, d] > 0 else hi[d])
        if s > planes[j, 3]:
            return True
    return False


@njit(cache=True)
def _shaft_candidates(planes, count, order, face_lo, face_hi, leaf_lo, leaf_hi, node_lo, node_hi, cluster):
    """Per cell, the faces whose boxes lie beyond none of its shaft's planes (the tree
    visited from its nodes down): ``(ptr (g + 1,), faces)``, each cell's ascending."""
    g = planes.shape[0]
    ptr = np.zeros(g + 1, np.int64)
    out = np.empty(1 << 16, np.int64)
    k = 0
    n_faces = order.shape[0]
    for i in range(g):
        pl, n = planes[i], count[i]
        for nd in range(node_lo.shape[0]):
            if _beyond(node_lo[nd], node_hi[nd], pl, n):
                continue
            for lf in range(nd * cluster, min((nd + 1) * cluster, leaf_lo.shape[0])):
                if _beyond(leaf_lo[lf], leaf_hi[lf], pl, n):
                    continue
                for r in range(lf * cluster, min((lf + 1) * cluster, n_faces)):
                    f = order[r]
                    if _beyond(face_lo[f], face_hi[f], pl, n):
                        continue
                    if k == out.shape[0]:
                        grown = np.empty(2 * k, np.int64)
                        grown[:k] = out
                        out = grown
                    out[k] = f
                    k += 1
        out[ptr[i]:k] = np.sort(out[ptr[i]:k])
        ptr[i + 1] = k
    return ptr, out[:k].copy()


@njit(cache=True)
def _crosses(cell, faces, cell_normal, cell_c, n_t, c_t, occ, occ_loop, loop_ptr):
    """(c,) bool: whether a vertex of face ``faces[c]`` lies behind the plane of its cell
    (``cell_normal · y = cell_c``) or of the light (``n_t · y = c_t``): then it is clipped
    (:func:`viscx.queries.formfactor.clip_loops` keeps the part with heights >= 0)."""
    out = np.zeros(faces.shape[0], np.bool_)
    for c in range(faces.shape[0]):
        f, i = faces[c], cell[c]
        for q in range(occ_loop[loop_ptr[f]], occ_loop[loop_ptr[f + 1]]):
            x, y, z = occ[q, 0], occ[q, 1], occ[q, 2]
            hi = cell_normal[i, 0] * x + cell_normal[i, 1] * y + cell_normal[i, 2] * z - cell_c[i]
            ht = n_t[0] * x + n_t[1] * y + n_t[2] * z - c_t
            if hi < 0.0 or ht < 0.0:
                out[c] = True
                break
    return out


@njit(cache=True)
def _groups_outside(cells, points, pt_ptr, cell, box, box_ptr, box_planes, tiny):
    """(c,) int64: for each (group ``cell[c]``, box ``box[c]``), a plane of the box (a row
    of ``box_planes``) with every corner of the group's patch more than 2 tiny in front,
    when each of the group's points is outside the box as
    :func:`viscx.geometry.occlusion._outside_box` judges (no plane with the point within
    (0, 2 tiny] in front of it, an open box's missing face within tiny in front or behind;
    conservatively: a face resting on the points' plane, which the kernel lets pass, keeps
    the box's planes here); else -1. Then that plane alone decides ``_outside_box`` at each point as all the planes
    do. A plane with the patch's corners all on or behind it, or all more than 2 tiny in
    front (all but a few of a sphere's seen from a patch beside it), is settled by the
    corners; the points are judged against the others."""
    out = np.full(cell.shape[0], -1, np.int64)
    for c in range(cell.shape[0]):
        g = cell[c]
        pa = cells[g]
        witness, ok = -1, True
        for k in range(box_ptr[box[c]], box_ptr[box[c] + 1]):
            nx, ny, nz, d = box_planes[k, 0], box_planes[k, 1], box_planes[k, 2], box_planes[k, 3]
            lo, hi = np.inf, -np.inf
            for q in range(pa.shape[0]):
                h = nx * pa[q, 0] + ny * pa[q, 1] + nz * pa[q, 2] - d
                lo, hi = min(lo, h), max(hi, h)
            missing = box_planes[k, 4] != 0.0
            if not missing and lo > 2.0 * tiny:
                if witness < 0:
                    witness = k
                continue
            if hi <= (tiny if missing else 0.0):
                continue
            for i in range(pt_ptr[g], pt_ptr[g + 1]):
                h = nx * points[i, 0] + ny * points[i, 1] + nz * points[i, 2] - d
                if (h > tiny) if missing else (0.0 < h <= 2.0 * tiny):
                    ok = False
                    break
            if not ok:
                break
        out[c] = witness if ok else -1
    return out


@njit(cache=True)
def _silhouette_faces(cells, cell, faces, nb_ptr, nb, normal, offset, tiny):
    """For (patch, face of a closed convex box) pairs: ``(ring, back)`` (c,) bool each.
    ``back``: every corner of the patch lies behind the face's plane by more than tiny (a
    back face for each of its points). ``ring``: not back, and a neighbour of the face
    (across an edge) is not a front face for each point (every corner more than tiny in
    front): for some point of the patch the face may hold an edge of the box's silhouette."""
    ring = np.zeros(faces.shape[0], np.bool_)
    back = np.zeros(faces.shape[0], np.bool_)
    for c in range(faces.shape[0]):
        pa = cells[cell[c]]
        f = faces[c]
        hi = -np.inf
        for q in range(pa.shape[0]):
            hi = max(hi, normal[f, 0] * pa[q, 0] + normal[f, 1] * pa[q, 1] + normal[f, 2] * pa[q, 2] - offset[f])
        if hi < -tiny:
            back[c] = True
            continue
        for r in range(nb_ptr[f], nb_ptr[f + 1]):
            g = nb[r]
            if g < 0:  # (no single face across: kept)
                ring[c] = True
                break
            lo = np.inf
            for q in range(pa.shape[0]):
                lo = min(lo, normal[g, 0] * pa[q, 0] + normal[g, 1] * pa[q, 1] + normal[g, 2] * pa[q, 2] - offset[g])
            if lo <= tiny:
                ring[c] = True
                break
    return ring, back


# --------------------------------------------------------------------------------------
# the kernels, group by group


@njit(cache=True, parallel=True)
def _tile_form_factors(points, pt_ptr, group_n, group_target, occ_ptr, occ_ids, occ, occ_loop, loop_ptr, poly_normal,
                       poly_point, poly_box, t_origin, t_eu, t_ev, t_n, t_c, t_j2, t_j2_ptr, t_jl, t_jl_ptr, t_hull,
                       t_hull_ptr, tiny, box_ptr, box_planes, w_ptr, w_box, w_row, visit):
    """F from each point (normal ``group_n`` of its group) to the part of its group's target
    it sees past the group's occluders (:func:`visible_form_factors` on the group's own
    arrays, gathered as :meth:`viscx.queries.formfactor.PairSetup.kernel_for` builds them).

    Parameters
    ----------
    points : (n, 3) float64
        Sorted by group: group g's at ``pt_ptr[g]:pt_ptr[g + 1]``.
    group_n : (g, 3) float64; group_target : (g,) int64
    occ_ptr, occ_ids : (g + 1,), (k,) int64
        The occluder polygons of each group (ids into the pool arrays below).
    occ, occ_loop, loop_ptr, poly_normal, poly_point, poly_box :
        The polygons' loops (polygon p's loops ``loop_ptr[p]:loop_ptr[p + 1]``), planes and boxes.
    t_* :
        Per target: the frame of :func:`viscx.queries.formfactor.target_frame` and its
        plane, j2/j_loop/hull flattened with offsets.
    box_ptr, box_planes :
        The closed boxes (:func:`viscx.queries.formfactor.closed_boxes`).
    w_ptr, w_box, w_row : (g + 1,), (w,), (w,) int64
        Per group, boxes its whole patch is outside of and a plane of each that says so
        alone (:func:`_groups_outside`): the group's box table holds that plane only for
        them (the kernel asks each point whether it is outside each box; a sphere has
        20,480 planes), the box's planes for the others.
    visit : (g,) int64
        The order the groups are shared out among the threads in (a shuffle: the costly
        groups of one face are not all one thread's).
    """
    out = np.zeros(points.shape[0])
    for r in prange(visit.shape[0]):
        g = visit[r]
        a, b = pt_ptr[g], pt_ptr[g + 1]
        if b == a:
            continue
        t = group_target[g]
        ids = occ_ids[occ_ptr[g]:occ_ptr[g + 1]]
        n_p = ids.shape[0]
        n_l, n_v = 0, 0
        for p in ids:
            n_l += loop_ptr[p + 1] - loop_ptr[p]
            n_v += occ_loop[loop_ptr[p + 1]] - occ_loop[loop_ptr[p]]
        l_occ = np.empty((n_v, 3))
        l_loop = np.zeros(n_l + 1, np.int64)
        l_poly = np.empty(n_l, np.int64)
        l_normal = np.empty((n_p, 3))
        l_point = np.empty((n_p, 3))
        l_box = np.empty(n_p, np.int64)
        L, v = 0, 0
        for k in range(n_p):
            p = ids[k]
            for q in range(loop_ptr[p], loop_ptr[p + 1]):
                for w in range(occ_loop[q], occ_loop[q + 1]):
                    l_occ[v] = occ[w]
                    v += 1
                l_poly[L] = k
                L += 1
                l_loop[L] = v
            l_normal[k] = poly_normal[p]
            l_point[k] = poly_point[p]
        # the group's boxes, numbered in order of first use, with their planes
        seen = np.empty(n_p, np.int64)
        n_b, n_planes = 0, 0
        for k in range(n_p):
            box = poly_box[ids[k]]
            l_box[k] = -1
            if box < 0:
                continue
            for j in range(n_b):
                if seen[j] == box:
                    l_box[k] = j
            if l_box[k] < 0:
                l_box[k] = n_b
                seen[n_b] = box
                n_b += 1
        l_box_ptr = np.zeros(n_b + 1, np.int64)
        l_row = np.full(n_b, -1, np.int64)
        for j in range(n_b):
            for q in range(w_ptr[g], w_ptr[g + 1]):
                if w_box[q] == seen[j]:
                    l_row[j] = w_row[q]
            n_planes += 1 if l_row[j] >= 0 else box_ptr[seen[j] + 1] - box_ptr[seen[j]]
            l_box_ptr[j + 1] = n_planes
        l_planes = np.empty((n_planes, box_planes.shape[1]))
        for j in range(n_b):
            if l_row[j] >= 0:
                l_planes[l_box_ptr[j]] = box_planes[l_row[j]]
            else:
                l_planes[l_box_ptr[j]:l_box_ptr[j + 1]] = box_planes[box_ptr[seen[j]]:box_ptr[seen[j] + 1]]
        # no surface patches' outlines here (poly_solid -1): each face of the group's list on its own
        out[a:b] = visible_form_factors(points[a:b], group_n[g], t_j2[t_j2_ptr[t]:t_j2_ptr[t + 1]],
                                        t_jl[t_jl_ptr[t]:t_jl_ptr[t + 1]], t_origin[t], t_eu[t], t_ev[t], t_n[t], t_c[t],
                                        t_hull[t_hull_ptr[t]:t_hull_ptr[t + 1]], l_occ, l_loop, l_poly, l_normal, l_point,
                                        tiny, l_box, l_box_ptr, l_planes, np.full(n_p, -1, np.int64),
                                        np.zeros(0, np.int64), np.full(n_v, -1, np.int64), np.zeros(n_v, np.int64),
                                        np.zeros(n_v, np.int64))
    return out


# --------------------------------------------------------------------------------------
# the render's shading


def tile_ids(shape, tile=TILE):
    """(h·w,) int64: the screen tile of each pixel (row-major pixels, ``tile`` × ``tile`` tiles)."""
    h, w = shape
    rows, cols = np.divmod(np.arange(h * w, dtype=np.int64), w)
    return (rows // tile) * -(-w // tile) + cols // tile


def box_faces_info(scene):
    """What :meth:`TileShading._box_faces` reads of the closed boxes (cached):
    ``nb_ptr`` (f + 1,), ``nb`` the faces across each edge of each face (from the half
    edges; -1 none), ``closed`` (b,) bool boxes with no missing face, ``vert_ptr`` (b + 1,)
    and ``verts`` the vertices of each box's faces."""

    def build(scene):
        face_box, box_ptr, box_planes = closed_boxes(scene)
        he = scene.half_edges
        order = np.argsort(he.face, kind="stable")
        nb = np.where(he.opp[order] >= 0, he.face[np.maximum(he.opp[order], 0)], -1).astype(np.int64)
        nb_ptr = np.r_[0, np.cumsum(np.bincount(he.face, minlength=scene.n_faces))].astype(np.int64)
        n_box = len(box_ptr) - 1
        closed = np.array([not np.any(box_planes[box_ptr[b]:box_ptr[b + 1], 4]) for b in range(n_box)], bool)
        lo = scene.loop_offsets[scene.face_loop_offsets[:-1]]
        hi = scene.loop_offsets[scene.face_loop_offsets[:-1] + 1]
        verts = [np.unique(np.concatenate([scene.loop_vertices[lo[f]:hi[f]] for f in np.flatnonzero(face_box == b)]))
                 for b in range(n_box)]
        return dict(nb_ptr=nb_ptr, nb=nb, closed=closed,
                    vert_ptr=np.r_[0, np.cumsum([len(v) for v in verts])].astype(np.int64),
                    verts=np.concatenate(verts).astype(np.int64) if verts else np.zeros(0, np.int64))

    return scene.cached("box_faces_info", build)


def _bases(normal):
    """(u, v) (g, 3) float64 each: unit vectors with (u, v, normal) right-handed (the
    vectorised :func:`viscx.geometry.polygon.plane_basis`)."""
    helper = np.eye(3)[np.argmin(np.abs(normal), axis=1)]
    u = np.cross(helper, normal)
    u /= np.linalg.norm(u, axis=1)[:, None]
    return u, np.cross(normal, u)


class TileShading:
    """The exact form factors F_l(x) of pixels' points to each light face, group by group
    (module docstring).

    Parameters
    ----------
    scene : Scene
    light : viscx.scene.light.Light
    """

    def __init__(self, scene, light):
        self.scene = scene
        self.light = light
        self.tiny = 1e-9 * scene.diagonal
        self.stats = {"groups": 0, "occluders": 0, "reduced": 0, "clipped": 0, "evaluations": 0}
        self._outlines = face_outlines(scene)
        self._normals = scene.face_normal.astype(np.float64)

    def form_factors(self, k, face, side, points, tile):
        """F from each point to the part of light face k it sees (zero where it sees none).

        Parameters
        ----------
        k : int
            Index into ``light.faces``.
        face, side : (n,) int64
            The face each point lies on and the side it is seen from (no background).
        points : (n, 3) float64
        tile : (n,) int64
            Its screen tile.

        Returns
        -------
        (n,) float64
        """
        scene, tiny = self.scene, self.tiny
        pool = occluder_pool(scene)
        out = np.zeros(len(face))
        l = int(self.light.faces[k])
        n_t = scene.face_normal[l].astype(np.float64)
        loops_t = oriented_loops(scene.face_loops(l), n_t)
        c_t = float(n_t @ loops_t[0][0])
        # points behind the light's plane (or on it) do not see its front
        live = np.flatnonzero((face != l) & (points @ n_t - c_t > tiny))
        if not len(live) or loops_area(loops_t, n_t) <= tiny * tiny:
            return out
        # the (face, side) pairs: their plane, and J' (the light face in front of it)
        pairs, pair_of = np.unique(face[live] * 2 + (side[live] > 0), return_inverse=True)
        pf, ps = pairs // 2, np.where(pairs % 2 == 1, 1, -1)
        n_i = ps[:, None] * scene.face_normal[pf].astype(np.float64)
        # the first vertex of the outer loop oriented about n_i (as PairSetup's c_i)
        c_i = np.einsum("ij,ij->i", n_i, np.where(ps[:, None] > 0, pool["first"][pf], pool["last"][pf]))
        h = np.concatenate(loops_t) @ n_i.T - c_i  # (corners of J, pairs)
        whole = h.min(axis=0) >= 0  # J' = J
        target = np.where(whole & (h.max(axis=0) > tiny), 0, -1)  # (J' in front by more than tiny)
        frames = [target_frame(loops_t, n_t)]
        for p in np.flatnonzero(~whole):
            J = clip_loops(loops_t, n_i[p], c_i[p])
            if not J or loops_area(J, n_t) <= tiny * tiny or max(float(np.max(lp @ n_i[p])) for lp in J) - c_i[p] <= tiny:
                continue
            target[p] = len(frames)
            frames.append(target_frame(J, n_t))
        keep = target[pair_of] >= 0
        live, pair_of = live[keep], pair_of[keep]
        if not len(live):
            return out
        # groups: (pair, tile), their points together
        n_tiles = int(tile.max()) + 1
        key = pair_of * n_tiles + tile[live]
        order = np.argsort(key, kind="stable")
        live, key = live[order], key[order]
        first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        pt_ptr = np.r_[first, len(key)].astype(np.int64)
        g_pair = key[first] // n_tiles
        g_n, g_c, g_target = n_i[g_pair], c_i[g_pair], target[g_pair]
        # each group's patch: the rectangle bounding its points in the face's plane
        u, v = _bases(g_n)
        pts = points[live]
        pu, pv = (np.einsum("ij,ij->i", pts, np.repeat(b, np.diff(pt_ptr), axis=0)) for b in (u, v))
        u0, u1 = np.minimum.reduceat(pu, first), np.maximum.reduceat(pu, first)
        v0, v1 = np.minimum.reduceat(pv, first), np.maximum.reduceat(pv, first)
        base = g_n * g_c[:, None]

        def rectangles(m):  # corners counter-clockwise about g_n, grown by m
            return np.ascontiguousarray(np.stack([base + a[:, None] * u + b[:, None] * v for a, b in (
                (u0 - m, v0 - m), (u1 + m, v0 - m), (u1 + m, v1 + m), (u0 - m, v1 + m))], axis=1))

        cells = rectangles(0.0)
        ptr, ids, witness = self._occluders(cells, rectangles(GROWN * scene.diagonal), pts, pt_ptr, g_n, g_target,
                                            [f[6] for f in frames], n_t, l, pf[g_pair])
        ids, polys = self._clipped(ptr, ids, g_pair, n_i, c_i, n_t, c_t)
        self.stats["groups"] += len(first)
        self.stats["occluders"] += len(ids)
        self.stats["evaluations"] += len(live)
        visit = np.random.default_rng(0).permutation(len(first)).astype(np.int64)
        t_origin, t_eu, t_ev, j2, jl, hull = (list(x) for x in zip(*[(f[0], f[1], f[2], f[3], f[4], f[6]) for f in frames]))
        offsets = lambda arrays: np.r_[0, np.cumsum([len(a) for a in arrays])].astype(np.int64)  # noqa: E731
        occ, occ_loop, loop_ptr, normal, point, box = polys
        face_box, box_ptr, box_planes = closed_boxes(scene)
        out[live] = _tile_form_factors(
            np.ascontiguousarray(pts), pt_ptr, np.ascontiguousarray(g_n), g_target.astype(np.int64), ptr, ids, occ,
            occ_loop, loop_ptr, normal, point, box, np.array(t_origin), np.array(t_eu), np.array(t_ev),
            np.tile(n_t, (len(frames), 1)), np.full(len(frames), c_t), np.concatenate(j2), offsets(j2), np.concatenate(jl),
            offsets(jl), np.concatenate(hull), offsets(hull), tiny, box_ptr, box_planes,
            np.r_[0, np.cumsum(np.bincount(witness[:, 0], minlength=len(first)))].astype(np.int64), witness[:, 1].copy(),
            witness[:, 2].copy(), visit)
        return out

    def _occluders(self, cells, grown, points, pt_ptr, g_n, g_target, hulls, n_t, light_face, g_face):
        """Each group's occluders: the faces meeting the interior of its shaft
        (:func:`_shaft_candidates`, then :func:`shaft_meets`), but its own face, the light
        face and faces of no area, the faces of closed convex boxes reduced
        (:meth:`_box_faces`).

        Returns
        -------
        ptr, ids : (g + 1,), (k,) int64
            CSR lists of faces, ascending per group.
        witness : (w, 3) int64
            Rows (group, box, plane): a plane of the box that decides alone that each of
            the group's points is outside it (:func:`_groups_outside`), sorted.
        """
        scene, tiny = self.scene, self.tiny
        pool = occluder_pool(scene)
        face_box = closed_boxes(scene)[0]
        order, leaf_lo, leaf_hi, node_lo, node_hi = face_tree(scene)
        f_lo, f_hi = face_boxes(scene)
        t_pts, t_ptr = np.ascontiguousarray(np.concatenate(hulls)), np.r_[0, np.cumsum([len(h) for h in hulls])].astype(np.int64)
        planes, count = _support_planes(cells, g_n, t_pts, t_ptr, g_target, n_t, tiny)
        ptr, ids = _shaft_candidates(planes, count, order, f_lo, f_hi, leaf_lo, leaf_hi, node_lo, node_hi, CLUSTER)
        cell = np.repeat(np.arange(len(cells)), np.diff(ptr))
        ok = (ids != g_face[cell]) & (ids != light_face) & pool["usable"][ids]
        cell, ids = cell[ok], ids[ok]
        kept = np.zeros(len(cell), bool)
        plain = np.flatnonzero(face_box[ids] < 0)
        kept[plain] = self._meets(cells, g_n, t_pts, t_ptr, g_target[cell[plain]], n_t, cell[plain], ids[plain])
        boxed = np.flatnonzero(face_box[ids] >= 0)
        kept[boxed], witness = self._box_faces(cells, grown, points, pt_ptr, g_n, g_target, hulls, n_t, cell[boxed],
                                               ids[boxed])
        ptr = np.r_[0, np.cumsum(np.bincount(cell[kept], minlength=len(cells)))].astype(np.int64)
        return ptr, ids[kept], witness

    def _meets(self, cells, g_n, t_pts, t_ptr, target, n_t, cell, faces):
        """:func:`shaft_meets` of (cell, face) pairs, the cells' targets ``target`` (each
        pair's) among ``t_pts``/``t_ptr``."""
        outline, o_lo, o_hi = self._outlines
        by = np.argsort(target, kind="stable")
        out = np.zeros(len(cell), bool)
        out[by] = _meets_by_target(cells, g_n, t_pts, t_ptr, target[by], n_t, cell[by], faces[by], outline, o_lo, o_hi,
                                   self._normals, self.tiny)
        return out

    def _box_faces(self, cells, grown, points, pt_ptr, g_n, g_target, hulls, n_t, cell, faces):
        """Which faces of closed convex boxes a group keeps, of those its shaft's planes
        left (``cell``, ``faces``).

        A box each of whose points is outside (:func:`_groups_outside`) hides from each
        point x the central projection S of its part inside the pyramid from x over J''s
        hull, and the kernel takes S as the convex hull of the listed faces clipped to the
        pyramid and projected (:func:`viscx.geometry.occlusion._visible_one`): any faces
        whose clipped projections hold S's corners give it. When the box lies between the
        light's plane and every point of the patch (heights above that plane in (tiny,
        least height of the patch − tiny)), central projection from x maps it onto a
        convex set and S = proj(box) ∩ hull(J'): its corners are corners of the box's
        silhouette seen from x, crossings of the silhouette with the hull's sides, and
        corners of the hull whose ray from x meets the box, on the face the ray enters
        through. So the group keeps the faces that may hold an edge of the silhouette for
        some point of the patch (:func:`_silhouette_faces`) and the faces meeting the cone
        from the patch (grown by :data:`GROWN` of the diagonal: the rays from its border
        points inside) to a hull corner (:func:`shaft_meets`); on a sphere of 20,480 faces
        a shaft through it meets thousands of faces, these are tens. Other boxes: the
        faces meeting the shaft (:func:`shaft_meets`), less the back faces (behind every
        point of the patch) of a box each point is outside of (as
        :func:`viscx.queries.formfactor.back_faces`: the box's front faces hide them).

        Returns
        -------
        kept : (c,) bool
        witness : (w, 3) int64
            (group, box, plane) as :meth:`_occluders`.
        """
        scene, tiny = self.scene, self.tiny
        face_box, box_ptr, box_planes = closed_boxes(scene)
        info = box_faces_info(scene)
        kept = np.zeros(len(cell), bool)
        if not len(cell):
            return kept, np.zeros((0, 3), np.int64)
        pairs, which = np.unique(np.stack([cell, face_box[faces]], axis=1), axis=0, return_inverse=True)
        which = which.reshape(-1)
        row = _groups_outside(cells, points, pt_ptr, pairs[:, 0].copy(), pairs[:, 1].copy(), box_ptr, box_planes, tiny)
        # the boxes between the light's plane and the patch (its corners' least height)
        c_t = n_t @ hulls[0][0]
        h = scene.vertices[info["verts"]] @ n_t - c_t
        h_lo, h_hi = np.minimum.reduceat(h, info["vert_ptr"][:-1]), np.maximum.reduceat(h, info["vert_ptr"][:-1])
        patch = (cells @ n_t - c_t).min(axis=1)
        b = pairs[:, 1]
        reduced = (row >= 0) & info["closed"][b] & (h_lo[b] > tiny) & (h_hi[b] < patch[pairs[:, 0]] - tiny)
        ring, back = _silhouette_faces(cells, cell, faces, info["nb_ptr"], info["nb"], self._normals,
                                       scene.face_offset.astype(np.float64), tiny)
        # reduced boxes: silhouette faces, and the faces the hull corners' cones meet
        red = reduced[which]
        kept[red] = ring[red]
        ask = np.flatnonzero(red & ~ring & ~back)
        if len(ask):
            # one target per (hull, corner): the pairs repeated for each corner of their hull
            sizes = np.array([len(hh) for hh in hulls])
            first = np.r_[0, np.cumsum(sizes)][:-1]
            t = g_target[cell[ask]]
            rep = np.repeat(np.arange(len(ask)), sizes[t])
            corner = first[t][rep] + (np.arange(len(rep)) - np.repeat(np.cumsum(sizes[t]) - sizes[t], sizes[t]))
            apex = np.ascontiguousarray(np.concatenate(hulls))
            hit = self._meets(grown, g_n, apex, np.arange(len(apex) + 1, dtype=np.int64), corner, n_t, cell[ask][rep],
                              faces[ask][rep])
            kept[ask[np.unique(rep[hit])]] = True
        # other boxes: the shaft's faces, less the back faces of a box each point is outside of
        other = np.flatnonzero(~red)
        if len(other):
            t_pts = np.ascontiguousarray(np.concatenate(hulls))
            t_ptr = np.r_[0, np.cumsum([len(hh) for hh in hulls])].astype(np.int64)
            meets = self._meets(cells, g_n, t_pts, t_ptr, g_target[cell[other]], n_t, cell[other], faces[other])
            kept[other] = meets & ~(back[other] & (row[which[other]] >= 0))
        self.stats["reduced"] += int(np.sum(reduced))
        has = row >= 0
        return kept, np.stack([pairs[has, 0], pairs[has, 1], row[has]], axis=1).astype(np.int64)

    def _clipped(self, ptr, ids, g_pair, n_i, c_i, n_t, c_t):
        """The occluder polygons: the scene's faces as they are, and those crossing their
        group's receiver plane or the light's plane clipped to the front of both (as
        :func:`viscx.queries.formfactor.pair_occluders`; once per (face, side) pair and
        occluder), appended to the pool; a clipped face of no area is dropped.

        Returns
        -------
        ids : (k,) int64
            The groups' occluders (their CSR rows as ``ptr``, less the dropped) as polygon ids.
        polys : tuple
            ``(occ, occ_loop, loop_ptr, normal, point, box)`` of every polygon.
        """
        scene, tiny = self.scene, self.tiny
        pool = occluder_pool(scene)
        face_box = closed_boxes(scene)[0]
        normals = scene.face_normal.astype(np.float64)
        cell = np.repeat(np.arange(len(ptr) - 1), np.diff(ptr))
        pair = g_pair[cell]
        cross = _crosses(cell, ids, n_i[g_pair], c_i[g_pair], n_t, c_t, pool["occ"], pool["occ_loop"], pool["loop_ptr"])
        occ, occ_loop, loop_ptr = [pool["occ"]], [pool["occ_loop"]], [pool["loop_ptr"]]
        normal, point, box = [normals], [pool["first"]], [face_box]
        new_ids = ids.copy()
        if np.any(cross):
            n_f, n_v, n_l = scene.n_faces, len(pool["occ"]), len(pool["occ_loop"]) - 1
            wanted, back = np.unique(np.stack([pair[cross], ids[cross]], axis=1), axis=0, return_inverse=True)
            made = np.full(len(wanted), -1, np.int64)
            for j, (p, f) in enumerate(wanted):
                loops = pool_loops(pool, f)
                loops = clip_loops(clip_loops(loops, n_i[p], c_i[p]), n_t, c_t)
                if not loops or abs(loops_area(loops, normals[f])) <= tiny * tiny:
                    continue
                made[j] = n_f
                n_f += 1
                sizes = np.cumsum([len(lp) for lp in loops])
                occ.append(np.concatenate(loops))
                occ_loop.append(n_v + sizes)
                loop_ptr.append(np.array([n_l + len(loops)]))
                n_v, n_l = n_v + int(sizes[-1]), n_l + len(loops)
                normal.append(normals[f][None])
                point.append(loops[0][:1])
                box.append(face_box[f:f + 1])
            new_ids[cross] = made[back.reshape(-1)]
            self.stats["clipped"] += int(np.sum(made >= 0))
        kept = new_ids >= 0
        ptr[1:] = np.cumsum(np.bincount(cell[kept], minlength=len(ptr) - 1))
        polys = (np.ascontiguousarray(np.concatenate(occ)), np.concatenate(occ_loop).astype(np.int64),
                 np.concatenate(loop_ptr).astype(np.int64), np.ascontiguousarray(np.concatenate(normal)),
                 np.ascontiguousarray(np.concatenate(point)), np.concatenate(box).astype(np.int64))
        return new_ids[kept], polys


def pool_loops(pool, face):
    """Face ``face``'s loops from :func:`occluder_pool` (list of (k, 3) float64, oriented)."""
    lo, hi = pool["loop_ptr"][face], pool["loop_ptr"][face + 1]
    cut = pool["occ_loop"]
    return [pool["occ"][cut[j]:cut[j + 1]] for j in range(lo, hi)]


def shade_tiles(lighting, hits, tile=TILE):
    """Exact radiance (direct light reflected, plus emission) of every pixel of an image,
    tile by tile (module docstring).

    Parameters
    ----------
    lighting : viscx.render.direct.Lighting
    hits : viscx.render.camera.Hits
    tile : int

    Returns
    -------
    radiance : (n, 3) float64
    stats : dict
    """
    scene, em = lighting.scene, lighting.emitter
    out = np.zeros((len(hits.face), 3))
    hit = np.flatnonzero(hits.face >= 0)
    face, side, points = hits.face[hit], hits.side[hit], np.ascontiguousarray(hits.point[hit])
    tiles = tile_ids(hits.shape, tile)[hit]
    shading = TileShading(scene, em.light)
    total = np.zeros((len(hit), 3))
    for k in range(len(em.light.faces)):
        f = shading.form_factors(k, face, side, points, tiles)
        total += np.maximum(f, 0.0)[:, None] * em.radiance[k][None, :]
    out[hit] = total * lighting.kd[face]
    for j, l in enumerate(em.light.faces):  # the light's faces seen from their front
        on = hit[(face == l) & (side > 0)]
        out[on] += em.radiance[j][None, :]
    return out, shading.stats
