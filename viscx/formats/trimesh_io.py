"""Every mesh format other than OBJ, through trimesh (PLY, STL, OFF, GLB, ...)."""

from pathlib import Path

import numpy as np

from viscx.errors import ViscxError
from viscx.formats.atomic import register_input
from viscx.memory import memory_budget
from viscx.scene.soup import PolygonSoup


def read_mesh(path):
    """Read a mesh file with trimesh into a :class:`PolygonSoup` of triangles
    (:func:`soup_of_trimesh`; a single mesh's group is named after the file)."""
    import trimesh

    path = Path(path)
    check_header(path)
    try:
        loaded = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # trimesh raises many kinds for unreadable files
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if isinstance(exc, ImportError):  # trimesh's fallback for a file it could not parse needs an optional module
            reason = f"corrupt or unsupported file (trimesh's fallback needs the missing module {exc.name!r})"
        raise ViscxError(f"cannot read {path} as a mesh: {reason}") from None
    return soup_of_trimesh(loaded, path.stem, str(path), (path.name,))


def soup_of_trimesh(mesh, name, where=None, names=()):
    """A trimesh mesh or scene as a :class:`PolygonSoup` of triangles.

    Each geometry of a trimesh scene becomes a group named after it (sorted by
    name, so the result does not depend on hashing), its instances placed by the
    scene graph; a single mesh becomes one group named ``name``.

    Parameters
    ----------
    mesh : trimesh.Trimesh or trimesh.Scene
    name : str
        The group of a single mesh (a Trimesh, or a scene of one geometry named
        ``geometry_0`` or one of ``names``).
    where : str, optional
        Its origin in messages (default ``name``).
    names : tuple of str
        Geometry names that also mean a single unnamed mesh (a file's name).
    """
    import trimesh

    where = where or name
    single = isinstance(mesh, trimesh.Trimesh)
    if single:
        mesh = trimesh.Scene(mesh)
    if not isinstance(mesh, trimesh.Scene):
        raise ViscxError(f"{where}: not a scene file, a trimesh mesh or scene, or a viscx Scene "
                         f"(got {type(mesh).__name__})")
    loaded, geometries = mesh, []
    for key in sorted(loaded.geometry):
        geom = loaded.geometry[key]
        if not hasattr(geom, "faces") or len(geom.faces) == 0:
            continue
        # apply the scene graph's transforms of every instance of this geometry
        for node in sorted(loaded.graph.geometry_nodes.get(key, [key])):
            transform, _ = loaded.graph[node]
            vertices = trimesh.transform_points(np.asarray(geom.vertices, dtype=np.float64), transform)
            geometries.append((key if node == key else node, vertices, np.asarray(geom.faces, dtype=np.int64)))
    if not geometries:
        raise ViscxError(f"{where}: no faces")
    if len(geometries) == 1 and (single or geometries[0][0] in ("geometry_0", *names)):
        geometries = [(name, geometries[0][1], geometries[0][2])]
    vertices, faces, groups = [], [], []
    base = 0
    for gid, (_, v, f) in enumerate(geometries):
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ViscxError(f"{where}: face index out of range")
        vertices.append(v)
        faces.append(f + base)
        groups.append(np.full(len(f), gid, dtype=np.int64))
        base += len(v)
    verts = np.concatenate(vertices)
    if not np.all(np.isfinite(verts)):
        raise ViscxError(f"{where}: a vertex has a NaN or infinite coordinate")
    tris = np.concatenate(faces)
    return PolygonSoup(
        vertices=verts,
        polygon_offsets=np.arange(0, 3 * len(tris) + 1, 3, dtype=np.int64),
        polygon_vertices=tris.reshape(-1),
        polygon_group=np.concatenate(groups),
        group_names=[g[0] for g in geometries],
    )


# Bytes each value takes at least: binary PLY by type, ASCII PLY one digit and a separator.
_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
              "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
_HEADER_LIMIT = 1 << 16


def check_header(path):
    """Refuse, before a reader allocates anything, a file whose header declares more than
    the file can hold (PLY element counts, OFF counts) or more than the memory budget, and
    a glTF scene whose buffers or images lie outside its folder."""
    suffix = path.suffix.lower()
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(_HEADER_LIMIT)
    if suffix == ".ply":
        declared = _ply_bytes(head)
    elif suffix == ".off":
        declared = _off_bytes(head)
    elif suffix in (".gltf", ".glb"):  # the whole JSON of a .gltf (trimesh reads it all too)
        _check_gltf_references(path, path.read_bytes() if suffix == ".gltf" else None)
        return
    else:
        return
    if declared is None:
        return  # not a header viscx understands: the reader reports it
    needed, pieces = declared
    if needed > size:
        raise ViscxError(f"{path}: the header declares {pieces} but the file holds {size} bytes; truncated or damaged")
    if needed * 8 > memory_budget():
        raise ViscxError(f"{path}: the header declares {pieces}, over the memory budget (VISCX_MEMORY_BUDGET)")


def _ply_bytes(head):
    """(least bytes the body needs, what the header declares) of a PLY header, or None."""
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None
    lines = head[:end].decode("ascii", "replace").splitlines()
    ascii_body = any(line.split()[:2] == ["format", "ascii"] for line in lines)
    total, element, counts = 0, None, []
    for tokens in (line.split() for line in lines):
        if tokens[:1] == ["element"] and len(tokens) == 3:
            try:
                element = int(tokens[2])
            except ValueError:
                return None
            counts.append(f"{element} {tokens[1]}")
        elif tokens[:1] == ["property"] and element is not None and len(tokens) >= 3:
            if tokens[1] == "list":  # the count of an empty list
                per = 2 if ascii_body else _PLY_SIZES.get(tokens[2], 1)
            else:
                per = 2 if ascii_body else _PLY_SIZES.get(tokens[1], 1)
            total += element * per
    return total, ", ".join(counts)


def _off_bytes(head):
    """(least bytes the body needs, what the header declares) of an OFF header, or None:
    a vertex takes at least "0 0 0\n", a face at least "0\n"."""
    tokens = []
    for line in head.decode("ascii", "replace").splitlines():
        line = line.split("#", 1)[0].split()
        tokens.extend(line)
        if len(tokens) >= 4:
            break
    if not tokens or not tokens[0].endswith("OFF"):
        return None
    try:
        n_vertices, n_faces = int(tokens[1]), int(tokens[2])
    except (IndexError, ValueError):
        return None
    return 6 * n_vertices + 2 * n_faces, f"{n_vertices} vertices and {n_faces} faces"


def _check_gltf_references(path, text=None):
    """Every buffer and image of a glTF (``text``) or GLB file must be embedded (``data:``)
    or a file inside the scene's folder."""
    import struct
    from urllib.parse import unquote

    from viscx.formats.obj import inside_folder
    from viscx.formats.validate import load_json

    if text is None:  # GLB: 12-byte header, then the JSON chunk (length, type, bytes)
        with open(path, "rb") as fh:
            header = fh.read(20)
            if len(header) < 20 or header[:4] != b"glTF" or header[16:20] != b"JSON":
                return
            (length,) = struct.unpack("<I", header[12:16])
            if length > path.stat().st_size:
                raise ViscxError(f"{path}: the GLB JSON chunk declares {length} bytes, more than the file holds")
            text = fh.read(length)
    doc = load_json(text, f"{path}: the glTF JSON")
    if not isinstance(doc, dict):
        return
    for key in ("buffers", "images"):
        for item in doc.get(key) or []:
            uri = item.get("uri") if isinstance(item, dict) else None
            if not isinstance(uri, str) or uri.startswith("data:"):
                continue
            if ":" in uri.split("/", 1)[0]:
                raise ViscxError(f"{path}: {key[:-1]} uri {uri[:80]!r} is not a file beside the scene; viscx reads no URL")
            inside_folder(path, unquote(uri), f"{key[:-1]} uri")


def read_soup(path):
    """Read any supported scene file (OBJ by viscx, the rest by trimesh)."""
    path = Path(path)
    if not path.exists():
        raise ViscxError(f"no such file: {path}")
    if path.is_dir():
        raise ViscxError(f"{path} is a directory, not a scene file")
    if path.stat().st_size == 0:
        raise ViscxError(f"{path} is empty")
    register_input(path)
    if path.suffix.lower() == ".obj":
        from viscx.formats.obj import read_obj

        return read_obj(path)
    return read_mesh(path)
