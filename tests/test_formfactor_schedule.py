"""How the form-factor matrix shares its work among cores (viscx.queries.formfactor:
``row_rules``' pieces on threads, ``_map_rows``' core tokens): a row evaluated on several
threads is the row on one, bit for bit, and the matrix does not depend on the workers."""

import threading
import time

import numpy as np
import pytest
from conftest import SAMPLES

from viscx.queries import formfactor as ff
from viscx.scene import load_scene


def row_on(scene, face, side, threads):
    """:func:`ff.row_form_factors` of one side on ``threads`` threads (every receiver)."""
    return ff.row_form_factors(scene, face, side, np.arange(scene.n_faces, dtype=np.int64), 1e-2, True, threads)


def assert_same_rows(a, b):
    for x, y in zip(a[:3], b[:3]):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert a[3] == b[3] and (a[4], a[5]) == (b[4], b[5])


@pytest.mark.parametrize("three_levels", [False, True])
def test_a_row_on_threads_is_the_row_on_one_to_the_bit(three_levels, monkeypatch):
    """The Cornell back wall's row (cut along its kinks: RowCubature; or, with no kink
    cells allowed, the three-level ThreeLevelRowCubature) evaluated in pieces on 3 threads equals
    the row on 1: each piece writes its own triangles and its values do not depend on the
    other pieces. The row has many pieces (else the test would show nothing)."""
    if three_levels:
        monkeypatch.setattr(ff, "MAX_KINK_CELLS", 0)
    scene = load_scene(SAMPLES / "cornell_box.obj")
    face = int(scene.group_faces("back_wall")[0])
    calls = []
    kernel = ff.point_views

    def counted(points, *args):
        calls.append((len(points), threading.get_ident()))
        return kernel(points, *args)

    monkeypatch.setattr(ff, "point_views", counted)
    one = row_on(scene, face, 1, 1)
    pieces = len(calls)
    assert ff.cubature_cells(scene, face, 1)[2] is not three_levels
    many = row_on(scene, face, 1, 3)
    assert pieces > 8 and len(calls) == 2 * pieces  # the same pieces on both
    assert_same_rows(one, many)


def test_row_pieces_hold_a_core_token(monkeypatch):
    """:func:`ff.row_rules` runs its pieces on ``cubature.threads`` threads, each holding
    one of the pool's core tokens (:data:`ff._ROW_CORES`): with one token the pieces run
    one at a time, without tokens several at once; the values are the same."""
    rng = np.random.default_rng(0)
    tri = rng.random((160, 3, 3))  # 10 pieces of 16 triangles
    width = 3
    state = {"now": 0, "most": 0}
    lock = threading.Lock()

    class Slow:
        threads = 4
        evaluations = 0

        @staticmethod
        def integrand(points, part):
            with lock:
                state["now"] += 1
                state["most"] = max(state["most"], state["now"])
            time.sleep(0.01)  # lets the other threads in, if they may
            with lock:
                state["now"] -= 1
            return np.stack([points[:, 0], points[:, 1] * points[:, 2], np.ones(len(points))], axis=1)

    def run(cores):
        monkeypatch.setattr(ff, "_ROW_CORES", cores)
        state["most"] = 0
        cub = Slow()
        out = ff.row_rules(cub, tri, width, (ff.RULE_WEIGHTS, ff.NULL_RULE))
        assert cub.evaluations == 7 * len(tri)
        return out, state["most"]

    free, most_free = run(None)
    one, most_one = run(threading.BoundedSemaphore(1))
    assert most_one == 1 and most_free > 1
    assert np.array_equal(free, one)
    # the last column integrates 1: the areas
    assert np.allclose(free[0, :, 2], ff.triangle_areas(tri), rtol=1e-14)


def test_rows_do_not_depend_on_the_workers():
    """Rows of boxes_on_floor on 1 worker (in turn, one thread each) and on 2 (forked,
    largest first, each row's points on 2 threads holding the pool's 2 core tokens): the
    same arrays, bit for bit (the whole matrix: the slow test below)."""
    scene = load_scene(SAMPLES / "boxes_on_floor.obj")
    faces = np.arange(scene.n_faces, dtype=np.int64)
    rows = [(int(f), s, faces) for f in np.argsort(-scene.face_area)[:2] for s in (1, -1)]
    one = ff._map_rows(ff.row_form_factors, scene, rows, 1e-2, True, 1, threads=True)
    two = ff._map_rows(ff.row_form_factors, load_scene(SAMPLES / "boxes_on_floor.obj"), rows, 1e-2, True, 2,
                       threads=True)
    for a, b in zip(one, two):
        assert_same_rows(a, b)
    assert ff._ROW_CORES is None  # the pool's tokens are gone with it


@pytest.mark.slow
def test_the_matrix_does_not_depend_on_the_workers():
    """The Cornell matrix at 1e-4 on 1 worker and on 2: the same arrays, bit for bit."""
    one = ff.form_factor_matrix(load_scene(SAMPLES / "cornell_box.obj"), tol=1e-4, workers=1)
    two = ff.form_factor_matrix(load_scene(SAMPLES / "cornell_box.obj"), tol=1e-4, workers=2)
    for name in ("indptr", "indices", "data", "error", "sky", "sky_error"):
        assert np.array_equal(getattr(one, name), getattr(two, name)), name
    assert one.method_counts == two.method_counts
