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


def check_generators(scene, nodes):
    """The line passes within epsilon of each generator; edge points lie on their edges."""
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


def check_free(scene, nodes):
    """Every piece between consecutive points (ends and generators) is free, trimmed by epsilon."""
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


def check_ends(scene, nodes):
    """Each end lies on its blocker (face plane, vertex, edge, or the sky box)."""
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


def check_perturbation(scene, nodes):
    """Shift the node's line sideways by δ in 16 directions and look for hits with the
    faces touching the generator point (brute force, independent of the tangency
    predicates). A passed generator has a shift that misses them all (the
    line can be moved off the surface); a blocking one is hit by every shift
    (the surface separates the line's two rays there). Grazing generators are skipped."""
    from viscx.scene.neighbourhood import incident_faces

    vo, vf, eo, ef = incident_faces(scene)
    delta = 1e-5 * scene.diagonal
    angles = np.linspace(0, 2 * np.pi, 16, endpoint=False) + 0.1234  # not aligned with the axes
    checked = 0
    for i in range(len(nodes)):
        d = nodes.direction[i]
        u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(d, u)
        shifts = np.cos(angles)[:, None] * u + np.sin(angles)[:, None] * w
        kinds = {VV: (1, 1, 0, 0), VEE: (1, 0, 0, 0), E4: (0, 0, 0, 0)}[int(nodes.kind[i])]
        for slot in range(4):
            g = nodes.generators[i, slot]
            if g < 0:
                continue
            # every face touching the generator point, its own or not (a block's
            # bottom edge lies on the floor): found geometrically, not by topology
            p = nodes.generator_points[i, slot]
            _, near = scene.ray_caster.exact.triangles_near(p[None], 2 * scene.weld_tolerance)
            faces = np.unique(np.concatenate([vf[vo[g] : vo[g + 1]] if kinds[slot] else ef[eo[g] : eo[g + 1]], scene.triangle_face[near]]))
            slope = np.abs(scene.face_normal[faces] @ d).min()
            if slope < 1e-6:
                continue  # the line grazes one of its faces
            # stay local: the probe must not reach past the faces' other corners
            corners = np.concatenate([scene.face_loops(f)[k] for f in faces for k in range(len(scene.face_loops(f)))])
            gap = np.linalg.norm(corners - p, axis=1)
            local = gap[gap > 10 * scene.weld_tolerance].min()
            # a shift of δ meets a face at an angle θ after δ / sin θ
            shift = min(delta, local * slope / 8)
            reach = 4 * shift / slope
            tris = scene.triangles[np.isin(scene.triangle_face, faces)]
            a = p + shift * shifts - reach * d
            b = p + shift * shifts + reach * d
            at_end = [np.allclose(p, nodes.ends[i, k]) for k in (0, 1)]
            blocking = any(at_end[k] and nodes.blocker_kind[i, k] in (BLOCK_EDGE, BLOCK_VERTEX) for k in (0, 1))
            # grown faces for "every shift hits", shrunk ones for "some shift misses":
            # a shifted line through an edge of the faces is decided by a hair
            hit, _ = segment_hits_reference(a, b, scene.vertices, tris, bary_slack=1e-9 if blocking else -1e-9)
            hits = hit.any(axis=1)
            if blocking:
                assert hits.all(), f"node {i} slot {slot}: blocked there, yet a shifted line misses"
            else:
                assert not hits.all(), f"node {i} slot {slot}: passed there, yet every shifted line hits"
            checked += 1
    assert checked > 0 or len(nodes) == 0


def test_nodes_pass_through_their_generators(scene_nodes):
    check_generators(*scene_nodes)


def test_node_segments_are_free_between_generators(scene_nodes):
    check_free(*scene_nodes)


def test_node_ends_lie_on_their_blockers(scene_nodes):
    check_ends(*scene_nodes)


def test_blocked_and_passed_generators_by_perturbation(scene_nodes):
    check_perturbation(*scene_nodes)


def random_scene_nodes(seed, kind):
    from random_scenes import random_boxes, random_tetrahedra

    from viscx.scene import build_scene

    rng = np.random.default_rng(seed)
    if kind == "tetrahedra":
        s = random_tetrahedra(rng, int(rng.integers(2, 4)))
    else:
        s = random_boxes(rng, int(rng.integers(1, 3)), axis_aligned=kind != "rotated boxes", on_floor=kind == "boxes on a floor")
    scene = build_scene(s)
    return scene, reference_nodes(scene)


KINDS = ["tetrahedra", "rotated boxes", "floating aligned boxes", "boxes on a floor"]


def _check_random(seed, kind):
    scene, nodes = random_scene_nodes(seed, kind)
    for check in (check_generators, check_free, check_ends, check_perturbation):
        check(scene, nodes)


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("kind", KINDS)
def test_random_scenes(kind, seed):
    """20 random scenes in the default suite; `-m slow` runs 200 more through hypothesis."""
    _check_random(1000 + seed, kind)


@pytest.mark.slow
def test_many_random_scenes():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=200, deadline=None, derandomize=True)
    @given(st.integers(0, 2**31 - 1), st.sampled_from(KINDS))
    def run(seed, kind):
        _check_random(seed, kind)

    run()


def test_pencil_line_passes_a_row_of_touching_blocks(tmp_path):
    """A line lying in the contact plane x = 4.2 of two columns of ten blocks touching side
    by side (heights 1 and 1.5, staggered in z) passes every face beside the plane that it
    touches and every face in it: free to the end (``first_triangles`` with
    ``plane_face``), however many it passes (MAX_PASSED, not MAX_GRAZED = 8); without the
    plane, the first face beside it stops it."""
    from test_discontinuities import floor_light_boxes_obj

    from viscx.skeleton.nodes import first_triangles

    boxes = {}
    for i in range(10):
        boxes[f"a{i}"] = (3.0, 4.2, 1.0, 0.5 + i, 1.5 + i)
        boxes[f"b{i}"] = (4.2, 5.4, 1.5, 0.75 + i, 1.75 + i)
    scene = load_scene(floor_light_boxes_obj(tmp_path / "row.obj", 0.3, (5.0, 5.0), boxes))
    in_plane = np.flatnonzero((np.abs(np.abs(scene.face_normal[:, 0]) - 1) < 1e-12)
                              & (np.abs(np.abs(scene.face_offset) - 4.2) < 1e-9))
    assert len(in_plane) == 20
    o, d = np.array([[4.2, 0.5, 0.0]]), np.array([[0.0, 0.0, 1.0]])
    tri, _ = first_triangles(scene, o, d, 1e-9, 11.0, plane_face=in_plane[:1])
    assert tri[0] == -1
    tri, _ = first_triangles(scene, o, d, 1e-9, 11.0)
    assert tri[0] >= 0


def _first_triangles_loop(scene, o, d, tmin, tmax):
    """first_triangles' rule for rays in no pencil's plane, one ray at a time: cast; where
    the hit face's plane holds the ray (|n · d| and |n · o - offset| within GRAZE_COSINE
    and the weld tolerance), cast again from the weld tolerance beyond, at most
    MAX_GRAZED + 1 casts (the last hit kept)."""
    from viscx.skeleton.nodes import MAX_GRAZED
    from viscx.tolerances import GRAZE_COSINE

    tri, t = np.full(len(o), -1), np.full(len(o), np.inf)
    for i in range(len(o)):
        lo = tmin
        for _ in range(MAX_GRAZED + 1):
            h, th = scene.ray_caster.exact.first_hit(o[i:i + 1], d[i:i + 1], np.array([lo]), np.array([tmax]))
            tri[i], t[i] = h[0], th[0]
            if h[0] < 0:
                break
            f = scene.triangle_face[h[0]]
            n = scene.face_normal[f]
            if not (abs(np.einsum("ij,ij->i", n[None], d[i:i + 1])[0]) <= GRAZE_COSINE
                    and abs(np.einsum("ij,ij->i", n[None], o[i:i + 1])[0] - scene.face_offset[f]) <= scene.weld_tolerance):
                break
            lo = th[0] + scene.weld_tolerance
    return tri, t


def test_first_triangles_passes_grazed_faces_as_its_loop_definition():
    """first_triangles' kernel (rays in no pencil's plane: ``TriangleGrid.first_hit_off_planes``)
    against the rule cast by cast, bit for bit, on a furnished room (touching boxes: faces of
    one plane side by side): rays lying in the faces' planes (grazing, several in a row) and
    random rays."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from buildings import furnished_room

    from viscx.scene import build_scene
    from viscx.skeleton.nodes import first_triangles

    scene = build_scene(furnished_room(n_desks=2, n_cabinets=1, n_dividers=1, n_lights=1, seed=3))
    rng = np.random.default_rng(0)
    lo, hi = scene.vertices.min(axis=0), scene.vertices.max(axis=0)
    # rays in the planes of random faces: origin a random point of the face's plane in the box
    f = rng.integers(scene.n_faces, size=300)
    n = scene.face_normal[f]
    x = rng.uniform(lo, hi, size=(300, 3))
    x -= (np.einsum("ij,ij->i", n, x) - scene.face_offset[f])[:, None] * n
    d = np.cross(n, rng.normal(size=(300, 3)))
    o = np.concatenate([x, rng.uniform(lo, hi, size=(200, 3))])
    d = np.concatenate([d, rng.normal(size=(200, 3))])
    d /= np.linalg.norm(d, axis=1)[:, None]
    tri, t = first_triangles(scene, o, d, 1e-9, 50.0)
    ref_tri, ref_t = _first_triangles_loop(scene, o, d, 1e-9, 50.0)
    assert np.array_equal(tri, ref_tri) and np.array_equal(t, ref_t)
    # grazing happened: rays went on past a face of their plane
    grazed = np.flatnonzero(tri[:300] >= 0)
    assert np.any(scene.triangle_face[tri[:300][grazed]] != f[grazed])
