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
    assert free.mean() > 0.99
