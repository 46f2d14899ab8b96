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
- ``update/``: what a local move / insert / remove needs beyond these (the topology's state
  in canonical form, the blocker table, the re-scanned degenerate lines, the opening gap;
  :func:`viscx.flatland.dynamic.update_arrays`, checked by
  :func:`viscx.flatland.dynamic.check_update_arrays`; docs/flatland.md).  Optional: a
  file without it is updated by deriving the state again.
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
from viscx.formats import validate
from viscx.formats.atomic import atomic_path, register_input

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
    from viscx.flatland.dynamic import update_arrays

    with atomic_path(path, stream=False) as tmp:
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
            upd = update_arrays(cx)
            if upd is not None:
                gu = f.create_group("update")
                for k in sorted(upd):
                    big = dict(compression="gzip", compression_opts=1, shuffle=True) if k == "blockers" else {}
                    gu.create_dataset(k, data=upd[k], track_times=False, **big)
            if mesh is not None:
                gm = f.create_group("mesh")
                for k in sorted(mesh):
                    gm.create_dataset(k, data=np.asarray(mesh[k]), track_times=False)


def read_hdf5(path, with_mesh=False):
    """Read a flatland HDF5 file back into a :class:`FlatComplex` (and the mesh dict),
    checked (:func:`check_complex`; HDF5 structure by :func:`viscx.formats.validate.check_structure`)."""
    import h5py

    register_input(path)
    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError) as exc:
        raise ViscxError(f"{path}: not a readable HDF5 file ({exc})") from None
    with f:
        if f.attrs.get("format") != FORMAT:
            raise ViscxError(f"{path}: not a viscx flatland file (format attribute is {f.attrs.get('format')!r})")
        version = f.attrs.get("format_version", -1)
        if not (np.ndim(version) == 0 and np.asarray(version).dtype.kind in "iu" and version == FORMAT_VERSION):
            raise ViscxError(f"{path}: unsupported flatland format version {version!r}")
        validate.check_structure(f, path)
        c = validate.Checker(path)
        g = f.get("scene")
        if not isinstance(g, h5py.Group):
            raise ViscxError(f"{path}: a flatland file without its scene (/scene)")
        scene = {name: c.read(g, name, "i" if name in ("kind", "vert_start") else "f", dims)
                 for name, dims in _SCENE_DIMS.items()}
        names = c.read(g, "names", "s", ("n",))
        arrays = {}
        for grp, prefix in (*_GROUPS.items(), ("formfactors", "")):
            group = f.get(grp)
            if not isinstance(group, h5py.Group):
                c.fail(f"/{grp}", "missing")
            for k in group:
                arrays[prefix + k] = _numbers(c, group, k)
        mesh = None
        if "mesh" in f:
            mesh = {k: _numbers(c, f["mesh"], k) for k in f["mesh"]}
        upd = {k: _numbers(c, f["update"], k) for k in f["update"]} if isinstance(f.get("update"), h5py.Group) else None
        eps = f.attrs.get("epsilon")
    cx = _complex(c, scene, names, arrays, eps, upd)
    return (cx, mesh) if with_mesh else cx


def _complex(c, scene, names, arrays, eps, upd):
    """The checked :class:`FlatComplex` of a file, with its checked update group."""
    from viscx.flatland.complex import FlatComplex
    from viscx.flatland.dynamic import check_update_arrays

    flat = check_complex(c, scene, names, arrays, eps)
    stored = None if upd is None else check_update_arrays(c, arrays, upd, flat.n)
    return FlatComplex(scene=flat, eps=float(eps), arrays=arrays, stored=stored)


_SCENE_DIMS = {"kind": ("n",), "vert_start": ("n+1",), "verts": ("V", 2), "radius": ("n",), "emission": ("n",),
               "reflectance": ("n",)}
# what the integer arrays of the complex name (-1 where nothing: the sky, no edge): its
# objects, support points, vertices, edges, faces
_IDS = {"obj": "n", "pair": "n", "tail": "n", "head": "n", "support": "V", "verts": "nv", "vert": "nv",
        "edges": "ne", "edge": "ne", "faces": "nf"}
# the float arrays that may hold inf (the unbounded face), never NaN
_INFINITE = ("f_area", "f_area_twin", "f_strings", "f_strings_twin")


def _numbers(c, group, name):
    """A dataset of numbers (bool, integers or floats, any shape)."""
    import h5py

    obj = group[name]
    where = f"{group.name}/{name}"
    if not isinstance(obj, h5py.Dataset):
        c.fail(where, "not a dataset")
    if obj.dtype.kind not in "biuf":
        c.fail(where, f"dtype {obj.dtype} is not numeric")
    return obj[()]


def check_complex(c, scene, names, arrays, eps):
    """The scene (as :func:`viscx.flatland.scene.make_scene` checks a scene file: convex,
    disjoint objects) and the complex's arrays (dtypes, shapes, ids in range, CSR lists,
    finite numbers) of a flatland file. Returns the :class:`Scene`."""
    from viscx.flatland.scene import CIRCLE, SEGMENT, Scene, make_scene

    where = str(c.path)
    if not (np.ndim(eps) == 0 and np.asarray(eps).dtype.kind in "iuf" and np.isfinite(eps) and eps > 0):
        raise ViscxError(f"{where}: the epsilon attribute {eps!r} is not a finite positive number")
    s = c.sizes
    c.offsets("/scene/vert_start", scene["vert_start"], s["V"], strict=True)
    c.within("/scene/kind", scene["kind"], CIRCLE, SEGMENT + 1)
    flat = Scene(scene["kind"].astype(np.int8), scene["vert_start"], scene["verts"], scene["radius"], scene["emission"],
                 scene["reflectance"], list(names))
    # every rule of a scene file, one line naming the object; its contact pairs are kept
    flat._contacts = make_scene(flat.to_json()["objects"])._contacts
    sizes = {"n": s["n"], "V": s["V"], "nv": len(arrays.get("v_key", ())), "ne": len(arrays.get("e_obj", ())),
             "nf": len(arrays.get("f_area", ()))}
    for name, a in arrays.items():
        path = f"/{dict(v=('vertices'), e='edges', f='faces').get(name[0], 'formfactors')}/{name.partition('_')[2] or name}"
        if name.startswith(("v_", "e_", "f_")) and not name.startswith(("f_edge", "f_vert")):
            count = sizes[{"v": "nv", "e": "ne", "f": "nf"}[name[0]]]
            if a.ndim == 0 or len(a) != count:
                c.fail(path, f"{a.shape[:1]} rows, expected {count}")
        ids = _IDS.get(name.partition("_")[2])
        if ids and a.dtype.kind in "iu":
            c.within(path, a, -1, sizes[ids])
        if a.dtype.kind == "f" and a.size:
            bad = np.isnan(a) if name in _INFINITE else ~np.isfinite(a)
            if bad.any():
                c.fail(path, "a NaN or infinite value")
    for csr, flat_name in (("f_edge_start", "f_edge"), ("f_vert_start", "f_vert")):
        if csr in arrays:
            starts = arrays[csr]
            if starts.ndim != 1 or len(starts) != sizes["nf"] + 1:
                c.fail(f"/faces/{csr[2:]}", f"shape {starts.shape}, expected ({sizes['nf'] + 1},)")
            c.offsets(f"/faces/{csr[2:]}", starts, len(arrays.get(flat_name, ())))
    for name in ("F_area", "F_strings"):
        if name not in arrays or arrays[name].shape != (s["n"], s["n"] + 1):
            c.fail(f"/formfactors/{name}", f"missing or not of shape ({s['n']}, {s['n'] + 1})")
    return flat


def _pack_array(a):
    a = np.ascontiguousarray(a)
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.tobytes()}


def _unpack_array(d, c, where):
    """A packed array (``{"dtype", "shape", "data"}``), checked: numbers only (an object
    dtype is refused), a shape the data's length holds exactly."""
    if not (isinstance(d, dict) and isinstance(d.get("dtype"), str) and isinstance(d.get("shape"), list)
            and isinstance(d.get("data"), bytes) and all(type(x) is int and x >= 0 for x in d["shape"])):
        c.fail(where, "not a packed array (dtype, shape, data)")
    try:
        dtype = np.dtype(d["dtype"])
    except (TypeError, ValueError):
        c.fail(where, f"unknown dtype {d['dtype'][:40]!r}")
    if dtype.kind not in "biuf" or dtype.hasobject:
        c.fail(where, f"dtype {dtype} is not numeric")
    if int(np.prod(d["shape"], dtype=object)) * dtype.itemsize != len(d["data"]):
        c.fail(where, f"shape {tuple(d['shape'])} does not match its {len(d['data'])} bytes")
    return np.frombuffer(d["data"], dtype=dtype).reshape(d["shape"]).copy()


def write_msgpack(path, cx, mesh=None):
    """msgpack export: ``{"format", "format_version", "epsilon", "scene": {...}, "names",
    "arrays": {name: {"dtype", "shape", "data"}}, "mesh": {...} or None}`` (little-endian
    raw array bytes, numpy dtype strings)."""
    import msgpack

    from viscx.flatland.dynamic import update_arrays

    doc = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "epsilon": float(cx.eps),
        "scene": {k: _pack_array(v) for k, v in _scene_arrays(cx.scene).items()},
        "names": list(cx.scene.names),
        "arrays": {k: _pack_array(cx.arrays[k]) for k in sorted(cx.arrays)},
        "mesh": None if mesh is None else {k: _pack_array(mesh[k]) for k in sorted(mesh)},
    }
    upd = update_arrays(cx)
    if upd is not None:
        doc["update"] = {k: _pack_array(upd[k]) for k in sorted(upd)}
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(msgpack.packb(doc, use_bin_type=True))


def read_msgpack(path, with_mesh=False):
    """Read a flatland msgpack file, checked as :func:`read_hdf5` checks its HDF5 twin."""
    import msgpack

    register_input(path)
    try:
        with open(path, "rb") as fh:
            # msgpack bounds its own nesting (an exception, not a crash); sizes by the file's length
            doc = msgpack.unpackb(fh.read(), raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises many kinds for damaged data
        raise ViscxError(f"{path}: not a readable msgpack file ({type(exc).__name__}: {str(exc)[:80]})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ViscxError(f"{path}: not a viscx flatland msgpack file")
    if doc.get("format_version") != FORMAT_VERSION:
        raise ViscxError(f"{path}: unsupported flatland format version {doc.get('format_version')!r}")
    c = validate.Checker(path)
    packed, arrays = doc.get("scene"), doc.get("arrays")
    if not isinstance(packed, dict) or not isinstance(arrays, dict):
        raise ViscxError(f"{path}: a flatland msgpack file without its scene or arrays")
    scene = {}
    for name, dims in _SCENE_DIMS.items():
        if name not in packed:
            c.fail(f"scene/{name}", "missing")
        a = _unpack_array(packed[name], c, f"scene/{name}")
        if a.ndim != len(dims):
            c.fail(f"scene/{name}", f"shape {a.shape}")
        for size, dim in zip(a.shape, dims):
            c._dim(f"scene/{name}", size, dim)
        scene[name] = c.convert(f"scene/{name}", a, "i" if name in ("kind", "vert_start") else "f")
    names = doc.get("names")
    if not (isinstance(names, list) and len(names) == c.sizes["n"] and all(isinstance(x, str) for x in names)):
        c.fail("names", f"not a list of {c.sizes['n']} strings")
    arrays = {str(k): _unpack_array(v, c, f"arrays/{k}") for k, v in arrays.items()}
    mesh = doc.get("mesh")
    if mesh is not None:
        if not isinstance(mesh, dict):
            c.fail("mesh", "not a map of arrays")
        mesh = {str(k): _unpack_array(v, c, f"mesh/{k}") for k, v in mesh.items()}
    upd = doc.get("update")
    if upd is not None:
        if not isinstance(upd, dict):
            c.fail("update", "not a map of arrays")
        upd = {str(k): _unpack_array(v, c, f"update/{k}") for k, v in upd.items()}
    eps = doc.get("epsilon")
    eps = eps if isinstance(eps, (int, float)) and not isinstance(eps, bool) else repr(eps)
    cx = _complex(c, scene, names, arrays, eps, upd)
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
