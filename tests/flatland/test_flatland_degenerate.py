"""Degenerate layouts built exactly, without perturbation: uniform rows of tilted panels
(every tip on one line), lattices of square columns (rows, columns and lattice lines of
every rational slope touching many corners and edges), aligned walls.  Form factors
against an independent exact integration (edge-pair visibility + analytic inner
integrals, ``flatland_oracles.exact_F_polygons``) to 1e-9."""

import numpy as np
import pytest
from flatland_oracles import exact_F_part, exact_F_polygons, monte_carlo_F
from flatland_scenes import corners_of, panel_rows, square_grid

from viscx.flatland.complex import build
from viscx.flatland.scene import make_scene


def check_exact(scene, cx, rows, window=None, cols=None, tol=1e-9):
    """F_ij of the given rows i against the oracle, for j in ``cols`` (default: all), or
    within ``window`` objects of i (the farther ones must then be exactly 0 in the
    complex: hidden by the rows between).  The last object (the ground) is always
    compared."""
    objs = corners_of(scene)
    g = scene.n - 1
    worst = 0.0
    for i in rows:
        for j in (range(scene.n) if cols is None else cols):
            if j == i:
                continue
            if window is not None and abs(i - j) > window and g not in (i, j):
                assert cx.F_area[i, j] == 0.0
                continue
            worst = max(worst, abs(exact_F_polygons(objs, i, j) - cx.F_area[i, j]))
    assert worst < tol, worst
    return worst


def check_sums(cx):
    assert np.max(np.abs(cx.F_area - cx.F_strings)) < 1e-9
    assert np.max(np.abs(cx.F_area.sum(axis=1) - 1.0)) < 1e-9
    Lp = cx.scene.perimeters()
    LF = Lp[:, None] * cx.F_area[:, :-1]
    assert np.max(np.abs(LF - LF.T)) < 1e-9


# (n = 10 under slow, beside test_uniform_rows_large_exact's 100 and 1000: ~5 s of make test)
@pytest.mark.parametrize("n, rows", [(3, None), pytest.param(10, [0, 5, 10], marks=pytest.mark.slow)])
def test_uniform_rows_exact(n, rows):
    scene = panel_rows(n)
    cx = build(scene)
    check_sums(cx)
    check_exact(scene, cx, range(scene.n) if rows is None else rows)
    # the tip line really is shared: one vertex per pair of consecutive tips survives
    assert np.sum(cx.v_tau != 0) >= 2 * (n - 1)


@pytest.mark.slow
@pytest.mark.parametrize("n", [100, 1000])
def test_uniform_rows_large_exact(n):
    """Rows at both ends and in the middle against every row within 4 (farther rows are
    hidden: F = 0 exactly — a line joining them inside the band of the panels crosses the
    tilted panels between); at 100 rows also the ground against those rows, its top edge
    integrated piece by piece (one pitch each, so each piece's occluders stay few)."""
    scene = panel_rows(n)
    cx = build(scene)
    check_sums(cx)
    sample = [0, 1, n // 2, n - 2, n - 1]
    check_exact(scene, cx, sample, window=4, cols=range(n))
    if n > 100:
        return
    objs = corners_of(scene)
    g = scene.n - 1
    G = objs[g]
    xs = np.concatenate([[G[3, 0]], np.arange(0.0, n * 3.0, 3.0), [G[2, 0]]])[::-1]  # top edge runs right → left
    for i in sample:
        # F_gi L_g = Σ over the pieces of the top edge (the other edges face away from the panels)
        got = sum(exact_F_part(objs, g, i, np.array([x0, 0.0]), np.array([x1, 0.0])) * (x0 - x1)
                  for x0, x1 in zip(xs[:-1], xs[1:]))
        L = scene.perimeters()[g]
        assert abs(got / L - cx.F_area[g, i]) < 1e-9


def test_rows_monte_carlo():
    """An oracle of another kind (10⁶ random lines) on a small array, within 4σ."""
    scene = panel_rows(4, pitch=2.5, tilt=35.0)
    cx = build(scene)
    F, sigma = monte_carlo_F(scene, n_lines=1_000_000, seed=11)
    z = np.abs(cx.F_area - F) / np.maximum(sigma, 1e-12)
    assert np.all(z < 4.0), z


def test_square_grid_6x6_exact():
    scene = square_grid(6, pitch=2.0, side=1.0)
    cx = build(scene)
    check_sums(cx)
    check_exact(scene, cx, [14])


@pytest.mark.slow
def test_square_grid_20x20_exact():
    for pitch in (3.0, 2.0):
        scene = square_grid(20, pitch=pitch, side=1.0)
        cx = build(scene)
        check_sums(cx)
    objs = corners_of(scene)
    k = 10 * 20 + 10
    near = [j for j in range(scene.n) if j != k and np.hypot(*(objs[j][0] - objs[k][0])) < 9]
    worst = max(abs(exact_F_polygons(objs, k, j) - cx.F_area[k, j]) for j in near)
    assert worst < 1e-9


def test_aligned_walls_exact():
    """Collinear edges of three and four objects (a row of aligned rectangles, and a
    2 × 2 block of walls): no --perturb needed any more."""
    rects = [{"type": "polygon", "points": [[3.0 * i, 0], [3.0 * i + 2, 0], [3.0 * i + 2, 1], [3.0 * i, 1]]}
             for i in range(3)]
    rects.append({"type": "polygon", "points": [[0, 2.5], [2, 2.5], [2, 3.5], [0, 3.5]]})
    scene = make_scene(rects)
    cx = build(scene)
    check_sums(cx)
    check_exact(scene, cx, range(scene.n))
