"""Scenes for benchmarks, generated deterministically from a seed."""

import numpy as np
import trimesh

from viscx.scene import PolygonSoup, build_scene


def spheres_in_room(n_spheres=6, subdivisions=5, seed=0):
    """A closed box room with ``n_spheres`` icospheres of 20·4^subdivisions triangles each.

    With the defaults: 122,880 sphere triangles plus the room's 12.
    """
    soup = spheres_in_room_soup(n_spheres, subdivisions, seed)
    return build_scene(soup, source=f"spheres_in_room(n={n_spheres}, subdivisions={subdivisions}, seed={seed})")


#: Where the light hangs in :func:`spheres_in_room` (under the ceiling, y = 5).
SPHERES_LIGHT = (0.0, 4.5, 0.0)


def spheres_in_room_soup(n_spheres=6, subdivisions=5, seed=0, quad_light=False):
    """The polygons of :func:`spheres_in_room` (a PolygonSoup, e.g. for :func:`write_obj`);
    ``quad_light``: plus a 2 × 2 square light (group ``light``, facing down) centred at
    :data:`SPHERES_LIGHT`, 0.5 under the ceiling, and the room's faces in groups floor,
    ceiling and walls (group ``room`` otherwise)."""
    rng = np.random.default_rng(seed)
    meshes = []
    for _ in range(n_spheres):
        sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0 + rng.random())
        sphere.apply_translation(rng.uniform([-7, -2, -7], [7, 2, 7]))
        meshes.append(sphere)
    return _in_room(meshes, [f"sphere{i}" for i in range(n_spheres)], quad_light)


def tori_in_room_soup(sections=180, n_tori=3, seed=0):
    """Tessellated tori in the room of :func:`spheres_in_room_soup` (its light and groups):
    ``n_tori`` tori (radii 1.5 and 0.5) of ``sections`` × ``sections // 2`` quads, each as
    two triangles (with the default 97,214 triangles in all), turned at random. The ring of
    quads on each torus' top, and on its bottom, lies in one plane: the scene's cleaning
    merges it into one face with a hole, an annulus (docs/queries.md, "A closed solid whose
    faces have holes")."""
    rng = np.random.default_rng(seed)
    meshes = []
    for _ in range(n_tori):
        torus = trimesh.creation.torus(major_radius=1.5, minor_radius=0.5, major_sections=sections,
                                       minor_sections=max(8, sections // 2))
        torus.apply_transform(trimesh.transformations.random_rotation_matrix(rng.random(3)))
        torus.apply_translation(rng.uniform([-6, -2, -6], [6, 1, 6]))
        meshes.append(torus)
    return _in_room(meshes, [f"torus{i}" for i in range(n_tori)], True)


def open_shells_in_room_soup(subdivisions=5, n_shells=6, seed=0):
    """Open shells, as scans without their undersides, in the room of
    :func:`spheres_in_room_soup` (its light and groups): ``n_shells`` icospheres whose
    triangles beyond a plane at a random tilt (0.3 of the radius from the centre) are left
    out (with the default 73,793 triangles in all): no closed solid (docs/queries.md, "An
    open scanned shell")."""
    rng = np.random.default_rng(seed)
    meshes = []
    for _ in range(n_shells):
        shell = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0 + rng.random())
        axis = rng.normal(size=3)
        keep = shell.triangles_center @ (axis / np.linalg.norm(axis)) > -0.3
        shell = trimesh.Trimesh(shell.vertices, shell.faces[keep], process=False)
        shell.apply_translation(rng.uniform([-7, -2, -7], [7, 2, 7]))
        meshes.append(shell)
    return _in_room(meshes, [f"shell{i}" for i in range(n_shells)], True)


def columns_in_room_soup(sections=256, n_columns=4, seed=0):
    """Round columns from floor to ceiling in the room of :func:`spheres_in_room_soup` (its
    light and groups): ``n_columns`` closed prisms of ``sections`` sides (radius 0.4, in a
    row along x, at random z), their bottoms on the floor (y = −5) and their tops on the
    ceiling: a convex box of ``sections`` + 2 planes each, resting on both (docs/queries.md,
    "Columns resting on the floor"). With the default 4,110 triangles."""
    rng = np.random.default_rng(seed)
    meshes = []
    for k in range(n_columns):
        column = trimesh.creation.cylinder(radius=0.4, height=10.0, sections=sections)
        column.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
        v = column.vertices.copy()
        ends = np.abs(np.abs(v[:, 1]) - 5.0) < 1e-9  # the caps' rounded heights, on floor and ceiling exactly
        v[ends, 1] = np.sign(v[ends, 1]) * 5.0
        v += [-6.0 + 4.0 * k, 0.0, rng.uniform(-5, 5)]
        meshes.append(trimesh.Trimesh(v, column.faces, process=False))
    return _in_room(meshes, [f"column{k}" for k in range(n_columns)], True)


def scans_on_floor_soup(subdivisions=4, n_scans=6, seed=0):
    """Open scans standing on the floor of the room of :func:`spheres_in_room_soup` (its
    light and groups): ``n_scans`` icospheres cut flat by the floor (y = −5) 0.6 of their
    radius below their centres, the cut left open (a scan has no underside), the cut's
    points exactly on the floor: each shell meets the floor along a polygon, overhanging it
    (docs/queries.md, "Not done yet"). With the default 25,382 triangles."""
    rng = np.random.default_rng(seed)
    meshes = []
    for _ in range(n_scans):
        r = 1.0 + rng.random()
        sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=r)
        sphere.apply_translation([rng.uniform(-7, 7), -5.0 + 0.6 * r, rng.uniform(-7, 7)])
        meshes.append(_cut_above(sphere.triangles, -5.0))
    return _in_room(meshes, [f"scan{k}" for k in range(n_scans)], True)


def _cut_above(triangles, y):
    """The parts of triangles (t, 3, 3) above the plane at height ``y``
    (:func:`viscx.geometry.formfactor.clip_to_hemisphere`, the crossing points put on the
    plane exactly), fanned into triangles, as one mesh."""
    from viscx.geometry.formfactor import clip_to_hemisphere

    v, f = [], []
    for tri in triangles:
        kept = clip_to_hemisphere(tri, [0.0, y, 0.0], [0.0, 1.0, 0.0])
        if len(kept) < 3:
            continue
        on = ~np.any(np.all(kept[:, None, :] == tri[None], axis=2), axis=1)  # the crossing points
        kept[on, 1] = y
        f += [[len(v), len(v) + j, len(v) + j + 1] for j in range(1, len(kept) - 1)]
        v += list(kept)
    mesh = trimesh.Trimesh(np.array(v), np.array(f), process=False)
    mesh.merge_vertices()
    return mesh


def _in_room(meshes, names, quad_light):
    """The meshes (named) in a 20 × 10 × 20 room facing in, as one soup of triangles; with
    ``quad_light`` the light of :func:`spheres_in_room_soup` and the room's faces in groups
    floor, ceiling and walls."""
    room = trimesh.creation.box(extents=(20, 10, 20))
    room.invert()  # faces look inward
    meshes, names = [room] + list(meshes), ["room"] + list(names)
    if quad_light:  # two triangles wound to face -y
        x, y, z = SPHERES_LIGHT
        meshes.append(trimesh.Trimesh([[x - 1, y, z - 1], [x + 1, y, z - 1], [x + 1, y, z + 1], [x - 1, y, z + 1]],
                                      [[0, 1, 2], [0, 2, 3]], process=False))
        names.append("light")
    vertices = np.concatenate([m.vertices for m in meshes])
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    faces = np.concatenate([m.faces + o for m, o in zip(meshes, offsets)])
    groups = np.concatenate([np.full(len(m.faces), i) for i, m in enumerate(meshes)])
    if quad_light:  # the room's triangles by their inward normal: floor (+y), ceiling (-y), walls
        # (from the winding: trimesh keeps the outward face_normals after invert())
        t = room.triangles
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        up = n[:, 1] / np.linalg.norm(n, axis=1)
        groups[: len(room.faces)] = np.where(up > 0.5, 0, np.where(up < -0.5, len(names), len(names) + 1))
        names = ["floor"] + names[1:] + ["ceiling", "walls"]
    soup = PolygonSoup(
        vertices=vertices,
        polygon_offsets=np.arange(0, 3 * len(faces) + 1, 3),
        polygon_vertices=faces.reshape(-1),
        polygon_group=groups,
        group_names=names,
    )
    return soup


def random_boxes(n_polygons, seed=0, coverage=0.15, keep=None):
    """Boxes standing on a floor quad, about ``n_polygons`` faces (six per box plus the floor).

    A small city: each box has a random footprint (0.6–2.0 units a side), height
    (0.5–3.0) and rotation about y, and stands on the y = 0 floor; boxes never
    touch one another (a gap of at least 0.2 between their bounding circles), and
    they cover about ``coverage`` of the floor, whose side grows as the square
    root of the number of boxes (constant density). Deterministic in ``seed``.

    ``keep`` (box numbers, in the order the boxes are placed, from 0) keeps only those
    boxes, each where it stands in the whole city, on the whole city's floor: a smaller
    scene with the same neighbourhoods around the kept boxes (the others are still drawn).
    """
    rng = np.random.default_rng(seed)
    n_boxes = max(1, int(round((n_polygons - 1) / 6)))
    mean_area = 1.3**2
    side = float(np.sqrt(n_boxes * mean_area / coverage))
    vertices = [[0.0, 0.0, 0.0], [0.0, 0.0, side], [side, 0.0, side], [side, 0.0, 0.0]]
    polygons = [[0, 1, 2, 3]]
    groups = [0]
    names = ["floor"]
    placed = []
    unit = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (0.0, 1.0) for z in (-0.5, 0.5)])
    while len(placed) < n_boxes:
        size = np.array([rng.uniform(0.6, 2.0), rng.uniform(0.5, 3.0), rng.uniform(0.6, 2.0)])
        radius = 0.5 * float(np.hypot(size[0], size[2]))
        center = rng.uniform(radius + 0.2, side - radius - 0.2, 2)
        if any(np.hypot(*(center - c)) < radius + r + 0.2 for c, r in placed):
            continue
        placed.append((center, radius))
        angle = rng.uniform(0, np.pi / 2)
        if keep is not None and len(placed) - 1 not in keep:
            continue
        rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
        corners = (unit * size) @ rot.T + [center[0], 0.0, center[1]]
        base = len(vertices)
        vertices += corners.tolist()
        names.append(f"box{len(placed) - 1}")
        for quad in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
            polygons.append([base + i for i in quad])
            groups.append(len(names) - 1)
    sizes = [len(p) for p in polygons]
    soup = PolygonSoup(
        vertices=np.asarray(vertices, dtype=np.float64),
        polygon_offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        polygon_vertices=np.concatenate(polygons).astype(np.int64),
        polygon_group=np.asarray(groups, dtype=np.int64),
        group_names=names,
    )
    kept = "" if keep is None else f", keep={sorted(keep)}"
    return build_scene(soup, source=f"random_boxes(n_polygons={n_polygons}, seed={seed}{kept})")


def read_bunny(path):
    """The Stanford bunny of the npm registry (package ``bunny``: the scan of the Stanford 3D
    Scanning Repository, 1,839 vertices and 3,674 triangles), from its ``index.js``
    (``exports.positions=[[x, y, z], …]; exports.cells=[[i, j, k], …]``) or a JSON file
    ``{"positions": …, "cells": …}``. The data is not shipped with viscx (the repository asks
    to be credited and keeps its terms): ``npm pack bunny`` fetches it.

    Returns
    -------
    positions : (n, 3) float64
        y up, the ears at y ≈ 9.65.
    cells : (t, 3) int64
    """
    import json
    import re

    text = open(path, encoding="utf-8").read()
    if text.lstrip().startswith("{"):
        data = json.loads(text)
    else:
        data = {k: json.loads(v) for k, v in re.findall(r"exports\.(positions|cells)\s*=\s*(\[.*?\]\])", text, re.S)}
    return np.asarray(data["positions"], dtype=np.float64), np.asarray(data["cells"], dtype=np.int64)


#: Where a point light hangs in :func:`bunny_in_room` (under the quad light).
BUNNY_LIGHT = (0.0, 19.0, 0.0)


def decimate(positions, cells, triangles):
    """A mesh simplified to about ``triangles`` triangles by quadric edge collapse
    (trimesh's ``simplify_quadric_decimation``; it needs the package ``fast-simplification``,
    a benchmark-only dependency: ``pip install fast-simplification``). Deterministic.

    Parameters
    ----------
    positions : (n, 3) float
    cells : (t, 3) int
    triangles : int

    Returns
    -------
    positions : (n', 3) float64
    cells : (t', 3) int64
    """
    mesh = trimesh.Trimesh(positions, cells, process=False).simplify_quadric_decimation(face_count=int(triangles))
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def bunny_in_room(path, room=30.0, height=20.0, light=4.0, light_drop=0.5, triangles=None):
    """The npm bunny (:func:`read_bunny`) standing on the floor of a closed room under a
    quad light: its lowest vertex on the floor (y = 0), the room ``room`` wide and deep
    and ``height`` high around it, the light a ``light``-wide square ``light_drop`` under
    the ceiling, above the bunny. Groups: floor, ceiling, wall_x0, wall_x1, wall_z0,
    wall_z1, light, bunny. ``triangles``: the bunny decimated to about that many
    triangles first (:func:`decimate`), for growth ladders.

    Returns
    -------
    PolygonSoup
    """
    positions, cells = read_bunny(path)
    if triangles is not None:
        positions, cells = decimate(positions, cells, triangles)
    positions = positions - [0.0, positions[:, 1].min(), 0.0]
    h, y, q = room / 2, height, light / 2
    box = np.array([[x, yy, z] for x in (-h, h) for yy in (0.0, y) for z in (-h, h)])  # index 4x + 2y + z
    quads = {"floor": (0, 1, 5, 4), "ceiling": (2, 6, 7, 3), "wall_x0": (0, 2, 3, 1), "wall_x1": (4, 5, 7, 6),
             "wall_z0": (0, 4, 6, 2), "wall_z1": (1, 3, 7, 5)}
    lamp = np.array([[-q, y - light_drop, -q], [q, y - light_drop, -q], [q, y - light_drop, q], [-q, y - light_drop, q]])
    vertices = np.concatenate([box, lamp, positions])
    polygons = [list(v) for v in quads.values()] + [[8, 9, 10, 11]] + (cells + 12).tolist()
    names = list(quads) + ["light", "bunny"]
    groups = list(range(7)) + [7] * len(cells)
    sizes = [len(p) for p in polygons]
    return PolygonSoup(
        vertices=vertices,
        polygon_offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        polygon_vertices=np.concatenate(polygons).astype(np.int64),
        polygon_group=np.asarray(groups, dtype=np.int64),
        group_names=names,
    )


def write_obj(path, soup):
    """Write a PolygonSoup as an OBJ file, one ``o`` group per group name (what
    ``viscx build`` and the scoped queries read)."""
    with open(path, "w", encoding="ascii") as out:
        out.write("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in soup.vertices.tolist()))
        off, pv = soup.polygon_offsets, soup.polygon_vertices + 1
        for g, name in enumerate(soup.group_names):
            out.write(f"o {name}\n")
            for i in np.flatnonzero(soup.polygon_group == g):
                out.write("f " + " ".join(map(str, pv[off[i]:off[i + 1]].tolist())) + "\n")


if __name__ == "__main__":
    import argparse
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from buildings import write_obj

    parser = argparse.ArgumentParser(description="Write a scanned-mesh benchmark scene as OBJ: six closed spheres, "
                                                 "three tori whose top rings are faces with holes, six open shells, "
                                                 "four round columns from floor to ceiling or six open scans standing "
                                                 "on the floor, in a room with a light (groups light, floor, ceiling, "
                                                 "walls).")
    parser.add_argument("scene", choices=["spheres", "tori", "shells", "columns", "scans"])
    parser.add_argument("--size", type=int, help="icosphere subdivisions (spheres, shells: 5; scans: 4) or sections "
                                                 "(tori: 180, columns: 256)")
    parser.add_argument("-o", "--output", required=True)
    args = parser.parse_args()
    if args.scene == "spheres":
        soup = spheres_in_room_soup(subdivisions=5 if args.size is None else args.size, quad_light=True)
    elif args.scene == "tori":
        soup = tori_in_room_soup(180 if args.size is None else args.size)
    elif args.scene == "shells":
        soup = open_shells_in_room_soup(5 if args.size is None else args.size)
    elif args.scene == "columns":
        soup = columns_in_room_soup(256 if args.size is None else args.size)
    else:
        soup = scans_on_floor_soup(4 if args.size is None else args.size)
    write_obj(soup, args.output)
    print(f"{args.output}: {len(soup.polygon_offsets) - 1} triangles")
