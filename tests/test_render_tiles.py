"""The exact image by tiles (viscx.render.tiles) on spheres (closed convex boxes): equal to
the evaluation past every occluder of each pixel's pair, pixel by pixel; the culling rules
each shown to matter (the comparison fails without them); a Monte Carlo check; the
command from a scene file builds nothing. (Equal to the mesh path's image:
tests/test_render.py.)"""

import json

import numpy as np
import pytest
from conftest import viscx_in_process
from render_oracle import noise_check
from test_scoped_mesh import _spheres_obj

from viscx.pipeline import scene_of
from viscx.queries.discontinuities import open_light_query
from viscx.render import tiles
from viscx.render.camera import Camera, primary_hits
from viscx.render.direct import Lighting, emitter
from viscx.render.montecarlo import reference_radiance
from viscx.render.tiles import shade_tiles
from viscx.scene.light import light_of

#: The spheres' camera: the floor under them, their sides, two walls.
SPHERES_VIEW = dict(eye=[0.0, 1.0, 5.5], look_at=[0.0, -1.5, 0.0], up=[0, 1, 0], fov=75.0)


def _close(a, b):
    """Largest difference, relative to the image's largest value."""
    return float(np.max(np.abs(a - b)) / np.abs(b).max())


@pytest.fixture(scope="module")
def spheres(tmp_path_factory):
    """Three icospheres of 80 faces (closed convex boxes) in a room under a quad light, and
    its 40 × 40 image's hits, with the radiance of every pixel past every occluder of its
    (receiver, light face) pair (:meth:`Lighting.whole_radiance`)."""
    obj = _spheres_obj(tmp_path_factory.mktemp("tiles") / "spheres.obj", subdivisions=1, seed=2)
    scene = scene_of(obj)
    lighting = Lighting(scene, emitter(scene, light_of(scene, group="light"), radiance=(5.0, 5.0, 5.0)))
    hits = primary_hits(scene, Camera(width=40, height=40, **SPHERES_VIEW))
    whole = np.zeros((len(hits.face), 3))
    hit = np.flatnonzero(hits.face >= 0)
    for f, s in set(zip(hits.face[hit].tolist(), hits.side[hit].tolist())):
        on = hit[(hits.face[hit] == f) & (hits.side[hit] == s)]
        whole[on] = lighting.whole_radiance(f, s, hits.point[on]) + lighting.emitted(f, s)[None, :]
    return obj, lighting, hits, whole


def test_tiles_equal_every_occluder_on_spheres(spheres):
    """Each pixel's radiance from its group's culled occluders (the spheres' boxes reduced
    to silhouette and cone faces) is its radiance past every occluder of its pair, to
    1e-12; and the culling culls: fewer occluders per group than the pair's whole list."""
    _, lighting, hits, whole = spheres
    image, stats = shade_tiles(lighting, hits)
    assert _close(image, whole) <= 1e-12
    lit = np.sum(image, axis=1) > 0
    assert lit.sum() > 600 and (~lit & (hits.face >= 0)).sum() > 50  # lit and shadowed pixels
    assert stats["reduced"] > 10, stats
    mean_whole = np.mean([len(s.occluders) for pairs in lighting._setups.values() for s in pairs if s is not None])
    assert stats["occluders"] / stats["groups"] < mean_whole, (stats, mean_whole)


def _broken(monkeypatch, rule):
    """Break one culling rule of viscx.render.tiles."""
    if rule == "shaft":  # the shaft's planes moved in by 0.3
        planes = tiles._support_planes

        def shrunk(cells, *args):
            p, n = planes(cells, *args)
            p[:, :, 3] -= 0.3  # (the room is 12 × 8 × 12)
            return p, n

        monkeypatch.setattr(tiles, "_support_planes", shrunk)
    elif rule == "silhouette":  # no silhouette face kept
        ring = tiles._silhouette_faces
        monkeypatch.setattr(tiles, "_silhouette_faces", lambda *a: (np.zeros_like(ring(*a)[0]), ring(*a)[1]))
    elif rule == "cones":  # no face the cones to the light's corners meet
        meets = tiles.TileShading._meets

        def no_cones(self, cells, g_n, t_pts, t_ptr, *args):
            out = meets(self, cells, g_n, t_pts, t_ptr, *args)
            return out & (len(t_ptr) - 1 != len(t_pts))  # (a cone's target is one corner)

        monkeypatch.setattr(tiles.TileShading, "_meets", no_cones)


@pytest.mark.parametrize("rule", ["shaft", "silhouette", "cones"])
def test_a_dropped_occluder_is_seen(spheres, monkeypatch, rule):
    """The comparison above fails when a rule drops faces it needs: a shaft too small, the
    reduced boxes without their silhouette faces, or without the faces their cones meet
    (the corners of the light's hull hidden by a sphere)."""
    _, lighting, hits, whole = spheres
    _broken(monkeypatch, rule)
    image, _ = shade_tiles(lighting, hits)
    assert _close(image, whole) > 1e-6


def test_tiles_agree_with_monte_carlo(spheres):
    """The spheres' image against 128 shadow rays per pixel (render_oracle.noise_check);
    where it is black, no ray reaches the light either."""
    _, lighting, hits, _ = spheres
    image, _ = shade_tiles(lighting, hits)
    mc, se = reference_radiance(lighting, hits.face, hits.side, hits.point, 128, seed=3)
    ok, d = noise_check(image, mc, se)
    assert ok and d["n"] > 1500, d
    black = (image <= 1e-12) & (hits.face >= 0)[:, None]
    assert black.sum() > 100 and np.all(mc[black] == 0.0)


def test_render_of_a_scene_file_builds_nothing(spheres, tmp_path):
    """`viscx render scene.obj` (exact) reads the scene only (no V0, V1 or mesh) and writes
    the tiles' image."""
    obj, lighting, _, _ = spheres
    cx = open_light_query(obj, light_group="light", scene_only=True)
    assert cx.levels == [] and not cx.built
    args = ["render", obj, "--camera", ",".join(map(str, SPHERES_VIEW["eye"])), "--look-at",
            ",".join(map(str, SPHERES_VIEW["look_at"])), "--fov", 75, "--light-group", "light", "--radiance", "5,5,5",
            "--size", 24, 20]
    r = viscx_in_process(*args, "-o", tmp_path / "a.png")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stderr.strip().splitlines()[-1])
    assert info["method"] == "exact" and info["groups"] > 0
    hits = primary_hits(lighting.scene, Camera(width=24, height=20, **SPHERES_VIEW))
    image, _ = shade_tiles(lighting, hits)
    assert np.array_equal(np.load(tmp_path / "a.npy"), image.reshape(20, 24, 3).astype(np.float32))
