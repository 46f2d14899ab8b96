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


if __name__ == "__main__":
    main()
