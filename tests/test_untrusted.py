"""Damaged and hostile viscx files (issue: untrusted files): each is refused with exit 2 and
one line naming the dataset, before any kernel sees it or any other file is read.

Every file is made here from a golden file by one change (h5py), and run in-process.
"""

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from viscx.cli import main

GOLDEN = Path(__file__).resolve().parent / "golden"
ROOT_SAMPLES = Path(__file__).resolve().parent.parent / "sample_scenes"


def run(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--quiet", *map(str, args)])
    return exc.value.code, capsys.readouterr().err


def damaged_copy(tmp_path, change, golden="cornell_box.h5"):
    path = tmp_path / "damaged.h5"
    shutil.copyfile(GOLDEN / golden, path)
    with h5py.File(path, "r+") as f:
        change(f)
    return path


def replace(name, data, **kwargs):
    def change(f):
        del f[name]
        f.create_dataset(name, data=data, **kwargs)
    return change


def set_values(name, fill):
    def change(f):
        data = f[name][()]
        f[name][...] = fill(data)
    return change


def set_attr(name, value, group="/"):
    return lambda f: f[group].attrs.__setitem__(name, value)


def nested(depth):
    return "[" * depth + "]" * depth


CASES = {
    # kernels: a NaN vertex crashed the ray caster (free(): corrupted chunks), broken loops segfaulted
    "nan_vertex": (set_values("scene/vertices", lambda v: np.where(np.arange(v.size).reshape(v.shape) == 4, np.nan, v)),
                   "/scene/vertices"),
    "next_all_zero": (set_values("scene/half_edges/next", np.zeros_like), "/scene/half_edges/next"),
    "next_shuffled": (set_values("scene/half_edges/next", lambda a: np.roll(a, 1)), "/scene/half_edges/next"),
    # finite but absurd: the bounding box overflows, as the scene's builder refuses (slow fuzz,
    # seed 1934744149: the discontinuity mesh's KD-tree overflowed, exit 1)
    "vertex_far_away": (set_values("scene/vertices", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 0, 1e300, a)),
                        "/scene/vertices: coordinates too large"),
    "triangle_out_of_range": (set_values("scene/triangles", lambda a: a + 1000), "/scene/triangles"),
    "loop_offsets_backwards": (set_values("scene/loop_offsets", lambda a: a[::-1]), "/scene/loop_offsets"),
    "opp_unpaired": (set_values("scene/half_edges/opp", lambda a: np.where(a >= 0, 0, a)), "/scene/half_edges/opp"),
    "edge_wrong": (set_values("scene/half_edges/edge", lambda a: a[::-1]), "/scene/half_edges/edge"),
    # dtypes: strings or floats where integers belong
    "triangles_float": (lambda f: replace("scene/triangles", f["scene/triangles"][()].astype(np.float64))(f),
                        "/scene/triangles"),
    "vertices_strings": (lambda f: replace("scene/vertices", np.array([["a", "b", "c"]] * len(f["scene/vertices"]),
                                                                      dtype=h5py.string_dtype()))(f),
                         "/scene/vertices"),
    "counts_not_integers": (set_attr("counts", json.dumps({"cells": 1.5}), "V2"), "counts"),
    "counts_deep": (set_attr("counts", nested(20000), "V2"), "nests deeper"),
    "options_deep": (set_attr("options", nested(20000)), "nests deeper"),
    "options_not_json": (set_attr("options", "{"), "not JSON"),
    "epsilon_nan": (set_attr("epsilon", np.nan), "@epsilon"),
    # finite but absurd tolerances (slow fuzz, seed 1834672060: a weld tolerance of 1e308
    # corrupted the heap in the free point's kernels, SIGABRT)
    "weld_tolerance_huge": (set_attr("weld_tolerance", 1e308), "@weld_tolerance"),
    "epsilon_huge": (set_attr("epsilon", 1e300), "@epsilon"),
    "epsilon_text": (set_attr("epsilon", "small"), "@epsilon"),
    "scene_name_missing": (lambda f: f.attrs.__delitem__("scene_name"), "missing @scene_name"),
    "scene_name_not_text": (set_attr("scene_name", -1), "@scene_name"),
    "timings_not_seconds": (lambda f: f["provenance"].attrs.__setitem__("timings", '{"cells": "x"}'),
                            "/provenance@timings"),
    # levels listed, groups absent
    "levels_without_groups": (lambda f: [f.__delitem__(x) for x in ("V0", "V1", "V2")], "/V0"),
    "levels_unknown": (set_attr("levels", json.dumps(["scene", "V9"])), "@levels"),
    "levels_v2_without_v1": (lambda f: (f.__delitem__("V1"), f.attrs.__setitem__("levels", '["scene", "V0", "V2"]')),
                             "/V1: missing"),
    # other files through HDF5
    "external_link": (lambda f: (f.__delitem__("scene"), f.__setitem__("scene", h5py.ExternalLink("/etc/passwd", "/"))),
                      "external link"),
    "soft_link": (lambda f: f["scene"].__setitem__("alias", h5py.SoftLink("/scene/vertices")), "soft link"),
    "external_storage": (lambda f: (f["scene"].__delitem__("face_area"),
                                    f["scene"].create_dataset("face_area", shape=(16,), dtype="f8",
                                                              external=[("/etc/hostname", 0, 128)])),
                         "external raw storage"),
    "virtual_dataset": (lambda f: (f["scene"].__delitem__("face_area"),
                                   f["scene"].create_virtual_dataset("face_area", _layout())), "virtual dataset"),
    # memory bombs: declared but never written
    "declared_never_written": (lambda f: (f["scene"].__delitem__("face_area"),
                                          f["scene"].create_dataset("face_area", shape=(2**31,), dtype="f8",
                                                                    chunks=(1024,))),
                               "declares"),
    "compressed_never_written": (lambda f: (f["scene"].__delitem__("face_area"),
                                            f["scene"].create_dataset("face_area", shape=(2**31,), dtype="f8",
                                                                      chunks=(4096,), compression="gzip")),
                                 "declares"),
    "object_dtype": (lambda f: f["V0"].create_dataset("extra", data=np.zeros(3, dtype=[("a", "i4"), ("b", "f8")])),
                     "neither a number nor a string"),
    # the levels: kernels read V1 and V2
    "v1_end_node_out_of_range": (set_values("V1/end_node", lambda a: a + 10**6), "/V1/end_node"),
    "v1_interval_nan": (set_values("V1/interval", lambda a: a * np.nan), "/V1/interval"),
    "v2_element_zero": (set_values("V2/element", np.zeros_like), "/V2/element"),
    "v2_offsets_backwards": (set_values("V2/element_offsets", lambda a: a[::-1]), "/V2/element_offsets"),
    "v2_missing": (lambda f: f["V2"].__delitem__("twin"), "missing /V2/twin"),
    "v1_kind_float": (lambda f: replace("V1/kind", f["V1/kind"][()].astype(np.float32))(f), "/V1/kind"),
}


def _layout():
    layout = h5py.VirtualLayout(shape=(16,), dtype="f8")
    layout[:] = h5py.VirtualSource("/nonexistent/other.h5", "data", shape=(16,))
    return layout


@pytest.mark.parametrize("name", sorted(CASES))
def test_damaged_file_is_refused(name, tmp_path, capsys):
    change, keyword = CASES[name]
    path = damaged_copy(tmp_path, change)
    # a point query reads the scene and runs the kernels on it; the discontinuity mesh reads V1;
    # the V-cell plot reads V1 and V2
    if name.startswith("v1"):
        args = ["query", "discontinuities", path, "--light-group", "light", "-o", tmp_path / "out.json"]
    elif name.startswith("v2"):
        args = ["plot", "vcells", path, "--vertex", "0", "-o", tmp_path / "out.png"]
    else:
        args = ["query", "visible", path, "--from", "278,540,280", "-o", tmp_path / "out.json"]
    code, err = run(args, capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert keyword.lower() in err.lower(), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["damaged.h5"]


#: damage that ``viscx info`` reads (it counts V0's sites from the nodes' ends)
INFO_CASES = {"v0_end_far_away": (lambda f: f["V0/ends"].__setitem__((0, 0, 0), 1e300), "/V0/ends")}


@pytest.mark.parametrize("name", ["scene_name_missing", "scene_name_not_text", "epsilon_nan", "timings_not_seconds",
                                  "v0_end_far_away"])
def test_info_refuses_damaged_attributes(name, tmp_path, capsys):
    """``viscx info`` prints the root attributes: a missing or non-text one is exit 2 (the
    slow fuzz found ``info`` ending with KeyError, exit 1, when scene_name was dropped)."""
    change, keyword = {**CASES, **INFO_CASES}[name]
    code, err = run(["info", damaged_copy(tmp_path, change)], capsys)
    assert code == 2 and err.count("\n") == 1 and keyword in err, err


@pytest.mark.parametrize("name", ["external_link", "external_storage", "virtual_dataset", "declared_never_written"])
def test_diff_reads_no_other_file(name, tmp_path, capsys):
    change, keyword = CASES[name]
    path = damaged_copy(tmp_path, change)
    code, err = run(["diff", path, GOLDEN / "cornell_box.h5"], capsys)
    assert code == 2 and keyword in err, err


def test_golden_files_pass_validation(capsys):
    from viscx.formats.hdf5 import ViscxFile, read_arcs, read_eecells, read_nodes, read_vcells

    for path in sorted(GOLDEN.glob("*.h5")):
        with ViscxFile(path) as f:
            f.read_scene()
            read_nodes(f.h5["V0"])
            read_arcs(f.h5["V1"])
            read_vcells(f.h5["V2"])
            read_eecells(f.h5["V2"])


def test_json_depth_bounded():
    from viscx.errors import ViscxError
    from viscx.formats.validate import load_json

    assert load_json(nested(10), "x") == eval(nested(10))
    for depth in (65, 900, 20000):
        with pytest.raises(ViscxError, match="nests deeper"):
            load_json(nested(depth), "x")


def test_flatland_move_into_an_overlap(tmp_path, capsys):
    cx = tmp_path / "three.h5"
    assert run(["flatland", "build", GOLDEN.parent.parent / "sample_scenes/flatland/three_circles.json", "-o", cx],
               capsys)[0] == 0
    before = cx.read_bytes()
    code, err = run(["flatland", "move", cx, "--object", "lamp", "--by", "-2,2.5"], capsys)
    assert code == 2 and "overlap" in err and err.count("\n") == 1, err
    assert cx.read_bytes() == before


def test_flatland_msgpack_round_trip_and_damage(tmp_path, capsys):
    import msgpack

    good = tmp_path / "three.msgpack"
    assert run(["flatland", "build", GOLDEN.parent.parent / "sample_scenes/flatland/three_circles.json", "-o", good],
               capsys)[0] == 0
    assert run(["flatland", "formfactor", good], capsys)[0] == 0
    doc = msgpack.unpackb(good.read_bytes())
    for name, change, keyword in [
        ("nan", lambda d: d["scene"]["radius"].__setitem__("data", np.full(3, np.nan).tobytes()), "scene/radius"),
        ("shape", lambda d: d["arrays"]["e_obj"].__setitem__("shape", [10**9]), "does not match"),
        ("ids", lambda d: d["arrays"]["e_obj"].__setitem__("data", np.full(24, 99, np.int64).tobytes()), "/edges/obj"),
        ("eps", lambda d: d.__setitem__("epsilon", float("nan")), "epsilon"),
        ("deep", lambda d: d.__setitem__("names", [[[[]]]] * 3), "names"),
    ]:
        bad = msgpack.unpackb(good.read_bytes())
        change(bad)
        path = tmp_path / f"{name}.msgpack"
        path.write_bytes(msgpack.packb(bad))
        code, err = run(["flatland", "formfactor", path], capsys)
        assert code == 2 and keyword in err and err.count("\n") == 1, (name, err)
    assert doc["format"] == "viscx-flatland"


def test_render_size_over_the_budget(tmp_path, capsys, monkeypatch):
    code, err = run(["render", GOLDEN / "cornell_box.h5", "--camera", "278,273,-800", "--look-at", "278,273,0",
                     "--light-group", "light", "--size", "100000", "100000", "-o", tmp_path / "r.png"], capsys)
    assert code == 2 and "memory budget" in err, err
    monkeypatch.setenv("VISCX_MEMORY_BUDGET", "1000")
    code, err = run(["render", GOLDEN / "cornell_box.h5", "--camera", "278,273,-800", "--look-at", "278,273,0",
                     "--light-group", "light", "--size", "8", "8", "-o", tmp_path / "r.png"], capsys)
    assert code == 2 and "memory budget" in err, err
    assert list(tmp_path.iterdir()) == []


def test_mtllib_link_out_of_the_folder(tmp_path, capsys):
    """A material library beside the scene that is a link to a device is refused (links resolved)."""
    (tmp_path / "scene").mkdir()
    obj = tmp_path / "scene" / "s.obj"
    obj.write_text("mtllib lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n")
    (tmp_path / "scene" / "lib.mtl").symlink_to("/dev/zero")
    code, err = run(["build", obj, "-o", tmp_path / "out.h5", "--levels", "-1"], capsys)
    assert code == 2 and "outside the scene's folder" in err, err
    (tmp_path / "scene" / "lib.mtl").unlink()
    (tmp_path / "scene" / "sub").mkdir()
    (tmp_path / "scene" / "sub" / "lib.mtl").write_text("newmtl a\nKd 1 0 0\n")
    obj.write_text("mtllib sub/lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n")
    assert run(["build", obj, "-o", tmp_path / "out.h5", "--levels", "-1"], capsys)[0] == 0


def test_glb_with_an_outside_buffer(tmp_path, capsys):
    import struct

    doc = json.dumps({"asset": {"version": "2.0"}, "buffers": [{"uri": "/etc/passwd", "byteLength": 36}]}).encode()
    doc += b" " * (-len(doc) % 4)
    glb = b"glTF" + struct.pack("<II", 2, 20 + len(doc)) + struct.pack("<I", len(doc)) + b"JSON" + doc
    path = tmp_path / "s.glb"
    path.write_bytes(glb)
    code, err = run(["build", path, "-o", tmp_path / "out.h5"], capsys)
    assert code == 2 and "outside the scene's folder" in err, err


def test_declared_sizes_of_the_golden_files_are_their_storage():
    """The storage bound refuses nothing viscx writes: gzip-compressed datasets stay under
    the ratio bound, the others hold exactly their declared bytes."""
    from viscx.formats.validate import MAX_RATIO

    for path in GOLDEN.glob("*.h5"):
        with h5py.File(path, "r") as f:
            def check(name, d):
                if isinstance(d, h5py.Dataset) and d.dtype.kind in "biuf":
                    assert d.size * d.dtype.itemsize <= d.id.get_storage_size() * (MAX_RATIO if d.compression else 1)
            f.visititems(check)


def test_gltf_with_buffers_beside_it_is_read(tmp_path, capsys):
    import trimesh

    for name, data in trimesh.Scene(trimesh.creation.box()).export(file_type="gltf").items():
        (tmp_path / name).write_bytes(data)
    code, err = run(["build", tmp_path / "model.gltf", "-o", tmp_path / "out.h5", "--levels", "-1"], capsys)
    assert code == 0, err


def test_generator_flags_must_match_the_loops(tmp_path, capsys):
    """Found by the fuzz test: every edge flag flipped sent the point query into families
    with no generator (an IndexError, exit 1). The flags are rebuilt from the loops."""
    path = damaged_copy(tmp_path, set_values("scene/edges/is_generator", np.logical_not), "two_triangles.h5")
    code, err = run(["query", "visible", path, "--from", "0.2,0.3,0.9", "-o", tmp_path / "v.json"], capsys)
    assert code == 2 and "/scene/edges/is_generator" in err, err


@pytest.mark.parametrize("option", [["--epsilon", "1e300"], ["--relative-epsilon", "0.5"]])
def test_build_refuses_an_epsilon_near_the_scene_size(option, tmp_path, capsys):
    """An epsilon near the scene's size made the kernels fail (exit 1); the builder and the
    validator share the bound MAX_RELATIVE_EPSILON."""
    code, err = run(["build", ROOT_SAMPLES / "tetrahedra.obj", *option, "-o", tmp_path / "t.h5"], capsys)
    assert code == 2 and "too large" in err and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []
