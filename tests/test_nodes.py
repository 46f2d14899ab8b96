"""V0 nodes from the reference enumeration, checked by an independent ray oracle."""

import numpy as np
import pytest
from conftest import SAMPLES, sample_scene_paths
from oracles import segment_hits_reference

from viscx.scene import load_scene
from viscx.skeleton.nodes import BLOCK_EDGE, BLOCK_FACE, BLOCK_SKY, BLOCK_VERTEX, E4, VEE, VV
from viscx.skeleton.reference import reference_nodes


def point_segment_distance(p, a, b):
    ab = b - a
    s = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
    return np.linalg.norm(p - a - s[:, None] * ab, axis=1)


def line_point_distance(o, d, p):
    return np.linalg.norm(np.cross(p - o, d), axis=1)


@pytest.fixture(scope="module", params=[p.name for p in sample_scene_paths()])
def scene_nodes(request):
    scene = load_scene(SAMPLES / request.param)
    return scene, reference_nodes(scene)


def test_nodes_pass_through_their_generators(scene_nodes):
    scene, nodes = scene_nodes
    eps = scene.epsilon
    o = nodes.ends[:, 0]
    for slot in range(4):
        is_vertex = ((nodes.kind == VV) & (slot < 2)) | ((nodes.kind == VEE) & (slot == 0))
        is_edge = ((nodes.kind == VEE) & (slot in (1, 2))) | (nodes.kind == E4)
        v = is_vertex
        assert np.all(line_point_distance(o[v], nodes.direction[v], scene.vertices[nodes.generators[v, slot]]) <= eps)
        e = is_edge & (slot < np.where(nodes.kind == E4, 4, 3))
        ev = scene.half_edges.edge_vertices[nodes.generators[e, slot]]
        gp = nodes.generator_points[e, slot]
        assert np.all(point_segment_distance(gp, scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]) <= eps)
        assert np.all(line_point_distance(o[e], nodes.direction[e], gp) <= eps)


def test_node_segments_are_free_between_generators(scene_nodes):
    """Every piece between consecutive points (ends and generators) is free, trimmed by epsilon."""
    scene, nodes = scene_nodes
    eps = scene.epsilon
    pts = np.concatenate([nodes.ends[:, :1], nodes.generator_points, nodes.ends[:, 1:]], axis=1)
    t = np.einsum("nkj,nj->nk", pts - nodes.ends[:, :1], nodes.direction)
    t = np.where(np.isnan(t), np.inf, t)
    order = np.argsort(t, axis=1)
    pts = np.take_along_axis(pts, order[..., None], axis=1)
    t = np.take_along_axis(t, order, axis=1)
    a, b = [], []
    for j in range(5):
        ok = np.isfinite(t[:, j + 1])
        ok[ok] = t[ok, j + 1] - t[ok, j] > 2 * eps
        a.append(pts[ok, j])
        b.append(pts[ok, j + 1])
    a, b = np.concatenate(a), np.concatenate(b)
    u = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    hit, _ = segment_hits_reference(a + eps * u, b - eps * u, scene.vertices, scene.triangles, bary_slack=-1e-9)
    assert not hit.any(axis=1).any()


def test_node_ends_lie_on_their_blockers(scene_nodes):
    scene, nodes = scene_nodes
    eps = scene.epsilon
    for side in (0, 1):
        kind, blocker, end = nodes.blocker_kind[:, side], nodes.blocker[:, side], nodes.ends[:, side]
        f = kind == BLOCK_FACE
        height = np.einsum("ij,ij->i", scene.face_normal[blocker[f]], end[f]) - scene.face_offset[blocker[f]]
        assert np.all(np.abs(height) <= 1e-9 * scene.diagonal + scene.weld_tolerance)
        v = kind == BLOCK_VERTEX
        assert np.all(np.linalg.norm(end[v] - scene.vertices[blocker[v]], axis=1) <= eps)
        e = kind == BLOCK_EDGE
        ev = scene.half_edges.edge_vertices[blocker[e]]
        assert np.all(point_segment_distance(end[e], scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]) <= eps)
        s = kind == BLOCK_SKY
        lo, hi = scene.ray_caster.sky_box
        on_box = np.isclose(end[s], lo, atol=1e-9 * scene.diagonal) | np.isclose(end[s], hi, atol=1e-9 * scene.diagonal)
        assert np.all(on_box.any(axis=1))
        assert np.all(f | v | e | s)


def test_node_ids_are_canonical_and_deterministic(scene_nodes):
    scene, nodes = scene_nodes
    again = reference_nodes(scene)
    for name in nodes.__dataclass_fields__:
        assert np.array_equal(getattr(nodes, name), getattr(again, name), equal_nan=True), name
    gens = nodes.generators
    vv = nodes.kind == VV
    assert np.all(gens[vv, 0] < gens[vv, 1])
    vee = nodes.kind == VEE
    assert np.all(gens[vee, 1] < gens[vee, 2])
    e4 = nodes.kind == E4
    assert np.all(np.diff(gens[e4], axis=1) > 0)


def test_reference_finds_every_kind_on_the_cornell_box():
    scene = load_scene(SAMPLES / "cornell_box.obj")
    counts = reference_nodes(scene).counts()
    assert counts["E4"] > 0 and counts["VEE"] > 0 and counts["VV"] > 0
