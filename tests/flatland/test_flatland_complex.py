"""The 2-D visibility complex and its form factors against independent oracles."""

import math

import numpy as np
import pytest
from flatland_oracles import (chords, crossed_strings_circles, crossed_strings_polygons, monte_carlo_F,
                              objects_of)
from flatland_scenes import occluded_scene, random_circles, random_mixed, random_polygon

from viscx.flatland.complex import build
from viscx.flatland.scene import make_scene


def circle(c, r, **kw):
    return {"type": "circle", "center": list(c), "radius": r, **kw}


@pytest.mark.parametrize("seed", range(6))
def test_unoccluded_circles_match_crossed_strings(seed):
    rng = np.random.default_rng(seed)
    r1, r2 = rng.uniform(0.2, 2.0, 2)
    D = r1 + r2 + rng.uniform(0.01, 5.0)
    a = rng.uniform(0, 2 * np.pi)
    c1 = rng.uniform(-3, 3, 2)
    c2 = c1 + D * np.array([np.cos(a), np.sin(a)])
    cx = build(make_scene([circle(c1, r1), circle(c2, r2)]))
    want12 = crossed_strings_circles(c1, r1, c2, r2)
    want21 = crossed_strings_circles(c2, r2, c1, r1)
    for F in (cx.F_area, cx.F_strings):
        assert abs(F[0, 1] - want12) < 1e-9
        assert abs(F[1, 0] - want21) < 1e-9
    # a pair of circles has its four bitangents free
    assert cx.n_vertices == 4


@pytest.mark.parametrize("seed", range(6))
def test_unoccluded_polygons_match_crossed_strings(seed):
    rng = np.random.default_rng(100 + seed)
    P = random_polygon(rng, (0.0, 0.0), 1.0)
    Q = random_polygon(rng, (rng.uniform(2.2, 5), rng.uniform(-2, 2)), 1.0)
    cx = build(make_scene([{"type": "polygon", "points": P.tolist()}, {"type": "polygon", "points": Q.tolist()}]))
    Ps, Qs = cx.scene.verts[:cx.scene.vert_start[1]], cx.scene.verts[cx.scene.vert_start[1]:]
    want = crossed_strings_polygons(Ps, Qs)
    back = crossed_strings_polygons(Qs, Ps)
    assert abs(cx.F_area[0, 1] - want) < 1e-9 and abs(cx.F_strings[0, 1] - want) < 1e-9
    assert abs(cx.F_area[1, 0] - back) < 1e-9 and abs(cx.F_strings[1, 0] - back) < 1e-9


def test_occluded_monte_carlo_million_lines():
    """≥ 10⁶ random lines: every form factor of an occluded mixed scene within 4σ."""
    scene = occluded_scene()
    cx = build(scene)
    assert np.max(np.abs(cx.F_area - cx.F_strings)) < 1e-9
    F, sigma = monte_carlo_F(scene, n_lines=1_000_000, seed=7)
    z = np.abs(cx.F_area - F) / np.maximum(sigma, 1e-12)
    assert np.all(z < 4.0), z
    # the scene really is occluded: some pair sees less than crossed strings would give
    c0, c1 = scene.verts[0], scene.verts[scene.vert_start[1]]
    assert cx.F_area[0, 1] < crossed_strings_circles(c0, 1.0, c1, 1.2) - 0.01


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(8))
def test_random_scenes_monte_carlo_slow(seed):
    scene = random_mixed(8, seed=seed, density=3.0)
    cx = build(scene)
    F, sigma = monte_carlo_F(scene, n_lines=2_000_000, seed=seed)
    z = np.abs(cx.F_area - F) / np.maximum(sigma, 1e-12)
    assert np.all(z < 4.5), z


@pytest.mark.parametrize("seed", range(4))
def test_methods_agree_rows_sum_reciprocity(seed):
    scene = random_mixed(25, seed=seed, density=3.0)
    cx = build(scene)
    assert np.max(np.abs(cx.F_area - cx.F_strings)) < 1e-9
    assert np.max(np.abs(cx.F_area.sum(axis=1) - 1.0)) < 1e-9
    assert np.all(cx.F_area >= -1e-12)
    # reciprocity from the two orientations of every face, computed from different edges
    b = cx.f_bounded
    assert np.max(np.abs(cx.f_area[b] - cx.f_area_twin[b])) < 1e-9
    Lp = scene.perimeters()
    LF = Lp[:, None] * cx.F_area[:, :-1]
    assert np.max(np.abs(LF - LF.T)) < 1e-9


def _brute_vertices(scene, eps=1e-9):
    """All free bitangents of a circle scene by brute force: the four common tangents of
    each pair from the homothety construction, freeness by distance of every other centre
    to the segment.  Returns sorted (i, j, θ mod π) rows."""
    objs = objects_of(scene)
    rows = []
    n = len(objs)
    for i in range(n):
        for j in range(i + 1, n):
            c1, r1 = objs[i][1][0], objs[i][2]
            c2, r2 = objs[j][1][0], objs[j][2]
            for s in (+1, -1):  # outer (s=+1) and inner (s=-1): line nn·x = nn·c1 − r1, nn·w = s r2 − r1
                w = c2 - c1
                D = np.hypot(*w)
                # unit normals nn with nn·w = r1 − s r2
                a = math.atan2(w[1], w[0])
                x = math.acos((s * r2 - r1) / D)
                for sgn in (+1, -1):
                    nn = np.array([math.cos(a + sgn * x), math.sin(a + sgn * x)])
                    p = c1 - r1 * nn  # tangent points on the line {x: nn·x = nn·c1 − r1}
                    q = c2 - s * r2 * nn
                    seg = q - p
                    Ls = np.hypot(*seg)
                    d = seg / Ls
                    free = True
                    for k in range(n):
                        if k in (i, j):
                            continue
                        ck, rk = objs[k][1][0], objs[k][2]
                        t = np.clip((ck - p) @ d, 0, Ls)
                        if np.hypot(*(p + t * d - ck)) < rk - eps:
                            free = False
                            break
                    if free:
                        th = math.atan2(d[1], d[0]) % math.pi
                        rows.append((i, j, th))
    return sorted(rows)


@pytest.mark.parametrize("seed", range(5))
def test_vertices_equal_brute_force(seed):
    scene = random_circles(20, seed=seed, density=3.0)
    cx = build(scene)
    got = sorted((int(min(a, b)), int(max(a, b)), float(t)) for (a, b), t in zip(cx.v_obj, cx.v_theta))
    want = _brute_vertices(scene)
    assert len(got) == len(want)
    for g, w in zip(got, want):
        assert g[:2] == w[:2]
        dt = abs(g[2] - w[2])
        assert min(dt, math.pi - dt) < 1e-9


def _ray_blockers(objs, p, d, skip):
    """First object behind p and beyond p along d (−1 sky), by brute-force chords."""
    o = p[None, :]
    dd = d[None, :]
    tail, head, bt, bh = -1, -1, -np.inf, np.inf
    for k, ob in enumerate(objs):
        if k == skip:
            continue
        tin, tout = chords(ob, o, dd)
        if not np.isfinite(tin[0]):
            continue
        if tin[0] > 0 and tin[0] < bh:
            head, bh = k, tin[0]
        if tout[0] < 0 and tout[0] > bt:
            tail, bt = k, tout[0]
    return tail, head


@pytest.mark.parametrize("seed", range(3))
def test_incidences_and_edge_labels(seed):
    scene = random_mixed(15, seed=seed, density=3.0)
    cx = build(scene)
    objs = objects_of(scene)
    m, E = cx.n_vertices, cx.n_edges
    # a vertex: four distinct edges, six distinct faces
    assert np.all([len(set(r)) == 4 for r in cx.v_edges])
    # six faces (t,k1), (k1,k2), (t,k2), (k1,h), (t,h), (k2,h); when both ends are the sky
    # the unoriented (sky,k) faces seen before and after k can be one face (the quotient
    # of the oriented double cover identifies them), so distinctness is checked when t ≠ h
    lab = lambda f: tuple(sorted(cx.f_pair[f]))  # noqa: E731
    for v in range(m):
        (k1, k2), t, h = cx.v_obj[v], cx.v_tail[v], cx.v_head[v]
        want = [(t, k1), (k1, k2), (t, k2), (k1, h), (t, h), (k2, h)]
        assert [lab(f) for f in cx.v_faces[v]] == [tuple(sorted(w)) for w in want]
        if t != h:
            assert len(set(cx.v_faces[v])) == 6
    # every edge is bounded by two vertices and lies on three distinct faces
    assert np.all(cx.e_verts >= 0)
    assert all(len(set(r)) == 3 for r, t, h in zip(cx.e_faces, cx.e_tail, cx.e_head) if t != h)
    # each vertex appears as an end of exactly 4 edge-ends in the oriented cover (2 stored)
    cnt = np.bincount(cx.e_verts.ravel(), minlength=m)
    assert np.all(cnt == 4)
    # face labels match the edges' slots (unordered: a face is stored in one orientation)
    for e in range(E):
        k, t, h = cx.e_obj[e], cx.e_tail[e], cx.e_head[e]
        assert lab(cx.e_faces[e, 0]) == tuple(sorted((t, k)))
        assert lab(cx.e_faces[e, 1]) == tuple(sorted((k, h)))
        assert lab(cx.e_faces[e, 2]) == tuple(sorted((t, h)))
    # edge tail/head against a brute-force ray cast of the tangent line at mid-arc
    for e in range(0, E, 3):
        th = 0.5 * (cx.e_theta[e, 0] + cx.e_theta[e, 1])
        k, side = cx.e_obj[e], cx.e_side[e]
        d = np.array([math.cos(th), math.sin(th)])
        nrm = np.array([-d[1], d[0]])
        kind, v, r = objs[k]
        sig = 1.0 if side == 1 else -1.0
        j = np.argmax(sig * (v @ nrm)) if kind == 1 else 0
        p = v[j] + sig * r * nrm
        assert _ray_blockers(objs, p, d, k) == (cx.e_tail[e], cx.e_head[e])
    # each face is bounded by an upper and a lower chain (all of them here are disks,
    # except the unbounded sky-sky face: lines missing everything, the two oriented
    # annuli u → ±∞ being twins)
    assert np.sum(~cx.f_bounded) == 1
    assert np.all(np.diff(cx.f_edge_start) >= 2)


def test_single_object_and_sky():
    cx = build(make_scene([circle((1, 2), 0.5)]))
    # one stored edge: the two oriented loops around the lone object are twins
    assert cx.n_vertices == 0 and cx.n_edges == 1
    assert abs(cx.F_area[0, 1] - 1.0) < 1e-12 and abs(cx.F_strings[0, 1] - 1.0) < 1e-12


def test_aligned_rectangles_monte_carlo():
    """Aligned walls and a circle: common tangents containing whole polygon edges
    (collinear edges of different objects) built as they are; both methods agree and
    match 10⁶ random lines."""
    rects = []
    for i in range(2):
        for j in range(2):
            x, y = 3.0 * i, 2.5 * j
            rects.append({"type": "polygon", "points": [[x, y], [x + 2, y], [x + 2, y + 1], [x, y + 1]]})
    rects.append(circle((3.5, 1.75), 0.3))
    scene = make_scene(rects)
    cx = build(scene)
    assert np.max(np.abs(cx.F_area - cx.F_strings)) < 1e-9
    assert np.max(np.abs(cx.F_area.sum(axis=1) - 1)) < 1e-9
    F, sigma = monte_carlo_F(scene, n_lines=1_000_000, seed=5)
    z = np.abs(cx.F_area - F) / np.maximum(sigma, 1e-12)
    assert np.all(z < 4.0), z


def test_faces_are_bounded_by_two_chains():
    """Every bounded face has an upper and a lower chain spanning the same θ-interval."""
    cx = build(random_mixed(12, seed=9, density=3.0))
    span = cx.e_theta[:, 1] - cx.e_theta[:, 0]
    for f in np.nonzero(cx.f_bounded)[0]:
        sl = slice(cx.f_edge_start[f], cx.f_edge_start[f + 1])
        up = cx.f_edge_upper[sl]
        e = cx.f_edge[sl]
        assert up.any() and (~up).any()
        assert abs(span[e[up]].sum() - span[e[~up]].sum()) < 1e-9
        # its corners: exactly two extremal vertices unless it wraps all directions
        signs = cx.f_vert_sign[cx.f_vert_start[f]:cx.f_vert_start[f + 1]]
        if span[e[up]].sum() < 2 * np.pi - 1e-9:
            assert np.sum(signs == 1) == 2
