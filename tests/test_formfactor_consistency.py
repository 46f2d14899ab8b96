"""Every form-factor query gives the matrix's definition: the pair and group queries
(``face_to_face``, ``group_to_group``) equal the matrix rows (``row_form_factors``) within
their error estimates where faces lie on faces (docs/queries.md, "Faces lying on faces"):
a tile on a cube's floor, a cabinet's back on a room's wall and its bottom on the floor."""

import numpy as np
import pytest
from test_formfactor_rooms import closed_room
from test_formfactor_rows import cube_with_a_tile

from viscx.queries import formfactor as ff

TOL = 1e-5


def row(scene, face, tol=TOL):
    """{element: (F, error)} of the front side's matrix row."""
    cols, F, E, *_ = ff.row_form_factors(scene, face, 1, np.arange(scene.n_faces), tol, sky=False)
    return {int(c): (f, e) for c, f, e in zip(cols, F, E)}


def check_pair(scene, rows, i, j, tol=TOL):
    """face_to_face(i → j) (both sides of j) equals the matrix row's two entries."""
    r = ff.face_to_face(scene, i, j, side_i=1, tol=tol)
    ref = [rows[i].get(2 * j + k, (0.0, 0.0)) for k in (0, 1)]
    for k, name in enumerate(("front", "back")):
        got = r["sides"][name]
        assert abs(got["F"] - ref[k][0]) <= got["error"] + ref[k][1] + 1e-9, (i, j, name, got["F"], ref[k][0])
    return r


@pytest.fixture(scope="module")
def tile_cube():
    scene = cube_with_a_tile()
    return scene, {i: row(scene, i) for i in (0, 1, 6)}


@pytest.mark.parametrize("i, j", [(0, 1), (1, 0), (0, 6), (6, 0), (1, 6), (0, 2)])
def test_tile_cube_pairs_equal_the_matrix(tile_cube, i, j):
    """Floor → ceiling is 0.1631 (the floor under the tile sees the tile only), not 0.1998;
    floor → tile is the tile's share of the floor; the ceiling sees the tile, not the floor
    under it."""
    scene, rows = tile_cube
    check_pair(scene, rows, i, j)


def test_tile_cube_values(tile_cube):
    scene, rows = tile_cube
    assert abs(ff.face_to_face(scene, 0, 1, tol=TOL)["F"] - 0.1631) < 1e-3
    assert abs(ff.face_to_face(scene, 0, 6, tol=TOL)["sides"]["front"]["F"] - scene.face_area[6]) < 1e-9


def test_tile_cube_groups_equal_the_matrix(tile_cube):
    scene, rows = tile_cube
    g = ff.group_to_group(scene, [0, 1], [1, 6, 2], side_i=1, tol=TOL, workers=1)
    a = scene.face_area
    want = sum(a[i] * sum(rows[i].get(c, (0.0, 0.0))[0] for j in (1, 6, 2) if j != i for c in (2 * j, 2 * j + 1))
               for i in (0, 1)) / a[[0, 1]].sum()
    assert abs(g["F"] - want) <= g["error"] + 2 * TOL


@pytest.fixture(scope="module")
def cabinet_room():
    """The closed room of tests/test_formfactor_rooms.py with the cabinet's back on the west
    wall and its bottom on the floor (12 faces)."""
    scene = closed_room(0)
    west, east = (int(scene.group_faces(n)[0]) for n in ("wall_west", "wall_east"))
    return scene, (west, east), {i: row(scene, i, 1e-4) for i in (west, east)}


def test_cabinet_room_pairs_equal_the_matrix(cabinet_room):
    """West wall (the cabinet's back on it) ↔ east wall, and the west wall to the cabinet's
    faces (its back: the contact, F = the back's share of the wall)."""
    scene, (west, east), rows = cabinet_room
    for i, j in [(west, east), (east, west)] + [(west, int(c)) for c in scene.group_faces("cabinet0")]:
        check_pair(scene, rows, i, j, 1e-4)


def test_single_emitter_group_runs_on_threads(tile_cube, monkeypatch):
    """A query of one row (the floor, computing both pairs: the faces' areas are equal and
    it has the smaller index) runs in the query's process, its cubatures' kernels on the
    workers as threads, not as processes: the same value on 1 or 2 workers, equal to the
    pair query within the estimates."""
    assert [(f, s) for f, s, *_ in ff.group_rows(tile_cube[0], [0], 1, [1, 2])] == [(0, 1)]
    scene, rows = tile_cube

    def no_pool(*args, **kwargs):
        raise AssertionError("a query of one row forked workers")

    monkeypatch.setattr(ff, "_map_rows", no_pool)
    one = ff.group_to_group(scene, [0], [1, 2], tol=TOL, workers=1)
    two = ff.group_to_group(scene, [0], [1, 2], tol=TOL, workers=2)
    assert one == two
    pair = sum(ff.face_to_face(scene, 0, j, tol=TOL)["F"] for j in (1, 2))
    assert abs(one["F"] - pair) <= one["error"] + 4 * TOL
    assert abs(one["F"] - sum(rows[0].get(c, (0.0, 0.0))[0] for c in (2, 3, 4, 5))) <= one["error"] + 2 * TOL


def test_group_rows_share_the_cores_as_threads(tile_cube, monkeypatch):
    """A query of several rows runs them on processes and each row's cubature pieces on
    threads holding the pool's core tokens (``_map_rows(threads=True)``): a large row (a
    desk top's underside → the floor) takes the cores the other rows leave when they are
    done. The same value on 1 and 2 workers."""
    scene, _ = tile_cube
    assert len(ff.group_rows(scene, [0, 1], 1, [1, 6, 2])) > 1
    asked = []
    map_rows = ff._map_rows

    def recorded(*args, **kwargs):
        asked.append(kwargs.get("threads", False))
        return map_rows(*args, **kwargs)

    monkeypatch.setattr(ff, "_map_rows", recorded)
    one = ff.group_to_group(scene, [0, 1], [1, 6, 2], tol=TOL, workers=1)
    two = ff.group_to_group(scene, [0, 1], [1, 6, 2], tol=TOL, workers=2)
    assert asked == [True, True]
    assert one == two


def test_group_pairs_find_their_occluders_once(monkeypatch):
    """A group query's row finds each pair's occluders once: its kink lines
    (``kink_faces``) and its pairs' cubatures (``pair_form_factor``) share them."""
    scene = cube_with_a_tile()  # caches of its own
    calls = []
    pair_occluders = ff.pair_occluders

    def counted(scene, I, n_i, c_i, J, n_t, c_t, exclude):
        calls.append((tuple(sorted(exclude)), tuple(np.round(n_t, 9))))  # the faces and the target's side
        return pair_occluders(scene, I, n_i, c_i, J, n_t, c_t, exclude)

    monkeypatch.setattr(ff, "pair_occluders", counted)
    ff.group_to_group(scene, [0], [1, 2], tol=1e-3, workers=1)
    assert calls and len(calls) == len(set(calls)), calls


@pytest.mark.parametrize("i, j", [(4, 2), (2, 0)])
def test_three_level_pair_cubature_threads_and_lists(i, j, monkeypatch):
    """The pair cubature on three levels (``Cubature``: the emitter's cells uncut along its
    kinks, as on the office's floor) gives the same result, bit for bit, on 1, 2 or 3
    threads; and only the leaves' children are culled (the shaft test), not the
    grandchildren, which carry their parents' lists: the triangles culled are fewer than
    half those evaluated (each evaluated triangle was culled before: as many)."""
    scene = closed_room(0)
    culled = []
    shaft_cull = ff.PairSetup.shaft_cull

    def counted(self, tri, ptr, ids, exact=False):
        if not exact:  # (the exact test of the blind leaves is not the levels' culling)
            culled.append(len(tri))
        return shaft_cull(self, tri, ptr, ids, exact)

    monkeypatch.setattr(ff.PairSetup, "shaft_cull", counted)
    out = []
    for threads in (1, 2, 3):
        culled.clear()
        r = ff.pair_form_factor(scene, i, 1, ff.face_target(scene, j), 1, tol=1e-6, cells=ff.emitter_cells(scene, i, 1),
                                kinked=False, threads=threads)
        assert r.method == "quadrature" and r.cells > 1000
        assert sum(culled) < r.cells / 2, (sum(culled), r.cells)
        out.append((r.F, r.error, r.evaluations, r.cells))
    assert out[0] == out[1] == out[2]


def test_three_level_pair_cubature_refines_to_just_under_its_budget(monkeypatch):
    """A round of the pair cubature splits its worst leaves until REFINE_LEFT (0.9) of the
    budget is left, not half of it: fewer points for the same tolerance, and the two
    results within each other's estimates."""
    scene = closed_room(0)
    out = {}
    for left in (0.5, ff.REFINE_LEFT):
        monkeypatch.setattr(ff, "REFINE_LEFT", left)
        r = ff.pair_form_factor(scene, 4, 1, ff.face_target(scene, 2), 1, tol=1e-7, cells=ff.emitter_cells(scene, 4, 1),
                                kinked=False)
        assert r.error <= 1e-7
        out[left] = r
    half, left = out[0.5], out[ff.REFINE_LEFT]
    assert left.evaluations < 0.95 * half.evaluations, (left.evaluations, half.evaluations)
    assert abs(left.F - half.F) <= left.error + half.error


def _floor_ceiling_boxes(boxes):
    """A 6 × 6 floor (face 0, normal +y), a ceiling 3 above it facing down (face 1) and
    closed axis-aligned boxes ``(lo, hi)`` between them."""
    from test_formfactor_queries import scene_of

    quads = [[[0, 0, 0], [0, 0, 6], [6, 0, 6], [6, 0, 0]], [[0, 3, 0], [6, 3, 0], [6, 3, 6], [0, 3, 6]]]
    for lo, hi in boxes:
        c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        for q in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
            quads.append(c[list(q)].tolist())
    return scene_of([np.asarray(q, float) for q in quads])


def test_pair_kernel_leaves_out_a_box_inside_another_box_shadow():
    """From points under a wide box (a desk top), a small box between it and the ceiling
    casts its shadow on the ceiling inside the wide box's: the pair kernel leaves it out
    (``_drop_covered_hulls``), so that the values are those without it, to the bit; from
    points off to the side, where it casts a shadow of its own, it counts (against the
    values without it)."""
    from viscx.geometry.occlusion import _drop_covered_hulls

    wide, small = ((2, 1.0, 2), (4, 1.2, 4)), ((2.9, 2.0, 2.9), (3.1, 2.2, 3.1))
    both, alone = _floor_ceiling_boxes([wide, small]), _floor_ceiling_boxes([wide])
    f = {}
    for name, scene in (("both", both), ("alone", alone)):
        setup = ff.PairSetup(scene, 0, 1, ff.face_target(scene, 1), 1)
        assert len(setup.occluders) == (12 if name == "both" else 6)
        rng = np.random.default_rng(0)
        under = np.column_stack([rng.uniform(2.6, 3.4, 50), np.zeros(50), rng.uniform(2.6, 3.4, 50)])
        side = np.column_stack([rng.uniform(5.5, 6.0, 20), np.zeros(20), rng.uniform(0.0, 0.5, 20)])
        f[name] = setup.f(under), setup.f(side)
    assert np.array_equal(f["both"][0], f["alone"][0])
    assert np.all(f["both"][1] < f["alone"][1] - 1e-6)
    # the rule itself: of two nested counter-clockwise squares (edges after J's 2), the inner goes
    sq = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], float)
    pts = np.concatenate([[[9, 9], [8, 8]], sq + 1, sq * 2.5])  # J's 2 edges, the inner, the outer
    seg_a, seg_b = pts.copy(), np.concatenate([pts[[1, 0]], np.roll(sq + 1, -1, 0), np.roll(sq * 2.5, -1, 0)])
    seg_p, seg_w = np.array([0, 0, 1, 1, 1, 1, 2, 2, 2, 2]), np.ones(10, np.int64)
    first = np.array([2, 6], np.int64)
    n_seg, n_hulls = _drop_covered_hulls(seg_a, seg_b, seg_p, seg_w, 10, first, 2)
    assert (n_seg, n_hulls, first[0]) == (6, 1, 2) and np.array_equal(seg_a[2:6], sq * 2.5) and list(seg_p[2:6]) == [2] * 4
