"""V2 V-cells: every vertex's cells checked against the ray caster at random directions,
solid angles, twins, the seed's projected turning angles (§5.3), holes (seed Fig. 3a),
the measured V1 gaps of the degenerate samples, HDF5, determinism and the plot command."""

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from conftest import SAMPLES, soup
from random_scenes import general_position_scene

from viscx.scene import build_scene, load_scene
from viscx.skeleton.arcs import build_arcs
from viscx.skeleton.candidates import build_nodes
from viscx.skeleton.nodes import BLOCK_FACE, BLOCK_SKY, BLOCK_VERTEX, vertex_ray_blockers
from viscx.skeleton.vcells import FOUR_PI, TURNING_DECIMALS, build_vcells, locate, stored_elements

GENERAL = ["two_triangles.obj", "occluder_over_plane.ply", "tetrahedra.obj"]
DEGENERATE = ["boxes_on_floor.obj", "cornell_box.obj", "room_with_door.obj"]
#: Random directions per vertex for the ray oracle.
DIRECTIONS = 10_000
#: Directions closer than this (radians) to a cell boundary are not judged: the ray caster
#: and the half-cells' probes decide them within rounding.
BAND = 1e-4
#: Required agreement with the ray caster outside the band.
AGREEMENT = 0.999

_CACHE = {}


def built(name):
    """(scene, arcs, vcells) of a sample scene, a random scene ("rand:seed") or a scene object."""
    if name not in _CACHE:
        scene = general_position_scene(int(name.split(":")[1])) if name.startswith("rand:") else load_scene(SAMPLES / name)
        arcs = build_arcs(scene, build_nodes(scene))
        _CACHE[name] = scene, arcs, build_vcells(scene, arcs)
    return _CACHE[name]


def build_all(scene):
    arcs = build_arcs(scene, build_nodes(scene))
    return arcs, build_vcells(scene, arcs)


def uniform_directions(rng, n):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def angular_distance_to_arcs(d, starts, ends):
    """Angle from each direction (n, 3) to the nearest of the minor great-circle arcs
    starts[k] -> ends[k] ((m, 3) each), computed directly (not with the builder's code)."""
    if len(starts) == 0:
        return np.full(len(d), np.inf)
    normal = np.cross(starts, ends)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    h = d @ normal.T  # (n, m): sine of the angle to each arc's great circle
    # the foot of d on the great circle lies between the ends iff d is on the inner side of
    # the planes through (normal, start) and (end, normal)
    inside = (d @ np.cross(normal, starts).T >= 0) & (d @ np.cross(ends, normal).T >= 0)
    # the nearest point is the one of largest cosine: cos(arcsin |h|) = sqrt(1 - h^2) to
    # the foot, d . p to an end; one arccos per direction, not one per (direction, arc)
    near = np.where(inside, np.sqrt(np.maximum(1.0 - h * h, 0.0)), -1.0).max(axis=1)
    for p in (starts, ends):
        near = np.maximum(near, (d @ p.T).max(axis=1))
    return np.arccos(np.clip(near, -1.0, 1.0))


def near_arcs(d, starts, ends, band, chunk=1 << 21):
    """Whether each direction ((n, 3) unit) lies within ``band`` radians of one of the minor
    great-circle arcs starts[k] -> ends[k]: :func:`angular_distance_to_arcs` <= band,
    evaluated only for the directions whose z can be that near. A minor arc lies in the
    ball of radius |end - start| / 2 around its chord's midpoint (its farthest points from
    there are its ends), and a direction within band radians of it lies within band of it
    in space: directions with z outside that ball's z-range widened by band are farther."""
    near = np.zeros(len(d), bool)
    order = np.argsort(d[:, 2])
    z = d[order, 2]
    mid, reach = (starts[:, 2] + ends[:, 2]) / 2, np.linalg.norm(ends - starts, axis=1) / 2 + band
    lo, hi = np.searchsorted(z, mid - reach, "left"), np.searchsorted(z, mid + reach, "right")
    count = hi - lo
    if count.sum() > len(d) * len(starts) / 10:  # long arcs (the samples' big faces): all pairs at once, as fast
        return np.concatenate([angular_distance_to_arcs(d[k:k + 2000], starts, ends) for k in range(0, len(d), 2000)]) <= band
    total = np.concatenate([[0], np.cumsum(count)])
    first = 0
    while first < len(count):  # arcs in runs of at most `chunk` (direction, arc) pairs
        last = max(first + 1, int(np.searchsorted(total, total[first] + chunk, "right")) - 1)
        c = count[first:last]
        arc = np.repeat(np.arange(first, last), c)
        k = order[np.arange(c.sum()) - np.repeat(np.cumsum(c) - c - lo[first:last], c)]
        cos = angular_distance_to_arcs_pairs(d[k], starts[arc], ends[arc])
        near[k[cos >= np.cos(band)]] = True
        first = last
    return near


def angular_distance_to_arcs_pairs(d, starts, ends):
    """:func:`angular_distance_to_arcs`'s cosine, direction d[i] to arc i only ((p, 3) each)."""
    normal = np.cross(starts, ends)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    h = np.sum(d * normal, axis=1)
    inside = (np.sum(d * np.cross(normal, starts), axis=1) >= 0) & (np.sum(d * np.cross(ends, normal), axis=1) >= 0)
    near = np.where(inside, np.sqrt(np.maximum(1.0 - h * h, 0.0)), -1.0)
    return np.maximum(near, np.maximum(np.sum(d * starts, axis=1), np.sum(d * ends, axis=1)))


def vertex_boundaries(scene, arcs, vc, v):
    """Start and end directions of every boundary element of vertex v (loops and open chains)."""
    cells = np.flatnonzero(vc.vertex == v)
    parts = []
    for c in cells:
        lo, hi = vc.element_offsets[vc.loop_offsets[c]], vc.element_offsets[vc.loop_offsets[c + 1]]
        parts.append((vc.element[lo:hi], vc.antipodal[lo:hi]))
    for c in np.flatnonzero(vc.open_vertex == v):
        lo, hi = vc.open_offsets[c], vc.open_offsets[c + 1]
        parts.append((vc.open_element[lo:hi], vc.open_antipodal[lo:hi]))
    signed = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
    anti = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0, bool)
    el = stored_elements(scene, arcs, signed, anti)
    return el.start, el.end


def pair_name(kind, index):
    return {BLOCK_FACE: f"face {index}", BLOCK_SKY: "sky", BLOCK_VERTEX: f"vertex {index}"}[int(kind)]


def ray_oracle(scene, arcs, vc, vertices, n=DIRECTIONS, seed=0, memo=None):
    """Locate random directions of each vertex among its cells and compare the cell's
    blocker pair with the ray caster's (:func:`vertex_ray_blockers`, the judging rule of
    maximal_free_segments at one vertex). ``memo`` (a dict) keeps, per vertex and its
    directions, the caster's pairs and the band around the boundaries for a later call on
    the same cells (only the location is redone).

    Returns
    -------
    judged, agreed : int
        Directions judged (outside the band, not grazing a face at the vertex) and agreeing.
    disagreements : list of str
        Each disagreement with its vertex, direction, the cell's pair and the caster's.
    """
    rng = np.random.default_rng(seed)
    judged = agreed = 0
    disagreements = []
    for v in vertices:
        d = uniform_directions(rng, n)
        key = (v, d.tobytes())
        if memo is None or key not in memo:
            up_kind, up, down_kind, down, grazing = vertex_ray_blockers(scene, np.full(n, v), d)
            starts, ends = vertex_boundaries(scene, arcs, vc, v)
            away = ~near_arcs(d, starts, ends, BAND)
            if memo is not None:
                memo[key] = up_kind, up, down_kind, down, grazing, away
        else:
            up_kind, up, down_kind, down, grazing, away = memo[key]
        cell, holders = locate(scene, arcs, vc, v, d)
        c = np.maximum(cell, 0)
        agree = (cell >= 0) & (vc.up_kind[c] == up_kind) & (vc.up[c] == up) & (vc.down_kind[c] == down_kind) & (vc.down[c] == down)
        judge = away & ~grazing
        judged += int(judge.sum())
        agreed += int((agree & judge).sum())
        for i in np.flatnonzero(judge & ~agree)[:5]:
            where = (f"cell {cell[i]} ({pair_name(vc.up_kind[c[i]], vc.up[c[i]])} -> {pair_name(vc.down_kind[c[i]], vc.down[c[i]])})"
                     if cell[i] >= 0 else f"{holders[i]} cells")
            disagreements.append(f"vertex {v} direction {np.round(d[i], 6).tolist()}: {where}, rays: "
                                 f"{pair_name(up_kind[i], up[i])} -> {pair_name(down_kind[i], down[i])}")
    return judged, agreed, disagreements


def assert_oracle(scene, arcs, vc, vertices, seed=0):
    judged, agreed, wrong = ray_oracle(scene, arcs, vc, vertices, seed=seed)
    assert judged >= 0.99 * DIRECTIONS * len(vertices)
    assert agreed >= AGREEMENT * judged, (
        f"{judged - agreed} of {judged} directions disagree with the ray caster "
        f"({agreed / judged:.5f}); e.g.:\n" + "\n".join(wrong[:20]))
    return judged, agreed


def complete_vertices(vc):
    return np.unique(vc.vertex[vc.complete])


def per_vertex_solid_angle(vc, n_vertices):
    return np.bincount(vc.vertex, weights=vc.solid_angle, minlength=n_vertices)


# ---------------------------------------------------------------------------------------
# ray oracle


@pytest.mark.parametrize("name", GENERAL)
def test_ray_oracle_on_every_vertex(name):
    """General position: every vertex's cells close, tile its sphere and carry the blocker
    pair the ray caster finds at 10^4 random directions."""
    scene, arcs, vc = built(name)
    gv = scene.generator_vertices
    assert len(vc.open_vertex) == 0 and np.all(vc.complete)
    assert set(vc.vertex.tolist()) == set(gv.tolist())
    assert_oracle(scene, arcs, vc, gv)


@pytest.mark.parametrize("name", DEGENERATE)
def test_ray_oracle_on_complete_vertices_of_degenerate_samples(name):
    """Degenerate samples: the vertices whose loops all close (``complete``, all of them
    now: test below) pass the ray oracle; a few of them here, all with -m slow."""
    scene, arcs, vc = built(name)
    assert_oracle(scene, arcs, vc, complete_vertices(vc)[:3])


@pytest.mark.slow
@pytest.mark.parametrize("name", DEGENERATE)
def test_ray_oracle_on_all_complete_vertices_of_degenerate_samples(name):
    scene, arcs, vc = built(name)
    assert_oracle(scene, arcs, vc, complete_vertices(vc))


@pytest.mark.slow
@pytest.mark.parametrize("name", DEGENERATE)
def test_ray_oracle_on_every_vertex_of_degenerate_samples(name):
    scene, arcs, vc = built(name)
    assert_oracle(scene, arcs, vc, scene.generator_vertices)


#: Measured on the degenerate samples (docs/skeleton.md, "V-cells"): vertices whose loops
#: all close, generator vertices, open chains (before junctions, same-plane families and
#: half-cells in every sample: 6/18/8 complete, 167/56/144 open). A change means V1
#: changed: update the docs.
MEASURED_GAPS = {
    "boxes_on_floor.obj": (28, 28, 0),
    "cornell_box.obj": (28, 28, 0),
    "room_with_door.obj": (20, 20, 0),
}


@pytest.mark.parametrize("name", DEGENERATE)
def test_measured_gaps_of_degenerate_samples(name):
    scene, _, vc = built(name)
    assert (len(complete_vertices(vc)), len(scene.generator_vertices), len(vc.open_vertex)) == MEASURED_GAPS[name]


def check_random_scene(seed, directions_seed=0):
    name = f"rand:{seed}"
    scene, arcs, vc = built(name)
    done = complete_vertices(vc)
    # where V1 closes every loop the cells tile the sphere and agree with the caster
    assert np.allclose(per_vertex_solid_angle(vc, scene.n_vertices)[done], FOUR_PI, atol=1e-6)
    if len(done):
        assert_oracle(scene, arcs, vc, done, seed=directions_seed)
    return len(done), len(scene.generator_vertices)


@pytest.mark.parametrize("seed", range(8))
def test_random_scenes(seed):
    check_random_scene(seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(8, 20))
def test_random_scenes_more(seed):
    """Random scenes 8-19 (0-7 run by default; these 12 are ~9 s of make test's summed time)."""
    check_random_scene(seed)


@pytest.mark.parametrize("seed", [19, 161])
def test_random_scenes_with_thin_cells_close(seed):
    """The two random scenes that left open chains (8 in all): rand:19, where a half-cell
    probe 1e-8 rad off a face's plane and 2e-6 rad from an edge of its vertex's fan was
    judged tangent (a false gap between two faces of a closed fan, tangency.py), and
    rand:161, where a face seen 2e-4 off edge-on makes a sliver cell narrower than the
    probe angle near its corners (V1 now joins VE arcs across such unexplained half-cell
    changes, viscx.skeleton.arcs.stages). Every vertex closes and agrees with the ray caster."""
    scene, arcs, vc = built(f"rand:{seed}")
    assert len(vc.open_vertex) == 0 and np.all(vc.complete)
    assert set(vc.vertex.tolist()) == set(scene.generator_vertices.tolist())
    assert np.allclose(per_vertex_solid_angle(vc, scene.n_vertices)[scene.generator_vertices], FOUR_PI, atol=1e-6)
    assert_oracle(scene, arcs, vc, scene.generator_vertices)


@pytest.mark.slow
@pytest.mark.parametrize("block", range(10))
def test_many_random_scenes(block):
    """100 more random scenes (10 per test); at least 90 % of their vertices complete."""
    done = total = 0
    for seed in range(100 + 10 * block, 110 + 10 * block):
        d, t = check_random_scene(seed)
        done, total = done + d, total + t
    assert done >= 0.9 * total, f"only {done} of {total} vertices have closed loops"


def test_most_random_vertices_are_complete():
    """The default random scenes: V1's known gaps (tangency near a vertex's edges, see
    docs/skeleton.md "V-cells") leave few vertices open."""
    done = total = 0
    for seed in range(20):
        scene, _, vc = built(f"rand:{seed}")
        done += len(complete_vertices(vc))
        total += len(scene.generator_vertices)
    assert done >= 0.9 * total, f"only {done} of {total} vertices have closed loops"


# ---------------------------------------------------------------------------------------
# solid angles, twins, loops


@pytest.mark.parametrize("name", GENERAL + ["rand:1", "rand:2"])
def test_cells_cover_the_sphere(name):
    """Σ solid angles = 4π at every vertex; every cell has a solid angle in (0, 4π) and its
    loop of largest turning sum first (its outer loop; sums equal to TURNING_DECIMALS tie)."""
    scene, _, vc = built(name)
    total = per_vertex_solid_angle(vc, scene.n_vertices)
    assert np.allclose(total[np.unique(vc.vertex)], FOUR_PI, atol=1e-6)
    assert np.all(vc.solid_angle > 0) and np.all(vc.solid_angle < FOUR_PI + 1e-9)
    for c in range(len(vc)):
        loops = np.round(vc.turning[vc.loop_offsets[c]: vc.loop_offsets[c + 1]], TURNING_DECIMALS)
        assert loops[0] == loops.max()


@pytest.mark.parametrize("name", GENERAL + ["rand:1", "rand:2"])
def test_twins(name):
    """A cell whose up is not the vertex has an antipodal twin: the same segments seen from
    the other end (pair swapped, same solid angle, same half-cells on the other image);
    cells whose up is the vertex have none. Checked by the ray caster at the antipode too."""
    scene, arcs, vc = built(name)
    tangent = vc.up_kind != BLOCK_VERTEX
    assert np.all((vc.twin >= 0) == tangent)
    t = np.flatnonzero(tangent)
    tw = vc.twin[t]
    assert np.array_equal(vc.twin[tw], t)
    assert np.array_equal(vc.up[tw], vc.down[t]) and np.array_equal(vc.down[tw], vc.up[t])
    assert np.array_equal(vc.up_kind[tw], vc.down_kind[t]) and np.array_equal(vc.down_kind[tw], vc.up_kind[t])
    assert np.allclose(vc.solid_angle[tw], vc.solid_angle[t], rtol=1e-9, atol=1e-12)
    assert np.array_equal(vc.vertex[tw], vc.vertex[t])
    for c in t:
        assert elements_of(vc, c) == {(e, not a) for e, a in elements_of(vc, vc.twin[c])}


def elements_of(vc, c):
    lo, hi = vc.element_offsets[vc.loop_offsets[c]], vc.element_offsets[vc.loop_offsets[c + 1]]
    return {(int(e), bool(a)) for e, a in zip(vc.element[lo:hi], vc.antipodal[lo:hi])}


def test_twins_are_antipodal_by_the_caster():
    scene, arcs, vc = built("tetrahedra.obj")
    rng = np.random.default_rng(3)
    for v in scene.generator_vertices[:4]:
        d = uniform_directions(rng, 2000)
        here, _ = locate(scene, arcs, vc, v, d)
        there, _ = locate(scene, arcs, vc, v, -d)
        ok = (here >= 0) & (there >= 0) & (vc.up_kind[np.maximum(here, 0)] != BLOCK_VERTEX)
        assert ok.sum() > 1000
        assert np.array_equal(vc.twin[here[ok]], there[ok])


@pytest.mark.parametrize("name", GENERAL + ["rand:1", "rand:2"])
def test_projected_turning_angles(name):
    """The seed's classification (§5.3): project each loop of a cell with a face blocker
    through the vertex onto that face's plane (great-circle arcs become segments); seen
    from beyond the plane the outer loop turns by +2π and each hole by -2π (down face; the
    antipodal up face mirrors the signs)."""
    scene, arcs, vc = built(name)
    checked = 0
    for c in range(len(vc)):
        if vc.down_kind[c] == BLOCK_FACE:
            face, sign = vc.down[c], 1.0
        elif vc.up_kind[c] == BLOCK_FACE:
            face, sign = vc.up[c], -1.0
        else:
            continue
        x = scene.vertices[vc.vertex[c]]
        n, off = scene.face_normal[face], scene.face_offset[face]
        away = n if off - n @ x > 0 else -n  # plane normal pointing away from the vertex
        e1 = np.cross(away, [1.0, 0, 0] if abs(away[0]) < 0.9 else [0, 1.0, 0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(away, e1)
        for j in range(vc.loop_offsets[c], vc.loop_offsets[c + 1]):
            lo, hi = vc.element_offsets[j], vc.element_offsets[j + 1]
            d = sign * stored_elements(scene, arcs, vc.element[lo:hi], vc.antipodal[lo:hi]).start
            t = (off - n @ x) / (d @ n)
            assert np.all(t > 0), "a loop of a cell blocked by a face leaves that face's side"
            p = (x + t[:, None] * d) @ np.stack([e1, e2], axis=1)
            edge = np.roll(p, -1, axis=0) - p
            edge = edge[np.linalg.norm(edge, axis=1) > 1e-12 * np.abs(p).max()]
            nxt = np.roll(edge, -1, axis=0)
            total = np.sum(np.arctan2(edge[:, 0] * nxt[:, 1] - edge[:, 1] * nxt[:, 0], np.einsum("ij,ij->i", edge, nxt)))
            expected = 2 * np.pi if j == vc.loop_offsets[c] else -2 * np.pi
            assert total == pytest.approx(sign * expected, abs=1e-6), (c, j)
            checked += 1
    assert checked > 0


# ---------------------------------------------------------------------------------------
# holes (seed Fig. 3a, Fig. 8)


def triangle_solid_angle(x, tri):
    """Solid angle of a triangle ((3, 3) float) seen from x (Van Oosterom and Strackee)."""
    a, b, c = tri - x
    la, lb, lc = (np.linalg.norm(w) for w in (a, b, c))
    num = abs(a @ np.cross(b, c))
    den = la * lb * lc + (a @ b) * lc + (a @ c) * lb + (b @ c) * la
    return 2 * np.arctan2(num, den)


def test_small_occluder_inside_a_big_blocker_makes_a_hole():
    """From vertex v, a small triangle S projects inside a big triangle B: the cell
    (sky -> B) has one hole whose loop runs along S's edges, and the solid angles equal
    the triangles' (independent formula): Ω(sky -> S) = Ω(S), Ω(sky -> B) = Ω(B) - Ω(S)."""
    big = [[-10.0, -10.0, 0.0], [10.0, -10.0, 0.0], [0.0, 10.0, 0.0]]
    small = [[-0.5, -0.5, 1.0], [0.5, -0.4, 1.1], [0.1, 0.5, 0.9]]
    viewer = [[0.05, 0.02, 3.0], [1.0, 0.3, 5.0], [-0.4, 1.0, 5.2]]
    scene = build_scene(soup(big + small + viewer, [[0, 1, 2], [3, 4, 5], [6, 7, 8]], [0, 1, 2]))
    arcs, vc = build_all(scene)
    v = int(np.flatnonzero(np.all(scene.vertices == viewer[0], axis=1))[0])
    face_of = {g: int(np.flatnonzero(scene.face_group == g)[0]) for g in range(3)}
    b, s = face_of[0], face_of[1]
    mine = vc.vertex == v
    on_b = np.flatnonzero(mine & (vc.down_kind == BLOCK_FACE) & (vc.down == b))
    on_s = np.flatnonzero(mine & (vc.down_kind == BLOCK_FACE) & (vc.down == s))
    assert len(on_b) == 1 and len(on_s) == 1
    cb, cs = on_b[0], on_s[0]
    assert vc.up_kind[cb] == BLOCK_SKY and vc.up_kind[cs] == BLOCK_SKY
    assert vc.loop_offsets[cb + 1] - vc.loop_offsets[cb] == 2  # an outer loop and one hole
    hole = vc.loop_offsets[cb] + 1
    lo, hi = vc.element_offsets[hole], vc.element_offsets[hole + 1]
    edges = scene.half_edges.edge_vertices[arcs.half_cells.edge[np.abs(vc.element[lo:hi]) - 1]]
    small_vertices = set(np.flatnonzero(scene.face_group[scene.half_edges.face] == 1).tolist())
    s_ids = {int(i) for i in np.unique(scene.half_edges.start[list(small_vertices)])}
    assert set(edges.reshape(-1).tolist()) <= s_ids
    x = scene.vertices[v]
    assert vc.solid_angle[cs] == pytest.approx(triangle_solid_angle(x, np.array(small)), rel=1e-9)
    assert vc.solid_angle[cb] == pytest.approx(triangle_solid_angle(x, np.array(big)) - triangle_solid_angle(x, np.array(small)), rel=1e-9)
    assert_oracle(scene, arcs, vc, [v])


def test_a_lone_polygon_is_one_cell_per_corner():
    """Nothing on a lone triangle's corner spheres changes the pair: one loop-less cell of
    4π each, sky both ways, its own twin."""
    scene = build_scene(soup([[0, 0, 0], [1, 0, 0], [0.2, 1, 0.1]], [[0, 1, 2]]))
    arcs, vc = build_all(scene)
    assert len(vc) == 3 and np.all(np.diff(vc.loop_offsets) == 0) and np.all(vc.complete)
    assert np.allclose(vc.solid_angle, FOUR_PI) and np.array_equal(vc.twin, np.arange(3))
    assert np.all((vc.up_kind == BLOCK_SKY) & (vc.down_kind == BLOCK_SKY))
    assert_oracle(scene, arcs, vc, scene.generator_vertices)


def test_sample_with_holes():
    """occluder_over_plane (the samples' Fig. 8 scene): from each floor corner the small
    triangle's cell is a hole in the sky cell above the floor."""
    scene, _, vc = built("occluder_over_plane.ply")
    holes = np.diff(vc.loop_offsets) - 1
    assert holes.sum() >= 4
    assert np.all(vc.up_kind[holes > 0] != BLOCK_VERTEX)


# ---------------------------------------------------------------------------------------
# HDF5, determinism, CLI


def test_hdf5_round_trip(tmp_path):
    from oracles import assert_cells_round_trip

    from viscx.formats.hdf5 import read_vcells, write_vcells

    scene, _, vc = built("boxes_on_floor.obj")  # has open chains too
    assert_cells_round_trip(tmp_path, scene, vc, write_vcells, read_vcells, lambda h5: h5["V2"])


def test_damaged_v2_is_refused(tmp_path):
    from viscx.errors import ViscxError
    from viscx.formats.hdf5 import read_vcells, write_vcells

    _, _, vc = built("two_triangles.obj")
    with h5py.File(tmp_path / "x.h5", "w") as f:
        write_vcells(f.create_group("V2"), vc)
        del f["V2/twin"]
        with pytest.raises(ViscxError, match="missing"):
            read_vcells(f["V2"])
        del f["V2"]
        write_vcells(f.create_group("V2"), vc)
        del f["V2/loop_offsets"]
        f["V2/loop_offsets"] = np.zeros(len(vc) + 1, np.int64)
        with pytest.raises(ViscxError, match="CSR"):
            read_vcells(f["V2"])


def test_v2_bytes_are_deterministic(tmp_path):
    """Two builds (one from a fresh scene object) write identical V2 datasets."""
    from viscx.pipeline import build_file

    paths = [tmp_path / "a.h5", tmp_path / "b.h5"]
    for p in paths:
        build_file(SAMPLES / "cornell_box.obj", p, quiet=True)
    raw = []
    for p in paths:
        with h5py.File(p, "r") as f:
            found = {}
            f["V2"].visititems(lambda name, obj: found.__setitem__(name, obj[()].tobytes()) if isinstance(obj, h5py.Dataset) else None)
            raw.append(found)
    assert raw[0] == raw[1] and len(raw[0]) >= 20


def run(argv, capsys):
    from viscx.cli import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def test_plot_vcells(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    h5 = tmp_path / "t.h5"
    assert run(["--quiet", "build", str(SAMPLES / "tetrahedra.obj"), "-o", str(h5)], capsys)[0] == 0
    png = tmp_path / "v0.png"
    code, out, err = run(["plot", "vcells", str(h5), "--vertex", "0", "-o", str(png), "--size", "60"], capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "V-cells of vertex 0" in out


@pytest.mark.parametrize("args, message", [
    (["--vertex", "99"], "not a generator vertex"),
    (["--vertex", "-1"], "not a generator vertex"),
])
def test_plot_vcells_bad_vertex(args, message, tmp_path, capsys):
    h5 = tmp_path / "t.h5"
    assert run(["--quiet", "build", str(SAMPLES / "two_triangles.obj"), "-o", str(h5)], capsys)[0] == 0
    code, _, err = run(["plot", "vcells", str(h5), *args, "-o", str(tmp_path / "x.png")], capsys)
    assert code == 2 and err.count("\n") == 1 and message in err


def test_plot_vcells_needs_v2(tmp_path, capsys):
    h5 = tmp_path / "t.h5"
    assert run(["--quiet", "build", str(SAMPLES / "two_triangles.obj"), "--levels", "1", "-o", str(h5)], capsys)[0] == 0
    code, _, err = run(["plot", "vcells", str(h5), "--vertex", "0", "-o", str(tmp_path / "x.png")], capsys)
    assert code == 2 and err.count("\n") == 1 and "--levels 2" in err
    code, _, err = run(["plot", "vcells", str(tmp_path / "missing.h5"), "--vertex", "0", "-o", str(tmp_path / "x.png")], capsys)
    assert code == 2 and err.count("\n") == 1


def test_near_pairs_equal_the_brute_force_join():
    """near_pairs (binned) finds exactly the pairs of one group within each tolerance that
    the all-pairs join finds, points on a sphere and clustered within the tolerance."""
    from viscx.skeleton.loops import near_pairs, pairs_in_groups

    rng = np.random.default_rng(5)
    a = rng.normal(size=(3000, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = a[rng.permutation(len(a))] + rng.normal(scale=1e-7, size=a.shape)
    b[::3] = a[::3] + 3e-8  # many pairs near the tolerance
    group = rng.integers(0, 40, len(a))
    tol = np.where(rng.random(len(a)) < 0.5, 1e-7, 2e-7)
    i, j = pairs_in_groups(group)
    near = np.linalg.norm(a[i] - b[j], axis=1) <= tol[i]
    brute = np.stack([i[near], j[near]], axis=1)
    brute = brute[np.lexsort([brute[:, 1], brute[:, 0]])]
    fi, fj = near_pairs(a, b, group, tol)
    assert len(brute) > 500
    np.testing.assert_array_equal(np.stack([fi, fj], axis=1), brute)


#: The cities of the join tests (benchmarks/scenes.random_boxes): by default 11 of the 50
#: boxes of the 300-polygon city, each where it stands there (67 polygons, 92 vertices; the
#: whole city's V0 to V2 cost 9 s, these 1 s), kept by dropping boxes while every join rule
#: below still completed some vertex; ``-m slow`` runs the whole city.
CITIES = {"city": dict(keep=[16, 17, 18, 26, 29, 33, 38, 40, 41, 46, 48]), "city300": {}}
#: Cities and ray directions per vertex of the city tests: the default city at 500 per
#: vertex (~5 000 directions at its 10 joined vertices; the gap knock-out below still leaves
#: some of them in two cells), the whole city at the measured 2000 with ``-m slow``.
CITY_RUNS = [("city", 500), pytest.param("city300", 2000, marks=pytest.mark.slow)]
CITY_NAMES = ["city", pytest.param("city300", marks=pytest.mark.slow)]


def city(name):
    """(scene, arcs) of the city ``name`` of :data:`CITIES` (random_boxes(300, seed=0) or
    some of its boxes), built once, V1 without its rule 14."""
    if name not in _CACHE:
        import sys
        from pathlib import Path

        sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
        from scenes import random_boxes

        import viscx.skeleton.arcs.stages as stages

        scene = random_boxes(300, seed=0, **CITIES[name])
        # V1 without rule 14 (docs/skeleton.md "Furnished buildings"): these tests are of V2's
        # join, on the arcs whose gaps it bridges; rule 14 keeps most of those events apart
        # in V1 (the default city's join then completes 9 vertices, each join rule on its own
        # no longer needed there)
        real = stages._apart_at_reach
        stages._apart_at_reach = lambda scene, gens, s0, s1, reach: np.zeros(len(gens), bool)
        try:
            _CACHE[name] = scene, build_arcs(scene, build_nodes(scene))
        finally:
            stages._apart_at_reach = real
    return _CACHE[name]


def city_vcells(name):
    """The V-cells of :func:`city`, built once (the tests only read them)."""
    if (name, "vcells") not in _CACHE:
        _CACHE[name, "vcells"] = build_vcells(*city(name))
    return _CACHE[name, "vcells"]


def without_join(scene, el, group, *loops):
    """:func:`viscx.skeleton.vcells.join_open_chains` knocked out: the loops as FormLoops left them."""
    return loops


def city_strict(name):
    """The V-cells of :func:`city` without the join of open chains, built once."""
    import viscx.skeleton.vcells as vcells

    if (name, "strict") not in _CACHE:
        with pytest.MonkeyPatch.context() as m:
            m.setattr(vcells, "join_open_chains", without_join)
            _CACHE[name, "strict"] = build_vcells(*city(name))
    return _CACHE[name, "strict"]


def city_joined(name):
    """The vertices of :func:`city` the join completes (complete with it, not without)."""
    return np.setdiff1d(complete_vertices(city_vcells(name)), complete_vertices(city_strict(name)))


#: Per city, :func:`ray_oracle`'s memo for :func:`city_vcells` (the caster's pairs and the
#: band around the boundaries, per vertex and direction), and its results per set of
#: vertices: the vertices the join completes are judged by two tests with the same directions
CITY_ORACLE = {}


def city_oracle(name, vertices, n):
    """:func:`ray_oracle` of :func:`city_vcells` at ``vertices``, ``n`` directions each, computed once per set."""
    scene, arcs = city(name)
    memo = CITY_ORACLE.setdefault(name, {})
    key = ("result", n, tuple(int(v) for v in vertices))
    if key not in memo:
        memo[key] = ray_oracle(scene, arcs, city_vcells(name), vertices, n=n, memo=memo)
    return memo[key]


#: Per city: its vertices, and at most how many of them are complete without the join.
CITY_COUNTS = {"city": (92, 84), "city300": (404, 345)}


@pytest.mark.parametrize("name, n", CITY_RUNS)
def test_open_chains_joined_across_merged_events(name, n):
    """A city of boxes on a floor: where V1 merged a family's events closer than 4 epsilon,
    the two families at a cell's corner may keep different events, and the cell's boundary
    jumps by a few epsilon there. Without the join some vertices keep open chains (measured
    on the whole city: 340 of 404 complete, 235 chains; on the default city 82 of 92); with
    it every chain whose ends lie that close closes (all complete; on the whole city 1 chain
    left, a VE arc 0.8 epsilon long taken as a point), and the vertices it completes agree
    with the ray caster (measured on the whole city 127 901 of 127 901 directions at 2000
    per vertex)."""
    scene, arcs = city(name)
    joined = city_vcells(name)
    before, after = complete_vertices(city_strict(name)), complete_vertices(joined)
    n_vertices, most = CITY_COUNTS[name]
    assert set(before) <= set(after)
    assert len(after) == len(scene.generator_vertices) == n_vertices and len(joined.open_vertex) <= 2
    assert len(before) <= most
    new = city_joined(name)
    judged, agreed, wrong = city_oracle(name, new, n)
    assert judged >= 0.99 * n * len(new) and agreed >= 0.9999 * judged, wrong[:5]
    # a complete vertex's cells still cover its sphere
    total = per_vertex_solid_angle(joined, scene.n_vertices)[after]
    assert np.allclose(total, FOUR_PI, atol=1e-6)


def only_vertices(monkeypatch, vertices):
    """Make :func:`build_vcells` build the cells of ``vertices`` only (the boundary elements
    of the others dropped; pass ``vertices=`` too, for their whole-sphere cells): a vertex's
    cells depend on its own elements alone."""
    import viscx.skeleton.vcells as vcells

    real = vcells.boundary_elements

    def theirs(scene, arcs):
        el = real(scene, arcs)
        return el.take(np.flatnonzero(np.isin(el.vertex, vertices)))

    monkeypatch.setattr(vcells, "boundary_elements", theirs)


@pytest.mark.parametrize("name", CITY_NAMES)
def test_cells_of_some_vertices_equal_the_whole_build(monkeypatch, name):
    """:func:`only_vertices` (the knock-outs below build the vertices the join completes
    only): the same cells as the whole build at those vertices."""
    scene, arcs = city(name)
    new = city_joined(name)
    only_vertices(monkeypatch, new)
    part, whole = build_vcells(scene, arcs, vertices=new), city_vcells(name)
    assert np.array_equal(complete_vertices(part), new)
    mine = np.isin(whole.vertex, new)
    assert np.array_equal(part.vertex, whole.vertex[mine]) and np.array_equal(part.solid_angle, whole.solid_angle[mine])
    for field in ("up_kind", "up", "down_kind", "down", "turning"):
        loops = np.repeat(mine, np.diff(whole.loop_offsets)) if field == "turning" else mine
        assert np.array_equal(getattr(part, field), getattr(whole, field)[loops]), field


@pytest.mark.parametrize("name", CITY_NAMES)
@pytest.mark.parametrize("knockout", ["own_reach", "three_elements", "small_limit", "no_spike", "no_points"])
def test_each_join_rule_completes_city_vertices(knockout, name, monkeypatch):
    """Each rule is needed on the city (measured on the whole city, complete vertices of 404
    with it knocked out, against all 404): the gap measured from the nearest edge the end's
    line meets, not from its own edge (392: a VEE node (v, e, e') seen along e is merged on
    VE (v, e') nearer v); loops of two elements (399: a thin triangle whose third side V1
    merged away); gaps up to JOIN_LIMIT = 1e-3 (401: edges within a unit of the vertex); the
    spike rule of the turning sums (403: a gap running straight back along a collinear
    overlap turned by 2π instead of 0); open chains shorter than the join tolerance taken
    as points (403: a VE arc 0.8 epsilon long beside a sliver V1 merged away; it lies on a
    closed loop of its group too, so ``covered_chains`` is knocked out with it). On the
    default city, of its 92: 88, 91, 91, 91, 91. Every vertex each knock-out leaves open is
    one the join completes: the cells of those (64 in the whole city, 10 in the default
    one) are built (:func:`only_vertices`)."""
    import viscx.skeleton.vcells as vcells

    scene, arcs = city(name)
    new = city_joined(name)
    only_vertices(monkeypatch, new)
    if knockout == "own_reach":
        monkeypatch.setattr(vcells, "line_reach", lambda scene, vertex, direction, reach: reach)
    elif knockout == "three_elements":
        monkeypatch.setattr(vcells, "JOIN_MIN_ELEMENTS", 3)
    elif knockout == "small_limit":
        monkeypatch.setattr(vcells, "JOIN_LIMIT", 1e-4)
    elif knockout == "no_spike":
        monkeypatch.setattr(vcells, "SPIKE_ANGLE", -1.0)
    else:
        monkeypatch.setattr(vcells, "point_chains", lambda scene, walk, chain_offsets: np.zeros(len(chain_offsets) - 1, bool))
        # (that chain also lies on a closed loop of its group: covered_chains frees it too)
        monkeypatch.setattr(vcells, "covered_chains", lambda scene, walk, group, loops, chains: np.zeros(len(chains) - 1, bool))
    vc = build_vcells(scene, arcs, vertices=new)
    assert len(complete_vertices(vc)) < len(new)
    # whatever stays complete still covers its sphere
    assert np.allclose(per_vertex_solid_angle(vc, scene.n_vertices)[complete_vertices(vc)], FOUR_PI, atol=1e-6)


@pytest.mark.parametrize("name, n", CITY_RUNS)
def test_point_location_crosses_the_gaps_of_joined_loops(monkeypatch, name, n):
    """A path from a loop's reference point that passes through a gap of a joined loop
    crosses the loop there: without the gaps' arcs in the parity test, directions of
    the city's joined vertices lie in two cells (measured on the whole city, at the 64
    vertices the join completes, 2000 directions each: 495 of 127 901 judged directions
    disagree; 493 directions are held by two cells)."""
    import viscx.skeleton.vcells as vcells

    scene, arcs = city(name)
    vc = city_vcells(name)
    gapped = np.unique(vc.vertex[vc.complete & np.isin(vc.vertex, vertices_with_gaps(scene, arcs, vc))])
    assert len(gapped) >= 10
    # the same directions, pairs and boundaries below (CITY_ORACLE): only the location changes
    judged, agreed, wrong = city_oracle(name, gapped, n)
    assert agreed == judged, wrong[:5]

    def without_gaps(el, loop_offsets):
        n = loop_offsets[-1]
        return np.ascontiguousarray(el.start[:n]), np.ascontiguousarray(el.end[:n]), np.asarray(loop_offsets, np.int64)

    monkeypatch.setattr(vcells, "loop_segments", without_gaps)
    judged, agreed, wrong = ray_oracle(scene, arcs, vc, gapped, n=n, memo=CITY_ORACLE[name])
    assert agreed < judged and any("2 cells" in w for w in wrong)


def vertices_with_gaps(scene, arcs, vc):
    """Vertices with a loop whose elements do not meet end to start (a joined loop)."""
    el = stored_elements(scene, arcs, vc.element, vc.antipodal)
    n = len(vc.element)
    nxt = np.arange(1, n + 1)
    nxt[vc.element_offsets[1:] - 1] = vc.element_offsets[:-1]
    gap = np.linalg.norm(el.start[nxt] - el.end, axis=1) > 1e-7
    loop_of = np.repeat(np.arange(len(vc.element_offsets) - 1), np.diff(vc.element_offsets))
    cell_of = np.repeat(np.arange(len(vc)), np.diff(vc.loop_offsets))
    return np.unique(vc.vertex[cell_of[loop_of[gap]]])


def _unit(x):
    x = np.asarray(x, dtype=np.float64)
    return x / np.linalg.norm(x)


def _tangent(p, q):
    """At p, towards q along the great circle."""
    t = q - np.dot(p, q) * p
    return t / np.linalg.norm(t)


def _arcs_on_sphere(starts, ends):
    """Great-circle elements from ``starts`` to ``ends`` ((k, 3) unit vectors), as
    :func:`viscx.skeleton.vcells.sphere_turning_sums` reads them."""
    from types import SimpleNamespace

    return SimpleNamespace(start=starts, end=ends, start_tangent=np.array([_tangent(p, q) for p, q in zip(starts, ends)]),
                           end_tangent=np.array([-_tangent(q, p) for p, q in zip(starts, ends)]))


def test_turning_across_a_gap_running_back(monkeypatch):
    """A small spherical triangle A, B, C (counter-clockwise seen from outside) whose side
    B -> C overshoots C by 1e-6 rad (its family kept the farther of two merged events) and
    whose next side starts at C: the gap runs straight back along B -> C. Its turning sum is
    2π minus the triangle's area whichever way rounding tilts the gap (1e-8 rad either side
    of the great circle, or none); turning at both of the gap's ends (the spike and corner
    rules knocked out: the gap runs back along B -> C, whose circle meets C -> A at C)
    counts ±π at the overshoot and misses by 2π on one side."""
    import viscx.skeleton.vcells as vcells

    a, b, c = _unit([0, 0, 1]), _unit([0.01, 0, 1]), _unit([0, 0.01, 1])
    area = triangle_solid_angle(np.zeros(3), np.array([a, b, c]))
    offsets = np.array([0, 3])
    misses = []
    for tilt in (1e-8, -1e-8, 0.0):
        away = -_tangent(c, b)  # beyond C along B -> C
        over = _unit(c + 1e-6 * (away + tilt * np.cross(c, away)))
        starts, ends = np.array([a, b, c]), np.array([b, over, a])
        el = _arcs_on_sphere(starts, ends)
        assert abs(vcells.sphere_turning_sums(el, offsets)[0] - (2 * np.pi - area)) < 1e-9
        with monkeypatch.context() as m:
            m.setattr(vcells, "CORNER_REACH", 0.0)
            m.setattr(vcells, "SPIKE_ANGLE", -1.0)
            misses.append(vcells.sphere_turning_sums(el, offsets)[0] - (2 * np.pi - area))
    assert np.any(np.abs(np.abs(misses) - 2 * np.pi) < 1e-9), misses


def test_turning_at_the_base_of_a_sliver(monkeypatch):
    """Two elements running out and back between two great circles 2.4e-6 rad apart (a
    vertex 0.3 epsilon above a box top sees two edges of it so: random_boxes(1000), vertex
    367): a sliver trapezoid whose ends lie 3.6e-9 and 3.6e-8 apart, below JOIN_CHORD.
    At its base the loop turns by π plus the apex angle; one turn between the tangents
    wraps that to -π plus it, a cell of 2π sr instead of 3e-10 (the cusp rule knocked out);
    turning across the base's gap gives its area."""
    import viscx.skeleton.vcells as vcells

    p1, q1 = _unit([0, 0, 1]), _unit([0.0136, 0, 1])
    q2, p2 = _unit([0.0136, 3.6e-8, 1]), _unit([0, 3.6e-9, 1])  # left of p1 -> q1
    starts, ends = np.array([p1, q2]), np.array([q1, p2])
    el = _arcs_on_sphere(starts, ends)
    offsets = np.array([0, 2])
    area = (triangle_solid_angle(np.zeros(3), np.array([p1, q1, q2]))
            + triangle_solid_angle(np.zeros(3), np.array([p1, q2, p2])))
    turning = vcells.sphere_turning_sums(el, offsets)[0]
    assert abs(turning - (2 * np.pi - area)) < 1e-10  # the area is 2.7e-10
    monkeypatch.setattr(vcells, "CUSP_ANGLE", -1.0)
    assert abs(vcells.sphere_turning_sums(el, offsets)[0] - turning + 2 * np.pi) < 1e-9


def test_turning_where_elements_cross_by_a_gap(monkeypatch):
    """A triangle A, B, C whose side A -> B overshoots B by 6e-7 rad and whose side B -> C
    starts 1e-7 before B on its great circle (two families kept different events of a
    merged group; random_boxes(1000), vertex 418): the two elements cross by the gap, the
    corner is B and the loop turns there once. Turning at both ends of the gap (the corner
    rule knocked out) adds a full turn: a cell of 2π more than it is."""
    import viscx.skeleton.vcells as vcells

    a, b, c = np.array([0.0, 0.0]), np.array([0.01, 0.0]), np.array([0.0, 0.01])
    toward_c = (c - b) / np.linalg.norm(c - b)
    over, before = b + [6e-7, 0.0], b - 1e-7 * toward_c
    lift = [_unit([*x, 1.0]) for x in (a, over, before, c)]
    starts, ends = np.array([lift[0], lift[2], lift[3]]), np.array([lift[1], lift[3], lift[0]])
    el = _arcs_on_sphere(starts, ends)
    offsets = np.array([0, 3])
    area = triangle_solid_angle(np.zeros(3), np.array([_unit([*x, 1.0]) for x in (a, b, c)]))
    turning = vcells.sphere_turning_sums(el, offsets)[0]
    assert abs(turning - (2 * np.pi - area)) < 1e-8
    monkeypatch.setattr(vcells, "CORNER_REACH", 0.0)
    assert abs(vcells.sphere_turning_sums(el, offsets)[0] - turning + 2 * np.pi) < 1e-8


def test_point_location_in_a_loop_whose_element_runs_past_a_spike():
    """A small triangle P0, P1, P2 (counter-clockwise) whose side P0 -> P1 runs on 1.5 times
    its length past P1 (its family kept a farther event of a merged run), the gap running
    straight back along it to P1, where the next side starts (the whole npm bunny's vertex
    967: a cell of 2.9e-10 sr, sides 5e-5 to 9.4e-5 rad, the gap 6.5e-5 rad). The turning
    sum turns once at P1 (the spike rule) and gives the triangle's area; point location
    must see the same loop: the reference point beside the middle of the longest element,
    beyond P1, lay outside the triangle, so every direction of the sphere was inside this
    cell and in the one really holding it (every direction of vertex 967 in two cells).
    Directions in the triangle are inside, the rest of the sphere outside."""
    import viscx.skeleton.vcells as vcells

    corners = [_unit([*x, 1.0]) for x in ([0.0, 0.0], [1e-4, 0.0], [0.3e-4, 0.8e-4])]
    p0, p1, p2 = corners
    past = _unit(p0 + 2.5 * (p1 - p0))
    el = _arcs_on_sphere(np.array([p0, p1, p2]), np.array([past, p2, p0]))
    offsets = np.array([0, 3])
    area = triangle_solid_angle(np.zeros(3), np.array(corners))
    # (within 1e-8 sr: the spike's one turn is taken between tangents 1.5e-4 rad apart)
    assert abs(vcells.sphere_turning_sums(el, offsets)[0] - (2 * np.pi - area)) < 1e-8
    ref = vcells.reference_points(el, offsets)
    rng = np.random.default_rng(0)
    w = rng.dirichlet(np.ones(3), 200)
    within = w @ np.array(corners)
    within /= np.linalg.norm(within, axis=1, keepdims=True)
    targets = np.concatenate([within, uniform_directions(rng, 1000), [_unit(p0 + 2.0 * (p1 - p0) + [0, 1e-6, 0])]])
    inside = vcells.inside_loops(el, offsets, ref, np.zeros(len(targets), np.int64), targets)
    assert inside[:200].all() and not inside[200:].any()


@pytest.mark.slow
def test_every_vertex_of_the_1000_polygon_city_is_complete(monkeypatch):
    """random_boxes(1000) (997 polygons): every one of its 1332 vertices is complete (920
    before the join rules were mended, 17 point chains left); with the join limited to
    5 epsilon two vertices stay open (151 and 623: V1 merged runs of events two links
    long, 5.4 and 5.1 epsilon apart along the edge the families share), and the vertices
    completed by the rules past the nearest-edge join (cusps at vertices 367 and 370, an
    overshoot crossing the next element at 418, the 8 epsilon runs, point chains) agree
    with the ray caster (measured 35 961 of 35 961 directions)."""
    import sys
    from pathlib import Path

    import viscx.skeleton.vcells as vcells

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from scenes import random_boxes

    scene = random_boxes(1000, seed=0)
    arcs = build_arcs(scene, build_nodes(scene))
    vc = build_vcells(scene, arcs)
    assert len(complete_vertices(vc)) == len(scene.generator_vertices) == 1332
    special = [59, 151, 205, 221, 242, 261, 367, 370, 418, 623, 639, 786, 844, 892, 916, 963, 982, 1032]
    judged, agreed, wrong = ray_oracle(scene, arcs, vc, special, n=2000)
    assert judged >= 0.99 * 2000 * len(special) and agreed == judged, wrong[:5]
    monkeypatch.setattr(vcells, "JOIN_EPSILONS", 5)
    assert set(np.setdiff1d(scene.generator_vertices, complete_vertices(build_vcells(scene, arcs)))) == {151, 623}


def _closable_links_by_rounds(n, i, j):
    """The plain definition of loops._closable_links: drop elements with no living link in or
    out, round after round, until none is dropped."""
    alive = np.ones(n, bool)
    while True:
        keep = alive[i] & alive[j]
        still = alive & (np.bincount(i[keep], minlength=n) > 0) & (np.bincount(j[keep], minlength=n) > 0)
        if np.array_equal(still, alive):
            return keep
        alive = still


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 30).flatmap(lambda n: st.tuples(
    st.just(n), st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=3 * n),
    st.permutations(range(n)))))
def test_closable_links_peeled_in_one_pass_equal_the_rounds(case):
    """FormLoops' pruning of dangling elements (one queue pass in numba) keeps exactly the
    links the round-by-round definition keeps: random links plus a chain through every
    element (long dangling chains take one round per element there)."""
    from viscx.skeleton.loops import _closable_links

    n, links, perm = case
    i = np.array([a for a, _ in links] + list(perm[:-1]), dtype=np.int64)
    j = np.array([b for _, b in links] + list(perm[1:]), dtype=np.int64)
    assert np.array_equal(_closable_links(n, i, j), _closable_links_by_rounds(n, i, j))
