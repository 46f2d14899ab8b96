"""Point-to-polygon form factors against closed forms, closure and Monte Carlo."""

import numpy as np
import pytest

from viscx.geometry.formfactor import clip_to_hemisphere, point_to_polygon


def corner_rectangle(a, b):
    """Closed form: point at unit distance below a corner of a parallel a × b rectangle
    (Howell's catalogue, configuration A-2)."""
    A, B = a / np.sqrt(1 + a * a), b / np.sqrt(1 + b * b)
    return (A * np.arctan(b / np.sqrt(1 + a * a)) + B * np.arctan(a / np.sqrt(1 + b * b))) / (2 * np.pi)


@pytest.mark.parametrize("a, b", [(1.0, 1.0), (0.3, 2.5), (10.0, 0.1), (4.0, 4.0)])
def test_parallel_rectangle_from_below_a_corner(a, b):
    h = 2.0  # scale invariance: the closed form uses a/h, b/h
    rect = np.array([[0, 0, h], [a * h, 0, h], [a * h, b * h, h], [0, b * h, h]])
    got = point_to_polygon([[0, 0, 0]], [[0, 0, 1]], [rect])
    assert abs(got[0] - corner_rectangle(a, b)) < 1e-12
    # either winding gives the same value
    assert abs(point_to_polygon([[0, 0, 0]], [[0, 0, 1]], [rect[::-1]])[0] - got[0]) < 1e-15


def test_a_closed_box_around_the_point_takes_everything(rng):
    """The faces in front of a point inside a closed box sum to exactly 1."""
    lo, hi = np.array([-1.0, -2.0, -0.5]), np.array([3.0, 1.0, 2.0])
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    for _ in range(20):
        p = lo + (hi - lo) * rng.uniform(0.1, 0.9, 3)
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        total = 0.0
        for f in faces:
            part = clip_to_hemisphere(corners[f], p, n)
            if len(part) >= 3:
                total += point_to_polygon([p], [n], [part])[0]
        assert abs(total - 1.0) < 1e-12


def test_a_hole_subtracts_its_own_form_factor():
    outer = np.array([[-2, -2, 1], [2, -2, 1], [2, 2, 1], [-2, 2, 1.0]])
    hole = np.array([[-0.5, -0.5, 1], [-0.5, 0.5, 1], [0.5, 0.5, 1], [0.5, -0.5, 1.0]])  # clockwise
    p, n = [[0.3, -0.2, 0]], [[0, 0, 1]]
    with_hole = point_to_polygon(p, n, [outer, hole])[0]
    assert abs(with_hole - (point_to_polygon(p, n, [outer])[0] - point_to_polygon(p, n, [hole])[0])) < 1e-14
    assert 0 < with_hole < point_to_polygon(p, n, [outer])[0]


def test_against_monte_carlo_cosine_sampling(rng):
    """A tilted triangle seen from a tilted point: 10⁶ cosine-weighted directions."""
    tri = np.array([[0.2, -0.3, 1.0], [1.5, 0.4, 1.8], [-0.4, 1.2, 1.3]])
    p = np.array([0.1, 0.1, 0.0])
    n = np.array([0.2, -0.1, 1.0])
    n /= np.linalg.norm(n)
    exact = point_to_polygon([p], [n], [tri])[0]
    k = 1_000_000
    # cosine-weighted directions about n: F = P(a direction hits the triangle)
    u1, u2 = rng.random(k), rng.random(k)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    t = np.cross(n, [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    s = np.cross(n, t)
    d = (r * np.cos(phi))[:, None] * t + (r * np.sin(phi))[:, None] * s + np.sqrt(1 - u1)[:, None] * n
    # ray–triangle by barycentrics (independent of the contour formula)
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    q = np.cross(d, e2)
    det = q @ e1
    w = p - tri[0]
    u = (q @ w) / det
    v = (np.cross(w, e1) @ d.T) / det
    tt = (np.cross(w, e1) @ e2) / det
    hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (tt > 0)
    estimate = hit.mean()
    sigma = np.sqrt(estimate * (1 - estimate) / k)
    assert abs(estimate - exact) < 4 * sigma
