"""A matrix row at once (viscx.queries.formfactor.row_form_factors): every receiver from one
hidden-surface computation per point of the emitter (viscx.geometry.occlusion.point_views),
against the per-pair kernel, and faces lying on faces (docs/queries.md)."""

import numpy as np
import pytest
from conftest import SAMPLES
from test_formfactor_queries import scene_of

from viscx.geometry.occlusion import point_views
from viscx.geometry.polygon import plane_basis
from viscx.queries import formfactor as ff
from viscx.scene import load_scene


@pytest.fixture(scope="module")
def cornell():
    return load_scene(SAMPLES / "cornell_box.obj")


def emitter_points(scene, face, k, rng):
    tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
    w = rng.dirichlet([1, 1, 1], k)
    return np.einsum("gk,gkd->gd", w, tri[rng.integers(0, len(tri), k)])


def views(scene, face, side, points):
    n_i = side * scene.face_normal[face]
    eu, ev = plane_basis(n_i)
    return point_views(np.ascontiguousarray(points), n_i, eu, ev, *ff.scene_polygons(scene), face, 1e-9 * scene.diagonal,
                       *ff.closed_boxes(scene))


@pytest.mark.parametrize("face", [0, 1, 2, 15])  # floor, ceiling (light 0.1 mm under it), back wall, light
def test_point_views_equal_the_pair_kernel(cornell, face, rng):
    """Every column of the row kernel (hidden part of each face side) equals the pair kernel
    (:func:`blocked_form_factors` past the pair's culled occluders), and the sky column equals
    what the pair kernel sees of the six sky boxes."""
    pts = emitter_points(cornell, face, 12, rng)
    h = views(cornell, face, 1, pts)
    group = np.zeros(len(pts), np.int64)
    for j in range(cornell.n_faces):
        for t in (1, -1):
            col = h[:, 2 * j + (t < 0)]
            st = ff.PairSetup(cornell, face, 1, ff.face_target(cornell, j), t)
            if st.empty or j == face:
                assert np.abs(col).max() < 1e-12
                continue
            k = len(st.occluders)
            ref = st.blocked(pts, group, np.array([0, k]), np.arange(k)) if k else np.zeros(len(pts))
            assert np.abs(col - ref).max() < 1e-12, (j, t)
    sky = np.zeros(len(pts))
    for box in ff.sky_targets(cornell):
        st = ff.PairSetup(cornell, face, 1, box, 1)
        if not st.empty:
            sky += st.f(pts)
    assert np.abs(h[:, -1] - sky).max() < 1e-12


@pytest.mark.parametrize("tol", [1e-4, pytest.param(1e-5, marks=pytest.mark.slow)])
def test_row_equals_pairs(cornell, tol):
    """The floor's row and sky by the row cubature agree with the pair by pair ones within
    the sum of their error estimates, at tol 1e-4 (1e-5 with -m slow: 17 s of CPU)."""
    faces = np.arange(cornell.n_faces)
    r = ff.row_form_factors(cornell, 0, 1, faces, tol)
    o = ff.emitter_row(cornell, 0, 1, faces, tol)
    a, b = dict(zip(r[0], zip(r[1], r[2]))), dict(zip(o[0], zip(o[1], o[2])))
    assert set(b) <= set(a)
    for c in a:
        fb, eb = b.get(c, (0.0, 0.0))
        assert abs(a[c][0] - fb) <= a[c][1] + eb + 1e-12, c
    assert abs(r[4] - o[4]) <= r[5] + o[5]
    assert r[2].max() <= tol and r[5] <= tol


def cube_with_a_tile():
    """A closed unit cube (normals in) and a tile lying on its floor, facing the floor (a
    cabinet's bottom): faces 0..5 the cube (0 the floor), 6 the tile."""
    s = 1.0
    floor = [[0, 0, 0], [s, 0, 0], [s, s, 0], [0, s, 0]]  # normal +z, into the cube
    top = [[0, 0, s], [0, s, s], [s, s, s], [s, 0, s]]
    walls = [[[0, 0, 0], [0, s, 0], [0, s, s], [0, 0, s]], [[s, 0, 0], [s, 0, s], [s, s, s], [s, s, 0]],
             [[0, 0, 0], [0, 0, s], [s, 0, s], [s, 0, 0]], [[0, s, 0], [s, s, 0], [s, s, s], [0, s, s]]]
    tile = [[0.2, 0.3, 0], [0.2, 0.7, 0], [0.6, 0.7, 0], [0.6, 0.3, 0]]  # normal -z, onto the floor
    return scene_of([floor, top] + walls + [tile])


def test_faces_lying_on_faces():
    """The floor's part under the tile sees the tile's lower side only (F = its share of the
    floor), the tile's lower side sees the floor only (F = 1), and the tile's upper side sees
    the room: rows sum to 1 and reciprocity holds."""
    scene = cube_with_a_tile()
    assert list(ff.coplanar_faces(scene, 0)) == [6]
    m = ff.form_factor_matrix(scene, tol=1e-6, workers=1)
    F = m.dense()
    a_tile = scene.face_area[6]
    assert abs(F[0, 12] - a_tile) < 1e-9  # floor front -> tile front (facing the floor)
    assert abs(F[12, 0] - 1) < 1e-9 and abs(F[12].sum() - 1) < 1e-9
    assert F[13, 0] == 0.0 and F[0, 13] == 0.0  # the tile's upper side does not see the floor
    assert np.abs(m.row_sums() - 1).max() < 1e-6
    assert m.reciprocity_error() < 1e-6
