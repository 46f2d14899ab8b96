"""Form factors from a viscx file: point to face (exact, Hoberock et al. §7.4), face to face with
occlusion (quadrature with an error estimate), groups, and the sparse matrix of a scene.

Sides
-----
Faces are two-sided blockers, so a form factor is between *sides*: ``F[(i, s), (j, t)]``
is the fraction of the energy leaving side s of face i (cosine-weighted about that side's
normal, ``s * face_normal[i]`` with s = +1 front, -1 back) that first arrives on side t of
face j. With sides, reciprocity ``A_i F[(i,s),(j,t)] = A_j F[(j,t),(i,s)]`` holds exactly and
every side's row sums to 1 with its sky term (what leaves the scene). A face "to face j"
(``--to-face``) counts both sides of j.

Point to face
-------------
The visible part of face j from the point, from the point's V-cells (the file's, or
computed on demand: :func:`viscx.queries.visibility.view_from`), clipped to the point's
front hemisphere, then Lambert's contour formula over its loops (outer loops and holes):
exact up to float64.

Face to face
------------
``A_i F_ij = ∫_{x ∈ I} F(x → part of J visible from x) dx``. First the pair is reduced to
what can matter: I clipped to the half-space on side t of J's plane (I', the points that
see that side), J clipped to the front half-space of side s of I (J'), and the occluders:
every other face that meets the interior of the *shaft*, the convex hull of I' ∪ J'
(an exact separating-axis test in one numba call: a face only touching the hull blocks no
segment from I' to J'), clipped to both half-spaces. Then

    F_ij = F⁰(I' → J') − (1/A_i) ∫_{I'} [F(x → J') − F(x → visible part of J')] dx,

F⁰ the unoccluded form factor by the exact double contour integral
(:func:`viscx.geometry.formfactor.polygon_to_polygon`; with no occluder it is the answer)
and the second term what the occluders hide, by adaptive cubature over triangles of I'
(:class:`Cubature`):

* the integrand at x is exact: the visible part of J' from x by polygon clipping against
  the occluders' central projections (:func:`viscx.geometry.occlusion.blocked_form_factors`,
  a from-point hidden-surface computation, checked against the V-cells on samples), then
  Lambert, in numba batches;
* every triangle carries the occluders that meet *its* shaft to J' (culled from its
  parent's as it is split): where none does, the hidden part is zero, exactly, and nothing
  is evaluated; elsewhere the lists shrink to the few occluders that bound the shadows;
* I' starts as the emitter's cells (:func:`emitter_cells`): its triangles cut along the
  lines where other faces touch or cross it, across which F(x) jumps; inside a cell the
  integrand is continuous, with kinks along the discontinuity mesh that refinement follows;
* a triangle's error estimate comes from Radon's degree-5 rule on it and on its
  descendants (:class:`Cubature`, :class:`RowCubature`), and the triangles with the
  largest estimates are split until their sum meets the tolerance.
* where the emitter's cells can be cut along its kink lines too (:func:`cubature_cells`,
  as the matrix row's), the integrand is C1 on every cell and the row's two-level
  :class:`RowCubature` integrates the pair (one column); else the three levels of
  :class:`Cubature`.

The reported ``error`` is the contour integral's estimate (two node sets) plus the sum of
the triangles' estimates: an estimate of the actual error made to lie above it, not a
proven bound (tests check it against closed forms, finer integrals and Monte Carlo;
benchmarks/pair_honesty.py measures it on furnished rooms). Cost and memory grow with
the triangles that meet shadows, never with combinations of edges; every kernel call is
bounded (:data:`CHUNK`, :data:`MAX_CELLS`).
"""

import contextlib
import functools
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from viscx.arrays import expand_ranges, graph_components, loop_successors, reversed_loops, unique_rows
from viscx.errors import ViscxError
from viscx.geometry.arrangement import cut_pieces, flat_to_pieces, piece_centres, pieces_to_flat, segments_crossing
from viscx.geometry.formfactor import clip_to_hemisphere, point_to_polygon, polygon_to_polygon_orders
from viscx.geometry.occlusion import (TURNED_OVER, blocked_form_factors, point_views, points_behind_planes,
                                     shaft_boxes_meet, shaft_meets, umbra_triangles, visible_form_factors)
from viscx.geometry.polygon import newell_normal, newell_normals, plane_basis
from viscx.parallel import default_workers, map_chunks, row_chunks
from viscx.queries.kinks import apex_segments, face_generators, kink_segments, load_kink_kernels, sky_generators

#: Default target on the absolute error of one form factor (a pair, a group) ...
DEFAULT_TOL = 1e-6
#: ... and of each entry of the matrix.
MATRIX_TOL = 1e-6

#: Rotation of J's 2-D basis (radians), away from any axis a modeller would use.
GENERIC_ANGLE = 0.5873926
#: The cubature's first triangles are no longer than this fraction of the pair's extent.
MIN_SPLIT = 4
#: The first triangles of a matrix row on three levels (:class:`ThreeLevelRowCubature`)
#: are no longer than this fraction of the row's extent: its 16 grandchildren are each
#: evaluated, so the nodes lie as densely as those of the children of triangles a
#: :data:`MIN_SPLIT` start gives, where a kink-cut row (:class:`RowCubature`) starts.
THREE_LEVEL_SPLIT = 2


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def oriented_loops(loops, normal):
    """Loops with the outer (first) counter-clockwise about ``normal`` and holes clockwise."""
    out = []
    for k, loop in enumerate(loops):
        loop = np.asarray(loop, dtype=np.float64)
        if (newell_normal(loop) @ normal > 0) != (k == 0):
            loop = loop[::-1]
        out.append(loop)
    return out


def clip_loops(loops, normal, offset):
    """The loops' parts with ``normal · y >= offset`` (Sutherland–Hodgman per loop; holes
    stay holes, degenerate bridges along the cut cancel in every contour or winding sum)."""
    point = np.asarray(normal) * offset
    out = []
    for k, loop in enumerate(loops):
        part = clip_to_hemisphere(loop, point, normal)
        if len(part) >= 3:
            out.append(part)
        elif k == 0:
            return []
    return out


def _dots(a, b):
    """(l,) float64: the row-wise dot products of (l, 3) arrays, the same bits as ``a[i] @ b[i]``."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def loops_area(loops, normal):
    """Signed area about ``normal`` (outer counter-clockwise positive, holes negative)."""
    return 0.5 * float(sum(newell_normal(loop) @ normal for loop in loops)) if loops else 0.0


@dataclass
class Target:
    """A polygon to receive: a face or a virtual polygon (the sky's box faces).

    Attributes
    ----------
    loops : list of (k, 3) float64
        Outer loop first, then holes.
    normal : (3,) float64
        Its geometric normal (side +1).
    face : int
        Face id, -1 for a virtual polygon (no face is excluded from its occluders).
    """

    loops: list
    normal: np.ndarray
    face: int = -1


def face_target(scene, face):
    return Target(scene.face_loops(face), scene.face_normal[face].copy(), int(face))


def sky_targets(scene):
    """The six faces of the scene's bounding box enlarged by 5 % of its diagonal, normals
    inwards: every ray that meets no face leaves through exactly one of them, so the form
    factor to them is the sky term (a virtual closed box; they block nothing)."""
    lo, hi = scene.bbox
    m = 0.05 * scene.diagonal
    lo, hi = lo - m, hi + m
    out = []
    for axis in range(3):
        for sign, plane in ((1.0, lo[axis]), (-1.0, hi[axis])):
            a, b = (axis + 1) % 3, (axis + 2) % 3
            quad = np.zeros((4, 3))
            quad[:, axis] = plane
            quad[:, a] = [lo[a], hi[a], hi[a], lo[a]]
            quad[:, b] = [lo[b], lo[b], hi[b], hi[b]]
            n = np.zeros(3)
            n[axis] = sign
            out.append(Target(oriented_loops([quad], n), n, -1))
    return out


# --------------------------------------------------------------------------------------
# occluders of a pair


def face_boxes(scene):
    """Bounding boxes of the faces' outer loops, ``(lo, hi)`` (f, 3) float64 each (cached)."""

    def build(scene):
        start = scene.loop_offsets[scene.face_loop_offsets[:-1]]
        pts = scene.vertices[scene.loop_vertices]
        return np.minimum.reduceat(pts, start, axis=0), np.maximum.reduceat(pts, start, axis=0)

    return scene.cached("face_boxes", build)


def face_outlines(scene):
    """The faces' outer loops as flat arrays: ``(points (n, 3) float64, lo (f,) int64,
    hi (f,) int64)``, face f's loop at ``points[lo[f]:hi[f]]``."""
    first = scene.face_loop_offsets[:-1]
    return (np.ascontiguousarray(scene.vertices[scene.loop_vertices]), scene.loop_offsets[first].astype(np.int64),
            scene.loop_offsets[first + 1].astype(np.int64))


def closed_boxes(scene):
    """The closed convex polyhedra made of faces of the scene (a box: a cabinet, a desk's
    top, a panel), for culling their back faces (:func:`viscx.geometry.occlusion.blocked_form_factors`,
    :func:`viscx.geometry.occlusion.point_views`), and the convex boxes with one face missing
    (a Cornell block, open at the bottom, standing on the floor).

    Two faces without holes are linked when they share an edge, traversed in opposite
    directions (loops counter-clockwise about the normals), are not coplanar, and each
    lies behind or on the other's plane (a convex dihedral). A connected set of linked
    faces is a box when every directed edge of its faces has its reverse among them
    (closed, normals outward) and every vertex of its faces lies behind or on every one of
    their planes (convex). Faces flush with a face of another box (a desk's panel under
    its top) are coplanar or reflex with it, so boxes that touch are never merged.

    An *open* box: the edges without their reverse form one planar loop, the outline of
    the missing face M (that loop reversed, its normal outward), and every vertex lies
    behind or on M's plane too. For a point x behind or on M's plane (the side the box is
    on: a point of the room above a block standing on the floor), the faces form a closed
    box as far as x can tell: a ray enters a convex solid through a face whose outward
    normal it goes against, and a ray from x cannot go against M's normal when it meets M's
    plane (it leaves x's closed half-space there; x in the plane: it never meets it again).
    So every ray from x that meets a face x is behind has entered the box through a real
    face, and the closed-box rules hold. M's plane is listed with the box's planes, flagged
    ``open`` (:func:`viscx.geometry.occlusion._outside_box` then asks x to lie behind it or
    within ``tiny`` of it; beyond, the faces are swept on their own).

    Returns
    -------
    face_box : (f,) int64
        The box of each face, -1 if none.
    box_ptr : (b + 1,) int64
    box_planes : (k, 5) float64
        The planes ``n · y = c`` (n outward) of box b: ``box_planes[box_ptr[b]:box_ptr[b + 1]]``
        as ``(n, c, open)``, ``open`` 1.0 for the missing face of an open box, else 0.0.
    """

    def build(scene):
        n, nv = scene.n_faces, scene.n_vertices
        tol = 1e-9 * scene.diagonal
        normal = scene.face_normal.astype(np.float64)
        offset = scene.face_offset.astype(np.float64)
        flo, lo = scene.face_loop_offsets, scene.loop_offsets.astype(np.int64)
        # the directed edges of the faces without holes (a face with holes bounds no box),
        # each loop counter-clockwise about its face's normal
        one = np.flatnonzero(np.diff(flo) == 1)
        loop = flo[one]
        sizes = lo[loop + 1] - lo[loop]
        if not len(one):
            return np.full(n, -1, np.int64), np.zeros(1, np.int64), np.zeros((0, 5))
        turned = reversed_loops(lo, loop_normal_dots(scene) < 0)
        ea = scene.loop_vertices[turned[expand_ranges(lo[loop], sizes)[1]]].astype(np.int64)
        eb, ef = ea[loop_successors(np.concatenate([[0], np.cumsum(sizes)]))], np.repeat(one, sizes)
        # faces sharing an edge traversed both ways
        key, rev = ea * nv + eb, eb * nv + ea
        order = np.argsort(key, kind="stable")
        sk = key[order]
        left = np.searchsorted(sk, rev, "left")
        count = np.searchsorted(sk, rev, "right") - left
        f = np.repeat(ef, count)
        g = ef[order[expand_ranges(left, count)[1]]]
        f, g = f[f != g], g[f != g]
        # linked: not coplanar, and every vertex of each behind or on the other's plane
        # (a face's vertices padded with its first, so that one array holds them all)
        width = int(sizes.max(initial=1))
        padded = np.zeros((n, width), np.int64)
        col = np.minimum(np.arange(width), sizes[:, None] - 1)
        padded[one] = ea[(np.cumsum(sizes) - sizes)[:, None] + col]
        corners = scene.vertices[padded].astype(np.float64)  # (n, width, 3)

        def behind(f, g):  # every vertex of g behind or on f's plane
            return np.einsum("kjd,kd->kj", corners[g], normal[f]).max(axis=1) - offset[f] <= tol

        linked = np.abs(np.einsum("kd,kd->k", normal[f], normal[g])) < 1 - 1e-9
        linked[linked] &= behind(f[linked], g[linked]) & behind(g[linked], f[linked])
        _, comp = graph_components(n, f[linked], g[linked])
        # per component: its directed edges' counts and their reverses' (closed: equal;
        # an open box's bare edges, once and without reverse, outline its missing face)
        members = np.bincount(comp[one], minlength=n)
        ec = comp[ef]
        ids = unique_rows(np.concatenate([np.stack([ec, ea, eb], 1), np.stack([ec, eb, ea], 1)]))[1]
        tally = np.bincount(ids[:len(ea)], minlength=int(ids.max()) + 1)
        kcount, rcount = tally[ids[:len(ea)]], tally[ids[len(ea):]]
        bare = (kcount == 1) & (rcount == 0)
        broken = np.bincount(ec[~bare & (rcount != kcount)], minlength=n) > 0
        has_bare = np.bincount(ec[bare], minlength=n) > 0
        face_box = np.full(n, -1, np.int64)
        ptr, planes = [0], []
        by_comp = np.argsort(comp[one], kind="stable")
        comp_first = np.searchsorted(comp[one][by_comp], np.arange(n + 1))
        edge_order = np.argsort(ec, kind="stable")
        edge_first = np.searchsorted(ec[edge_order], np.arange(n + 1))
        for c in np.flatnonzero((members >= 3) & ~broken):
            faces = one[by_comp[comp_first[c]:comp_first[c + 1]]]
            if not has_bare[c] and len(faces) < 4:
                continue
            edges = edge_order[edge_first[c]:edge_first[c + 1]]
            verts = scene.vertices[np.unique(ea[edges])].astype(np.float64)
            box = np.concatenate([normal[faces], offset[faces, None], np.zeros((len(faces), 1))], axis=1)
            if has_bare[c]:
                m = _missing_face(scene.vertices, list(zip(ea[edges][bare[edges]].tolist(),
                                                            eb[edges][bare[edges]].tolist())), tol)
                if m is None:
                    continue
                box = np.concatenate([box, np.concatenate([m, [1.0]])[None]])
            if not points_behind_planes(verts, box, tol):
                continue
            face_box[faces] = len(ptr) - 1
            planes.extend(box)
            ptr.append(len(planes))
        return face_box, np.asarray(ptr, np.int64), np.asarray(planes, np.float64).reshape(-1, 5)

    return scene.cached("closed_boxes", build)


def _missing_face(vertices, bare, tol):
    """The plane ``(n, c)`` (4,) float64 of the face that would close an open box, or None:
    the box's edges without a reverse (``bare``, directed vertex pairs) must form one loop,
    lying in one plane within ``tol``; the missing face runs along it backwards, so its
    outward normal is the Newell normal of the reversed loop."""
    succ = {}
    for a, b in bare:
        if b in succ:
            return None  # two bare edges into one vertex: no simple loop
        succ[b] = a  # reversed: b -> a
    start = bare[0][1]
    loop, v = [start], succ[start]
    while v != start:
        if len(loop) > len(bare) or v not in succ:
            return None
        loop.append(v)
        v = succ[v]
    if len(loop) != len(bare):
        return None  # more than one loop
    pts = vertices[loop].astype(np.float64)
    nrm = newell_normal(pts)
    size = float(np.linalg.norm(nrm))
    if size == 0.0:
        return None
    nrm = nrm / size
    c = float(np.mean(pts @ nrm))
    if np.any(np.abs(pts @ nrm - c) > tol):
        return None
    return np.concatenate([nrm, [c]])


def _plane_ranges(ptr, boxes):
    """The rows of boxes ``boxes`` (n,) int64 in CSR ``ptr`` (the planes of
    :func:`closed_boxes`), box after box: ``(rows (t,) int64, first (n,) int64)``, box k's
    rows at ``first[k]:first[k] + its count`` of them."""
    sizes = ptr[boxes + 1] - ptr[boxes]
    first = np.cumsum(sizes) - sizes
    return np.arange(int(sizes.sum()), dtype=np.int64) - np.repeat(first - ptr[boxes], sizes), first


def _closed_box_flags(scene):
    """(b,) bool: the :func:`closed_boxes` boxes that are closed (no missing face), cached."""

    def build(scene):
        _, ptr, planes = closed_boxes(scene)
        if len(ptr) < 2:
            return np.zeros(0, bool)
        return ~np.logical_or.reduceat(planes[:, 4] != 0.0, ptr[:-1])

    return scene.cached("closed_box_flags", build)


#: A closed convex box of more planes than this (a tessellated or scanned convex solid)
#: is swept by the pair kernel as the outline of its front faces, as any closed solid
#: (:func:`closed_solids`), not as the convex hull of all its faces' projections, whose
#: points grow with its faces: per point, 6 icospheres over a floor, light → floor, 20
#: faces each 44 → 37 µs, 80 faces 250 → 178, 1,280 faces 1,392 → 296, 20,480 faces
#: 1.1e5 → 2,150. Furniture (boxes of 5 or 6 faces) keeps the hull, whose shadows inside
#: another box's are dropped whole (:func:`viscx.geometry.occlusion._drop_covered_hulls`).
HULL_BOX_FACES = 16

#: Planes per block of (triangle, box) pairs in :func:`back_faces`: bounds its memory (a
#: scanned convex solid is one box of thousands of planes).
PLANE_BLOCK = 1 << 20


def surface_patches(scene):
    """The faces joined into consistently oriented surfaces, closed or not (a scan's open
    shell, a solid's faces): two faces are neighbours across an edge that one traverses
    from a to b and the other from b to a, no third face traversing it (outer loops
    counter-clockwise about the normals, holes clockwise). Cached.

    Returns
    -------
    patch : (f,) int64
        The patch of each face (:func:`viscx.arrays.graph_components` of the neighbours:
        a face with none is a patch of its own).
    neighbour : (m,) int64
        Aligned with ``scene.loop_vertices``: the face across the edge from each loop
        vertex to the next, -1 none.
    """

    def build(scene):
        n, lv, lo = scene.n_faces, scene.loop_vertices.astype(np.int64), scene.loop_offsets.astype(np.int64)
        flo = scene.face_loop_offsets
        loop_face = np.repeat(np.arange(n), np.diff(flo))
        a, b = lv, lv[loop_successors(lo)]
        face = np.repeat(loop_face, np.diff(lo))
        nv = scene.n_vertices
        key, rev = a * nv + b, b * nv + a
        order = np.argsort(key, kind="stable")
        sk = key[order]
        count = np.searchsorted(sk, key, "right") - np.searchsorted(sk, key, "left")
        left = np.searchsorted(sk, rev, "left")
        rcount = np.searchsorted(sk, rev, "right") - left
        neighbour = np.full(len(lv), -1, np.int64)
        paired = (count == 1) & (rcount == 1)
        neighbour[paired] = face[order[left[paired]]]
        paired &= neighbour != face
        neighbour[~paired] = -1
        link = np.flatnonzero(paired)
        return graph_components(n, face[link], neighbour[link])[1], neighbour

    return scene.cached("surface_patches", build)


def closed_solids(scene):
    """The closed solids bounded by faces of the scene, convex or not (a scanned statue: the
    npm bunny's 3,674 triangles): connected sets of faces in which every directed edge of
    a face (outer loops counter-clockwise about the normals, holes clockwise) is traversed
    backwards by exactly one other face of the set and by no third face (a watertight,
    consistently oriented 2-manifold). A face may have holes: the ring of coplanar quads
    at the top of a finely tessellated torus is one face, an annulus, once the scene's
    coplanar triangles are merged, and so is a pipe's end. A ray from a point outside such a solid that meets a
    face the point is behind (a back face) has entered the solid before, through a face the
    point is in front of; so from such a point an edge between two front faces or two back
    faces is never on the outline of what the solid hides (docs/queries.md).

    Returns
    -------
    face_solid : (f,) int64
        The solid of each face, -1 if none.
    outward : (s,) float64
        +1 where the faces' normals point out of solid s, -1 where they point in (the
        sign of its volume by the divergence theorem).
    neighbour : (m,) int64
        Aligned with ``scene.loop_vertices``: the face across the edge from each loop
        vertex to the next, -1 outside a solid.
    """

    def build(scene):
        n = scene.n_faces
        comp, neighbour = surface_patches(scene)
        face = np.repeat(np.repeat(np.arange(n), np.diff(scene.face_loop_offsets)), np.diff(scene.loop_offsets))
        # a solid: every edge of every face of the patch paired
        bare = np.bincount(comp[face[neighbour < 0]], minlength=n) > 0
        faces_in = np.bincount(comp, minlength=n)
        good = ~bare & (faces_in >= 4)
        face_solid = np.full(n, -1, np.int64)
        ok = good[comp]
        ids, face_solid[ok] = np.unique(comp[ok], return_inverse=True)
        neighbour = np.where(ok[face], neighbour, -1)
        # volume: Σ_f A_f (n_f · p_f) / 3 over each solid's faces
        vol = np.bincount(face_solid[ok], weights=scene.face_area[ok] * scene.face_offset[ok], minlength=len(ids))
        return face_solid, np.where(vol >= 0, 1.0, -1.0), neighbour

    return scene.cached("closed_solids", build)


#: Rooms of more faces are not looked at by :func:`enclosed_sides` (a pass over every
#: vertex per plane of the room).
MAX_ROOM_FACES = 256

#: What share of a face may lie behind a room's plane (by the bound −h_min / (h_max − h_min)
#: on its heights over it) and still count as in the room: rounding (a panel standing on
#: the floor: −1e-17 against 0.72 m); the sky such a sliver could see is below any tol.
ROOM_SLIVER = 1e-12


def enclosed_sides(scene):
    """(2 f,) bool, element ``2 f`` the front of face f and ``2 f + 1`` its back: the sides
    whose sky term is 0 by construction, those inside a closed room.

    A room here is a :func:`closed_solids` solid whose normals point into it and which is
    convex (each of its faces in front of or on every plane of the others): the office's
    shell. Being closed and consistently oriented, its faces cover the whole boundary of
    the convex solid their planes bound. A face with every vertex in front of every plane
    of a room lies in it (a planar polygon lies in the convex hull of its vertices). A point
    of its relative interior not in a plane of the room is strictly inside, and every ray
    from it leaves the bounded room through one of its faces, which stops it: no sky. A
    face in a plane of the room (all its vertices within 1e-9 of the scene's size of it: a
    room's own face, a poster on a wall) has its side facing in enclosed too (its rays run
    in the room); its side facing out is not (it lies on the room's face: the plane meets
    the convex room in that face only; :func:`closed_form_row`). A face not in a plane but
    with a vertex behind it lies partly outside the room: it counts as in only if that
    part is at most ``ROOM_SLIVER`` of it (rounding), else neither side is enclosed (a
    poster crossing its wall's plane within 1e-9 sees the sky past it). Rooms of more than
    ``MAX_ROOM_FACES`` faces are not looked at. Cached."""

    def build(scene):
        n = scene.n_faces
        out = np.zeros(2 * n, bool)
        face_solid, outward, _ = closed_solids(scene)
        tiny = 1e-9 * scene.diagonal
        outline, lo, _ = face_outlines(scene)
        for s in np.flatnonzero(outward < 0):
            room = np.flatnonzero(face_solid == s)
            if len(room) > MAX_ROOM_FACES:
                continue
            inside = np.ones(n, bool)
            facing_out = np.zeros(2 * n, bool)
            for f in room:
                # each face's heights over the plane (its normal points into the room)
                n_r = scene.face_normal[f].astype(np.float64)
                h = outline @ n_r - float(scene.face_offset[f])
                low, high = np.minimum.reduceat(h, lo), np.maximum.reduceat(h, lo)
                flat = (low >= -tiny) & (high <= tiny)
                inside &= flat | (low >= -ROOM_SLIVER * (high - low))
                # the flat faces' side facing out of the room: the front (element 2 g) where
                # its normal goes against the plane's, else the back
                g = np.flatnonzero(flat)
                facing_out[2 * g + (scene.face_normal[g] @ n_r > 0)] = True
            if inside[room].all():  # convex
                out |= np.repeat(inside, 2) & ~facing_out
        return out

    return scene.cached("enclosed_sides", build)


def may_see_sky(scene, face, side):
    """Whether a face side's sky term must be computed: False for a side inside a closed
    room (:func:`enclosed_sides`), whose sky term is 0 exactly."""
    return not enclosed_sides(scene)[2 * int(face) + (0 if side > 0 else 1)]


def _outside_solids(scene, n, c, tiny):
    """(s,) bool: the :func:`closed_solids` whose normals point out and that lie in the
    closed front half-space ``n · y >= c`` (within ``tiny``) of an emitter's plane: every
    point of the plane is outside them or on them."""
    face_solid, outward, _ = closed_solids(scene)
    if not len(outward):
        return np.zeros(0, bool)
    loop_face = np.repeat(np.arange(scene.n_faces), np.diff(scene.face_loop_offsets))
    vface = np.repeat(loop_face, np.diff(scene.loop_offsets))
    solid = face_solid[vface]
    low = np.full(len(outward), np.inf)
    np.minimum.at(low, solid[solid >= 0], scene.vertices[scene.loop_vertices[solid >= 0]] @ n - c)
    return (outward > 0) & (low >= -tiny)


def solid_edge_positions(scene, face, loop, j=0):
    """(k,) int64: for loop ``j`` (0 the outer) ``loop`` (k, 3) of a face's part, the
    position in ``scene.loop_vertices`` of each edge's start when the part's loop is the
    face's whole loop j (not clipped: the same points in the same order), else -1 (no
    :func:`closed_solids` rule for its edges)."""
    first = scene.face_loop_offsets[face] + j
    if first >= scene.face_loop_offsets[face + 1]:
        return np.full(len(loop), -1, np.int64)
    lo, hi = scene.loop_offsets[first], scene.loop_offsets[first + 1]
    whole = scene.vertices[scene.loop_vertices[lo:hi]]
    if whole.shape != loop.shape or not np.array_equal(whole, loop):
        return np.full(len(loop), -1, np.int64)
    return np.arange(lo, hi, dtype=np.int64)


def inner_solid_edges(scene, n, c, tiny, faces, pos, points):
    """(e,) bool: whether edge e (the edge of face ``faces[e]`` starting at loop vertex
    ``pos[e]``, -1 none) is, from every one of ``points[e]`` (e, r, 3) on the emitter's
    plane ``n · y = c``, an edge between two front faces or between two back faces of a
    :func:`closed_solids` solid the plane is outside of (by more than ``tiny`` from each
    face's plane): never on the outline of what the solid hides from there. From a
    point outside the solid the front faces' images cover everything the solid hides, with
    the number of front faces a ray crosses as their winding, so an edge between two front
    faces lies inside their images and one between two back faces behind one of them; what
    a point sees of the light changes only across the images of edges between a front and
    a back face (or of faces seen edge-on). The facing is linear along the plane, so three
    points decide it for their triangle."""
    out = np.zeros(len(faces), bool)
    face_solid, outward, neighbour = closed_solids(scene)
    ok = (pos >= 0) & (faces >= 0)
    ok[ok] &= face_solid[faces[ok]] >= 0
    if not np.any(ok):
        return out
    eligible = _outside_solids(scene, n, c, tiny)
    ok[ok] &= eligible[face_solid[faces[ok]]]
    rows = np.flatnonzero(ok)
    if not len(rows):
        return out
    other = neighbour[pos[rows]]
    sign = outward[face_solid[faces[rows]]][:, None]
    x = points[rows]

    def facing(f):
        return sign * (np.einsum("erj,ej->er", x, scene.face_normal[f]) - scene.face_offset[f][:, None])

    a, b = facing(faces[rows]), facing(other)
    front = np.all(a > tiny, axis=1) & np.all(b > tiny, axis=1)
    back = np.all(a < -tiny, axis=1) & np.all(b < -tiny, axis=1)
    out[rows] = front | back
    return out


#: Planes parallel to the target across each closed solid whose sections show the
#: emitter's triangles wholly in its umbra (:func:`solid_sections`, :meth:`PairSetup.umbra`).
UMBRA_PLANES = 16


def solid_sections(scene, solids, n, c, tiny, count=UMBRA_PLANES):
    """Sections of closed solids (:func:`closed_solids`, ids ``solids``) by ``count`` planes
    ``n · y = c + h`` spread evenly across their extent along n (midpoints of ``count``
    equal slices; a plane within 10 ``tiny`` of a vertex of a solid is left out, so that
    every edge crossing it crosses it properly and no face lies in it), as 2-D segments in
    the basis :func:`plane_basis` (n). The crossing point of an edge is computed once per
    edge (from its lower vertex id to its higher), so the two faces along it give the same
    point bit for bit and the sections are closed polylines sharing their vertices (what
    the parity count of :func:`viscx.geometry.occlusion.umbra_triangles` needs). A face
    meets a plane in the chords between its crossing points taken in pairs along the line
    (a non-convex face: more than one).

    Returns
    -------
    heights : (k,) float64
    sec_ptr : (k + 1,) int64
    sec : (s, 4) float64
        Segments ``(u_a, v_a, u_b, v_b)`` of plane k: ``sec[sec_ptr[k]:sec_ptr[k + 1]]``.
    """
    face_solid = closed_solids(scene)[0]
    faces = np.flatnonzero(np.isin(face_solid, np.asarray(solids, np.int64)))
    eu, ev = plane_basis(n)
    if not len(faces):
        return np.zeros(0), np.zeros(1, np.int64), np.zeros((0, 4))
    flo = scene.face_loop_offsets
    row, loops = expand_ranges(flo[faces], flo[faces + 1] - flo[faces])  # holes too
    lo, hi = scene.loop_offsets[loops], scene.loop_offsets[loops + 1]
    sizes = hi - lo
    pos = expand_ranges(lo, sizes)[1]
    nxt = pos[loop_successors(np.concatenate([[0], np.cumsum(sizes)]))]
    edge_face = np.repeat(faces[row], sizes)
    a, b = scene.loop_vertices[pos].astype(np.int64), scene.loop_vertices[nxt].astype(np.int64)
    a, b = np.minimum(a, b), np.maximum(a, b)
    height = scene.vertices @ n - c
    used = np.unique(np.concatenate([a, b]))
    top, bottom = float(height[used].max()), float(height[used].min())
    heights, ptr, out = [], [0], []
    face_dir = np.cross(scene.face_normal[faces], n)  # along each face's chord
    for k in range(count):
        h = bottom + (top - bottom) * (k + 0.5) / count
        if np.min(np.abs(height[used] - h)) <= 10 * tiny:
            continue
        d = height - h
        cross = np.flatnonzero((d[a] > 0) != (d[b] > 0))
        ea, eb, ef = a[cross], b[cross], edge_face[cross]
        t = (d[ea] / (d[ea] - d[eb]))[:, None]
        p = scene.vertices[ea] + t * (scene.vertices[eb] - scene.vertices[ea])
        uv = np.stack([p @ eu, p @ ev], axis=1)
        order = np.argsort(ef, kind="stable")
        ef, uv = ef[order], uv[order]
        starts = np.flatnonzero(np.concatenate([[True], ef[1:] != ef[:-1]]))
        counts = np.diff(np.concatenate([starts, [len(ef)]]))
        two = starts[counts == 2]
        segs = [np.concatenate([uv[two], uv[two + 1]], axis=1)]
        for s0, m in zip(starts[counts > 2], counts[counts > 2]):
            # a non-convex face: its chords are between the crossings in pairs along the line
            f = int(np.searchsorted(faces, ef[s0]))
            along = np.array([face_dir[f] @ eu, face_dir[f] @ ev])
            q = uv[s0:s0 + m][np.argsort(uv[s0:s0 + m] @ along, kind="stable")]
            segs.append(np.concatenate([q[0::2], q[1::2]], axis=1))
        seg = np.concatenate(segs)
        heights.append(h)
        ptr.append(ptr[-1] + len(seg))
        out.append(seg)
    if not heights:
        return np.zeros(0), np.zeros(1, np.int64), np.zeros((0, 4))
    return np.asarray(heights), np.asarray(ptr, np.int64), np.ascontiguousarray(np.concatenate(out))


def back_faces(scene, tri, cell, faces, tiny, n_i):
    """(c,) bool: for each pair (triangle ``tri[cell[c]]``, face ``faces[c]``), whether the
    face is a back face of a closed convex box (:func:`closed_boxes`) for every point of the
    triangle, each of which is outside the box: all three vertices behind the face's plane
    (by more than tiny), and for each plane of the box either all three on or behind it or
    all three more than 2 tiny in front, the latter for at least one (a convex combination
    keeps each, so every point of the triangle is outside the box and not within 2 tiny in
    front of one of its planes but a face lying on the emitter's plane (its front side's unit
    normal ``n_i`` (3,) float64), as :func:`viscx.geometry.occlusion._outside_box` asks). Such
    a face hides nothing from the triangle that the box's front faces do not
    (:func:`viscx.geometry.occlusion._outside`): it can be dropped from its occluders.

    Parameters
    ----------
    tri : (g, 3, 3) float64
    cell, faces : (c,) int64
        ``faces`` -1 for an occluder that is no face of the scene.
    """
    out = np.zeros(len(cell), bool)
    face_box, ptr, planes = closed_boxes(scene)
    boxed = np.flatnonzero(faces >= 0)
    boxed = boxed[face_box[faces[boxed]] >= 0]
    if not len(boxed):
        return out
    f = faces[boxed]
    v = tri[cell[boxed]]  # (k, 3, 3)
    own = np.einsum("kvj,kj->kv", v, scene.face_normal[f]) - scene.face_offset[f][:, None]
    boxed = boxed[np.all(own < -tiny, axis=1)]
    if not len(boxed):
        return out
    # the rest depends on the triangle and the box only: once per pair of them (an
    # icosphere of 20,480 faces is one box: per face, 36 GB for a light's 48,145 pairs)
    pair, where = np.unique(cell[boxed] * len(ptr) + face_box[faces[boxed]], return_inverse=True)
    pc, pb = pair // len(ptr), pair % len(ptr)
    ok = np.zeros(len(pair), bool)
    count = ptr[pb + 1] - ptr[pb]
    ends = np.cumsum(count)
    start = 0
    while start < len(pair):  # blocks of at most PLANE_BLOCK planes (one pair at least)
        base = int(ends[start - 1]) if start else 0
        stop = max(start + 1, int(np.searchsorted(ends, base + PLANE_BLOCK, side="right")))
        rows, first = _plane_ranges(ptr, pb[start:stop])
        p = planes[rows]  # (t, 5)
        owner = np.repeat(pc[start:stop], count[start:stop])
        h = np.einsum("tvj,tj->tv", tri[owner], p[:, :3]) - p[:, 3][:, None]  # (t, 3)
        missing = p[:, 4] != 0.0  # an open box's missing face: x on or behind its plane
        front = np.all(h > 2 * tiny, axis=1) & ~missing
        # a face on the emitter's plane facing away from its front: no way in (_outside_box)
        floor = (p[:, :3] @ n_i < TURNED_OVER) & np.all(h <= 2 * tiny, axis=1)
        fine = front | floor | np.all(h <= np.where(missing, tiny, 0.0)[:, None], axis=1)
        ok[start:stop] = np.logical_and.reduceat(fine, first) & np.logical_or.reduceat(front, first)
        start = stop
    out[boxed] = ok[where]
    return out


def no_boxes(n):
    """The box arrays of :func:`closed_boxes` for n polygons none of which is culled (a
    subset of the faces: a box's front faces may be missing from it)."""
    return np.full(n, -1, np.int64), np.zeros(1, np.int64), np.zeros((0, 5))


def hull_order(loops2):
    """(h,) int64: the vertices of the convex hull of 2-D loops (list of (k, 2)),
    counter-clockwise, as indices into their concatenation (collinear points left out). A
    single loop that is already strictly convex and counter-clockwise (most faces and their
    clipped parts) is its own hull; else Andrew's monotone chain (a pair's loops have a few
    dozen points: Qhull's set-up cost more, and importing scipy.spatial ~0.3 CPU s of a
    matrix). ValueError when the points span no area."""
    if len(loops2) == 1 and len(loops2[0]) >= 3:
        p = np.asarray(loops2[0], np.float64)
        e = np.roll(p, -1, axis=0) - p
        turn = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
        if np.all(turn > 1e-12 * np.einsum("ij,ij->i", e, e).max()):
            return np.arange(len(p))
    p = np.concatenate(loops2).astype(np.float64)
    x, y = p[:, 0].tolist(), p[:, 1].tolist()

    def chain(order):
        out = []
        for c in order:
            while len(out) >= 2:
                a, b = out[-2], out[-1]
                if (x[b] - x[a]) * (y[c] - y[a]) - (y[b] - y[a]) * (x[c] - x[a]) > 0:
                    break
                out.pop()
            out.append(c)
        return out[:-1]

    order = np.lexsort((p[:, 1], p[:, 0])).tolist()
    hull = chain(order) + chain(order[::-1])
    if len(hull) < 3:
        raise ValueError("the points span no area")
    return np.asarray(hull, np.int64)


def convex_outline(loops, normal):
    """(k, 3) float64: the convex hull of planar loops, counter-clockwise about ``normal``
    (the points themselves when they span no area)."""
    pts = np.concatenate(loops)
    eu, ev = plane_basis(normal)
    try:
        return np.ascontiguousarray(pts[hull_order([np.stack([l @ eu, l @ ev], axis=1) for l in loops])])
    except ValueError:
        return np.ascontiguousarray(pts)


def _polygon_arrays(polygons):
    """Outer loops of ``(loops, normal, face)`` polygons as :func:`shaft_meets` wants them:
    ``(points, lo, hi, normals)``."""
    outer = [np.asarray(p[0][0], dtype=np.float64) for p in polygons]
    sizes = np.array([len(o) for o in outer], np.int64)
    hi = np.cumsum(sizes)
    pts = np.concatenate(outer) if outer else np.zeros((0, 3))
    normals = np.asarray([p[1] for p in polygons], np.float64).reshape(-1, 3)
    return np.ascontiguousarray(pts), (hi - sizes).astype(np.int64), hi.astype(np.int64), normals


def pair_occluders(scene, I, n_i, c_i, J, n_t, c_t, exclude):
    """Faces that may block a segment from I' to J': those meeting the interior of the shaft
    (the convex hull of I' ∪ J', :func:`viscx.geometry.occlusion.shaft_meets`, one numba
    call over the faces whose boxes meet the hull's box), clipped to the front of I and the
    receiving side of J (the hull lies in both half-spaces, so a face meets it iff its
    clipped part does).

    Returns
    -------
    list of (loops, normal, face)
        Clipped loops (outer counter-clockwise about the face normal, holes clockwise).
    """
    tol = 1e-9 * scene.diagonal
    pts = np.concatenate(I + J)
    lo, hi = pts.min(axis=0) - tol, pts.max(axis=0) + tol
    box_lo, box_hi = face_boxes(scene)
    near = np.flatnonzero(np.all(box_lo <= hi, axis=1) & np.all(box_hi >= lo, axis=1))
    near = near[~np.isin(near, list(exclude))]
    if not len(near):
        return []
    hull_i, hull_j = convex_outline(I, n_i), convex_outline(J, n_t)
    outline, o_lo, o_hi = face_outlines(scene)
    meets = shaft_meets(hull_i[None], n_i[None], hull_j, np.asarray(n_t, np.float64), np.zeros(len(near), np.int64),
                        near.astype(np.int64), outline, o_lo, o_hi, scene.face_normal.astype(np.float64), tol)
    hits = near[meets]
    # a face with no vertex behind either plane is its own clipped part: its cached loops,
    # clipped in Python only where a plane cuts it (office(1000): most of a pair's occluders
    # are not; the heights as Sutherland–Hodgman takes them, (y − n c) · n)
    areas, loop_faces = face_loops_oriented(scene)
    ahead = np.ones(len(hits), bool)
    for n, c in ((n_i, c_i), (n_t, c_t)):
        rel = outline - np.asarray(n, np.float64) * c
        h = rel[:, 0] * n[0] + rel[:, 1] * n[1] + rel[:, 2] * n[2]
        ahead &= np.minimum.reduceat(h, o_lo)[hits] >= 0
    clipped = []
    for k, free in zip(hits, ahead):
        nk = scene.face_normal[k]
        if free:
            loops = loop_faces[k]
            if areas[k] > tol * tol:
                clipped.append((loops, nk, int(k)))
            continue
        loops = clip_loops(clip_loops(loop_faces[k], n_i, c_i), n_t, c_t)
        if loops and abs(loops_area(loops, nk)) > tol * tol:
            clipped.append((loops, nk, int(k)))
    return clipped


def loop_normal_dots(scene):
    """(l,) float64: each loop's Newell normal (:func:`viscx.geometry.polygon.newell_normals`)
    dotted with its face's normal, as ``newell_normal(loop) @ normal``, bit for bit: the sign
    says which way the loop turns about the face. Cached."""

    def build(scene):
        flo, lo = scene.face_loop_offsets, scene.loop_offsets.astype(np.int64)
        normal = scene.face_normal.astype(np.float64)[np.repeat(np.arange(scene.n_faces), np.diff(flo))]
        return _dots(newell_normals(scene.vertices[scene.loop_vertices], lo), normal)

    return scene.cached("loop_normal_dots", build)


def face_loops_oriented(scene):
    """Every face's loops as :func:`oriented_loops` about its normal, and their areas
    ``|loops_area|`` (f,) float64: ``(areas, [loops per face])``, cached (the kernels'
    polygons, :func:`scene_polygons`, and a pair's occluders, :func:`pair_occluders`,
    as they are where no plane clips them). Read only."""

    def build(scene):
        # oriented_loops and loops_area of every face, vectorised over all loops (the same
        # bits: newell_normals sums as newell_normal does): a 10⁵-triangle mesh in a second
        n, flo, lo = scene.n_faces, scene.face_loop_offsets, scene.loop_offsets.astype(np.int64)
        loop_face = np.repeat(np.arange(n), np.diff(flo))
        outer = np.zeros(len(lo) - 1, bool)
        outer[flo[:-1][np.diff(flo) > 0]] = True
        normal = scene.face_normal.astype(np.float64)[loop_face]
        pts = scene.vertices[scene.loop_vertices].astype(np.float64)
        pts = pts[reversed_loops(lo, (loop_normal_dots(scene) > 0) != outer)]
        # 0.5 Σ_loops N · n, the loops added in order as Python's sum adds them
        dots = _dots(newell_normals(pts, lo), normal)
        areas = np.zeros(n)
        for k in range(int(np.diff(flo).max(initial=0))):
            has = np.flatnonzero(np.diff(flo) > k)
            areas[has] = areas[has] + dots[flo[has] + k]
        areas = np.abs(0.5 * areas)
        loops = np.split(pts, lo[1:-1])
        return areas, [loops[flo[f]:flo[f + 1]] for f in range(n)]

    return scene.cached("face_loops_oriented", build)


# --------------------------------------------------------------------------------------
# the emitter's cells: cut along its contact lines


def _cut_convex(piece, a, d, eps):
    """A convex 2-D polygon (k, 2) cut by the line through ``a`` along ``d`` (unit): its two
    parts (each possibly empty)."""
    # Python floats: a piece has a handful of vertices, and numpy's per-call cost would
    # be most of the work (the same IEEE operations, so the same digits)
    a0, a1, d0, d1 = float(a[0]), float(a[1]), float(d[0]), float(d[1])
    pts = piece.tolist()
    s = [(x - a0) * d1 - (y - a1) * d0 for x, y in pts]
    k = len(pts)
    out = []
    for sign in (1.0, -1.0):
        h = [sign * v for v in s]
        part = []
        for i in range(k):
            r = (i + 1) % k
            if h[i] >= 0:
                part.append(pts[i])
            if (h[i] > 0 and h[r] < 0) or (h[i] < 0 and h[r] > 0):
                t = h[i] / (h[i] - h[r])
                part.append([pts[i][0] + (pts[r][0] - pts[i][0]) * t, pts[i][1] + (pts[r][1] - pts[i][1]) * t])
        part = np.array(part, np.float64).reshape(-1, 2)
        out.append(part if len(part) >= 3 and abs(_area2(part)) > eps * eps else None)
    return out


def _area2(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(x[:-1] @ y[1:] - x[1:] @ y[:-1] + x[-1] * y[0] - x[0] * y[-1])


def _front_edges(scene, face, side, margin):
    """The edges of the other faces' parts in front of side ``side`` of a face (clipped to
    its closed front half-space), for the faces whose boxes meet the face's box grown by
    ``margin``: ``(n, c, tiny, edges)``, n · y = c the side's plane (n its normal), edges a
    list of ``(a, b, face)``: (k, 3) arrays, a loop's edges a → b, and the face's id."""
    n = side * scene.face_normal[face]
    c = float(n @ scene.face_loops(face)[0][0])
    box_lo, box_hi = face_boxes(scene)
    lo, hi = box_lo[face] - margin, box_hi[face] + margin
    near = np.flatnonzero(np.all(box_lo <= hi, axis=1) & np.all(box_hi >= lo, axis=1))
    edges = [(loop, np.roll(loop, -1, axis=0), k) for k in near if k != face
             for loop in clip_loops(scene.face_loops(k), n, c)]
    return n, c, 1e-9 * scene.diagonal, edges


def contact_segments(scene, face, side):
    """Segments of face ``face``'s plane where another face touches or crosses its side
    ``side``: the boundary of that face's part in front of the side, where it lies in the
    plane. Across them the form factor of the emitter's points jumps (a panel standing on
    the floor hides the light on one of its sides only).

    Returns
    -------
    (s, 2, 3) float64
    """
    n, c, tiny, edges = _front_edges(scene, face, side, 10 * 1e-9 * scene.diagonal)
    out = []
    for loop, b, _ in edges:
        flat = (np.abs(loop @ n - c) <= 10 * tiny) & (np.abs(b @ n - c) <= 10 * tiny)
        flat &= np.linalg.norm(b - loop, axis=1) > 10 * tiny
        out.append(np.stack([loop[flat], b[flat]], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 2, 3))


#: Ratio of the offsets of :func:`hover_segments` (grading of the cells along a hovering outline).
HOVER_GRADING = 8.0


def _hovering_loops(scene, face, side):
    """The loops of the other faces' parts in front of side ``side`` of a face that may
    hover over it (within a quarter of its extent), projected on its plane, with which of
    their edges hover (ends at heights 0 < h ≤ a quarter of the edge's length):
    ``(n, [(proj (k, 3), hover (k,) bool, low (k,), length (k,))])``, edge k from vertex k
    to k + 1, ``low`` its lower end's height. An edge of a closed solid that is, from every
    point of the band its cuts would grade (a quarter of its length around it), between
    two front or two back faces (:func:`inner_solid_edges`: the bunny's underside over the
    floor) is on no outline there and does not hover."""
    box_lo, box_hi = face_boxes(scene)
    n, c, tiny, edges = _front_edges(scene, face, side, 0.25 * float(np.linalg.norm(box_hi[face] - box_lo[face])))
    out = []
    for loop, b, k in edges:
        ha, hb = loop @ n - c, b @ n - c
        length = np.linalg.norm(b - loop, axis=1)
        low = np.minimum(ha, hb)
        hover = (low > 10 * tiny) & (np.maximum(ha, hb) <= 0.25 * length)
        if np.any(hover):
            pa, pb = loop - ha[:, None] * n, b - hb[:, None] * n
            d = pb - pa
            d = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
            m = (0.25 * length)[:, None]
            across = np.cross(n, d)
            band = np.stack([pa - m * d + m * across, pa - m * d - m * across, pb + m * d + m * across,
                             pb + m * d - m * across], axis=1)
            hover &= ~inner_solid_edges(scene, n, c, tiny, np.full(len(loop), k), solid_edge_positions(scene, k, loop),
                                        band)
        if np.any(hover):
            out.append((loop - ha[:, None] * n, hover, low, length))
    return n, out


def _offsets(h, length):
    """The grading offsets h·g^k ≤ length / 4 (g = :data:`HOVER_GRADING`)."""
    out, off = [], h
    while off <= 0.25 * length:
        out.append(off)
        off *= HOVER_GRADING
    return out


def hover_segments(scene, face, side):
    """Segments of face ``face``'s plane along which the form factor of its side ``side``
    changes over a width much smaller than the face: the outlines of faces that *hover* in
    front of the side (the Cornell light 0.1 mm under the ceiling), projected on the plane.

    An edge of another face's part in front of the side whose ends are at heights
    0 < h ≤ (its length) / 4 hides, from the points of the plane within ~h of its
    projection, everything on one side of it and almost nothing on the other: the integrand
    of the hidden part goes from ~0 to ~F(x → J) across a band of width ~h, and its
    variation at distance d from the projection is on the scale of d (the occluder is seen
    under an angle ~h/d). So the emitter is cut along the projection and along parallels at
    distances ±h·g^k (g = :data:`HOVER_GRADING`) up to a quarter of the edge: cells graded
    towards the near-discontinuity, each as wide as the scale of the integrand's variation
    in it, as contact lines (:func:`contact_segments`) are for true discontinuities. The
    offsets run past the edge's ends by their distance, so that the cells near a corner are
    graded in both directions; :func:`emitter_cells` cuts across each band at its ends
    first (the caps of :func:`_loop_segments`), so that its strips end there. (It grades a convex outline
    that hovers all round by rings instead: :func:`hover_rings`.)

    Returns
    -------
    (s, 2, 3) float64
    """
    n, loops = _hovering_loops(scene, face, side)
    return _loop_segments(n, loops)[1]


def _loop_segments(n, loops):
    """The graded bands of the hovering edges of ``loops`` (:func:`_hovering_loops`) on
    the plane of normal ``n``: ``(caps, lines)``, (s, 2, 3) float64 each. ``lines``: each
    edge and its parallels at ±h·g^k (:func:`hover_segments`). ``caps``: the segments
    across each band (as wide as its largest offset either side) at its two ends. Cut
    before the lines (:func:`_emitter_pieces`), they keep the graded strips along the
    edge: a line cuts the cells its segment crosses along their whole chord, and without
    them a PV post's 10 cm top edge 2 cm under a 20 m row made strips 1.8 cm wide across
    the whole row, fanned into triangles 1,000 times longer than wide (slivers: split in
    four, they stay so)."""
    caps, lines = [], []
    for proj, hover, low, length in loops:
        nxt = np.roll(proj, -1, axis=0)
        for p, q, h, ell in zip(proj[hover], nxt[hover], low[hover], length[hover]):
            d = (q - p) / np.linalg.norm(q - p)
            across = np.cross(n, d)
            offsets = _offsets(h, ell)
            if offsets:
                m = offsets[-1]
                caps += [(end - m * across, end + m * across) for end in (p - m * d, q + m * d)]
            lines.append((p, q))
            for off in offsets:
                for sgn in (1.0, -1.0):
                    lines.append((p - off * d + sgn * off * across, q + off * d + sgn * off * across))
    return tuple(np.asarray(x, np.float64).reshape(-1, 2, 3) for x in (caps, lines))


def _offset_polygon(poly, s):
    """A convex counter-clockwise 2-D polygon (k, 2) with every edge moved outwards by s
    (inwards for s < 0), vertices at the moved edges' crossings; None when an edge turns
    over (s too far inwards)."""
    d = np.roll(poly, -1, axis=0) - poly
    d = d / np.linalg.norm(d, axis=1)[:, None]
    out_n = np.stack([d[:, 1], -d[:, 0]], axis=1)  # outward normals of a counter-clockwise polygon
    a = poly + s * out_n
    pd, pa = np.roll(d, 1, axis=0), np.roll(a, 1, axis=0)  # the previous edge
    # vertex k: pa + t pd = a + r d
    den = pd[:, 0] * d[:, 1] - pd[:, 1] * d[:, 0]
    t = ((a[:, 0] - pa[:, 0]) * d[:, 1] - (a[:, 1] - pa[:, 1]) * d[:, 0]) / den
    v = pa + t[:, None] * pd
    e = np.roll(v, -1, axis=0) - v
    return v if np.all(np.einsum("kj,kj->k", e, d) > 0) else None


def hover_rings(outline, offsets):
    """Cells graded towards a convex outline (k, 2) that hovers all round, counter-clockwise
    in 2-D: the outline moved out and in by each offset (:func:`_offset_polygon`), the
    rings between consecutive ones cut at the corners into trapezoids (one per edge), and
    the innermost polygon. The graded parallels of :func:`hover_segments` without their
    extensions across the whole emitter: a ring is as wide as the scale of the integrand's
    variation in it (its distance to the outline) all along, also at the corners.

    Returns
    -------
    cells : list of (m, 2) float64
        Convex, counter-clockwise; they tile the outermost polygon.
    outer : (k, 2) float64
        The outermost polygon.
    """
    levels = [_offset_polygon(outline, -o) for o in offsets[::-1]] + [outline] + [_offset_polygon(outline, o) for o in offsets]
    levels = [v for v in levels if v is not None]
    cells = [levels[0]]
    k = len(outline)
    for inner, outer in zip(levels[:-1], levels[1:]):
        for e in range(k):
            f = (e + 1) % k
            cells.append(np.stack([outer[e], outer[f], inner[f], inner[e]]))
    return cells, levels[-1]


def _clip_convex(piece, poly, eps):
    """A convex 2-D piece's parts outside the convex counter-clockwise ``poly`` (convex,
    one per edge of poly at most) and its part inside (None if empty)."""
    outside, rest = [], piece
    for e in range(len(poly)):
        a, b = poly[e], poly[(e + 1) % len(poly)]
        d = (b - a) / np.linalg.norm(b - a)
        right, left = _cut_convex(rest, a, d, eps)  # the inside of a counter-clockwise polygon is on the left
        if right is not None:
            outside.append(right)
        rest = left
        if rest is None:
            break
    return outside, rest


def _meets_box(seg, lo, hi, eps):
    """(s,) bool: the 2-D segments (s, 2, 2) with more than ``eps`` of their length inside
    the box [lo, hi] (:func:`box_clip`): the others cut no piece inside it (a kink line of
    a cluttered room mostly runs far from a small face)."""
    t0, t1 = box_clip(seg, lo, hi)
    return (t1 - t0) * np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1) > eps


def box_clip(seg, lo, hi):
    """Where the 2-D segments ``seg`` (s, 2, 2) float64 run inside the box ``[lo, hi]`` (2,)
    (Liang–Barsky clipping, all at once): ``t0, t1`` (s,) float64, the part ``seg[:, 0] +
    t (seg[:, 1] − seg[:, 0])`` for t in [t0, t1]; t1 < t0 where a segment misses it."""
    a, d = seg[:, 0], seg[:, 1] - seg[:, 0]
    t0, t1 = np.zeros(len(seg)), np.ones(len(seg))
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(2):
            flat = d[:, k] == 0
            ta, tb = (lo[k] - a[:, k]) / d[:, k], (hi[k] - a[:, k]) / d[:, k]
            t0 = np.where(flat, t0, np.maximum(t0, np.minimum(ta, tb)))
            t1 = np.where(flat, t1, np.minimum(t1, np.maximum(ta, tb)))
            t1 = np.where(flat & ((a[:, k] < lo[k]) | (a[:, k] > hi[k])), -1.0, t1)
    return t0, t1


def cut_along(pieces, seg, eps, limit=None):
    """Convex 2-D pieces (list of (k, 2), counter-clockwise) cut along segments (s, 2, 2):
    a piece is cut by the line of a segment when the line crosses its interior (more than
    ``eps`` either side) along a chord that overlaps the segment by more than ``eps``;
    segment after segment (:func:`viscx.geometry.arrangement.cut_pieces`: the parts of a cut
    piece take its place in the list). None when there would be more than ``limit`` pieces.

    Returns
    -------
    list of (m, 2) float64, or None
    """
    pieces = list(pieces)
    if not len(seg) or not pieces:
        return pieces
    verts, ptr, _ = cut_flat(*pieces_to_flat(pieces), seg, eps, limit)
    return None if verts is None else flat_to_pieces(verts, ptr)


def cut_flat(verts, ptr, seg, eps, limit=None, owner=None):
    """:func:`cut_along` on flat pieces (``verts`` (V, 2) float64, ``ptr`` (N + 1,) int64:
    :mod:`viscx.geometry.arrangement`): ``(verts, ptr, owner)``, ``owner`` (N',) int64 the
    piece each part was cut from (or the label ``owner`` (N,) gave it); ``(None, None,
    None)`` past ``limit`` pieces."""
    owner = np.arange(len(ptr) - 1, dtype=np.int64) if owner is None else np.asarray(owner, np.int64)
    if not len(seg) or len(ptr) < 2:
        return verts, ptr, owner
    seg = np.asarray(seg, np.float64)
    seg = np.ascontiguousarray(seg[_meets_box(seg, verts.min(axis=0) - eps, verts.max(axis=0) + eps, eps)])
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)  # the digits of each vector's own norm (checked on 6e5)
    verts, ptr, owner, complete = cut_pieces(np.ascontiguousarray(verts, np.float64), np.asarray(ptr, np.int64), owner,
                                             seg, length, float(eps), -1 if limit is None else int(limit))
    return (verts, ptr, owner) if complete else (None, None, None)


#: Cells beyond which an emitter is not cut along its kink lines (:func:`emitter_cells`):
#: the Cornell box's sides have at most 286; the floor of a 58-polygon office would have
#: 15,596 (1,036 kink segments), more points for the start alone than the three-level
#: cubature of the uncut cells takes (:class:`ThreeLevelRowCubature`).
MAX_KINK_CELLS = 1_000


def emitter_cells(scene, face, side, kinks=False, limit=MAX_KINK_CELLS, generators=None, apexes=None, fits=None):
    """Side ``side`` of a face cut into convex cells along its contact segments
    (:func:`contact_segments`) and graded towards the outlines that hover over it: the
    face's triangles, each cut by the line of every segment that crosses its interior, so
    that the form factor of the points is continuous on every cell (the cubature's error
    estimate assumes it), and graded along the hovering outlines (:func:`hover_segments`;
    a convex outline whose every edge hovers by rings around it, :func:`hover_rings`).
    Depends on the emitter only: computed once per side and shared by all its pairs.
    With ``kinks`` the cells are cut along the D1 lines of every receiver too
    (:func:`viscx.queries.kinks.kink_segments`: the matrix row, whose columns are all the
    receivers), so that every integrand is C1 on every cell; None when that would make more
    than ``limit`` cells or the lines are too many to list (in a cluttered scene the lines
    are quadratic in the edges and their arrangement quadratic in the lines); the lines of
    the pairs listed first are tried as they come (``past`` of :func:`kink_segments`), and
    when they alone make more cells than ``limit`` the rest are not listed: cuts only add
    cells. ``generators``: the kink lines of these rows of
    :func:`viscx.queries.kinks.generator_segments` only (default all; :func:`kink_faces`).
    ``apexes`` (r,) int64: with ``kinks`` and ``generators``, cut along the lines through
    the points where those edges touch the face too, to the corners of these receivers
    (:func:`viscx.queries.kinks.apex_segments`), unless that makes more than ``limit``
    cells or cells ``fits(cells) -> bool`` refuses: then along the kink lines alone (listed
    once for both).

    Returns
    -------
    list of (k, 3) float64
        Convex cells, counter-clockwise about the side's normal.
    """
    origin, eu, ev, eps, pieces = scene.cached(f"emitter_pieces {int(face)} {int(side)}",
                                               lambda s: _emitter_pieces(s, face, side))

    def to2(p):
        return np.stack([(p - origin) @ eu, (p - origin) @ ev], axis=-1)

    def to3(pieces):
        return [origin + p[:, :1] * eu + p[:, 1:] * ev for p in pieces]

    if kinks:
        kinks = kink_segments(scene, face, side, generators,
                              lambda seg: cut_along(pieces, to2(seg), eps, limit) is None)
        if kinks is None:
            return None
        extra = np.zeros((0, 2, 3)) if apexes is None else apex_segments(scene, face, side, generators, apexes)
        if len(extra):
            cut = cut_along(pieces, to2(np.concatenate([kinks, extra])), eps, limit)
            if cut is not None and (fits is None or fits(to3(cut))):
                return to3(cut)
        pieces = cut_along(pieces, to2(kinks), eps, limit)
        if pieces is None:
            return None
    return to3(pieces)


def _emitter_pieces(scene, face, side):
    """The cells of :func:`emitter_cells` without the kink cuts, in 2-D: ``(origin, eu, ev,
    eps, pieces)``, a point y of the plane being ``origin + u eu + v ev`` for a vertex (u, v)
    of a piece (k, 2) (computed once per side: the row cuts them along its kink lines after
    its pair cubatures' or closed forms' need them uncut)."""
    n = side * scene.face_normal[face]
    eu, ev = plane_basis(n)
    tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
    origin = tri[0, 0]
    eps = 1e-8 * scene.diagonal

    def to2(p):
        return np.stack([(p - origin) @ eu, (p - origin) @ ev], axis=-1)

    pieces = [t if _area2(t) > 0 else t[::-1] for t in to2(tri)]
    n_h, loops = _hovering_loops(scene, face, side)
    lines = []
    for loop in loops:
        proj, hover, low, length = loop
        outline = to2(proj)
        if _area2(outline) < 0:
            outline = outline[::-1]
        e = np.roll(outline, -1, axis=0) - outline
        turn = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
        if not (np.all(hover) and np.all(turn > eps * np.linalg.norm(e, axis=1).max())):
            lines.append(loop)
            continue
        rings, outer = hover_rings(outline, _offsets(float(low.min()), float(length.min())))
        out = []
        for p in pieces:
            outside, rest = _clip_convex(p, outer, eps)
            out.extend(outside)
            if rest is not None:
                for r in rings:
                    part = _clip_convex(rest, r, eps)[1]
                    if part is not None:
                        out.append(part)
        pieces = out
    caps, bands = _loop_segments(n_h, lines)
    pieces = cut_along(pieces, to2(np.concatenate([contact_segments(scene, face, side), caps, bands])), eps)
    return origin, eu, ev, eps, pieces


def plane_segments(scene, face, side):
    """(s, 2, 3) float64: the lines where the planes of the faces in front of side ``side``
    of a face cross it (each plane once, as a segment across the face), those of the
    faces that have vertices more than 1e-9 of the scene's size on both sides of it and a
    vertex that far ahead of the side's plane (a face behind the plane, touching it, as a
    desk's panels under its front edge, is never seen from the side and hides nothing in
    front of it: no column kinks along its plane). On
    such a line a face turns edge-on: F to it goes to 0 there like the distance and its
    shadow's edges pass over each other, so every column it sees or hides has a kink
    (D1) along the whole line (the planes' kink lines of :func:`viscx.queries.kinks.kink_segments`,
    pair of edges of one face, extended across the face)."""
    outline, lo, hi = face_outlines(scene)
    tiny = 1e-9 * scene.diagonal
    mine = outline[lo[face]:hi[face]]
    n_i = side * scene.face_normal[face]
    ahead = np.maximum.reduceat(outline @ n_i, lo) - float(n_i @ mine[0]) > tiny
    others = seen_faces(scene, face, side)
    others = others[(others != face) & ahead[others]]
    normal = scene.face_normal[others]
    c = np.einsum("fj,fj->f", normal, outline[lo[others]])
    h = mine @ normal.T - c
    cross = (h.max(axis=0) > tiny) & (h.min(axis=0) < -tiny)
    normal, c = normal[cross], c[cross]
    # one segment per plane: the sign fixed by the normal's largest component, then rounded
    flip = np.sign(normal[np.arange(len(normal)), np.argmax(np.abs(normal), axis=1)])
    normal, c = normal * flip[:, None], c * flip
    key = np.round(np.column_stack([normal, c / tiny]), 6)
    _, first = np.unique(key, axis=0, return_index=True)
    normal, c = normal[np.sort(first)], c[np.sort(first)]
    n_i = scene.face_normal[face]
    c_i = float(n_i @ mine[0])
    centre = mine.mean(axis=0)
    radius = float(np.linalg.norm(mine - centre, axis=1).max()) * 1.01
    d = np.cross(n_i, normal)
    d /= np.linalg.norm(d, axis=1)[:, None]
    # the point of each line nearest the centre: centre + a n_i + b n_g, both planes met
    g = normal @ n_i
    det = 1 - g * g
    r_i, r_g = c_i - n_i @ centre, c - normal @ centre
    a, b = (r_i - g * r_g) / det, (r_g - g * r_i) / det
    p = centre + a[:, None] * n_i + b[:, None] * normal
    return np.stack([p - radius * d, p + radius * d], axis=1)


def plane_cells(scene, face, side, cells, start):
    """The cells (list of convex (k, 3), counter-clockwise about the side's normal) cut
    along :func:`plane_segments`, or None when that makes more than twice ``start`` (the
    first triangles without the cuts) plus the lines cells: a line adds about a cell for
    each cell it crosses, and a grid of lines (the floor of a furnished room, crossed by
    the vertical planes of every box) multiplies them instead. For
    the rows on three levels (:class:`ThreeLevelRowCubature`): a kink along a line that runs
    within a node's distance of a first triangle's edge is seen by none of the three levels
    (office(100), a divider's end 0.05 × 1.46 m: the desks' plane at 0.72 m ran 0.009
    below its triangles' edges at half its height, and two entries came out 2.3e-8 and
    6.4e-6 off for estimates of 1.7e-13 and 1.1e-7); cut along them, no line crosses a
    cell. The other kink lines (two edges of different faces lining up) are partial and
    quadratic in the edges; the planes are few in a building."""
    seg = plane_segments(scene, face, side)
    if not len(seg):
        return cells
    n = side * scene.face_normal[face]
    eu, ev = plane_basis(n)
    origin = cells[0][0]

    def to2(p):
        return np.stack([(p - origin) @ eu, (p - origin) @ ev], axis=-1)

    pieces = cut_along([to2(c) for c in cells], to2(seg), 1e-8 * scene.diagonal, 2 * (start + len(seg)))
    return None if pieces is None else [origin + p[:, :1] * eu + p[:, 1:] * ev for p in pieces]


def cubature_cells(scene, face, side, min_size=None, receivers=None, sky=False, setups=None, pairs=False):
    """The cells every cubature of side ``side`` of a face integrates over (the row's and
    each pair's): :func:`emitter_cells` cut along the kink lines, so that every integrand is
    C1 on every cell and two levels give an honest estimate (:class:`RowCubature`), unless
    that makes more than :data:`MAX_KINK_CELLS` cells or more start triangles than three
    levels (21 triangles each) on the uncut ones; then the uncut cells (three levels:
    :class:`Cubature`, :class:`ThreeLevelRowCubature`). Uncut cells already past that
    many are kept without listing the kink lines at all, and so are those the receivers'
    own lines alone cut past it (before the pairs' shafts are searched for the occluders
    that add the rest), or the lines of the first pairs listed (:func:`emitter_cells`):
    office(1000)'s box sides list a million pairs for 10⁵ lines, 1–3 CPU s a row, and
    these short cuts decide most of them from a few thousand.

    ``receivers`` (k,) int64: the cells of a row whose columns are the pairs to (both sides
    of) these faces only, no sky (a group query's row, :func:`emitter_row`), cut along the
    kink lines of those pairs' integrands only (:func:`kink_faces`): in a furnished room a
    wall's kink lines of every receiver are thousands (past :data:`MAX_KINK_CELLS`), those
    of the pairs to a few receivers can be few. With ``sky`` too, the lines of the sky's
    integrand as well (:func:`viscx.queries.kinks.sky_generators`): a matrix row that
    computes only some of its pairs (reciprocity: the Cornell box's ceiling, only its sky).
    Default: every receiver and the sky (the matrix's row). ``setups``: the row's pair
    set-ups, for :func:`kink_faces` (with ``min_size`` only: not cached). ``pairs``: the
    cells are for pair cubatures (:func:`emitter_row`, :func:`face_to_face`), whose kernels
    see one pair's faces and cost a fraction of a row's point: cut along the kink lines up
    to :data:`PAIR_KINK_START` start triangles, however few the uncut cells have (a desk
    top's 3 cm end, two uncut triangles: the three levels on them were 1.8e-6 off for an
    estimate of 7.7e-7 to desk3's panel end at tol 1e-6, and missed the band 7.7 mm wide
    from which desk8's top's end sees desk3's panel side; cut, 40 and 134 cells, 546 and
    1,862 points, each within its estimate of a quadrature of the pair's kernel).

    Returns
    -------
    cells : list of (k, 3) float64
    tri : (g, 3, 3) float64
        Their :func:`start_triangles` at ``min_size`` (default: 1 / :data:`MIN_SPLIT` of
        the face's box, where its pairs' cubatures start at the least; cached per side:
        the kink lines are quadratic in the edges near the face).
    kinked : bool
    """
    if min_size is None:
        box_lo, box_hi = face_boxes(scene)
        size = float(np.linalg.norm(box_hi[face] - box_lo[face])) / MIN_SPLIT
        receivers = None if receivers is None else np.unique(np.asarray(receivers, np.int64))
        return scene.cached(_side_key("cubature_cells", face, side, receivers) + (" and the sky" if sky else "")
                            + (" for pairs" if pairs else ""),
                            lambda s: cubature_cells(s, face, side, size, receivers, sky, pairs=pairs))
    cells = emitter_cells(scene, face, side)
    tri = start_triangles(cells, min_size)
    start = max(21 * len(tri), PAIR_KINK_START if pairs else 0)
    limit = min(MAX_KINK_CELLS, start)
    if len(cells) > limit:
        # cuts only add cells: past the limit before the kink lines are even listed (they
        # are quadratic in the edges in front: the bunny's floor, 3,466 cells, 5,500 edges)
        return cells, tri, False
    generators = None
    if receivers is not None:
        # the receivers' own lines first: they are among the row's (kink_faces lists every
        # receiver), so when they alone cut past the limit all do, and the pairs' shafts
        # need not be searched for the occluders whose edges add the rest
        if emitter_cells(scene, face, side, kinks=True, limit=limit,
                         generators=face_generators(scene, receivers)) is None:
            return cells, tri, False
        generators = face_generators(scene, kink_faces(scene, face, side, receivers, setups))
        if sky:
            generators = np.union1d(generators, sky_generators(scene, face))
    # a pair's cells are cut along the lines through its apexes too, unless they make the
    # cells too many: then along the kink lines alone
    kinked = emitter_cells(scene, face, side, kinks=True, limit=limit, generators=generators,
                           apexes=receivers if pairs and receivers is not None else None,
                           fits=lambda c: len(start_triangles(c, min_size)) <= start)
    if kinked is not None:
        kinked_tri = start_triangles(kinked, min_size)
        if len(kinked_tri) <= start:
            return kinked, kinked_tri, True
    return cells, tri, False


#: Start triangles up to which the cells of pair cubatures are cut along their kink lines
#: whatever the uncut cells' count (:func:`cubature_cells` with ``pairs``).
PAIR_KINK_START = 400


def _side_key(name, face, side, receivers=None):
    """The cache key of something of a face side, or of its row to ``receivers`` (k,) int64."""
    key = f"{name} {int(face)} {int(side)}"
    return key if receivers is None else key + " to " + " ".join(str(j) for j in np.unique(receivers).tolist())


def kink_faces(scene, face, side, receivers, setups=None):
    """(k,) int64, sorted: the faces whose edges may make the kinks (D1) of the integrands of
    the pairs from side ``side`` of a face to the sides of ``receivers`` (k,) int64 it may
    see: each receiver, the faces lying in its plane (the outlines of its covered cells,
    holes of the target: :func:`target_holes`) and the faces meeting each pair's shaft
    (:func:`pair_occluders`, both sides of the receiver). A pair's kernel sees no other
    face (:meth:`PairSetup.f`), so its integrand kinks only where two edges of these line
    up; the kink lines of the other edges are those of the other receivers and the sky.
    ``setups``: {(j, t): :class:`PairSetup`} of such pairs the caller has made (a matrix
    row's), whose occluders are then searched on them (once: the row's shadow search reads
    them) rather than on new set-ups."""
    receivers = np.asarray(receivers, np.int64)
    setups = setups or {}
    out = [receivers]
    for j, t in zip(*facing_sides(scene, face, side, receivers)):
        out.append(coplanar_faces(scene, int(j)))
        setup = setups.get((int(j), int(t)))
        if setup is None:
            setup = PairSetup(scene, face, side, face_target(scene, int(j)), int(t), keep=True)
        elif not setup.empty and not setup.occluders_found:
            setup.find_occluders()
        out.append(np.asarray([o[2] for o in setup.occluders], np.int64))
    return np.unique(np.concatenate(out))


# --------------------------------------------------------------------------------------
# adaptive cubature over triangles

# Radon's degree-5 rule on a triangle (7 points): barycentric nodes and weights summing to 1
_R = np.sqrt(15.0)
_A, _B, _C, _D = (6 - _R) / 21, (9 + 2 * _R) / 21, (6 + _R) / 21, (9 - 2 * _R) / 21
RULE_NODES = np.array([[1 / 3, 1 / 3, 1 / 3], [_A, _A, _B], [_A, _B, _A], [_B, _A, _A], [_C, _C, _D], [_C, _D, _C],
                       [_D, _C, _C]])
RULE_WEIGHTS = np.array([9 / 40] + [(155 - _R) / 1200] * 3 + [(155 + _R) / 1200] * 3)

#: Bound on the triangles one integral evaluates (memory and time); the error estimate
#: reported when it is reached says how far the result is from the tolerance.
MAX_CELLS = 200_000
#: Triangles per kernel call (7 points each): bounds the memory of one call.
CHUNK = 20_000


def _middle_of(g):
    """(4 g,) int64: for the children of g triangles (:func:`split4`), the parent whose
    centroid each shares (the middle child, the last of four), -1 for the others."""
    out = np.full((g, 4), -1, np.int64)
    out[:, 3] = np.arange(g)
    return out.reshape(-1)


def split4(tri):
    """(g, 3, 3) triangles → (g, 4, 3, 3): the four halves-by-midpoints of each (same orientation)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
    return np.stack([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1),
                     np.stack([bc, ca, ab], 1)], axis=1)


def child_rows(rows, k=4):
    """(len(rows) k,) int64: where the children of the triangles ``rows`` (m,) int64 lie in
    an array holding k children per triangle, each triangle's consecutively (:func:`split4`'s
    order for k = 4, their children's for k = 16)."""
    return (k * np.asarray(rows, np.int64)[:, None] + np.arange(k)).reshape(-1)


def start_triangles(cells, min_size):
    """The cells (list of convex (k, 3)) fanned into triangles (g, 3, 3), split by
    :func:`split_large`."""
    count = np.array([len(c) for c in cells], np.int64)
    first = np.cumsum(count) - count  # each cell's first vertex in the flat list
    cell = np.repeat(np.arange(len(cells)), count - 2)  # triangle k of a cell: vertices 0, k + 1, k + 2
    k = np.arange(len(cell)) - np.repeat(np.cumsum(count - 2) - (count - 2), count - 2)
    flat = np.concatenate(cells)
    return split_large(np.stack([flat[first[cell]], flat[first[cell] + k + 1], flat[first[cell] + k + 2]], axis=1),
                       min_size)


def split_large(tri, min_size):
    """Triangles (g, 3, 3) larger than ``min_size`` (the side of a square of twice their
    area) split by midpoints until none is: a rule on a large triangle may miss a small
    shadow entirely. (Area, not length: the thin cells graded along a hovering outline are
    as thin as the integrand's scale across them and smooth along them; halving them in
    both directions would only multiply them.)"""
    while len(tri) and min_size > 0:
        long = np.sqrt(2 * triangle_areas(tri)) > min_size
        if not np.any(long):
            break
        tri = np.concatenate([tri[~long], split4(tri[long]).reshape(-1, 3, 3)])
    return tri


def triangle_areas(tri):
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def three_level_error(q, kq, gq):
    """The error estimate of the sum of a triangle's 16 grandchildren on the smooth model,
    and that sum: the change from its 4 children to them, at least 1/64 of the change from
    its own rule to its children. Too optimistic where a kink line crosses the triangle
    (:func:`kinked_three_level_error`, which the three-level cubatures use); kept as the
    model the tests show failing there. Works column by column alike.

    Parameters
    ----------
    q : (g,) or (g, R) float
    kq : (g, 4) or (g, 4, R) float
    gq : (g, 16) or (g, 16, R) float

    Returns
    -------
    err, g_sum : (g,) or (g, R) float
    """
    k_sum, g_sum = kq.sum(axis=1), gq.sum(axis=1)
    return np.maximum(np.abs(k_sum - g_sum), np.abs(q - k_sum) / 64), g_sum


#: The error model of a triangle a kink line (D1) may cross (the rows and pairs on three
#: levels, whose cells are not cut along their kinks): the degree-5 rule's error on a triangle the line
#: crosses is ~ slope jump × h³, and the crossed triangles double from one level to the
#: next, so each level's error is ~1/4 of the one before (against 1/64 where the integrand
#: is smooth). Then ``|Q − K| ≈ 3 err(K) = 12 err(G)``: G's error is at least
#: ``|Q − K| / KINK_LEVELS`` when ``|K − G|`` came out small by chance.
KINK_LEVELS = 12
#: A triangle whose finest change ``|K − G|`` is larger than the one before ``|Q − K|`` is
#: not converging yet (a shadow first seen by the grandchildren: office(100), a cabinet
#: side's row, whose values over the levels ran 0, 0, 1.6e-7, 4.7e-7, then settled at
#: 4.37e-7, G's error 1.7 × ``|K − G|``). No model bounds what such a triangle has not
#: seen yet: this is a safety factor (its next change may be as large as the last again,
#: and then its successors', ≤ 1/3 of it on the kink model: ≤ 4/3, times 3 as the kink
#: model's margin), and it puts such triangles first in line to be split.
KINK_GROWTH = 4


def kinked_three_level_error(q, kq, gq):
    """(g,) or (g, R) float64: the error estimate of the sum of each triangle's 16 grandchildren, on
    the kink model (:data:`KINK_LEVELS`, :data:`KINK_GROWTH`): ``max(|K − G|, |Q − K| / 12)``,
    or ``4 |K − G|`` where the change grows from level to level. :func:`three_level_error`'s
    ``|Q − K| / 64`` is the smooth model's: where a kink crosses a triangle, K and G can
    agree by chance while both are off (office(100), a desk side's row at 1e-4: the level
    errors ran 4.1e-7, 2.7e-8, 4.0e-8, 1.0e-8, 1.9e-9: G's 4.0e-8 for ``|K − G|`` = 1.3e-8,
    ``|Q − K| / 64`` = 6.9e-9).

    Parameters
    ----------
    q : (g,) or (g, R) float
    kq : (g, 4) or (g, 4, R) float
    gq : (g, 16) or (g, 16, R) float
    """
    k_sum, g_sum = kq.sum(axis=1), gq.sum(axis=1)
    coarse, fine = np.abs(q - k_sum), np.abs(k_sum - g_sum)
    return np.where(fine > coarse, KINK_GROWTH * fine, np.maximum(fine, coarse / KINK_LEVELS))


class Levels(NamedTuple):
    """Leaf triangles of :class:`Cubature` on their three levels: ``tri`` (g, 3, 3) with
    their occluder lists (CSR ``ptr`` (g + 1,), ``ids``) and Radon's rule ``q`` (g,); their
    midpoint children ``K`` (4 g, 3, 3) (rows 4 k … 4 k + 3 those of leaf k) with lists
    ``kptr, kids`` and rules ``kq`` (4 g,); their grandchildren ``G, gptr, gids, gq`` alike
    (16 g, rows 16 k … 16 k + 15 those of leaf k)."""

    tri: np.ndarray
    ptr: np.ndarray
    ids: np.ndarray
    q: np.ndarray
    K: np.ndarray
    kptr: np.ndarray
    kids: np.ndarray
    kq: np.ndarray
    G: np.ndarray
    gptr: np.ndarray
    gids: np.ndarray
    gq: np.ndarray

    def take(self, rows):
        """The leaves ``rows`` (k,) int64, with their children and grandchildren."""
        k_rows, g_rows = child_rows(rows), child_rows(rows, 16)
        return Levels(self.tri[rows], *_sub_lists(self.ptr, self.ids, rows), self.q[rows], self.K[k_rows],
                      *_sub_lists(self.kptr, self.kids, k_rows), self.kq[k_rows], self.G[g_rows],
                      *_sub_lists(self.gptr, self.gids, g_rows), self.gq[g_rows])

    def join(self, other):
        """These leaves, then ``other``'s."""
        return Levels(np.concatenate([self.tri, other.tri]), *_join_lists(self.ptr, self.ids, other.ptr, other.ids),
                      np.concatenate([self.q, other.q]), np.concatenate([self.K, other.K]),
                      *_join_lists(self.kptr, self.kids, other.kptr, other.kids), np.concatenate([self.kq, other.kq]),
                      np.concatenate([self.G, other.G]), *_join_lists(self.gptr, self.gids, other.gptr, other.gids),
                      np.concatenate([self.gq, other.gq]))


class Cubature:
    """Adaptive cubature of an integrand over triangles, each triangle carrying the list of
    occluders that may matter on it (CSR ``ptr``, ``ids``; an empty list means the integrand
    is zero there, exactly).

    Each triangle T (a leaf) is evaluated on three levels: Radon's degree-5 rule on T, on
    its four midpoint children and on their sixteen children, whose sum is the value used.
    The cells it is given are not cut along the kink lines (else the pair takes the
    two-level :class:`RowCubature`), so its error estimate is the kink model's, as the
    rows' on three levels (:func:`kinked_three_level_error`): the change from the children
    to the grandchildren, at least 1/12 of the change from T to its children (across a
    kink each level's error is ~1/4 of the one before, not the smooth 1/64: office(100), a
    divider's narrow side → the floor it stands on at tol 1e-4 was 1.2e-7 off for an
    estimate of 6.3e-8 with 1/64), four times the last change where it grows. Two levels
    are not enough: a kink that only clips a corner of T lies between the nodes of T and
    of its children alike, and the two can agree to 1e-12 while both are off (the Cornell
    light → floor: 5e-8 off for an estimate of 9e-9; the grandchildren see it). A first
    triangle whose 21 rules see nothing while its list is not empty is looked at closer
    (:func:`look_for_shadows`, as the rows do). Refinement is global: while the sum of the
    estimates exceeds the budget, the triangles with the largest estimates are split
    (their children become leaves, each with its own three levels) until what is left is
    :data:`REFINE_LEFT` of the budget, so the effort goes where the integrand is rough.

    Parameters
    ----------
    integrand : callable
        ``integrand(points (m, 3), group (m,), ptr, ids) -> (m,)``, group the triangle of
        each point.
    cull : callable
        ``cull(tri (g, 3, 3), ptr, ids) -> (ptr, ids)``: each triangle's list reduced from the
        candidates given (its parent's).
    unresolved : callable, optional
        ``unresolved(tri, ptr, ids) -> (g,) float64``: a bound on what the rule may miss on
        each triangle, too large for what its occluders may do in it (:meth:`estimates`).
    unseen : callable, optional
        ``unseen(tri) -> (g,) float64``: what the integral over each triangle may be at the
        most (the integrand's bound integrated), the estimate of a triangle whose 21 rules
        see nothing while its list says they should (:meth:`estimates`).
    threads : int
        Threads the integrand's and the cull's pieces run on (:meth:`_pieces`: the same
        result on any number).
    progress : callable, optional
        ``progress(points, ratio)``, told after each refinement round the points evaluated
        so far and the summed estimate over the budget (a progress bar's; the result does
        not depend on it).
    gaps : callable, optional
        ``gaps(tri, q, kq, gq) -> (hidden (g,) bool, new (h, 3, 3))``: the first triangles
        (with their three levels' rule values) from whose nodes the integrand says the
        target is wholly hidden, where it may yet be seen through a gap between the nodes,
        and the triangles that replace them (:meth:`PairSetup.gaps`).
    """

    def __init__(self, integrand, cull, unresolved=None, unseen=None, threads=1, progress=None, gaps=None, exact=None):
        self.integrand = integrand
        self.cull = cull
        self.exact = exact
        self.unresolved = unresolved
        self.unseen = unseen
        self.gaps = gaps
        self.threads = threads
        self.progress = progress
        self.evaluations = 0
        self.leaves = None  # after integrate: (tri, ptr, ids, q, kq, gq, err) of the final triangles

    def estimates(self, tri, ptr, ids, q, kq, gq):
        """(g,) float64: each triangle's error estimate for the sum of its 16 grandchildren
        (``gq`` (g, 16)): :func:`kinked_three_level_error` of its rule ``q``, its 4 children's
        (``kq`` (g, 4)) and theirs (when the two finer levels agree by accident, a feature
        the coarser level saw is not forgotten), and at least what the ``unresolved``
        callback says a feature smaller than the rule can see may hide in it (at most the
        triangle's area: the integrand's values lie in [0, 1]).

        A triangle whose 21 rules see nothing (as :func:`look_for_shadows` says) while its
        list is not empty gets the ``unseen`` bound: its shaft meets an occluder, so a
        shadow lies between its nodes (the shaft test is exact for a convex target: some
        segment from the triangle to J' is blocked), and nothing the nodes saw says how
        large (office(100), a desk panel → another desk's narrow top side: after the search
        for shadows, leaves 0.015 m² wide still saw nothing of a shadow worth 1.2e-8 each,
        and at tol 1e-8 the pair was 3.3e-8 off for an estimate of 6.9e-9). Such a triangle
        is split until its children see the shadow or their shafts miss the occluders.
        A list culled from its parent's may hold more than meets the shaft (``cull`` keeps
        a closed solid's faces where their boxes meet it); the ``exact`` cull, where given,
        says which blind triangles' shafts do meet an occluder (the bunny's floor → light:
        19,419 of its 23,689 leaves at 1e-4 were counted blind on such lists, out to 25 m
        from the bunny, and the pair stopped at MAX_CELLS with an estimate of 6.6e-3)."""
        err = kinked_three_level_error(q, kq, gq)
        if self.unresolved is not None and len(tri):
            err = np.maximum(err, np.minimum(self.unresolved(tri, ptr, ids), triangle_areas(tri)))
        if self.unseen is not None and len(tri):
            seen = levels_seen(q, kq, gq)
            blind = np.flatnonzero((seen <= UNSEEN * triangle_areas(tri)) & (np.diff(ptr) > 0))
            if len(blind) and self.exact is not None:
                blind = blind[np.diff(self.exact(tri[blind], *_sub_lists(ptr, ids, blind))[0]) > 0]
            if len(blind):
                err[blind] = np.maximum(err[blind], self.unseen(tri[blind]))
        return err

    def _pieces(self, n):
        """The slices of ``n`` triangles that one call of the integrand or of the cull takes:
        as :func:`row_rules`' pieces, shared by :attr:`threads` threads (the integrand and
        the cull must be thread-safe and release the GIL: ``blocked_form_factors`` and
        ``shaft_meets`` are ``nogil``); they depend on ``n`` only, and each triangle's
        values and list on the triangle only, so the result is the same, bit for bit, on
        any number of threads. In a pool of rows (a group query's, :func:`_map_rows`) each
        piece holds one of the pool's core tokens (:func:`row_core`), as the rows' do."""
        return row_chunks(n, max(1, min(CHUNK, max(ROW_PIECE, -(-n // ROW_PIECES)))))

    def rule(self, tri, ptr, ids):
        """(g,) float64: Radon's rule on each triangle (zero where the list is empty)."""
        out = np.zeros(len(tri))
        live = np.flatnonzero(np.diff(ptr) > 0)
        area = triangle_areas(tri)

        def piece(s):
            rows = live[s]
            pts = np.einsum("rk,gkd->grd", RULE_NODES, tri[rows]).reshape(-1, 3)
            group, lists = np.repeat(np.arange(len(rows)), 7), _sub_lists(ptr, ids, rows)
            with row_core():
                values = self.integrand(np.ascontiguousarray(pts), group, *lists)
            out[rows] = values.reshape(-1, 7) @ RULE_WEIGHTS * area[rows]
            return len(pts)

        self.evaluations += sum(map_chunks(piece, self._pieces(len(live)), self.threads))
        return out

    def culled(self, tri, ptr, ids):
        """:attr:`cull` of the triangles (g, 3, 3) with lists ``ptr, ids``, piece by piece
        (:meth:`_pieces`): the same lists."""
        def piece(s):
            lists = _sub_lists(ptr, ids, np.arange(s.start, s.stop))
            with row_core():
                return self.cull(tri[s], *lists)

        return _concat_lists(map_chunks(piece, self._pieces(len(tri)), self.threads))

    def expand(self, tri, ptr, ids, cull=True):
        """Children of the triangles, their lists (culled from the parents', or with
        ``cull=False`` the parents' own) and rule values: ``(kids (g, 4, 3, 3), kptr,
        kids_ids, q (g, 4))``."""
        kids = split4(tri).reshape(-1, 3, 3)
        kptr, kids_ids = _sub_lists(ptr, ids, np.repeat(np.arange(len(tri)), 4))
        if cull:
            kptr, kids_ids = self.culled(kids, kptr, kids_ids)
        q = self.rule(kids, kptr, kids_ids)
        return kids.reshape(-1, 4, 3, 3), kptr, kids_ids, q.reshape(-1, 4)

    def levels(self, tri, ptr, ids):
        """The :class:`Levels` of the triangles (g, 3, 3) with lists (``ptr, ids``), those
        with an empty list dropped.

        The grandchildren carry their parents' lists, not culled: a list may hold more
        than the integrand needs (a triangle's shaft lies in its parent's), and the kernel
        drops an occluder outside a point's pyramid at the cost of a clip test, while the
        shaft test of :attr:`cull` costs several times that for the 7 points of a triangle,
        and the grandchildren are 16 of a leaf's 21 triangles (the office's floor →
        ceiling at 1e-4: the shaft tests were a fifth of the time). A grandchild's list is
        culled when it becomes a child, in :meth:`integrate`: the leaves' and children's
        lists are exact (their empty lists say where the integrand is zero, and the
        estimates read them)."""
        live = np.flatnonzero(np.diff(ptr) > 0)
        tri, (ptr, ids) = tri[live], _sub_lists(ptr, ids, live)
        q = self.rule(tri, ptr, ids)
        K, kptr, kids, kq = self.expand(tri, ptr, ids)
        K, kq = K.reshape(-1, 3, 3), kq.reshape(-1)
        G, gptr, gids, gq = self.expand(K, kptr, kids, cull=False)
        return Levels(tri, ptr, ids, q, K, kptr, kids, kq, G.reshape(-1, 3, 3), gptr, gids, gq.reshape(-1))

    def integrate(self, tri, candidates, budget, min_size=0.0):
        """∫ over the triangles (g, 3, 3) of the integrand.

        Parameters
        ----------
        tri : (g, 3, 3) float64
        candidates : (P,) int64
            The occluders that may matter anywhere (each triangle's list is culled from them).
        budget : float
            Target on the sum of the error estimates.
        min_size : float
            Triangles larger than this (the side of a square of twice their area) are split
            before anything is trusted: a rule on a large triangle may miss a small shadow
            entirely. (Area, not length: the thin cells graded along a hovering outline,
            :func:`hover_segments`, are as thin as the integrand's scale across them and
            smooth along them; halving them in both directions would only multiply them.)

        Returns
        -------
        value, error : float
        cells : int
            Triangles evaluated.
        """
        candidates = np.asarray(candidates, np.int64)
        ptr, ids = cull_all(self.cull, tri, candidates)
        while len(tri) and min_size > 0:
            long = np.sqrt(2 * triangle_areas(tri)) > min_size
            if not np.any(long):
                break
            kids = split4(tri[long]).reshape(-1, 3, 3)
            parent = np.repeat(np.flatnonzero(long), 4)
            kptr, kids_ids = self.cull(kids, *_sub_lists(ptr, ids, parent))
            keep = np.flatnonzero(~long)
            sptr, sids = _sub_lists(ptr, ids, keep)
            tri = np.concatenate([tri[keep], kids])
            ptr, ids = _join_lists(sptr, sids, kptr, kids_ids)
        leaves = self.levels(tri, ptr, ids)
        # a shadow smaller than the grandchildren's nodes' spacing may lie between all 147
        # nodes of a first triangle whose shaft meets an occluder, and its three levels then
        # agree on nothing seen (office(100), a desk panel → another desk's narrow side at
        # any tol: 1.2e-7 off for an estimate of 1.5e-14): looked for as in the rows
        seen = levels_seen(leaves.q, leaves.kq.reshape(-1, 4), leaves.gq.reshape(-1, 16))
        unseen, new, _, _ = look_for_shadows(leaves.tri, seen[:, None], lambda t, need: (np.diff(cull_all(
            self.cull, t, candidates)[0]) > 0)[:, None])
        if len(new):
            leaves = leaves.take(np.flatnonzero(~unseen)).join(self.levels(new, *cull_all(self.cull, new, candidates)))
        # the dual: a target seen through a gap between all the nodes of a first triangle
        # from which they see it wholly hidden (office(300), a desk panel's end → a cabinet
        # seen over another desk only from a 5 mm band along the panel's top edge: 0 ± 3e-10
        # for 2.2e-6)
        if self.gaps is not None and len(leaves.tri):
            hidden, new = self.gaps(leaves.tri, leaves.q, leaves.kq.reshape(-1, 4), leaves.gq.reshape(-1, 16))
            if np.any(hidden):
                leaves = leaves.take(np.flatnonzero(~hidden))
                if len(new):
                    leaves = leaves.join(self.levels(new, *cull_all(self.cull, new, candidates)))
        cells = 21 * len(leaves.tri)
        for _ in range(200):
            err = self.estimates(*leaves[:4], leaves.kq.reshape(-1, 4), leaves.gq.reshape(-1, 16))
            total = float(err.sum())
            if self.progress is not None:
                self.progress(self.evaluations, estimate_ratio(total, budget))
            if total <= budget or cells >= MAX_CELLS or not len(leaves.tri):
                break
            # split the leaves with the largest estimates until what is left is REFINE_LEFT
            # of the budget
            split = worst_leaves(err[:, None], np.array([total]), [0], np.array([budget]), REFINE_LEFT)
            # the split leaves' children become leaves (children with nothing to hide are
            # exactly zero and dropped); their children and grandchildren move up a level,
            # and the grandchildren's children are evaluated
            child = child_rows(np.flatnonzero(split))
            child = child[np.diff(leaves.kptr)[child] > 0]
            grand = child_rows(child)
            new_K = leaves.G[grand]
            nkptr, nkids = self.culled(new_K, *_sub_lists(leaves.gptr, leaves.gids, grand))
            new_G, ngptr, ngids, new_gq = self.expand(new_K, nkptr, nkids, cull=False)
            cells += 16 * len(child)
            born = Levels(leaves.K[child], *_sub_lists(leaves.kptr, leaves.kids, child), leaves.kq[child], new_K, nkptr,
                          nkids, leaves.gq[grand], new_G.reshape(-1, 3, 3), ngptr, ngids, new_gq.reshape(-1))
            leaves = leaves.take(np.flatnonzero(~split)).join(born)
        tri, ptr, ids, q = leaves[:4]
        kq, gq = leaves.kq.reshape(-1, 4), leaves.gq.reshape(-1, 16)
        err = self.estimates(tri, ptr, ids, q, kq, gq)
        self.leaves = (tri, ptr, ids, q, kq, gq, err)
        return float(gq.sum()), float(err.sum()), cells


#: Candidate pairs (triangle, occluder) culled at once by :func:`cull_all`: every triangle
#: against every occluder of a pair is 27 million pairs on the bunny's floor, whose arrays
#: (GBs, mapped afresh and faulted in page by page) cost seconds of system time.
CULL_BLOCK = 1 << 20


def cull_all(cull, tri, candidates):
    """``cull(tri, ptr, ids)`` of every triangle against all the candidates, by blocks of
    triangles (at most :data:`CULL_BLOCK` pairs each, at least one triangle): the same
    lists, in bounded memory.

    Returns
    -------
    ptr : (g + 1,) int64
    ids : (k,) int64
    """
    step = max(1, CULL_BLOCK // max(len(candidates), 1))
    ptrs, lists = [np.zeros(1, np.int64)], []
    for lo in range(0, len(tri), step):
        block = tri[lo:lo + step]
        ptr, ids = cull(block, (np.arange(len(block) + 1) * len(candidates)).astype(np.int64),
                        np.tile(candidates, len(block)))
        ptrs.append(ptr[1:] + ptrs[-1][-1])
        lists.append(ids)
    return np.concatenate(ptrs).astype(np.int64), (np.concatenate(lists) if lists else np.zeros(0, np.int64))


def _longest_side(tri):
    return np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2).max(axis=1)


def _sub_lists(ptr, ids, rows):
    """The CSR lists of ``rows`` (with repeats), as a new CSR ``(ptr, ids)``."""
    counts = np.diff(ptr)[rows]
    out_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    starts = np.repeat(ptr[:-1][rows] - out_ptr[:-1], counts)
    return out_ptr, ids[starts + np.arange(out_ptr[-1])] if out_ptr[-1] else np.zeros(0, np.int64)


def _join_lists(ptr_a, ids_a, ptr_b, ids_b):
    """Two CSR lists one after the other."""
    return np.concatenate([ptr_a[:-1], ptr_b + ptr_a[-1]]).astype(np.int64), np.concatenate([ids_a, ids_b]).astype(np.int64)


def _concat_lists(lists):
    """CSR lists ``[(ptr, ids), ...]`` one after the other, as one ``(ptr, ids)``."""
    if not lists:
        return np.zeros(1, np.int64), np.zeros(0, np.int64)
    ends = np.cumsum([ptr[-1] for ptr, _ in lists])
    ptr = np.concatenate([[0]] + [p[1:] + e - p[-1] for (p, _), e in zip(lists, ends)])
    return ptr.astype(np.int64), np.concatenate([ids for _, ids in lists]).astype(np.int64)


# --------------------------------------------------------------------------------------
# one pair of sides


@dataclass
class PairResult:
    """F from side ``side_i`` of face i to side ``side_j`` of a target, with its error estimate."""

    F: float
    error: float
    method: str  # "none" (they cannot see each other), "contour" (unoccluded, exact), "quadrature"
    occluders: int = 0
    evaluations: int = 0
    cells: int = 0
    seconds: float = 0.0


def target_frame(J, n_t):
    """A target polygon in a 2-D basis of its plane, as the kernels of
    :mod:`viscx.geometry.occlusion` want it: ``(origin, eu, ev, j2, j_loop, hull2, hull3)``.

    J : list of (k, 3) float64 (outer loop counter-clockwise about n_t, holes clockwise);
    n_t : (3,) float64 its normal, towards the points that see it.
    """
    eu, ev = plane_basis(n_t)
    # a generic rotation of the basis: no edge of an axis-aligned scene is vertical in
    # 2-D, so the slab sweep needs no vertical sides (viscx.geometry.occlusion)
    c, s_ = np.cos(GENERIC_ANGLE), np.sin(GENERIC_ANGLE)
    eu, ev = c * eu + s_ * ev, -s_ * eu + c * ev
    origin = J[0][0].copy()
    j2 = [np.stack([(l - origin) @ eu, (l - origin) @ ev], axis=1) for l in J]
    allj = np.ascontiguousarray(np.concatenate(j2))
    j_loop = np.concatenate([[0], np.cumsum([len(l) for l in j2])]).astype(np.int64)
    h = hull_order(j2)  # counter-clockwise in 2-D
    return origin, eu, ev, allj, j_loop, np.ascontiguousarray(allj[h]), np.ascontiguousarray(np.concatenate(J)[h])


class PairSetup:
    """Everything x-independent of a pair (I side s, J side t) for the cubature.

    ``cells``: :func:`emitter_cells` of (face_i, side_i) when the caller has them (they
    depend on the emitter only), else computed when needed; ``kinked``: they are cut along
    the kink lines (:func:`cubature_cells`), so the cubature needs two levels only;
    ``occluders``: find them now (else :meth:`find_occluders` when needed); ``keep``: keep
    them on the scene for the next set-up of the same pair of sides (a group query's:
    :func:`kink_faces` and :func:`pair_form_factor` both need them; a target's holes
    change neither J's hull nor its box, so not the occluders)."""

    def __init__(self, scene, face_i, side_i, target, side_t, cells=None, occluders=True, kinked=False, keep=False):
        self.scene = scene
        self.face_i, self.side_i, self._cells, self.kinked = int(face_i), int(side_i), cells, bool(kinked)
        self.side_t, self.keep = int(side_t), bool(keep)
        self.area_i = float(scene.face_area[face_i])
        n_i = side_i * scene.face_normal[face_i]
        loops_i = oriented_loops(scene.face_loops(face_i), n_i)
        c_i = float(n_i @ loops_i[0][0])
        n_t = side_t * np.asarray(target.normal, dtype=np.float64)
        loops_t = oriented_loops(target.loops, n_t)
        c_t = float(n_t @ loops_t[0][0])
        tiny = 1e-9 * scene.diagonal
        self.tiny = tiny
        self.n_i, self.c_i, self.n_t, self.c_t = n_i, c_i, n_t, c_t
        self._loops_i = loops_i
        self.I = clip_loops(loops_i, n_t, c_t + tiny)
        self.J = clip_loops(loops_t, n_i, c_i)
        self.empty = (
            not self.I or not self.J
            or loops_area(self.I, n_i) <= tiny * tiny
            or loops_area(self.J, n_t) <= tiny * tiny
            or max(float(np.max(l @ n_i)) for l in self.J) - c_i <= tiny
            or max(float(np.max(l @ n_t)) for l in self.I) - c_t <= tiny
        )
        self.face_t = int(target.face)
        self.occluders, self.occluders_found = [], False
        if not self.empty and occluders:
            self.find_occluders()

    def clip_bound(self):
        """An upper bound, in F, of what clipping the emitter ``tiny`` off the target's plane
        leaves out (I' is I in front of the plane by more than tiny: the contour integral
        is not taken, and the kernels see no column, where a point lies within tiny of a
        polygon's plane). The strip of I within tiny in front of the plane, area ΔA, lies
        where faces share an edge (a cabinet's side on the floor); a point there sees at
        most F = (1 − n_i · n_t) / 2 of anything in the plane (all of its side facing the
        point), so the bound is that times ΔA / A_i: 0 where no vertex of I lies within
        tiny of the plane, ~1e-9 on the office's pairs meeting at an edge."""
        h = min(float(np.min(l @ self.n_t)) for l in self._loops_i) - self.c_t
        if h > self.tiny or not self.I:
            return 0.0
        strip = loops_area(clip_loops(self._loops_i, self.n_t, self.c_t), self.n_i) - loops_area(self.I, self.n_i)
        return max(0.0, 0.5 * (1.0 - float(self.n_i @ self.n_t))) * max(strip, 0.0) / self.area_i

    def find_occluders(self):
        """Set :attr:`occluders` (:func:`pair_occluders`; a setup made without them gets them
        here when it needs them first; with ``keep``, a face target's are kept on the scene)
        and :attr:`occluders_found`."""
        def build(scene):
            return pair_occluders(scene, self.I, self.n_i, self.c_i, self.J, self.n_t, self.c_t, {self.face_i, self.face_t})

        self.occluders_found = True
        if not self.keep or self.face_t < 0:
            self.occluders = build(self.scene)
            return
        self.occluders = self.scene.cached(f"pair_occluders {self.face_i} {self.side_i} {self.face_t} {self.side_t}", build)

    # -- the integrand ------------------------------------------------------------------
    @functools.cached_property
    def frame(self):
        """J' in a 2-D basis of its plane (:func:`target_frame`)."""
        return target_frame(self.J, self.n_t)

    def kernel_for(self, occluders):
        """The arrays of :func:`viscx.geometry.occlusion.visible_form_factors` with these
        occluders (the pair's, or a subset that is known to be enough for some points)."""
        origin, eu, ev, allj, j_loop, _, hull3 = self.frame
        occ, occ_loop, occ_poly, pn, pp = [], [0], [], [], []
        face_box, box_ptr, box_planes = closed_boxes(self.scene)
        boxes = np.asarray([face_box[o[2]] if len(o) > 2 and o[2] >= 0 else -1 for o in occluders], np.int64)
        for k, (loops, nk, *_) in enumerate(occluders):
            for loop in loops:
                occ.append(loop)
                occ_loop.append(occ_loop[-1] + len(loop))
                occ_poly.append(k)
            pn.append(nk)
            pp.append(loops[0][0])
        occ_loop, occ_poly = np.asarray(occ_loop, np.int64), np.asarray(occ_poly, np.int64)
        occ = np.ascontiguousarray(np.concatenate(occ) if occ else np.zeros((0, 3)))
        return dict(
            n_i=self.n_i, j2=allj, j_loop=j_loop, origin=origin, eu=eu, ev=ev, n_j=self.n_t, c_j=self.c_t, hull=hull3,
            occ=occ, occ_loop=occ_loop, occ_poly=occ_poly, poly_normal=np.asarray(pn, np.float64).reshape(-1, 3),
            poly_point=np.asarray(pp, np.float64).reshape(-1, 3), tiny=self.tiny, poly_box=boxes, box_ptr=box_ptr,
            box_planes=box_planes, **self._solid_arrays(occluders, occ, occ_loop, occ_poly, boxes, box_ptr),
        )

    def _solid_arrays(self, occluders, occ, occ_loop, occ_poly, boxes, box_ptr):
        """The :func:`surface_patches` arrays of :func:`viscx.geometry.occlusion.visible_form_factors`
        for these occluders (their loops ``occ`` (no, 3) float64, ``occ_loop``, ``occ_poly``
        as the kernel has them): ``poly_solid`` (the patch of an unclipped occluder (every
        loop whole) that is no face of a convex box of at most :data:`HULL_BOX_FACES` planes,
        those the kernel sweeps as the convex hull of their projection, nor a patch of its
        own, nor a face within ``tiny`` of I's plane; numbered among these occluders from 0;
        else -1), ``solid_open`` (per patch: 0 for a :func:`closed_solids` solid in the closed
        front half-space of I, so that every point of I is outside it and its front faces
        hide all it hides, else 1: its back faces' outline is swept too), ``occ_nb`` (the
        occluder across each edge, -1 none), ``occ_vid`` (vertex ids, per patch) and
        ``occ_next`` (the next vertex of each loop)."""
        n = int(occ_loop[-1])
        poly_solid = np.full(len(occluders), -1, np.int64)
        occ_nb = np.full(n, -1, np.int64)
        occ_vid = np.zeros(n, np.int64)
        occ_next = loop_successors(occ_loop)
        patch, neighbour = surface_patches(self.scene)
        face_solid = closed_solids(self.scene)[0]
        eligible = _outside_solids(self.scene, self.n_i, self.c_i, self.tiny)
        scene = self.scene
        flo, lo = scene.face_loop_offsets, scene.loop_offsets
        faces = np.asarray([o[2] if len(o) > 2 else -1 for o in occluders], np.int64).reshape(-1)
        count = np.asarray([len(o[0]) for o in occluders], np.int64).reshape(-1)
        first_loop = np.cumsum(count) - count  # occluder k's loops, one after the other
        hulled = boxes >= 0
        hulled[hulled] = np.diff(box_ptr)[boxes[hulled]] <= HULL_BOX_FACES
        take = (faces >= 0) & ~hulled
        take[take] &= (np.bincount(patch, minlength=scene.n_faces)[patch[faces[take]]] >= 2) & \
            (count[take] == np.diff(flo)[faces[take]])
        # a face touching I's plane stays on its own: the outline may run along the horizon
        # of a point of I for more than half of it (the Cornell box's walls seen from its
        # floor; a U-shaped solid standing on it, seen from inside the U), where its clipped
        # projection loses its winding; on its own it hides what it hides
        low = np.full(len(occluders), -np.inf)
        edge_poly = np.repeat(occ_poly, np.diff(occ_loop))
        if n:
            np.maximum.at(low, edge_poly, -(occ @ self.n_i))
        take &= -low - self.c_i > self.tiny
        # unclipped: every loop the face's own, the same points in the same order
        # (:func:`solid_edge_positions`, for all occluders at once)
        loop_k = occ_poly
        scene_loop = flo[np.maximum(faces[loop_k], 0)] + np.arange(len(loop_k)) - first_loop[loop_k]
        scene_loop = np.minimum(scene_loop, len(lo) - 2)
        fits = take[loop_k] & (np.diff(occ_loop) == np.diff(lo)[scene_loop])
        take &= np.bincount(loop_k[~fits], minlength=len(occluders)) == 0
        edge_loop = np.repeat(np.arange(len(loop_k)), np.diff(occ_loop))
        edges = np.flatnonzero(take[edge_poly])
        at = lo[scene_loop[edge_loop[edges]]] + edges - occ_loop[edge_loop[edges]]
        same = np.all(occ[edges] == scene.vertices[scene.loop_vertices[at]], axis=1)
        take &= np.bincount(edge_poly[edges[~same]], minlength=len(occluders)) == 0
        poly_solid[take] = patch[faces[take]]
        inside_edges = take[edge_poly]
        pos = np.full(n, -1, np.int64)
        pos[edges[take[edge_poly[edges]]]] = at[take[edge_poly[edges]]]
        edge_patch = np.where(inside_edges, poly_solid[edge_poly], -1)
        pid_of = np.full(scene.n_faces, -1, np.int64)
        pid_of[faces[take]] = np.flatnonzero(take)
        # the patches numbered among these occluders (the kernel's work arrays have one
        # entry per occluder; the scene's ids may be larger), each closed or open from I
        inside = np.flatnonzero(poly_solid >= 0)
        solid = face_solid[faces[inside]]
        closed = solid >= 0
        closed[closed] = eligible[solid[closed]]
        ids, poly_solid[inside] = np.unique(poly_solid[inside], return_inverse=True)
        solid_open = np.ones(len(ids), np.int64)
        solid_open[poly_solid[inside][closed]] = 0
        rows = np.flatnonzero(pos >= 0)
        nb_face = neighbour[pos[rows]]
        occ_nb[rows] = np.where(nb_face >= 0, pid_of[np.maximum(nb_face, 0)], -1)
        # a vertex's id per patch: two patches meeting at a vertex (a bow-tie where a scan
        # has holes) must not chain their outlines into each other's polygons
        key = edge_patch[rows] * self.scene.n_vertices + self.scene.loop_vertices[pos[rows]]
        _, occ_vid[rows] = np.unique(key, return_inverse=True)
        return dict(poly_solid=poly_solid, solid_open=solid_open, occ_nb=occ_nb, occ_vid=occ_vid, occ_next=occ_next)

    @functools.cached_property
    def kernel(self):
        """:meth:`kernel_for` all the pair's occluders."""
        return self.kernel_for(self.occluders)

    def f(self, points, kernel=None):
        """F from differential areas at ``points`` (m, 3) on I to the part of J' each sees;
        ``kernel``: :meth:`kernel_for` a subset of the occluders (default all)."""
        k = self.kernel if kernel is None else kernel
        return visible_form_factors(np.ascontiguousarray(points), k["n_i"], k["j2"], k["j_loop"], k["origin"], k["eu"], k["ev"],
                                    k["n_j"], k["c_j"], k["hull"], k["occ"], k["occ_loop"], k["occ_poly"], k["poly_normal"],
                                    k["poly_point"], k["tiny"], k["poly_box"], k["box_ptr"], k["box_planes"], k["poly_solid"],
                                    k["solid_open"], k["occ_nb"], k["occ_vid"], k["occ_next"])

    def blocked(self, points, group, ptr, ids):
        """F(x → J') − F(x → visible part of J') at ``points``, each past its group's occluders
        (:func:`viscx.geometry.occlusion.blocked_form_factors`)."""
        k = self.kernel
        return blocked_form_factors(points, np.asarray(group, np.int64), ptr, ids, k["n_i"], k["j2"], k["j_loop"], k["origin"],
                                    k["eu"], k["ev"], k["n_j"], k["c_j"], k["hull"], k["occ"], k["occ_loop"], k["occ_poly"],
                                    k["poly_normal"], k["poly_point"], k["tiny"], k["poly_box"], k["box_ptr"], k["box_planes"],
                                    k["poly_solid"], k["solid_open"], k["occ_nb"], k["occ_vid"], k["occ_next"])

    # -- the cubature's domain ----------------------------------------------------------
    def triangles(self):
        """(g, 3, 3) float64: I' as triangles, from the emitter's cells (cut at its contact
        lines) clipped to the receiving side of J."""
        cells = self._cells if self._cells is not None else emitter_cells(self.scene, self.face_i, self.side_i)
        point = self.n_t * (self.c_t + self.tiny)
        out = []
        for cell in cells:
            h = cell @ self.n_t - self.c_t - self.tiny
            if h.max() <= 0:
                continue
            if h.min() < 0:
                cell = clip_to_hemisphere(cell, point, self.n_t)
                if len(cell) < 3:
                    continue
            k = np.arange(1, len(cell) - 1)
            out.append(np.stack([np.repeat(cell[:1], len(k), axis=0), cell[k], cell[k + 1]], axis=1))
        return np.concatenate(out) if out else np.zeros((0, 3, 3))

    def shaft_cull(self, tri, ptr, ids, exact=False):
        """Each triangle's occluders (CSR ``ptr, ids`` into :attr:`occluders`) reduced to the
        ones meeting its shaft to J' (:func:`viscx.geometry.occlusion.shaft_meets`) that are
        not back faces of a closed box outside of which the whole triangle lies
        (:func:`back_faces`). The faces of a closed solid (``poly_solid`` of :attr:`kernel`)
        in a list already culled (fewer than all the pair's occluders: a child's list, from
        its parent's) are kept where their boxes meet the shaft's
        (:func:`viscx.geometry.occlusion.shaft_boxes_meet`): a superset, as exact (a face
        that misses the shaft hides nothing), and the kernel's cost grows little with them
        (their outline is what it sweeps) while the full test of the hundreds of bunny
        triangles in each shaft was most of the cubature's time. With ``exact``, every
        occluder by the full test: the lists of the triangles whose shafts meet one."""
        pts, lo, hi, normals = self.occluder_outlines
        counts = np.diff(ptr)
        cell = np.repeat(np.arange(len(tri)), counts)
        keep = ~back_faces(self.scene, tri, cell, self._occluder_faces[ids], self.tiny, self.n_i)
        cell, ids = cell[keep], ids[keep]
        tri = np.ascontiguousarray(tri)
        rough = (self.kernel["poly_solid"][ids] >= 0) & (counts[cell] < len(self.occluders)) & (not exact)
        meets = np.empty(len(ids), bool)
        meets[rough] = shaft_boxes_meet(tri, self.frame[6], cell[rough], ids[rough], pts, lo, hi, self.tiny)
        # (np.tile: a writable copy even for one triangle, as a broadcast one is not: one kernel signature)
        meets[~rough] = shaft_meets(tri, np.tile(self.n_i, (len(tri), 1)), self.frame[6],
                                    np.asarray(self.n_t, np.float64), cell[~rough], ids[~rough], pts, lo, hi, normals,
                                    self.tiny)
        counts = np.bincount(cell[meets], minlength=len(tri))
        return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64), ids[meets]

    @functools.cached_property
    def occluder_outlines(self):
        """The occluders' outer loops as :func:`viscx.geometry.occlusion.shaft_meets` wants
        them: ``(points, lo, hi, normals)``."""
        return _polygon_arrays(self.occluders)

    @functools.cached_property
    def _occluder_faces(self):
        """(P,) int64: the scene's face of each occluder (-1 none)."""
        return np.asarray([o[2] if len(o) > 2 else -1 for o in self.occluders], np.int64).reshape(-1)

    @functools.cached_property
    def _heights(self):
        """Per occluder: the least height above I of its vertices not on I (inf if none),
        its outline's edges projected on I's plane ``(a, b)`` (P, k, 3) and their ends'
        heights above I ``(ha, hb)`` (P, k) (padded by repeating the last edge)."""
        pts, lo, hi, _ = self.occluder_outlines
        h = pts @ self.n_i - self.c_i
        k = int((hi - lo).max()) if len(lo) else 1
        idx = np.minimum(lo[:, None] + np.arange(k), hi[:, None] - 1)
        nxt = np.where(idx + 1 < hi[:, None], idx + 1, lo[:, None])
        flat = pts - h[:, None] * self.n_i
        above = np.where(h[idx] > 10 * self.tiny, h[idx], np.inf).min(axis=1)
        return above, flat[idx], flat[nxt], h[idx], h[nxt]

    @functools.cached_property
    def _edge_positions(self):
        """(P, k) int64: :func:`solid_edge_positions` of each occluder's outline edges, in
        :attr:`_heights`' padded order."""
        pts, lo, hi, _ = self.occluder_outlines
        k = int((hi - lo).max()) if len(lo) else 1
        out = np.full((len(lo), k), -1, np.int64)
        faces = self._occluder_faces
        for p in np.flatnonzero(faces >= 0):
            pos = solid_edge_positions(self.scene, faces[p], pts[lo[p]:hi[p]])
            out[p] = pos[np.minimum(np.arange(k), len(pos) - 1)]
        return out

    def unresolved(self, tri, ptr, ids):
        """(g,) float64: what a rule may miss on each triangle crossed by the outline of an
        occluder that hovers above I by less than half the triangle's width. Its shadow there
        has an edge as narrow as its height h (the Cornell light 0.1 mm under the ceiling),
        where the hidden part goes from about 0 to about F(x → J') ≤ 1 across a band of
        width ~h: the rule may miss up to 2 h times the outline's length in the triangle
        (at most its size). The emitter's cells are cut along such outlines and graded
        towards them (:func:`hover_segments`), so on those cells no outline crosses a
        triangle and nothing is added; what is left is for outlines the cuts do not know
        (occluders hovering higher than a quarter of their edges). The height is the
        outline's where it crosses the triangle: the least of the edge's heights over the
        part whose projection lies across the triangle (an edge rising away from I, a post's
        vertical edge under a tilted panel whose top hovers 2 cm under it, has a narrow
        shadow edge near its low end only; with the occluder's lowest vertex for every
        edge, the whole projected outline got the bound and a PV row's back → the ground
        stopped at MAX_CELLS with an estimate of 6e-3 at tol 1e-3)."""
        size = _longest_side(tri)
        above, a, b, ha, hb = self._heights
        cell = np.repeat(np.arange(len(tri)), np.diff(ptr))
        near = (2 * above[ids] < size[cell]) & (size[cell] > 1e-7 * self.scene.diagonal)
        out = np.zeros(len(tri))
        if not np.any(near):
            return out
        cell, occ = cell[near], ids[near]
        d = b[occ] - a[occ]  # (c, k, 3) the outline's edges on I's plane
        length = np.linalg.norm(d, axis=2)
        unit = d / np.maximum(length, 1e-300)[..., None]
        across = np.cross(self.n_i, unit)
        rel = tri[cell][:, None, :, :] - a[occ][:, :, None, :]  # (c, k, 3 vertices, 3)
        s = np.einsum("ckvj,ckj->ckv", rel, across)
        t = np.einsum("ckvj,ckj->ckv", rel, unit)
        # the edge's height (linear along it) at the ends of its part across the triangle
        safe = np.maximum(length, 1e-300)
        t0, t1 = np.clip(t.min(axis=2), 0, length) / safe, np.clip(t.max(axis=2), 0, length) / safe
        h_a, h_b = ha[occ], hb[occ]
        h = np.minimum(h_a + (h_b - h_a) * t0, h_a + (h_b - h_a) * t1)
        h = np.where(h > 10 * self.tiny, h, above[occ][:, None])  # an end on I: its other vertices'
        # the edge's line crosses the triangle with more than h on both sides, within the
        # edge, where it hovers by less than half the triangle's width
        crosses = (s.max(axis=2) > h) & (s.min(axis=2) < -h) & (t.max(axis=2) > 0) & (t.min(axis=2) < length)
        crosses &= (length > 0) & (2 * h < size[cell][:, None])
        # edges of a closed solid between two front or two back faces from the whole
        # triangle are on no outline there (the bunny's underside over the floor)
        c_, k_ = np.nonzero(crosses)
        if len(c_):
            inner = inner_solid_edges(self.scene, self.n_i, self.c_i, self.tiny, self._occluder_faces[occ[c_]],
                                      self._edge_positions[occ[c_], k_], tri[cell[c_]])
            crosses[c_[inner], k_[inner]] = False
        hit = crosses.any(axis=1)
        low = np.where(crosses, h, np.inf).min(axis=1)
        np.maximum.at(out, cell[hit], 2 * low[hit] * size[cell[hit]])
        return out

    def blocked_integral(self, budget, threads=1, progress=None, halvings=0):
        """∫_{I'} (F(x → J') − F(x → visible J')) dx by adaptive cubature, error estimate ≤
        ``budget`` where :data:`MAX_CELLS` allows: on cells cut along the kink lines the
        two-level :class:`RowCubature` (one column) over the triangles whose shafts meet an
        occluder (elsewhere the integrand is zero, exactly), else the three-level
        :class:`Cubature`. ``progress``: the cubature's (:class:`Cubature`). The first
        triangles are at most 1 / :data:`MIN_SPLIT` of the pair's box, each split
        ``halvings`` times more (:func:`confirm_mostly_hidden`: 4^halvings as many).

        Returns
        -------
        value, error : float
        evaluations, cells : int
        """
        tri = self.triangles()
        pts = np.concatenate(self.I + self.J)
        min_size = np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)) / MIN_SPLIT / 2 ** halvings
        for _ in range(halvings):  # midpoint splits nest: each first triangle's 4^halvings
            tri = split4(tri).reshape(-1, 3, 3)
        if self.kinked:
            tri = split_large(tri, min_size)
        # the triangles wholly in a closed solid's umbra hide F(x → J') whole: its
        # contour integral, exact, instead of the cubature (the bunny's floor under it;
        # tested before the three-level path splits the large ones, whose lists it culls
        # level by level)
        shadow = self.umbra(tri)
        umbra, umbra_err = self.unoccluded_integral(tri[shadow])
        tri = tri[~shadow]
        budget = max(budget - umbra_err, 0.5 * budget)
        if self.kinked:
            k = len(self.occluders)
            ptr, _ = cull_all(self.shaft_cull, tri, np.arange(k))
            tri = tri[np.diff(ptr) > 0]

            def column(points, tri):
                # each triangle past the occluders that meet its shaft (as Cubature's lists)
                ptr, ids = cull_all(self.shaft_cull, tri, np.arange(k))
                return self.blocked(points, np.repeat(np.arange(len(tri)), 7), ptr, ids)[:, None]

            def live(tri, need):
                ptr, _ = cull_all(self.shaft_cull, tri, np.arange(k))
                return (np.diff(ptr) > 0)[:, None]

            # a blind leaf hides at most F(x → J'), as on three levels (Cubature.estimates)
            cub = RowCubature(column, threads, progress)
            value, error, cells = cub.integrate(tri, np.array([budget]), live,
                                                blind_bound=lambda t: self.unoccluded_bound(t)[:, None])
            return umbra + float(value[0]), umbra_err + float(error[0]), cub.evaluations, cells
        cub = Cubature(self.blocked, self.shaft_cull, self.unresolved, self.unoccluded_bound, threads, progress,
                       self.gaps, functools.partial(self.shaft_cull, exact=True))
        value, error, cells = cub.integrate(tri, np.arange(len(self.occluders)), budget, min_size)
        return umbra + value, umbra_err + error, cub.evaluations, cells

    def gaps(self, tri, q, kq, gq):
        """The first triangles (g, 3, 3) of the three-level cubature from whose 147 nodes J'
        is wholly hidden (:meth:`gap_candidates` of their rules ``q`` (g,), ``kq`` (g, 4),
        ``gq`` (g, 16)), cut along the pair's critical lines crossing them
        (:func:`cut_hidden`): ``(hidden (g,) bool, new (h, 3, 3))``, the triangles replaced
        and what replaces them."""
        hidden = self.gap_candidates(tri, np.concatenate([q[:, None], kq, gq], axis=1))
        if not np.any(hidden):
            return hidden, np.zeros((0, 3, 3))
        return cut_hidden(self.scene, self.n_i, tri, hidden, self.gap_lines(tri[hidden]), self.f)

    def gap_candidates(self, tri, rules):
        """(g,) bool: the triangles (g, 3, 3) from whose nodes J' is wholly hidden
        (:meth:`hidden_at_nodes`, ``rules`` (g, 21)) but not shown hidden from the whole
        triangle by one occluder or a closed solid (:meth:`face_umbra`, :meth:`umbra`):
        where J' may yet be seen through a gap between the nodes."""
        out = self.hidden_at_nodes(tri, rules)
        for umbra in (self.face_umbra, self.umbra):
            rows = np.flatnonzero(out)
            if len(rows):
                out[rows] = ~umbra(tri[rows])
        return out

    def hidden_at_nodes(self, tri, rules):
        """(g,) bool: the triangles (g, 3, 3) of I' from whose 147 nodes (Radon's rule on
        each, its 4 children and 16 grandchildren, as :meth:`Cubature.levels`) J' is
        wholly hidden: the 21 rules of the hidden part ``rules`` (g, 21) equal those of the
        unoccluded F(x → J') (:func:`point_to_polygon`), which are not 0 (the integrands lie
        in [0, 1] and the rules' weights are positive, so equal sums are equal values at
        every node, to :data:`UNSEEN` times the area). The finer levels are evaluated only
        on the triangles whose own rule already agrees."""
        area = triangle_areas(tri)

        def rule(t):  # (m, 3, 3) -> (m,): Radon's rule of F(x → J'), in ∫ units
            pts = np.einsum("rk,gkd->grd", RULE_NODES, t).reshape(-1, 3)
            f = point_to_polygon(pts, np.broadcast_to(self.n_i, pts.shape), self.J)
            return f.reshape(-1, 7) @ RULE_WEIGHTS * triangle_areas(t)

        own = rule(tri)
        out = np.zeros(len(tri), bool)
        ask = np.flatnonzero(np.abs(own - rules[:, 0]) <= UNSEEN * area)  # else the sum of 21 is past it
        if not len(ask):
            return out
        kids = split4(tri[ask]).reshape(-1, 3, 3)
        grand = split4(kids).reshape(-1, 3, 3)
        f0 = np.concatenate([own[ask, None], rule(kids).reshape(-1, 4), rule(grand).reshape(-1, 16)], axis=1)
        out[ask] = (np.abs(f0 - rules[ask]).sum(axis=1) <= UNSEEN * area[ask]) & (f0.sum(axis=1) > UNSEEN * area[ask])
        return out

    def gap_lines(self, tri):
        """(s, 2, 3) float64 or None: the pair's critical lines on I for the triangles
        (g, 3, 3) of I': where two edges of the faces that can hide J' from them line up
        (:func:`kink_segments`): J, the faces lying in J's plane, and the occluders meeting
        one of their shafts to J' (:meth:`shaft_cull`; an occluder outside them changes what
        no point of the triangles sees, and the lines are quadratic in the edges). None
        where they are too many to list, or for a sky target, whose edges are no scene's."""
        if self.face_t < 0:
            return None
        if not self.occluders_found:
            self.find_occluders()
        ids = cull_all(self.shaft_cull, tri, np.arange(len(self.occluders)))[1] if len(self.occluders) else []
        occ = self._occluder_faces[np.unique(ids).astype(np.int64)]
        faces = np.concatenate([[self.face_t], coplanar_faces(self.scene, self.face_t), occ[occ >= 0]])
        return kink_segments(self.scene, self.face_i, self.side_i, face_generators(self.scene, np.unique(faces)))

    def umbra(self, tri):
        """(g,) bool: the triangles (g, 3, 3) of I' from every point of which a closed solid
        hides the whole of J' (:func:`viscx.geometry.occlusion.umbra_triangles`, by the
        sections of the solids that lie in the closed front half-space of I:
        :func:`solid_sections`); conservative (False where not shown)."""
        out = np.zeros(len(tri), bool)
        solids = np.flatnonzero(_outside_solids(self.scene, self.n_i, self.c_i, self.tiny))
        if not len(tri) or not len(solids):
            return out
        heights, sec_ptr, sec = solid_sections(self.scene, solids, self.n_t, self.c_t, self.tiny)
        if not len(heights):
            return out
        eu, ev = plane_basis(self.n_t)
        hull = np.ascontiguousarray(self.frame[6])
        return umbra_triangles(np.ascontiguousarray(tri), hull, np.asarray(self.n_t, np.float64), float(self.c_t), eu, ev,
                               heights, sec_ptr, sec, 10 * self.tiny)

    def hidden_whole(self):
        """Whether J' is hidden from every point of I' by one occluder or a closed solid:
        :meth:`face_umbra` or :meth:`umbra` of each triangle of the convex hull of I' (they
        hold every point of it). A shelf board's underside sees nothing of the next unit's
        back panel, behind its own: office-like scenes have hundreds of such pairs in a
        group query, each a cubature of F(x → J') − F(x → visible J') to rounding."""
        hull = convex_outline(self.I, self.n_i)
        if len(hull) < 3:
            return False
        tri = start_triangles([hull], 0.0)
        hidden = self.face_umbra(tri)
        rest = np.flatnonzero(~hidden)
        if len(rest):
            hidden[rest] = self.umbra(tri[rest])
        return bool(hidden.all())

    def face_umbra(self, tri):
        """(g,) bool: the triangles (g, 3, 3) of I' from every point of which one occluder
        hides the whole of J' (a desk's top over the floor beneath it): a convex occluder
        without holes whose plane strictly separates the triangle from J', and which holds
        every point where a segment from a corner of the triangle to a corner of J's hull
        crosses that plane (such crossings of any segment from the triangle to J' are
        convex combinations of these, so all lie in the occluder); conservative (the
        points at least tiny inside)."""
        out = np.zeros(len(tri), bool)
        if not len(tri):
            return out
        loop, inward, reach, normal, c = self._convex_occluders
        if not len(c):
            return out
        hull = self.frame[6]  # J's convex hull (m, 3)
        h_j = hull @ normal.T - c  # (m, P)
        side = np.where(np.all(h_j < -self.tiny, axis=0), 1.0, np.where(np.all(h_j > self.tiny, axis=0), -1.0, 0.0))
        h_t = np.einsum("gkd,pd->gpk", tri, normal) - c[None, :, None]  # (g, P, 3)
        g, o = np.nonzero(np.all(side[None, :, None] * h_t > self.tiny, axis=2) & (side != 0)[None])
        for lo in range(0, len(g), 4096):  # bounded memory
            gi, oi = g[lo:lo + 4096], o[lo:lo + 4096]
            a, b = h_t[gi, oi][:, :, None, None], h_j.T[oi][:, None, :, None]  # (k, 3, 1, 1), (k, 1, m, 1)
            x = (a * hull[None, None] - b * tri[gi][:, :, None]) / (a - b)  # (k, 3, m, 3) on the plane
            depth = np.einsum("ktmvd,kvd->ktmv", x[:, :, :, None, :] - loop[oi][:, None, None], inward[oi])
            inside = np.all((depth >= reach[oi][:, None, None]).reshape(len(gi), -1), axis=1)
            out[gi[inside]] = True
        return out

    @functools.cached_property
    def _convex_occluders(self):
        """The occluders :meth:`face_umbra` may use (convex, one loop): ``loop`` (P, V, 3)
        their corners (the last repeated up to V), ``inward`` (P, V, 3) each edge's normal
        into the polygon (length the edge's), ``reach`` (P, V) tiny times that length,
        ``normal`` (P, 3), ``c`` (P,) their planes."""
        if not self.occluders_found:
            self.find_occluders()
        whole = convex_face_loops(self.scene)
        keep = []
        for loops, normal, face in self.occluders:
            # the whole face: it hides where its clipped part does, and more where the clip
            # was I's plane (the segments grazing it there hide nothing but fail the test)
            entry = whole[face] if face >= 0 else _convex_loop(loops, normal)
            if entry is not None:
                keep.append(entry)
        if not keep:
            return np.zeros((0, 1, 3)), np.zeros((0, 1, 3)), np.zeros((0, 1)), np.zeros((0, 3)), np.zeros(0)
        v = max(len(k[0]) for k in keep)
        loop = np.stack([np.concatenate([k[0], np.repeat(k[0][-1:], v - len(k[0]), axis=0)]) for k in keep])
        inward = np.stack([np.concatenate([k[1], np.zeros((v - len(k[1]), 3))]) for k in keep])
        normal = np.stack([k[2] for k in keep])
        return loop, inward, self.tiny * np.linalg.norm(inward, axis=2), normal, np.einsum("pd,pd->p", normal, loop[:, 0])

    def unoccluded_bound(self, tri):
        """(g,) float64: about the most ∫_T F(x → J') dx can be over each triangle (g, 3, 3)
        of I', and so the most its occluders can hide: its area times the largest
        unoccluded F(x → J') at its corners and centroid (F(x → J') is smooth on I': no
        occlusion in it)."""
        pts = np.concatenate([tri, tri.mean(axis=1, keepdims=True)], axis=1).reshape(-1, 3)
        f = point_to_polygon(pts, np.broadcast_to(self.n_i, pts.shape), self.J).reshape(len(tri), 4)
        return triangle_areas(tri) * f.max(axis=1)

    def unoccluded_integral(self, tri):
        """∫ F(x → J') dx over the triangles (g, 3, 3) of I' (disjoint): the contour integral
        of their union (exact), ``(value, error)`` in area × F. Triangles of less than tiny²
        area (slivers of the emitter's cuts) are left out, their area (F ≤ 1) added to the
        error: the contour integral is F times the area, and of no area it was 0 / 0 (F = inf
        from a floor beside a box standing on it, the umbra's triangles all slivers)."""
        areas = triangle_areas(tri)
        keep = areas > self.tiny * self.tiny
        sliver = float(areas[~keep].sum())
        if not keep.any():
            return 0.0, sliver
        area = float(areas[keep].sum())
        v, e = contour_form_factor(list(tri[keep]), self.n_i, self.J, self.n_t, separate=True)
        return v * area, e * area + sliver


def convex_face_loops(scene):
    """Per face, :func:`_convex_loop` of its whole loops about its normal (None for a face
    with holes or not convex), for all faces at once, by their vertex counts (a scanned
    mesh's 10⁵ triangles: one call each took 0.25 ms), cached."""

    def build(scene):
        loops = face_loops_oriented(scene)[1]
        out = [None] * scene.n_faces
        by_size = {}
        for f in range(scene.n_faces):
            if len(loops[f]) == 1 and len(loops[f][0]) >= 3:
                by_size.setdefault(len(loops[f][0]), []).append(f)
        for faces in by_size.values():
            faces = np.asarray(faces, np.int64)
            pts = np.stack([loops[f][0] for f in faces])
            normal = scene.face_normal[faces].astype(np.float64)
            inward, convex = _convex_loops(pts, normal)
            for f, p, w, n in zip(faces[convex], pts[convex], inward[convex], normal[convex]):
                out[f] = (p, w, n)
        return out

    return scene.cached("convex_face_loops", build)


def _convex_loops(pts, normal):
    """Loops ``pts`` (n, k, 3), counter-clockwise about their ``normal`` (n, 3): each edge's
    normal into the polygon, the edge's length, ``inward`` (n, k, 3), and whether the loop
    is convex (left turns only) ``(n,) bool``."""
    edge = np.roll(pts, -1, axis=1) - pts
    inward = np.cross(normal[:, None, :], edge)
    return inward, np.all(np.einsum("nkd,nkd->nk", np.roll(inward, -1, axis=1), edge) <= 0, axis=1)


def _convex_loop(loops, normal):
    """``(loop (V, 3), inward (V, 3), normal (3,))`` of an occluder that is one convex loop
    (counter-clockwise about ``normal``; ``inward`` each edge's normal into the polygon,
    the edge's length), else None (:meth:`PairSetup._convex_occluders`)."""
    if len(loops) != 1 or len(loops[0]) < 3:
        return None
    normal = np.asarray(normal, np.float64)
    inward, convex = _convex_loops(np.asarray(loops[0])[None], normal[None])
    return (loops[0], inward[0], normal) if convex[0] else None


def pair_form_factor(scene, face_i, side_i, target, side_t, tol=DEFAULT_TOL, cells=None, contact=None, kinked=False,
                     threads=1, progress=None):
    """F from side ``side_i`` (+1 front, -1 back) of face i to side ``side_t`` of a target.

    The unoccluded form factor of I' and J' by the contour integral (exact), minus what the
    occluders hide: ∫_{I'} (F(x → J') − F(x → visible part of J')) dx / A_i, whose
    integrand is zero, exactly, on every triangle of I' whose shaft to J' meets no
    occluder, so the cubature works only where shadows are.

    Faces lying on faces (docs/queries.md) as the matrix has them: the emitter's cells that
    lie against another face (:func:`contact_sides`) see that face's side with F = 1 and
    nothing else (their unoccluded part is taken off the contour integral, exactly, and
    they add their area to the pair they touch), and the receiver's cells covered from
    side t (:func:`covered_cells`) receive nothing (they are holes of the target, but for
    those an empty closed box hides from every point of face i anyway: :func:`target_holes`).
    A pair on three levels that comes out mostly hidden is integrated again on finer first
    triangles until two agree (:func:`confirm_mostly_hidden`).

    Parameters
    ----------
    tol : float
        Target on the error estimate (absolute, in F).
    cells, contact : list, (c,) int64, optional
        :func:`cubature_cells` of (face_i, side_i) and their :func:`contact_sides`, shared
        by the pairs of one row (default: those cut along this pair's kink lines, cached).
    kinked : bool
        ``cells`` are cut along the kink lines (:func:`cubature_cells`).
    threads : int
        Threads the cubature's kernels run on (:class:`Cubature`: the same result on any
        number).
    progress : callable, optional
        ``progress(points, ratio)`` after each of the cubature's refinement rounds
        (:class:`Cubature`).

    Returns
    -------
    PairResult
    """
    t0 = time.perf_counter()
    if cells is None:
        # cut along the kinks of this pair only (as a group query's row of one receiver)
        receivers = None if target.face < 0 else [target.face]
        cells, _, kinked = cubature_cells(scene, face_i, side_i, receivers=receivers, pairs=receivers is not None)
        contact = cell_contacts(scene, face_i, side_i, receivers, pairs=receivers is not None)
    if contact is None:
        contact = contact_sides(scene, face_i, side_i, cells)
    lying = contact_cells(scene, face_i, side_i)  # the exact terms: uncut, fewer contour integrals
    if target.face >= 0:
        # the cells covered from side t are holes of the target (they are cells of J, so
        # they lie inside it and do not overlap its holes or each other: non-zero winding
        # and the contour integral take J minus them), but those a box hides anyway
        target = Target(target.loops + target_holes(scene, face_i, target.face, side_t), target.normal, target.face)
    free = [c for c, k in zip(cells, contact) if k < 0]
    touching = 0.0
    if target.face >= 0:
        element = 2 * target.face + (0 if side_t > 0 else 1)
        touching = sum(abs(_cell_area(c)) for c, k in zip(*lying) if k == element) / float(scene.face_area[face_i])
    if target.face >= 0 and box_hidden(scene, face_i, side_i, [target.face], [side_t])[0]:
        # a box's inner side and a face outside the box: nothing seen, exactly
        return PairResult(touching, 0.0, "contact" if touching else "none", seconds=time.perf_counter() - t0)
    setup = PairSetup(scene, face_i, side_i, target, side_t, cells=free, kinked=kinked, keep=True)
    if setup.empty:
        return PairResult(touching, 0.0, "contact" if touching else "none", seconds=time.perf_counter() - t0)
    if setup.occluders and setup.hidden_whole():
        # I' sees nothing of J'; what the strip of I within tiny of J's plane (not in I')
        # may see is still its estimate
        return PairResult(touching, setup.clip_bound(), "contact" if touching else "none",
                          seconds=time.perf_counter() - t0)
    value, err = touching, setup.clip_bound()
    # the emitter's part I' (all its cells) by the contour integral, less its cells in
    # contact, which see nothing else
    parts = [(setup.I, 1.0)] + [(clip_loops([c], setup.n_t, setup.c_t + setup.tiny), -1.0) for c in lying[0]]
    for loops, sign in parts:
        a = loops_area(loops, setup.n_i) / setup.area_i
        if not loops or a * setup.area_i <= setup.tiny ** 2:
            continue
        v, e = contour_form_factor(loops, setup.n_i, setup.J, setup.n_t)
        value, err = value + sign * v * a, err + e * a
    if not setup.occluders or not free:
        return PairResult(value, err, "contour", seconds=time.perf_counter() - t0)
    budget = max(tol - err, 0.1 * tol) * setup.area_i
    hidden, hidden_err, evals, n_cells = setup.blocked_integral(budget, threads, progress)
    if not setup.kinked:
        hidden, hidden_err, evals, more_cells = confirm_mostly_hidden(setup, value, hidden, hidden_err, budget, threads,
                                                                      progress, evals)
        n_cells += more_cells
    return PairResult(value - hidden / setup.area_i, err + hidden_err / setup.area_i, "quadrature", len(setup.occluders),
                      evals, n_cells, time.perf_counter() - t0)


#: A pair or a row's column is *mostly hidden* where F < THIN_BAND × F⁰ (its unoccluded F):
#: what is seen of J' may then be a band or a few patches thinner than the three levels'
#: node spacing, which their differences do not bound (office(300) at 1e-4: 3 of 152 such
#: row entries and 1 of 152 such pair queries were 1.1–7.1 times their estimates off).
THIN_BAND = 1e-2
#: How many times :func:`confirm_mostly_hidden` halves the first triangles at the most.
CONFIRM_HALVINGS = 3


def mostly_hidden(F, F0):
    """Whether F (seen from the nodes: above :data:`UNSEEN`, else the gap searches' case)
    is under :data:`THIN_BAND` times the unoccluded F⁰ (arrays or floats alike)."""
    return (F > UNSEEN) & (F < THIN_BAND * F0)


def confirm_mostly_hidden(setup, F0, hidden, err, budget, threads=1, progress=None, evaluations=0):
    """A three-level pair's hidden integral (``hidden``, ``err``:
    :meth:`PairSetup.blocked_integral`, in area × F, of ``evaluations`` points), confirmed
    where the pair is mostly hidden (:func:`mostly_hidden`; ``F0`` its unoccluded F):
    integrated again on first triangles half as long (four times as many, the nodes twice
    as dense), until the change is within the new integral's estimate, at most
    :data:`CONFIRM_HALVINGS` times; the last is kept, its estimate at least the last
    change (as if the change were all the coarser one's error: a loose estimate before
    does not vouch for a tight one after). The first triangles are 1 / :data:`MIN_SPLIT`
    of the pair's box, metres wide when J' is a wall, and what their nodes see of it
    through the gaps between furniture is then a few of their 147 values (office(300),
    desk0's side panel → the west wall: 3.3214e-6 ± 1.3e-7 at 1e-6 on 2 first triangles,
    3.0501e-6 ± 7.6e-8 on 8 and 3.0550e-6 ± 7.0e-8 on 32, the oracle 3.05173e-6).
    ``progress(points, ratio)`` is told the points of all the integrals so far.

    Returns
    -------
    hidden, err : float
    evaluations : int
        The points of all the integrals.
    cells : int
        The triangles of the integrals added.
    """
    area, cells = setup.area_i, 0
    halvings = 0
    while mostly_hidden(F0 - hidden / area, F0) and halvings < CONFIRM_HALVINGS:
        halvings += 1
        told = None if progress is None else functools.partial(_told_after, progress, evaluations)
        again, again_err, e, c = setup.blocked_integral(budget, threads, told, halvings)
        evaluations, cells = evaluations + e, cells + c
        change = abs(again - hidden)
        hidden, err = again, max(again_err, change)
        if change <= again_err:
            break
    return hidden, err, evaluations, cells


def _told_after(progress, before, points, ratio):
    """``progress(before + points, ratio)``: a cubature's points after ``before`` others."""
    progress(before + points, ratio)


def _cell_area(cell):
    return 0.5 * float(np.linalg.norm(newell_normal(cell)))


def polygon_subset(scene, keep):
    """:func:`scene_polygons` of the faces ``keep`` (sorted (k,) int64) only, polygon p of
    the result being face ``keep[p]`` (ranks kept: only their order matters)."""
    pts, lo, hi, loop_poly, normals, offsets, rank = scene_polygons(scene)
    loops = np.flatnonzero(np.isin(loop_poly, keep))
    sizes = hi[loops] - lo[loops]
    new_hi = np.cumsum(sizes)
    idx = np.repeat(lo[loops] - (new_hi - sizes), sizes) + np.arange(int(sizes.sum()))
    return (np.ascontiguousarray(pts[idx]), (new_hi - sizes).astype(np.int64), new_hi.astype(np.int64),
            np.searchsorted(keep, loop_poly[loops]).astype(np.int64), np.ascontiguousarray(normals[keep]),
            np.ascontiguousarray(offsets[keep]), np.ascontiguousarray(rank[keep]))


def contact_sides(scene, face, side, cells):
    """(c,) int64: for each cell of side ``side`` of a face (:func:`emitter_cells`), the
    element (``2 k`` front, ``2 k + 1`` back) of the face side it lies against, −1 if none
    (docs/queries.md, "Faces lying on faces"). Decided by the matrix's own kernel,
    :func:`viscx.geometry.occlusion.point_views`, at each cell's centroid, over the face and
    the faces in its plane: the cells are cut along the other faces' outlines there
    (:func:`contact_segments`), so a cell lies against one face or none."""
    others = coplanar_faces(scene, face)
    out = np.full(len(cells), -1, np.int64)
    if not len(others) or not len(cells):
        return out
    keep = np.unique(np.concatenate([[face], others])).astype(np.int64)
    n_i = side * scene.face_normal[face]
    eu, ev = plane_basis(n_i)
    centroids = np.ascontiguousarray([c.mean(axis=0) for c in cells])  # convex cells: inside
    h = point_views(centroids, n_i, eu, ev, *polygon_subset(scene, keep), int(np.searchsorted(keep, face)),
                    1e-9 * scene.diagonal, *no_boxes(len(keep)))
    rows, col = np.nonzero(h[:, :-1] == -1.0)
    out[rows] = 2 * keep[col // 2] + col % 2
    return out


def contact_cells(scene, face, side):
    """The cells of side ``side`` of a face that lie against another face's side, and that
    side's element (:func:`contact_sides` of the uncut :func:`emitter_cells`: their exact
    terms need no kink cuts). Cached per face side.

    Returns
    -------
    cells : list of (k, 3) float64
    elements : (c,) int64
    """

    def build(scene):
        if not len(coplanar_faces(scene, face)):
            return [], np.zeros(0, np.int64)
        cells = emitter_cells(scene, face, side)
        contact = contact_sides(scene, face, side, cells)
        return [c for c, k in zip(cells, contact) if k >= 0], contact[contact >= 0]

    return scene.cached(f"contact_cells {int(face)} {int(side)}", build)


def covered_cells(scene, face, side):
    """The cells of side ``side`` of a face that another face covers from that side (a
    cabinet's back on the wall's front, the wall on the back's side against it): the
    :func:`contact_cells` of the side (seen from side t, the point of J lies against K
    exactly where, emitting from side t, it would).

    Returns
    -------
    list of (k, 3) float64
    """
    return contact_cells(scene, face, side)[0]


def target_holes(scene, face_i, face, side):
    """The cells of side ``side`` of a face that a pair from face i must take as holes of
    its target: :func:`covered_cells`, but those lying against a face of an empty closed
    box (:func:`empty_boxes`) that stands on that side, face i not being one of the box's.
    Such a cell C needs no hole: face i meets no point of the box's open interior, so a
    point x of it on side ``side`` is outside the box, and a segment from x to a point y
    of C arrives at y from the box's interior (the box lies on x's side of C's plane), so
    it entered the box through another face, strictly between x and y, which the pair's
    occluders hold (it meets the shaft's interior). So C is hidden from every such x, F(x
    → C) is all hidden, and the pair's F is the same with C in the target or not
    (``F⁰(I' → J') − ∫ hidden`` gains F⁰(I' → C) in both terms). Taking them out of the
    holes spares the kernel their edges at every point (the office's floor: 56 covered
    cells, all under cabinets, desk panels and dividers; ceiling → floor ~620 → ~500 µs a
    point with all its occluders) and the contour integral its 224 edges.

    Returns
    -------
    list of (k, 3) float64
    """
    cells, elements = contact_cells(scene, face, side)
    if not len(cells):
        return []
    face_box = closed_boxes(scene)[0]
    empty = empty_boxes(scene)
    n_t = side * scene.face_normal[face]
    box = face_box[elements // 2]
    # the box stands on side t of the target: the covering face's outward normal points away
    hidden = (box >= 0) & (box != face_box[face_i]) & (scene.face_normal[elements // 2] @ n_t < 0)
    hidden[hidden] = empty[box[hidden]]
    return [c for c, h in zip(cells, hidden) if not h]


def contour_form_factor(loops_i, n_i, loops_j, n_j, separate=False):
    """Unoccluded F_ij by the double contour integral, with the change between two node
    sets (10- and 6-point Gauss–Legendre panels) plus a bound on the rounding of its
    cancelling terms as its error estimate. ``separate``: the loops of i are disjoint
    polygons (F from their union), not one polygon with holes."""
    (value, coarse), rounding = polygon_to_polygon_orders(loops_i, n_i, loops_j, n_j, (10, 6), separate)
    return float(value), abs(float(value) - float(coarse)) + rounding



# --------------------------------------------------------------------------------------
# many pairs: faces, groups, the matrix

SIDES = (1, -1)  # element 2 f + 0: front of face f, 2 f + 1: its back


def estimates_above(errors, tol):
    """How many of the error estimates ``errors`` (k,) float64 are above ``tol`` (by more
    than 1e-9 of it, the rounding of a derived entry's scaled estimate): where a refinement
    stopped at :data:`MAX_CELLS` first, its estimate saying how far from ``tol`` it got, or
    a matrix entry taken from a row's sum (:func:`summation_column`)."""
    return int(np.count_nonzero(np.asarray(errors, np.float64) > tol * (1 + 1e-9)))


def tol_reached(errors, tol):
    """Whether every error estimate ``errors`` (k,) float64 is within ``tol``
    (:func:`estimates_above`)."""
    return estimates_above(errors, tol) == 0


def face_to_face(scene, face_i, target_face, side_i=1, tol=DEFAULT_TOL, quiet=True):
    """F from one side of face i to face j (both of its sides; a progress bar of their
    cubatures' points unless ``quiet``, :func:`pair_bar`).

    Returns
    -------
    dict
        ``F``, ``error``, per-side ``sides`` (front/back of j: F, error, method, ...) and
        ``tol_reached`` (:func:`tol_reached` of the two sides' estimates).
    """
    from viscx.progress import bar

    target = face_target(scene, target_face)
    parts = {}
    with bar(desc="form factors", quiet=quiet, unit="point") as progress:
        show = pair_bar(progress)
        for k, (name, t) in enumerate((("front", 1), ("back", -1))):
            parts[name] = pair_form_factor(scene, face_i, side_i, target, t, tol=tol,
                                           progress=_pair_progress(show, k, 2))
    return {
        "F": float(sum(p.F for p in parts.values())),
        "error": float(sum(p.error for p in parts.values())),
        "sides": {name: _pair_dict(p) for name, p in parts.items()},
        "tol_reached": tol_reached([p.error for p in parts.values()], tol),
    }


def _pair_dict(p):
    return {"F": float(p.F), "error": float(p.error), "method": p.method, "occluders": p.occluders,
            "evaluations": int(p.evaluations), "cells": int(p.cells), "seconds": round(p.seconds, 4)}


def group_to_group(scene, faces_i, faces_j, side_i=1, tol=DEFAULT_TOL, workers=None, reciprocal=True, quiet=True):
    """Area-weighted F from side ``side_i`` of the faces_i to (both sides of) the faces_j:
    ``Σ_i A_i Σ_j F_ij / Σ_i A_i``. A face in both sets does not see itself (planar).

    With ``reciprocal`` (the default, as the matrix), each face pair is computed once, in
    the rows of its face of smaller area (:func:`computed_pairs`), and the other direction
    derived as the matrix derives it (:func:`derived_entries`): the floor's part of
    floor → desk is ``A_i F_(i,s)→j = Σ_t A_j F_(j,t)→(i,s)``, from the desk faces' rows
    to the floor, each estimate scaled by A_j / A_i ≤ 1 (:func:`group_rows`). Without,
    every pair is computed from the faces_i (two-sided: the oracle the tests compare with).

    Each emitting face side's cells are computed once for all its receivers
    (:func:`emitter_row`), and the pairs it cannot see are left out of its row by the
    vectorised facing test (:func:`seen_receivers`); rows run on ``workers`` processes
    (default: the CPU count). A query of one row (a floor to a ceiling) runs in this
    process, its cubatures' kernels on ``workers`` threads (:class:`Cubature`), so that it
    too uses the cores; the result does not depend on the workers. ``tol`` bounds the
    error estimate of each face pair (``tol_reached``: every entry's is within it,
    :func:`tol_reached`). Unless ``quiet``, a progress bar: the rows done, or the one
    row's points and its pair's estimate against its target (:func:`pair_bar`)."""
    faces_i = np.asarray(sorted({int(i) for i in faces_i}), np.int64)
    faces_j = np.asarray(sorted({int(j) for j in faces_j}), np.int64)
    row, _, val, err = group_entries(scene, faces_i, faces_j, side_i, tol, workers, reciprocal, quiet)
    area = scene.face_area[row // 2]
    a = float(scene.face_area[faces_i].sum())
    pairs = len(faces_i) * len(faces_j) - int(np.isin(faces_i, faces_j).sum())
    return {"F": float(np.sum(area * val)) / a, "error": float(np.sum(area * err)) / a, "pairs": int(pairs),
            "tol_reached": tol_reached(err, tol)}


def group_entries(scene, faces_i, faces_j, side_i=1, tol=DEFAULT_TOL, workers=None, reciprocal=True, quiet=True):
    """The entries F_(i,side_i)→(j,t) of a group query (:func:`group_to_group`), computed or
    derived: ``(rows, cols (m,) int64, values, errors (m,) float64)``, rows the elements
    ``2 i + (0 front, 1 back)`` of side ``side_i`` of the faces_i, cols those of both sides
    of the faces_j, j ≠ i; a progress bar unless ``quiet``."""
    from viscx.progress import bar

    faces_i, faces_j = np.asarray(faces_i, np.int64), np.asarray(faces_j, np.int64)
    rows = group_rows(scene, faces_i, side_i, faces_j, reciprocal)
    if len(rows) == 1:
        # one row (a floor to a ceiling): in this process, its pairs' cubatures on the cores
        # as threads (the same result on any number), refined to tol as one integral
        f, s, r, scale = rows[0]
        with bar(desc="form factors", quiet=quiet, unit="point") as progress:
            results = [emitter_row(scene, f, s, r, tol * scale, False, default_workers(workers), pair_bar(progress))]
    else:
        # the rows on processes, each row's pieces on threads holding the pool's core tokens:
        # the largest row (the desk top's underside → the floor) takes the cores the others
        # leave when they are done
        with bar(total=len(rows), desc="form factors", quiet=quiet, unit="row") as progress:
            results = _map_rows(emitter_row, scene, [row[:3] for row in rows], [tol * row[3] for row in rows], False,
                                workers, progress=lambda: progress.update(1), threads=True)
    row, col, val, err = row_entries(results, [2 * f + (0 if s > 0 else 1) for f, s, *_ in rows])
    if reciprocal:
        row, col, val, err = (np.concatenate(pair) for pair in zip((row, col, val, err),
                                                                      derived_entries(scene, row, col, val, err)))
    keep = (np.isin(row, 2 * faces_i + (0 if side_i > 0 else 1)) & np.isin(col // 2, faces_j)
            & (row // 2 != col // 2))
    return row[keep], col[keep], val[keep], err[keep]


def group_rows(scene, faces_i, side_i, faces_j, reciprocal=True):
    """The rows a group query computes: ``[(face, side, receivers (k,) int64, scale (k,)
    float64)]``, each face side once with every receiver it computes a pair with, in the
    order of the faces, and the factor of ``tol`` each pair needs.

    Two-sided, the rows are (i, side_i) → faces_j ∖ {i}, each pair to tol. With
    ``reciprocal``, a pair {i, j} is computed in the rows of the face :func:`computed_pairs`
    names: (i, side_i) → j where i is the smaller, else (j, +1) and (j, −1) → i, whose
    entries to side side_i of i give F_(i,side_i)→(j,t) = (A_j / A_i) F_(j,t)→(i,side_i)
    (:func:`derived_entries`). The query asks for F from the faces_i only, so a pair
    computed for its derived direction alone needs its estimate within tol · A_i / A_j
    (≥ tol): scaled by A_j / A_i, it is within tol (a desk panel's side to the floor, ~100
    times smaller, is refined to ~100 tol in its own F; the matrix, which needs both
    directions, computes every pair to tol). A face in both groups has its rows shared by
    the pairs it emits and those it is derived from, each pair to the smaller of its
    needs. Receivers a side cannot see or touch are left out (:func:`seen_receivers`), and
    the rows left with none."""
    faces_i, faces_j = np.asarray(faces_i, np.int64), np.asarray(faces_j, np.int64)
    area = scene.face_area
    wanted = {}  # (face, side) -> {receiver: factor of tol}

    def need(row, receiver, scale):
        got = wanted.setdefault(row, {})
        got[receiver] = min(got.get(receiver, np.inf), scale)

    for i in faces_i:
        others = faces_j[faces_j != i]
        mine = computed_pairs(scene, int(i), others) if reciprocal else np.ones(len(others), bool)
        for j in others[mine]:
            need((int(i), int(side_i)), int(j), 1.0)
        for j in others[~mine]:
            for t in SIDES:
                need((int(j), t), int(i), float(area[i] / area[j]))
    rows = []
    for (f, s) in sorted(wanted, key=lambda k: (k[0], -k[1])):
        receivers = np.asarray(sorted(wanted[f, s]), np.int64)
        seen = seen_receivers(scene, f, s, receivers)
        if len(seen):
            rows.append((f, s, seen, np.array([wanted[f, s][int(r)] for r in seen])))
    return rows


def seen_receivers(scene, face, side, faces):
    """(k,) int64, sorted: those of ``faces`` that side ``side`` of a face may see
    (:func:`facing_sides`) or touch (lying in its plane: :func:`coplanar_faces`); the rest
    have F = 0 from it."""
    faces = np.asarray(faces, np.int64)
    fj, _ = facing_sides(scene, face, side, faces)
    return faces[np.isin(faces, fj) | np.isin(faces, coplanar_faces(scene, face))]


def cell_contacts(scene, face, side, receivers=None, pairs=False):
    """:func:`contact_sides` of the :func:`cubature_cells` of a face side (those of a row to
    ``receivers``, default all, and for ``pairs``; cached)."""
    return scene.cached(_side_key("cell_contacts", face, side, receivers) + (" for pairs" if pairs else ""),
                        lambda s: contact_sides(s, face, side,
                                                cubature_cells(s, face, side, receivers=receivers, pairs=pairs)[0]))


def box_hidden(scene, face, side, faces, sides):
    """(k,) bool: for the sides ``sides`` (k,) int64 (+1 front, -1 back) of ``faces`` (k,)
    int64, whether they and side ``side`` of a face see nothing of each other because one
    of the two is the inner side (the back: a box's normals point out) of a face of a
    closed convex box (:func:`closed_boxes`, not an open one) and the other face lies
    outside that box: all of its vertices on or in front of one of the box's planes
    (within 1e-9 of the scene's size), and it is not a face of the box seen from inside.

    Why F is 0 then, exactly: a segment from a point x of the other face (outside the
    box's interior, or on its boundary) to a point y of the relative interior of face f
    seen from inside runs, just before y, in the box's interior. It entered the interior
    at a point z of the boundary before y, which lies on a face of the box: the segment is
    blocked there (z on an edge, or the segment grazing the boundary, is a set of measure
    zero). The one exception is x on the boundary with the segment going straight into
    the interior: x on a face g of the box emitting inwards (g's inner side, excluded
    above), or x on a face lying on g's outer side, which by the rule of faces lying on
    faces (docs/queries.md) sees only g's outer side there. Of office(300)'s 48,326
    facing pairs of sides, 39,279 are such (every box's inner sides seen from the room);
    the matrix had integrated them to noise within their estimates (up to 5.2e-6 at
    tol 1e-4)."""
    faces = np.asarray(faces, np.int64)
    sides = np.asarray(sides, np.int64)
    out = np.zeros(len(faces), bool)
    if not len(faces):
        return out
    face_box, ptr, planes = closed_boxes(scene)
    if len(ptr) < 2:
        return out
    closed = _closed_box_flags(scene)
    outline, lo, hi = face_outlines(scene)
    tiny = 1e-9 * scene.diagonal
    # the faces' inner sides seen from this face (outside their box)
    b = face_box[faces]
    ask = np.flatnonzero((b >= 0) & (sides < 0) & ~((face_box[face] == b) & (side < 0)))
    ask = ask[closed[b[ask]]]
    if len(ask):
        mine = outline[lo[face]:hi[face]]  # (v, 3)
        boxes, where = np.unique(b[ask], return_inverse=True)
        rows, first = _plane_ranges(ptr, boxes)
        h = mine @ planes[rows, :3].T - planes[rows, 3]  # (v, t)
        apart = np.logical_or.reduceat(np.all(h >= -tiny, axis=0), first)  # (boxes,)
        out[ask] = apart[where]
    # this face's inner side seeing the faces outside its box
    own = face_box[face]
    if own >= 0 and side < 0 and closed[own]:
        mine = planes[ptr[own]:ptr[own + 1]]
        h = outline @ mine[:, :3].T - mine[:, 3]  # (n, m)
        low = np.minimum.reduceat(h, lo, axis=0)[faces]  # (k, m) each face's lowest vertex
        out |= np.any(low >= -tiny, axis=1) & ~((b == own) & (sides < 0))
    return out


def facing_sides(scene, face, side, faces):
    """The sides of ``faces`` that side ``side`` of a face may see, by their vertices alone
    (vectorised): J has a vertex in front of the side's plane, and I one in front of the
    side of J's plane, and neither is the inner side of a closed box the other lies
    outside of (:func:`box_hidden`). ``(faces (k,), sides (k,))`` int64, each face once
    per side."""
    outline, lo, hi = face_outlines(scene)
    n_i = side * scene.face_normal[face]
    c_i = float(n_i @ scene.face_loops(face)[0][0])
    tiny = 1e-9 * scene.diagonal
    h = outline @ n_i - c_i
    ahead = np.maximum.reduceat(h, lo)[faces] > tiny
    mine = outline[lo[face]:hi[face]]
    d = mine @ scene.face_normal[faces].T - np.einsum("fj,fj->f", scene.face_normal[faces], outline[lo[faces]])
    out_f, out_s = [], []
    for t, ok in ((1, d.max(axis=0) > tiny), (-1, d.min(axis=0) < -tiny)):
        keep = faces[ahead & ok & (faces != face)]
        out_f.append(keep)
        out_s.append(np.full(len(keep), t, np.int64))
    f, s = np.concatenate(out_f), np.concatenate(out_s)
    keep = ~box_hidden(scene, face, side, f, s)
    f, s = f[keep], s[keep]
    order = np.lexsort([-s, f])
    return f[order], s[order]


# --------------------------------------------------------------------------------------
# rows in closed form: inner sides of empty closed boxes, sides lying wholly on others


def empty_boxes(scene):
    """(b,) bool: for each convex box (:func:`closed_boxes`), whether it is closed and nothing
    is inside it (an open box, one face missing, is never empty: its inner sides see out
    through the missing face, or, where a face covers that, :func:`box_caps`): no other face
    meets its open interior, and nothing lies on the inner side of one of its faces
    (:func:`_nothing_inside`). Cached."""

    def build(scene):
        face_box, ptr, planes = closed_boxes(scene)
        return np.array([not np.any(planes[ptr[b]:ptr[b + 1], 4] != 0.0) and _nothing_inside(scene, b)
                         for b in range(len(ptr) - 1)], bool)

    return scene.cached("empty_boxes", build)


def _nothing_inside(scene, b):
    """Whether no face but box b's own meets the open interior of the convex region bounded
    by all its planes (:func:`closed_boxes`, the missing face's of an open box included) and
    nothing lies on the inner side of one of its faces (docs/queries.md, "Faces lying on
    faces").

    A face meets the open interior when a part of positive area is left of it after
    clipping to every plane of the box moved inwards by 1e-9 of the scene's size (a
    polygon meeting an open set meets it in an open piece of itself). A face lies on the
    inner side of a box face g only if it is coplanar with g, overlaps it and has its
    normal on g's outward side (the smaller lies on the larger's front, so g's inner side
    can touch only a larger face whose front g's outer side faces): for those few, the
    matrix's own test decides (:func:`contact_cells` of g's inner side is empty)."""
    face_box, ptr, planes = closed_boxes(scene)
    tiny = 1e-9 * scene.diagonal
    box_lo, box_hi = face_boxes(scene)
    mine = np.flatnonzero(face_box == b)
    lo, hi = box_lo[mine].min(axis=0), box_hi[mine].max(axis=0)
    # faces whose boxes overlap the box's by more than tiny in every axis
    near = np.flatnonzero(np.all(box_lo < hi - tiny, axis=1) & np.all(box_hi > lo + tiny, axis=1))
    for k in near[face_box[near] != b]:
        loops = face_loops_oriented(scene)[1][k]
        for p in planes[ptr[b]:ptr[b + 1]]:
            loops = clip_loops(loops, -p[:3], -(p[3] - tiny))
            if not loops:
                break
        if loops and abs(loops_area(loops, scene.face_normal[k])) > tiny * tiny:
            return False
    for g in mine:
        same = coplanar_faces(scene, g)
        same = same[scene.face_normal[same] @ scene.face_normal[g] > 0]
        axes = np.abs(scene.face_normal[g]) < 0.5  # the box test in the plane's two widest axes
        overlap = np.all((box_lo[same] < box_hi[g] - tiny) | ~axes, axis=1) & np.all(
            (box_hi[same] > box_lo[g] + tiny) | ~axes, axis=1)
        if np.any(overlap) and len(contact_cells(scene, int(g), -1)[0]):
            return False
    return True


def box_caps(scene):
    """For each convex box (:func:`closed_boxes`): ``(g, t, loop)`` where it is an open box
    whose missing face M lies wholly on side t of one face g (a Cornell block standing on the
    floor: M is its footprint), no other face overlaps M in its plane, and nothing is inside
    (:func:`_nothing_inside`, M's plane included); else None. Cached.

    Such a box is closed by g: M ⊂ g, so the box's faces and M bound a convex polyhedron
    whose open interior no face meets, and a segment between the relative interiors of two
    of its faces runs inside it (:func:`closed_form_row`); the inner side of a box face sees
    the other faces' inner sides and side t of g over M (t the side facing into the box),
    nothing else. ``loop`` (k, 3) float64: M's outline, the box's own vertices in M's plane
    (the faces' edges along M share them exactly), counter-clockwise about t's normal.
    M ⊂ g is measured as area(g ∩ M) ≥ (1 − 1e-9) area(M), g's loops clipped to M's sides;
    another face overlaps M where more than 1e-9 of M's area is left of it so clipped.
    """

    def build(scene):
        face_box, ptr, planes = closed_boxes(scene)
        tiny = 1e-9 * scene.diagonal
        outline, lo, _ = face_outlines(scene)
        out = [None] * (len(ptr) - 1)
        for b in range(len(ptr) - 1):
            box = planes[ptr[b]:ptr[b + 1]]
            missing = box[:, 4] != 0.0
            if not np.any(missing):
                continue
            n_m, c_m = box[missing][0, :3], float(box[missing][0, 3])
            mine = np.flatnonzero(face_box == b)
            ids = np.unique(np.concatenate([scene.loop_vertices[scene.loop_offsets[scene.face_loop_offsets[f]]:
                                                                scene.loop_offsets[scene.face_loop_offsets[f] + 1]]
                                            for f in mine]))
            pts = scene.vertices[ids].astype(np.float64)
            pts = pts[np.abs(pts @ n_m - c_m) <= tiny]
            # M is convex (a face of a convex box): its vertices in angular order about its
            # centre, counter-clockwise about −n_m (the normal facing into the box)
            eu, ev = plane_basis(-n_m)
            d = pts - pts.mean(axis=0)
            loop = pts[np.argsort(np.arctan2(d @ ev, d @ eu), kind="stable")]
            area_m = loops_area([loop], -n_m)
            if len(loop) < 3 or area_m <= tiny * tiny:
                continue
            # the faces in M's plane, and what of each lies over M (clipped to M's sides)
            flat = np.maximum.reduceat(np.abs(outline @ n_m - c_m), lo) <= tiny
            flat[mine] = False
            sides = [(np.cross(-n_m, loop[(k + 1) % len(loop)] - loop[k])) for k in range(len(loop))]
            over = []
            for g in np.flatnonzero(flat):
                loops = oriented_loops(scene.face_loops(g), -n_m)
                for k, s in enumerate(sides):
                    s = s / np.linalg.norm(s)
                    loops = clip_loops(loops, s, float(s @ loop[k]))
                    if not loops:
                        break
                a = loops_area(loops, -n_m)
                if a > 1e-9 * area_m:  # not a sliver of rounding along a side
                    over.append((int(g), a))
            if len(over) != 1 or over[0][1] < (1 - 1e-9) * area_m or not _nothing_inside(scene, b):
                continue
            g = over[0][0]
            out[b] = (g, 1 if scene.face_normal[g] @ n_m < 0 else -1, loop)
        return out

    return scene.cached("box_caps", build)


def closed_form_row(scene, face, side, faces, sky=True):
    """The row of one face side where it has a closed form, else None; what
    :func:`emitter_row` returns (``method`` counts under ``closed``).

    * **Inside an empty closed box** (side −1 of a face of a box of :func:`empty_boxes`):
      the side sees the inner sides of the box's other faces and nothing else (a segment
      between the relative interiors of two faces of a convex polyhedron runs in its open
      interior, which no face meets), unoccluded: each F by the exact contour integral
      (:func:`contour_form_factor`), no sky. The row sums to 1 up to that integral's error.
      Likewise inside an open box closed by the face it stands on (:func:`box_caps`: a
      Cornell block on the floor), which it sees over the box's missing face only.
    * **Lying wholly on other faces**: the side's cells in contact (:func:`contact_cells`)
      cover it (a cabinet's bottom on the floor, its back on the wall, a desk panel's top
      under the desk top): each point sees the side it lies against with F = 1 and nothing
      else, so F to each such side is the area in contact with it over the face's, exactly.
      A rest of the face not covered, up to 1e-9 of its area, is the error estimate.
    """
    faces = np.asarray(faces, np.int64)
    none = 2 * len(faces) - 2 * int(np.isin(face, faces))  # the columns, the face's own left out
    area = float(scene.face_area[face])
    face_box = closed_boxes(scene)[0]
    b = face_box[face]
    cap = box_caps(scene)[b] if side == -1 and b >= 0 else None
    if side == -1 and b >= 0 and (empty_boxes(scene)[b] or cap is not None):
        n_i = -scene.face_normal[face]
        loops_i = oriented_loops(scene.face_loops(face), n_i)
        others = np.flatnonzero(face_box == b)
        others = others[(others != face) & np.isin(others, faces)]
        seen = [(2 * int(g) + 1, oriented_loops(scene.face_loops(g), -scene.face_normal[g]), -scene.face_normal[g])
                for g in others]
        if cap is not None and np.isin(cap[0], faces):
            g, t, loop = cap  # the face the open box stands on, over its missing face only
            seen.append((2 * g + (0 if t > 0 else 1), [loop], t * scene.face_normal[g]))
        seen.sort(key=lambda c: c[0])
        cols = np.array([c[0] for c in seen], np.int64)
        vals, errs = np.zeros(len(seen)), np.zeros(len(seen))
        for k, (_, loops, n_g) in enumerate(seen):
            vals[k], errs[k] = contour_form_factor(loops_i, n_i, loops, n_g)
        return cols, vals, errs, {"closed": len(seen), "none": none - len(seen)}, 0.0, 0.0
    cells, elements = contact_cells(scene, face, side)
    if not len(cells):
        return None
    cell_area = np.array([abs(_cell_area(c)) for c in cells])
    rest = max(area - float(cell_area.sum()), 0.0) / area
    if rest > 1e-9:
        return None
    cols = np.unique(elements)
    vals = np.bincount(np.searchsorted(cols, elements), weights=cell_area) / float(cell_area.sum())
    keep = np.isin(cols // 2, faces)
    cols, vals = cols[keep], vals[keep]
    return (cols.astype(np.int64), vals, np.full(len(cols), rest), {"closed": len(cols), "none": none - len(cols)}, 0.0,
            rest if sky else 0.0)


def emitter_row(scene, face, side, faces, tol, sky=True, threads=1, progress=None):
    """F from one side of a face to every side of ``faces`` it may see, and to the sky; a
    side with a closed form (:func:`closed_form_row`) takes it. ``tol``: the target on each
    pair's estimate, one for all or (k,) float64, one per face of ``faces`` (the sky
    takes the smallest). ``threads``: what each pair's cubature runs on
    (:func:`pair_form_factor`). ``progress``: ``progress(pair, pairs, points, ratio)``
    after each refinement round of each pair's cubature (the pair's number, how many,
    its points so far and its estimate over its target: a progress bar's,
    :func:`pair_bar`).

    Returns
    -------
    cols : (k,) int64
        Elements ``2 j + (0 front, 1 back)`` with a non-zero F.
    values, errors : (k,) float64
    counts : dict
        Pairs per method.
    sky, sky_error : float
    """
    sky = sky and may_see_sky(scene, face, side)
    closed = closed_form_row(scene, face, side, faces, sky)
    if closed is not None:
        return closed
    receivers = None if sky else faces  # cut along the kinks of these pairs only
    cells, _, kinked = cubature_cells(scene, face, side, receivers=receivers, pairs=True)
    contact = cell_contacts(scene, face, side, receivers, pairs=True)
    cols, vals, errs, counts = [], [], [], {}
    faces = np.asarray(faces, np.int64)
    tols = np.broadcast_to(np.asarray(tol, np.float64), faces.shape)
    fj, sj = facing_sides(scene, face, side, faces)
    # the sides it lies against (faces in its plane: not facing it, F = their common area)
    touched = np.unique(contact[contact >= 0])
    touched = touched[np.isin(touched // 2, faces)]
    fj, sj = np.concatenate([fj, touched // 2]), np.concatenate([sj, 1 - 2 * (touched % 2)])
    counts["none"] = 2 * len(faces) - len(fj) - 2 * int(face in set(faces.tolist()))
    boxes = sky_targets(scene) if sky else []
    pairs = len(fj) + len(boxes)
    for k, (j, t) in enumerate(zip(fj, sj)):
        r = pair_form_factor(scene, face, side, face_target(scene, int(j)), int(t), tol=float(tols[faces == j][0]),
                             cells=cells, contact=contact, kinked=kinked, threads=threads,
                             progress=_pair_progress(progress, k, pairs))
        counts[r.method] = counts.get(r.method, 0) + 1
        if r.method != "none" and r.F != 0.0:
            cols.append(2 * int(j) + (0 if t > 0 else 1))
            vals.append(r.F)
            errs.append(r.error)
    sky_v, sky_e = 0.0, 0.0
    if sky:
        for k, box in enumerate(boxes):
            r = pair_form_factor(scene, face, side, box, 1, tol=float(np.min(tols, initial=np.max(tol))), cells=cells,
                                 contact=contact, kinked=kinked, threads=threads,
                                 progress=_pair_progress(progress, len(fj) + k, pairs))
            counts["sky " + r.method] = counts.get("sky " + r.method, 0) + 1
            sky_v += r.F
            sky_e += r.error
    return np.asarray(cols, np.int64), np.asarray(vals, np.float64), np.asarray(errs, np.float64), counts, sky_v, sky_e


def estimate_ratio(total, budget):
    """What a cubature's ``progress`` is told: its summed estimate over its budget, the
    largest of its columns' (``total``, ``budget``: float or (R,) float64; inf where a
    budget is 0)."""
    total, budget = np.asarray(total, np.float64), np.asarray(budget, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.max(np.where(budget > 0, total / budget, np.inf)))


def _pair_progress(progress, pair, pairs):
    """A cubature's ``progress(points, ratio)`` for pair ``pair`` of ``pairs`` of a row's
    ``progress(pair, pairs, points, ratio)`` (None without one)."""
    return None if progress is None else functools.partial(progress, pair, pairs)


def pair_bar(bar):
    """A row's ``progress(pair, pairs, points, ratio)`` (:func:`emitter_row`) that counts
    the points evaluated on a progress bar (:func:`viscx.progress.bar`) and shows the pair
    and how far its estimate is from its target."""
    last = {}

    def progress(pair, pairs, points, ratio):
        bar.set_postfix_str(f"pair {pair + 1} of {pairs}: estimate {ratio:.3g} × its target")
        bar.update(points - last.get(pair, 0))
        last[pair] = points

    return progress


# --------------------------------------------------------------------------------------
# a whole row at once: every receiver from the same points


def scene_polygons(scene):
    """The faces as the flat arrays of :func:`viscx.geometry.occlusion.point_views`:
    ``(pts, loop_lo, loop_hi, loop_poly, normals, offsets, rank)`` (cached; rank: the order
    of the faces by area, the smallest first)."""

    def build(scene):
        polys = [(loops, scene.face_normal[f]) for f, loops in enumerate(face_loops_oriented(scene)[1])]
        loops = [(np.asarray(loop, np.float64), p) for p, (ls, _) in enumerate(polys) for loop in ls]
        sizes = np.array([len(l) for l, _ in loops], np.int64)
        hi = np.cumsum(sizes)
        normals = np.array([n for _, n in polys], np.float64)
        offsets = np.array([float(n @ ls[0][0]) for ls, n in polys])
        rank = np.empty(len(polys), np.int64)
        rank[np.argsort(scene.face_area, kind="stable")] = np.arange(len(polys))
        return (np.ascontiguousarray(np.concatenate([l for l, _ in loops])), (hi - sizes).astype(np.int64),
                hi.astype(np.int64), np.array([p for _, p in loops], np.int64), normals, offsets, rank)

    return scene.cached("formfactor_polygons", build)


def worst_leaves(err, total, over, budget, left=0.5):
    """(g,) bool: for each column in ``over`` (its summed estimate ``total`` above its
    ``budget``), its leaves with the largest estimates (``err`` (g, R)) until what is left
    of its estimate is ``left`` times its budget."""
    pick = np.zeros(len(err), bool)
    for c in over:
        order = np.argsort(-err[:, c], kind="stable")
        rest = total[c] - np.cumsum(err[order, c])
        pick[order[:int(np.searchsorted(-rest, -left * budget[c])) + 1]] = True
    return pick


def _degree2_weights(a):
    """Weights (7,) on Radon's nodes of the degree-2 rule on the centroid and the orbit
    (a, a, 1 − 2a) (the second moments: w₀/9 + w₁ Σ λ₁² = 1/6 with w₀ + 3 w₁ = 1)."""
    w1 = (1 / 18) / (2 * a * a + (1 - 2 * a) ** 2 - 1 / 3)
    out = np.zeros(7)
    out[0] = 1 - 3 * w1
    out[1:4] = w1 if a == _A else 0.0
    out[4:7] = w1 if a == _C else 0.0
    return out


#: Radon's rule minus the degree-2 rule on its centroid and its orbit near the edges'
#: midpoints: a null rule of degree 2 (it integrates every quadratic to 0). It is the only
#: one on these 7 nodes up to a factor (7 nodes, 6 quadratic monomials; the rule on the
#: other orbit gives −0.365 times it), so ``|values · NULL_RULE|`` is about the error of a
#: degree-2 rule (:class:`RowCubature`).
NULL_RULE = RULE_WEIGHTS - _degree2_weights(_C)


#: Triangles per piece of a :func:`row_rules` call at the least, and the pieces a larger
#: call is cut into at the most: what the threads of a row share
#: (``cubature.threads``). The pieces depend on the call only, never on the threads.
ROW_PIECE, ROW_PIECES = 16, 32

#: The row kernels' cores (:func:`_map_rows`): a semaphore, shared by the forked workers,
#: holding one token per worker process; each piece of :func:`row_rules` runs holding one.
#: None outside a pool.
_ROW_CORES = None


def row_core():
    """One of the pool's core tokens (:data:`_ROW_CORES`) while a kernel piece runs, or
    nothing outside a pool."""
    return _ROW_CORES if _ROW_CORES is not None else contextlib.nullcontext()


def row_rules(cubature, tri, width, weights, centres=None, centre_of=None, keep_centres=False):
    """Rules on Radon's 7 nodes of each triangle for a vector integrand, in pieces that bound
    the memory of one integrand call: ``(len(weights), g, R)`` float64, each ``weights``
    (7,) summed over the nodes and scaled by the area (``cubature.integrand(points, tri)``
    is called with the piece's triangles and the nodes not known, in their order: nodes
    7 k … 7 k + 6 in triangle k; ``cubature.evaluations`` counts the points).

    The first node is the centroid, which a triangle's middle child (the last of
    :func:`split4`) shares with it: where ``centre_of`` (g,) int64 is ≥ 0, the integrand at
    triangle k's centroid is ``centres[centre_of[k]]`` (R,), not evaluated again. With
    ``keep_centres``, also returns the integrand at every centroid, ``(g, R)`` float64.

    The pieces run on ``cubature.threads`` threads (:func:`viscx.parallel.map_chunks`; the
    integrand must be thread-safe and release the GIL: ``point_views`` is ``nogil``), so
    that a large row (the office's floor) uses the cores the other rows leave idle. Each
    piece writes its own triangles' slice and its values do not depend on the other
    pieces: the result is the same, bit for bit, on any number of threads. In a pool of
    row processes (:func:`_map_rows`), a piece runs holding one of the pool's core tokens
    (:data:`_ROW_CORES`), so that the kernels of all the rows together keep as many cores
    busy as there are workers, no more: a row's threads get the cores when the other rows
    are done."""
    from viscx.parallel import map_chunks, row_chunks

    out = np.zeros((len(weights), len(tri), width))
    kept = np.zeros((len(tri), width)) if keep_centres else None
    area = triangle_areas(tri)
    chunk = max(1, min(CHUNK, 4_000_000 // (7 * max(width, 1)), max(ROW_PIECE, -(-len(tri) // ROW_PIECES))))

    def piece(s):
        part = tri[s]
        pts = np.einsum("rk,gkd->grd", RULE_NODES, part)
        need = np.ones((len(part), 7), bool)
        if centre_of is not None:
            known = centre_of[s] >= 0
            need[known, 0] = False
        values = np.empty((len(part), 7, width))
        with row_core():
            values[need] = cubature.integrand(np.ascontiguousarray(pts[need]), part)
        if centre_of is not None:
            values[known, 0] = centres[centre_of[s][known]]
        for k, w in enumerate(weights):
            out[k, s] = np.einsum("grc,r->gc", values, w) * area[s, None]
        if keep_centres:
            kept[s] = values[:, 0]
        return int(need.sum())

    cubature.evaluations += sum(map_chunks(piece, row_chunks(len(tri), chunk), getattr(cubature, "threads", 1)))
    return (out, kept) if keep_centres else out


#: A triangle's rules "see nothing" of a column where the sum of their absolute values
#: (and estimates) is at most this times its area (the integrands lie in [0, 1]).
UNSEEN = 1e-10


def levels_seen(q, kq, gq):
    """(g,) or (g, R) float64: what the 21 rules of each triangle's three levels see of the
    integrand (q (g[, R]), kq (g, 4[, R]), gq (g, 16[, R])): the sum of their absolute
    values, to compare with :data:`UNSEEN` times its area."""
    return np.abs(q) + np.abs(kq).sum(axis=1) + np.abs(gq).sum(axis=1)


def look_for_shadows(tri, seen, live, bound=None):
    """Where a small shadow may lie between the nodes of the first triangles (g, 3, 3): a
    column an occluder may hide on a triangle (``live``, its shaft test) whose nodes see
    nothing of it (``seen`` (g, R): what the rules and their estimates say, ≤ 1e-10 × the
    triangle's area: :func:`blind_columns`). Such a triangle is replaced by its 4 children,
    and each child whose shaft still meets an occluder of such a column by its own 4
    children (:func:`shadow_triangles`), but for the columns ``bound(tri, blind, seen) ->
    blind, spent`` settles by an upper bound (:func:`unseen_shadow_bound`). ``live(tri,
    need) -> (g, R) bool`` is asked only where ``need`` is set.

    Returns
    -------
    unseen : (g,) bool
        The triangles replaced.
    new : (h, 3, 3) float64
        What replaces them (the children, then the grandchildren).
    whole : (m,) int64
        The children kept whole (``new[:m]``), as positions among the replaced triangles'
        children (child ``k`` is ``split4``'s child ``k % 4`` of the ``k // 4``-th).
    spent : (R,) float64
        The bounds taken as the columns' estimates instead (0 without ``bound``).
    """
    blind = blind_columns(tri, seen, live)
    blind, spent = (blind, np.zeros(seen.shape[1])) if bound is None else bound(tri, blind, seen)
    return (*shadow_triangles(tri, blind, live), spent)


def blind_columns(tri, seen, live):
    """(g, R) bool: the columns an occluder may hide on each triangle (g, 3, 3) (``live``,
    its shaft test, asked only where the nodes see nothing) whose nodes see nothing of them
    (``seen`` (g, R) ≤ :data:`UNSEEN` × the triangle's area)."""
    blind = seen <= UNSEEN * triangle_areas(tri)[:, None]
    ask = np.flatnonzero(np.any(blind, axis=1))  # the shaft tests only where they matter
    blind[ask] &= live(tri[ask], blind[ask])
    return blind


def shadow_triangles(tri, blind, live):
    """The triangles (g, 3, 3) with a ``blind`` (g, R) column replaced by their 4 children,
    and each child whose shaft still meets an occluder of such a column by its own 4
    children (the node density four times finer where the shadow may be; on the other
    children the column is exactly 0): ``unseen`` (g,) bool, the triangles replaced,
    ``new`` (h, 3, 3), what replaces them, and ``whole`` (m,) int64, the children kept
    whole (:func:`look_for_shadows`)."""
    unseen = np.any(blind, axis=1)
    if not np.any(unseen):
        return unseen, np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    kids = split4(tri[unseen]).reshape(-1, 3, 3)
    need = np.repeat(blind[unseen], 4, axis=0)
    deeper = np.any(live(kids, need) & need, axis=1)
    return unseen, np.concatenate([kids[~deeper], split4(kids[deeper]).reshape(-1, 3, 3)]), np.flatnonzero(~deeper)


#: Pieces beyond which the first triangles that see J' wholly hidden at their nodes are not
#: cut along the pair's critical lines (:func:`cut_hidden`).
MAX_GAP_PIECES = 1_000


def cut_hidden(scene, n_i, tri, hidden, lines, sees):
    """The first triangles (g, 3, 3) of an emitter (normal ``n_i``) from whose nodes a
    receiver is wholly hidden (``hidden`` (g,) bool, :meth:`PairSetup.hidden_at_nodes`),
    cut along the critical lines ``lines`` (s, 2, 3) of the pair (:meth:`PairSetup.gap_lines`)
    where it is seen from a piece: ``(replaced (g,) bool, new (h, 3, 3))``.

    The receiver may yet be seen through a gap between the nodes (office(300): desk5's
    3 cm panel end sees cabinet3's front over desk4's top only from a band 7 mm wide
    along its top edge, and its first triangles' nodes lie 17 mm and more from it).
    Where J' is seen from one point of a triangle and not from another, the segments to
    J' change their occluders, and the edges of where they do are the pair's critical
    lines (there, the line where desk4's top edge and J's top edge line up), or curves
    where three edges line up, across which F is C1 and whose seen part, as it opens,
    grows like the cube of the distance. So a triangle is cut along every line crossing
    it, and where J' is seen from the centre of a piece (``sees(points (m, 3)) -> (m,)``,
    F to the seen part of J', above :data:`UNSEEN`) it is replaced by pieces in which the
    region of the seen pieces has its own (cut along that region's outline,
    :meth:`GapSearch.bounding`), fanned into triangles (each then on three levels, with
    nodes of its own); elsewhere, as where no line crosses it, J' is taken as hidden on
    the whole triangle, as its nodes say. Where the lines are too many to list (``lines`` None) or
    cut the triangles into more than :data:`MAX_GAP_PIECES` pieces, nothing is replaced
    (docs/queries.md, "Not done yet")."""
    search = GapSearch.start(scene, n_i, tri, hidden, lines)
    if search is None:
        return np.zeros(len(tri), bool), np.zeros((0, 3, 3))
    return search.cells(search.bounding(sees(search.points) > UNSEEN))


def _in_plane(origin, eu, ev, uv):
    """(m, 3) float64: the points ``origin + u eu + v ev`` of ``uv`` (m, 2) (:class:`GapSearch`'s plane)."""
    return origin + uv[:, :1] * eu + uv[:, 1:] * ev


def _counter_clockwise(corners):
    """2-D triangles (r, 3, 2) float64, each turned counter-clockwise (in place)."""
    c = corners
    flip = c[:, 0, 0] * (c[:, 1, 1] - c[:, 2, 1]) + c[:, 1, 0] * (c[:, 2, 1] - c[:, 0, 1]) + c[:, 2, 0] * (
        c[:, 0, 1] - c[:, 1, 1]) <= 0
    c[flip] = c[flip, ::-1]
    return c


@dataclass
class GapSearch:
    """The pieces of :func:`cut_hidden`: the triangles wholly hidden at their nodes, in 2-D
    (the emitter's plane, ``origin + u eu + v ev``), cut along the lines crossing them, and
    the centres of the pieces to ask. A matrix row asks every column's at once
    (:func:`row_gaps`)."""

    tri: np.ndarray  # (g, 3, 3) the first triangles
    origin: np.ndarray  # (3,)
    eu: np.ndarray  # (3,)
    ev: np.ndarray  # (3,)
    eps: float
    rows: np.ndarray  # (r,) the triangles cut
    seg: np.ndarray  # (s, 2, 2) the lines crossing them
    verts: np.ndarray  # the pieces (:mod:`viscx.geometry.arrangement`)
    ptr: np.ndarray
    owner: np.ndarray  # (N,) each piece's triangle, a position in rows
    ask: np.ndarray  # (a,) the pieces of the triangles cut in two or more
    points: np.ndarray  # (a, 3) their centres

    @classmethod
    def start(cls, scene, n_i, tri, hidden, lines):
        """The search on the triangles ``hidden`` (g,) bool of ``tri`` (g, 3, 3), along the
        lines (s, 2, 3); None where nothing is to be asked (no line crosses them, or the
        pieces would be more than :data:`MAX_GAP_PIECES`)."""
        if lines is None or not len(lines) or not np.any(hidden):
            return None
        eu, ev = plane_basis(n_i)
        origin = tri[0, 0]
        eps = 1e-8 * scene.diagonal

        def to2(p):
            return np.stack([(p - origin) @ eu, (p - origin) @ ev], axis=-1)

        seg = to2(lines)
        crossing = segments_crossing(np.ascontiguousarray(seg), np.ascontiguousarray(to2(tri[hidden])), eps)
        rows = np.flatnonzero(hidden)[crossing.any(axis=0)]
        if not len(rows):
            return None
        corners = _counter_clockwise(to2(tri[rows]))
        seg = seg[crossing.any(axis=1)]
        verts, ptr, owner = cut_flat(corners.reshape(-1, 2), np.arange(0, 3 * len(rows) + 1, 3), seg, eps,
                                     MAX_GAP_PIECES + len(rows))
        if verts is None or len(owner) == len(rows):
            return None
        ask = np.flatnonzero((np.bincount(owner, minlength=len(rows)) > 1)[owner])
        centre = piece_centres(verts, ptr)[ask]
        points = _in_plane(origin, eu, ev, centre)
        return cls(tri, origin, eu, ev, eps, rows, seg, verts, ptr, owner, ask, points)

    def bounding(self, lit):
        """Where the target is seen from the centres ``lit`` (a,) bool of the pieces asked:
        ``{triangle: (b, 2, 2)}``, the triangles to replace and the outline of the region
        their seen pieces make (the edges of a seen piece with no seen piece across them).
        A triangle cut along these segments keeps that region in pieces of its own and the
        rest in few (cut along the whole lines, the seen band of office(300)'s wall 16
        behind a desk took 424 triangles, every one then on three levels)."""
        lit = self.ask[lit]
        out = {}
        for r in np.unique(self.owner[lit]):
            mine = lit[self.owner[lit] == r]
            idx = np.concatenate([np.arange(self.ptr[k], self.ptr[k + 1]) for k in mine])
            nxt = np.concatenate([np.roll(np.arange(self.ptr[k], self.ptr[k + 1]), -1) for k in mine])
            a, b = self.verts[idx], self.verts[nxt]  # (e, 2) each, the pieces counter-clockwise
            d = b - a
            outward = np.stack([d[:, 1], -d[:, 0]], axis=1) / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
            probe = 0.5 * (a + b) + 10 * self.eps * outward  # just across each edge
            across = np.zeros(len(probe), bool)
            for k in mine:
                p = self.verts[self.ptr[k]:self.ptr[k + 1]]
                e = np.roll(p, -1, axis=0) - p
                rel = probe[:, None, :] - p[None]
                across |= np.all(e[None, :, 0] * rel[..., 1] - e[None, :, 1] * rel[..., 0] > 0, axis=1)
            out[int(self.rows[r])] = np.stack([a, b], axis=1)[~across]
        return out

    def lit_triangles(self, lit):
        """(h, 3, 3): the pieces asked whose centres see the target (``lit`` (a,) bool),
        fanned into triangles."""
        pieces = self.ask[lit]
        flat = _in_plane(self.origin, self.eu, self.ev, self.verts)
        return start_triangles([flat[self.ptr[k]:self.ptr[k + 1]] for k in pieces], 0.0)

    def cells(self, lines):
        """``(replaced (g,) bool, new (h, 3, 3))``: the triangles ``lines`` names, each cut
        along its lines ``{triangle: (b, 2, 2)}`` (:meth:`bounding`'s; a row's, of all its
        columns' searches on the same triangles, :func:`row_gaps`), fanned into triangles."""
        replaced = np.zeros(len(self.tri), bool)
        if not lines:
            return replaced, np.zeros((0, 3, 3))
        rows = np.array(sorted(lines), np.int64)
        replaced[rows] = True
        rel = self.tri[rows] - self.origin
        corners = _counter_clockwise(np.stack([rel @ self.eu, rel @ self.ev], axis=-1))  # (r, 3, 2)
        cells = []
        for corner, r in zip(corners, rows):
            verts, ptr, _ = cut_flat(corner, np.array([0, 3]), lines[r], self.eps)
            flat = _in_plane(self.origin, self.eu, self.ev, verts)
            cells += [flat[ptr[k]:ptr[k + 1]] for k in range(len(ptr) - 1)]
        return replaced, start_triangles(cells, 0.0)


def row_gaps(scene, n_i, tri, q, kq, gq, shafts, budget):
    """:meth:`PairSetup.gaps` for every column of a three-level matrix row: the first
    triangles (g, 3, 3) (their rules ``q`` (g, R), ``kq`` (g, 4, R), ``gq`` (g, 16, R))
    from whose nodes a pair's receiver may be seen through a gap
    (:meth:`PairSetup.gap_candidates`), cut along the pair's critical lines crossing them
    (:meth:`PairSetup.gap_lines`, :class:`GapSearch`), the centres of the pieces asked
    with the pair's kernel (:meth:`PairSetup.f`). Each triangle where some column is seen
    from a piece is cut along the outlines of such pieces, all its columns' together.

    A column seen from some pieces is settled by a bound instead where it is small: its
    rules there count J' as hidden at every point, so they are off by what is seen of it
    from the pieces whose centres see it (between the lines J' is seen from all of a piece
    or none of it, but across curves where three edges line up, beyond which the seen
    part grows like the cube of the distance: :func:`cut_hidden`), at most ∫ F(x → J') dx
    over those pieces (:meth:`GapSearch.lit_triangles`; the contour integral of their
    parts in front of J, :func:`front_unoccluded`); where that is at most
    :data:`GAP_BOUND` of the column's ``budget`` (R,) (in ∫ units, what the shadow
    search left), it is the column's estimate there and its triangles are not cut for it,
    unless another column's cuts them anyway (office(300) at 1e-4: the row of desk3's
    panel end (face 129) settles its two such columns, bounds of 7.9e-9 and 2.1e-7 against
    budgets of 4.8e-5 (in ∫ units), in 1,704 points; cut, it took 5,112. The band of
    desk5's panel end (face 164) → cabinet3's front is not settled, its bound 2.1e-6 against
    a budget of 2.1e-6, and is found as before: 2.2083081e-6 ± 7.5e-11).

    ``shafts``: the row's pairs, ``(setup, column)``. Returns ``(replaced (g,) bool, new
    (h, 3, 3), spent (R,))``: as :meth:`PairSetup.gaps`, and the bounds taken as the
    columns' estimates."""
    area = triangle_areas(tri)
    seen = levels_seen(q, kq, gq)
    spent = np.zeros(len(budget))
    lines, search, lit_columns = {}, None, []
    for setup, c in shafts:
        rows = np.flatnonzero(seen[:, c] > UNSEEN * area)
        if not len(rows):
            continue
        rows = rows[setup.gap_candidates(tri[rows], np.concatenate([q[rows, None, c], kq[rows, :, c], gq[rows, :, c]],
                                                                   axis=1))]
        if not len(rows):
            continue
        hidden = np.zeros(len(tri), bool)
        hidden[rows] = True
        found = GapSearch.start(scene, n_i, tri, hidden, setup.gap_lines(tri[rows]))
        if found is None:
            continue
        lit = setup.f(found.points) > UNSEEN
        outlines = found.bounding(lit)
        if outlines:
            search = found
            lit_columns.append((c, outlines, sum(front_unoccluded(setup, found.lit_triangles(lit)))))
    # the triangles cut: those of the columns a bound does not settle, each along the
    # outlines of all the columns seen from its pieces (a column settled on some other
    # triangle keeps its bound for all of them)
    cut = {r for c, outlines, bound in lit_columns if bound > GAP_BOUND * budget[c] for r in outlines}
    for c, outlines, bound in lit_columns:
        if bound <= GAP_BOUND * budget[c] and not cut.issuperset(outlines):
            spent[c] += bound
            continue
        for r, seg in outlines.items():
            lines.setdefault(r, []).append(seg)
    if not lines:
        return np.zeros(len(tri), bool), np.zeros((0, 3, 3)), spent
    return (*search.cells({r: np.concatenate(seg) for r, seg in lines.items()}), spent)


#: The share of a column's budget that an upper bound of its unseen shadows may take, where
#: it settles them, instead of looking for them (:func:`unseen_shadow_bound`).
SHADOW_BOUND = 0.25
#: The share of a column's budget (what the shadow search left) that a bound of what is
#: seen of it through gaps may take, where it settles them, instead of cutting the
#: triangles along them (:func:`row_gaps`).
GAP_BOUND = 0.25


def front_unoccluded(setup, tri):
    """∫ F(x → J') dx over the parts of the triangles (g, 3, 3) of the emitter's plane in
    front of J (where the pair's I' is: ``n_t · y ≥ c_t + tiny``; F(x → J') is 0 behind):
    the contour integral of those parts (:meth:`PairSetup.unoccluded_integral`, exact),
    ``(value, error)`` in area × F."""
    front = [part for t in tri for part in clip_loops([t], setup.n_t, setup.c_t + setup.tiny)]
    return setup.unoccluded_integral(start_triangles(front, 0.0)) if front else (0.0, 0.0)


def unseen_shadow_bound(scene, shafts, f0, e0, area, budget):
    """``bound(tri, blind, seen) -> blind, spent`` for the row cubatures' shadow search:
    where a column's nodes on a first triangle see nothing of it but an occluder meets the
    triangle's shaft to it (``blind`` (g, R) bool, :func:`blind_columns`), the hidden part
    there lies between 0 and the unoccluded integrand F(x → J') ≥ 0, so the rules' value
    (``seen`` (g, R): ≤ 1e-10 of the area) is off by at most ``seen`` plus ∫ F(x → J') over
    those triangles. That integral is at most the whole pair's, ``(F⁰ + its error) × A_i``
    (``f0``, ``e0`` (R,) in F, ``area`` A_i), and at most Σ area(T) min(1, A_J / (π d²)) with
    d the distance between the boxes of T and J (F(x → J) = (1/π) ∫_J cos cos / r² ≤
    A_J / (π d²)); where neither is small enough, it is the contour integral over the
    triangles' parts in front of J (:meth:`PairSetup.unoccluded_integral`, exact). Where the
    bound is at most :data:`SHADOW_BOUND` of the column's ``budget`` (R,) (in ∫ units), it
    is the column's estimate there (``spent`` (R,)) and its triangles are not split for it:
    a far or small receiver (a desk panel across the room) is settled where the shadow
    search (16 grandchildren on their own three levels each) would cost most.
    ``shafts``: (:class:`PairSetup`, column c) of the columns searched."""
    box_lo, box_hi = face_boxes(scene)

    def bound(tri, blind, seen):
        blind = blind.copy()
        spent = np.zeros(blind.shape[1])
        lo, hi = tri.min(axis=1), tri.max(axis=1)
        a = triangle_areas(tri)
        for setup, c in shafts:
            rows = np.flatnonzero(blind[:, c])
            if not len(rows):
                continue
            j, there = setup.face_t, float(seen[rows, c].sum())
            allowed = SHADOW_BOUND * budget[c] - there
            gap = np.maximum(0.0, np.maximum(box_lo[j] - hi[rows], lo[rows] - box_hi[j]))
            with np.errstate(divide="ignore"):
                near = a[rows] * np.minimum(1.0, scene.face_area[j] / (np.pi * np.einsum("ij,ij->i", gap, gap)))
            b = min((f0[c] + e0[c]) * area, float(near.sum()))
            if b > allowed:
                b = sum(front_unoccluded(setup, tri[rows]))
            if b <= allowed:
                blind[rows, c] = False
                spent[c] = b + there
        return blind, spent

    return bound


#: What :class:`RowCubature` and :class:`Cubature` leave of a column's estimate unrefined
#: in a round, as a fraction of its budget: a refined leaf's estimate mostly goes (a leaf
#: on its rule trades its null rule, about a degree-2 rule's error, for |Q − S|, about
#: its degree-5 rule's; a split leaf of the three levels its estimate for its children's,
#: ~1/4 of it across a kink), so the round stops just under the budget rather than at half
#: of it (which split more leaves than the budget needed: the office's floor → ceiling at
#: 1e-4, 248,878 points at half, 202,734 at 0.9).
REFINE_LEFT = 0.9


class RowCubature:
    """Adaptive cubature of a vector integrand (one value per receiver column at each point,
    each column with its own budget) over triangles on which every column is C1: the
    triangles of the emitter's cells cut along the contact (D0) and kink (D1) lines
    (:func:`emitter_cells` with ``kinks``), so that what is left inside them is smooth up to
    the D2 traces, across which the integrands' second derivatives jump.

    A leaf T is on one of two levels:

    * **its rule only** (7 points): the value is Radon's degree-5 rule Q, the estimate the
      difference of Q from a degree-2 rule on four of its nodes (:data:`NULL_RULE`), about
      the error of a degree-2 rule: O(h³) against Q's O(h⁶) where the integrand is smooth
      and O(h⁴) where a D2 trace crosses T;
    * **with its four midpoint children** (28 more points): the value is their sum S,
      the estimate ``|Q − S|``. Halving the triangles divides the rule's error along a
      D2 trace by ~8 and elsewhere by ~64, so S's error is ≤ 1/7 of ``|Q − S|``
      (= |(I − Q) − (I − S)|) wherever the rule is in its asymptotic regime.

    Both are honest only where no kink line crosses T: a kink (D1) can clip a corner of T
    between the nodes of every level, which then agree while all are off (the reason for
    the three levels of :class:`Cubature`, whose cells are not cut along kinks); here no
    kink line crosses a leaf. A feature smaller than the nodes' spacing (a small shadow
    lying between them) is what the first split guards against (:func:`start_triangles`),
    and where the columns' shaft tests say an occluder may hide a column on a first
    triangle whose nodes see nothing of it, that triangle starts at its children, and
    those whose shafts still meet such an occluder at their own children (the node
    density of three levels, there only; :meth:`_look_for_shadows`), unless an upper
    bound of what it may hide there is within a quarter of the column's budget
    (:func:`unseen_shadow_bound`: the bound is then its estimate there). A triangle the
    search or a refinement makes whose nodes still see nothing of a column while its
    shaft meets an occluder is *blind* there: its rule's 0 may miss a shadow between all
    its nodes (a window sill's top beside the wall's end, which hides the light from a
    wedge whose apex is the sill's corner: at every size the corner's triangle has no
    node in it), so it carries ``blind_bound``'s upper bound of what may be hidden there
    as its estimate (nothing refines a leaf whose estimate is 0), until the bounds are
    within the budget.

    While some column's summed estimate exceeds its budget, that column's leaves with the
    largest estimates are refined (until what is left is :data:`REFINE_LEFT` of its
    budget): a leaf on its rule only gets its children evaluated; a leaf with its children
    is replaced by them, each on its rule only (nothing evaluated: their rules and null
    rules are known). A point is evaluated once for all receivers.

    Parameters
    ----------
    integrand : callable
        ``integrand(points (m, 3), tri (g, 3, 3)) -> (m, R) float64``, the points the nodes of
        the triangles (:func:`row_rules`).
    threads : int
        Threads the integrand's calls run on (:func:`row_rules`; the result does not
        depend on them).
    progress : callable, optional
        As :class:`Cubature`'s, the ratio the largest of the columns'.
    """

    def __init__(self, integrand, threads=1, progress=None):
        self.integrand = integrand
        self.evaluations = 0
        self.threads = threads
        self.progress = progress

    def rule(self, tri, width):
        """Radon's rule on each triangle and its null-rule estimate: ``q, e`` (g, R) float64."""
        q, e = row_rules(self, tri, width, (RULE_WEIGHTS, NULL_RULE))
        return q, np.abs(e)

    def integrate(self, tri, budget, live=None, bound=None, blind_bound=None):
        """∫ over the triangles (g, 3, 3) of every column (:func:`start_triangles`);
        ``budget`` (R,) the targets on the columns' estimates; ``live(tri, need) -> (g, R)
        bool``, where an occluder may hide the column (its shaft test), asked only where
        ``need`` (g, R) bool is set (elsewhere it may say anything); ``bound(tri, blind,
        seen) -> blind, spent``, the columns whose unseen shadows an upper bound settles
        (:func:`unseen_shadow_bound`); ``blind_bound(tri) -> (g, R)``, upper bounds of
        each column's integral over the triangles, for the blind leaves (without it they
        count as their rules say). Returns ``value,
        error`` (R,) and the triangles evaluated."""
        width = len(budget)
        q, e = self.rule(tri, width)
        spent = np.zeros(width)
        b = np.zeros((len(tri), width))  # each leaf's blind bound (0: not blind)
        if live is not None:
            tri, q, e, b, spent = self._look_for_shadows(tri, q, e, live, width, bound, blind_bound)
            budget = budget - spent
        # leaves with their children: K (4 per leaf), kq, ke, kb; -1 in kid_of where not evaluated
        K, kq, ke, kb = np.zeros((0, 3, 3)), np.zeros((0, width)), np.zeros((0, width)), np.zeros((0, width))
        kid_of = np.full(len(tri), -1, np.int64)
        cells = len(tri)
        for _ in range(400):
            value, err = self._leaves(q, e, b, kid_of, kq, kb)
            total = err.sum(axis=0)
            over = np.flatnonzero(total > budget)
            if self.progress is not None:
                self.progress(self.evaluations, estimate_ratio(total, budget))
            if not len(over) or cells >= MAX_CELLS or not len(tri):
                break
            pick = worst_leaves(err, total, over, budget, REFINE_LEFT)
            deep = kid_of >= 0
            # leaves on their rule only: evaluate their children
            grow = np.flatnonzero(pick & ~deep)
            new_K = split4(tri[grow]).reshape(-1, 3, 3)
            new_kq, new_ke = self.rule(new_K, width)
            new_kb = self._blind(new_K, new_kq, new_ke, live, blind_bound)
            cells += len(new_K)
            kid_of[grow] = len(K) // 4 + np.arange(len(grow))
            K, kq, ke = np.concatenate([K, new_K]), np.concatenate([kq, new_kq]), np.concatenate([ke, new_ke])
            kb = np.concatenate([kb, new_kb])
            # leaves with their children: replaced by them
            split = pick & deep
            if np.any(split):
                rows = child_rows(kid_of[split])
                # the children share their parent's estimate |Q − S| (which bounds the error
                # of S, the sum of their rules) in proportion to their null rules: the total
                # stays what it was, and the next round deepens the children that carry most
                share = ke[rows].reshape(-1, 4, width) + 1e-300
                parent = np.abs(q[split] - kq[rows].reshape(-1, 4, width).sum(axis=1))
                kid_e = (share / share.sum(axis=1, keepdims=True) * parent[:, None, :]).reshape(-1, width)
                keep = ~split
                tri = np.concatenate([tri[keep], K[rows]])
                q, e = np.concatenate([q[keep], kq[rows]]), np.concatenate([e[keep], kid_e])
                b = np.concatenate([b[keep], kb[rows]])
                kid_of = np.concatenate([kid_of[keep], np.full(len(rows), -1, np.int64)])
                # drop the children no leaf refers to any more (bounded memory)
                held = np.flatnonzero(kid_of >= 0)
                idx = child_rows(kid_of[held])
                K, kq, ke, kb = K[idx], kq[idx], ke[idx], kb[idx]
                kid_of[held] = np.arange(len(held))
        value, err = self._leaves(q, e, b, kid_of, kq, kb)
        return value.sum(axis=0), err.sum(axis=0) + spent, cells

    def _look_for_shadows(self, tri, q, e, live, width, bound=None, blind_bound=None):
        """:func:`look_for_shadows` on the first triangles, whose rules and null rules are
        ``q, e`` (g, R): the new triangles on their rules. Returns the new ``tri, q, e``,
        their blind bounds (:meth:`_blind`) and the bounds spent (R,)."""
        unseen, new, _, spent = look_for_shadows(tri, np.abs(q) + e, live, bound)
        if not len(new):
            return tri, q, e, np.zeros(q.shape), spent
        nq, ne = self.rule(new, width)
        nb = self._blind(new, nq, ne, live, blind_bound)
        return (np.concatenate([tri[~unseen], new]), np.concatenate([q[~unseen], nq]),
                np.concatenate([e[~unseen], ne]), np.concatenate([np.zeros(((~unseen).sum(), width)), nb]), spent)

    @staticmethod
    def _blind(tri, q, e, live, blind_bound):
        """(g, R) float64: the blind bounds of triangles (g, 3, 3) on their rules ``q, e``:
        where their nodes see nothing of a column (:func:`blind_columns`) while an occluder
        meets their shaft to it (``live``), ``blind_bound``'s bound; else 0."""
        out = np.zeros(q.shape)
        if blind_bound is None or live is None:
            return out
        blind = blind_columns(tri, np.abs(q) + e, live)
        rows = np.flatnonzero(np.any(blind, axis=1))  # the bound only where it is taken
        if len(rows):
            out[rows] = np.where(blind[rows], blind_bound(tri[rows]), 0.0)
        return out

    @staticmethod
    def _leaves(q, e, b, kid_of, kq, kb):
        """Each leaf's value and estimate (g, R): S and |Q − S| plus its blind children's
        bounds where its children are known, else Q and its null-rule estimate plus its
        own blind bound (``b``, ``kb``: :meth:`_blind`)."""
        value, err = q.copy(), e + b
        deep = np.flatnonzero(kid_of >= 0)
        if len(deep):
            s = kq.reshape(-1, 4, q.shape[1])[kid_of[deep]].sum(axis=1)
            value[deep] = s
            err[deep] = np.abs(q[deep] - s) + kb.reshape(-1, 4, q.shape[1])[kid_of[deep]].sum(axis=1)
        return value, err


class ThreeLevelRowCubature:
    """The adaptive cubature of :class:`Cubature` for a vector integrand, for the rows whose
    kink lines are too many to cut the emitter along (:data:`MAX_KINK_CELLS`): its cells
    are not cut along kinks, so the estimate needs the three levels (:class:`RowCubature`
    explains why): one value per receiver column at each point, each column with its own
    budget. Every triangle is
    evaluated on the same three levels (its rule, 4 children, 16 grandchildren); a column's
    estimate is the sum of its triangles' estimates, on the kink model
    (:func:`kinked_three_level_error`: a kink line may cross any triangle here, so the
    smooth model's ``|Q − K| / 64`` of :class:`Cubature` is too optimistic where K and G
    agree by chance), and while some column's exceeds its budget, that column's triangles with the
    largest estimates are split (until what is left is half its budget). A point is
    evaluated once for all receivers.

    A shadow smaller than the grandchildren's nodes' spacing may fall between all 147 nodes
    of a first triangle, and its three levels then agree on nothing seen (office(100), a
    desk side's row at 1e-4: an entry 4.2e-8 off for an estimate of 2.9e-14): the first
    triangles go through the shadow search of :class:`RowCubature` (:func:`blind_columns`,
    :func:`unseen_shadow_bound`, :func:`shadow_triangles`), each new triangle on its own
    three levels (a child kept whole has its first triangle's two finer levels as its
    first two: only its grandchildren are evaluated). (A kink near a triangle's edge is the other thing
    three levels miss: :func:`plane_cells`.) The dual, a receiver seen through a gap
    between all the nodes of a first triangle from which they see it wholly hidden, is
    looked for next (``gaps``: :func:`row_gaps`), and the triangles where it is seen
    replaced, each new one on its own three levels.

    Parameters
    ----------
    integrand : callable
        ``integrand(points (m, 3), tri (g, 3, 3)) -> (m, R) float64`` (:func:`row_rules`).
    threads : int
        As :class:`RowCubature`'s.
    gaps : callable, optional
        ``gaps(tri, q (g, R), kq (g, 4, R), gq (g, 16, R), budget (R,)) -> (replaced (g,)
        bool, new (h, 3, 3), spent (R,))``: :func:`row_gaps` of the row (``budget`` what
        the shadow search left; ``spent`` the bounds taken as estimates).
    """

    def __init__(self, integrand, threads=1, gaps=None):
        self.integrand = integrand
        self.evaluations = 0
        self.threads = threads
        self.gaps = gaps

    def rule(self, tri, width):
        """(g, R) float64: Radon's rule on each triangle."""
        return row_rules(self, tri, width, (RULE_WEIGHTS,))[0]

    def levels(self, tri, width):
        """The three levels of the triangles (g, 3, 3): ``q`` (g, R), their children ``K``
        (4 g, 3, 3) (rows 4 k … 4 k + 3 those of triangle k) and rules ``kq`` (4 g, R), their
        grandchildren ``G`` (16 g, 3, 3) and rules ``gq`` (16 g, R). A middle child's
        centroid is its parent's (:func:`row_rules`): 142 points a triangle, not 147."""
        K = split4(tri).reshape(-1, 3, 3)
        G = split4(K).reshape(-1, 3, 3)
        (q,), centres = row_rules(self, tri, width, (RULE_WEIGHTS,), keep_centres=True)
        (kq,), kid_centres = row_rules(self, K, width, (RULE_WEIGHTS,), centres, _middle_of(len(tri)), True)
        (gq,) = row_rules(self, G, width, (RULE_WEIGHTS,), kid_centres, _middle_of(len(K)))
        return q, K, kq, G, gq

    def estimates(self, tri, q, kq, gq):
        """(g, R): :func:`kinked_three_level_error` per column (q (g, R), kq (g, 4, R), gq (g, 16, R))."""
        return kinked_three_level_error(q, kq, gq)

    def integrate(self, tri, budget, live=None, bound=None):
        """∫ over the triangles (g, 3, 3) of every column (:func:`start_triangles`);
        ``budget`` (R,) the targets on the columns' estimates; ``live`` and ``bound`` the
        shaft test and the unseen shadows' bound of :meth:`RowCubature.integrate`. Returns
        ``value, error`` (R,) and the triangles evaluated."""
        width = len(budget)
        q, K, kq, G, gq = self.levels(tri, width)
        spent = np.zeros(width)
        if live is not None:
            # what each first triangle's 21 rules see of each column
            seen = levels_seen(q, kq.reshape(-1, 4, width), gq.reshape(-1, 16, width))
            unseen, new, whole, spent = look_for_shadows(tri, seen, live, bound)
            budget = budget - spent
            if len(new):
                keep = ~unseen
                # a child kept whole is a row of K: its rule and its children's are the
                # first triangle's second and third levels, and only its grandchildren are
                # new (112 points, not 142); the grandchildren of the others on their own
                kid = child_rows(np.flatnonzero(unseen))[whole]
                kid_K = child_rows(kid)
                kid_G = split4(G[kid_K]).reshape(-1, 3, 3)
                kid_gq = self.rule(kid_G, width)
                grandkids = new[len(whole):]
                nq, nK, nkq, nG, ngq = self.levels(grandkids, width)
                k_keep, g_keep = np.repeat(keep, 4), np.repeat(keep, 16)
                tri = np.concatenate([tri[keep], K[kid], grandkids])
                q = np.concatenate([q[keep], kq[kid], nq])
                K, kq = np.concatenate([K[k_keep], G[kid_K], nK]), np.concatenate([kq[k_keep], gq[kid_K], nkq])
                G, gq = np.concatenate([G[g_keep], kid_G, nG]), np.concatenate([gq[g_keep], kid_gq, ngq])
        if self.gaps is not None and len(tri):
            replaced, new, settled = self.gaps(tri, q, kq.reshape(-1, 4, width), gq.reshape(-1, 16, width), budget)
            spent, budget = spent + settled, budget - settled
            if np.any(replaced):
                keep = ~replaced
                k_keep, g_keep = np.repeat(keep, 4), np.repeat(keep, 16)
                nq, nK, nkq, nG, ngq = self.levels(new, width)
                tri, q = np.concatenate([tri[keep], new]), np.concatenate([q[keep], nq])
                K, kq = np.concatenate([K[k_keep], nK]), np.concatenate([kq[k_keep], nkq])
                G, gq = np.concatenate([G[g_keep], nG]), np.concatenate([gq[g_keep], ngq])
        cells = 21 * len(tri)
        for _ in range(200):
            err = self.estimates(tri, q, kq.reshape(-1, 4, width), gq.reshape(-1, 16, width))
            total = err.sum(axis=0)
            over = np.flatnonzero(total > budget)
            if not len(over) or cells >= MAX_CELLS or not len(tri):
                break
            split = worst_leaves(err, total, over, budget)
            keep, rows = np.flatnonzero(~split), np.flatnonzero(split)
            child = child_rows(rows)
            grand = child_rows(child)
            new_G = split4(G[grand]).reshape(-1, 3, 3)
            new_gq = self.rule(new_G, width)
            cells += 16 * len(child)
            k_keep, g_keep = child_rows(keep), child_rows(keep, 16)
            tri = np.concatenate([tri[keep], K[child]])
            q = np.concatenate([q[keep], kq[child]])
            K = np.concatenate([K[k_keep], G[grand]])
            kq = np.concatenate([kq[k_keep], gq[grand]])
            G = np.concatenate([G[g_keep], new_G])
            gq = np.concatenate([gq[g_keep], new_gq])
        err = self.estimates(tri, q, kq.reshape(-1, 4, width), gq.reshape(-1, 16, width))
        return gq.sum(axis=0), err.sum(axis=0) + spent, cells


def coplanar_faces(scene, face):
    """(k,) int64: the other faces lying in the plane of a face (all their vertices within
    1e-9 of the scene's size of it), which may lie on it (docs/queries.md, "Faces lying on
    faces")."""
    outline, lo, hi = face_outlines(scene)
    n = scene.face_normal[face]
    h = np.abs(outline @ n - float(n @ outline[lo[face]]))
    flat = np.maximum.reduceat(h, lo) <= 1e-9 * scene.diagonal
    flat[face] = False
    return np.flatnonzero(flat)


def seen_faces(scene, face, side):
    """(k,) int64, sorted: the face and the faces that its side ``side`` may see or touch, a
    vertex ahead of the side's plane or all in it (within 1e-9 of the scene's size). The
    others lie behind the plane: no point of the side sees them, and they hide nothing in
    front of it (a segment from the side to a point ahead of it runs ahead of the plane; where
    it enters a closed box, it does so through a face with a point ahead, kept, so the box's
    back faces may still be culled by :func:`viscx.geometry.occlusion.point_views`). What a
    matrix row's points are computed over."""
    outline, lo, _ = face_outlines(scene)
    n_i = side * scene.face_normal[face]
    ahead = np.maximum.reduceat(outline @ n_i, lo) - float(n_i @ outline[lo[face]]) > -1e-9 * scene.diagonal
    ahead[face] = True
    return np.flatnonzero(ahead).astype(np.int64)


def pair_contour(scene, setup, key):
    """:func:`contour_form_factor` of a pair's I' and J' (``key``: face i, side, face j,
    side), computed once for (i, j) and (j, i) where neither is clipped by the other's
    plane (every vertex of each more than tiny in front of the other: both rows then take
    the same whole loops, and A_i F⁰_ij = A_j F⁰_ji, errors alike). Kept per process on the
    scene: a worker reuses the terms of the rows it ran before. (Computing them all in the
    matrix's parent before it forks would save more CPU on the Cornell box, ~0.1 s, but
    serially: on a room of hundreds of faces, with tens of thousands of facing pairs, that
    is wall time no worker shares.)"""
    memo = scene.cached("pair contours", lambda s: {})
    if not _unclipped(setup):
        return contour_form_factor(setup.I, setup.n_i, setup.J, setup.n_t)
    a_i = loops_area(setup.I, setup.n_i)
    key = tuple(int(k) for k in key)
    rev = (key[2], key[3], key[0], key[1])
    canonical = min(key, rev)  # A_i F⁰_ij = A_j F⁰_ji
    flux = memo.get(canonical)
    if flux is None:
        # always from the canonical order's emitter, whichever row asks first: the same
        # digits in every run, however the rows are shared among the workers
        if key == canonical:
            value, err = contour_form_factor(setup.I, setup.n_i, setup.J, setup.n_t)
            flux = (value * a_i, err * a_i)
        else:
            a_j = loops_area(setup.J, setup.n_t)
            value, err = contour_form_factor(setup.J, setup.n_t, setup.I, setup.n_i)
            flux = (value * a_j, err * a_j)
        memo[canonical] = flux
    return flux[0] / a_i, flux[1] / a_i


def _unclipped(setup):
    """Whether every vertex of I and of J lies more than tiny in front of the other's plane."""
    return (min(float(np.min(l @ setup.n_t)) for l in setup.I) - setup.c_t > setup.tiny
            and min(float(np.min(l @ setup.n_i)) for l in setup.J) - setup.c_i > setup.tiny)


def row_form_factors(scene, face, side, faces, tol, sky=True, reciprocal=False, threads=1, gap_search=True):
    """F from one side of a face to every side of ``faces`` and to the sky, all receivers at
    once: ``F_c = F⁰_c − (1/A_i) ∫_I hidden_c(x) dx`` for every column c, F⁰ the exact
    contour integral of the pair (I', J') where they face each other (:class:`PairSetup`),
    ``hidden`` the vector :func:`viscx.geometry.occlusion.point_views` gives at each point
    (every receiver from one hidden-surface computation, over the faces in front of the
    side or in its plane: :func:`seen_faces`), integrated by
    :class:`RowCubature` over the emitter's cells cut along the kink lines of all the
    receivers (:func:`emitter_cells` with ``kinks``; where those cells would cost more points
    at the start than three levels on the uncut cells, :class:`ThreeLevelRowCubature` on
    these) with each column's budget ``tol − (contour error)`` (in F). Each column's pair
    occluders, tested against the first triangles' shafts, say where a shadow may lie
    that the rule's nodes miss (:meth:`RowCubature.integrate`). A side with a closed form
    (inside an empty closed box, or lying wholly on other faces: :func:`closed_form_row`)
    takes it instead. Only the columns asked for (and the sky, with ``sky``) have a budget:
    the others are integrated with them (one kernel call gives every column) but neither
    refined nor searched for shadows. With ``reciprocal``, only the faces of ``faces`` this
    side computes the pairs of (:func:`computed_pairs`) are asked for: :func:`assemble_matrix`
    derives the others. The row's points are evaluated on ``threads`` threads
    (:func:`row_rules`: the same result on any number). With ``gap_search`` (the
    default), a three-level row looks for receivers seen through gaps between the nodes of
    its first triangles (:func:`row_gaps`: without it, such an entry says 0 with a small
    estimate; at 1e-4 1.05 times the rows' CPU on office(300), 1.155 on office(1000)).
    A three-level row's computed column that is mostly hidden (:func:`mostly_hidden`: seen
    from a few nodes, perhaps through a band between them) is the pair's query instead
    where that is cut along the pair's own kink lines (:func:`pair_form_factor` at
    ``tol``), counted as ``"mostly hidden"``.

    Returns what :func:`emitter_row` returns.
    """
    n = scene.n_faces
    faces = np.asarray(faces, np.int64)
    if reciprocal:
        faces = faces[computed_pairs(scene, face, faces)]
    sky = sky and may_see_sky(scene, face, side)
    closed = closed_form_row(scene, face, side, faces, sky)
    if closed is not None:
        return closed
    none = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0), {"none": 2 * len(faces) - 2 * int(np.isin(face, faces))})
    seen = seen_faces(scene, face, side)
    if not sky and not np.isin(seen[seen != face], faces).any():
        # nothing asked of this side (a closed room's ceiling: its pair with the floor is the
        # floor's, its sky 0)
        return none + (0.0, 0.0)
    fj, sj = facing_sides(scene, face, side, np.arange(n, dtype=np.int64))
    if not len(fj) and not len(coplanar_faces(scene, face)):
        # nothing in front of the side and nothing lying on it: it sees the sky, exactly
        return none + (1.0 if sky else 0.0, 0.0)
    # the first triangles no larger than 1 / MIN_SPLIT of the smallest box holding the
    # emitter and a receiver, as the pair cubature's (4 times larger, the Cornell matrix
    # at 1e-4 took half the time, but 3 of 376 entries were off by more than their
    # estimates, up to 30 times: grazing pairs whose small shadows the coarser start missed)
    box_lo, box_hi = face_boxes(scene)
    others = np.unique(np.concatenate([fj, coplanar_faces(scene, face)])).astype(np.int64)
    extent = np.linalg.norm(np.maximum(box_hi[others], box_hi[face]) - np.minimum(box_lo[others], box_lo[face]),
                            axis=1).min(initial=float(np.linalg.norm(box_hi[face] - box_lo[face])))
    # the row's columns: the sides of the faces it may see or touch, then the sky; the pairs
    # it computes (their set-ups' cells are not needed: only the pair cubature's start reads them)
    width = 2 * len(seen) + 1
    targets = [(face_target(scene, int(j)), int(t), 2 * int(np.searchsorted(seen, j)) + (0 if t > 0 else 1))
               for j, t in zip(fj, sj) if np.isin(j, faces)]
    setups = {(target.face, t): PairSetup(scene, face, side, target, t, occluders=False) for target, t, _ in targets}
    # cut along the kink lines of the columns the row computes only (the others are
    # integrated with them but not used): the sky's and its pairs', where it leaves some out
    every = bool(np.isin(others, faces).all())
    cells, tri, kinked = cubature_cells(scene, face, side, extent / MIN_SPLIT, None if every else faces, sky, setups)
    if not kinked:
        # three levels: the grandchildren of triangles twice as long lie as densely as the
        # two-level row's children (Cornell: what a kink-cut start needs to see its small
        # shadows); office(300)'s box outer sides at 1e-4: a cabinet side 4,704 -> 1,176 points
        tri = start_triangles(cells, extent / THREE_LEVEL_SPLIT)
        planed = plane_cells(scene, face, side, cells, len(tri))
        if planed is not None:
            cells = planed
            tri = start_triangles(cells, extent / THREE_LEVEL_SPLIT)
    f0, e0 = np.zeros(width), np.zeros(width)
    wanted = np.zeros(width, bool)
    wanted[:-1] = np.repeat(np.isin(seen, faces) & (seen != face), 2)
    # a box's inner side and a face outside the box: 0 exactly, though the kernel's
    # columns hold what its front hides of the unoccluded F (box_hidden)
    wanted[:-1] &= ~box_hidden(scene, face, side, np.repeat(seen, 2), np.tile(SIDES, len(seen)))
    wanted[-1] = sky
    area = float(scene.face_area[face])
    shafts = []  # (setup, column) of the pairs whose occluders the shadow search may ask for
    for target, t, c in targets:
        setup = setups[target.face, t]
        if not setup.empty:
            value, err = pair_contour(scene, setup, (face, side, target.face, t))
            scale = loops_area(setup.I, setup.n_i) / area
            f0[c], e0[c] = value * scale, err * scale + setup.clip_bound()
            shafts.append((setup, c))
    def live(tri, need):
        """(g, width) bool: an occluder meets the triangle's shaft to the column (tested
        where ``need`` (g, width) bool asks, else False)."""
        out = np.zeros((len(tri), width), bool)
        for setup, c in shafts:
            rows = np.flatnonzero(need[:, c])
            if not len(rows):
                continue
            if not setup.occluders_found:  # found when first asked for
                setup.find_occluders()
            k = len(setup.occluders)
            if not k:
                continue
            ptr, _ = cull_all(setup.shaft_cull, tri[rows], np.arange(k))
            out[rows, c] = np.diff(ptr) > 0
        return out
    n_i = side * scene.face_normal[face]
    eu, ev = plane_basis(n_i)
    polygons = polygon_subset(scene, seen)
    face_box, box_ptr, box_planes = closed_boxes(scene)
    boxes = (np.ascontiguousarray(face_box[seen]), box_ptr, box_planes)
    own = int(np.searchsorted(seen, face))
    tiny = 1e-9 * scene.diagonal

    def hidden(points, tri=None):
        return point_views(points, n_i, eu, ev, *polygons, own, tiny, *boxes)

    budget = np.where(wanted, np.maximum(tol - e0, 0.1 * tol) * area, np.inf)
    if kinked:
        cub = RowCubature(hidden, threads)
    else:
        gaps = (lambda tri, q, kq, gq, left: row_gaps(scene, n_i, tri, q, kq, gq, shafts, left)) if gap_search else None
        cub = ThreeLevelRowCubature(hidden, threads, gaps)
    bound = unseen_shadow_bound(scene, shafts, f0, e0, area, budget)
    h, h_err, _ = cub.integrate(tri, budget, live, bound)
    F, E = f0 - h / area, e0 + h_err / area
    F[-1] = h[-1] / area  # the sky's column holds what is seen of it, not what is hidden
    wanted[-1] = False
    taken = 0
    if not kinked:
        # a mostly hidden column's three levels do not bound a band seen between their
        # nodes; the pair's query does where it cuts along its own kink lines (on three
        # levels too, it starts on coarser triangles than the row: docs/queries.md)
        by_column = {c: (target, t) for target, t, c in targets}
        for c in np.flatnonzero(wanted & mostly_hidden(F, f0)):
            target, t = by_column[int(c)]
            if cubature_cells(scene, face, side, receivers=[target.face], pairs=True)[2]:
                pair = pair_form_factor(scene, face, side, target, t, tol, threads=threads)
                F[c], E[c] = pair.F, pair.error
                taken += 1
    cols = np.flatnonzero(wanted & (F != 0.0))
    counts = {"contour": int(np.sum(wanted & (f0 != 0) & (h == 0))), "quadrature": int(np.sum(wanted & (h != 0))),
              "evaluations": int(cub.evaluations), "mostly hidden": taken}
    sky_v, sky_e = (float(F[-1]), float(E[-1])) if sky else (0.0, 0.0)
    element = (2 * seen[:, None] + np.arange(2)).reshape(-1)  # the scene's element of each column (but the sky)
    return element[cols].astype(np.int64), F[cols], E[cols], counts, sky_v, sky_e


def computed_pairs(scene, face, faces):
    """(k,) bool: for each of ``faces`` (k,) int64, whether the matrix computes the pair's
    form factors in the rows of ``face`` (both sides) rather than in its rows: the pair
    {a, b} is computed from the face of smaller area (the smaller index between equal areas)
    and the other direction derived, ``A_a F_ab = A_b F_ba`` (:func:`assemble_matrix`). Its
    error is then the computed entry's times A_a / A_b ≤ 1 (radiosity's usual practice: the
    small face's row resolves what it sees of the large one to ``tol``, and the large
    face's row, refined for every small receiver, would cost the most for the least)."""
    area = scene.face_area
    faces = np.asarray(faces, np.int64)
    return (area[faces] > area[face]) | ((area[faces] == area[face]) & (faces > face))


def summation_column(scene, face, side):
    """The element (``2 j`` front, ``2 j + 1`` back) whose form factor from a side of a face
    the matrix takes from the row's sum instead of computing it, or -1.

    A side inside a closed room (:func:`enclosed_sides`) sees no sky, so its row sums to 1
    exactly (radiosity's summation rule): ``F_ik = 1 − Σ_(j ≠ k) F_ij``. Where the matrix
    computes one pair only in this row (:func:`computed_pairs`: every other entry is
    derived from the rows of smaller faces) and the side may see one side k of that face
    only, F_ik follows from the derived entries, its error estimate their estimates' sum
    (:func:`assemble_matrix`). The office's floor: its only computed pair is the one with
    the ceiling (same area, smaller index), the dearest pair of the matrix (a 1,006-face
    office's floor → ceiling: every piece of furniture hides some ceiling from every
    point of the floor; 274 CPU s by the pair cubature at 1e-4, more than 10 min by the
    row's). That row's sum is then 1 by construction and checks nothing; the ceiling's
    row, which derives F_ki from it by reciprocity, still sums its own entries."""
    if may_see_sky(scene, face, side):
        return -1
    b = closed_boxes(scene)[0][face]
    if side == -1 and b >= 0 and (empty_boxes(scene)[b] or box_caps(scene)[b] is not None):
        return -1  # inside an empty box: every entry in closed form (closed_form_row)
    faces = np.arange(scene.n_faces, dtype=np.int64)
    mine = faces[computed_pairs(scene, face, faces)]
    fj, sj = facing_sides(scene, face, side, mine)
    if len(fj) != 1 or np.isin(coplanar_faces(scene, face), mine).any():
        return -1
    return 2 * int(fj[0]) + (0 if sj[0] > 0 else 1)


def load_row_kernels(scene, every_sweep=False):
    """Load (or compile) the numba kernels of :func:`row_form_factors` with the types its
    calls have, on no points: a parent that does so before forking its workers loads them
    once (~0.4 CPU s on the Cornell box) instead of once per worker (every kernel a row
    calls, the kink lines', the cuts' and the searches' too: `NUMBA_DEBUG_CACHE=1` shows
    each loaded once in a matrix). With ``every_sweep``, also the version of
    :func:`point_views` that rooms of more than ``SWEEP_RUNS_FROM`` projected edges sweep
    with, whatever the scene (:mod:`viscx.warmup`: all compiled at install)."""
    n_i = np.asarray(scene.face_normal[0], np.float64)
    eu, ev = plane_basis(n_i)
    face_box, box_ptr, box_planes = closed_boxes(scene)
    point_views(np.zeros((0, 3)), n_i, eu, ev, *scene_polygons(scene), 0, 1.0, face_box, box_ptr, box_planes)
    # a row of few faces sweeps without the runs' records (point_views): its version too
    one = np.zeros(1, np.int64)
    point_views(np.zeros((0, 3)), n_i, eu, ev, *polygon_subset(scene, one), 0, 1.0, np.ascontiguousarray(face_box[one]),
                box_ptr, box_planes)
    if every_sweep:
        point_views(np.zeros((0, 3)), n_i, eu, ev, *scene_polygons(scene), 0, 1.0, face_box, box_ptr, box_planes,
                    sweep_kind=2)
    none_i, none_f = np.zeros(0, np.int64), np.zeros((0, 3))
    shaft_meets(np.zeros((0, 3, 3)), none_f, none_f, n_i, none_i, none_i, none_f, none_i, none_i, none_f, 1.0)
    shaft_boxes_meet(np.zeros((0, 3, 3)), none_f, none_i, none_i, none_f, none_i, none_i, 1.0)
    # the shadow and gap searches' (PairSetup.umbra, GapSearch) and the cells' cuts
    umbra_triangles(np.zeros((0, 3, 3)), none_f, n_i, 0.0, eu, ev, np.zeros(0), np.zeros(1, np.int64), np.zeros((0, 4)),
                    1.0)
    segments_crossing(np.zeros((0, 2, 2)), np.zeros((0, 3, 2)), 1.0)
    cut_pieces(np.zeros((0, 2)), np.zeros(1, np.int64), none_i, np.zeros((0, 2, 2)), np.zeros(0), 1.0, -1)
    load_kink_kernels()


_POOL_SCENE = None


def _row_task(args, scene=None):
    row, face, side, faces, tol, sky, options = args
    return row(_POOL_SCENE if scene is None else scene, face, side, faces, tol, sky, **options)


def _map_rows(row, scene, rows, tol, sky, workers=None, progress=None, threads=False):
    """``row(scene, face, side, faces, tol, sky)`` (:func:`emitter_row` pair by pair, or
    :func:`row_form_factors` all receivers at once) of every (face, side, faces) in
    ``rows`` (each row its own receivers ``faces`` (k,) int64), in that order, on
    ``workers`` processes (forked: they share the scene; the results do not depend on
    their number). ``tol``: one for every row, or a list of one per row (for
    :func:`emitter_row`, each may be one per receiver).

    The costly rows (large faces) go first, so that no worker is left with one at the end.
    With ``threads`` (:func:`row_form_factors`, and :func:`emitter_row` whose pairs'
    cubatures do likewise: :meth:`Cubature._pieces`), each row also evaluates its points on as
    many threads as there are workers, each piece of points holding one of ``workers``
    core tokens shared by the processes (:func:`row_rules`): while every worker has a row,
    each row's kernels run on about one core; once the queue is empty, the rows still
    running take the cores the finished workers left (the office's floor row is 40 % of
    its matrix: without this, one core would do it alone while the other idles). Threads
    only share a row's points out: the row is the same, bit for bit."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    global _POOL_SCENE, _ROW_CORES
    workers = min(default_workers(workers), len(rows))
    options = {"threads": workers} if threads and workers > 1 else {}
    tols = tol if isinstance(tol, list) else [tol] * len(rows)
    tasks = [(row, int(r[0]), int(r[1]), np.asarray(r[2], np.int64), t, sky, options)
             for r, t in zip(rows, tols)]
    if workers <= 1 or "fork" not in mp.get_all_start_methods():
        out = []
        for t in tasks:
            out.append(_row_task(t, scene))
            if progress:
                progress()
        return out
    order = np.argsort(-scene.face_area[[t[1] for t in tasks]], kind="stable")
    ctx = mp.get_context("fork")
    _POOL_SCENE, _ROW_CORES = scene, (ctx.BoundedSemaphore(workers) if options else None)
    try:
        with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            futures = {k: pool.submit(_row_task, tasks[k]) for k in order}
            out = [None] * len(tasks)
            for k in order:
                out[k] = futures[k].result()
                if progress:
                    progress()
    finally:
        _POOL_SCENE, _ROW_CORES = None, None
    return out


@dataclass
class Matrix:
    """Form factors between all sides of all faces (sparse), with the sky term.

    Element ``2 f`` is the front of face f (its normal side), ``2 f + 1`` its back.

    Attributes
    ----------
    indptr, indices : CSR structure (2n + 1,), (nnz,) int64
    data, error : (nnz,) float64
        F and its error estimate.
    sky, sky_error : (2n,) float64
        F to the sky (the enlarged bounding box, :func:`sky_targets`).
    area : (n,) float64
    method_counts : dict
    seconds : float
    tol : float
    reciprocal : bool
        Each pair computed once, in the rows of its smaller face, and the other direction
        derived (:func:`computed_pairs`): the reciprocity error is then 0 by construction
        (up to rounding), and row sums are the check. Entries taken from a closed room's
        row sum (:func:`summation_column`, ``method_counts["summation"]``) have the sum of
        that row's other estimates as theirs, which may pass ``tol``, and that row's sum
        checks nothing.
    """

    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray
    error: np.ndarray
    sky: np.ndarray
    sky_error: np.ndarray
    area: np.ndarray
    method_counts: dict
    seconds: float
    tol: float
    reciprocal: bool = False

    def dense(self):
        n = len(self.indptr) - 1
        out = np.zeros((n, n))
        for r in range(n):
            out[r, self.indices[self.indptr[r]:self.indptr[r + 1]]] = self.data[self.indptr[r]:self.indptr[r + 1]]
        return out

    def row_sums(self):
        """Σ_j F + sky per element (1 for every side, up to the error)."""
        rows = np.repeat(np.arange(len(self.sky)), np.diff(self.indptr))
        return np.bincount(rows, weights=self.data, minlength=len(self.sky)) + self.sky

    def reciprocity_error(self, per="smaller"):
        """max |A_a F_ab - A_b F_ba| over element pairs, in F units of the smaller face of
        each pair (``per="smaller"``: the strictest) or of the larger (``"larger"``: with
        every entry within ``tol`` in F it is at most 2 tol, whatever the areas; in F units
        of the smaller face it may be up to (1 + A_larger / A_smaller) tol, the office's
        floor row weighing 5,000 times against a desk panel's side)."""
        d = self.dense()
        a = np.repeat(self.area, 2)
        flux = a[:, None] * d
        pick = np.minimum if per == "smaller" else np.maximum
        diff = np.abs(flux - flux.T) / pick(a[:, None], a[None, :])
        return float(diff.max()) if diff.size else 0.0

    def summary(self):
        rows = self.row_sums()
        return {
            "elements": int(len(self.sky)),
            "nonzeros": int(len(self.data)),
            "reciprocity": "imposed" if self.reciprocal else "measured",
            "reciprocity_max_error": self.reciprocity_error(),
            "reciprocity_max_error_larger": self.reciprocity_error("larger"),
            "row_sum_min": float(rows.min()),
            "row_sum_max": float(rows.max()),
            "row_sum_max_deviation": float(np.abs(rows - 1).max()),
            "max_error_estimate": float(max(self.error.max(initial=0.0), self.sky_error.max(initial=0.0))),
            "tol": self.tol,
            "methods": self.method_counts,
            "seconds": round(self.seconds, 3),
        }


def form_factor_matrix(scene, tol=MATRIX_TOL, quiet=True, workers=None, reciprocal=True, gap_search=True):
    """F between every pair of sides, plus every side's sky term: one
    :func:`row_form_factors` per side (the sides with a closed form by it,
    :func:`closed_form_row`), on ``workers`` processes (default: the CPU count; the largest
    faces first; a row's points on the cores the others leave idle, :func:`_map_rows`),
    with a progress bar. With ``reciprocal`` (the default) each pair is computed in the
    rows of its smaller face and the other direction derived, ``A_a F_ab = A_b F_ba``
    (:func:`computed_pairs`), and a closed room's row of one pair takes it from its sum
    (:func:`summation_column`); without, every entry is computed on its own and reciprocity
    is a measurement (the oracle the tests compare the two with). ``gap_search``: the
    rows' (:func:`row_form_factors`). The result does not depend on ``workers``, to the
    bit."""
    from viscx.progress import bar

    t0 = time.perf_counter()
    n = scene.n_faces
    rows, summation = matrix_rows(scene, reciprocal)
    row = functools.partial(row_form_factors, reciprocal=reciprocal, gap_search=gap_search)
    load_row_kernels(scene)  # once here, not once in each forked worker
    with bar(total=2 * n, desc="form factors", quiet=quiet, unit="side") as progress:
        results = _map_rows(row, scene, rows, tol, True, workers,
                            progress=lambda: progress.update(1), threads=True)
    return assemble_matrix(scene, results, tol, time.perf_counter() - t0, reciprocal, summation)


def matrix_rows(scene, reciprocal=True):
    """The matrix's rows: ``([(face, side, receivers (k,) int64)], summation (2n,) int64)``,
    one per side (face 0 front, face 0 back, face 1 front, ...), and per side the element
    its sum gives (:func:`summation_column`, with ``reciprocal``; -1 for none), left out of
    its receivers: such a row computes no pair (its sky is 0: enclosed)."""
    n = scene.n_faces
    faces = np.arange(n, dtype=np.int64)
    sides = [(i, s) for i in range(n) for s in SIDES]
    summation = np.array([summation_column(scene, i, s) if reciprocal else -1 for i, s in sides], np.int64)
    return [(i, s, faces if c < 0 else faces[faces != c // 2]) for (i, s), c in zip(sides, summation)], summation


def assemble_matrix(scene, results, tol, seconds, reciprocal=False, summation=None):
    """The :class:`Matrix` of the rows ``results`` (what :func:`emitter_row` returns, one per
    side: face 0 front, face 0 back, face 1 front, ...). With ``reciprocal``, the rows hold
    only the pairs they compute (:func:`computed_pairs`), and each entry gives the other
    direction (:func:`derived_entries`). ``summation`` (2n,) int64: per row, the element
    whose entry its sum gives (:func:`summation_column`), -1 for none; those entries are
    added, row by row from the smallest face up (an entry taken so is the larger face's,
    never needed by a smaller face's sum), with their derived directions."""
    counts = {}
    for r in results:
        for k, v in r[3].items():
            counts[k] = counts.get(k, 0) + v
    rows, cols, vals, errs = row_entries(results, np.arange(len(results), dtype=np.int64))
    if reciprocal:
        derived = derived_entries(scene, rows, cols, vals, errs)
        rows, cols, vals, errs = (np.concatenate(pair) for pair in zip((rows, cols, vals, errs), derived))
        taken = np.flatnonzero(np.asarray(summation if summation is not None else [], np.int64) >= 0)
        for r in taken[np.lexsort([taken, scene.face_area[taken // 2]])]:
            c = int(summation[r])
            mine = rows == r
            assert not np.any(mine & (cols == c)), "a row's summation entry was computed too"
            # F_rc = 1 − Σ of the row's other entries − its sky (0: enclosed); an F outside
            # [0, 1] is clamped, the error widened by as much
            value = 1.0 - float(vals[mine].sum()) - results[r][4]
            err = float(errs[mine].sum()) + results[r][5]
            clamped = min(max(value, 0.0), 1.0)
            value, err = clamped, err + abs(value - clamped)
            entry = (np.array([r]), np.array([c]), np.array([value]), np.array([err]))
            rows, cols, vals, errs = (np.concatenate(k) for k in zip((rows, cols, vals, errs), entry,
                                                                     derived_entries(scene, *entry)))
        if len(taken):
            counts["summation"] = int(len(taken))
        order = np.lexsort([cols, rows])
        rows, cols, vals, errs = rows[order], cols[order], vals[order], errs[order]
        counts["derived"] = int(len(derived[0]))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=len(results)))]).astype(np.int64)
    sky_v = np.array([r[4] for r in results])
    sky_e = np.array([r[5] for r in results])
    return Matrix(indptr, cols, vals, errs, sky_v, sky_e, scene.face_area.astype(np.float64).copy(), counts, seconds,
                  float(tol), bool(reciprocal))


def row_entries(results, elements):
    """The entries of rows ``results`` (what :func:`emitter_row` returns), result k being
    a row of element ``elements[k]``: ``(rows, cols (m,) int64, values, errors (m,) float64)``,
    in the rows' order."""
    lengths = np.array([len(r[0]) for r in results], np.int64)
    cat = lambda k, dt: np.concatenate([r[k] for r in results]).astype(dt) if len(results) else np.zeros(0, dt)  # noqa: E731
    rows = np.repeat(np.asarray(elements, np.int64), lengths)
    return rows, cat(0, np.int64), cat(1, np.float64), cat(2, np.float64)


def derived_entries(scene, rows, cols, values, errors):
    """The other direction of computed entries F_ab (element a = ``rows``, b = ``cols``):
    by reciprocity ``A_a F_ab = A_b F_ba``, so ``F_ba = F_ab A_a / A_b``, its error
    estimate scaled alike (the pair computed from its smaller face, :func:`computed_pairs`:
    A_a / A_b ≤ 1, within ``tol`` if F_ab is). Returns ``(rows, cols, values, errors)``
    of the F_ba."""
    ratio = scene.face_area[rows // 2] / scene.face_area[cols // 2]
    return cols, rows, values * ratio, errors * ratio


# --------------------------------------------------------------------------------------
# point to face (Hoberock et al. §7.4)


def point_to_faces(query, point, normal, faces):
    """Exact F from a differential area (point, normal) to each face, over the part of the
    face the point sees: the point's V-cells (:func:`viscx.queries.visibility.view_from`),
    clipped to the front hemisphere, then Lambert's formula.

    Returns
    -------
    dict
        ``F`` (sum over ``faces``), per face ``F`` and visible area, ``complete``, ``source``.
    """
    from viscx.queries.visibility import view_from

    n = np.asarray(normal, dtype=np.float64).reshape(3)
    size = float(np.linalg.norm(n))
    if not np.isfinite(size) or size == 0.0:
        raise ViscxError("--normal must be a non-zero vector")
    n = n / size
    p = np.asarray(point, dtype=np.float64).reshape(3)
    t0 = time.perf_counter()
    view, stored = view_from(query, p)
    per = []
    for f in faces:
        fv = view.faces[int(f)]
        loops = [clip_to_hemisphere(loop, p, n) for loop in fv.loops]
        loops = [loop for loop in loops if len(loop) >= 3]
        value = float(point_to_polygon([p], [n], loops)[0]) if loops else 0.0
        per.append({"face": int(f), "F": value, "visible_area": fv.area(), "complete": bool(fv.complete)})
    return {
        "F": float(sum(r["F"] for r in per)),
        "from": p.tolist(),
        "normal": n.tolist(),
        "faces": per,
        "method": "V-cells + Lambert (exact)",
        "complete": bool(view.complete),
        "source": "file" if stored else "on demand",
        "seconds": round(time.perf_counter() - t0, 4),
    }
