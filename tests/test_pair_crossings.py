"""The pair kernel's crossings (viscx.geometry.occlusion._polygon_crossings: the edges paired
run by run, runs whose boxes are apart never paired) against every edge paired with every
other (the kernel's rule before: closed u ranges overlapping, polygons different or one that
crosses itself, no vertical edge): the same breaks, bit for bit, on polygons that overlap,
touch along shared edges and corners (a grid of squares), meet only at a box's side, and
cross themselves."""

import numpy as np
import pytest

from viscx.geometry import occlusion


def _edges(polygons):
    """Consecutive runs of edges, one per polygon ``(loop (k, 2), id)``: ``seg_a, seg_b (n, 2),
    seg_p (n,)``."""
    a, b, p = [], [], []
    for loop, pid in polygons:
        a.append(loop)
        b.append(np.roll(loop, -1, axis=0))
        p.append(np.full(len(loop), pid, np.int64))
    return np.concatenate(a), np.concatenate(b), np.concatenate(p)


def _every_pair(seg_a, seg_b, seg_p, seg_w, lo_u, hi_u, self_cross):
    out = []
    n = len(seg_a)
    for e in range(n):
        for f in range(e + 1, n):
            if seg_w[e] == 0 or seg_w[f] == 0 or (seg_p[e] == seg_p[f] and self_cross[seg_p[e]] == 0):
                continue
            if lo_u[f] > hi_u[e] or lo_u[e] > hi_u[f]:
                continue
            u = occlusion._crossing_u(seg_a, seg_b, e, f)
            if u == u:
                out.append(u)
    return np.sort(np.asarray(out, np.float64))


def _crossings(polygons, crossing_itself=()):
    seg_a, seg_b, seg_p = _edges(polygons)
    n = len(seg_a)
    seg_w = np.ones(n, np.int64)
    for e in range(n):  # the kernel's weights: 0 where vertical (no slab's side)
        seg_w[e] = 0 if seg_a[e, 0] == seg_b[e, 0] else 1
    lo_u, hi_u = np.minimum(seg_a[:, 0], seg_b[:, 0]), np.maximum(seg_a[:, 0], seg_b[:, 0])
    self_cross = np.zeros(int(seg_p.max()) + 1, np.int64)
    self_cross[list(crossing_itself)] = 1
    brk, m = occlusion._polygon_crossings(seg_a, seg_b, seg_p, seg_w, n, lo_u, hi_u, self_cross, np.empty(4), 0)
    return np.sort(brk[:m]), _every_pair(seg_a, seg_b, seg_p, seg_w, lo_u, hi_u, self_cross)


@pytest.mark.parametrize("seed", range(6))
def test_crossings_of_overlapping_convex_shadows(seed):
    """Random convex polygons (some far apart, most overlapping), one polygon split in two
    runs apart, one crossing itself: the same breaks as every pair."""
    rng = np.random.default_rng(seed)
    polygons = []
    for k in range(14):
        centre = rng.uniform(0, 4 if k % 3 else 12, 2)
        angles = np.sort(rng.uniform(0, 2 * np.pi, rng.integers(3, 8)))
        radius = rng.uniform(0.2, 1.5)
        polygons.append((centre + radius * np.stack([np.cos(angles), np.sin(angles)], 1), 1 + k))
    polygons.append((polygons[0][0] + 0.7, 1))  # polygon 1 again, in a run of its own
    polygons.append((np.array([[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]]) + rng.uniform(0, 3, 2), 20))
    polygons.append((np.array([[-1.0, -1.0], [20.0, -1.0], [20.0, 20.0], [-1.0, 20.0]]), 0))  # J, around all
    got, want = _crossings(polygons, crossing_itself=(20,))
    assert len(want) > 3
    assert np.array_equal(got, want)


def test_crossings_of_touching_squares_and_boxes_meeting_at_a_side():
    """A grid of unit squares (shared edges and corners: boxes that touch), a square whose
    box meets another's only along a side, a square with vertical edges in a tilted frame:
    the same breaks as every pair (none lost where the boxes only touch)."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    polygons = [(square + [i, j], 1 + 3 * i + j) for i in range(3) for j in range(3)]
    polygons.append((square * 0.5 + [2.75, 0.25], 10))  # across the grid's right side
    polygons.append((square * [1.0, 3.0] + [3.0, 0.0], 11))  # its box meets the grid's at u = 3
    turn = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    polygons.append((square * 2.0 @ turn.T + [0.5, 0.5], 12))
    got, want = _crossings(polygons)
    assert len(want) > 5
    assert np.array_equal(got, want)
