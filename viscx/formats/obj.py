"""Wavefront OBJ (and MTL) reader that keeps group names, polygons and materials.

trimesh's OBJ path renames groups (an ``o`` and a ``g`` become ``object_group``),
orders them by hash and triangulates, so viscx reads OBJ itself: ``o`` and ``g``
name the current group (the latest statement wins, so a ``g`` inside an ``o``
names its faces; ``g a b`` puts them in group ``a``: a face belongs to one
group), ``usemtl`` the current material, ``f`` lines are polygons
of any size (``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``, negative indices relative to
the vertices read so far). Texture coordinates, normals, lines and curves are
ignored. Materials come from ``mtllib`` files beside the OBJ (``Kd``, ``Ke``).
"""

import re
from pathlib import Path

import numpy as np

from viscx.errors import ViscxError
from viscx.scene.soup import PolygonSoup

DEFAULT_GROUP = "default"
#: a material library is text of a few lines per material
MAX_LIBRARY_BYTES = 64 << 20
_INDEX = re.compile(r"-?[0-9]+")


def _float_tokens(tokens, path, lineno, count):
    try:
        values = [float(t) for t in tokens[:count]]
    except ValueError:
        raise ViscxError(f"{path}:{lineno}: expected {count} numbers, got {' '.join(tokens)!r}") from None
    if len(values) < count:
        raise ViscxError(f"{path}:{lineno}: expected {count} numbers, got {len(values)}")
    return values


def inside_folder(scene, name, what):
    """The file ``name`` that ``scene`` refers to (``mtllib``, a glTF buffer), or ViscxError
    when it lies outside the scene's folder (after links are resolved: ``/dev/zero``,
    ``../secret``) or is not a regular file. A missing file is returned as it is (the
    reader treats it as absent)."""
    folder = Path(scene).resolve().parent
    target = (folder / name).resolve()
    if folder not in target.parents:
        raise ViscxError(f"{scene}: {what} {name!r} is outside the scene's folder; viscx reads only files beside it")
    if target.exists() and not target.is_file():
        raise ViscxError(f"{scene}: {what} {name!r} is not a regular file")
    if target.exists() and target.stat().st_size > MAX_LIBRARY_BYTES:
        raise ViscxError(f"{scene}: {what} {name!r} is larger than {MAX_LIBRARY_BYTES >> 20} MiB")
    return target


def read_mtl(path):
    """Materials of an MTL file: ``{name: (kd (3,) float, ke (3,) float)}``."""
    materials = {}
    current = None
    try:
        text = Path(path).read_text(errors="replace")
    except OSError:
        return materials
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        key = tokens[0]
        if key == "newmtl":
            current = " ".join(tokens[1:]) or f"material{len(materials)}"
            materials[current] = [np.full(3, 0.5), np.zeros(3)]
        elif current is not None and key in ("Kd", "Ke") and len(tokens) >= 2:
            values = _float_tokens(tokens[1:], path, lineno, 1 if len(tokens) == 2 else 3)
            vec = np.array(values * 3 if len(values) == 1 else values, dtype=np.float64)
            if not np.all(np.isfinite(vec)):
                raise ViscxError(f"{path}:{lineno}: non-finite {key}")
            materials[current][0 if key == "Kd" else 1] = vec
    return materials


def read_obj(path):
    """Read an OBJ file into a :class:`PolygonSoup`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    soup : PolygonSoup
        Polygons in file order; groups and materials in order of first use.

    Raises
    ------
    ViscxError
        On malformed numbers, non-finite coordinates or out-of-range indices.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ViscxError(f"cannot read {path}: {exc.strerror}") from None
    if b"\x00" in raw:  # anywhere: a text file with a binary tail is not an OBJ either
        raise ViscxError(f"{path}: not a text OBJ file (binary data)")
    text = raw.decode("utf-8", errors="replace").removeprefix("\ufeff")  # the BOM some Windows tools write

    vertices = []
    poly_vertices, poly_sizes, poly_group, poly_material = [], [], [], []
    groups, group_ids = [], {}
    mtl_files, material_names, material_ids = [], [], {}
    group = None
    material = -1

    def group_id(name):
        if name not in group_ids:
            group_ids[name] = len(groups)
            groups.append(name)
        return group_ids[name]

    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key == "v":
            vertices.append(_float_tokens(tokens[1:], path, lineno, 3))
        elif key == "f":
            n = len(vertices)
            face = []
            for token in tokens[1:]:
                head = token.split("/", 1)[0]
                if not _INDEX.fullmatch(head):  # int() would also take "+2" and "1_1"
                    raise ViscxError(f"{path}:{lineno}: bad vertex index {token!r}")
                index = int(head)
                index = index - 1 if index > 0 else n + index
                if index < 0 or index >= n or head in ("0", "-0"):
                    raise ViscxError(f"{path}:{lineno}: vertex index {head} out of range (1..{n})")
                face.append(index)
            if len(face) < 3:
                raise ViscxError(f"{path}:{lineno}: a face needs at least 3 vertices")
            poly_vertices.extend(face)
            poly_sizes.append(len(face))
            poly_group.append(group_id(group if group is not None else DEFAULT_GROUP))
            poly_material.append(material)
        elif key in ("o", "g"):
            group = tokens[1] if len(tokens) > 1 else DEFAULT_GROUP
        elif key == "usemtl":
            name = " ".join(tokens[1:])
            if name not in material_ids:
                material_ids[name] = len(material_names)
                material_names.append(name)
            material = material_ids[name]
        elif key == "mtllib":
            mtl_files.extend(tokens[1:])

    verts = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(verts)):
        bad = int(np.argwhere(~np.isfinite(verts))[0, 0]) + 1
        raise ViscxError(f"{path}: vertex {bad} has a NaN or infinite coordinate")

    library = {}
    for name in mtl_files:
        library.update(read_mtl(inside_folder(path, name, "mtllib")))
    kd = np.array([library.get(m, [np.full(3, 0.5)])[0] for m in material_names]).reshape(-1, 3)
    ke = np.array([library.get(m, [None, np.zeros(3)])[1] for m in material_names]).reshape(-1, 3)

    return PolygonSoup(
        vertices=verts,
        polygon_offsets=np.concatenate([[0], np.cumsum(poly_sizes, dtype=np.int64)]).astype(np.int64),
        polygon_vertices=np.asarray(poly_vertices, dtype=np.int64),
        polygon_group=np.asarray(poly_group, dtype=np.int64),
        group_names=groups,
        polygon_material=np.asarray(poly_material, dtype=np.int64),
        material_names=material_names,
        material_kd=kd.astype(np.float64),
        material_ke=ke.astype(np.float64),
    )
