"""Closed convex boxes in the form-factor kernels (viscx.queries.formfactor.closed_boxes):
the pair kernel projects the faces of a box a point is outside of as one convex polygon,
``point_views`` does not sweep the box's back faces, and the cubature's triangles drop the
back faces of boxes they lie wholly outside of. Each is exact; the reference is the same
kernels with every face swept on its own (``no_boxes``), which tests/test_formfactor_rows.py
and tests/test_formfactor_queries.py check against the V-cells and each other."""

import numpy as np
import pytest
from conftest import soup
from random_scenes import random_boxes

from viscx.geometry.formfactor import point_to_polygon
from viscx.geometry.occlusion import TURNED_OVER, _clip_to_frustum, _outside_box, _wedges, point_views
from viscx.geometry.polygon import plane_basis
from viscx.queries import formfactor as ff
from viscx.scene import build_scene


@pytest.fixture(scope="module")
def open_box_above_floor():
    """A 10 × 10 floor (y = 0, facing up), a ceiling (y = 3, facing down) and a box open at
    its bottom floating between them (x, z in [4, 6], y in [1, 2]: top and four sides,
    normals outward): from the floor, its inside is seen through the missing bottom."""
    v = [[0, 0, 0], [10, 0, 0], [10, 0, 10], [0, 0, 10], [0, 3, 0], [10, 3, 0], [10, 3, 10], [0, 3, 10]]
    v += [[x, y, z] for y in (1, 2) for x, z in ((4, 4), (6, 4), (6, 6), (4, 6))]
    polygons = [[0, 3, 2, 1], [4, 5, 6, 7],  # floor (up), ceiling (down)
                [12, 15, 14, 13],  # top (up)
                [8, 12, 13, 9], [9, 13, 14, 10], [10, 14, 15, 11], [11, 15, 12, 8]]  # sides (out)
    return build_scene(soup(v, polygons, [0, 1, 2, 2, 2, 2, 2], ["floor", "ceiling", "box"]))


@pytest.fixture(scope="module")
def boxes_on_floor():
    return build_scene(random_boxes(np.random.default_rng(5), 8, axis_aligned=False, on_floor=True))


def face_points(scene, face, k, rng):
    tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
    w = rng.dirichlet([1, 1, 1], k)
    return np.ascontiguousarray(np.einsum("gk,gkd->gd", w, tri[rng.integers(0, len(tri), k)]))


def test_closed_boxes_of_the_office(office60):
    """Every cabinet and divider is one box of six faces, every desk three (its top and two
    panels: flush with the top's ends and under it, never merged with it); the room (facing
    in) and the lights (single quads) are none."""
    face_box, ptr, planes = ff.closed_boxes(office60)
    names = office60.group_names
    group = office60.face_group
    for g, name in enumerate(names):
        faces = np.flatnonzero(group == g)
        boxes = set(face_box[faces].tolist())
        if name.startswith(("cabinet", "divider")):
            assert len(boxes) == 1 and -1 not in boxes and len(faces) == 6, name
        elif name.startswith("desk"):
            assert len(boxes) == 3 and -1 not in boxes, name
        else:
            assert boxes == {-1}, name
    assert np.all(np.diff(ptr) == 6) and len(planes) == ptr[-1]
    # every box vertex on or behind every plane of its box (outward normals)
    for b in range(len(ptr) - 1):
        verts = np.concatenate([np.concatenate(office60.face_loops(f)) for f in np.flatnonzero(face_box == b)])
        assert np.all(verts @ planes[ptr[b]:ptr[b + 1], :3].T - planes[ptr[b]:ptr[b + 1], 3] <= 1e-9)


def test_open_boxes_of_the_cornell_box(cornell, open_box_above_floor):
    """The Cornell blocks (five faces each, no bottom, standing on the floor) are open boxes:
    their missing face's plane is the floor's, outward normal down, flagged open; every
    vertex of a block on or behind each of its six planes. The floating box open at its
    bottom is one too (its missing face's plane y = 1)."""
    face_box, ptr, planes = ff.closed_boxes(cornell)
    for name in ("short_block", "tall_block"):
        boxes = set(face_box[cornell.group_faces(name)].tolist())
        assert len(boxes) == 1 and -1 not in boxes
    assert (face_box >= 0).sum() == 10 and np.array_equal(np.diff(ptr), [6, 6])
    missing = planes[planes[:, 4] != 0.0]
    assert np.allclose(missing[:, :4], [[0, -1, 0, 0]] * 2, atol=1e-12)
    for b in range(2):
        verts = np.concatenate([np.concatenate(cornell.face_loops(f)) for f in np.flatnonzero(face_box == b)])
        assert np.all(verts @ planes[ptr[b]:ptr[b + 1], :3].T - planes[ptr[b]:ptr[b + 1], 3] <= 1e-9)
    s = open_box_above_floor
    face_box, ptr, planes = ff.closed_boxes(s)
    assert face_box.tolist() == [-1, -1, 0, 0, 0, 0, 0]
    assert np.allclose(planes[planes[:, 4] != 0.0, :4], [[0, -1, 0, -1]])


def test_rotated_boxes_are_found(boxes_on_floor):
    face_box = ff.closed_boxes(boxes_on_floor)[0]
    assert len(set(face_box.tolist()) - {-1}) == 8
    assert face_box[boxes_on_floor.face_group == 0].tolist() == [-1]  # the floor


def _pair_values(scene, i, j, points, boxes, holes=False):
    """The pair kernel's hidden part at the points, all the pair's occluders, with the box
    rules (boxes) or every face on its own; ``holes``: J's covered cells as holes, as the
    pair cubature has them."""
    target = ff.face_target(scene, j)
    if holes:
        target = ff.Target(target.loops + ff.covered_cells(scene, j, 1), target.normal, j)
    setup = ff.PairSetup(scene, i, 1, target, 1)
    assert setup.occluders
    if not boxes:
        setup.kernel_for = lambda occ, s=setup: ff.PairSetup.kernel_for(s, [o[:2] for o in occ])
    ids = np.arange(len(setup.occluders), dtype=np.int64)
    return setup, setup.blocked(points, np.zeros(len(points), np.int64), np.array([0, len(ids)], np.int64), ids)


@pytest.mark.parametrize("pair", [("floor", "ceiling"), ("wall_west", "wall_east"), ("floor", "light1"),
                                  ("light1", "floor"), ("wall_south", "wall_north")])
def test_pair_kernel_with_boxes_equals_faces_one_by_one(office60, pair, rng):
    """The box hulls change what is swept, not the visible part: equal to 1e-12 at 1,500
    points of the emitter (rounding only: other slab breaks)."""
    s = office60
    i = int(s.group_faces(pair[0])[0])
    j = int(s.group_faces(pair[1])[-1])
    pts = face_points(s, i, 1500, rng)
    setup, with_boxes = _pair_values(s, i, j, pts, True)
    assert np.any(setup.kernel["poly_box"] >= 0)  # the rule is used
    _, one_by_one = _pair_values(s, i, j, pts, False)
    assert np.abs(with_boxes - one_by_one).max() <= 1e-12
    assert np.any(one_by_one > 1e-3)  # something is hidden


def test_pair_kernel_drops_holes_in_a_box_shadow(office60, rng):
    """Ceiling → floor with the floor's covered cells (under cabinets and desk panels) as
    holes: inside a box's shadow they are left out of the visible part (on its boundary
    within 1e-12 of its size); equal to every face and hole swept on its own to 1e-12."""
    s = office60
    i, j = int(s.group_faces("ceiling")[0]), int(s.group_faces("floor")[0])
    assert len(ff.covered_cells(s, j, 1)) >= 6
    pts = face_points(s, i, 1500, rng)
    _, a = _pair_values(s, i, j, pts, True, holes=True)
    _, b = _pair_values(s, i, j, pts, False, holes=True)
    assert np.abs(a - b).max() <= 1e-12


def test_pair_kernel_boxes_on_a_floor(boxes_on_floor, rng):
    """Rotated boxes standing on a floor: floor → every face of two boxes (their back faces
    included, seen through the box: all hidden), 1,000 points each."""
    s = boxes_on_floor
    face_box = ff.closed_boxes(s)[0]
    for j in np.flatnonzero(face_box == face_box[1])[:6].tolist() + [int(np.flatnonzero(face_box == face_box[7])[0])]:
        pts = face_points(s, 0, 1000, rng)
        setup = ff.PairSetup(s, 0, 1, ff.face_target(s, j), 1)
        if setup.empty or not setup.occluders:
            continue
        _, a = _pair_values(s, 0, j, pts, True)
        _, b = _pair_values(s, 0, j, pts, False)
        assert np.abs(a - b).max() <= 1e-12


def _views(scene, face, points, boxes):
    n_i = scene.face_normal[face]
    eu, ev = plane_basis(n_i)
    extra = ff.closed_boxes(scene) if boxes else ff.no_boxes(scene.n_faces)
    return point_views(points, n_i, eu, ev, *ff.scene_polygons(scene), face, 1e-9 * scene.diagonal, *extra)


@pytest.mark.parametrize("group", ["floor", "wall_north", "ceiling"])
def test_point_views_without_back_faces_equal(office60, group, rng):
    """point_views not sweeping back faces of boxes: every column (their own included: all of
    their F hidden) and the sky equal to 1e-12 at 1,000 points."""
    face = int(office60.group_faces(group)[0])
    pts = face_points(office60, face, 1000, rng)
    a, b = _views(office60, face, pts, True), _views(office60, face, pts, False)
    assert np.abs(a - b).max() <= 1e-12


def test_point_views_from_a_box_face(boxes_on_floor, rng):
    """From a box's own faces, outside and inside (its back side, into the box): the box is
    never culled from a point on it (not strictly outside), other boxes are. Equal to
    1e-13: swept, a far box's back face meets its front face along an edge seen nearly
    edge-on (a sliver thinner than 1e-7), and the tie rule of faces lying on faces gave
    the sliver to the smaller, the back face (seen -4.1e-13 at point 18 of the box's top),
    until it was kept to faces in one plane (:func:`viscx.geometry.occlusion._nearest`)."""
    s = boxes_on_floor
    face_box = ff.closed_boxes(s)[0]
    for face in np.flatnonzero(face_box == face_box[1])[:3]:
        pts = face_points(s, int(face), 500, rng)
        for side in (1, -1):
            n_i = side * s.face_normal[face]
            eu, ev = plane_basis(n_i)
            args = (pts, n_i, eu, ev, *ff.scene_polygons(s), int(face), 1e-9 * s.diagonal)
            a = point_views(*args, *ff.closed_boxes(s))
            b = point_views(*args, *ff.no_boxes(s.n_faces))
            assert np.abs(a - b).max() <= 1e-13


@pytest.mark.parametrize("group,side", [("floor", 1), ("ceiling", 1), ("back_wall", 1), ("left_wall", 1), ("light", 1),
                                        ("short_block", 1), ("short_block", -1), ("tall_block", 1)])
def test_point_views_open_boxes_equal(cornell, group, side, rng):
    """The Cornell blocks as open boxes (their back faces not swept from a point above the
    floor, outside them): every column and the sky equal to every face swept on its own, to
    1e-12 at 300 points of each emitter (a block's faces: the top, from outside and from
    inside the block); the rule is used at them for every box but their own."""
    s = cornell
    face = int(s.group_faces(group)[0])
    pts = face_points(s, face, 300, rng)
    n_i = side * s.face_normal[face]
    eu, ev = plane_basis(n_i)
    args = (pts, n_i, eu, ev, *ff.scene_polygons(s), face, 1e-9 * s.diagonal)
    a = point_views(*args, *ff.closed_boxes(s))
    b = point_views(*args, *ff.no_boxes(s.n_faces))
    assert np.abs(a - b).max() <= 1e-12
    face_box, ptr, planes = ff.closed_boxes(s)
    outside = np.array([[_outside_box(x, n_i, planes, ptr[k], ptr[k + 1], 1e-9 * s.diagonal) for k in range(2)] for x in pts])
    for k in range(2):  # never its own box (a point on it is not strictly outside); the other's
        assert outside[:, k].any() == (face_box[face] != k)


def test_open_box_rule_holds_on_its_side_only(open_box_above_floor, rng):
    """A box open at its bottom, floating: from the ceiling (above the missing face's plane)
    it is a closed box; from the floor (below it) its inside is seen through the open
    bottom, so its back faces must be swept: both equal to every face swept on its own
    (1e-12), and without the open plane's condition the floor's views are wrong (its far
    sides' inner faces hidden)."""
    s = open_box_above_floor
    tiny = 1e-9 * s.diagonal
    boxes = ff.closed_boxes(s)
    for face in (0, 1):
        pts = face_points(s, face, 300, rng)
        n_i = s.face_normal[face]
        eu, ev = plane_basis(n_i)
        args = (pts, n_i, eu, ev, *ff.scene_polygons(s), face, tiny)
        a = point_views(*args, *boxes)
        b = point_views(*args, *ff.no_boxes(s.n_faces))
        assert np.abs(a - b).max() <= 1e-12
        assert np.any(b[:, 4:14] > 1e-3)  # something of the box is hidden
        ungated = boxes[2].copy()
        ungated[:, 4] = 0.0  # the missing face's plane taken as a real one: x beyond it is outside
        c = point_views(*args, boxes[0], boxes[1], ungated)
        assert (np.abs(c - b).max() > 1e-3) == (face == 0)
    # the cubature's triangles: from the ceiling the box's back faces are dropped, from the
    # floor (below the open plane) none
    tri = np.array([[[0, 3, 0], [3, 3, 0], [0, 3, 3]], [[0, 0, 0], [3, 0, 0], [0, 0, 3]]], np.float64)
    faces = np.arange(2, 7)
    down, up = np.array([0.0, -1.0, 0.0]), np.array([0.0, 1.0, 0.0])
    assert ff.back_faces(s, tri[:1], np.zeros(5, np.int64), faces, tiny, down).any()
    assert not ff.back_faces(s, tri[1:], np.zeros(5, np.int64), faces, tiny, up).any()


def test_back_faces_rule(office60):
    """back_faces drops (triangle, face) pairs only where every point of the triangle is
    outside the face's box and behind the face, and drops some on the floor's triangles
    (the far sides of desks and cabinets); a triangle under a box (on its bottom's plane,
    inside its outline) or straddling one of its planes drops nothing of that box."""
    s = office60
    tiny = 1e-9 * s.diagonal
    floor = int(s.group_faces("floor")[0])
    face_box, ptr, planes = ff.closed_boxes(s)
    boxed = np.flatnonzero(face_box >= 0)
    rng = np.random.default_rng(0)
    centers = face_points(s, floor, 400, rng)
    tri = centers[:, None, :] + 0.05 * rng.normal(size=(400, 3, 3)) * np.array([1, 0, 1])
    cell = np.repeat(np.arange(len(tri)), len(boxed))
    faces = np.tile(boxed, len(tri))
    up = s.face_normal[floor]
    drop = ff.back_faces(s, tri, cell, faces, tiny, up)
    assert drop.sum() > 0.2 * len(tri) * len(set(face_box[boxed].tolist()))
    # brute force on the triangles' points: each dropped face is behind, its box in front
    w = rng.dirichlet([1, 1, 1], 50)
    for c in np.flatnonzero(drop)[::7]:
        pts = w @ tri[cell[c]]
        f, b = faces[c], face_box[faces[c]]
        assert np.all(pts @ s.face_normal[f] - s.face_offset[f] < 0)
        h = pts @ planes[ptr[b]:ptr[b + 1], :3].T - planes[ptr[b]:ptr[b + 1], 3]
        on_floor = planes[ptr[b]:ptr[b + 1], :3] @ up < TURNED_OVER  # a bottom: no way in from the floor
        assert np.all(np.any(h > 2 * tiny, axis=1)) and not np.any((h > 0) & (h <= 2 * tiny) & ~on_floor)
    # a triangle under a cabinet (inside its footprint): nothing of it
    cab = np.flatnonzero(s.face_group == s.group_names.index("cabinet0"))
    bottom = cab[np.argmin(s.face_normal[cab, 1])]
    c0 = s.face_loops(bottom)[0].mean(axis=0)
    under = (c0 + 0.01 * np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1.0]]))[None]
    assert not ff.back_faces(s, under, np.zeros(len(cab), np.int64), cab, tiny, up).any()


def test_back_faces_of_a_many_faced_solid_in_bounded_memory():
    """An icosphere of 5,120 faces above a floor is one closed convex box
    (:func:`viscx.queries.formfactor.closed_boxes`). back_faces used to test every
    (triangle, face) pair against all of its box's planes at once, (pairs, planes, 5)
    float64: 21 GB for these 20 floor triangles against the sphere (and 36.7 GB, a
    MemoryError, for a light → the floor in a room of six 20,480-face spheres, where 10⁷
    rays take seconds). Now the box's planes once per (triangle, box) pair, in blocks of
    :data:`PLANE_BLOCK`: the same answers as the rule per pair (the faces behind which the
    whole triangle lies, of a box it is outside of), in a few MB (tracemalloc)."""
    import resource
    import tracemalloc

    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    v = np.concatenate([sphere.vertices + [0.0, 2.0, 0.0], [[-5, 0, -5], [-5, 0, 5], [5, 0, 5], [5, 0, -5]]])
    polygons = sphere.faces.tolist() + [[len(v) - 4, len(v) - 3, len(v) - 2, len(v) - 1]]
    scene = build_scene(soup(v, polygons, [0] * len(sphere.faces) + [1], ["sphere", "floor"]))
    face_box, ptr, planes = ff.closed_boxes(scene)
    faces = np.flatnonzero(face_box >= 0)
    assert len(ptr) == 2 and len(faces) == len(sphere.faces) == ptr[1]
    rng = np.random.default_rng(1)
    corner = rng.uniform(-4, 4, (20, 3)) * [1, 0, 1]
    # small: the traces of 5,120 planes on the floor are dense, and a triangle straddling
    # one of them drops nothing of the sphere
    tri = corner[:, None, :] + [[0, 0, 0], [1e-3, 0, 0], [0, 0, 1e-3]]
    cell, pair_faces = np.repeat(np.arange(20), len(faces)), np.tile(faces, 20)
    tiny = 1e-9 * scene.diagonal
    # (the dense version would ask for ~10 GB: a MemoryError under a limit 1 GB above what
    # this process maps now, not the machine's out-of-memory killer)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/status") as status:
        mapped = next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmSize:"))
    limit = mapped + (1 << 30)
    resource.setrlimit(resource.RLIMIT_AS, (limit if hard == resource.RLIM_INFINITY else min(limit, hard), hard))
    tracemalloc.start()
    try:
        drop = ff.back_faces(scene, tri, cell, pair_faces, tiny, np.array([0.0, 1.0, 0.0]))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
    assert peak < 64e6, peak
    # the rule, per pair: behind the face; each plane of the box with the whole triangle on
    # or behind it, or more than 2 tiny in front (one at least)
    h = np.einsum("gvj,pj->gpv", tri, planes[:, :3]) - planes[:, 3][None, :, None]  # (20, planes, 3)
    front = np.all(h > 2 * tiny, axis=2)
    outside = np.all(front | np.all(h <= 0, axis=2), axis=1) & np.any(front, axis=1)  # (20,)
    own = np.einsum("cvj,cj->cv", tri[cell], scene.face_normal[pair_faces]) - scene.face_offset[pair_faces][:, None]
    assert np.array_equal(drop, outside[cell] & np.all(own < -tiny, axis=1))
    dropped = np.bincount(cell[drop], minlength=20)
    assert np.sum(dropped > len(faces) // 4) >= 10  # the sphere's far side from most triangles


@pytest.fixture(scope="module")
def sphere_under_light():
    """An icosphere of 1,280 faces (one closed convex box) between a 10 × 10 floor (y = 0,
    facing up) and a 2 × 2 light (y = 5, facing down), off the light's axis so that its
    shadow falls partly on the floor's edge."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    v = np.concatenate([sphere.vertices + [3.5, 2.5, 0.5], [[-5, 0, -5], [-5, 0, 5], [5, 0, 5], [5, 0, -5]],
                        [[-1, 5, -1], [1, 5, -1], [1, 5, 1], [-1, 5, 1]]])
    n = len(sphere.vertices)
    polygons = sphere.faces.tolist() + [[n, n + 1, n + 2, n + 3], [n + 4, n + 5, n + 6, n + 7]]
    return build_scene(soup(v, polygons, [0] * len(sphere.faces) + [1, 2], ["sphere", "floor", "light"]))


def test_a_many_faced_box_is_swept_as_its_outline(sphere_under_light, monkeypatch, rng):
    """A closed convex box of more than :data:`HULL_BOX_FACES` faces (a tessellated or
    scanned convex solid) is swept by the pair kernel as the outline of its front faces,
    not as the hull of all its faces' projections (whose points grow with the faces: a
    20,480-face sphere took 1.1 s a point, now 2 ms). Three different sweeps of the same
    shadow agree to 1e-12 at 300 points of the light: the outline, the hull, and every
    face on its own."""
    s = sphere_under_light
    light, floor = int(s.group_faces("light")[0]), int(s.group_faces("floor")[0])
    pts = face_points(s, light, 300, rng)
    setup, outline = _pair_values(s, light, floor, pts, True)
    sphere = setup._occluder_faces < int(s.group_faces("floor")[0])
    assert sphere.sum() > 100 and np.all(setup.kernel["poly_solid"][sphere] >= 0)
    monkeypatch.setattr(ff, "HULL_BOX_FACES", 10 ** 6)
    setup, hull = _pair_values(s, light, floor, pts, True)
    assert np.all(setup.kernel["poly_solid"] < 0) and np.all(setup.kernel["poly_box"][sphere] >= 0)
    _, one_by_one = _pair_values(s, light, floor, pts, False)
    assert np.abs(outline - one_by_one).max() <= 1e-12
    assert np.abs(hull - one_by_one).max() <= 1e-12
    assert np.all(one_by_one > 0) and np.any(one_by_one > 1e-2)  # the sphere hides some of the floor from every point


@pytest.mark.parametrize("name", ["office60", "cornell", "sphere_under_light"])
def test_face_loops_oriented_at_once_equal_face_by_face(name, request):
    """:func:`face_loops_oriented` and :func:`loop_normal_dots` (all loops at once, numpy by
    loop length) give the same bits as :func:`oriented_loops`, :func:`loops_area` and
    :func:`newell_normal` face by face; :func:`newell_normals` too on loops of 3 to 12
    points (numpy sums 8 terms and more pairwise: the rows of one loop are added in order)."""
    from viscx.geometry.polygon import newell_normal, newell_normals

    s = request.getfixturevalue(name)
    areas, loops = ff.face_loops_oriented(s)
    for k in range(s.n_faces):
        want = ff.oriented_loops(s.face_loops(k), s.face_normal[k])
        assert len(loops[k]) == len(want) and all(np.array_equal(a, b) for a, b in zip(loops[k], want))
        assert areas[k] == abs(ff.loops_area(want, s.face_normal[k]))
    lo = s.loop_offsets
    dots = [newell_normal(s.vertices[s.loop_vertices[lo[j]:lo[j + 1]]]) @ s.face_normal[np.searchsorted(
        s.face_loop_offsets, j, "right") - 1] for j in range(len(lo) - 1)]
    assert np.array_equal(ff.loop_normal_dots(s), dots)
    rng = np.random.default_rng(2)
    sizes = rng.integers(3, 13, 200)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    pts = rng.normal(size=(offsets[-1], 3)) * 1e3
    want = np.array([newell_normal(pts[offsets[j]:offsets[j + 1]]) for j in range(len(sizes))])
    assert np.array_equal(newell_normals(pts, offsets), want)


def test_convex_hull_of_many_points():
    """The kernel's 2-D hull (Andrew's monotone chain) above :data:`HULL_INSERTION` points
    sorts them by merge sort: the same hull as scipy's Qhull, counter-clockwise, on
    thousands of points with repeats, and on a few dozen (insertion sort)."""
    from scipy.spatial import ConvexHull

    from viscx.geometry.occlusion import HULL_INSERTION, _convex_hull

    rng = np.random.default_rng(3)
    for n in (HULL_INSERTION - 5, HULL_INSERTION + 1, 5000):
        pts = rng.normal(size=(n, 2))
        pts[: n // 10] = pts[n // 2: n // 2 + n // 10]  # repeated points
        work, out = pts.copy(), np.empty(n + 1, np.int64)
        m = _convex_hull(work, n, out)
        got = work[out[:m]]
        want = pts[ConvexHull(pts).vertices]  # counter-clockwise
        assert m == len(want)
        first = int(np.flatnonzero(np.all(want == got[0], axis=1))[0])
        assert np.array_equal(np.roll(want, -first, axis=0), got)


def test_cubature_with_back_face_culling_equals_without(office60, monkeypatch):
    """The pair cubature with the triangles' back faces dropped gives the same F (the
    integrand is the same at every point) and needs shorter lists."""
    s = office60
    i, j = int(s.group_faces("desk0")[0]), int(s.group_faces("floor")[0])
    lengths = []
    real = ff.PairSetup.blocked

    def blocked(self, points, group, ptr, ids):
        lengths.append(len(ids))
        return real(self, points, group, ptr, ids)

    monkeypatch.setattr(ff.PairSetup, "blocked", blocked)
    with_rule = ff.pair_form_factor(s, i, 1, ff.face_target(s, j), 1, tol=1e-3)
    culled = sum(lengths)
    lengths.clear()
    monkeypatch.setattr(ff, "back_faces", lambda scene, tri, cell, faces, tiny, n_i: np.zeros(len(cell), bool))
    without = ff.pair_form_factor(s, i, 1, ff.face_target(s, j), 1, tol=1e-3)
    assert with_rule.method == "quadrature"
    assert abs(with_rule.F - without.F) <= 1e-12
    assert culled < sum(lengths)


def test_an_open_box_is_closed_only_by_a_face_it_stands_on(cornell, open_box_above_floor):
    """An open box is never :func:`empty_boxes`'s (its inner sides see out through the missing
    face); it is closed by a face only where its missing face lies wholly on it
    (:func:`box_caps`). The Cornell blocks stand on the floor: each is capped by the floor's
    front over its footprint, and their inner rows are closed forms
    (tests/test_formfactor_closed.py checks them). A box floating above the floor is not
    capped, and its inner rows go the general way."""
    face_box = ff.closed_boxes(cornell)[0]
    assert (face_box >= 0).sum() == 10 and not ff.empty_boxes(cornell).any()
    caps = ff.box_caps(cornell)
    assert len(caps) == 2 and all(c is not None and c[:2] == (0, 1) for c in caps)
    faces = np.arange(cornell.n_faces)
    for f in np.flatnonzero(face_box >= 0):
        row = ff.closed_form_row(cornell, int(f), -1, faces)
        assert row is not None and 0 in row[0] and row[4] == 0.0
    s = open_box_above_floor
    assert ff.box_caps(s) == [None] and not ff.empty_boxes(s).any()
    for f in s.group_faces("box"):
        assert ff.closed_form_row(s, int(f), -1, np.arange(s.n_faces)) is None


def test_covered_cells_under_a_box_need_no_hole(office60, rng):
    """A covered cell under an empty closed box standing on the target is hidden by the box
    from every point of another face (``target_holes``): without it as a hole the pair
    kernel's hidden part grows by exactly the cell's unoccluded F at every point (the box
    hides all of it), so the pair's F is unchanged. A face of that box keeps its holes."""
    from viscx.geometry.formfactor import point_to_polygon

    s = office60
    i, j = int(s.group_faces("ceiling")[0]), int(s.group_faces("floor")[0])
    covered = ff.covered_cells(s, j, 1)
    assert len(covered) >= 6 and ff.target_holes(s, i, j, 1) == []
    pts = face_points(s, i, 800, rng)
    _, with_holes = _pair_values(s, i, j, pts, True, holes=True)
    _, without = _pair_values(s, i, j, pts, True, holes=False)
    n = np.ascontiguousarray(np.broadcast_to(s.face_normal[i], (len(pts), 3)))
    cells_f = sum(point_to_polygon(pts, n, [c]) for c in covered)
    assert np.abs(without - with_holes - cells_f).max() <= 1e-12
    assert cells_f.max() > 1e-3
    # the box's own face (a cabinet's top, emitting from its inner side) keeps the holes
    face_box = ff.closed_boxes(s)[0]
    _, elements = ff.contact_cells(s, j, 1)
    k = int(elements[0] // 2)
    own = np.flatnonzero(face_box == face_box[k])
    assert len(ff.target_holes(s, int(own[own != k][0]), j, 1)) >= 1


def _clip_half_plane(poly, n, c):
    """The part of the 2-D polygon ``poly`` (k, 2) with n · y <= c (Sutherland–Hodgman)."""
    out = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        ha, hb = n @ a - c, n @ b - c
        if ha <= 0:
            out.append(a)
        if (ha < 0) != (hb < 0) and ha != hb:
            out.append(a + (b - a) * ha / (ha - hb))
    return np.array(out)


@pytest.mark.parametrize("sweep", [0, 2])
def test_point_views_steep_edge_against_the_shadow(boxes_on_floor, sweep):
    """A point of a box's side from which an edge of the floor projects nearly vertical in
    one of point_views' wedges (dv/du ~ 2e6), crossed by the edges of a panel standing on
    the floor: what the panel hides of the floor is its shadow from x (the panel's foot and
    the rays from x's foot through its ends: its top is above x), clipped to the floor, F by
    Lambert's contour sum. The sweep placed the steep edge's runs by their rounded u: 5e-12
    off, until the wedge's 2-D basis is turned away from steep edges (STEEP). Both sweeps
    (``sweep_kind`` 2: the output-sensitive one, used from SWEEP_RUNS_FROM edges)."""
    s = boxes_on_floor
    emitter, panel = 2, 18
    x = np.array([4.020630893958552, 2.0074638197203583, 3.627165377330768])
    n_i = s.face_normal[emitter]
    eu, ev = plane_basis(n_i)
    floor = s.face_loops(0)[0]
    assert np.allclose(floor[:, 1], 0) and np.ptp(floor[:, 0]) == np.ptp(floor[:, 2]) == 14.0
    # the premise: an edge of the floor clipped to a wedge is steep there (|dv/du| > 1e5)
    frames, planes = _wedges(n_i, eu, ev)
    steep = 0.0
    for (fa, fb, fc), pl in zip(frames, planes):
        buf = np.empty((12, 3))
        k = _clip_to_frustum(floor, 0, 4, x, pl, 3, buf, np.empty((12, 3)))
        d = buf[:k] - x
        uv = np.c_[d @ fa, d @ fb] / (d @ fc)[:, None]
        du, dv = (np.roll(uv, -1, axis=0) - uv).T
        steep = max([steep, *np.abs(dv / du)])
    assert steep > 1e5
    # the panel: a quad standing on the floor, wholly in front of x, its top above x
    quad = s.face_loops(panel)[0]
    assert len(quad) == 4 and np.all((quad - x) @ n_i > 0) and quad[:, 1].max() > x[1]
    foot = quad[quad[:, 1] == 0][:, [0, 2]]
    rays = foot - x[[0, 2]]
    far = foot + 60 * rays / np.linalg.norm(rays, axis=1)[:, None]
    shadow = np.array([foot[0], foot[1], far[1], far[0]])
    for n, c in (([1, 0], 12), ([-1, 0], 2), ([0, 1], 12), ([0, -1], 2)):
        shadow = _clip_half_plane(shadow, np.array(n, float), c)
    shadow3 = np.c_[shadow[:, 0], np.zeros(len(shadow)), shadow[:, 1]]
    ref = point_to_polygon(x[None], n_i[None], [shadow3])[0]
    # the scene's floor, the panel and the emitter only (the other boxes hide more of the floor)
    keep = [0, emitter, panel]
    sub = soup(np.concatenate([s.face_loops(f)[0] for f in keep]), [[4 * k + i for i in range(4)] for k in range(3)],
               [0, 1, 2], ["floor", "emitter", "panel"])
    sub = build_scene(sub)
    h = point_views(x[None], n_i, eu, ev, *ff.scene_polygons(sub), 1, 1e-9 * sub.diagonal, *ff.closed_boxes(sub),
                    sweep)
    assert abs(h[0, 0] - ref) < 1e-14


def _facing_pairs(scene, monkeypatch):
    """Every pair of face sides that face each other by their vertices (the test of
    :func:`ff.facing_sides` without :func:`ff.box_hidden`), and which of them box_hidden
    calls hidden: ``(face, side, faces (k,), sides (k,), hidden (k,))`` per emitter side."""
    hidden_by_box = ff.box_hidden
    with monkeypatch.context() as m:
        m.setattr(ff, "box_hidden", lambda scene, face, side, faces, sides: np.zeros(len(faces), bool))
        raw = [(f, s, *ff.facing_sides(scene, f, s, np.arange(scene.n_faces))) for f in range(scene.n_faces)
               for s in (1, -1)]
    return [(f, s, fj, sj, hidden_by_box(scene, f, s, fj, sj)) for f, s, fj, sj in raw]


def _free_segments(scene, pairs, rng, k=12):
    """For pairs ``(i, s, j, t)`` of face sides, ``k`` × ``k`` segments from random points
    of side s of face i to random points of side t of face j, each point moved 1e-6 of the
    scene's size off its face to its side, the segments with each end in front of the
    other's side kept, and the points lying against another face left out (a point of the
    floor under a cabinet's bottom: moved off the floor, it would be inside the cabinet;
    docs/queries.md, "Faces lying on faces"). Returns (kept, free): how many segments, and
    how many meet no triangle of the scene (brute force, tests/oracles.py)."""
    from oracles import segment_hits_reference

    vertices = scene.vertices.astype(np.float64)
    delta = 1e-6 * scene.diagonal

    def off(face, normal):  # k points of the face moved off it, those lying on nothing
        p = face_points(scene, face, k, rng)
        others = scene.triangles[scene.triangle_face != face]
        hit, _ = segment_hits_reference(p + 2 * delta * normal, p - 2 * delta * normal, vertices, others)
        return p[~hit.any(axis=1)] + delta * normal

    starts, ends = [], []
    for i, s, j, t in pairs:
        n_i, n_t = s * scene.face_normal[i], t * scene.face_normal[j]
        x, y = off(i, n_i), off(j, n_t)
        a, b = np.repeat(x, len(y), axis=0), np.tile(y, (len(x), 1))
        ok = ((b - a) @ n_i > 0) & ((a - b) @ n_t > 0)
        starts.append(a[ok])
        ends.append(b[ok])
    starts, ends = np.concatenate(starts), np.concatenate(ends)
    free = 0
    for lo in range(0, len(starts), 4000):
        hit, _ = segment_hits_reference(starts[lo:lo + 4000], ends[lo:lo + 4000], vertices, scene.triangles)
        free += int(np.sum(~hit.any(axis=1)))
    return len(starts), free


def test_box_hidden_pairs_see_nothing(office60, monkeypatch):
    """ff.box_hidden: the inner side of a box's face and a face outside the box see nothing
    of each other. Of office60's facing pairs of sides, most are such (every desk's,
    cabinet's and divider's inner sides seen from the room, and from inside a box the
    faces outside it); on 200 of them, no segment between random points of the two sides
    is free (brute-force segment tests); on 200 pairs it does not name, some are (the
    oracle finds free segments where there are). The pair cubature returns 0 exactly for
    them, with no estimate."""
    rng = np.random.default_rng(7)
    rows = _facing_pairs(office60, monkeypatch)
    hidden = [(f, s, int(j), int(t)) for f, s, fj, sj, h in rows for j, t in zip(fj[h], sj[h])]
    seen = [(f, s, int(j), int(t)) for f, s, fj, sj, h in rows for j, t in zip(fj[~h], sj[~h])]
    assert len(hidden) > 2 * len(seen) > 1000
    # both directions of a pair are named together, and only inner sides (backs) of box faces
    named = set(hidden)
    assert all((j, t, f, s) in named for f, s, j, t in hidden)
    face_box = ff.closed_boxes(office60)[0]
    assert all((t < 0 and face_box[j] >= 0) or (s < 0 and face_box[f] >= 0) for f, s, j, t in hidden)
    pick = rng.choice(len(hidden), 200, replace=False)
    kept, free = _free_segments(office60, [hidden[k] for k in pick], rng)
    assert kept > 5000 and free == 0
    pick = rng.choice(len(seen), 200, replace=False)
    kept, free = _free_segments(office60, [seen[k] for k in pick], rng)
    assert kept > 5000 and free > 0.1 * kept
    for f, s, j, t in [hidden[k] for k in rng.choice(len(hidden), 5, replace=False)]:
        r = ff.pair_form_factor(office60, f, s, ff.face_target(office60, j), t)
        assert (r.F, r.error, r.method) == (0.0, 0.0, "none")


def pillar_room(sides=24):
    """A 20 × 20 floor at y = −5 (facing up) and a ceiling at y = 5 (facing down), with three
    closed prisms of ``sides`` sides (radius 0.6, trimesh's cylinder turned upright) standing
    on the floor up to y = −2: round columns resting on the emitter. Their bottoms' planes
    come out of the rounding of their vertices, the floor's points up to a few 1e-15 in
    front of them."""
    import trimesh

    v = [[-10, -5, -10], [-10, -5, 10], [10, -5, 10], [10, -5, -10], [-10, 5, -10], [10, 5, -10], [10, 5, 10],
         [-10, 5, 10]]
    polygons, groups = [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1]
    for k, (x, z) in enumerate(((-4.0, 1.0), (0.5, -3.0), (5.0, 2.5))):
        c = trimesh.creation.cylinder(radius=0.6, height=3.0, sections=sides)
        c.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
        p = c.vertices + [x, -3.5, z]
        p[np.abs(p[:, 1] + 5.0) < 1e-9, 1] = -5.0
        polygons += (c.faces + len(v)).tolist()
        groups += [2 + k] * len(c.faces)
        v += p.tolist()
    return build_scene(soup(v, polygons, groups, ["floor", "ceiling", "pillar0", "pillar1", "pillar2"]))


def test_a_box_resting_on_the_emitter_is_outside_from_it(rng):
    """A closed box standing on the floor, seen from the floor's points outside its
    footprint: they are outside it (:func:`_outside_box`), though rounding puts some of
    them a few 1e-15 in front of its bottom's plane, where the rule for a face seen edge-on
    (within 2 tiny in front of its plane) had said no: then its back faces were swept and
    it was no hull (three 24-sided columns: ~250 faces a point on their own; four 64-sided
    ones 2.7 ms a point, 256-sided more than 12 minutes for floor → ceiling at 1e-4). A
    face on the emitter's plane facing away from its front is no way into the box. The
    same values as every face swept on its own (pair kernel and row kernel, 1e-12 at 400
    points), the back faces dropped from the floor's triangles, and F within 4 σ of
    Monte Carlo."""
    from oracles import form_factor_monte_carlo

    s = pillar_room()
    floor, ceiling = int(s.group_faces("floor")[0]), int(s.group_faces("ceiling")[0])
    face_box, ptr, planes = ff.closed_boxes(s)
    assert len(ptr) == 4 and np.all(np.diff(ptr) == 26)
    tiny = 1e-9 * s.diagonal
    n_i = s.face_normal[floor]
    pts = face_points(s, floor, 400, rng)
    centres = np.array([[-4.0, 1.0], [0.5, -3.0], [5.0, 2.5]])
    clear = np.linalg.norm(pts[:, None, [0, 2]] - centres[None], axis=2).min(axis=1) > 0.61
    pts = np.ascontiguousarray(pts[clear])
    # the case: some floor points within (0, 2 tiny] in front of a bottom's plane
    bottoms = planes[:, :3] @ n_i < TURNED_OVER
    h = pts @ planes[bottoms, :3].T - planes[bottoms, 3]
    assert np.any((h > 0) & (h <= 2 * tiny))
    for x in pts:
        assert all(_outside_box(x, n_i, planes, ptr[b], ptr[b + 1], tiny) for b in range(3))
    # under a column (on its bottom, inside its footprint): not outside
    under = np.array([-4.0, -5.0, 1.0])
    assert not _outside_box(under, n_i, planes, ptr[0], ptr[1], tiny)
    # the pair kernel (the columns as hulls) and the row kernel (their back faces left out)
    _, hulls = _pair_values(s, floor, ceiling, pts, True)
    _, one_by_one = _pair_values(s, floor, ceiling, pts, False)
    assert np.abs(hulls - one_by_one).max() <= 1e-12 and np.any(one_by_one > 1e-3)
    eu, ev = plane_basis(n_i)
    args = (pts, n_i, eu, ev, *ff.scene_polygons(s), floor, tiny)
    a, b = point_views(*args, *ff.closed_boxes(s)), point_views(*args, *ff.no_boxes(s.n_faces))
    assert np.abs(a - b).max() <= 1e-12
    # the floor's triangles (outside the footprints) drop the columns' back faces
    tri = pts[:20, None, :] + 0.01 * np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1.0]])
    boxed = np.flatnonzero(face_box >= 0)
    cell, faces = np.repeat(np.arange(20), len(boxed)), np.tile(boxed, 20)
    drop = ff.back_faces(s, tri, cell, faces, tiny, n_i)
    assert drop.sum() >= 20 * 3 * 8
    # F against cosine-weighted rays
    r = ff.face_to_face(s, floor, ceiling, tol=1e-5)
    mc, sigma = form_factor_monte_carlo(s, [floor], 1, 2_000_000, seed=3)
    assert abs(r["F"] - mc[2 * ceiling]) <= 4 * sigma[2 * ceiling] + r["error"]  # (its front faces the floor)


def test_an_umbra_of_slivers_adds_nothing():
    """A 4 × 4 floor, a 1 × 1 light 3 above it facing down, and a closed box standing on
    the floor under the light's edge (its corners as lo + (hi − lo), one polygon of its own
    each: the far ones 2.0000000000000004): the triangles of the floor found in the box's
    umbra (their F(x → light) taken whole by the contour integral) were all slivers of the
    emitter's cuts, of no area, and the contour integral of no area was 0 / 0: floor →
    light gave F = inf at every tol. Now finite, and A_floor F = A_light F back (computed
    from the light, another cubature) within both estimates, and within 4 σ of Monte Carlo."""
    from oracles import form_factor_monte_carlo

    def rect(c, a, b):  # normal a × b
        c, a, b = (np.asarray(x, float) for x in (c, a, b))
        return [c, c + a, c + a + b, c + b]

    lo, hi = np.array([1.2, 1.0, 0.0]), np.array([2.0, 2.2, 0.9])
    X, Y, Z = np.diag(hi - lo)
    faces = [rect([0, 0, 0], [4, 0, 0], [0, 4, 0]), rect([1.5, 1.5, 3], [0, 1, 0], [1, 0, 0]),
             rect(lo, Y, X), rect(lo + Z, X, Y), rect(lo, X, Z), rect(lo + Y, Z, X), rect(lo, Z, Y), rect(lo + X, Y, Z)]
    v = [p.tolist() for f in faces for p in f]
    polygons = [list(range(4 * k, 4 * k + 4)) for k in range(len(faces))]
    s = build_scene(soup(v, polygons, [0, 1] + [2] * 6, ["floor", "light", "box"]))
    assert len(ff.closed_boxes(s)[1]) == 2
    up = ff.face_to_face(s, 0, 1, tol=1e-6)
    down = ff.face_to_face(s, 1, 0, tol=1e-6)
    assert np.isfinite(up["F"]) and np.isfinite(up["error"]) and up["error"] <= 1e-6
    assert abs(16.0 * up["F"] - 1.0 * down["F"]) <= 16.0 * up["error"] + down["error"]
    mc, sigma = form_factor_monte_carlo(s, [0], 1, 2_000_000, seed=5)
    assert abs(up["F"] - mc[2]) <= 4 * sigma[2] + up["error"]  # (the light's front faces the floor)
