"""Scene model: welding, cleaning, coplanar merging, loops, half-edges, generators."""

import numpy as np
import pytest
from conftest import sample_scene_paths, soup

from viscx.errors import ViscxError
from viscx.scene import build_scene, load_scene


def check_half_edge_invariants(scene):
    he = scene.half_edges
    n = len(he.start)
    assert n == len(scene.loop_vertices)
    h = np.arange(n)
    has_opp = he.opp >= 0
    assert np.all(he.opp[he.opp[has_opp]] == h[has_opp]), "opp of opp"
    assert np.all(he.edge[he.opp[has_opp]] == he.edge[has_opp])
    assert np.all(he.start[he.next] == he.end), "next starts where h ends"
    assert np.all(he.face[he.next] == he.face), "next stays on the face"
    assert np.all(he.loop[he.next] == he.loop)
    # next cycles close after exactly the loop's length
    cyc = h.copy()
    steps = np.zeros(n, dtype=int)
    done = np.zeros(n, dtype=bool)
    for k in range(1, int(np.diff(scene.loop_offsets).max()) + 1):
        cyc = he.next[cyc]
        back = (cyc == h) & ~done
        steps[back] = k
        done |= back
    assert np.all(done) and np.all(steps == np.diff(scene.loop_offsets)[he.loop]), "next cycles close"
    assert np.all((he.face >= 0) & (he.face < scene.n_faces)), "every half-edge has a face"
    # every face has at least one loop, and its first loop is counter-clockwise about its normal
    assert np.all(np.diff(scene.face_loop_offsets) >= 1)
    for f in range(scene.n_faces):
        loops = scene.face_loops(f)
        signed = [np.cross(p, np.roll(p, -1, 0)).sum(0) @ scene.face_normal[f] / 2 for p in loops]
        assert signed[0] > 0 and all(s < 0 for s in signed[1:])
        assert np.isclose(sum(signed), scene.face_area[f], rtol=1e-9), "loops enclose the face's area"
    # undirected edges are sorted and canonical
    ev = he.edge_vertices
    assert np.all(ev[:, 0] < ev[:, 1])
    assert np.all(np.diff(ev[:, 0] * scene.n_vertices + ev[:, 1]) > 0)
    assert np.all(np.sort(np.stack([he.start, he.end], 1), 1) == ev[he.edge])
    # generator vertices are exactly the endpoints of generator edges
    expected = np.zeros(scene.n_vertices, dtype=bool)
    expected[ev[he.edge_is_generator].ravel()] = True
    assert np.array_equal(expected, he.vertex_is_generator)


QUAD = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]


def test_triangulated_quad_is_one_face_and_diagonal_is_no_generator():
    scene = build_scene(soup(QUAD, [[0, 1, 2], [0, 2, 3]]))
    assert scene.n_faces == 1
    assert len(scene.half_edges.edge_vertices) == 4  # the diagonal is gone
    assert scene.half_edges.edge_is_generator.all()  # the 4 boundary edges
    assert np.isclose(scene.face_area[0], 1.0)
    check_half_edge_invariants(scene)


def test_welding_within_tolerance_merges_and_beyond_does_not():
    close = QUAD + [[1 + 1e-12, 1, 0], [0, 1e-12, 0]]
    scene = build_scene(soup(close, [[0, 1, 2], [5, 4, 3]]))
    assert scene.n_vertices == 4 and scene.n_faces == 1
    far = QUAD + [[1 + 1e-3, 1, 0], [0, 1e-3, 0]]
    scene = build_scene(soup(far, [[0, 1, 2], [5, 4, 3]]))
    assert scene.n_vertices == 6 and scene.n_faces == 2


def test_degenerate_and_duplicate_triangles_are_dropped():
    verts = QUAD + [[2, 0, 0], [3, 0, 0], [2, 1e-12, 0]]
    polys = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [0, 2, 1], [1, 4, 5]]  # sliver, reversed duplicate, collinear
    scene = build_scene(soup(verts, polys))
    assert scene.n_faces == 1 and len(scene.triangles) == 2
    with pytest.raises(ViscxError, match="degenerate"):
        build_scene(soup(verts, [[4, 5, 6], [1, 4, 5]]))


def test_coplanar_faces_of_different_groups_stay_apart_and_their_edge_is_flat():
    scene = build_scene(soup(QUAD, [[0, 1, 2], [0, 2, 3]], groups=[0, 1], names=["a", "b"]))
    assert scene.n_faces == 2
    he = scene.half_edges
    diagonal = np.flatnonzero((he.edge_vertices == [0, 2]).all(1))
    assert len(diagonal) == 1 and not he.edge_is_generator[diagonal[0]]
    check_half_edge_invariants(scene)


def test_inconsistent_winding_is_not_merged_but_flat():
    scene = build_scene(soup(QUAD, [[0, 1, 2], [0, 3, 2]]))
    assert scene.n_faces == 2
    assert scene.half_edges.edge_is_generator.sum() == 4


def cube(offset=(0, 0, 0), size=1.0):
    v = (np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]) * size + offset).tolist()
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    tris = [t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])]
    return v, tris


def test_closed_cube():
    v, tris = cube()
    scene = build_scene(soup(v, tris))
    he = scene.half_edges
    assert scene.n_faces == 6 and len(he.edge_vertices) == 12
    assert np.all(he.opp >= 0) and np.all(he.start[he.opp] == he.end)
    assert he.edge_is_generator.all() and he.vertex_is_generator.all()
    assert np.allclose(scene.face_area, 1.0)
    check_half_edge_invariants(scene)


def grid_squares(cells):
    """Triangulated unit squares at integer cells (i, j) in the z=0 plane."""
    verts, index, tris = [], {}, []

    def vid(p):
        if p not in index:
            index[p] = len(verts)
            verts.append([p[0], p[1], 0.0])
        return index[p]

    for i, j in cells:
        a, b, c, d = vid((i, j)), vid((i + 1, j)), vid((i + 1, j + 1)), vid((i, j + 1))
        tris += [[a, b, c], [a, c, d]]
    return verts, tris


def test_face_with_a_hole():
    cells = [(i, j) for i in range(4) for j in range(4) if not (1 <= i <= 2 and 1 <= j <= 2)]
    scene = build_scene(soup(*grid_squares(cells)))
    assert scene.n_faces == 1
    loops = scene.face_loops(0)
    assert len(loops) == 2
    # collinear grid vertices are dropped: both loops are plain squares
    assert [len(p) for p in loops] == [4, 4]
    assert np.isclose(scene.face_area[0], 12.0)
    check_half_edge_invariants(scene)


def test_pinch_vertex_keeps_each_wedge_on_its_own_side():
    # a ring of 7 squares whose hole touches the outside at the vertex (2, 1)
    cells = [(i, j) for i in range(3) for j in range(3) if (i, j) not in [(1, 1), (2, 0)]]
    scene = build_scene(soup(*grid_squares(cells)))
    assert scene.n_faces == 1
    check_half_edge_invariants(scene)
    loop = scene.loop_vertices
    pinch = [k for k, p in enumerate(scene.vertices) if tuple(p) == (2.0, 1.0, 0.0)][0]
    assert np.count_nonzero(loop == pinch) == 2  # the boundary passes the pinch twice


def test_collinear_vertex_is_dropped_unless_a_third_face_uses_it():
    # an L-fold along x, the shared edge split at (1, 0, 0)
    verts = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [0, 0, -1], [2, 0, -1]]
    flat = [0, 1, 2, 3, 4]
    down = [2, 1, 0, 5, 6]
    def on_loops(scene, point):
        return np.any(np.all(scene.vertices[scene.loop_vertices] == point, axis=1))

    scene = build_scene(soup(verts, [flat, down]))
    assert scene.n_faces == 2 and not on_loops(scene, [1, 0, 0])
    assert len(scene.half_edges.edge_vertices) == 7
    check_half_edge_invariants(scene)
    # a fin standing on (1, 0, 0) keeps it
    verts2 = verts + [[1, 1, 1], [1, -1, 1]]
    scene = build_scene(soup(verts2, [flat, down, [1, 7, 8]]))
    assert on_loops(scene, [1, 0, 0])
    check_half_edge_invariants(scene)


def test_non_manifold_edge_has_no_opp_and_is_a_generator():
    verts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0.2], [0, 0.2, 1]]
    scene = build_scene(soup(verts, [[0, 1, 2], [1, 0, 3], [0, 1, 4]]))
    he = scene.half_edges
    shared = np.flatnonzero((he.edge_vertices == [0, 1]).all(1))[0]
    assert np.all(he.opp[he.edge == shared] == -1)
    assert he.edge_is_generator[shared]
    check_half_edge_invariants(scene)


def test_non_convex_polygon_survives_triangulation_and_merge():
    # a U-shaped (notched) wall, one polygon
    u = [[0, 0, 0], [1, 0, 0], [1, 2, 0], [2, 2, 0], [2, 0, 0], [3, 0, 0], [3, 3, 0], [0, 3, 0]]
    scene = build_scene(soup(u, [list(range(8))]))
    assert scene.n_faces == 1
    assert sorted(scene.loop_vertices.tolist()) == list(range(8))
    assert np.isclose(scene.face_area[0], 9 - 2)
    check_half_edge_invariants(scene)


def test_same_input_same_ids():
    v, tris = cube()
    a = build_scene(soup(v, tris))
    b = build_scene(soup(v, tris))
    for name in ("vertices", "triangles", "triangle_face", "loop_vertices", "face_normal"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert np.array_equal(a.half_edges.opp, b.half_edges.opp)


@pytest.mark.parametrize("path", sample_scene_paths(), ids=lambda p: p.name)
def test_sample_scenes_are_clean(path):
    scene = load_scene(path)
    assert scene.n_faces > 0
    check_half_edge_invariants(scene)
    # every triangle lies in its face's plane
    height = np.einsum("tkj,tj->tk", scene.vertices[scene.triangles], scene.face_normal[scene.triangle_face])
    assert np.all(np.abs(height - scene.face_offset[scene.triangle_face][:, None]) <= scene.weld_tolerance * 1.01)
    # (the loops enclose each face's triangle area: checked in check_half_edge_invariants)


# -- configurations from review (each broke an earlier version) ----------------------------


def test_keyhole_polygon_is_a_face_with_a_hole():
    V = [[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0], [1, 1, 0], [1, 3, 0], [3, 3, 0], [3, 1, 0]]
    scene = build_scene(soup(V, [[0, 1, 2, 3, 0, 4, 5, 6, 7, 4]]))
    assert scene.n_faces == 1 and np.isclose(scene.face_area[0], 12.0)
    assert [len(p) for p in scene.face_loops(0)] == [4, 4]
    check_half_edge_invariants(scene)


@pytest.mark.parametrize("offset", [0.0, 1e8, 1e10, 1e12])
def test_a_planar_quad_far_from_the_origin_is_one_face(offset):
    quad = np.array([[0, 0, 0], [1, 0, 2], [1, 1, 5], [0, 1, 3.0]]) + offset  # plane z = 2x + 3y + c
    scene = build_scene(soup(quad, [[0, 1, 2], [0, 2, 3]]))
    assert scene.n_faces == 1 and len(scene.half_edges.edge_vertices) == 4


def test_a_gentle_arc_keeps_the_vertices_that_shape_it():
    n, sag = 1000, 0.01
    x = np.linspace(0, 1, n + 1)
    arc = np.stack([x, -sag * np.sin(np.pi * x), 0 * x], 1)
    scene = build_scene(soup(np.concatenate([arc, [[1, 1, 0], [0, 1, 0]]]), [list(range(n + 1)) + [n + 1, n + 2]]))
    loop = scene.face_loops(0)[0]
    enclosed = np.cross(loop, np.roll(loop, -1, 0)).sum(0) @ scene.face_normal[0] / 2
    perimeter = np.linalg.norm(np.roll(loop, -1, 0) - loop, axis=1).sum()
    # every dropped vertex is within tolerance of the loop: areas agree to tolerance × perimeter
    assert abs(enclosed - scene.face_area[0]) <= scene.weld_tolerance * perimeter
    assert len(loop) < n / 2  # and straight runs were simplified


def test_collinear_decisions_agree_between_neighbouring_loops():
    h = 2e-7  # a sliver thinner than the weld tolerance next to a fat face
    V = [[0, 0, 0], [1, -h, 0], [2, 0, 0], [1, h, 0], [0, -1, 0], [2, -1, 0]]
    polys = [[4, 5, 1], [4, 1, 0], [5, 2, 1], [1, 2, 3], [1, 3, 0]]
    scene = build_scene(soup(V, polys, groups=[0, 0, 0, 1, 1], names=["big", "sliver"]))
    check_half_edge_invariants(scene)
    he = scene.half_edges
    # every edge between the two faces is shared: none became a lone boundary
    shared = (he.opp >= 0).sum()
    assert shared >= 2 and np.all(he.face[he.opp[he.opp >= 0]] != he.face[he.opp >= 0])


def test_a_shallow_fold_is_a_generator_when_its_faces_do_not_merge():
    a = 1e-5
    V = [[0, 0, 0], [0, 1, 0], [1, 0.5, 0], [-1, 0.5, np.tan(a)]]
    scene = build_scene(soup(V, [[0, 2, 1], [0, 1, 3]]))
    assert scene.n_faces == 2
    edge = np.flatnonzero((scene.half_edges.edge_vertices == [0, 1]).all(1))[0]
    assert scene.half_edges.edge_is_generator[edge]
