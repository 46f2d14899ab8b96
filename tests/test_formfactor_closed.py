"""Matrix rows in closed form (:func:`viscx.queries.formfactor.closed_form_row`): the inner
sides of empty closed boxes (contour integrals to the box's other faces) and sides lying
wholly on other faces (F = 1 to what they lie on), against Howell's closed forms, the
general row cubature and Monte Carlo rays."""

import sys

import numpy as np
import pytest
from conftest import ROOT, soup
from oracles import form_factor_monte_carlo
from test_formfactor import parallel_rectangles, perpendicular_rectangles

from viscx.queries import formfactor as ff
from viscx.scene import build_scene, load_scene

sys.path.insert(0, str(ROOT / "benchmarks"))
from buildings import furnished_room  # noqa: E402


@pytest.fixture(scope="module")
def room():
    """37 faces: a 4 x 3 x 3 m room, a light, a cabinet against a wall, a desk, a divider."""
    return build_scene(furnished_room(n_desks=1, n_cabinets=1, n_dividers=1, n_lights=1, size=(4, 3, 3), seed=0))


def general_row(scene, face, side, tol, monkeypatch):
    """The row by the row cubature, the closed forms switched off."""
    with monkeypatch.context() as m:
        m.setattr(ff, "closed_form_row", lambda *a, **k: None)
        return ff.row_form_factors(scene, face, side, np.arange(scene.n_faces), tol)


def dense(scene, row):
    out = np.zeros(2 * scene.n_faces)
    out[row[0]] = row[1]
    return out


def test_box_inner_rows_are_howells_closed_forms(room):
    """Every inner side of the cabinet (an axis-aligned box): F to the opposite face is
    Howell's C-11, to the four adjacent ones C-14, to 1e-9; the row sums to 1 to 1e-12
    without sky (the identity of a closed convex polyhedron, which independent errors of
    the five integrals would not keep)."""
    faces = np.arange(room.n_faces)
    cabinet = np.asarray(room.group_faces("cabinet0"))
    pts = np.concatenate([room.face_loops(f)[0] for f in cabinet])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    size = hi - lo
    assert ff.empty_boxes(room).all()
    for f in cabinet:
        row = ff.closed_form_row(room, f, -1, faces)
        assert row is not None and row[3]["closed"] == 5 and row[4] == 0.0
        assert abs(row[1].sum() - 1) < 1e-12
        axis = int(np.argmax(np.abs(room.face_normal[f])))
        a, b = [size[k] for k in range(3) if k != axis]
        for col, value, err in zip(*row[:3]):
            g = col // 2
            assert col % 2 == 1 and g in cabinet and g != f
            other = int(np.argmax(np.abs(room.face_normal[g])))
            if other == axis:
                exact = parallel_rectangles(a / size[axis], b / size[axis])
            else:
                shared = size[3 - axis - other]
                exact = perpendicular_rectangles(size[axis] / shared, size[other] / shared)
            assert abs(value - exact) < 1e-9 and err < 1e-9


def test_closed_rows_against_the_row_cubature(room, monkeypatch):
    """A desk panel's top side: inside (box inner) and outside (lying wholly under the desk
    top); the general row at tol 1e-6 agrees within its estimate plus 2e-7 (its own bias:
    it clips the emitter 1e-9 of the scene's size off each receiver's plane, which for
    faces sharing an edge moves F by 1.0e-7, beyond its estimate; the closed rows sum to 1
    to 1e-12, the general one to -2.1e-7)."""
    faces = np.arange(room.n_faces)
    desk = np.asarray(room.group_faces("desk0"))
    top = desk[room.face_normal[desk, 1] > 0.99]
    panel_top = int(top[np.argmin(room.face_area[top])])
    for side in (-1, 1):
        closed = ff.closed_form_row(room, panel_top, side, faces)
        assert closed is not None
        general = general_row(room, panel_top, side, 1e-6, monkeypatch)
        est = np.zeros(2 * room.n_faces)
        est[general[0]] = general[2]
        assert np.all(np.abs(dense(room, closed) - dense(room, general)) <= est + 2e-7)
        assert abs(closed[1].sum() + closed[4] - 1) < 1e-12
    lying = ff.closed_form_row(room, panel_top, 1, faces)
    assert len(lying[0]) == 1 and lying[1][0] == 1.0 and lying[0][0] % 2 == 0  # the desk top underside's front


@pytest.mark.slow
def test_box_inner_rows_against_the_row_cubature_slow(room, monkeypatch):
    """Every third inner side of the room's boxes (10 rows, ~60 CPU s of general rows at
    tol 1e-7): within the general row's estimate plus 2e-7 (measured: at most 1.03e-7)."""
    faces = np.arange(room.n_faces)
    boxed = np.flatnonzero(ff.closed_boxes(room)[0] >= 0)[::3]
    for f in boxed:
        closed = ff.closed_form_row(room, f, -1, faces)
        general = general_row(room, f, -1, 1e-7, monkeypatch)
        est = np.zeros(2 * room.n_faces)
        est[general[0]] = general[2]
        assert np.all(np.abs(dense(room, closed) - dense(room, general)) <= est + 2e-7), f


@pytest.mark.parametrize("k", [200_000, pytest.param(10_000_000, marks=pytest.mark.slow)])
def test_box_inner_row_against_monte_carlo(room, k):
    """The divider's largest face, inner side, against k cosine-weighted rays within 4 σ.
    A ray reaching the divider's bottom may be counted on the floor it lies on (embree's tie
    between coincident faces): the bottom's column is compared with the rays counted
    outside the box."""
    faces = np.arange(room.n_faces)
    divider = np.asarray(room.group_faces("divider0"))
    f = int(divider[np.argmax(room.face_area[divider])])
    row = ff.closed_form_row(room, f, -1, faces)
    F = dense(room, row)
    mc, _ = form_factor_monte_carlo(room, [f], -1, k, seed=3)
    bottom = 2 * int(divider[room.face_normal[divider, 1] < -0.99][0]) + 1
    inside = 2 * divider + 1
    mc_bottom = mc[bottom] + (1 - mc[inside].sum())  # rays counted elsewhere
    for col in inside:
        got = mc_bottom if col == bottom else mc[col]
        sigma = max(np.sqrt(F[col] * (1 - F[col]) / k), 1 / k)
        assert abs(got - F[col]) < 4 * sigma, (col, got, F[col])


def test_a_face_inside_a_box_makes_it_not_empty():
    """A unit cube with a quad crossing its inside, and a second cube with a quad touching it
    from outside only: the first is not empty (its inner rows go the general way), the
    second is."""
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    verts = np.concatenate([cube, cube + [3, 0, 0], [[0.5, -1, -1], [0.5, 2, -1], [0.5, 2, 2], [0.5, -1, 2]],
                            [[4, 0, -1], [4, 1, -1], [4, 1, 0], [4, 0, 0]]])
    polys = [list(q) for q in quads] + [[8 + i for i in q] for q in quads] + [[16, 17, 18, 19], [20, 21, 22, 23]]
    scene = build_scene(soup(verts, polys))
    face_box = ff.closed_boxes(scene)[0]
    empty = ff.empty_boxes(scene)
    crossed = face_box[0]
    assert not empty[crossed] and empty[1 - crossed]
    faces = np.arange(scene.n_faces)
    assert ff.closed_form_row(scene, 0, -1, faces) is None
    free = int(np.flatnonzero(face_box == 1 - crossed)[0])
    row = ff.closed_form_row(scene, free, -1, faces)
    assert row is not None and abs(row[1].sum() - 1) < 1e-12


def test_rows_over_the_faces_in_front_only(room, monkeypatch):
    """A row's points see only the faces with a vertex ahead of its plane or in it
    (:func:`viscx.queries.formfactor.seen_faces`): a cabinet's outer side leaves out the
    faces behind it, and its row is the row over every face, bit for bit."""
    cabinet = np.asarray(room.group_faces("cabinet0"))
    up = int(cabinet[room.face_normal[cabinet, 1] > 0.99][0])  # its top: the desk and the floor lie below
    seen = ff.seen_faces(room, up, 1)
    assert up in seen and 0 not in seen and len(seen) < room.n_faces
    faces = np.arange(room.n_faces)
    got = ff.row_form_factors(room, up, 1, faces, 1e-3)
    with monkeypatch.context() as m:
        m.setattr(ff, "seen_faces", lambda scene, face, side: np.arange(scene.n_faces, dtype=np.int64))
        every = ff.row_form_factors(room, up, 1, faces, 1e-3)
    for a, b in zip(got[:3] + got[4:], every[:3] + every[4:]):
        assert np.array_equal(a, b)


def open_box_scene(shift=0.0, tile=False):
    """A 10 × 10 floor (y = 0, facing up) and a unit box open at its bottom standing on it
    at x, z in [2 + shift, 3 + shift] (top and four sides, normals outward); ``tile``: a
    0.2 × 0.2 tile lying on the floor inside the box's footprint."""
    v = [[0, 0, 0], [10, 0, 0], [10, 0, 10], [0, 0, 10]]
    v += [[x + shift, y, z] for y in (0, 1) for x, z in ((2, 2), (3, 2), (3, 3), (2, 3))]
    polygons = [[0, 3, 2, 1], [8, 11, 10, 9], [4, 8, 9, 5], [5, 9, 10, 6], [6, 10, 11, 7], [7, 11, 8, 4]]
    if tile:
        v += [[2.4, 0, 2.4], [2.6, 0, 2.4], [2.6, 0, 2.6], [2.4, 0, 2.6]]
        polygons.append([12, 15, 14, 13])
    return build_scene(soup(v, polygons))


def test_an_open_box_capped_by_the_face_it_stands_on():
    """:func:`box_caps`: a box open at its bottom standing wholly on the floor is closed by the
    floor over its footprint; half over the floor's edge, or with a tile lying on the floor
    inside it, it is not (its inner sides then see past the floor, or the tile), and its
    inner rows are not closed forms."""
    on = open_box_scene()
    cap = ff.box_caps(on)[0]
    assert cap is not None and cap[:2] == (0, 1)
    assert np.allclose(np.sort(cap[2][:, [0, 2]], axis=0), [[2, 2], [2, 2], [3, 3], [3, 3]])
    for scene in (open_box_scene(shift=7.5), open_box_scene(tile=True)):
        assert ff.box_caps(scene)[0] is None
        assert ff.closed_form_row(scene, 1, -1, np.arange(scene.n_faces)) is None
    # the unit box on the floor: its top's inner side sees the floor's front over the
    # footprint, a unit square parallel to it at distance 1 (Howell's C-11), and the rest on
    # the four sides; no sky
    row = ff.closed_form_row(on, 1, -1, np.arange(on.n_faces))
    F = dense(on, row)
    assert abs(F[0] - parallel_rectangles(1.0, 1.0)) < 1e-9 and row[4] == 0.0
    assert abs(row[1].sum() - 1) < 1e-12


def graded_form_factor(P, n, J):
    """F from a convex quadrilateral P (4, 3) (side n) to a polygon J (k, 3), independent of
    the contour integrals: the exact point-to-polygon F (Lambert's formula) integrated over P
    by a product Gauss rule on P's bilinear map, graded geometrically towards P's first edge
    with both ends on J's plane (where P and J share an edge the integrand's derivative
    blows up there) and towards the two other sides' ends along it."""
    from viscx.geometry.formfactor import point_to_polygon
    from viscx.geometry.polygon import newell_normal

    nj = newell_normal(J) / np.linalg.norm(newell_normal(J))
    on = np.abs((P - J[0]) @ nj) < 1e-9
    k = next((a for a in range(4) if on[a] and on[(a + 1) % 4]), 0)
    a, b, c, d = (P[(k + i) % 4] for i in range(4))
    g, w = np.polynomial.legendre.leggauss(10)
    g, w = (g + 1) / 2, w / 2

    def nodes(breaks):
        lo, hi = breaks[:-1, None], breaks[1:, None]
        return (lo + (hi - lo) * g).ravel(), ((hi - lo) * w).ravel()

    t, tw = nodes(np.concatenate([[0.0], 0.5 ** np.arange(22, 0, -1), [1.0]]))
    s, sw = nodes(np.concatenate([[0.0], 0.5 ** np.arange(16, 1, -1), [0.5], 1 - 0.5 ** np.arange(2, 17), [1.0]]))
    S, T = (x.ravel() for x in np.meshgrid(s, t, indexing="ij"))
    W = np.outer(sw, tw).ravel()
    x = (((1 - T) * (1 - S))[:, None] * a + ((1 - T) * S)[:, None] * b + (T * S)[:, None] * c
         + (T * (1 - S))[:, None] * d)
    jac = np.abs(np.cross((1 - T)[:, None] * (b - a) + T[:, None] * (c - d),
                          (1 - S)[:, None] * (d - a) + S[:, None] * (c - b)) @ n)
    f = point_to_polygon(x, np.ascontiguousarray(np.broadcast_to(n, x.shape)), [J])
    return float((f * jac * W).sum() / (jac * W).sum())


def test_cornell_block_inner_rows_closed_by_the_floor(monkeypatch):
    """The inner sides of the Cornell blocks (open boxes standing on the floor,
    :func:`box_caps`) see the block's other inner sides and the floor's front over the
    footprint, nothing else: the closed rows sum to 1 to 1e-12 (the closed polyhedron's
    identity); a tall block side's entries equal an independent cubature of the exact
    point-to-polygon F (:func:`graded_form_factor`) to 1e-12; the general row cubature
    agrees within its estimate plus 1e-8 (its bias: it clips the emitter 1e-9 of the
    scene's size off each receiver's plane, which moves F between faces sharing an edge by
    ~3e-9, beyond its estimates of ~3e-13, as the graded cubature shows: see also
    test_closed_rows_against_the_row_cubature); and 200,000 cosine-weighted rays within 4 σ
    (the floor's column: the rays counted outside the block's faces, which also holds the
    rays embree gives to the floor's coincident edges)."""
    scene = load_scene(ROOT / "sample_scenes" / "cornell_box.obj")
    faces = np.arange(scene.n_faces)
    block = np.flatnonzero(ff.closed_boxes(scene)[0] == ff.closed_boxes(scene)[0][11])
    for f in (6, 11):
        row = ff.closed_form_row(scene, f, -1, faces)
        assert row is not None and row[4] == 0.0 and abs(row[1].sum() - 1) < 1e-12
    side = 12
    closed = dense(scene, ff.closed_form_row(scene, side, -1, faces))
    P, n = scene.face_loops(side)[0], -scene.face_normal[side]
    cap = ff.box_caps(scene)[ff.closed_boxes(scene)[0][side]][2]
    for col, J in [(2 * g + 1, scene.face_loops(g)[0]) for g in block if g != side] + [(0, cap)]:
        assert abs(closed[col] - graded_form_factor(P, n, J)) < 1e-12, col
    general = general_row(scene, 11, -1, 1e-6, monkeypatch)
    est = np.zeros(2 * scene.n_faces)
    est[general[0]] = general[2]
    closed = dense(scene, ff.closed_form_row(scene, 11, -1, faces))
    assert np.all(np.abs(closed - dense(scene, general)) <= est + 1e-8)
    k = 200_000
    mc, _ = form_factor_monte_carlo(scene, [11], -1, k, seed=3)
    inside = 2 * block[block != 11] + 1
    mc_floor = 1 - mc[inside].sum()
    for col, got in [(c, mc[c]) for c in inside] + [(0, mc_floor)]:
        sigma = max(np.sqrt(closed[col] * (1 - closed[col]) / k), 1 / k)
        assert abs(got - closed[col]) < 4 * sigma, (col, got, closed[col])
