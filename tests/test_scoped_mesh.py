"""Builds scoped to an area light (viscx/skeleton/scope.py): ``viscx query discontinuities
SCENE_FILE``, ``viscx render SCENE_FILE`` and ``viscx build --light-group`` build only the
nodes and arcs of the light's families, and answer exactly as from the full build.

Two checks: the scoped V0 and V1 are the full build's rows of the nodes and families in
scope, field for field (node ids renumbered); the discontinuity mesh (events, traces,
contacts, regions) is the full file's, with the events' arc ids mapped to their arcs. The
full builds of the samples are the golden files (tests/test_golden.py keeps them equal to
a fresh build); that the mesh itself is right is the oracle's business
(tests/test_discontinuities.py).
"""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLES, viscx_in_process
from test_discontinuities import (contact_scene_obj, crossing_scene_obj, graze_scene_obj, light_scene_obj,
                                  panel_scene_obj, saddle_scene_obj, tip_scene_obj)

from viscx.pipeline import build_complex, light_scope, open_complex
from viscx.queries.discontinuities import light_mesh, mesh_result, open_discontinuities, open_light_query
from viscx.skeleton.scope import pairs_near
from viscx.skeleton.arcs.kinds import END_NODE, END_PLANAR

GOLDEN = Path(__file__).resolve().parent / "golden"

#: The sample scenes with an area light (a group, or a face as the discontinuity tests use).
SAMPLE_LIGHTS = {
    "cornell_box.obj": {"light_group": "light"},
    "room_with_door.obj": {"light_group": "light"},
    "tetrahedra.obj": {"light_face": 0},
    "boxes_on_floor.obj": {"light_face": 5},
}

NODE_FIELDS = ("kind", "generators", "direction", "ends", "blocker_kind", "blocker", "generator_points")
ARC_FIELDS = ("kind", "generators", "interval", "end_type", "blocker_kind", "blocker", "parameter", "direction",
              "ends", "generator_points")
HALF_FIELDS = ("vertex", "edge", "up_kind", "up", "down_kind", "down", "start_type", "end_type")


def _equal(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and (np.array_equal(a, b, equal_nan=True) if a.dtype.kind == "f" else np.array_equal(a, b))


def assert_scoped_levels(full, scoped, **light):
    """The scoped V0 and V1 are the full build's rows in scope, field for field."""
    scope = light_scope(full.scene, **light)
    N, n = full.nodes, scoped.nodes
    keep = scope.nodes(N.kind, N.generators)
    assert len(n) == np.count_nonzero(keep) > 0
    for f in NODE_FIELDS:
        assert _equal(getattr(N, f)[keep], getattr(n, f)), f
    renumber = np.full(len(N), -1)
    renumber[keep] = np.arange(len(n))
    A, a = full.arcs, scoped.arcs
    P, p = A.planar, a.planar
    planar = scope.nodes(P.kind, P.generators)
    for f in NODE_FIELDS:
        assert _equal(getattr(P, f)[planar], getattr(p, f)), f
    renumber_planar = np.full(len(P), -1)
    renumber_planar[planar] = np.arange(len(p))
    mine = scope.families(A.kind, A.generators)
    assert len(a) == np.count_nonzero(mine) > 0
    for f in ARC_FIELDS:
        assert _equal(getattr(A, f)[mine], getattr(a, f)), f
    ends = A.end_node[mine].copy()
    for code, ids in ((END_NODE, renumber), (END_PLANAR, renumber_planar)):
        at = A.end_type[mine] == code
        assert (ids[ends[at]] >= 0).all()  # every node an arc in scope ends at is in scope
        ends[at] = ids[ends[at]]
    assert _equal(ends, a.end_node)
    # VE half-cells: one per VE arc, in the arcs' order
    H, h = A.half_cells, a.half_cells
    hm = mine[H.arc]
    arc_id = np.cumsum(mine) - 1
    assert _equal(arc_id[H.arc[hm]], h.arc)
    for f in HALF_FIELDS:
        assert _equal(getattr(H, f)[hm], getattr(h, f)), f
    for side, kind in (("start", "start_type"), ("end", "end_type")):
        x = getattr(H, side)[hm].copy()
        for code, ids in ((END_NODE, renumber), (END_PLANAR, renumber_planar)):
            at = getattr(H, kind)[hm] == code
            x[at] = ids[x[at]]
        assert _equal(x, getattr(h, side)), side


def comparable(result, arcs):
    """The mesh answer with each event's arc id replaced by the arc's family and interval
    (ids differ between a file and a scoped build; the arcs are the same)."""
    out = json.loads(json.dumps(result))
    for face in out["faces"]:
        for seg in face["segments"]:
            k = seg["arc"]
            seg["arc"] = None if k < 0 else [int(arcs.kind[k]), arcs.generators[k].tolist(), arcs.interval[k].tolist()]
    return out


def assert_same_mesh(full_path, scoped_source, **light):
    """The mesh of the light from a full file and from a scene file (scoped): equal."""
    answers = []
    for source in (full_path, scoped_source):
        cx = open_light_query(source, **light)
        answers.append(comparable(mesh_result(cx.scene, light_mesh(cx, **light)), cx.arcs))
    assert answers[0] == answers[1]
    return answers[0]


@pytest.mark.parametrize("name", sorted(SAMPLE_LIGHTS))
def test_scoped_mesh_equals_full_build_samples(name, sample_build):
    """Every sample scene with a light: the mesh from the scene file equals the full build's."""
    mesh = assert_same_mesh(sample_build(name), SAMPLES / name, **SAMPLE_LIGHTS[name])
    # (tetrahedra.obj's face 0 casts every trace behind itself; the box side only its LP line)
    assert mesh["events"] >= {"cornell_box.obj": 100, "room_with_door.obj": 30}.get(name, 0)


@pytest.mark.parametrize("name", ["cornell_box.obj", "tetrahedra.obj"])
def test_scoped_levels_equal_full_build_samples(name, sample_build):
    light = SAMPLE_LIGHTS[name]
    full = open_complex(sample_build(name))
    assert_scoped_levels(full, build_complex(SAMPLES / name, quiet=True, **light), **light)


def _random_scene(tmp_path, kind, seed):
    make = {"tetrahedra": lambda p: light_scene_obj(p, seed, count=2 + seed % 2),
            "contact": lambda p: contact_scene_obj(p, seed),
            "crossing": crossing_scene_obj,
            "panel": lambda p: panel_scene_obj(p, tilt=0.3, fold=True),
            "saddle": saddle_scene_obj, "graze": graze_scene_obj, "tip": tip_scene_obj}[kind]
    return make(tmp_path / f"{kind}{seed}.obj")


def _check_random(tmp_path, kind, seed):
    obj = _random_scene(tmp_path, kind, seed)
    full = build_complex(obj, quiet=True, output=tmp_path / "full.h5")
    assert_scoped_levels(full, build_complex(obj, quiet=True, light_group="light"), light_group="light")
    assert assert_same_mesh(tmp_path / "full.h5", obj, light_group="light")["events"] > 0


@pytest.mark.parametrize("kind, seed", [("tetrahedra", 3), ("crossing", 0), ("saddle", 0), ("graze", 0), ("tip", 0)])
def test_scoped_equals_full_build_random(tmp_path, kind, seed):
    """Random tetrahedra under a square light; touching boxes with an X-junction (XE arcs); a
    closed mesh with a saddle at a receiver's vertex (RPV lines of the receiver's own vertex,
    traces across the solid dropped); a receiver grazed by the lines between two merged
    events (a window of lines traced, arc -1); a closed solid's tip just above a receiver's
    plane (receiver-plane events from the lit side only)."""
    _check_random(tmp_path, kind, seed)


@pytest.mark.slow
@pytest.mark.parametrize("kind, seed", [("tetrahedra", s) for s in range(20, 40)]
                         + [("contact", s) for s in (5, 9, 11, 20)] + [("panel", 0)])
def test_scoped_equals_full_build_random_slow(tmp_path, kind, seed):
    """The discontinuity tests' random scenes (seeds 20–39), touching boxes whose contact
    faces overlap in part (pencils of touched planes, cracks), a folded panel."""
    _check_random(tmp_path, kind, seed)


# --------------------------------------------------------------------------------------
# the light-centred outer pairs of the scoped node scans


def test_pairs_near_equals_brute_force():
    """pairs_near (per scope box, by side codes) gives exactly the pairs whose joint box
    meets a scope box, as checking every pair does; one set: i < j."""
    rng = np.random.default_rng(0)
    lo1 = rng.uniform(0, 10, (60, 3))
    hi1 = lo1 + rng.uniform(0, 3, (60, 3))
    lo2 = rng.uniform(0, 10, (50, 3))
    hi2 = lo2 + rng.uniform(0, 3, (50, 3))
    s_lo = rng.uniform(2, 8, (3, 3))
    s_hi = s_lo + rng.uniform(0, 1, (3, 3))
    for same, (l2, h2) in ((False, (lo2, hi2)), (True, (lo1, hi1))):
        first, (off, partners) = pairs_near(s_lo, s_hi, lo1, hi1, l2, h2, same=same)
        got = {(i, int(j)) for i in range(len(lo1)) for j in partners[off[i] : off[i + 1]]}
        lo = np.minimum(lo1[:, None], l2[None])
        hi = np.maximum(hi1[:, None], h2[None])
        meets = ((lo[:, :, None] <= s_hi[None, None]) & (hi[:, :, None] >= s_lo[None, None])).all(axis=3).any(axis=2)
        if same:
            meets &= np.arange(len(lo1))[:, None] < np.arange(len(lo1))[None]
        want = set(zip(*map(lambda x: x.tolist(), np.nonzero(meets))))
        assert got == want and 0 < len(want) < meets.size // 2
        assert first.tolist() == sorted({i for i, _ in want})


def light_between_obj(path):
    """The tests' light scene (seed 3, two tetrahedra between the floor and the light) with
    a third tetrahedron above the light: node lines run from the tetrahedra below past a
    light edge to the one above, the light edge between their outer generators."""
    light_scene_obj(path, 3)
    pts = np.array([[4.2, 11.0, 4.3], [6.1, 11.2, 4.6], [5.0, 11.1, 6.2], [5.1, 12.4, 5.0]])
    n = sum(1 for line in path.read_text().splitlines() if line.startswith("v "))
    lines = ["o above"] + [f"v {p[0]!r} {p[1]!r} {p[2]!r}" for p in pts.tolist()]
    lines += ["f " + " ".join(str(n + 1 + i) for i in tri) for tri in ((0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3))]
    path.write_text(path.read_text() + "\n".join(lines) + "\n")
    return path


def test_scoped_light_between_generators(tmp_path, monkeypatch):
    """Knock-out of the light-centred pairs with generators beyond the light: visiting only
    the outer pairs with an item at the light (a light edge or vertex, or anything reaching
    its box) loses nodes of the scoped V0 (which is the full build's in scope:
    :func:`test_scoped_light_between_generators_levels`), those whose light generator lies
    strictly between the outer pair."""
    import viscx.skeleton.scope as scope_module

    obj = light_between_obj(tmp_path / "between.obj")
    scoped = build_complex(obj, quiet=True, levels=0, light_group="light")

    real = scope_module.pairs_near

    def at_the_light(s_lo, s_hi, lo1, hi1, lo2, hi2, same=False):
        first, (off, partners) = real(s_lo, s_hi, lo1, hi1, lo2, hi2, same)
        i = np.repeat(np.arange(len(lo1)), np.diff(off))
        near1 = ((lo1[:, None] <= s_hi[None]) & (hi1[:, None] >= s_lo[None])).all(axis=2).any(axis=1)
        near2 = ((lo2[:, None] <= s_hi[None]) & (hi2[:, None] >= s_lo[None])).all(axis=2).any(axis=1)
        keep = near1[i] | near2[partners]
        i, partners = i[keep], partners[keep]
        return np.unique(i), (np.searchsorted(i, np.arange(len(lo1) + 1)), partners)

    monkeypatch.setattr(scope_module, "pairs_near", at_the_light)
    knocked = build_complex(obj, quiet=True, levels=0, light_group="light")
    rows = {tuple(g) for g in scoped.nodes.generators.tolist()}
    assert {tuple(g) for g in knocked.nodes.generators.tolist()} < rows


@pytest.mark.slow
def test_scoped_light_between_generators_levels(tmp_path):
    """The same scene: the scoped V0 and V1 and the mesh are the full build's."""
    obj = light_between_obj(tmp_path / "between.obj")
    full = build_complex(obj, quiet=True, output=tmp_path / "full.h5")
    assert_scoped_levels(full, build_complex(obj, quiet=True, light_group="light"), light_group="light")
    assert assert_same_mesh(tmp_path / "full.h5", obj, light_group="light")["events"] > 0


# --------------------------------------------------------------------------------------
# the command line: scene files, scoped files, errors


def test_cli_scoped_discontinuities(tmp_path):
    """From the OBJ and from a file built for the light: the golden file's answer."""
    out, built = tmp_path / "m.json", tmp_path / "light.h5"
    r = viscx_in_process("query", "discontinuities", SAMPLES / "tetrahedra.obj", "--light-face", "0", "-o", out)
    assert r.returncode == 0, r.stderr
    full_scene, full_mesh = open_discontinuities(GOLDEN / "tetrahedra.h5", light_face=0)
    full = comparable(mesh_result(full_scene, full_mesh), open_complex(GOLDEN / "tetrahedra.h5").arcs)
    scoped_arcs = open_light_query(SAMPLES / "tetrahedra.obj", light_face=0).arcs
    assert comparable(json.loads(out.read_text()), scoped_arcs) == full
    r = viscx_in_process("build", SAMPLES / "tetrahedra.obj", "--light-face", "0", "-o", built)
    assert r.returncode == 0, r.stderr
    cx = open_complex(built)
    assert cx.levels == ["V0", "V1"] and cx.options["light"] == {"light_face": 0}
    r = viscx_in_process("query", "discontinuities", built, "--light-face", "0", "-o", out)
    assert r.returncode == 0, r.stderr
    assert comparable(json.loads(out.read_text()), cx.arcs) == full
    r = viscx_in_process("info", built)
    assert r.returncode == 0 and "built for one light: light face 0" in r.stdout, r.stderr


@pytest.fixture(scope="module")
def tetra_light_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("scoped") / "tetra_light.h5"
    build_complex(SAMPLES / "tetrahedra.obj", quiet=True, light_face=0, output=out)
    return out


@pytest.mark.parametrize("args,message", [
    (["query", "discontinuities", "{obj}", "--light-group", "nope"], "no group named 'nope'"),
    (["query", "discontinuities", "{obj}"], "--light-face"),
    (["query", "discontinuities", "{scoped}", "--light-face", "1"], "built for one light (light face 0) only"),
    (["query", "discontinuities", "{h5}", "--light-face", "0", "--weld", "1e-6"], "--weld apply to scene files only"),
    (["query", "shadows", "{scoped}", "--light", "5,5,5"], "V2"),
    (["formfactor", "faces", "{scoped}", "--from-face", "0", "--to-face", "1"], "V2"),
    (["build", "{obj}", "--light-group", "nope", "-o", "{tmp}/x.h5"], "no group named 'nope'"),
    (["build", "{obj}", "--light-face", "0", "--levels", "2", "-o", "{tmp}/x.h5"], "--levels 2 needs a full build"),
    (["build", "{obj}", "--light-face", "0", "--point", "1,2,3", "-o", "{tmp}/x.h5"], "cannot be combined"),
    (["render", "{obj}", "--camera", "0,0,9", "--look-at", "0,0,0", "--light-group", "nope", "--size", "8", "8",
      "-o", "{tmp}/x.png"], "no group named 'nope'"),
    # (said before anything is built)
    (["render", "{obj}", "--camera", "0,0,9", "--look-at", "0,0,0", "--light-face", "0", "--size", "8", "8",
      "-o", "{tmp}/x.png"], "emits nothing"),
])
def test_cli_scoped_errors(tmp_path, tetra_light_file, args, message):
    args = [a.format(obj=SAMPLES / "tetrahedra.obj", h5=GOLDEN / "tetrahedra.h5", scoped=tetra_light_file, tmp=tmp_path)
            for a in args]
    r = viscx_in_process(*args)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and message in r.stderr, r.stderr
    assert not (tmp_path / "x.h5").exists() and not (tmp_path / "x.png").exists()


def test_scoped_render_equals_full_build(tmp_path):
    """The exact image of the Cornell box from its OBJ (scoped) and from the golden file:
    the same linear radiance, bit for bit."""
    images = []
    for source, name in ((GOLDEN / "cornell_box.h5", "full"), (SAMPLES / "cornell_box.obj", "scoped")):
        png = tmp_path / f"{name}.png"
        r = viscx_in_process("render", source, "--camera", "278,273,-800", "--look-at", "278,273,0",
                             "--light-group", "light", "--size", "48", "40", "-o", png)
        assert r.returncode == 0, r.stderr
        images.append(np.load(tmp_path / f"{name}.npy"))
    assert images[0].shape == (40, 48, 3) and images[0].max() > 0
    assert np.array_equal(images[0], images[1])


# --------------------------------------------------------------------------------------
# the scoped planar events: corner planes a scope edge reaches, crossings near its lines


def _spheres_obj(path, subdivisions=1, seed=0):
    """Icospheres under a quad light (group ``light``, facing down), in a closed room: many
    corner planes, most crossed by a light edge far from any event in scope."""
    import trimesh

    rng = np.random.default_rng(seed)
    room = trimesh.creation.box(extents=(12, 8, 12))
    room.invert()
    parts = [("room", room)]
    for i in range(3):
        sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.8 + 0.5 * rng.random())
        sphere.apply_translation(rng.uniform([-3, -2, -3], [3, 1, 3]))
        parts.append((f"sphere{i}", sphere))
    parts.append(("light", trimesh.Trimesh([[-1, 3.5, -1], [1, 3.5, -1], [1, 3.5, 1], [-1, 3.5, 1]], [[0, 1, 2], [0, 2, 3]],
                                           process=False)))
    lines, n = [], 0
    for name, mesh in parts:
        lines.append(f"o {name}")
        lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in mesh.vertices.tolist()]
        lines += ["f " + " ".join(str(n + 1 + int(i)) for i in face) for face in mesh.faces]
        n += len(mesh.vertices)
    path.write_text("\n".join(lines) + "\n")
    return path


def test_scoped_planar_events_equal_full(tmp_path):
    """planar_events with a scope (viscx.skeleton.scope.planar_crossings: only the corner
    planes a scope edge reaches, only the crossings on a line through a scope crossing that
    cuts the corner, the full build's floats and representative rows) is the full
    build's rows in scope, field for field."""
    from viscx.pipeline import scene_of
    from viscx.skeleton.arcs.events import planar_events

    from viscx.skeleton.scope import Scope

    scene = scene_of(_spheres_obj(tmp_path / "spheres.obj"))
    full = planar_events(scene)
    # the light; and three random sphere edges (their events are often proposed by two
    # corners, one of whose planes is not whole: without the full build's row order
    # (full_build_order) 5 of 10 such scopes differ in the last bits)
    rng = np.random.default_rng(0)
    scopes = [light_scope(scene, light_group="light")]
    scopes += [Scope.of(scene, edges=rng.choice(scene.generator_edges, 3, replace=False)) for _ in range(6)]
    for scope in scopes:
        scoped = planar_events(scene, scope)
        keep = scope.nodes(full.kind, full.generators)
        assert np.count_nonzero(keep) > 0
        for f in NODE_FIELDS:
            assert _equal(getattr(full, f)[keep], getattr(scoped, f)), f
