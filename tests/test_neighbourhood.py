"""The surface around generators: exact point/segment–triangle distances (against dense
sampling), the per-scene contact cache (against the geometric search it replaces)."""

import numpy as np
import pytest
from conftest import sample_scene_paths

from viscx.grid import _point_triangle_dist2, _segment_triangle_dist2
from viscx.scene import load_scene
from viscx.scene.neighbourhood import faces_near, generator_wedges, surface_wedges


def sampled_triangle(a, b, c, n):
    """Points of a triangle on an n-step barycentric lattice (corners and edges included)."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    inside = u + v <= 1 + 1e-12
    return a + u[inside, None] * (b - a) + v[inside, None] * (c - a)


def test_point_triangle_distance_against_sampling(rng):
    """Exact distance ≤ the distance to every lattice point, and within the lattice's
    spacing of the nearest one."""
    for _ in range(100):
        a, b, c, p = rng.normal(size=(4, 3))
        exact = np.sqrt(_point_triangle_dist2(p, a, b, c))
        q = sampled_triangle(a, b, c, 300)
        sampled = np.linalg.norm(q - p, axis=1).min()
        spacing = max(np.linalg.norm(b - a), np.linalg.norm(c - a)) / 299
        assert exact <= sampled + 1e-12
        assert sampled - exact <= spacing


def test_segment_triangle_distance_against_sampling(rng):
    for trial in range(40):
        a, b, c, p0, p1 = rng.normal(size=(5, 3))
        if trial % 4 == 0:  # a segment through the triangle: distance 0
            x = sampled_triangle(a, b, c, 7)[rng.integers(0, 28)]
            p0, p1 = x - rng.normal(size=3), x
            p1 = x + (x - p0) * rng.random()
        exact = np.sqrt(_segment_triangle_dist2(p0, p1, a, b, c))
        q = sampled_triangle(a, b, c, 80)
        s = p0 + np.linspace(0, 1, 400)[:, None] * (p1 - p0)
        sampled = min(np.linalg.norm(q - x, axis=1).min() for x in s)
        spacing = max(np.linalg.norm(b - a), np.linalg.norm(c - a)) / 79 + np.linalg.norm(p1 - p0) / 399
        assert exact <= sampled + 1e-12
        assert sampled - exact <= spacing
        if trial % 4 == 0:
            assert exact <= 1e-12


@pytest.mark.parametrize("path", sample_scene_paths(), ids=lambda p: p.name)
def test_segments_near_triangles_match_brute_force(path):
    """The grid search finds exactly the pairs that testing every triangle finds."""
    scene = load_scene(path)
    grid = scene.ray_caster.exact
    ev = scene.half_edges.edge_vertices
    p, q = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
    tol = 10 * scene.weld_tolerance
    seg, tri = grid.triangles_near_segments(p, q, tol)
    found = set(zip(seg.tolist(), tri.tolist()))
    corners = scene.vertices[scene.triangles]
    brute = {(i, t) for i in range(len(p)) for t in range(len(corners))
             if _segment_triangle_dist2(p[i], q[i], *corners[t]) <= tol * tol}
    assert found == brute


def wedge_set(w, i):
    lo, hi = w.offsets[i], w.offsets[i + 1]
    return sorted((int(f), tuple(np.round(a, 9)), round(float(s), 9)) for f, a, s in zip(w.face[lo:hi], w.first[lo:hi], w.span[lo:hi]))


@pytest.mark.parametrize("path", sample_scene_paths(), ids=lambda p: p.name)
def test_cached_generator_wedges_equal_the_geometric_search(path, rng):
    """At vertices and at random inner points of every edge (some within a few epsilon
    of an end), the cached wedges are the ones the geometric search finds."""
    scene = load_scene(path)
    ev = scene.half_edges.edge_vertices
    n_edges = len(ev)
    edges = np.repeat(np.arange(n_edges), 6)
    a, b = scene.vertices[ev[edges, 0]], scene.vertices[ev[edges, 1]]
    length = np.linalg.norm(b - a, axis=1)
    s = rng.random(len(edges))
    s[::6] = np.minimum(1.5 * scene.epsilon / length[::6], 0.5)  # just past the shrink at the start
    s[1::6] = 1 - np.minimum(3 * scene.epsilon / length[1::6], 0.5)
    points = a + s[:, None] * (b - a)
    vertices = np.arange(scene.n_vertices)
    is_vertex = np.concatenate([np.ones(len(vertices), bool), np.zeros(len(edges), bool)])
    generator = np.concatenate([vertices, edges])
    all_points = np.concatenate([scene.vertices, points])
    cached = generator_wedges(scene, is_vertex, generator, all_points)
    geometric = surface_wedges(scene, all_points)
    for i in range(len(all_points)):
        assert wedge_set(cached, i) == wedge_set(geometric, i), (i, generator[i], is_vertex[i])


@pytest.mark.parametrize("path", sample_scene_paths(), ids=lambda p: p.name)
def test_clean_edges_touch_only_their_own_faces(path):
    """Along every edge (41 inner points): a foreign face within the weld tolerance of any
    point makes the edge unclean; a clean edge has only its own faces near."""
    scene = load_scene(path)
    ev = scene.half_edges.edge_vertices
    a, b = scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]
    t = np.linspace(0.02, 0.98, 41)
    points = (a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, 3)
    point, face = faces_near(scene, points, scene.weld_tolerance)
    edge = point // len(t)
    own = set(zip(scene.half_edges.edge.tolist(), scene.half_edges.face.tolist()))
    foreign = np.array([(e, f) not in own for e, f in zip(edge.tolist(), face.tolist())], dtype=bool)
    touched = np.zeros(len(ev), bool)
    touched[edge[foreign]] = True
    assert not np.any(scene.contacts.edge_clean & touched)
    if path.name == "boxes_on_floor.obj":
        # exactly the boxes' bottom edges on the floor and the three edges where box0 and
        # box1 share the plane x = 3 are unclean
        assert np.array_equal(~scene.contacts.edge_clean, touched)
        assert np.count_nonzero(touched) == 3 * 4 + 3


def _covered_by_sampling(first, normal, span, d, n=20_000):
    """Brute force of tangency's cover test: shift the line along d sideways by u (n unit
    vectors ⊥ d around the circle) and intersect it with each wedge's plane; u is covered
    when that point lies in some wedge (angle about the normal from the first ray within
    the span). Returns the fraction of the circle covered."""
    e1 = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    phi = (np.arange(n) + 0.5) * (2 * np.pi / n)
    u = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    covered = np.zeros(n, dtype=bool)
    for a, nrm, sp in zip(first, normal, span):
        t = -(u @ nrm) / (d @ nrm)
        p = u + t[:, None] * d
        ang = np.arctan2(p @ np.cross(nrm, a), p @ a) % (2 * np.pi)
        covered |= ang <= sp
    return covered.mean()


def test_cover_closed_by_a_wrapping_wedge(rng):
    """The surface separates a line's rays iff the wedges' projections cover the circle,
    whichever wedge starts first. A T-vertex (a desk panel's inner top corner on the
    top's bottom edge: two half-planes of the top and three quarters of the panel) had a
    quarter starting inside the wrap of a half-plane, and the sweep from the smallest start
    stopped at the quarter's end: lines entering the top were judged tangent there. Against
    sampling, for random subsets of the twelve quarters of the coordinate planes (rotated)
    and random directions."""
    from viscx.geometry.tangency import tangent_in_wedges
    from viscx.scene.neighbourhood import Wedges

    axes = np.eye(3)
    quarters = []  # (first, normal, span) of the four quarters of each coordinate plane
    for k in range(3):
        n, a = axes[k], axes[(k + 1) % 3]
        for turn in range(4):
            quarters.append((a, n, np.pi / 2))
            a = np.cross(n, a)
    # the desk's T-vertex, in its own frame: the top's bottom and front half-planes and the panel's
    # inner, top and front quarters; lines into the top are blocked
    desk = ([(1, 0, 0), (0, -1, 0), np.pi], [(-1, 0, 0), (0, 0, -1), np.pi], [(0, 0, 1), (1, 0, 0), np.pi / 2],
            [(-1, 0, 0), (0, 1, 0), np.pi / 2], [(0, -1, 0), (0, 0, -1), np.pi / 2])
    cases = [(desk, np.array([0.99845847, 0.02186405, 0.05101613]))]
    for _ in range(300):
        pick = rng.random(12) < rng.uniform(0.2, 0.7)
        pick[rng.integers(12)] = True
        rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        wedges = [(rot @ a, rot @ n, sp) for (a, n, sp), p in zip(quarters, pick) if p]
        d = rng.normal(size=3)
        cases.append((wedges, d / np.linalg.norm(d)))
    wrong = 0
    for wedges, d in cases:
        first = np.array([np.asarray(w[0], float) for w in wedges])
        normal = np.array([np.asarray(w[1], float) for w in wedges])
        span = np.array([w[2] for w in wedges], dtype=float)
        w = Wedges(np.array([0, len(wedges)]), np.zeros(len(wedges), np.int64), first, normal, span)
        tangent, degenerate = tangent_in_wedges(w, d[None])
        assert not degenerate[0]
        wrong += bool(tangent[0]) != (_covered_by_sampling(first, normal, span, d) < 1.0)
    assert wrong == 0
