"""Sides inside a closed room (viscx.queries.formfactor.enclosed_sides) see no sky, and the
matrix takes a row's single pair from its sum (summation_column, assemble_matrix).

Oracles: embree rays (tests/oracles.py: cosine-weighted rays from area-uniform points of
a side, first hits counted) for the sky — no ray from an enclosed side may leave the
scene, and a side poking out of the room must see some sky; the exact contour integral in
an empty room and the pair cubature at a tight tolerance in a furnished one for the entry
a row's sum gives."""

import sys

import numpy as np
import pytest
from conftest import ROOT, soup
from oracles import form_factor_monte_carlo

from viscx.queries import formfactor as ff
from viscx.scene import build_scene

sys.path.insert(0, str(ROOT / "benchmarks"))
from buildings import furnished_room  # noqa: E402


def _box(v, lo, hi, inward=False):
    """The six quads of the box [lo, hi], normals outward (or inward), appended to ``v``."""
    base = len(v)
    v += [[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]

    def c(i, j, k):
        return base + 4 * i + 2 * j + k

    quads = [[c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)], [c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)],
             [c(0, 0, 0), c(1, 0, 0), c(1, 0, 1), c(0, 0, 1)], [c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)],
             [c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)], [c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)]]
    return [q[::-1] for q in quads] if inward else quads


def _quad(v, corners):
    v += corners
    return list(range(len(v) - 4, len(v)))


#: faces of the room scene: the room [0, 4] × [0, 3] × [0, 3] (normals in: 0 x=0, 1 x=4,
#: 2 y=0 the floor, 3 y=3 the ceiling, 4 z=0, 5 z=3), a cube on the floor (6–11), a panel
#: hanging in the room (12), a panel poking out through the wall x = 4 (13), a poster on
#: the wall z = 0, its front facing the room (14)
def _room(ceiling=True, poster=(0.0, 0.0)):
    v, polys = [], []
    polys += _box(v, (0, 0, 0), (4, 3, 3), inward=True)
    polys += _box(v, (1, 0, 1), (2, 1, 2))
    polys.append(_quad(v, [[2.5, 1.5, 0.5], [3.5, 1.5, 0.5], [3.5, 1.5, 2.5], [2.5, 1.5, 2.5]]))
    polys.append(_quad(v, [[3.0, 2.0, 1.0], [5.0, 2.0, 1.0], [5.0, 2.0, 2.0], [3.0, 2.0, 2.0]]))
    polys.append(_quad(v, [[1.0, 1.0, poster[0]], [2.0, 1.0, poster[0]], [2.0, 2.0, poster[1]], [1.0, 2.0, poster[1]]]))
    if not ceiling:
        del polys[3]
    return build_scene(soup(v, polys))


def test_enclosed_sides_of_a_room():
    """Both sides of the cube's faces and of the hanging panel, the room's inner sides and
    the poster's front are enclosed; the room's outer sides, the panel poking out, the
    poster's back and the cube's bottom's front (they face into the wall, the floor) are
    not; with the ceiling gone, nothing is."""
    scene = _room()
    assert np.allclose(scene.face_normal[2], [0, 1, 0]) and np.allclose(scene.face_normal[14], [0, 0, 1])
    got = ff.enclosed_sides(scene).reshape(-1, 2)  # (face, front / back)
    want = np.zeros((15, 2), bool)
    want[:6, 0] = True  # the room's inner sides (normals point in)
    want[6:13] = True
    want[14, 0] = True
    want[8, 0] = False  # the cube's bottom, its normal down into the floor
    assert (got == want).all(), np.argwhere(got != want).tolist()
    assert not ff.enclosed_sides(_room(ceiling=False)).any()


def test_a_face_crossing_a_wall_plane_by_less_than_tiny_is_not_enclosed():
    """The poster tilted through its wall's plane, from 0.5 tiny behind it to 2 tiny in
    front (tiny = 1e-9 of the scene's size): not in the plane, every vertex within tiny of
    the room, but a fifth of it lies outside and sees the sky past the wall; neither of its
    sides is enclosed. Tilted the other way (0 to 2 tiny, all in front) its front is."""
    tiny = 1e-9 * _room().diagonal
    crossing = ff.enclosed_sides(_room(poster=(-0.5 * tiny, 2 * tiny))).reshape(-1, 2)
    assert not crossing[14].any()
    assert crossing[12].all()  # the hanging panel is unaffected
    ahead = ff.enclosed_sides(_room(poster=(0.0, 2 * tiny))).reshape(-1, 2)
    assert ahead[14].all()  # not in the plane (2 tiny off): strictly inside, both sides


def test_enclosed_sides_see_no_sky_by_rays():
    """No ray of 4,000 from each enclosed side leaves the room (the oracle counts the
    rays that meet no face); the panel poking out sees the sky from both sides."""
    scene = _room()
    enclosed = ff.enclosed_sides(scene)
    for face in range(scene.n_faces):
        for k, side in enumerate((1, -1)):
            if face == 14 and side == -1:
                continue  # it lies on the wall: its rays would start in the wall's plane
            est, _ = form_factor_monte_carlo(scene, [face], side, 4_000, seed=face)
            if enclosed[2 * face + k]:
                assert est[-1] == 0.0, (face, side)
    est_up, _ = form_factor_monte_carlo(scene, [13], 1, 20_000, seed=1)
    est_down, _ = form_factor_monte_carlo(scene, [13], -1, 20_000, seed=2)
    assert est_up[-1] > 0.01 and est_down[-1] > 0.01


def test_enclosed_rows_take_no_sky():
    """An enclosed side's row (both paths) gives a sky of exactly 0 (it was computed as
    ~1e-16 of rounding) and sums to 1 within its estimates."""
    scene = _room()
    faces = np.arange(scene.n_faces, dtype=np.int64)
    for row in (ff.row_form_factors, ff.emitter_row):
        r = row(scene, 12, -1, faces, 1e-3)
        assert r[4] == 0.0 and r[5] == 0.0
        assert abs(r[1].sum() - 1.0) <= r[2].sum() + 1e-12


def _frustum_room():
    """A room shaped as a frustum, nothing inside: floor 4 × 4 at y = 0 (face 0), ceiling
    5 × 5 at y = 1.5 (face 1), four sloping walls of 7.12 m² (faces 2–5), normals in."""
    v = [[x, 0.0, z] for x, z in ((-2, -2), (2, -2), (2, 2), (-2, 2))] + \
        [[x, 1.5, z] for x, z in ((-2.5, -2.5), (2.5, -2.5), (2.5, 2.5), (-2.5, 2.5))]
    polys = [[0, 1, 2, 3], [4, 7, 6, 5]] + [[k, 4 + k, 4 + (k + 1) % 4, (k + 1) % 4] for k in range(4)]
    pts = np.asarray(v, float)
    centre = pts.mean(axis=0)
    out = []
    for p in polys:  # oriented with the normal into the room
        q = pts[p]
        n = np.cross(q[1] - q[0], q[2] - q[0])
        out.append(p if n @ (centre - q.mean(axis=0)) > 0 else p[::-1])
    return build_scene(soup(v, out))


def test_summation_entry_in_an_empty_frustum_room_against_the_contour_integral():
    """Nothing occludes: F(floor → ceiling) is the contour integral of the two squares. The
    matrix takes it from the floor's sum (its only computed pair: the walls are smaller
    than the floor, the ceiling larger), and derives the ceiling → floor entry as 16/25 of
    it; the same matrix, bit for bit, on 1 and 2 workers."""
    s = _frustum_room()
    assert np.allclose(s.face_area[:2], [16.0, 25.0]) and np.allclose(s.face_normal[0], [0, 1, 0])
    assert ff.enclosed_sides(s).reshape(-1, 2)[:, 0].all()
    assert ff.summation_column(s, 0, 1) == 2 * 1
    exact, exact_err = ff.contour_form_factor(s.face_loops(0), s.face_normal[0], s.face_loops(1), s.face_normal[1])
    m = ff.form_factor_matrix(s, tol=1e-6, workers=1)
    assert m.method_counts["summation"] == 1
    d, e = m.dense(), np.zeros((12, 12))
    for r in range(12):
        e[r, m.indices[m.indptr[r]:m.indptr[r + 1]]] = m.error[m.indptr[r]:m.indptr[r + 1]]
    assert 0.6 < exact < 0.7  # a low, wide room
    # the rows clip 1e-9 of the scene's size off each receiver's plane, which takes 6.5e-10
    # off F between faces sharing an edge (the floor's four walls: 2.6e-9 of the sum): the
    # estimates bound it (PairSetup.clip_bound); without, this fails
    assert abs(d[0, 2] - exact) <= e[0, 2] + exact_err, (d[0, 2], exact, e[0, 2])
    assert d[2, 0] == pytest.approx(d[0, 2] * 16 / 25, rel=1e-15)
    assert e[2, 0] == pytest.approx(e[0, 2] * 16 / 25, rel=1e-15)
    two = ff.form_factor_matrix(s, tol=1e-6, workers=2)
    for k in ("indptr", "indices", "data", "error", "sky", "sky_error"):
        assert np.array_equal(getattr(m, k), getattr(two, k)), k


@pytest.fixture(scope="module")
def small_room():
    """31 polygons: a 5 x 3 x 4 m closed room (its walls smaller than the floor), a light,
    a cabinet against a wall, one desk."""
    return build_scene(furnished_room(n_desks=1, n_cabinets=1, n_dividers=0, n_lights=1, size=(5, 3, 4), seed=0))


def test_matrix_takes_the_floor_ceiling_pair_from_the_floor_row_sum(small_room):
    """The floor's only computed pair is the ceiling's (equal areas, the floor's index
    smaller): the matrix takes F(floor → ceiling) as 1 − the floor row's other entries,
    all derived from smaller faces' rows, its estimate the sum of theirs (here 1.16e-4 at
    tol 1e-4: a sum of estimates may pass tol). Within that and the reference's estimate
    of the pair cubature at 1e-6; the ceiling's row holds it by reciprocity and still sums to 1
    within its estimates."""
    s = small_room
    floor, ceiling = int(s.group_faces("floor")[0]), int(s.group_faces("ceiling")[0])
    assert ff.summation_column(s, floor, 1) == 2 * ceiling
    assert [ff.summation_column(s, f, t) for f in range(s.n_faces) for t in ff.SIDES].count(-1) == 2 * s.n_faces - 1
    m = ff.form_factor_matrix(s, tol=1e-4, workers=1)
    assert m.method_counts["summation"] == 1
    lo, hi = m.indptr[2 * floor], m.indptr[2 * floor + 1]
    k = lo + int(np.flatnonzero(m.indices[lo:hi] == 2 * ceiling)[0])
    ref = ff.pair_form_factor(s, floor, 1, ff.face_target(s, ceiling), 1, tol=1e-6)
    assert ref.error < 1e-6
    assert abs(m.data[k] - ref.F) <= m.error[k] + ref.error, (m.data[k], ref.F, m.error[k])
    others = np.arange(lo, hi) != k
    assert m.data[k] == pytest.approx(1.0 - m.data[lo:hi][others].sum(), abs=1e-15)
    assert m.error[k] == pytest.approx(m.error[lo:hi][others].sum(), rel=1e-12)  # 1.16e-4 (measured)
    rows = m.row_sums()
    assert abs(rows[2 * ceiling] - 1.0) < 1e-4
    assert rows[2 * floor] == pytest.approx(1.0, abs=1e-15)
