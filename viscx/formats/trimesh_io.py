"""Every mesh format other than OBJ, through trimesh (PLY, STL, OFF, GLB, ...)."""

from pathlib import Path

import numpy as np

from viscx.errors import ViscxError
from viscx.scene.soup import PolygonSoup


def read_mesh(path):
    """Read a mesh file with trimesh into a :class:`PolygonSoup` of triangles.

    Each geometry of a trimesh scene becomes a group named after it (sorted by
    name, so the result does not depend on hashing); a single mesh becomes one
    group named after the file.
    """
    import trimesh

    path = Path(path)
    try:
        loaded = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # trimesh raises many kinds for unreadable files
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if isinstance(exc, ImportError):  # trimesh's fallback for a file it could not parse needs an optional module
            reason = f"corrupt or unsupported file (trimesh's fallback needs the missing module {exc.name!r})"
        raise ViscxError(f"cannot read {path} as a mesh: {reason}") from None
    geometries = []
    for name in sorted(loaded.geometry):
        geom = loaded.geometry[name]
        if not hasattr(geom, "faces") or len(geom.faces) == 0:
            continue
        # apply the scene graph's transforms of every instance of this geometry
        for node in sorted(loaded.graph.geometry_nodes.get(name, [name])):
            transform, _ = loaded.graph[node]
            vertices = trimesh.transform_points(np.asarray(geom.vertices, dtype=np.float64), transform)
            geometries.append((name if node == name else node, vertices, np.asarray(geom.faces, dtype=np.int64)))
    if not geometries:
        raise ViscxError(f"{path}: no faces")
    if len(geometries) == 1 and geometries[0][0] in ("geometry_0", path.name):
        geometries = [(path.stem, geometries[0][1], geometries[0][2])]
    vertices, faces, groups = [], [], []
    base = 0
    for gid, (_, v, f) in enumerate(geometries):
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ViscxError(f"{path}: face index out of range")
        vertices.append(v)
        faces.append(f + base)
        groups.append(np.full(len(f), gid, dtype=np.int64))
        base += len(v)
    verts = np.concatenate(vertices)
    if not np.all(np.isfinite(verts)):
        raise ViscxError(f"{path}: a vertex has a NaN or infinite coordinate")
    tris = np.concatenate(faces)
    return PolygonSoup(
        vertices=verts,
        polygon_offsets=np.arange(0, 3 * len(tris) + 1, 3, dtype=np.int64),
        polygon_vertices=tris.reshape(-1),
        polygon_group=np.concatenate(groups),
        group_names=[g[0] for g in geometries],
    )


def read_soup(path):
    """Read any supported scene file (OBJ by viscx, the rest by trimesh)."""
    path = Path(path)
    if not path.exists():
        raise ViscxError(f"no such file: {path}")
    if path.is_dir():
        raise ViscxError(f"{path} is a directory, not a scene file")
    if path.stat().st_size == 0:
        raise ViscxError(f"{path} is empty")
    if path.suffix.lower() == ".obj":
        from viscx.formats.obj import read_obj

        return read_obj(path)
    return read_mesh(path)
