"""A matrix row at once (viscx.queries.formfactor.row_form_factors): every receiver from one
hidden-surface computation per point of the emitter (viscx.geometry.occlusion.point_views),
against the per-pair kernel, and faces lying on faces (docs/queries.md)."""

import numpy as np
import pytest
from conftest import SAMPLES
from oracles import cosine_directions, first_face_reference
from test_formfactor_queries import scene_of

from viscx.geometry.occlusion import SNAP, _collinear, _snap_breaks, point_views
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


def assert_columns_equal_pairs(scene, face, pts, h, side=1):
    """Every face-side column of ``point_views`` from a side of ``face`` at ``pts`` equals
    the pair kernel (:func:`blocked_form_factors`: per pair, its own occluders clipped and
    swept in J's plane, another sweep than the hemicube's) within 1e-12.

    As in :func:`viscx.queries.formfactor.pair_form_factor`, the cells of J covered from
    side t (:func:`covered_cells`: a tile lying on the floor, seen from above) are holes of
    the pair's target, so the pair kernel gives what x sees of J minus them; the column
    (hidden part of the whole of J) is then F(x → J) − that. Without the holes, from a box
    face above the tiled floor the floor's column differs by F(x → tile) (2.2e-3)."""
    group = np.zeros(len(pts), np.int64)
    for j in range(scene.n_faces):
        for t in (1, -1):
            col = h[:, 2 * j + (t < 0)]
            target = ff.face_target(scene, j)
            st = ff.PairSetup(scene, face, side, target, t)
            if st.empty or j == face:
                assert np.abs(col).max() < 1e-12
                continue
            covered = ff.covered_cells(scene, j, t)
            if covered:
                st_free = ff.PairSetup(scene, face, side, ff.Target(target.loops + covered, target.normal, j), t)
                ref = st.f(pts, st.kernel_for([])) - st_free.f(pts)
            else:
                k = len(st.occluders)
                ref = st.blocked(pts, group, np.array([0, k]), np.arange(k)) if k else np.zeros(len(pts))
            assert np.abs(col - ref).max() < 1e-12, (j, t)


@pytest.mark.parametrize("face", [0, 1, 2, 15])  # floor, ceiling (light 0.1 mm under it), back wall, light
def test_point_views_equal_the_pair_kernel(cornell, face, rng):
    """Every column of the row kernel (hidden part of each face side) equals the pair kernel
    (:func:`blocked_form_factors` past the pair's culled occluders), and the sky column equals
    what the pair kernel sees of the six sky boxes."""
    pts = emitter_points(cornell, face, 12, rng)
    h = views(cornell, face, 1, pts)
    assert_columns_equal_pairs(cornell, face, pts, h)
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


def test_reciprocity_imposed_against_the_two_sided_matrix():
    """The matrix computes each pair in the rows of its smaller face and derives the other
    direction (``A_a F_ab = A_b F_ba``, its estimate scaled by A_a / A_b): reciprocity holds
    to rounding, and the matrix computed two-sided (every entry on its own, the oracle) is
    within the estimates of both entry by entry, its own reciprocity within its estimates.
    Rows + sky = 1 stays a check (the derived entries come from other rows), and the matrix
    is the same bit for bit on 1 and 2 processes."""
    from test_formfactor_queries import square

    scene = scene_of([square(0), square(1, size=0.5, flip=True), [[0.3, 0.3, 0.5], [0.6, 0.35, 0.5], [0.45, 0.7, 0.55]]])
    m = ff.form_factor_matrix(scene, tol=1e-6, workers=1)
    two = ff.form_factor_matrix(scene, tol=1e-6, workers=1, reciprocal=False)
    assert m.summary()["reciprocity"] == "imposed" and two.summary()["reciprocity"] == "measured"
    assert m.method_counts["derived"] > 0 and m.reciprocity_error() < 1e-15
    F, E, F2, E2 = m.dense(), ff.Matrix.dense(_errors(m)), two.dense(), ff.Matrix.dense(_errors(two))
    assert np.array_equal(F != 0, F2 != 0)
    assert np.all(np.abs(F - F2) <= E + E2 + 1e-14)
    a = np.repeat(scene.face_area, 2)
    flux, bound = a[:, None] * F2, a[:, None] * E2
    assert np.all(np.abs(flux - flux.T) <= bound + bound.T + 1e-14)
    assert two.reciprocity_error() > 1e-12  # two-sided, it is a measurement
    # the face of smaller area computes: square 1 (0.25) to square 0 (1), derived back
    assert ff.computed_pairs(scene, 1, np.array([0, 2])).tolist() == [True, scene.face_area[2] > 0.25]
    assert np.isclose(F[0, 2], F[2, 0] * scene.face_area[1] / scene.face_area[0], rtol=1e-15, atol=0)
    assert np.abs(m.row_sums() - 1).max() < 1e-5
    par = ff.form_factor_matrix(scene, tol=1e-6, workers=2)
    for k in ("indptr", "indices", "data", "error", "sky", "sky_error"):
        assert np.array_equal(getattr(par, k), getattr(m, k)), k


def _errors(m):
    """The matrix ``m`` with its error estimates as its values (for :meth:`Matrix.dense`)."""
    return ff.Matrix(m.indptr, m.indices, m.error, m.error, m.sky, m.sky_error, m.area, {}, 0.0, m.tol)


def test_reciprocity_in_units_of_the_smaller_and_the_larger_face():
    """|A_a F_ab − A_b F_ba| over min(A) and over max(A): a big face (area 100) whose entry
    to a small one (area 1) is 1e-4 off weighs 100 times in the small face's F units."""
    z = np.zeros
    # faces 0 (area 1) and 1 (area 100): F[front 0 -> front 1] = 0.5, F[front 1 -> front 0] = 0.005 + 1e-4
    m = ff.Matrix(np.array([0, 1, 1, 2, 2]), np.array([2, 0]), np.array([0.5, 0.005 + 1e-4]), z(2), z(4), z(4),
                  np.array([1.0, 100.0]), {}, 0.0, 1e-4)
    assert abs(m.reciprocity_error() - 1e-2) < 1e-12
    assert abs(m.reciprocity_error("larger") - 1e-4) < 1e-12
    assert m.summary()["reciprocity_max_error_larger"] == m.reciprocity_error("larger")


def touching_boxes(rng):
    """A 10 × 10 floor (face 0, normal +y) with, on it, a row of two to four axis-aligned
    closed boxes each touching the next along a whole face, a box stacked on the first
    (its bottom lying on the first's top, smaller: faces lying on faces), and a tile lying
    on the floor: shared edges, coincident edges seen from every point, coplanar faces."""
    quads = [[[0, 0, 0], [0, 0, 10], [10, 0, 10], [10, 0, 0]]]

    def box(lo, hi):
        c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        for q in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
            quads.append(c[list(q)].tolist())

    x = float(rng.uniform(1, 3))
    z0, z1 = float(rng.uniform(2, 4)), float(rng.uniform(6, 8))
    first = None
    for _ in range(int(rng.integers(2, 5))):
        w, hgt = float(rng.uniform(0.8, 1.6)), float(rng.uniform(0.5, 2.5))
        box((x, 0, z0), (x + w, hgt, z1))
        first = first or (x, w, hgt)
        x += w
    x, w, hgt = first
    box((x + 0.2 * w, hgt, z0 + 0.5), (x + 0.8 * w, hgt + 1.0, z1 - 0.5))
    t = float(rng.uniform(7, 8.5))
    quads.append([[t, 0, 1], [t, 0, 2], [t + 1, 0, 2], [t + 1, 0, 1]])  # a tile facing up, lying on the floor
    return scene_of([np.asarray(q, float) for q in quads])


@pytest.mark.parametrize("seed, emitters", [(0, (0, -6)), pytest.param(1, None, marks=pytest.mark.slow)])
def test_point_views_among_touching_boxes(seed, emitters):
    """The row kernel's sweep (its owners reused from slab to slab where a region keeps its
    two edges and covering polygons, searched again in slivers between coincident edges)
    against the pair kernel, on boxes touching along faces and faces lying on faces: from
    the floor, and from the stacked box's +x face (its bottom edge on the first box's top,
    the tile lying on the floor in view: the floor minus the tile is what it sees); the
    slow case from every face. Points in contact (a −1 column: they see the side they lie
    against only, which the pair queries take exactly from their contact cells) are left out."""
    rng = np.random.default_rng(seed)
    scene = touching_boxes(rng)
    faces = range(scene.n_faces) if emitters is None else [f % scene.n_faces for f in emitters]
    n_free = 0
    for face in faces:
        pts = emitter_points(scene, face, 12 if emitters is None else 6, rng)
        h = views(scene, face, 1, pts)
        free = ~np.any(h[:, :-1] == -1.0, axis=1)
        n_free += free.sum()
        if free.any():
            assert_columns_equal_pairs(scene, face, pts[free], h[free])
    assert n_free >= 4 * len(faces)


@pytest.mark.slow  # 10^6 brute-force rays (numpy): ~13 CPU s
def test_point_views_see_the_floor_minus_the_tile_by_rays():
    """From the stacked box's +x face (its bottom edge on the first box's top), what a point
    sees of the floor's front, by 10^6 cosine-weighted rays (brute-force first hits; a ray
    meeting the floor and the tile lying on it at one distance meets the tile: the smaller
    lies on the larger's front), within 4 σ of ``point_views``. Without the tile's covered
    cell as a hole of the pair's target, the pair kernel counts the floor under the tile as
    seen: 0.07280 against 0.07067 ± 0.00026 by the rays (8 σ; point_views 0.07062)."""
    rng = np.random.default_rng(0)
    scene = touching_boxes(rng)
    face, floor, tile = scene.n_faces - 6, 0, scene.n_faces - 1
    x = emitter_points(scene, face, 6, rng)[2]
    n = scene.face_normal[face]
    h = views(scene, face, 1, x[None])
    st = ff.PairSetup(scene, face, 1, ff.face_target(scene, floor), 1)
    seen = st.f(x[None], st.kernel_for([]))[0] - h[0, 0]
    assert seen > 0.05  # the floor beyond the boxes, the tile in view
    k, chunk, hits = 1_000_000, 40_000, 0
    ray_rng = np.random.default_rng(1)
    for _ in range(k // chunk):
        d = cosine_directions(np.broadcast_to(n, (chunk, 3)), ray_rng)
        _, _, tied = first_face_reference(np.broadcast_to(x + 1e-9 * n, (chunk, 3)), d, np.full(chunk, 2 * scene.diagonal),
                                          scene.vertices, scene.triangles, scene.triangle_face, tie=1e-9)
        hits += int(np.sum(tied[:, floor] & ~tied[:, tile] & (d @ scene.face_normal[floor] < 0)))
    est = hits / k
    assert abs(seen - est) < 4 * np.sqrt(est * (1 - est) / k), (seen, est)


def test_sweep_breaks_and_crossings_within_snap_are_rounding():
    """The row kernel's sweep takes breaks within SNAP of the last one kept for one (the
    last break kept where the sweep ends), and two edges whose ends lie within SNAP of
    each other's line for collinear (no crossing); a real offset or crossing stays."""
    us = np.array([0.0, 1e-16, 0.5, 0.5 + 5e-15, 0.7, 1.0 - 1e-15, 1.0])
    n = _snap_breaks(us, len(us), SNAP)
    assert us[:n].tolist() == [0.0, 0.5, 0.7, 1.0]
    assert _snap_breaks(np.array([0.0, 1e-13]), 2, SNAP) == 2
    # e on a line, f on it up to rounding, g 1e-12 off it, h crossing it
    a = np.array([[0.1, 0.2], [0.3, 0.3 + 1e-16], [0.3, 0.3 + 1e-12], [0.3, 0.0]])
    b = np.array([[0.9, 0.6], [1.1, 0.7 - 1e-16], [1.1, 0.7 + 1e-12], [0.5, 0.9]])
    assert _collinear(a, b, 0, 1, SNAP) and _collinear(a, b, 1, 0, SNAP)
    assert not _collinear(a, b, 0, 2, SNAP) and not _collinear(a, b, 0, 3, SNAP)


def test_a_sliver_slab_does_not_hand_a_wrong_owner_on(cornell):
    """A point of the Cornell light (face 15, seen downwards) whose sweep has a slab barely
    wider than SNAP (1.2e-14) holding coincident edges: there the edge order and a sliver
    region's owner are rounding, so the event-local sweep must search the next slab's owners
    again instead of reusing that one (reused, column 20 was off by 0.014). Checked against
    the pair kernel, column by column."""
    pts = np.array([[270.09516994108697, 548.6999999999999, 314.91157856591104]])
    side = 1 if cornell.face_normal[15][1] < 0 else -1
    h = views(cornell, 15, side, pts)
    assert_columns_equal_pairs(cornell, 15, pts, h, side=side)


def _cyclic(seq, first):
    seq = list(seq)
    k = seq.index(first)
    return seq[k:] + seq[:k]


def test_hull_order_is_qhulls(rng):
    """The pairs' hulls (:func:`viscx.queries.formfactor.hull_order`): a single strictly
    convex counter-clockwise loop is its own hull; a clockwise, non-convex or holed one goes
    to the monotone chain; both give Qhull's hull (as a cyclic sequence)."""
    from scipy.spatial import ConvexHull

    for k in (3, 4, 7):
        angles = np.sort(rng.uniform(0, 2 * np.pi, k))
        loop = np.stack([np.cos(angles), 2 * np.sin(angles)], axis=1) + rng.normal(size=2)
        fast = ff.hull_order([loop])
        assert list(fast) == list(range(k))
        qh = list(ConvexHull(loop).vertices)
        assert qh == _cyclic(fast, qh[0])
        cw = ff.hull_order([loop[::-1]])  # clockwise: the chain, counter-clockwise again
        qh = list(ConvexHull(loop[::-1]).vertices)
        assert sorted(cw) == list(range(k)) and _cyclic(cw, qh[0]) == qh
    dent = np.array([[0, 0], [2, 0], [1, 0.5], [2, 2], [0, 2.0]])  # not convex: vertex 2 is not on the hull
    assert _cyclic(ff.hull_order([dent]), 0) == [0, 1, 3, 4]
    # clouds and holed loops, with points on the hull's edges (left out, as by Qhull)
    for _ in range(20):
        pts = rng.integers(0, 5, size=(int(rng.integers(4, 30)), 2)).astype(np.float64) + rng.normal(size=2)
        pts = np.unique(pts, axis=0)
        rng.shuffle(pts)
        cut = int(rng.integers(1, len(pts)))
        qh = list(ConvexHull(pts).vertices)
        assert _cyclic(ff.hull_order([pts[:cut], pts[cut:]]), qh[0]) == qh
    with pytest.raises(ValueError):
        ff.hull_order([np.array([[0.0, 0], [1, 1], [2, 2]]), np.array([[3.0, 3]])])  # collinear: no area


def test_contour_terms_are_shared_by_both_orders_only_where_unclipped(cornell):
    """:func:`viscx.queries.formfactor.pair_contour`: a facing pair whose polygons are
    both wholly in front of the other's plane gets one contour integral for both orders
    (A_i F⁰_ij = A_j F⁰_ji exactly), each within its estimate of its own integral; a pair
    sharing an edge (each row clips its emitter off the other's plane) is not shared."""
    scene = load_scene(SAMPLES / "cornell_box.obj")  # a fresh memo
    floor, ceiling, back = (int(scene.group_faces(g)[0]) for g in ("floor", "ceiling", "back_wall"))

    def setup(i, s, j, t):
        return ff.PairSetup(scene, i, s, ff.face_target(scene, j), t, occluders=False)

    pairs = {}
    for i, s, j, t in ((floor, 1, ceiling, 1), (ceiling, 1, floor, 1), (floor, 1, back, 1), (back, 1, floor, 1)):
        st = setup(i, s, j, t)
        pairs[i, j] = (ff.pair_contour(scene, st, (i, s, j, t)), ff.contour_form_factor(st.I, st.n_i, st.J, st.n_t),
                       ff.loops_area(st.I, st.n_i))
    memo = scene.cached("pair contours", lambda s: {})
    assert (floor, 1, ceiling, 1) in memo and (ceiling, 1, floor, 1) not in memo  # one for both orders
    assert not any(back in k for k in memo)  # they share an edge: each order computed on its own
    (fc, _, a_f), (cf, direct, a_c) = pairs[floor, ceiling], pairs[ceiling, floor]
    assert fc[0] * a_f == pytest.approx(cf[0] * a_c, rel=1e-15)
    assert abs(cf[0] - direct[0]) <= cf[1] + direct[1]
    for i, j in ((floor, back), (back, floor)):
        assert pairs[i, j][0] == pairs[i, j][1]
    # the same digits whichever order a process asks first (determinism of the matrix,
    # whose rows are shared among workers in no fixed order): floor and light differ in area
    light = int(scene.group_faces("light")[0])
    answers = []
    for order in (((floor, light), (light, floor)), ((light, floor), (floor, light))):
        fresh = load_scene(SAMPLES / "cornell_box.obj")
        got = {}
        for i, j in order:
            st = ff.PairSetup(fresh, i, 1, ff.face_target(fresh, j), 1, occluders=False)
            assert ff._unclipped(st)
            got[i, j] = ff.pair_contour(fresh, st, (i, 1, j, 1))
        answers.append(got)
    assert answers[0] == answers[1]


def test_three_levels_share_the_middle_childs_centroid(rng):
    """:meth:`ThreeLevelRowCubature.levels` evaluates a middle child's centroid once, as its
    parent's (142 points a triangle, not 147): its three levels equal those of every node
    evaluated (:func:`ff.row_rules` on each level) to rounding, and no point is asked twice."""
    asked = []

    def integrand(points, tri):
        asked.append(points.copy())
        x, y, z = points.T
        return np.stack([np.exp(x) * np.cos(2 * y) + z ** 3, 1.0 + 0 * x], axis=1)

    tri = rng.uniform(-1, 1, (5, 3, 3))
    cub = ff.ThreeLevelRowCubature(integrand)
    q, K, kq, G, gq = cub.levels(tri, 2)
    assert cub.evaluations == 142 * len(tri)
    pts = np.concatenate(asked)
    assert len(np.unique(np.round(pts, 12), axis=0)) == len(pts)
    plain = ff.ThreeLevelRowCubature(integrand)
    for level, got in ((tri, q), (K, kq), (G, gq)):
        want = plain.rule(level, 2)
        assert np.abs(got - want).max() <= 1e-15 * np.abs(want).max()
    assert plain.evaluations == 147 * len(tri)
