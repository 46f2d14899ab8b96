"""The ray caster against a brute-force float64 reference (tests/oracles.py)."""

import numpy as np
import pytest
from conftest import sample_scene_paths
from oracles import first_face_reference, sample_on_triangles, segment_hits_reference

from viscx.scene import load_scene

SLACK = 1e-6  # relative triangle growth that marks a segment as decided by a hair


def random_segments(scene, n, rng):
    """Three kinds: box to box, surface to surface, and surface along a direction."""
    lo, hi = scene.bbox
    k = n // 3
    box = lo + (hi - lo) * rng.random((2, k, 3))
    s1, t1 = sample_on_triangles(scene.vertices, scene.triangles, k, rng)
    s2, _ = sample_on_triangles(scene.vertices, scene.triangles, k, rng)
    # a segment lying in its start face's plane is degenerate by construction: resample it
    normal = scene.face_normal[scene.triangle_face[t1]]
    coplanar = np.abs(np.einsum("ij,ij->i", normal, s2 - s1)) < 1e-6 * scene.diagonal
    s2[coplanar] = lo + (hi - lo) * rng.random((coplanar.sum(), 3))
    d = rng.normal(size=(k, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    s3 = s1 + d * rng.random((k, 1)) * scene.diagonal
    starts = np.concatenate([box[0], s1, s1])
    ends = np.concatenate([box[1], s2, s3])
    return starts, ends


def reference_free(scene, starts, ends, trim, slack):
    u = ends - starts
    length = np.linalg.norm(u, axis=1, keepdims=True)
    u = u / length
    a, b = starts + trim * u, ends - trim * u
    hit, _ = segment_hits_reference(a, b, scene.vertices, scene.triangles, bary_slack=slack)
    return ~hit.any(axis=1) | (length[:, 0] <= 2 * trim)


@pytest.mark.parametrize("path", sample_scene_paths(), ids=lambda p: p.name)
def test_free_segments_match_float64_reference(path, rng):
    scene = load_scene(path)
    starts, ends = random_segments(scene, 6000, rng)
    got = scene.ray_caster.free_segments(starts, ends)
    eps = scene.epsilon
    grown = reference_free(scene, starts, ends, eps, SLACK)
    shrunk = reference_free(scene, starts, ends, eps, -SLACK)
    clear = grown == shrunk  # not decided by a hair
    assert clear.mean() > 0.95, "the comparison would be vacuous"
    expected = reference_free(scene, starts, ends, eps, 0.0)
    bad = np.flatnonzero(clear & (got != expected))
    assert len(bad) == 0, f"{len(bad)} decisions differ, e.g. {starts[bad[:3]].tolist()} -> {ends[bad[:3]].tolist()}"
    n_free = int(expected[clear].sum())
    assert n_free >= 5 and clear.sum() - n_free >= 5, "both answers occur"


@pytest.mark.parametrize("path", sample_scene_paths(), ids=lambda p: p.name)
def test_first_hit_matches_reference(path, rng):
    scene = load_scene(path)
    origins, _ = sample_on_triangles(scene.vertices, scene.triangles, 3000, rng)
    d = rng.normal(size=(3000, 3))
    tmax = np.full(3000, 2 * scene.diagonal)
    tmin = 10 * scene.epsilon
    face, t = scene.ray_caster.first_hit(origins, d, tmin=tmin, tmax=tmax)
    dn = d / np.linalg.norm(d, axis=1, keepdims=True)
    ref_face, ref_t, tied = first_face_reference(
        origins + tmin * dn, dn, tmax - tmin, scene.vertices, scene.triangles, scene.triangle_face
    )
    ref_t = ref_t + tmin
    # rays that graze an edge are excluded: grown and shrunk triangles must agree
    a = origins + tmin * dn
    grown, _ = segment_hits_reference(a, a + dn * (tmax - tmin)[:, None], scene.vertices, scene.triangles, SLACK)
    shrunk, _ = segment_hits_reference(a, a + dn * (tmax - tmin)[:, None], scene.vertices, scene.triangles, -SLACK)
    clear = (grown == shrunk).all(axis=1)
    assert clear.mean() > 0.95
    assert np.array_equal(face[clear] >= 0, ref_face[clear] >= 0)
    hit = clear & (ref_face >= 0)
    assert np.all(tied[np.flatnonzero(hit), face[hit]]), "the face found is a first face"
    assert np.allclose(t[hit], ref_t[hit], rtol=1e-9, atol=1e-9 * scene.diagonal)


def test_segments_ending_on_a_surface_are_decided_in_float64(rng):
    """Ends on a blocker: trimmed by epsilon (free) vs pushed 2 epsilon past it (blocked)."""
    scene = load_scene(sample_scene_paths()[0].parent / "cornell_box.obj")
    caster = scene.ray_caster
    origins, _ = sample_on_triangles(scene.vertices, scene.triangles, 4000, rng)
    d = rng.normal(size=(4000, 3))
    seg = caster.maximal_segments(origins, d)
    p, q, face = origins, seg["front_point"], seg["front_face"]
    on_face = face >= 0
    p, q = p[on_face], q[on_face]
    u = (q - p) / np.linalg.norm(q - p, axis=1, keepdims=True)
    eps = scene.epsilon
    assert caster.free_segments(p, q).all(), "a segment to its own blocker is free"
    checks = caster.stats["float64_checks"]
    assert not caster.free_segments(p, q + 3 * eps * u).any(), "pushed 2 eps past the blocker it is not"
    assert caster.stats["float64_checks"] > checks, "those were float64 decisions"


@pytest.mark.parametrize("path", sample_scene_paths(), ids=lambda p: p.name)
def test_maximal_segments_end_on_their_blockers(path, rng):
    scene = load_scene(path)
    caster = scene.ray_caster
    points = scene.bbox[0] + (scene.bbox[1] - scene.bbox[0]) * rng.random((2000, 3))
    d = rng.normal(size=(2000, 3))
    seg = caster.maximal_segments(points, d)
    for side in ("front", "back"):
        face, end = seg[f"{side}_face"], seg[f"{side}_point"]
        on = face >= 0
        height = np.einsum("ij,ij->i", scene.face_normal[face[on]], end[on]) - scene.face_offset[face[on]]
        assert np.all(np.abs(height) <= 1e-9 * scene.diagonal + scene.weld_tolerance)
        sky = ~on
        lo, hi = caster.sky_box
        on_box = np.isclose(end[sky], lo, atol=1e-9 * scene.diagonal) | np.isclose(end[sky], hi, atol=1e-9 * scene.diagonal)
        assert np.all(on_box.any(axis=1)), "sky ends lie on the enlarged box"
    # the whole segment is free (beyond epsilon from its ends)
    free = reference_free(scene, seg["back_point"], seg["front_point"], 2 * scene.epsilon, -SLACK)
    assert free.all()


# -- hard configurations (each once broke an earlier design) ----------------------------

def tilted_frame():
    n = np.array([0.3, 0.5, 0.8])
    n /= np.linalg.norm(n)
    u = np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return n, u, np.cross(n, u)


def caster(vertices, triangles, epsilon=1e-9):
    from viscx.raycast import RayCaster

    vertices, triangles = np.asarray(vertices, float), np.asarray(triangles)
    return RayCaster(vertices, triangles, np.arange(len(triangles)), epsilon=epsilon)


def test_a_ray_just_outside_a_triangle_finds_the_closer_blocker(rng):
    """Passing a hair outside F's edge, the first hit is the blocker B, not F's neighbour W beyond it."""
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 5, -10], [1, -10, -10], [-1, -2, -2], [3, -2, -2], [0.5, 2, -2]]
    T = [[0, 1, 2], [0, 3, 4], [5, 6, 7]]
    rc = caster(V, T)
    n = 5000
    delta = 10 ** rng.uniform(-12, -7, n)
    o = np.stack([rng.uniform(0.3, 0.7, n), 0.2 - delta, np.ones(n)], 1)
    d = np.tile([0.0, -0.2, -1.0], (n, 1))
    face, t = rc.first_hit(o, d, tmin=0.0, tmax=100.0)
    ref, ref_t, _ = first_face_reference(o, d, np.full(n, 100.0), np.asarray(V, float), np.asarray(T), np.arange(3))
    assert np.all(ref == 2) and np.array_equal(face, ref)
    assert np.allclose(t, ref_t, rtol=1e-12)


@pytest.mark.parametrize("pieces", [1, 400])
def test_rays_in_a_floor_plane_reach_the_wall(rng, pieces):
    """Rays lying in a (tessellated) tilted floor graze it and hit the wall ahead."""
    n, u, w = tilted_frame()
    xs = np.linspace(0, 10, pieces // 2 + 2 if pieces > 1 else 2)
    V, T = [], []
    for x in xs:
        V += [x * u - 10 * w, x * u + 10 * w]
    for i in range(len(xs) - 1):
        a, b, c, d = 2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1
        T += [[a, b, c], [a, c, d]]
    k = len(V)
    V += [9.5 * u - 3 * w - 2 * n, 9.5 * u + 3 * w - 2 * n, 9.5 * u + 2 * n]
    T += [[k, k + 1, k + 2]]
    rc = caster(V, T, epsilon=1e-6)
    m = 2000
    o = 0.01 * u + rng.uniform(-0.5, 0.5, m)[:, None] * w
    d = u + rng.uniform(-0.02, 0.02, m)[:, None] * w
    face, _ = rc.first_hit(o, d, tmin=1e-3)
    assert np.all(face == len(T) - 1)


def test_rays_through_two_close_plates_hit_the_second(rng):
    """Vertical rays just outside plate A hit plate B 5e-8 below, never the sky."""
    for gap in (3e-7, 5e-8):
        V = [[-1, 0, 0], [1, 0, 0], [0, 1, 0], [-2, -2, -gap], [2, -2, -gap], [0, 2, -gap]]
        rc = caster(V, [[0, 1, 2], [3, 4, 5]], epsilon=1e-9)
        n = 4000
        delta = 10 ** rng.uniform(-12, -7, n)
        o = np.stack([rng.uniform(-0.3, 0.3, n), -delta, np.ones(n)], 1)
        face, _ = rc.first_hit(o, np.tile([0.0, 0.0, -1.0], (n, 1)), tmin=0.0, tmax=10.0)
        assert np.all(face == 1)


def test_near_plane_rays_never_report_a_hit_beyond_a_closer_wall(rng):
    """Rays descending through a floor at 1e-9..1e-7 rad: float32 may not see that crossing
    (documented), but a reported hit is never farther than the true first hit."""
    n, u, w = tilted_frame()
    V = [-10 * w, 20 * u, 10 * w, u - 3 * w - 2 * n, u + 3 * w - 2 * n, u + 2 * n]
    T = [[0, 1, 2], [3, 4, 5]]
    rc = caster(V, T, epsilon=1e-6)
    m = 4000
    o = rng.uniform(-0.5, 0.2, m)[:, None] * u + rng.uniform(-1, 1, m)[:, None] * w + 1e-8 * n
    d = u + rng.uniform(-0.3, 0.3, m)[:, None] * w - 10 ** rng.uniform(-9, -7, m)[:, None] * n
    face, t = rc.first_hit(o, d, tmin=1e-3)
    dn = d / np.linalg.norm(d, axis=1, keepdims=True)
    ref, ref_t, _ = first_face_reference(
        o + 1e-3 * dn, dn, np.full(m, 100.0), np.asarray(V, float), np.asarray(T), np.arange(2)
    )
    # the wall alone: no answer may lie beyond it
    wall, wall_t, _ = first_face_reference(
        o + 1e-3 * dn, dn, np.full(m, 100.0), np.asarray(V, float), np.asarray(T)[1:], np.arange(1)
    )
    assert np.all(wall == 0)
    assert np.all(t <= wall_t + 1e-3 + 1e-9)
    assert np.all(face[ref == 1] == 1), "the wall, when it is first, is always found"
    agree = np.mean(face == ref)
    assert agree > 0.5, agree  # the rest: floor crossings float32 cannot see (documented)
