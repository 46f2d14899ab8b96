"""The output-sensitive sweep of point_views (viscx.geometry.occlusion._sweep_runs: the active
edges' order kept from break to break, regions named by their top edge, decided again only
next to an event) against the plain sweep (every slab sorted, every region searched, whole
trapezoids summed: ``sweep=1``), on scenes where it is easy to get wrong: many events at one
break and coincident events (the Cornell box's blocks, touching furniture: desks resting on
panels, cabinets on the floor, coplanar faces meeting at an edge, faces lying on faces),
collinear and touching edges, and a steep edge (a turned basis)."""

import sys
from pathlib import Path

import numpy as np
import pytest

from viscx.geometry.occlusion import point_views
from viscx.geometry.polygon import plane_basis
from viscx.queries import formfactor as ff
from viscx.scene import build_scene, load_scene

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from buildings import office  # noqa: E402


def _points(scene, face, n, rng):
    tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
    w = rng.dirichlet([1, 1, 1], n)
    return np.ascontiguousarray(np.einsum("gk,gkd->gd", w, tri[rng.integers(0, len(tri), n)]))


def _both(scene, face, points):
    n_i = scene.face_normal[face]
    eu, ev = plane_basis(n_i)
    args = (points, n_i, eu, ev, *ff.scene_polygons(scene), int(face), 1e-9 * scene.diagonal, *ff.closed_boxes(scene))
    return point_views(*args, 2), point_views(*args, 1)


@pytest.fixture(scope="module")
def office60():
    return build_scene(office(60, seed=0))


@pytest.fixture(scope="module")
def cornell():
    return load_scene(ROOT / "sample_scenes" / "cornell_box.obj")


def test_sweep_runs_equals_the_plain_sweep_on_the_cornell_box(cornell, rng):
    """Every face of the Cornell box (its blocks' faces meet the floor along edges, the light
    lies on the ceiling), 12 points each: every column within 1e-13 (the rows sum to 1)."""
    for face in range(cornell.n_faces):
        a, b = _both(cornell, face, _points(cornell, face, 12, rng))
        assert np.abs(a - b).max() < 1e-13, face


@pytest.mark.parametrize("group", ["floor", "wall_west", "desk0", "light1", "cabinet0"])
def test_sweep_runs_equals_the_plain_sweep_in_a_furnished_room(office60, group, rng):
    """Desks on panels, cabinets against walls, lights on the ceiling: from faces of each
    kind, 15 points, every column within 1e-13."""
    face = int(office60.group_faces(group)[0])
    a, b = _both(office60, face, _points(office60, face, 15, rng))
    assert np.abs(a - b).max() < 1e-13
