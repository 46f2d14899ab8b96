"""Regenerate the binary members of the bad-input corpus (the text ones are written by hand).

Run from anywhere: ``python tests/bad_inputs/make_binary.py``. Fixed seeds, so
the garbage is the same garbage every time. The HDF5 members start from
``tests/golden/two_triangles.h5``.
"""

import shutil
import struct
from pathlib import Path

import h5py
import numpy as np

HERE = Path(__file__).resolve().parent
GOLDEN = HERE.parent / "golden" / "two_triangles.h5"


def main():
    rng = np.random.default_rng(20261123)
    (HERE / "binary_garbage.obj").write_bytes(rng.integers(0, 256, 2048, dtype=np.uint8).tobytes())
    (HERE / "binary_garbage.ply").write_bytes(rng.integers(0, 256, 2048, dtype=np.uint8).tobytes())
    # a valid OBJ saved as UTF-16 by a text editor: NUL bytes everywhere
    (HERE / "utf16.obj").write_bytes("# bad input: UTF-16 text\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("utf-16"))
    # binary PLY whose header promises 100 vertices and 50 faces; the data stops after 2 vertices
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment bad input: truncated binary data\n"
        "element vertex 100\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 50\nproperty list uchar int vertex_indices\nend_header\n"
    )
    (HERE / "truncated_binary.ply").write_bytes(header.encode() + struct.pack("<6f", 0, 0, 0, 1, 0, 0))
    # binary STL claiming 1000 triangles and holding one
    stl = b"bad input: truncated binary STL".ljust(80, b" ") + struct.pack("<I", 1000)
    stl += struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    (HERE / "truncated.stl").write_bytes(stl)

    # HDF5: truncated, from another program, from the future, damaged, a viscx file as a scene
    data = GOLDEN.read_bytes()
    (HERE / "truncated.h5").write_bytes(data[: len(data) // 2])
    (HERE / "hdf5_as_scene.obj").write_bytes(data)
    shutil.copyfile(GOLDEN, HERE / "viscx_file_as_scene.h5")
    with h5py.File(HERE / "other_program.h5", "w") as f:
        f.attrs["comment"] = "bad input: an HDF5 file written by another program"
        f.create_dataset("temperature", data=np.linspace(280.0, 300.0, 16), track_times=False)
    for name, change in [
        ("future_version.h5", lambda f: f.attrs.__setitem__("format_version", 99)),
        ("format_version_text.h5", lambda f: f.attrs.__setitem__("format_version", "one")),
        ("no_scene_level.h5", lambda f: f.__delitem__("scene")),
        ("missing_dataset.h5", lambda f: f.__delitem__("scene/vertices")),
    ]:
        shutil.copyfile(GOLDEN, HERE / name)
        with h5py.File(HERE / name, "r+") as f:
            f.attrs["comment"] = f"bad input: {name[:-3].replace('_', ' ')}"
            change(f)


    untrusted()


def _replace(f, name, data):
    del f[name]
    f.create_dataset(name, data=data)


def _virtual(f):
    layout = h5py.VirtualLayout(shape=(1,), dtype="f8")
    layout[:] = h5py.VirtualSource("/nonexistent/other.h5", "data", shape=(1,))
    del f["scene/face_area"]
    f["scene"].create_virtual_dataset("face_area", layout)


def _nested(depth):
    return "[" * depth + "]" * depth


def untrusted():
    """Hostile and damaged files of the untrusted-files issue (docs/security.md)."""
    obj = b"# bad input: a valid OBJ followed by a NUL-filled binary tail\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    (HERE / "obj_binary_tail.obj").write_bytes(obj + b"\x00" * 8192)
    (HERE / "bom.obj").write_bytes("\ufeff# odd input: a UTF-8 byte-order mark first\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
                                   .encode("utf-8"))
    (HERE / "flatland_deep.json").write_text('{"objects": ' + _nested(20000) + "}\n")
    for name, change in [
        ("nan_in_scene.h5", lambda f: f["scene/vertices"].__setitem__((1, 1), np.nan)),
        ("broken_next.h5", lambda f: f["scene/half_edges/next"].__setitem__(Ellipsis, 0)),
        ("external_link.h5", lambda f: (f.__delitem__("scene"), f.__setitem__("scene", h5py.ExternalLink("/etc/passwd", "/")))),
        ("external_storage.h5", lambda f: (f.__delitem__("scene/face_area"), f["scene"].create_dataset(
            "face_area", shape=(2,), dtype="f8", external=[("/etc/hostname", 0, 16)]))),
        ("virtual_dataset.h5", _virtual),
        ("declared_never_written.h5", lambda f: (f.__delitem__("scene/face_area"), f["scene"].create_dataset(
            "face_area", shape=(2**31,), dtype="f8", chunks=(1024,)))),
        ("levels_without_groups.h5", lambda f: [f.__delitem__(level) for level in ("V0", "V1", "V2")]),
        ("triangles_float.h5", lambda f: _replace(f, "scene/triangles", f["scene/triangles"][()].astype(np.float64))),
        ("vertices_strings.h5", lambda f: _replace(f, "scene/vertices", np.array(
            [["a", "b", "c"]] * len(f["scene/vertices"]), dtype=h5py.string_dtype()))),
        ("counts_not_integers.h5", lambda f: f["scene"].attrs.__setitem__("counts", '{"faces": 1.5}')),
        ("options_deep.h5", lambda f: f.attrs.__setitem__("options", _nested(20000))),
        ("epsilon_nan.h5", lambda f: f.attrs.__setitem__("epsilon", np.nan)),
    ]:
        shutil.copyfile(GOLDEN, HERE / name)
        with h5py.File(HERE / name, "r+") as f:
            f.attrs["comment"] = f"bad input: {name[:-3].replace('_', ' ')}"
            change(f)
    # flatland files without a scene, with an object dtype
    import msgpack

    with h5py.File(HERE / "flatland_no_scene.h5", "w") as f:
        f.attrs.update(format="viscx-flatland", format_version=1, epsilon=1e-9, comment="bad input: no scene")
        f.create_group("vertices")
    doc = {"format": "viscx-flatland", "format_version": 1, "epsilon": 1e-9, "comment": "bad input: no scene"}
    (HERE / "flatland_no_scene.msgpack").write_bytes(msgpack.packb(doc))
    array = {"dtype": "|O", "shape": [1], "data": b"\x00" * 8}
    doc = {**doc, "comment": "bad input: object dtype", "names": ["a"],
           "scene": {k: array for k in ("kind", "vert_start", "verts", "radius", "emission", "reflectance")},
           "arrays": {}}
    (HERE / "flatland_object_dtype.msgpack").write_bytes(msgpack.packb(doc))


if __name__ == "__main__":
    main()
