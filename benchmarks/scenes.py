"""Scenes for benchmarks, generated deterministically from a seed."""

import numpy as np
import trimesh

from viscx.scene import PolygonSoup, build_scene


def spheres_in_room(n_spheres=6, subdivisions=5, seed=0):
    """A closed box room with ``n_spheres`` icospheres of 20·4^subdivisions triangles each.

    With the defaults: 122,880 sphere triangles plus the room's 12.
    """
    rng = np.random.default_rng(seed)
    room = trimesh.creation.box(extents=(20, 10, 20))
    room.invert()  # faces look inward
    meshes = [room]
    for _ in range(n_spheres):
        sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0 + rng.random())
        sphere.apply_translation(rng.uniform([-7, -2, -7], [7, 2, 7]))
        meshes.append(sphere)
    vertices = np.concatenate([m.vertices for m in meshes])
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    faces = np.concatenate([m.faces + o for m, o in zip(meshes, offsets)])
    groups = np.concatenate([np.full(len(m.faces), i) for i, m in enumerate(meshes)])
    soup = PolygonSoup(
        vertices=vertices,
        polygon_offsets=np.arange(0, 3 * len(faces) + 1, 3),
        polygon_vertices=faces.reshape(-1),
        polygon_group=groups,
        group_names=["room"] + [f"sphere{i}" for i in range(n_spheres)],
    )
    return build_scene(soup, source=f"spheres_in_room(n={n_spheres}, subdivisions={subdivisions}, seed={seed})")
