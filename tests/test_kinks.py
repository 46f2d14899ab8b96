"""The D1 (kink) lines of an emitter (viscx.queries.kinks) against a brute-force search, and
the row cubature's estimate on cells cut along them (viscx.queries.formfactor.RowCubature)."""

import itertools

import numpy as np
import pytest
from conftest import SAMPLES
from test_formfactor_queries import scene_of

from viscx.geometry.polygon import plane_basis
from viscx.queries import formfactor as ff
from viscx.queries.kinks import generator_segments, kink_segments
from viscx.scene import load_scene


@pytest.fixture(scope="module")
def cornell():
    return load_scene(SAMPLES / "cornell_box.obj")


def _front(seg, n, c):
    """The part of a segment (2, 3) in front of the plane n · y = c, or None."""
    h = seg @ n - c
    if h.max() <= 0:
        return None
    p, q = seg
    if h[0] < 0:
        p = p + (q - p) * h[0] / (h[0] - h[1])
    if h[1] < 0:
        q = q + (p - q) * h[1] / (h[1] - h[0])
    return np.stack([p, q])


def _overlap(x, a, b, u, v, samples=400):
    """Brute force: the angular overlap (radians, negative for a gap) of the images of the
    segments a and b (2, 3), in one plane with x, seen from x: each sampled densely, angles
    measured in that plane from u (along the emitter) towards v (away from it), in [0, π]."""
    t = np.linspace(0, 1, samples)[:, None]

    def angles(s):
        d = s[0] + t * (s[1] - s[0]) - x
        return np.arctan2(np.maximum(d @ v, 0.0), d @ u)

    ia, ib = angles(a), angles(b)
    return min(ia.max(), ib.max()) - max(ia.min(), ib.min())


def _distance_to_segments(p, segs):
    a, b = segs[:, 0], segs[:, 1]
    d = b - a
    t = np.clip(np.einsum("kj,kj->k", p - a, d) / np.einsum("kj,kj->k", d, d), 0, 1)
    return np.linalg.norm(a + t[:, None] * d - p, axis=1).min()


@pytest.mark.parametrize("face, side", [(0, 1), (15, 1), (2, 1)])  # floor, light, back wall
def test_kink_segments_against_brute_force(cornell, face, side, rng):
    """Every pair of generator edges whose (front) parts lie in one plane crossing the
    emitter's: points of the plane's line on the emitter from which the two edges' images
    overlap (sampled densely, by angles in that plane) lie on a kink segment, and from
    which they are apart do not need one; and every kink segment's middle is such a point
    of some pair (no line where no two edges line up)."""
    segs = kink_segments(cornell, face, side)
    n = side * cornell.face_normal[face]
    c = float(n @ cornell.face_loops(face)[0][0])
    loop = cornell.face_loops(face)[0]
    eu, ev = plane_basis(n)
    basis = np.stack([eu, ev], axis=1)
    corners = (loop - loop[0]) @ basis
    lo2, hi2 = corners.min(axis=0), corners.max(axis=0)  # the Cornell faces are rectangles
    centre = loop.mean(axis=0)
    radius = np.linalg.norm(loop - centre, axis=1).max()
    edges = [f for f in (_front(s, n, c) for s in generator_segments(cornell)) if f is not None]
    lines = []
    tiny = 1e-9 * cornell.diagonal
    for a, b in itertools.combinations(edges, 2):
        pts = np.concatenate([a, b])
        if np.linalg.matrix_rank(pts[1:] - pts[0], tol=1e-7 * cornell.diagonal) != 2:
            continue  # not in one plane, or on one line
        m = np.linalg.svd(pts - pts.mean(axis=0))[2][2]
        d = np.cross(m, n)
        if np.linalg.norm(d) < 1e-9:
            continue  # the plane is the emitter's own (or parallel to it)
        d /= np.linalg.norm(d)
        up = np.cross(m, d)
        up *= np.sign(up @ n)
        # a point of the line: in both planes
        x0 = np.linalg.lstsq(np.stack([m, n]), np.array([m @ pts[0], c]), rcond=None)[0]
        lines.append((a, b, x0, d, up))
    checked = 0
    for a, b, x0, d, up in lines:
        # points of the line over the emitter's rectangle in its 2-D basis
        x0 = x0 + ((centre - x0) @ d) * d  # the line's point nearest the emitter's centre
        for s in rng.uniform(-radius, radius, 16):
            x = x0 + s * d
            q = (x - loop[0]) @ basis
            if np.any(q < lo2) or np.any(q > hi2) or min(np.linalg.norm(x - p) for p in np.concatenate([a, b])) < tiny:
                continue
            ov = _overlap(x, a, b, d, up)
            if ov > 1e-3:
                assert _distance_to_segments(x, segs) < 1e-6 * cornell.diagonal, (a, b, x)
                checked += 1
    assert checked > 20
    for p in 0.5 * (segs[:, 0] + segs[:, 1]):
        q = (p - loop[0]) @ basis
        if np.any(q < lo2) or np.any(q > hi2):
            continue
        on = [(a, b, d, up) for a, b, x0, d, up in lines if np.linalg.norm(np.cross(p - x0, d)) < 1e-6 * cornell.diagonal]
        assert any(_overlap(p, a, b, d, up) > -1e-6 for a, b, d, up in on), p


def _levels(cub, tri, deep=4):
    """Radon's rule on each triangle (g, 3, 3): (Q, its null-rule estimate, S on the four
    children, the rule on the 4^deep descendants) per triangle, the floor column."""
    q, e = cub.rule(tri, 1)
    kids = ff.split4(tri).reshape(-1, 3, 3)
    s = cub.rule(kids, 1)[0].reshape(-1, 4).sum(axis=1)
    fine = tri
    for _ in range(deep):
        fine = ff.split4(fine).reshape(-1, 3, 3)
    return q[:, 0], e[:, 0], s, cub.rule(fine, 1)[0].reshape(len(tri), -1).sum(axis=1)


def test_kink_cuts_make_the_row_estimate_honest(cornell):
    """Light → floor, the triangle at the light's corner (213, 227) whose opposite corner a
    kink line clips (an event of the short block, `test_estimate_sees_a_kink_clipping_a_corner`):
    uncut, the rule, its children and its null rule all miss the kink, and both of the
    row cubature's estimates (null rule for Q, |Q − S| for S) are below the error. Cut
    along the emitter's kink segments (the cells of `emitter_cells(kinks=True)`), each
    piece's estimates are above it."""
    setup = ff.PairSetup(cornell, 15, 1, ff.face_target(cornell, 0), 1)
    p = len(setup.occluders)

    def floor(points, tri=None):
        return setup.blocked(points, np.zeros(len(points), np.int64), np.array([0, p]), np.arange(p))[:, None]

    cub = ff.RowCubature(floor)
    tri = np.array([[[213.0, 548.7, 227.0], [245.5, 548.7, 227.0], [245.5, 548.7, 253.25]]])
    q, e, s, fine = _levels(cub, tri)
    assert abs(q - s) < abs(s - fine) and e < abs(q - fine)  # blind
    eu, ev = plane_basis(cornell.face_normal[15])
    o = tri[0, 0]
    to2 = np.stack([eu, ev], axis=1)
    segs = kink_segments(cornell, 15, 1)
    piece = (tri[0] - o) @ to2
    pieces = ff.cut_along([piece if ff._area2(piece) > 0 else piece[::-1]], (segs - o) @ to2, 1e-8 * cornell.diagonal)
    assert len(pieces) > 1
    cut = np.concatenate([np.stack([np.repeat(c[:1], len(c) - 2, axis=0), c[1:-1], c[2:]], axis=1) for c in pieces])
    cut = o + cut @ to2.T
    q, e, s, fine = _levels(cub, cut)
    assert abs(fine.sum() - _levels(cub, tri)[3].sum()) < 1e-3  # the same integral, roughly
    assert np.all(np.abs(s - fine) <= np.abs(q - s) + 1e-12)
    assert np.all(np.abs(q - fine) <= e + 1e-12)


def _box(x0, x1, y0, y1, h):
    """The four sides (normals out) and the top of a box standing on z = 0."""
    return [[[x0, y0, 0], [x1, y0, 0], [x1, y0, h], [x0, y0, h]], [[x1, y0, 0], [x1, y1, 0], [x1, y1, h], [x1, y0, h]],
            [[x1, y1, 0], [x0, y1, 0], [x0, y1, h], [x1, y1, h]], [[x0, y1, 0], [x0, y0, 0], [x0, y0, h], [x0, y1, h]],
            [[x0, y0, h], [x1, y0, h], [x1, y1, h], [x0, y1, h]]]


@pytest.fixture(scope="module")
def box_room():
    """A unit floor with a back and a left wall and a box standing on it (its vertical edges
    parallel to the walls' corner: kink lines through the floor)."""
    floor = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    back = [[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]]
    left = [[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]
    return scene_of([floor, back, left] + _box(0.3, 0.6, 0.4, 0.7, 0.4))


_ROWS = {}


def floor_row(box_room, tol):
    """The box room's floor row (front side, every face) at ``tol``, computed once for the
    tests below."""
    if tol not in _ROWS:
        _ROWS[tol] = ff.row_form_factors(box_room, 0, 1, np.arange(box_room.n_faces), tol)
    return _ROWS[tol]


def test_row_within_its_estimates_of_a_tight_row(box_room):
    """The box room's floor row and sky at tol 1e-3 and 1e-4 are within their estimates of
    the row at 1e-7 (plus its estimate)."""
    scene = box_room
    assert len(kink_segments(scene, 0, 1)) > 10
    ref = floor_row(scene, 1e-7)
    tight = dict(zip(ref[0], zip(ref[1], ref[2])))
    for tol in (1e-3, 1e-4):
        cols, F, E, _, sky, sky_e = floor_row(scene, tol)
        assert set(cols) == set(tight) and E.max() <= tol
        for c, f, e in zip(cols, F, E):
            assert abs(f - tight[c][0]) <= e + tight[c][1], (tol, c)
        assert abs(sky - ref[4]) <= sky_e + ref[5]


def test_rows_with_too_many_kink_cells_use_three_levels(box_room, monkeypatch):
    """Where the kink cells would cost more than three levels on the uncut cells (a
    cluttered scene: :data:`MAX_KINK_CELLS`), the row falls back to the three-level
    cubature; both agree within their estimates."""
    faces = np.arange(box_room.n_faces)
    kinked = floor_row(box_room, 1e-4)
    calls = []
    monkeypatch.setattr(ff, "MAX_KINK_CELLS", 0)
    monkeypatch.setattr(ff.ThreeLevelRowCubature, "levels", lambda self, *a, _r=ff.ThreeLevelRowCubature.levels:
                        calls.append(1) or _r(self, *a))
    plain = ff.row_form_factors(box_room, 0, 1, faces, 1e-4)
    assert calls and list(plain[0]) == list(kinked[0])
    assert np.all(np.abs(plain[1] - kinked[1]) <= plain[2] + kinked[2])
    assert abs(plain[4] - kinked[4]) <= plain[5] + kinked[5]


def test_a_shadow_between_the_start_nodes_is_looked_for(cornell):
    """Short block top+ → light+: the tall block's corner hides a small penumbra of the light
    near the short block's corner (∫ hidden = 0.0298 of 27,633, 1.1e-6 in F) that no node of
    the start triangles sees (their rules are 1e-12): their estimates said 1.4e-7 for an
    error of 9.3e-7 at tol 1e-4. The shaft test says an occluder may hide the light there,
    so those triangles start at their 16 grandchildren, and the entry is within its
    estimate of the 1e-7 row."""
    faces = np.arange(cornell.n_faces)
    ref = ff.row_form_factors(cornell, 5, 1, faces, 1e-7)
    r = ff.row_form_factors(cornell, 5, 1, faces, 1e-4)
    (k,), (j,) = np.flatnonzero(r[0] == 30), np.flatnonzero(ref[0] == 30)
    assert abs(r[1][k] - ref[1][j]) <= r[2][k] + ref[2][j]
    assert abs(r[1][k] - ref[1][j]) > 1e-8  # the rule is not exact there: the estimate matters


@pytest.mark.slow
@pytest.mark.parametrize("face", [0, 2])  # floor, back wall: kink lines of the blocks and the walls' corners
def test_cornell_rows_within_their_estimates_of_tight_rows(cornell, face):
    """The Cornell floor's and back wall's rows (and sky) at tol 1e-4 and 1e-6 are within
    their estimates of the same rows at 1e-7 (plus its estimates): the estimates are honest
    where D1 lines cross the emitter (with the three-level cubature of the uncut cells, back
    wall → tall block side 12− was 1.46× beyond its estimate at 1e-4)."""
    faces = np.arange(cornell.n_faces)
    ref = ff.row_form_factors(cornell, face, 1, faces, 1e-7)
    tight = dict(zip(ref[0], zip(ref[1], ref[2])))
    for tol in (1e-4, 1e-6):
        cols, F, E, _, sky, sky_e = ff.row_form_factors(cornell, face, 1, faces, tol)
        assert E.max() <= tol and sky_e <= tol
        for c, f, e in zip(cols, F, E):
            assert abs(f - tight[c][0]) <= e + tight[c][1], (tol, c)
        assert abs(sky - ref[4]) <= sky_e + ref[5]


def test_segments_meeting_a_box(rng):
    """cut_along's prefilter (ff._meets_box) keeps a segment exactly when more than eps of
    it lies in the box: against 2,001 points along each of 400 random segments (axis-
    parallel ones included), the brute-force length inside agreeing to 1/1000."""
    seg = rng.uniform(-2, 2, (400, 2, 2))
    seg[:50, 1, 0] = seg[:50, 0, 0]  # vertical
    seg[50:100, 1, 1] = seg[50:100, 0, 1]  # horizontal
    lo, hi, eps = np.array([-0.5, -0.3]), np.array([0.7, 0.4]), 1e-3
    got = ff._meets_box(seg, lo, hi, eps)
    t = np.linspace(0, 1, 2001)
    pts = seg[:, None, 0] + t[None, :, None] * (seg[:, None, 1] - seg[:, None, 0])
    inside = np.all((pts >= lo) & (pts <= hi), axis=2).mean(axis=1) * np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    clear = np.abs(inside - eps) > 4e-3  # away from the threshold, where sampling decides
    assert np.array_equal(got[clear], inside[clear] > eps)
    assert 50 < got.sum() < 350


def test_a_shadow_between_the_nodes_is_looked_for_where_the_shafts_say():
    """A first triangle whose nodes see nothing of a column that an occluder may hide there
    is replaced by its 4 children, and only the children whose shafts still meet an
    occluder of that column by their own 4 (the 16 grandchildren's node density where the
    shadow may be, none elsewhere: the column is exactly 0 there). A small shadow (a disc
    of radius 0.03 between the nodes of the triangle, inside one of its children): that
    child's 4 children and the 3 other children are evaluated, 7 triangles instead of 16,
    and their rules see it."""
    centre, radius = np.array([0.25, 0.05, 0.0]), 0.03

    def integrand(points, tri=None):
        return (np.linalg.norm(points - centre, axis=1) < radius).astype(np.float64)[:, None]

    def live(tri, need=None):
        # the disc meets the triangle: its centre inside, or an edge within the radius (sampled)
        t = np.linspace(0, 1, 201)
        edges = [tri[:, k, None] + t[None, :, None] * (tri[:, (k + 1) % 3, None] - tri[:, k, None]) for k in range(3)]
        near = np.min([np.linalg.norm(e - centre, axis=2).min(axis=1) for e in edges], axis=0) < radius
        side = [np.cross(tri[:, (k + 1) % 3] - tri[:, k], centre - tri[:, k])[:, 2] for k in range(3)]
        inside = np.all(np.array(side) > 0, axis=0)
        return (near | inside)[:, None]

    tri = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    cub = ff.RowCubature(integrand)
    q, e = cub.rule(tri, 1)
    assert q[0, 0] == 0.0 and e[0, 0] == 0.0 and live(tri)[0, 0]  # the nodes miss it
    new, nq, _, _, _ = cub._look_for_shadows(tri, q, e, live, 1)
    assert len(new) == 3 + 4
    assert nq.sum() > 0  # seen now
    assert np.allclose(ff.triangle_areas(new).sum(), 0.5)


@pytest.mark.parametrize("centre, radius", [((0.25, 0.05), 0.003), ((0.11, 0.13), 0.005)])
def test_a_shadow_the_search_misses_is_bounded_until_found(centre, radius):
    """A shadow smaller than the search's grandchildren's node spacing (a C1 bump
    (1 − ρ²)² of radius 3–5 mm: ∫ = π r² / 3) is missed by all their nodes: their rules and
    estimates say 0 and nothing refines them. Blind leaves (nodes seeing nothing, the shaft
    test saying the column may be hidden) carry the bound ``blind_bound`` gives (here the
    area: the integrand is at most 1) as their estimate, so the refinement goes on into
    them until it finds the bump: within its estimate of the exact integral."""
    centre = np.array([*centre, 0.0])

    def integrand(points, tri=None):
        d = np.linalg.norm(points - centre, axis=1) / radius
        return np.where(d < 1, (1 - d * d) ** 2, 0.0)[:, None]

    def live(tri, need=None):
        t = np.linspace(0, 1, 201)
        edges = [tri[:, k, None] + t[None, :, None] * (tri[:, (k + 1) % 3, None] - tri[:, k, None]) for k in range(3)]
        near = np.min([np.linalg.norm(e - centre, axis=2).min(axis=1) for e in edges], axis=0) < radius
        side = [np.cross(tri[:, (k + 1) % 3] - tri[:, k], centre - tri[:, k])[:, 2] for k in range(3)]
        return (near | np.all(np.array(side) > 0, axis=0))[:, None]

    exact = np.pi * radius ** 2 / 3
    tri = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    value, error, _ = ff.RowCubature(integrand).integrate(tri, np.array([1e-3 * exact]), live,
                                                          blind_bound=lambda t: ff.triangle_areas(t)[:, None])
    assert abs(value[0] - exact) <= error[0] <= 1e-3 * exact
    value, error, _ = ff.RowCubature(integrand).integrate(tri, np.array([1e-3 * exact]), live)
    assert value[0] == 0.0 and error[0] == 0.0  # without the bounds: missed, and said to be exact


def tile_under_receiver(half, tile=True):
    """The polygons of a unit floor, a square receiver of half-width ``half`` 1 above its
    centre (facing down: element 2) and (with ``tile``) a 0.01 tile hovering 0.03 over the
    floor at the point farthest from every node of the 21 rules of the floor's first
    triangles (0.031 from the nearest, found on a 181² grid)."""
    c = 0.665
    floor = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    lo, hi = 0.5 - half, 0.5 + half
    receiver = [[lo, lo, 1], [lo, hi, 1], [hi, hi, 1], [hi, lo, 1]]
    square = [[c - 0.005, c - 0.005, 0.03], [c + 0.005, c - 0.005, 0.03], [c + 0.005, c + 0.005, 0.03],
              [c - 0.005, c + 0.005, 0.03]]
    return [floor, receiver, square] if tile else [floor, receiver]


def test_a_shadow_between_the_three_level_nodes_is_looked_for(monkeypatch):
    """A row on three levels (:class:`ThreeLevelRowCubature`, forced by no kink cells
    allowed) looks for shadows between its nodes as :class:`RowCubature` does: a small tile
    hovering 0.03 over a unit floor, at the point farthest from every node of the 21 rules
    of the floor's first triangles (0.031 from the nearest), hides a bit of the receiver
    above. Without the search the floor → receiver entry is 1.2e-6 off for an estimate of
    1.3e-15 at tol 1e-4; with it, within its estimate of the pair's F at 1e-9."""
    monkeypatch.setattr(ff, "MAX_KINK_CELLS", 0)
    scene = scene_of(tile_under_receiver(0.1))
    faces = np.arange(scene.n_faces)
    ref = ff.face_to_face(scene, 0, 1, side_i=1, tol=1e-9)

    def entry():
        cols, F, E, *_ = ff.row_form_factors(scene, 0, 1, faces, 1e-4)
        assert not ff.cubature_cells(scene, 0, 1)[2]  # on three levels
        (k,) = np.flatnonzero(cols == 2)
        return F[k], E[k]

    F, E = entry()
    assert abs(F - ref["F"]) <= E + ref["error"]
    monkeypatch.setattr(ff, "shadow_triangles", lambda tri, blind, live: (np.zeros(len(tri), bool), np.zeros((0, 3, 3)),
                                                                             np.zeros(0, np.int64)))
    F, E = entry()
    assert abs(F - ref["F"]) > 100 * (E + ref["error"])  # without the search: the shadow unseen


def test_the_shadow_search_reuses_the_first_triangles_finer_levels(monkeypatch):
    """A child the shadow search keeps whole takes its first triangle's second and third
    levels as its first two (only its 16 grandchildren evaluated, 112 points instead of
    142): the tile's row gives the same entries and estimates as with every new triangle on
    levels of its own (``whole`` emptied: the search as before), to rounding, with fewer
    points, and the entry within its estimate of the pair's F at 1e-9."""
    monkeypatch.setattr(ff, "MAX_KINK_CELLS", 0)
    scene = scene_of(tile_under_receiver(0.1))
    faces = np.arange(scene.n_faces)
    kept = []
    search = ff.shadow_triangles

    def spy(tri, blind, live):
        unseen, new, whole = search(tri, blind, live)
        kept.append(len(whole))
        return unseen, new, whole

    def row():
        evaluations = []
        levels = ff.ThreeLevelRowCubature.integrate

        def integrate(self, *a, **k):
            out = levels(self, *a, **k)
            evaluations.append(self.evaluations)
            return out

        with monkeypatch.context() as m:
            m.setattr(ff.ThreeLevelRowCubature, "integrate", integrate)
            cols, F, E, *_ = ff.row_form_factors(scene, 0, 1, faces, 1e-4)
        return cols, F, E, evaluations[0]

    monkeypatch.setattr(ff, "shadow_triangles", spy)
    cols, F, E, points = row()
    assert kept[-1] > 0
    monkeypatch.setattr(ff, "shadow_triangles", lambda *a: (*search(*a)[:2], np.zeros(0, np.int64)))
    cols0, F0, E0, points0 = row()
    assert list(cols) == list(cols0)
    assert np.allclose(F, F0, rtol=0, atol=1e-14) and np.allclose(E, E0, rtol=1e-9, atol=1e-16)
    assert points0 - points == 30 * kept[-1]  # 7 + 4 · 7 = 35 known, less the middle child's shared centroid
    ref = ff.face_to_face(scene, 0, 1, side_i=1, tol=1e-9)
    (k,) = np.flatnonzero(cols == 2)
    assert abs(F[k] - ref["F"]) <= E[k] + ref["error"]


def test_front_unoccluded_against_the_point_form_factor():
    """The exact bound of the shadow search (:func:`viscx.queries.formfactor.front_unoccluded`):
    ∫ F(x → J') over triangles of a floor straddling the plane of a wall piece standing on
    it (F is 0 behind it), against a Radon rule on 4,096 sub-triangles of each of the exact
    point-to-polygon F (set to 0 behind the plane), within the rule's change from 1,024. The contour integral of the whole
    triangles, unclipped, is not it."""
    from viscx.geometry.formfactor import point_to_polygon

    floor = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    wall = [[0.5, 0.2, 0.1], [0.5, 0.2, 0.6], [0.5, 0.8, 0.6], [0.5, 0.8, 0.1]]  # facing -x
    scene = scene_of([floor, wall])
    setup = ff.PairSetup(scene, 0, 1, ff.face_target(scene, 1), 1, occluders=False)
    tri = np.array([[[0.3, 0.1, 0], [0.7, 0.3, 0], [0.4, 0.9, 0]], [[0.45, 0.4, 0], [0.6, 0.45, 0], [0.5, 0.6, 0]]])
    value, error = ff.front_unoccluded(setup, tri)

    def oracle(levels):
        fine = tri
        for _ in range(levels):
            fine = ff.split4(fine).reshape(-1, 3, 3)
        pts = np.einsum("rk,gkd->grd", ff.RULE_NODES, fine).reshape(-1, 3)
        f = point_to_polygon(pts, np.broadcast_to(setup.n_i, pts.shape), setup.J) * (pts @ setup.n_t >= setup.c_t)
        return float((f.reshape(len(fine), 7) @ ff.RULE_WEIGHTS) @ ff.triangle_areas(fine))

    coarse, fine = oracle(5), oracle(6)  # the kink along the wall's plane: the rule converges as h³
    assert fine > 1e-3 and abs(value - fine) <= error + abs(fine - coarse) < 2e-5 * fine
    whole = setup.unoccluded_integral(tri)[0]
    assert abs(whole - fine) > 1e-4


def test_an_unseen_shadow_of_a_small_far_receiver_is_bounded_not_looked_for(monkeypatch):
    """The tile of the test above hovering between the nodes under a receiver of 0.02 square
    (F ≈ 9.6e-5 from the floor, 1.0e-8 of it hidden) at tol 1e-3: the shadow search's bound
    (the hidden part lies between 0 and F(x → J), whose integral over the triangles where
    the column is unseen is at most the pair's whole contour term,
    :func:`viscx.queries.formfactor.unseen_shadow_bound`) is within a quarter of the
    budget, so the triangles are not split for it (fewer points) and the bound is the
    entry's estimate there: within it of the pair's F at 1e-9. Settled without the bound in
    the estimate (the search skipped, nothing added) the entry is off by more than 10 times
    its estimate and the reference's, as without the search; looked for (the bound switched
    off) it costs more points for an entry within its estimate too."""
    monkeypatch.setattr(ff, "MAX_KINK_CELLS", 0)
    scene = scene_of(tile_under_receiver(0.01))
    faces = np.arange(scene.n_faces)
    ref = ff.face_to_face(scene, 0, 1, side_i=1, tol=1e-9)
    unoccluded = ff.face_to_face(scene_of(tile_under_receiver(0.01, tile=False)), 0, 1, side_i=1, tol=1e-9)["F"]
    assert 1e-9 < unoccluded - ref["F"] and unoccluded < 0.25e-3  # a shadow, and a bound within the share

    def entry():
        cols, F, E, counts, *_ = ff.row_form_factors(scene, 0, 1, faces, 1e-3)
        (k,) = np.flatnonzero(cols == 2)
        return F[k], E[k], counts["evaluations"]

    F, E, points = entry()
    assert abs(F - ref["F"]) <= E + ref["error"]
    with monkeypatch.context() as m:
        m.setattr(ff, "SHADOW_BOUND", -1.0)  # no bound: looked for
        F1, E1, points1 = entry()
    assert points1 > points and abs(F1 - ref["F"]) <= E1 + ref["error"]
    # settled without its bound in the estimate: dishonest
    bound = ff.unseen_shadow_bound
    monkeypatch.setattr(ff, "unseen_shadow_bound", lambda *a: (lambda tri, blind, seen: (
        bound(*a)(tri, blind, seen)[0], np.zeros(blind.shape[1]))))
    F, E, _ = entry()
    assert abs(F - ref["F"]) > 10 * (E + ref["error"])  # 1.0e-8 off for 1.2e-15 (+ the reference's 4e-10)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_merge_collinear_is_the_union_of_each_lines_pieces(seed):
    """:func:`viscx.queries.kinks.merge_collinear` against a plain interval union: pieces
    drawn on a few known lines (each given either way round, some overlapping, touching,
    nested, or apart by less or more than the 1e-9 join), per line the union of their
    spans, compared as sets of end points."""
    from viscx.queries.kinks import merge_collinear

    rng = np.random.default_rng(seed)
    scale = 10.0
    gap = 1e-9 * scale
    dirs = rng.standard_normal((6, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dirs[0] = [1.0, 0.0, 0.0]
    dirs[1] = [0.0, -1.0, 0.0]  # turned round: lines keep one direction
    points = rng.uniform(-3, 3, (6, 3))
    points[2] = points[3] + 0.5 * np.cross(dirs[3], [0.0, 0.0, 1.0])  # two parallel lines
    dirs[2] = dirs[3]
    k = int(rng.integers(50, 400))
    line = rng.integers(0, 6, k)
    t0 = rng.integers(-8, 8, k) * 0.5
    t1 = t0 + rng.choice([0.25, 0.5, 1.0, 2.0], k) - rng.choice([0.0, 0.5 * gap, 50 * gap], k)  # short of a start
    a = points[line] + t0[:, None] * dirs[line]
    b = points[line] + t1[:, None] * dirs[line]
    swap = rng.random(k) < 0.5
    a[swap], b[swap] = b[swap].copy(), a[swap].copy()
    want = []
    for r in np.unique(line):
        spans = sorted(zip(t0[line == r], t1[line == r]))
        lo, hi = spans[0]
        for x, y in spans[1:] + [(np.inf, np.inf)]:
            if x > hi + gap:
                want.append(_ends_in_order(np.stack([points[r] + lo * dirs[r], points[r] + hi * dirs[r]])))
                lo, hi = x, y
            else:
                hi = max(hi, y)
    got = merge_collinear(a, b, np.zeros(3), scale)
    assert got.shape == (len(want), 2, 3)
    key = lambda s: tuple(np.round(s.ravel(), 6))
    want, got = sorted(want, key=key), sorted(map(_ends_in_order, got), key=key)
    for w, g in zip(want, got):
        assert np.allclose(g, w, rtol=0, atol=1e-12)


def _ends_in_order(seg):
    """A segment (2, 3) with its ends in lexicographic order."""
    return seg if tuple(seg[0]) <= tuple(seg[1]) else seg[::-1]


def test_kink_pairs_in_blocks_and_past_the_cap(cornell, monkeypatch):
    """The segment pairs are tested in blocks of whole rows (memory linear in the block, not
    quadratic in the segments: the 122,892-triangle spheres listed 1.7 · 10¹⁰ pairs at
    once): blocks of 7 pairs give the segments of one block, array for array; past
    ``MAX_KINK_GENERATORS`` segments in front the lines are not listed (None), and the
    emitter's kinked cells are None too, so its row keeps the cells without them."""
    from viscx.queries import kinks

    floor = int(cornell.group_faces("floor")[0])
    whole = kink_segments(cornell, floor, 1)
    monkeypatch.setattr(kinks, "PAIR_BLOCK", 7)
    assert len(whole) and np.array_equal(kink_segments(cornell, floor, 1), whole)
    monkeypatch.setattr(kinks, "MAX_KINK_GENERATORS", 10)
    assert kink_segments(cornell, floor, 1) is None
    assert ff.emitter_cells(cornell, floor, 1, kinks=True) is None


def test_kink_lines_stop_once_the_caller_has_too_many(cornell, monkeypatch):
    """``past`` is asked of the lines of the pairs listed so far, each time their number
    has doubled: the lines asked are pieces of the whole list's (pairs only add lines), the
    list is the same when it never says stop, and None at its first True."""
    from viscx.queries import kinks

    floor = int(cornell.group_faces("floor")[0])
    whole = kink_segments(cornell, floor, 1)
    monkeypatch.setattr(kinks, "FIRST_BLOCK", 7)
    asked = []
    assert np.array_equal(kink_segments(cornell, floor, 1, past=lambda seg: asked.append(seg) or False), whole)
    assert len(asked) >= 2 and len(asked[-1]) < len(whole)
    for seg in asked:
        for end in seg.reshape(-1, 3):
            assert _distance_to_segments(end, whole) <= 1e-9 * cornell.diagonal
    calls = []
    assert kink_segments(cornell, floor, 1, past=lambda seg: calls.append(1) or True) is None
    assert calls == [1]


def test_emitter_cells_stop_cutting_past_the_limit_as_the_whole_cut_would(cornell, monkeypatch):
    """The kinked cells are None as soon as the lines of the first pairs cut past the limit
    (:func:`viscx.queries.formfactor.emitter_cells`), and exactly when cutting along all the
    lines would be: on each side of the limit, the Cornell floor's cells as before."""
    from viscx.queries import kinks

    floor = int(cornell.group_faces("floor")[0])
    full = ff.emitter_cells(cornell, floor, 1, kinks=True, limit=10 ** 6)  # one block: no early stop
    monkeypatch.setattr(kinks, "FIRST_BLOCK", 7)
    listed = []
    pair_kinks = kinks._pair_kinks
    monkeypatch.setattr(kinks, "_pair_kinks", lambda *a: listed.append(a[-1] - a[-2]) or pair_kinks(*a))
    same = ff.emitter_cells(cornell, floor, 1, kinks=True, limit=len(full))
    assert len(same) == len(full) and all(np.array_equal(a, b) for a, b in zip(same, full))
    everything = sum(listed)
    listed.clear()
    assert ff.emitter_cells(cornell, floor, 1, kinks=True, limit=len(full) - 1) is None
    listed.clear()
    assert ff.emitter_cells(cornell, floor, 1, kinks=True, limit=len(full) // 4) is None
    assert 0 < sum(listed) < everything  # stopped before all the pairs were listed


def test_rows_keep_or_cut_their_cells_as_along_all_their_lines(office60, monkeypatch):
    """A matrix row's cells (:func:`viscx.queries.formfactor.cubature_cells` with its
    computed receivers and the sky) are those of the rule without its short cuts: cut along
    the lines of all its generators (:func:`viscx.queries.formfactor.kink_faces`, the sky's),
    listed whole, when that makes few enough cells, else uncut. The short cuts (the
    receivers' own lines tried first, the lines tried as the pairs are listed) decide some
    sides of the furnished room before listing them all, the same way."""
    from viscx.queries import kinks
    from viscx.queries.kinks import face_generators, sky_generators

    scene = office60
    faces = np.arange(scene.n_faces, dtype=np.int64)
    seen = {True: 0, False: 0, "before kink_faces": 0}
    kink_faces = ff.kink_faces
    asked = []
    monkeypatch.setattr(ff, "kink_faces", lambda *a: asked.append(1) or kink_faces(*a))
    for face in range(0, scene.n_faces, 3):
        for side in (1, -1):
            mine = faces[ff.computed_pairs(scene, face, faces)]
            if not len(ff.facing_sides(scene, face, side, mine)[0]):
                continue
            size = 0.3
            sky = ff.may_see_sky(scene, face, side)
            asked.clear()
            cells, tri, kinked = ff.cubature_cells(scene, face, side, size, mine, sky)
            seen["before kink_faces"] += not asked
            with monkeypatch.context() as m:
                m.setattr(kinks, "FIRST_BLOCK", 1 << 40)  # every pair in one block: nothing asked early
                m.setattr(kinks, "PAIR_BLOCK", 1 << 40)
                plain = ff.emitter_cells(scene, face, side)
                start = ff.start_triangles(plain, size)
                limit = min(ff.MAX_KINK_CELLS, 21 * len(start))
                gen = face_generators(scene, kink_faces(scene, face, side, mine))
                if sky:
                    gen = np.union1d(gen, sky_generators(scene, face))
                whole = None if len(plain) > limit else ff.emitter_cells(scene, face, side, True, limit, gen)
            expect = whole is not None and len(ff.start_triangles(whole, size)) <= 21 * len(start)
            assert kinked == expect, (face, side)
            want = whole if expect else plain
            assert len(cells) == len(want) and all(np.array_equal(a, b) for a, b in zip(cells, want))
            seen[kinked] += 1
    assert seen[True] >= 3 and seen[False] >= 3 and seen["before kink_faces"] >= 3, seen


def test_the_sky_is_seen_beside_no_edge_sky_generators_leaves_out(cornell):
    """:func:`viscx.queries.kinks.sky_generators` against brute-force rays: from points of
    the ceiling, the back wall and the light, a ray passing just beside an interior point of
    an edge it leaves out (in front of the face), on either side, always meets a face; beside
    the edges it keeps (the open front's rims, the blocks' outlines) some rays reach the sky."""
    from oracles import first_face_reference

    from viscx.queries.kinks import sky_generators

    s, rng = cornell, np.random.default_rng(7)
    seg = generator_segments(s)
    tri = s.triangles
    for face in (1, 2, 15):
        n = s.face_normal[face]
        keep = np.zeros(len(seg), bool)
        keep[sky_generators(s, face)] = True
        ahead = (seg @ n - n @ s.face_loops(face)[0][0]).max(axis=1) > 1e-6 * s.diagonal
        assert np.any(~keep & ahead) and np.any(keep & ahead)
        corners = s.vertices[tri[s.triangle_face == face]]
        escaped = 0
        for k in np.flatnonzero(ahead):
            w = rng.dirichlet([4, 4, 4], 64)
            x = np.einsum("gk,gkd->gd", w, corners[rng.integers(0, len(corners), 64)]) + 1e-6 * s.diagonal * n
            p = seg[k, 0] + rng.uniform(0.05, 0.95, 64)[:, None] * (seg[k, 1] - seg[k, 0])
            d = p - x
            across = np.cross(d, seg[k, 1] - seg[k, 0])
            across /= np.linalg.norm(across, axis=1)[:, None]
            for sign in (1, -1):
                aim = p + sign * 1e-4 * np.linalg.norm(d, axis=1)[:, None] * across
                hit, _, _ = first_face_reference(x, aim - x, np.full(64, 3 * s.diagonal), s.vertices, tri,
                                                 s.triangle_face)
                if keep[k]:
                    escaped += int(np.sum(hit < 0))
                else:
                    assert np.all(hit >= 0), (face, k)
        assert escaped > 0, face


def test_rows_cut_along_the_kinks_of_what_they_compute(cornell):
    """A matrix row that computes only some of its columns (reciprocity: the ceiling only its
    sky, the floor the ceiling and its sky) is cut along those columns' kink lines
    (its pairs' :func:`viscx.queries.formfactor.kink_faces` and the sky's
    :func:`viscx.queries.kinks.sky_generators`): fewer cells than with every line, and its
    entries within their estimates of the row cut along every line at a tolerance 10 times
    finer (every entry asked of it: no restriction)."""
    s = cornell
    faces = np.arange(s.n_faces)
    for face in (0, 1):
        asked = faces[ff.computed_pairs(s, face, faces)]
        assert len(asked) < s.n_faces - 1
        every = ff.cubature_cells(s, face, 1)[0]
        own = ff.cubature_cells(s, face, 1, receivers=asked, sky=True)[0]
        assert len(own) < 0.8 * len(every)
        row = ff.row_form_factors(s, face, 1, faces, 1e-4, reciprocal=True)
        tight = ff.row_form_factors(s, face, 1, faces, 1e-5)
        ref = dict(zip(tight[0], zip(tight[1], tight[2])))
        for col, value, err in list(zip(*row[:3])) + [("sky", row[4], row[5])]:
            f_ref, e_ref = (tight[4], tight[5]) if col == "sky" else ref[col]
            assert abs(value - f_ref) <= err + e_ref, (face, col)
