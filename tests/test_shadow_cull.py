"""The row kernel's shadow cull (viscx.geometry.occlusion._cull_shadowed, _in_shadow):
``point_views`` leaves out of its sweep every face that lies in the shadow of a closed
convex box from the point. A face it leaves out must be seen nowhere: the kernel with the
cull must give what it gives with every face swept (``cull_from`` beyond the scene), and
the faces around an occluder that are seen — peeking past its outline by a sliver, touching
it and reaching out of its shadow, lying on its front face, above the plane of its top
face from a point in that plane — must never be left out."""

import numpy as np
import pytest
from conftest import soup
from random_scenes import random_boxes

from viscx.geometry.formfactor import point_to_polygon
from viscx.geometry.occlusion import _cull_shadowed, _spheres, point_views
from viscx.geometry.polygon import plane_basis
from viscx.queries import formfactor as ff
from viscx.scene import build_scene

NEVER = 1 << 40  # cull_from: no point has that many faces to sweep


def _box(v, lo, hi):
    """The six quads of the box [lo, hi] (normals outward), appended to the vertex list v."""
    base = len(v)
    v += [[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]

    def c(i, j, k):
        return base + 4 * i + 2 * j + k

    return [[c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)], [c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)],
            [c(0, 0, 0), c(1, 0, 0), c(1, 0, 1), c(0, 0, 1)], [c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)],
            [c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)], [c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)]]


def _quad(v, corners):
    v += corners
    return [list(range(len(v) - 4, len(v)))]


#: The faces of the occluder scene around the box O = [0, 1] × [1, 2] × [0, 1] (y up).
FACES = ["ceiling", "wall", "floor", "A", "B", "C", "D", "E", "G", "H"]


@pytest.fixture(scope="module")
def occluder_scene():
    """Seen from X = (0.5, 4, 0.5) on the ceiling (above O's centre), O's shadow in the plane
    y = h is the square of half-width 0.5 (4 − h) / 2 about (0.5, 0.5): A (y = 0) lies in
    it; B (y = 0.5) reaches 1e-3 past its edge at x = 1.375; C hangs from O's bottom face,
    inside; D hangs from it too and reaches out beyond x = 1.5; E lies on O's top face.
    Seen from W = (3, 2, 0.5) on the wall, in the plane of O's top face: G (x = −1) reaches
    up to that plane, y = 2 (seen along a line only); H (x = −1.5) 1e-3 above it."""
    v, polys = [], []
    polys += _quad(v, [[-3, 4, -3], [4, 4, -3], [4, 4, 4], [-3, 4, 4]])  # ceiling, facing down
    polys += _quad(v, [[3, 0, -3], [3, 0, 4], [3, 4, 4], [3, 4, -3]])  # wall x = 3, facing -x
    polys += _quad(v, [[-3, -1, -3], [-3, -1, 4], [4, -1, 4], [4, -1, -3]])  # floor, facing up
    polys += _quad(v, [[-0.4, 0, -0.4], [-0.4, 0, 1.4], [1.4, 0, 1.4], [1.4, 0, -0.4]])  # A
    polys += _quad(v, [[0.0, 0.5, 0.2], [0.0, 0.5, 0.8], [1.376, 0.5, 0.8], [1.376, 0.5, 0.2]])  # B
    polys += _quad(v, [[0.2, 0.6, 0.45], [0.8, 0.6, 0.45], [0.8, 1.0, 0.45], [0.2, 1.0, 0.45]])  # C
    polys += _quad(v, [[0.8, 0.6, 0.55], [1.6, 0.6, 0.55], [1.6, 1.0, 0.55], [0.8, 1.0, 0.55]])  # D
    polys += _quad(v, [[0.2, 2, 0.2], [0.2, 2, 0.4], [0.4, 2, 0.4], [0.4, 2, 0.2]])  # E
    polys += _quad(v, [[-1, 1.2, 0.2], [-1, 2.0, 0.2], [-1, 2.0, 0.8], [-1, 1.2, 0.8]])  # G
    polys += _quad(v, [[-1.5, 1.2, 0.2], [-1.5, 2.001, 0.2], [-1.5, 2.001, 0.8], [-1.5, 1.2, 0.8]])  # H
    polys += _box(v, [0, 1, 0], [1, 2, 1])  # O
    return build_scene(soup(v, polys, list(range(len(FACES))) + [len(FACES)] * 6, FACES + ["O"]))


def _face(scene, name):
    return int(scene.group_faces(name)[0])


def _args(scene, face, points):
    n_i = scene.face_normal[face]
    eu, ev = plane_basis(n_i)
    return (np.ascontiguousarray(points, np.float64), n_i, eu, ev, *ff.scene_polygons(scene), face,
            1e-9 * scene.diagonal, *ff.closed_boxes(scene))


def _culled(scene, face, x):
    """The names of the faces :func:`_cull_shadowed` leaves out from x (every face but the
    emitter offered)."""
    pts, lo, hi, poly, *_ = ff.scene_polygons(scene)
    poly_box, ptr, planes = ff.closed_boxes(scene)
    P, nb = scene.n_faces, len(ptr) - 1
    first = np.searchsorted(poly, np.arange(P + 1)).astype(np.int64)
    sweep = np.ones(P, bool)
    sweep[face] = False
    poly_o, box_o, box_r = _spheres(pts, lo, hi, first, poly_box, nb)
    k = int(np.diff(ptr).max())
    n_i = np.asarray(scene.face_normal[face], np.float64)
    _cull_shadowed(np.asarray(x, np.float64), n_i, sweep, pts, lo, hi, first, poly_box, poly_o, ptr, planes, box_o, box_r,
                   np.zeros(nb + 1, np.int64), 1e-9 * scene.diagonal, np.ones(nb), np.empty(len(planes)),
                   np.empty(nb, np.int64), np.empty((nb, 5)), np.empty(k), np.empty(k))
    names = scene.group_names
    return {names[scene.face_group[p]] for p in np.flatnonzero(~sweep) if p != face}


def _seen(scene, face, x, hidden, name):
    """What x sees of a face: its unoccluded F (exact) less the kernel's hidden part."""
    j = _face(scene, name)
    n_i = scene.face_normal[face]
    loops = scene.face_loops(j)
    front = scene.face_normal[j] @ (x - loops[0][0]) > 0
    return point_to_polygon(x, n_i, loops)[0] - hidden[2 * j + (0 if front else 1)]


def _with_and_without(scene, face, k, rng):
    """The largest difference of ``point_views`` with the cull from without it at k random
    points of the face, and the points."""
    tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
    w = rng.dirichlet([1, 1, 1], k)
    pts = np.einsum("gk,gkd->gd", w, tri[rng.integers(0, len(tri), k)])
    a = point_views(*_args(scene, face, pts), cull_from=0)
    b = point_views(*_args(scene, face, pts), cull_from=NEVER)
    return np.abs(a - b).max(), pts


def test_the_cull_leaves_out_the_hidden_faces_only(occluder_scene):
    """From X: A and C (and O's back faces' neighbours below) are left out, B (a 1e-3 sliver
    past the shadow's edge), D (touching O, reaching out), E (lying on O's top face) are kept,
    and each is seen as the test says; from W, in the plane of O's top face: G (up to that
    plane) left out, H (1e-3 above it) kept. The kernel gives the same with the cull and
    with every face swept."""
    s = occluder_scene
    ceiling, wall = _face(s, "ceiling"), _face(s, "wall")
    X, W = np.array([0.5, 4.0, 0.5]), np.array([3.0, 2.0, 0.5])
    out = _culled(s, ceiling, X)
    assert {"A", "C"} <= out and not out & {"B", "D", "E", "floor", "wall"}
    out = _culled(s, wall, W)
    assert "G" in out and not out & {"H", "floor", "ceiling"}  # (E: in W's plane, seen edge-on)
    for face, x in ((ceiling, X), (wall, W)):
        h = point_views(*_args(s, face, x[None]), cull_from=0)[0]
        h_all = point_views(*_args(s, face, x[None]), cull_from=NEVER)[0]
        assert np.abs(h - h_all).max() <= 1e-13
        if face == ceiling:
            assert abs(_seen(s, face, x, h, "A")) <= 1e-14 and abs(_seen(s, face, x, h, "C")) <= 1e-14
            for name in ("B", "D", "E"):
                assert _seen(s, face, x, h, name) > 1e-7, name
        else:
            assert abs(_seen(s, face, x, h, "G")) <= 1e-14
            assert _seen(s, face, x, h, "H") > 1e-8


@pytest.mark.parametrize("emitter", ["ceiling", "wall", "floor"])
def test_the_cull_changes_nothing_around_an_occluder(occluder_scene, emitter, rng):
    """500 points of each emitter, the box's shadow falling on and past the faces around it:
    every column and the sky the same with the cull as with every face swept (1e-13)."""
    assert _with_and_without(occluder_scene, _face(occluder_scene, emitter), 500, rng)[0] <= 1e-13


def test_the_cull_on_the_office_and_rotated_boxes(office60, rng):
    """office(60) from its floor, a wall, a desk top and a cabinet's side, and rotated boxes
    on a floor from the floor and a box's face: the same with the cull as without (1e-13),
    and the cull leaves faces out (the test is not empty)."""
    boxes = build_scene(random_boxes(np.random.default_rng(5), 8, axis_aligned=False, on_floor=True))
    cases = [(office60, _face(office60, g)) for g in ("floor", "wall_north", "desk0", "cabinet0")] + [(boxes, 0), (boxes, 3)]
    left_out = 0
    for s, face in cases:
        diff, pts = _with_and_without(s, face, 200, rng)
        assert diff <= 1e-13
        left_out += sum(len(_culled(s, face, x)) for x in pts[:20])
    assert left_out > 100
