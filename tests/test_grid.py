"""The exact float64 grid caster (viscx.grid.TriangleGrid) against a brute force that
tests every triangle with the same Möller–Trumbore: the same first triangle and the same
t, bit for bit, on the parallel kernel, the serial one and inside a thread pool."""

import numpy as np
import pytest
from random_scenes import random_boxes

from viscx.grid import BARY_SLACK, SERIAL_RAYS, moller_trumbore
from viscx.parallel import map_chunks
from viscx.scene import build_scene


def brute_first_hits(grid, o, d, tmin, tmax):
    """Lowest t on [tmin, tmax] over every triangle (closed, BARY_SLACK), ties to the lowest id."""
    tri = np.full(len(o), -1)
    t = np.full(len(o), np.inf)
    for i in range(len(o)):
        for k in range(len(grid.triangles)):
            tk, margin, _ = moller_trumbore(o[i], d[i], grid.vertices, grid.triangles, k)
            if margin >= -BARY_SLACK and tmin[i] <= tk <= tmax[i] and tk < t[i]:
                tri[i], t[i] = k, tk
    return tri, t


@pytest.fixture(scope="module")
def boxes_and_rays():
    """Axis-aligned boxes on a floor, and rays from their vertices towards other vertices
    and random points (through edges and corners: ties between faces), along the floor
    (grazing) and from random points."""
    rng = np.random.default_rng(3)
    scene = build_scene(random_boxes(rng, 6, axis_aligned=True, on_floor=True))
    v = scene.vertices
    lo, hi = scene.bbox
    n = 1500
    o = np.concatenate([v[rng.integers(0, len(v), n)], lo + (hi - lo) * rng.random((n, 3))])
    target = np.concatenate([v[rng.integers(0, len(v), n)], lo + (hi - lo) * rng.random((n, 3))])
    o[: n // 4, 1] = target[: n // 4, 1] = 0.0  # in the floor's plane
    d = target - o
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    d[~np.isfinite(d).all(axis=1) | (np.linalg.norm(d, axis=1) == 0)] = (0.0, 0.0, 1.0)
    tmin = np.full(len(o), 1e-9)
    tmax = np.where(rng.random(len(o)) < 0.5, np.inf, rng.random(len(o)) * scene.diagonal)
    grid = scene.ray_caster.exact
    return grid, o, d, tmin, tmax, brute_first_hits(grid, o, d, tmin, tmax)


def test_parallel_kernel_is_the_brute_force(boxes_and_rays):
    grid, o, d, tmin, tmax, (tri, t) = boxes_and_rays
    assert len(o) >= SERIAL_RAYS
    got_tri, got_t = grid.first_hit(o, d, tmin, tmax)
    assert np.array_equal(got_tri, tri) and np.array_equal(got_t, t)
    assert 0.2 < (tri >= 0).mean() < 0.95


def test_serial_kernel_and_pooled_threads_are_the_brute_force(boxes_and_rays):
    grid, o, d, tmin, tmax, (tri, t) = boxes_and_rays
    # small calls run the serial kernel; so do the threads of a pool (each its own stamps)
    parts = map_chunks(lambda r: grid.first_hit(o[r], d[r], tmin[r], tmax[r]), [slice(k, k + 700) for k in range(0, len(o), 700)],
                       workers=2)
    assert np.array_equal(np.concatenate([p[0] for p in parts]), tri)
    assert np.array_equal(np.concatenate([p[1] for p in parts]), t)


def test_segment_triangle_distance_against_sampling():
    """The exact segment-triangle distance (scalar code) against the distance from points
    densely spaced along the segment (Ericson's point-triangle distance): never above the
    sampled minimum, and within the sampling step of it; zero where the segment pierces the
    triangle (crossing its plane inside it)."""
    from viscx.grid import _point_triangle_dist2, _segment_triangle_dist2

    rng = np.random.default_rng(11)
    t = np.linspace(0.0, 1.0, 1001)
    for k in range(150):
        p0, p1, a, b, c = rng.normal(size=(5, 3))
        if k % 3 == 0:  # a segment through the triangle's interior
            w = rng.dirichlet(np.ones(3))
            x = w[0] * a + w[1] * b + w[2] * c
            p1 = x + (x - p0) * rng.uniform(0.2, 2.0)
        exact = np.sqrt(_segment_triangle_dist2(p0, p1, a, b, c))
        sampled = min(np.sqrt(_point_triangle_dist2(p0 + s * (p1 - p0), a, b, c)) for s in t)
        step = np.linalg.norm(p1 - p0) / (len(t) - 1)
        assert exact <= sampled + 1e-12
        assert sampled - exact <= step
        if k % 3 == 0:
            assert exact <= 1e-9
