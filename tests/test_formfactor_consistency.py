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


def test_single_emitter_group_runs_in_parts(tile_cube):
    """A query of one row (the floor, computing both pairs: the faces' areas are equal and
    it has the smaller index) runs as SINGLE_PARTS parts (its free cells dealt out): the
    same value on 1 or 2 workers, equal to the pair query within the estimates."""
    assert [(f, s) for f, s, *_ in ff.group_rows(tile_cube[0], [0], 1, [1, 2])] == [(0, 1)]
    scene, rows = tile_cube
    one = ff.group_to_group(scene, [0], [1, 2], tol=TOL, workers=1)
    two = ff.group_to_group(scene, [0], [1, 2], tol=TOL, workers=2)
    assert one == two
    pair = sum(ff.face_to_face(scene, 0, j, tol=TOL)["F"] for j in (1, 2))
    assert abs(one["F"] - pair) <= one["error"] + 4 * TOL
    assert abs(one["F"] - sum(rows[0].get(c, (0.0, 0.0))[0] for c in (2, 3, 4, 5))) <= one["error"] + 2 * TOL


def test_single_emitter_parts_share_the_parents_work(monkeypatch):
    """The parts of one emitter use the cells, their contacts and the receivers' covered
    cells that the parent computed before forking them (``shared_emitter_work``): no part
    computes them again (each did, and loaded their kernels, on its own)."""
    scene = cube_with_a_tile()  # caches of its own
    receivers = np.array([1, 2, 6], np.int64)
    ff.shared_emitter_work(scene, 0, 1, receivers)

    def again(*args, **kwargs):
        raise AssertionError("computed again in a part")

    monkeypatch.setattr(ff, "emitter_cells", again)
    monkeypatch.setattr(ff, "contact_sides", again)
    cols, F, *_ = ff.emitter_row(scene, 0, 1, receivers, 1e-3, False, (0, ff.SINGLE_PARTS))
    assert len(cols)


def test_parts_are_dealt_pieces_of_the_cells():
    """A single emitter's parts are dealt the start triangles of its free cells
    (``part_pieces``), not the cells: more pieces than cells, none larger than the
    start size (1 / MIN_SPLIT of the face), tiling the free cells (equal area)."""
    scene = cube_with_a_tile()
    cells, _, _ = ff.cubature_cells(scene, 0, 1)
    free = [c for c, k in zip(cells, ff.cell_contacts(scene, 0, 1)) if k < 0]
    pieces = ff.part_pieces(scene, 0, free)
    assert len(free) < len(pieces) and ff.SINGLE_PARTS <= len(pieces)
    lo, hi = ff.face_boxes(scene)
    assert max(np.sqrt(2 * ff._cell_area(p)) for p in pieces) <= np.linalg.norm(hi[0] - lo[0]) / ff.MIN_SPLIT
    area = sum(ff._cell_area(c) for c in free)
    assert abs(sum(ff._cell_area(p) for p in pieces) - area) < 1e-9 * area
