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


def parallel_rectangles(X, Y):
    """Closed form: directly opposed parallel rectangles X = a/c, Y = b/c (Howell C-11)."""
    return (2 / (np.pi * X * Y)) * (
        np.log(np.sqrt((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y)))
        + X * np.sqrt(1 + Y * Y) * np.arctan(X / np.sqrt(1 + Y * Y))
        + Y * np.sqrt(1 + X * X) * np.arctan(Y / np.sqrt(1 + X * X))
        - X * np.arctan(X)
        - Y * np.arctan(Y)
    )


def perpendicular_rectangles(H, W):
    """Closed form: rectangles at a right angle sharing an edge of length l, H = h/l, W = w/l,
    from the w × l one to the h × l one (Howell C-14)."""
    a = (1 + W * W) * (1 + H * H) / (1 + W * W + H * H)
    b = (W * W * (1 + W * W + H * H) / ((1 + W * W) * (W * W + H * H))) ** (W * W)
    c = (H * H * (1 + H * H + W * W) / ((1 + H * H) * (H * H + W * W))) ** (H * H)
    return (W * np.arctan(1 / W) + H * np.arctan(1 / H) - np.hypot(H, W) * np.arctan(1 / np.hypot(H, W)) + 0.25 * np.log(a * b * c)) / (np.pi * W)


@pytest.mark.parametrize("a, b, c", [(1, 1, 1), (2, 0.5, 1.5), (0.2, 3.0, 0.7)])
def test_parallel_rectangles(a, b, c):
    from viscx.geometry.formfactor import polygon_to_polygon

    lower = np.array([[0, 0, 0], [a, 0, 0], [a, b, 0], [0, b, 0.0]])
    upper = lower + [0, 0, c]
    got = polygon_to_polygon([lower], [0, 0, 1], [upper], [0, 0, -1])
    assert abs(got - parallel_rectangles(a / c, b / c)) < 1e-9


@pytest.mark.parametrize("l, w, h", [(1, 1, 1), (2, 0.5, 1.5), (0.7, 3.0, 0.4)])
def test_perpendicular_rectangles_sharing_an_edge(l, w, h):
    from viscx.geometry.formfactor import polygon_to_polygon

    floor = np.array([[0, 0, 0], [l, 0, 0], [l, w, 0], [0, w, 0.0]])
    wall = np.array([[0, 0, 0], [l, 0, 0], [l, 0, h], [0, 0, h]])
    got = polygon_to_polygon([floor], [0, 0, 1], [wall], [0, 1, 0])
    assert abs(got - perpendicular_rectangles(h / l, w / l)) < 1e-9
    # reciprocity: A_i F_ij = A_j F_ji
    back = polygon_to_polygon([wall], [0, 1, 0], [floor], [0, 0, 1])
    assert abs(l * w * got - l * h * back) < 1e-9


def test_polygon_to_polygon_is_the_integral_of_point_to_polygon(rng):
    """Tilted triangles, no shared boundary: the contour integral against Monte Carlo
    integration of the exact point-to-polygon formula over the emitter."""
    from viscx.geometry.formfactor import polygon_to_polygon

    tri_i = np.array([[0, 0, 0], [1.0, 0.1, 0.05], [0.2, 0.9, -0.1]])
    tri_j = np.array([[0.1, 0.2, 1.0], [1.2, 0.5, 1.4], [-0.3, 1.1, 1.2]])
    n_i = np.cross(tri_i[1] - tri_i[0], tri_i[2] - tri_i[0])
    n_i /= np.linalg.norm(n_i)
    n_j = -np.cross(tri_j[1] - tri_j[0], tri_j[2] - tri_j[0])
    n_j /= np.linalg.norm(n_j)
    exact = polygon_to_polygon([tri_i], n_i, [tri_j], n_j)
    k = 200_000
    u, v = rng.random(k), rng.random(k)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    points = tri_i[0] + u[:, None] * (tri_i[1] - tri_i[0]) + v[:, None] * (tri_i[2] - tri_i[0])
    values = point_to_polygon(points, np.tile(n_i, (k, 1)), [tri_j])
    sigma = values.std() / np.sqrt(k)
    assert abs(values.mean() - exact) < 4 * sigma


def _cornell_contour_pair(emitter, side, receiver, side_r):
    """I' and J' of a Cornell pair as :class:`viscx.queries.formfactor.PairSetup` clips them."""
    from conftest import SAMPLES

    from viscx.queries import formfactor as ff
    from viscx.scene import load_scene

    scene = load_scene(SAMPLES / "cornell_box.obj")
    setup = ff.PairSetup(scene, emitter, side, ff.face_target(scene, receiver), side_r, occluders=False)
    return setup.I, setup.n_i, setup.J, setup.n_t


def test_contour_estimate_covers_its_rounding_near_touching_edges():
    """Back of the short block's side 8 → floor: I' is clipped to 1e-9 of the scene above
    the floor's plane (9.6e-7), so its bottom edge runs 1e-6 from the floor's edges' lines.
    The inner closed form's distance to a line as √(|w|² − t²) lost half the digits there:
    the value came out 1.03e-8 off for an estimate (10- vs 6-point panels) of 2.7e-9. The
    same quadrature in 80-bit extended precision is the oracle: the float64 value is within
    the estimate of it (the perpendicular part's length, and a bound on the rounding of the
    cancelling terms)."""
    from viscx.geometry.formfactor import polygon_to_polygon_orders
    from viscx.queries.formfactor import contour_form_factor

    I, n_i, J, n_j = _cornell_contour_pair(8, -1, 0, 1)
    assert min(float(np.min(l[:, 1])) for l in I) < 1e-6  # the grazing case
    value, error = contour_form_factor(I, n_i, J, n_j)
    wide = [np.asarray(l, np.longdouble) for l in I], [np.asarray(l, np.longdouble) for l in J]
    (ref,), _ = polygon_to_polygon_orders(wide[0], n_i, wide[1], n_j, (10,))
    assert np.asarray(ref).dtype == np.longdouble
    assert abs(value - float(ref)) <= error
    assert error < 1e-9


def test_contour_grading_stops_at_the_distance_to_the_other_polygon(monkeypatch):
    """The outer nodes are graded toward a knot only down to a quarter of its distance from
    the other polygon's edges (:func:`viscx.geometry.formfactor._knot_levels`): two unit
    squares facing each other at distance 1 take a handful of panels per edge instead of 82,
    and the value is the one with all 40 levels everywhere to 1e-14; touching polygons
    (perpendicular squares sharing an edge) keep all 40 levels at the shared edge."""
    from viscx.geometry import formfactor as gf

    lower = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    upper = lower + [0, 0, 1]
    wall = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1.0]])
    p, q = upper, np.roll(upper, -1, axis=0)
    far = gf._knot_levels(lower[:2], p, q, np.array([1.0, 1.0]))
    assert far.max() <= 2
    near = gf._knot_levels(lower[:2], wall, np.roll(wall, -1, axis=0), np.array([1.0, 1.0]))
    assert np.all(near == gf.LEVELS)
    for loops in (([lower], [0, 0, 1], [upper], [0, 0, -1]), ([lower], [0, 0, 1], [wall], [0, 1, 0])):
        graded = gf.polygon_to_polygon(*loops)
        with monkeypatch.context() as m:
            m.setattr(gf, "_knot_levels", lambda points, p, q, span: np.full(len(span), gf.LEVELS))
            dense = gf.polygon_to_polygon(*loops)
        assert abs(graded - dense) < 1e-14
