"""The grid broad phase of a free point's edge pairs (``edge_pairs_seen_together``) finds
exactly the pairs the exact test accepts among all pairs (brute force), including the
degenerate points: on an edge's line, in the plane of several edges."""

import sys

import numpy as np
import pytest
from conftest import ROOT, SAMPLES

from viscx.scene import load_scene
from viscx.skeleton.point_nodes import edge_pairs_seen_together, seen_together
from viscx.tolerances import ANGLE_TOLERANCE

sys.path.insert(0, str(ROOT / "benchmarks"))
from scenes import random_boxes, spheres_in_room  # noqa: E402


def _segments(scene):
    ev = scene.half_edges.edge_vertices[scene.generator_edges]
    return scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]


def _all_pairs(p, a, b, slack):
    i, j = np.triu_indices(len(a), 1)
    pairs = np.stack([i, j], axis=1)
    return pairs[seen_together(p, a, b, slack, pairs)]


@pytest.mark.parametrize("make", [lambda: random_boxes(100, seed=3), lambda: spheres_in_room(subdivisions=1)],
                         ids=["boxes", "spheres"])
def test_grid_pairs_equal_all_pairs(make):
    scene = make()
    a, b = _segments(scene)
    lo, hi = scene.vertices.min(axis=0), scene.vertices.max(axis=0)
    rng = np.random.default_rng(7)
    points = [lo + (hi - lo) * rng.uniform(0.05, 0.95, 3) for _ in range(4)]
    points.append(0.3 * a[5] + 0.7 * b[5])  # on an edge: its arc is a whole great circle
    points.append(np.array([0.5 * (lo[0] + hi[0]), a[0][1], 0.5 * (lo[2] + hi[2])]))  # at a vertex's height
    for p in points:
        dist = np.minimum(np.linalg.norm(a - p, axis=1), np.linalg.norm(b - p, axis=1))
        slack = 4 * scene.epsilon / np.maximum(dist, 1e-300) + ANGLE_TOLERANCE
        found = edge_pairs_seen_together(p, a, b, slack)
        assert len(found) > 0
        assert np.array_equal(found, _all_pairs(p, a, b, slack))


def test_coplanar_edges_far_apart_on_one_circle():
    """Edges in one plane with p: their great circles are one, so the exact test leaves the
    pair to validation wherever the arcs lie; the normals' broad phase must find it."""
    p = np.zeros(3)
    a = np.array([[1.0, 0.0, 0.0], [-1.0, 0.2, 0.0], [0.0, 0.0, 1.0]])
    b = np.array([[1.0, 0.1, 0.0], [-1.0, 0.3, 0.0], [0.1, 0.0, 1.0]])
    slack = np.full(3, ANGLE_TOLERANCE)
    found = edge_pairs_seen_together(p, a, b, slack)
    assert [0, 1] in found.tolist()
    assert np.array_equal(found, _all_pairs(p, a, b, slack))


def _free_points(scene, rng):
    """Free points of a scene: random ones, on the line of an edge (beyond its end) and in
    the plane of a face (off the face), as far as check_points admits them."""
    from viscx.skeleton.points import check_points

    lo, hi = scene.vertices.min(axis=0), scene.vertices.max(axis=0)
    ev = scene.half_edges.edge_vertices
    out = [lo + (hi - lo) * rng.uniform(0.05, 0.95, 3) for _ in range(3)]
    for e in rng.choice(len(ev), 3, replace=False):
        a, b = scene.vertices[ev[e]]
        out.append(b + (b - a) * rng.uniform(0.5, 3.0))
    for f in rng.choice(scene.n_faces, 3, replace=False):
        loop = scene.face_loops(f)[0]
        u = loop[1] - loop[0]
        out.append(loop.mean(axis=0) + u * rng.uniform(1.5, 4.0))
    free = []
    for p in out:
        try:
            check_points(scene, p[None])
            free.append(p)
        except Exception:
            pass
    return free


@pytest.mark.parametrize("make", [lambda: random_boxes(60, seed=5), lambda: spheres_in_room(subdivisions=2),
                                  lambda: load_scene(SAMPLES / "boxes_on_floor.obj"),
                                  lambda: load_scene(SAMPLES / "room_with_door.obj")],
                         ids=["boxes", "spheres", "boxes_on_floor", "room_with_door"])
def test_blocked_inner_edges_leave_the_nodes_unchanged(make, monkeypatch):
    """Dropping the VEE candidates whose nearer edge blocks the line (inner_edge_blocks)
    before validation gives the nodes of validating every candidate, field for field, at
    random points, points on an edge's line and points in a face's plane."""
    from viscx.skeleton import point_nodes as pn
    from viscx.skeleton.nodes import Nodes, validate_candidates
    from viscx.skeleton.points import with_points

    scene = make()
    points = _free_points(scene, np.random.default_rng(9))
    assert len(points) >= 5
    dropped = []
    for p in points:
        ext = with_points(scene, p[None])
        ids = np.array([scene.n_vertices])
        fast = pn.point_nodes(ext, ids)
        kept = len(pn.point_candidates(ext, ids)[0])
        with monkeypatch.context() as m:
            m.setattr(pn, "inner_edge_blocks", lambda scene, p, e1, e2, d: np.zeros(len(d), bool))
            every = pn.point_candidates(ext, ids)
        slow = validate_candidates(ext, *every)
        dropped.append(1 - kept / len(every[0]))
        for name in Nodes.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
    assert max(dropped) > 0.2  # the rule does drop candidates here
