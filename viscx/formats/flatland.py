"""File layouts of the 2-D (flatland) visibility complex: HDF5 and msgpack.

HDF5 (``format = "viscx-flatland"``, ``format_version = 1``)
-----------------------------------------------------------
Root attributes: ``format``, ``format_version``, ``viscx_version``, ``epsilon``,
``scene_sha256`` (SHA-256 of the canonical scene JSON), ``n_objects``.

- ``scene/``: ``kind`` (n,) int8 (0 circle, 1 polygon, 2 segment), ``vert_start`` (n+1,) int64,
  ``verts`` (V, 2) float64, ``radius``, ``emission``, ``reflectance`` (n,) float64,
  ``names`` (n,) utf-8 strings.
- ``vertices/``: every ``v_*`` array of :class:`viscx.flatland.complex.FlatComplex`
  without the prefix (``key``, ``obj``, ``side``, ``tail``, ``head``, ``theta``, ``tau``
  (the infinitesimal offset of a vertex of a resolved degenerate line, 0 elsewhere; files
  written before it existed read as 0), ``p``, ``q``, ``length``, ``seg``, ``edges``,
  ``faces``), sorted by ``key``.
- ``edges/``: the ``e_*`` arrays (``obj``, ``side``, ``tail``, ``head``, ``verts``, ``theta``,
  ``integral``, ``arclength``, ``faces``).
- ``faces/``: the ``f_*`` arrays (``pair``, ``area``, ``strings``, ``bounded``,
  ``area_twin``, CSR ``edge_start``/``edge``/``edge_upper``/``edge_reversed``,
  ``vert_start``/``vert``/``vert_sign``).  The unbounded face (lines missing every
  object) has area ``inf``.
- ``formfactors/``: ``F_area`` and ``F_strings`` (n, n+1), column n = the blue sky.
- ``mesh/`` (optional, after ``viscx flatland radiosity``): the discontinuity mesh and the
  radiosity solution (see :mod:`viscx.flatland.mesh`), with ``elem_H`` the irradiance,
  ``elem_edge`` each element's boundary edge (segment side) and ``sky_radiance``.

Object id −1 is the blue sky everywhere.  Datasets are written without timestamps, so the
same scene gives byte-identical content.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np

from viscx.errors import ViscxError
from viscx.formats.atomic import atomic_path

FORMAT = "viscx-flatland"
FORMAT_VERSION = 1
_GROUPS = {"vertices": "v_", "edges": "e_", "faces": "f_"}


def scene_sha256(scene) -> str:
    doc = json.dumps(scene.to_json(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(doc.encode()).hexdigest()


def _scene_arrays(scene):
    return {"kind": scene.kind, "vert_start": scene.vert_start, "verts": scene.verts, "radius": scene.radius,
            "emission": scene.emission, "reflectance": scene.reflectance}


def write_hdf5(path, cx, mesh=None):
    """Write a :class:`FlatComplex` (and optionally a radiosity mesh dict) atomically."""
    import h5py

    from viscx import __version__

    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w", track_order=False) as f:
            f.attrs["format"] = FORMAT
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["viscx_version"] = __version__
            f.attrs["epsilon"] = float(cx.eps)
            f.attrs["scene_sha256"] = scene_sha256(cx.scene)
            f.attrs["n_objects"] = cx.scene.n
            g = f.create_group("scene")
            for k, v in _scene_arrays(cx.scene).items():
                g.create_dataset(k, data=np.asarray(v), track_times=False)
            g.create_dataset("names", data=np.array(cx.scene.names, dtype=object),
                             dtype=h5py.string_dtype("utf-8"), track_times=False)
            for grp, prefix in _GROUPS.items():
                gg = f.create_group(grp)
                for k in sorted(cx.arrays):
                    if k.startswith(prefix):
                        gg.create_dataset(k[len(prefix):], data=np.asarray(cx.arrays[k]), track_times=False)
            gf = f.create_group("formfactors")
            for k in ("F_area", "F_strings"):
                gf.create_dataset(k, data=cx.arrays[k], track_times=False)
            if mesh is not None:
                gm = f.create_group("mesh")
                for k in sorted(mesh):
                    gm.create_dataset(k, data=np.asarray(mesh[k]), track_times=False)


def read_hdf5(path, with_mesh=False):
    """Read a flatland HDF5 file back into a :class:`FlatComplex` (and the mesh dict)."""
    import h5py

    from viscx.flatland.complex import FlatComplex
    from viscx.flatland.scene import Scene

    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError) as exc:
        raise ViscxError(f"{path}: not a readable HDF5 file ({exc})") from None
    with f:
        if f.attrs.get("format") != FORMAT:
            raise ViscxError(f"{path}: not a viscx flatland file (format attribute is {f.attrs.get('format')!r})")
        if int(f.attrs.get("format_version", -1)) != FORMAT_VERSION:
            raise ViscxError(f"{path}: unsupported flatland format version {f.attrs.get('format_version')}")
        g = f["scene"]
        names = [x.decode() if isinstance(x, bytes) else str(x) for x in g["names"][()]]
        scene = Scene(g["kind"][()], g["vert_start"][()], g["verts"][()], g["radius"][()], g["emission"][()],
                      g["reflectance"][()], names)
        arrays = {}
        for grp, prefix in _GROUPS.items():
            for k in f[grp]:
                arrays[prefix + k] = f[grp][k][()]
        for k in f["formfactors"]:
            arrays[k] = f["formfactors"][k][()]
        mesh = {k: f["mesh"][k][()] for k in f["mesh"]} if "mesh" in f else None
        cx = FlatComplex(scene=scene, eps=float(f.attrs["epsilon"]), arrays=arrays)
    return (cx, mesh) if with_mesh else cx


def _pack_array(a):
    a = np.ascontiguousarray(a)
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.tobytes()}


def _unpack_array(d):
    return np.frombuffer(d["data"], dtype=np.dtype(d["dtype"])).reshape(d["shape"]).copy()


def write_msgpack(path, cx, mesh=None):
    """msgpack export: ``{"format", "format_version", "epsilon", "scene": {...}, "names",
    "arrays": {name: {"dtype", "shape", "data"}}, "mesh": {...} or None}`` (little-endian
    raw array bytes, numpy dtype strings)."""
    import msgpack

    doc = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "epsilon": float(cx.eps),
        "scene": {k: _pack_array(v) for k, v in _scene_arrays(cx.scene).items()},
        "names": list(cx.scene.names),
        "arrays": {k: _pack_array(cx.arrays[k]) for k in sorted(cx.arrays)},
        "mesh": None if mesh is None else {k: _pack_array(mesh[k]) for k in sorted(mesh)},
    }
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(msgpack.packb(doc, use_bin_type=True))


def read_msgpack(path, with_mesh=False):
    import msgpack

    from viscx.flatland.complex import FlatComplex
    from viscx.flatland.scene import Scene

    try:
        with open(path, "rb") as fh:
            doc = msgpack.unpackb(fh.read(), raw=False)
    except (OSError, ValueError, msgpack.exceptions.ExtraData) as exc:
        raise ViscxError(f"{path}: not a readable msgpack file ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ViscxError(f"{path}: not a viscx flatland msgpack file")
    s = {k: _unpack_array(v) for k, v in doc["scene"].items()}
    scene = Scene(s["kind"], s["vert_start"], s["verts"], s["radius"], s["emission"], s["reflectance"],
                  list(doc["names"]))
    cx = FlatComplex(scene=scene, eps=doc["epsilon"], arrays={k: _unpack_array(v) for k, v in doc["arrays"].items()})
    mesh = None if doc.get("mesh") is None else {k: _unpack_array(v) for k, v in doc["mesh"].items()}
    return (cx, mesh) if with_mesh else cx


def read_any(path, with_mesh=False):
    """Read a flatland complex from ``.h5``/``.hdf5`` or ``.msgpack``/``.mpk`` by suffix."""
    p = str(path).lower()
    if p.endswith((".msgpack", ".mpk")):
        return read_msgpack(path, with_mesh)
    return read_hdf5(path, with_mesh)


def write_any(path, cx, mesh=None):
    p = str(path).lower()
    if p.endswith((".msgpack", ".mpk")):
        return write_msgpack(path, cx, mesh)
    return write_hdf5(path, cx, mesh)
