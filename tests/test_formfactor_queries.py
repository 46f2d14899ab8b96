"""Form-factor queries (viscx formfactor): the from-point hidden-surface kernel against the
V-cells and Lambert, closed forms, Monte Carlo with embree rays, reciprocity and row sums."""

import json
import subprocess
import sys

import msgpack
import numpy as np
import pytest
from conftest import ROOT, SAMPLES, soup, viscx_in_process
from oracles import form_factor_monte_carlo
from test_formfactor import corner_rectangle, parallel_rectangles, perpendicular_rectangles

from viscx.geometry.formfactor import clip_to_hemisphere, point_to_polygon, polygon_to_polygon
from viscx.queries import formfactor as ff
from viscx.queries.visibility import point_view
from viscx.scene import build_scene, load_scene
from viscx.skeleton.points import point_vcells

GOLDEN_CORNELL = ROOT / "tests" / "golden" / "cornell_box.h5"


@pytest.fixture(scope="module")
def cornell():
    return load_scene(SAMPLES / "cornell_box.obj")


def square(z, size=1.0, flip=False):
    q = [[0, 0, z], [size, 0, z], [size, size, z], [0, size, z]]
    return q[::-1] if flip else q


def scene_of(polygons):
    verts, faces = [], []
    for poly in polygons:
        faces.append(list(range(len(verts), len(verts) + len(poly))))
        verts.extend(poly)
    return build_scene(soup(verts, faces, groups=np.arange(len(faces)), names=[f"p{k}" for k in range(len(faces))]))


def monte_carlo(scene, i, side_i, j, side_j=None, k=1_000_000, seed=0):
    """F from a side of face i to face j (a side of it, or both) by k cosine-weighted rays
    from area-uniform points of i (embree first hits, tests/oracles.py): estimate and its σ."""
    F, _ = form_factor_monte_carlo(scene, [i], side_i, k, seed=seed)
    est = F[2 * j] + F[2 * j + 1] if side_j is None else F[2 * j + (side_j < 0)]
    return est, np.sqrt(est * (1 - est) / k)


# --------------------------------------------------------------------------------------
# the integrand: visible part of J from a point, by clipping


# (two of the five pairs under slow: ~2.5 s of make test)
@pytest.mark.parametrize("pair", [(15, 0), (0, 15), (2, 3), *(pytest.param(p, marks=pytest.mark.slow) for p in [(1, 0), (11, 4)])])
def test_clipping_kernel_equals_vcells(cornell, pair, rng):
    """F(x → visible part of J) by polygon clipping equals Lambert over the V-cells' visible part."""
    i, j = pair
    setup = ff.PairSetup(cornell, i, 1, ff.face_target(cornell, j), 1)
    loop = setup.I[0]
    checked = 0
    for _ in range(12):
        # just off I (a point on a face is refused); both visible parts are clipped at I's
        # plane (the kernel's J'), not at the point's
        x = rng.dirichlet(np.ones(len(loop))) @ loop + 2e-3 * setup.n_i
        try:
            pc = point_vcells(cornell, x, epsilon=1e-5)  # epsilon-visibility at the default 1e-3 mm: ~1e-8
        except Exception:  # inside a block (the floor under it)
            continue
        view = point_view(pc.scene, pc.arcs, pc.vcells, int(pc.point_ids[0]), x)
        loops = [c for c in (clip_to_hemisphere(l, loop[0], setup.n_i) for l in view.faces[j].loops) if len(c) >= 3]
        ref = point_to_polygon([x], [setup.n_i], loops)[0] if loops else 0.0
        # the V-cells' loops end at bisected or snapped transitions (V1), exact to about
        # epsilon over the scene (1e-5 / 550 here): F agrees far below that, not to rounding
        assert abs(setup.f(x[None])[0] - ref) < 1e-9
        checked += 1
    assert checked >= 6


def test_clipping_kernel_unoccluded_is_lambert(rng):
    tri = np.array([[0.2, -0.3, 1.0], [1.5, 0.4, 1.8], [-0.4, 1.2, 1.3]])
    s = scene_of([[[-1, -1, 0], [2, -1, 0], [2, 2, 0], [-1, 2, 0]], tri.tolist()])
    setup = ff.PairSetup(s, 0, 1, ff.face_target(s, 1), -1 if s.face_normal[1][2] > 0 else 1)
    x = np.c_[rng.uniform(-1, 2, (500, 2)), np.zeros(500)]
    got = setup.f(x)
    ref = point_to_polygon(x, np.tile([0, 0, 1.0], (500, 1)), [tri])
    assert np.abs(got - ref).max() < 1e-13


# --------------------------------------------------------------------------------------
# closed forms (unoccluded: contour integral and the quadrature path)


def _forced_cubature(scene, i, side_i, j, side_j, tol):
    """The cubature of the pair's whole (unoccluded) integrand F(x → J') over I': value and
    error estimate, to check against closed forms."""
    setup = ff.PairSetup(scene, i, side_i, ff.face_target(scene, j), side_j)
    tri = setup.triangles()

    def one_each(t, ptr, ids):  # a non-empty list everywhere: nothing is known to be zero
        return np.arange(len(t) + 1, dtype=np.int64), np.zeros(len(t), np.int64)

    cub = ff.Cubature(lambda p, g, ptr, ids: setup.f(p), one_each)
    value, err, _ = cub.integrate(tri, np.zeros(1, np.int64), tol * setup.area_i)
    return value / setup.area_i, err / setup.area_i


def test_parallel_unit_squares():
    s = scene_of([square(0), square(1, flip=True)])
    exact = parallel_rectangles(1.0, 1.0)
    r = ff.pair_form_factor(s, 0, 1, ff.face_target(s, 1), 1)
    assert r.method == "contour" and abs(r.F - exact) < 1e-9
    for tol in (1e-4, 1e-7, 1e-10):  # the estimate is honest and meets the tolerance
        value, err = _forced_cubature(s, 0, 1, 1, 1, tol)
        assert abs(value - exact) <= err < tol


def test_perpendicular_unit_squares():
    s = scene_of([square(0), [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]]])
    exact = perpendicular_rectangles(1.0, 1.0)
    side_wall = 1 if s.face_normal[1][1] > 0 else -1
    r = ff.pair_form_factor(s, 0, 1, ff.face_target(s, 1), side_wall)
    assert r.method == "contour" and abs(r.F - exact) < 1e-9
    for tol in (1e-4, 1e-7):  # a shared edge: the integrand's log singularity there
        value, err = _forced_cubature(s, 0, 1, 1, side_wall, tol)
        assert abs(value - exact) <= err < tol
    back = ff.pair_form_factor(s, 1, side_wall, ff.face_target(s, 0), 1)
    assert abs(back.F - exact) < 1e-9  # reciprocity, equal areas


def test_contour_with_a_partly_shared_edge(cornell):
    """A block's side standing on the floor (its bottom edge inside the floor): contour integral
    against the quadrature of the exact integrand."""
    r = ff.pair_form_factor(cornell, 0, 1, ff.face_target(cornell, 9), 1)
    assert r.method == "contour"
    value, err = _forced_cubature(cornell, 0, 1, 9, 1, 1e-7)
    assert abs(value - r.F) <= err < 1e-7


# --------------------------------------------------------------------------------------
# emitter cells, shafts, and the cubature of what is hidden


def test_emitter_cells_are_cut_at_contacts(cornell):
    """The floor's cells: no contact segment (the blocks' feet) crosses a cell's interior,
    and the cells tile the floor."""
    cells = ff.emitter_cells(cornell, 0, 1)
    seg = ff.contact_segments(cornell, 0, 1)
    assert len(seg) == 11  # the two blocks' feet (8) and the three walls' bottom edges
    assert abs(sum(ff.loops_area([c], cornell.face_normal[0]) for c in cells) - cornell.face_area[0]) < 1e-6
    for a, b in seg:
        t = np.linspace(0.01, 0.99, 50)
        pts = a + t[:, None] * (b - a)
        for c in cells:
            # strictly inside a convex cell: every edge sees the point on its left
            e = np.roll(c, -1, axis=0) - c
            left = np.einsum("pkj,j->pk", np.cross(e[None], pts[:, None] - c[None]), cornell.face_normal[0])
            assert not np.any((left > 1e-6).all(axis=1))


def test_shaft_culling_drops_nothing_that_hides(cornell, rng):
    """Every triangle's culled list hides exactly what all the pair's occluders hide."""
    setup = ff.PairSetup(cornell, 0, 1, ff.face_target(cornell, 15), 1)
    tri = ff.split4(ff.split4(setup.triangles()).reshape(-1, 3, 3)).reshape(-1, 3, 3)
    p = len(setup.occluders)
    ptr, ids = setup.shaft_cull(tri, (np.arange(len(tri) + 1) * p).astype(np.int64), np.tile(np.arange(p), len(tri)))
    assert 0 < len(ids) < p * len(tri)
    w = rng.dirichlet(np.ones(3), (len(tri), 4))
    pts = np.einsum("gsk,gkd->gsd", w, tri).reshape(-1, 3)
    group = np.repeat(np.arange(len(tri)), 4)
    every = (np.arange(len(tri) + 1) * p).astype(np.int64), np.tile(np.arange(p), len(tri))
    assert np.abs(setup.blocked(pts, group, ptr, ids) - setup.blocked(pts, group, *every)).max() < 1e-13


def test_contact_corners_cut_the_outer_integral(cornell):
    """Floor → inside of the short block's top: the integrand is the unoccluded one on the
    block's footprint and 0 elsewhere (a jump along the contact lines, where the floor's
    cells are cut): equal to the contour integral over the footprint, and the estimate is
    honest at every tolerance."""
    top = cornell.face_loops(5)[0]
    foot = top * [1, 0, 1]
    exact = polygon_to_polygon([foot], [0, 1, 0], [top], [0, -1, 0]) * cornell.face_area[5] / cornell.face_area[0]
    for tol in (1e-4, 1e-6, 1e-8):
        r = ff.pair_form_factor(cornell, 0, 1, ff.face_target(cornell, 5), -1, tol=tol)
        assert r.method == "quadrature"
        assert abs(r.F - exact) <= r.error < tol


def test_no_cubic_memory(tmp_path):
    """A floor, a light and 125 boxes between them (625 occluder faces, 2,500 edges): the
    pair's form factor under a 3 GB address-space limit (all triples of edges would be
    2.6e9)."""
    script = tmp_path / "run.py"
    script.write_text(f"""
import resource, sys
sys.path.insert(0, {str(ROOT / 'tests')!r})
resource.setrlimit(resource.RLIMIT_AS, (3_000_000_000, 3_000_000_000))
import numpy as np
from test_formfactor_queries import scene_of
from viscx.queries import formfactor as ff
polys = [[[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]], [[4, 4, 5], [4, 6, 5], [6, 6, 5], [6, 4, 5]]]
for i in range(5):
    for j in range(5):
        for k in range(5):
            x, y, z = 0.5 + 2 * i, 0.5 + 2 * j, 0.5 + 0.8 * k
            polys += [[[x, y, z], [x + 0.5, y, z], [x + 0.5, y + 0.5, z], [x, y + 0.5, z]],
                      [[x, y, z], [x, y, z + 0.3], [x + 0.5, y, z + 0.3], [x + 0.5, y, z]],
                      [[x, y + 0.5, z], [x + 0.5, y + 0.5, z], [x + 0.5, y + 0.5, z + 0.3], [x, y + 0.5, z + 0.3]],
                      [[x, y, z], [x, y + 0.5, z], [x, y + 0.5, z + 0.3], [x, y, z + 0.3]],
                      [[x + 0.5, y, z], [x + 0.5, y, z + 0.3], [x + 0.5, y + 0.5, z + 0.3], [x + 0.5, y + 0.5, z]]]
s = scene_of(polys)
r = ff.pair_form_factor(s, 0, 1, ff.face_target(s, 1), 1 if s.face_normal[1][2] < 0 else -1, tol=1e-4)
print(r.occluders, r.F, r.error)
""")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    occluders, value, error = out.stdout.split()
    assert int(occluders) >= 100 and float(error) < 1e-4 and 0 < float(value) < 0.1


# --------------------------------------------------------------------------------------
# occluded pairs: Monte Carlo and reciprocity


_PAIRS = {}


def occluded_pair(scene, i, si, j, sj):
    """``pair_form_factor`` of the Cornell box at tol 1e-7, computed once per pair for the
    tests below (the light to the floor is judged against Monte Carlo and by reciprocity)."""
    if (i, si, j, sj) not in _PAIRS:
        _PAIRS[i, si, j, sj] = ff.pair_form_factor(scene, i, si, ff.face_target(scene, j), sj, tol=1e-7)
    return _PAIRS[i, si, j, sj]


# (the wall pair under slow, beside test_occluded_against_monte_carlo_slow's: ~4.5 s of make test)
@pytest.mark.parametrize("pair", [(15, 1, 0, 1), pytest.param((2, 1, 3, 1), marks=pytest.mark.slow)])
def test_occluded_against_monte_carlo(cornell, pair):
    i, si, j, sj = pair
    r = occluded_pair(cornell, i, si, j, sj)
    assert r.method == "quadrature" and r.error < 1e-7
    est, sigma = monte_carlo(cornell, i, si, j, sj)
    assert abs(r.F - est) < 4 * sigma


def test_occluded_reciprocity_light_floor(cornell):
    a = cornell.face_area
    up, down = occluded_pair(cornell, 15, 1, 0, 1), occluded_pair(cornell, 0, 1, 15, 1)
    # within the two estimates (in F of the light), measured 1.4e-7 against 2.0e-6
    assert abs(a[15] * up.F - a[0] * down.F) / a[15] <= up.error + down.error * a[0] / a[15] < 1e-5


@pytest.mark.slow
@pytest.mark.parametrize("pair", [(0, 1, 15, 1), (1, 1, 0, 1), (3, 1, 4, 1), (10, 1, 15, 1), (1, 1, 15, -1), (6, -1, 0, 1)])
def test_occluded_against_monte_carlo_slow(cornell, pair):
    i, si, j, sj = pair
    r = occluded_pair(cornell, i, si, j, sj)
    est, sigma = monte_carlo(cornell, i, si, j, sj, seed=7)
    assert abs(r.F - est) < 4 * max(sigma, 1e-6)


# --------------------------------------------------------------------------------------
# the matrix


def test_matrix_small_scene_reciprocity_and_rows():
    """Two unit squares and a small occluder between them: rows + sky = 1, reciprocity,
    within 10 tol (tol 1e-7: rows off by 3.1e-8, reciprocity 3.1e-9; tol 1e-9 took 11x the CPU, 16 s,
    for the same methods and the same margins)."""
    s = scene_of([square(0), square(1, flip=True), [[0.3, 0.3, 0.5], [0.6, 0.35, 0.5], [0.45, 0.7, 0.55]]])
    m = ff.form_factor_matrix(s, tol=1e-7)
    summary = m.summary()
    assert summary["reciprocity_max_error"] < 1e-6
    assert summary["row_sum_max_deviation"] < 1e-6
    assert m.method_counts.get("quadrature", 0) >= 2


@pytest.mark.slow
def test_cornell_matrix(cornell):
    """The acceptance: reciprocity to 1e-6 and every side's row (with its sky term: the open
    front and the outside) sums to 1 within 1e-6."""
    m = ff.form_factor_matrix(cornell, tol=1e-7)
    summary = m.summary()
    assert summary["reciprocity_max_error"] < 1e-6
    assert summary["row_sum_max_deviation"] < 1e-6


@pytest.mark.slow
def test_closed_cornell_rows_sum_to_one(cornell):
    """The Cornell box closed by a front wall at z = 0: rows sum to 1 without the sky for the
    inside faces."""
    polys = [cornell.face_loops(f)[0].tolist() for f in range(cornell.n_faces)]
    polys.append([[556, 0, 0], [556, 548.8, 0], [0, 548.8, 0], [0, 0, 0]])  # facing +z, into the box
    closed = scene_of(polys)
    m = ff.form_factor_matrix(closed, tol=1e-7)
    rows = m.row_sums()
    assert np.abs(rows - 1).max() < 1e-6
    # the front sides of the walls, floor and ceiling see no sky
    inside = [2 * f for f in range(closed.n_faces) if closed.face_area[f] > 2e5]
    assert m.sky[inside].max() < 1e-6


# --------------------------------------------------------------------------------------
# point to face


def test_point_to_face_closed_form(tmp_path):
    """A point below a corner of a parallel 1 × 2 rectangle at height 2 (Howell A-2), through
    the file and its on-demand V-cells."""
    from viscx.pipeline import build_file
    from viscx.queries.visibility import open_query

    obj = tmp_path / "rect.obj"
    obj.write_text("o rect\nv 0 0 2\nv 2 0 2\nv 2 4 2\nv 0 4 2\nf 1 2 3 4\n")
    build_file(obj, tmp_path / "rect.h5", quiet=True)
    q = open_query(tmp_path / "rect.h5")
    r = ff.point_to_faces(q, [0, 0, 0], [0, 0, 3.0], [0])
    assert abs(r["F"] - corner_rectangle(1.0, 2.0)) < 1e-9


def test_point_to_face_occluded_against_monte_carlo(cornell):
    from viscx.queries.visibility import QueryScene

    q = QueryScene(str(GOLDEN_CORNELL), cornell, np.zeros((0, 3)))
    p, n = np.array([300.0, 1.0, 200.0]), np.array([0.0, 1.0, 0.0])
    r = ff.point_to_faces(q, p, n, [15])
    setup = ff.PairSetup(cornell, 0, 1, ff.face_target(cornell, 15), 1)
    assert abs(r["F"] - setup.f(p[None])[0]) < 1e-12
    k = 1_000_000
    rng = np.random.default_rng(3)
    u1, u2 = rng.random(k), rng.random(k)
    d = np.c_[np.sqrt(u1) * np.cos(2 * np.pi * u2), np.sqrt(1 - u1), np.sqrt(u1) * np.sin(2 * np.pi * u2)]
    face, _ = cornell.ray_caster.first_hit(np.tile(p, (k, 1)), d, tmin=cornell.epsilon)
    est = (face == 15).mean()
    sigma = np.sqrt(est * (1 - est) / k)
    assert 0 < r["F"] and abs(r["F"] - est) < 4 * sigma


# --------------------------------------------------------------------------------------
# the command


def _viscx(*args):
    return viscx_in_process(*args)


def test_cli_json_and_msgpack(tmp_path):
    out = _viscx("formfactor", "faces", GOLDEN_CORNELL, "--from-face", 15, "--to-face", 0, "--tol", "1e-5")
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert set(r) >= {"F", "error", "from_face", "to_face", "sides"} and 0.1 < r["F"] < 0.15
    out = _viscx("formfactor", "point", GOLDEN_CORNELL, "--point", "278,1,280", "--normal", "0,1,0", "--to-group", "light",
                 "--format", "msgpack", "-o", tmp_path / "p.msgpack")
    assert out.returncode == 0, out.stderr
    r = msgpack.unpackb((tmp_path / "p.msgpack").read_bytes())
    assert r["to_group"] == "light" and 0 < r["F"] < 0.1


def test_cli_matrix(tmp_path):
    obj = tmp_path / "two.obj"
    obj.write_text("o a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\no b\nv 0 0 1\nv 0 1 1\nv 1 1 1\nv 1 0 1\nf 5 6 7 8\n")
    from viscx.formats.formfactors import read_matrix
    from viscx.pipeline import build_file

    build_file(obj, tmp_path / "two.h5", quiet=True)
    out = _viscx("-q", "formfactor", "matrix", tmp_path / "two.h5", "-o", tmp_path / "F.h5")
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    m = read_matrix(tmp_path / "F.h5")
    assert summary["elements"] == 4 and len(m["data"]) == 2
    assert abs(m["data"][0] - parallel_rectangles(1.0, 1.0)) < 1e-9
    assert summary["reciprocity_max_error"] < 1e-9
    # the sky is integrated (what each point sees of no face), within its estimate (tol 1e-6)
    assert np.abs(m["row_sum"] - 1).max() <= m["sky_error"].max() + 1e-12 <= 1e-6
    # plain exports: the arrays and the group table (front sides, area-weighted; sky last)
    for suffix in ("npz", "csv"):
        out = _viscx("-q", "formfactor", "matrix", tmp_path / "two.h5", "-o", tmp_path / f"F.{suffix}")
        assert out.returncode == 0, out.stderr
    z = np.load(tmp_path / "F.npz")
    assert list(z["groups"]) == ["a", "b"] and np.array_equal(z["data"], m["data"])
    exact = parallel_rectangles(1.0, 1.0)
    assert np.allclose(z["group_F"], [[0, exact, 1 - exact], [exact, 0, 1 - exact]], atol=1e-6)
    assert np.allclose(z["group_F"][:, :2], [[0, exact], [exact, 0]], atol=1e-9)
    lines = (tmp_path / "F.csv").read_text().splitlines()
    assert lines[0] == "from_group,to_group,F" and len(lines) == 5 and lines[1].startswith("a,b,")


@pytest.mark.parametrize("args, message", [
    (["faces", "--from-face", "99", "--to-face", "0"], "out of range"),
    (["faces", "--from-face", "0", "--to-face", "-1"], "out of range"),
    (["point", "--point", "200,50,150", "--normal", "0,1,0", "--to-face", "15"], "inside a solid"),
    (["point", "--point", "200,300,150", "--to-face", "15"], "--normal"),
    (["faces", "--from-face", "0"], "--to-face"),
    (["matrix"], "-o"),
    (["groups", "--from-group", "nope", "--to-group", "light"], "no group"),
])
def test_bad_queries(args, message):
    out = _viscx("formfactor", args[0], GOLDEN_CORNELL, *args[1:])
    assert out.returncode == 2
    assert len(out.stderr.strip().splitlines()) == 1 and message in out.stderr


def test_file_without_v2(tmp_path):
    from viscx.pipeline import build_file

    build_file(SAMPLES / "two_triangles.obj", tmp_path / "v1.h5", quiet=True, levels=1)
    out = _viscx("formfactor", "faces", tmp_path / "v1.h5", "--from-face", "0", "--to-face", "1")
    assert out.returncode == 2 and "no V-cells" in out.stderr and len(out.stderr.strip().splitlines()) == 1


# --------------------------------------------------------------------------------------
# hovering occluders: the Cornell light 0.1 mm under the ceiling


def test_hover_cells_follow_the_light_outline(cornell):
    """The ceiling's cells are cut along the light's outline projected on the ceiling and
    graded towards it (offsets h·8^k, h = 0.1 mm): no projected edge crosses a cell's
    interior, the cells tile the ceiling, and the narrowest cells are no wider than h. Without the cuts the ceiling is its two triangles.
    The light's outline hovers all round and is convex: rings around it (6 rings of 4
    trapezoids and the core, cut by the ceiling's diagonal, and the parts outside them: 45
    cells), not the parallels extended across the whole ceiling (177 cells)."""
    seg = ff.hover_segments(cornell, 1, 1)
    light = cornell.face_loops(15)[0]
    assert len(seg) == 4 * 7  # 4 edges: the edge and 3 offsets on each side (0.1, 0.8, 6.4 mm)
    cells = ff.emitter_cells(cornell, 1, 1)
    n = cornell.face_normal[1]
    assert 25 < len(cells) < 60
    assert abs(sum(ff.loops_area([c], n) for c in cells) - cornell.face_area[1]) < 1e-6
    proj = light * [1, 0, 1] + [0, 548.8, 0]
    t = np.linspace(0.01, 0.99, 50)
    widths = []
    for k in range(4):
        a, b = proj[k], proj[(k + 1) % 4]
        pts = a + t[:, None] * (b - a)
        for c in cells:
            e = np.roll(c, -1, axis=0) - c
            left = np.einsum("pkj,j->pk", np.cross(e[None], pts[:, None] - c[None]), n)
            assert not np.any((left > 1e-6).all(axis=1))
    for c in cells:
        e = np.roll(c, -1, axis=0) - c
        widths.append(2 * ff.loops_area([c], n) / np.linalg.norm(e, axis=1).max())
    # 2 area / longest side: a triangle's width, up to twice a trapezoid's (the rings' cells)
    assert 0.01 < min(widths) <= 2 * 0.1 + 1e-9


def _cells_follow(cells, n, area, outline):
    """The cells tile a face of ``area`` and no edge of ``outline`` (projected) crosses a cell."""
    assert abs(sum(ff.loops_area([c], n) for c in cells) - area) < 1e-9 * area
    t = np.linspace(0.01, 0.99, 40)
    for k in range(len(outline)):
        a, b = outline[k], outline[(k + 1) % len(outline)]
        pts = a + t[:, None] * (b - a)
        for c in cells:
            e = np.roll(c, -1, axis=0) - c
            left = np.einsum("pkj,j->pk", np.cross(e[None], pts[:, None] - c[None]), n)
            assert not np.any((left > 1e-9).all(axis=1))


@pytest.mark.parametrize("light", [
    [[0.3, 0.2, 0.999], [0.5, 0.75, 0.999], [0.7, 0.2, 0.999]],  # convex: rings
    [[0.2, 0.2, 0.999], [0.2, 0.7, 0.999], [0.4, 0.7, 0.999], [0.4, 0.4, 0.999], [0.7, 0.4, 0.999], [0.7, 0.2, 0.999]],  # L: lines
])
def test_hover_rings_and_lines_tile_the_face(light):
    """A light 1 mm under a unit ceiling: a convex one grades the ceiling by rings (graded
    widths h·8^k around it, the narrowest h), a non-convex one by the extended parallels;
    both tile the ceiling with no projected light edge crossing a cell."""
    scene = scene_of([[[0, 0, 1], [0, 1, 1], [1, 1, 1], [1, 0, 1]], light])
    side = 1 if scene.face_normal[0][2] < 0 else -1  # the ceiling's side facing down
    cells = ff.emitter_cells(scene, 0, side)
    n = side * scene.face_normal[0]
    proj = np.asarray(light, float) * [1, 1, 0] + [0, 0, 1]
    _cells_follow(cells, n, scene.face_area[0], proj)
    # 2 area / longest side: the width of a triangle, up to twice that of a trapezoid
    widths = [2 * ff.loops_area([c], n) / np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1).max() for c in cells]
    assert 1e-4 < min(widths) <= 2e-3 + 1e-12
    convex = len(light) == 3
    # rings: 1 core + 6 rings x 3 trapezoids, cut by the ceiling's diagonal, and the parts outside
    assert (len(cells) < 60) == convex, len(cells)


@pytest.mark.parametrize("tol", [1e-5, pytest.param(1e-6, marks=pytest.mark.slow)])
def test_hovering_light_reciprocity_ceiling_floor(cornell, tol):
    """Ceiling → floor (the light hides the ceiling's points above it, a jump over 0.1 mm
    along its outline) against floor → ceiling (the light seen from the floor: smooth), two
    independent integrands of equal areas: equal within the two estimates, at 1e-5 (1e-6
    with -m slow: 12 s of CPU)."""
    down = ff.pair_form_factor(cornell, 1, 1, ff.face_target(cornell, 0), 1, tol=tol)
    up = ff.pair_form_factor(cornell, 0, 1, ff.face_target(cornell, 1), 1, tol=tol)
    assert down.method == up.method == "quadrature"
    assert down.error < tol and up.error < tol
    assert abs(down.F - up.F) <= down.error + up.error


def post_under_a_panel():
    """A 2 × 2 panel at y = 1 facing down, the floor (4 × 4, facing up) and a post on it
    (x in [0.5, 1.5], z in [0.9, 1.1]) whose top slopes down from 2 cm under the panel at
    x = 0.5 to 30 cm under it at x = 1.5: the top's edges along x rise away from the panel
    (a PV panel's post seen in the panel's frame, where the panel is tilted and the post's
    top level)."""
    return [[[0, 1, 0], [2, 1, 0], [2, 1, 2], [0, 1, 2]], [[-1, 0, -1], [-1, 0, 3], [3, 0, 3], [3, 0, -1]],
            [[0.5, 0.98, 0.9], [0.5, 0.98, 1.1], [1.5, 0.7, 1.1], [1.5, 0.7, 0.9]],  # top
            [[0.5, 0, 0.9], [0.5, 0, 1.1], [0.5, 0.98, 1.1], [0.5, 0.98, 0.9]],
            [[1.5, 0, 0.9], [1.5, 0.7, 0.9], [1.5, 0.7, 1.1], [1.5, 0, 1.1]],
            [[0.5, 0, 0.9], [0.5, 0.98, 0.9], [1.5, 0.7, 0.9], [1.5, 0, 0.9]],
            [[0.5, 0, 1.1], [1.5, 0, 1.1], [1.5, 0.7, 1.1], [0.5, 0.98, 1.1]],
            [[0.5, 0, 0.9], [1.5, 0, 0.9], [1.5, 0, 1.1], [0.5, 0, 1.1]]]


def test_an_edge_rising_away_hovers_near_its_low_end_only(monkeypatch):
    """What a rule may miss where an occluder's outline crosses a cubature triangle
    (:meth:`PairSetup.unresolved`) is 2 h × its size, h the outline's height above the
    emitter *where it crosses*: a triangle of size 0.11 across the post top's edge along
    x at x in [1.25, 1.35], where the edge is 0.23–0.26 under the panel (more than half
    the triangle's size: the rule sees its shadow's edge), gets nothing; one at x in
    [0.55, 0.65], where it is 3.4–6.2 cm under the panel, gets 2 × 0.034 × its size. With
    the post's lowest vertex for every edge (as before), both got 2 × 0.02 × size: on a
    PV row's back over 4 posts, along the projections of every edge of the posts, and
    the pair → the ground stopped at MAX_CELLS with an estimate of 6e-3 at tol 1e-3
    (docs/queries.md, "A PV field"). The pair on three levels (its cells uncut) agrees
    with the pair on its kink-cut cells within the two estimates."""
    scene = scene_of(post_under_a_panel())
    assert scene.face_normal[0][1] < -0.99 and scene.face_normal[1][1] > 0.99
    setup = ff.PairSetup(scene, 0, 1, ff.face_target(scene, 1), 1)
    k = len(setup.occluders)
    far = np.array([[1.25, 1.0, 0.85], [1.35, 1.0, 0.85], [1.3, 1.0, 0.95]])
    near = far - [0.7, 0.0, 0.0]
    tri = np.stack([far, near])
    ptr, ids = np.array([0, k, 2 * k], np.int64), np.tile(np.arange(k, dtype=np.int64), 2)
    size = np.hypot(0.05, 0.1)  # the longest side
    assert setup.unresolved(tri, ptr, ids) == pytest.approx([0.0, 2 * 0.034 * size], rel=1e-9)
    # the knock-out: every edge at its occluder's lowest vertex's height
    heights = type(setup)._heights.func(setup)
    above = heights[0]
    monkeypatch.setitem(setup.__dict__, "_heights", heights[:3] + (np.broadcast_to(above[:, None], heights[3].shape),) * 2)
    assert setup.unresolved(tri, ptr, ids) == pytest.approx([2 * 0.02 * size] * 2, rel=1e-9)
    monkeypatch.undo()
    cut = ff.pair_form_factor(scene, 0, 1, ff.face_target(scene, 1), 1, tol=1e-6)
    monkeypatch.setattr(ff, "MAX_KINK_CELLS", 0)  # three levels on the uncut cells
    three = ff.pair_form_factor(scene_of(post_under_a_panel()), 0, 1, ff.face_target(scene, 1), 1, tol=1e-5)
    assert cut.error <= 1e-6 and three.error <= 1e-5
    assert abs(cut.F - three.F) <= cut.error + three.error, (cut, three)


def test_a_short_hovering_edge_grades_its_own_band_only(monkeypatch):
    """The post top's edge at x = 0.5, 2 cm under the panel for z in [0.9, 1.1], hovers
    (its height is under a quarter of its length): the panel's cells are graded towards
    it by strips 2 cm wide either side (:func:`viscx.queries.formfactor.hover_segments`).
    Cut first across the band at its ends (the caps of ``_loop_segments``: z = 0.88 and 1.12), the strips
    stop there; without, they ran on across the panel (to z = 2), fanned into triangles
    40 times longer than wide, and the pair on three levels took 3.5 times the points at
    tol 1e-5 (108,234 against 31,325), for the same F within the estimates."""
    scene = scene_of(post_under_a_panel())
    strips = [c for c in ff.emitter_cells(scene, 0, 1) if abs(c.mean(axis=0)[0] - 0.5) < 0.03]
    assert len(strips) == 2
    assert all(c[:, 2].min() >= 0.88 - 1e-12 and c[:, 2].max() <= 1.12 + 1e-12 for c in strips)
    monkeypatch.setattr(ff, "MAX_KINK_CELLS", 0)  # three levels on the uncut cells
    capped = ff.pair_form_factor(scene, 0, 1, ff.face_target(scene, 1), 1, tol=1e-5)
    loop_segments = ff._loop_segments
    monkeypatch.setattr(ff, "_loop_segments", lambda n, loops: (np.zeros((0, 2, 3)), loop_segments(n, loops)[1]))
    fresh = scene_of(post_under_a_panel())
    strips = [c for c in ff.emitter_cells(fresh, 0, 1) if abs(c.mean(axis=0)[0] - 0.5) < 0.03]
    assert max(c[:, 2].max() for c in strips) == pytest.approx(2.0)
    uncapped = ff.pair_form_factor(fresh, 0, 1, ff.face_target(fresh, 1), 1, tol=1e-5)
    assert capped.error <= 1e-5 and uncapped.error <= 1e-5
    assert abs(capped.F - uncapped.F) <= capped.error + uncapped.error
    assert capped.evaluations < 0.5 * uncapped.evaluations, (capped.evaluations, uncapped.evaluations)


# --------------------------------------------------------------------------------------
# the three-level error estimate


def test_estimate_sees_a_kink_clipping_a_corner(cornell):
    """Light → floor, the triangle at the light's corner (213, 227) where a kink line of the
    integrand (an event of the short block) clips the opposite corner: the rule on the
    triangle and on its 4 children agree to 1e-12 while both are 5e-4 off (what made tol 1e-8
    come out 5e-8 off for an estimate of 9e-9). The estimate of the grandchildren's value
    covers its error against 5 levels of refinement."""
    setup = ff.PairSetup(cornell, 15, 1, ff.face_target(cornell, 0), 1)
    tri = np.array([[[213.0, 548.7, 227.0], [245.5, 548.7, 227.0], [245.5, 548.7, 253.25]]])
    p = len(setup.occluders)

    def every(t):
        return (np.arange(len(t) + 1) * p).astype(np.int64), np.tile(np.arange(p), len(t))

    cub = ff.Cubature(setup.blocked, setup.shaft_cull)
    levels, t = [], tri
    for _ in range(6):
        levels.append(cub.rule(t, *every(t)).sum())
        t = ff.split4(t).reshape(-1, 3, 3)
    q, k, g, fine = levels[0], levels[1], levels[2], levels[5]
    assert abs(q - k) < 1e-8 < 1e-4 < abs(k - fine)  # two levels are blind here
    kids = ff.split4(tri).reshape(-1, 3, 3)
    kq = cub.rule(kids, *every(kids))[None]
    gk = ff.split4(kids).reshape(-1, 3, 3)
    gq = cub.rule(gk, *every(gk))[None]
    est = cub.estimates(tri, *every(tri), np.array([q]), kq, gq)[0]
    assert abs(gq.sum() - g) < 1e-9 and abs(g - fine) <= est


@pytest.mark.slow
@pytest.mark.parametrize("pair", [(15, 1, 0, 1), (2, 1, 3, 1)])
def test_tol_1e8_against_nested_gauss_kronrod(cornell, pair):
    """The accuracy question of tol 1e-8: an independent reference, nested adaptive 1-D
    Gauss–Kronrod (scipy quad, absolute 1e-11) of the exact point kernel over the emitter
    rectangle. Measured: light → floor 0.123645351843, back wall → left wall
    0.159547200512 (the values the first quadrature documented, to 3e-10 and 5e-10)."""
    from scipy.integrate import quad

    i, si, j, sj = pair
    setup = ff.PairSetup(cornell, i, si, ff.face_target(cornell, j), sj)
    o, a, b = setup.I[0][0], setup.I[0][1] - setup.I[0][0], setup.I[0][3] - setup.I[0][0]

    def inner(v):
        return quad(lambda u: float(setup.f((o + u * a + v * b)[None])[0]), 0, 1, epsabs=1e-11, epsrel=0, limit=400)[0]

    ref = quad(inner, 0, 1, epsabs=1e-11, epsrel=0, limit=400)[0]
    r = ff.pair_form_factor(cornell, i, si, ff.face_target(cornell, j), sj, tol=1e-8)
    # on the emitters' cells cut along their kink lines (ff.cubature_cells): light → floor
    # 1.3e-9 off for an estimate of 7.1e-9, back → left 3.5e-10 off for 8.1e-9 (uncut, the
    # three-level estimate was 2x optimistic there: 2.0e-8 off for 9.8e-9)
    assert abs(r.F - ref) <= r.error


def test_pairs_cut_along_kinks_are_honest(cornell):
    """Back wall → left wall at tol 1e-8 on the back wall's cells cut along its kink lines
    (ff.cubature_cells): within its estimate of the nested Gauss–Kronrod value of
    test_tol_1e8_against_nested_gauss_kronrod (0.159547200512, to 5e-10); measured 3.5e-10
    off for an estimate of 8.1e-9 in 46,000 points. Uncut (the three-level ff.Cubature) it
    was 2.0e-8 off for an estimate of 9.8e-9, in 232,000 points."""
    cells, _, kinked = ff.cubature_cells(cornell, 2, 1)
    assert kinked
    r = ff.pair_form_factor(cornell, 2, 1, ff.face_target(cornell, 3), 1, tol=1e-8)
    assert r.method == "quadrature" and r.error <= 1e-8
    assert abs(r.F - 0.159547200512) <= r.error - 5e-10


def test_cut_hidden_replaces_only_the_triangles_whose_pieces_see(cornell):
    """:func:`viscx.queries.formfactor.cut_hidden` on two unit triangles of the plane z = 0
    from whose nodes a receiver is hidden, one crossed by a critical line (y = 0.95) near
    its top corner, the other by none: the crossed one is replaced by its pieces (which
    tile it: the same area, every piece on one side of the line) where a piece's centre
    sees the receiver (``sees``: y > 0.95), and kept where none does; the other is kept
    whatever it sees."""
    n = np.array([0.0, 0.0, 1.0])
    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[2, 0, 0], [3, 0, 0], [2, 0.5, 0]]], np.float64)
    lines = np.array([[[-5, 0.95, 0], [5, 0.95, 0]]], np.float64)
    hidden = np.array([True, True])
    replaced, new = ff.cut_hidden(cornell, n, tri, hidden, lines, lambda p: (p[:, 1] > 0.95).astype(float))
    assert replaced.tolist() == [True, False]
    assert abs(ff.triangle_areas(new).sum() - 0.5) < 1e-12
    centre_y = new[:, :, 1].mean(axis=1)
    assert np.all((new[:, :, 1] >= 0.95 - 1e-12).all(axis=1) | (new[:, :, 1] <= 0.95 + 1e-12).all(axis=1))
    assert np.any(centre_y > 0.95) and np.any(centre_y < 0.95)
    replaced, new = ff.cut_hidden(cornell, n, tri, hidden, lines, lambda p: np.zeros(len(p)))
    assert not replaced.any() and not len(new)
    replaced, _ = ff.cut_hidden(cornell, n, tri, np.array([False, True]), lines, lambda p: np.ones(len(p)))
    assert not replaced.any()  # the line crosses only the triangle not asked about
    assert not ff.cut_hidden(cornell, n, tri, hidden, None, lambda p: np.ones(len(p)))[0].any()


@pytest.fixture(scope="module")
def two_shelves():
    """Two shelving units of one bay and two boards each, with back panels
    (benchmarks/buildings.py ``shelving``): the boards' ends lie on the uprights, unit 0's
    back panel on the south wall."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from buildings import shelving

    return build_scene(shelving(units=2, bays=1, levels=2, n_lights=1))


def _face_where(scene, group, normal, test):
    faces = [int(f) for f in scene.group_faces(group)
             if np.allclose(scene.face_normal[f], normal) and test(np.concatenate(scene.face_loops(f)))]
    assert len(faces) == 1, faces
    return faces[0]


def test_a_pair_hidden_whole_by_one_face_is_not_integrated(two_shelves):
    """Unit 1's upper board's underside sees nothing of unit 0's back panel (the side facing
    unit 0's boards): unit 1's own back panel lies between, and its far face (z = 1.80)
    holds every crossing of a segment between the two (:meth:`PairSetup.hidden_whole`).
    The pair is then F = 0 exactly, with no point evaluated; before, a cubature of
    F(x → J') − F(x → visible J') gave rounding (~1e-11) ± ~1e-6 from 4,000 points, and
    the shelves' 502 pairs between two units spent 60 % of their time on 400 such. The
    test needs the whole face: clipped to the board's plane (the pair's occluder), the
    panel's top edge runs through the crossings of the segments grazing that plane.
    Oracle: embree rays from random points of the board to random points of the panel,
    every one blocked before it; and a pair that does see (the board's underside → the
    board below it) is not taken as hidden."""
    scene = two_shelves
    board = _face_where(scene, "shelf1", [0, -1, 0], lambda p: 1.0 < p[:, 1].min() < 1.5)  # y = 1.05
    below = _face_where(scene, "shelf1", [0, 1, 0], lambda p: p[:, 1].max() < 0.2)  # the lower board's top
    def back(p):  # a back panel's face: the unit's width and height
        return np.ptp(p[:, 0]) > 1.0 and np.ptp(p[:, 1]) > 1.9

    panel = _face_where(scene, "shelf0", [0, 0, 1], back)
    far = _face_where(scene, "shelf1", [0, 0, -1], back)
    setup = ff.PairSetup(scene, board, 1, ff.face_target(scene, panel), 1)
    assert setup.hidden_whole()
    clipped = [loops for loops, _, f in setup.occluders if f == far]
    assert len(clipped) == 1 and np.concatenate(clipped[0])[:, 1].max() < 1.9  # clipped at the board's plane
    r = ff.pair_form_factor(scene, board, 1, ff.face_target(scene, panel), 1, tol=1e-6)
    assert (r.F, r.error, r.evaluations, r.method) == (0.0, 0.0, 0, "none")
    rng = np.random.default_rng(3)

    def points(face, k):
        tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
        return np.einsum("pk,pkd->pd", rng.dirichlet(np.ones(3), k), tri[rng.integers(0, len(tri), k)])

    p, q = points(board, 20_000), points(panel, 20_000)
    d = q - p
    hit, t = scene.ray_caster.first_hit(p, d, tmin=1e-6)
    assert np.all((hit >= 0) & (hit != panel) & (t < 1 - 1e-6))
    seen = ff.PairSetup(scene, board, 1, ff.face_target(scene, below), 1)
    assert not seen.hidden_whole()
    r = ff.pair_form_factor(scene, board, 1, ff.face_target(scene, below), 1, tol=1e-6)
    est, sigma = monte_carlo(scene, board, 1, below, k=400_000)
    assert r.F > 0.1 and abs(r.F - est) < 4 * sigma + r.error
