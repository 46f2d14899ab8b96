"""`viscx diff` and viscx.formats.diff: each kind of change in a copy of a golden file is found and named."""

import json
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from viscx.cli import main
from viscx.formats import diff as diffmod
from viscx.formats.diff import diff_files

GOLDEN = Path(__file__).resolve().parent / "golden" / "cornell_box.h5"


def run(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return exc.value.code, out, err


@pytest.fixture
def copy(tmp_path):
    """A writable copy of the golden Cornell box file."""
    path = tmp_path / "copy.h5"
    shutil.copyfile(GOLDEN, path)
    return path


def edit(path, change):
    """Apply ``change(h5py.File)`` to the file in place."""
    with h5py.File(path, "r+") as f:
        change(f)


def test_identical_files_exit_0(copy, capsys):
    code, out, err = run(["diff", str(copy), str(GOLDEN)], capsys)
    assert code == 0 and err == "" and "are equal" in out
    code, out, _ = run(["--quiet", "diff", str(copy), str(GOLDEN), "--rtol", "0", "--atol", "0"], capsys)
    assert code == 0 and out == ""


def test_one_float_value_changed(copy, capsys):
    def change(f):
        f["scene/vertices"][5, 1] = 548.75

    edit(copy, change)
    code, out, err = run(["diff", str(copy), str(GOLDEN)], capsys)
    assert code == 1 and err == ""
    assert "differ in 1 place(s)" in out
    assert "/scene/vertices[5, 1]: 548.75 != 548.8 (1 of 84 values differ)" in out


def test_one_integer_value_changed(copy):
    edit(copy, lambda f: f["scene/half_edges/next"].__setitem__(7, 0))
    result = diff_files(copy, GOLDEN)
    assert result.total == 1
    (d,) = result.differences
    assert (d.path, d.kind, d.index, d.b, d.count, d.size) == ("/scene/half_edges/next", "value", (7,), 4, 1, 64)


def test_tolerances(copy, capsys):
    def change(f):
        v = f["scene/face_area"]
        v[3] = v[3] * (1 + 1e-12)  # within the default rtol 1e-9

    edit(copy, change)
    assert run(["diff", str(copy), str(GOLDEN)], capsys)[0] == 0
    code, out, _ = run(["diff", str(copy), str(GOLDEN), "--rtol", "0", "--atol", "0"], capsys)
    assert code == 1 and "/scene/face_area[3]" in out
    assert run(["diff", str(copy), str(GOLDEN), "--rtol", "0", "--atol", "1e-6"], capsys)[0] == 0


def test_changed_attributes(copy, capsys):
    def change(f):
        f.attrs["scene_name"] = "other.obj"
        options = json.loads(f.attrs["options"])
        options["epsilon"] = 0.5
        f.attrs["options"] = json.dumps(options)
        f["scene"].attrs["note"] = "new"

    edit(copy, change)
    code, out, _ = run(["diff", str(copy), str(GOLDEN)], capsys)
    assert code == 1 and "differ in 3 place(s)" in out
    assert "/@scene_name: 'other.obj' != 'cornell_box.obj'" in out
    assert re.search(r"/@options\['epsilon'\]: 0.5 != 0.00096074\d+\n", out)
    assert f"/scene/@note: attribute only in {copy}" in out


def test_missing_dataset_and_extra_level(copy, capsys):
    def change(f):
        del f["scene/edges/is_generator"]
        f.create_group("V9").create_dataset("node_kind", data=np.arange(3))

    edit(copy, change)
    code, out, _ = run(["diff", str(GOLDEN), str(copy)], capsys)
    assert code == 1
    assert f"/scene/edges/is_generator: dataset only in {GOLDEN}" in out
    assert f"/V9: group only in {copy}" in out


def test_shape_and_dtype_changes(copy):
    def change(f):
        area = f["scene/face_area"][()]
        del f["scene/face_area"]
        f["scene/face_area"] = np.append(area, 1.0)
        group = f["scene/face_group"][()]
        del f["scene/face_group"]
        f["scene/face_group"] = group.astype(np.float64)
        vis = f["scene/vertex_is_generator"][()]
        del f["scene/vertex_is_generator"]
        f["scene/vertex_is_generator"] = vis.astype(np.int32)  # bool -> integer is a kind change

    edit(copy, change)
    found = {d.path: d for d in diff_files(copy, GOLDEN).differences}
    assert found["/scene/face_area"].kind == "shape" and found["/scene/face_area"].a == (17,)
    assert (found["/scene/face_group"].kind, found["/scene/face_group"].a) == ("dtype", "float")
    assert found["/scene/vertex_is_generator"].kind == "dtype"
    assert len(found) == 3


def test_same_values_in_another_integer_width_are_equal(copy):
    def change(f):
        faces = f["scene/half_edges/face"][()]
        del f["scene/half_edges/face"]
        f["scene/half_edges/face"] = faces.astype(np.int32)

    edit(copy, change)
    assert diff_files(copy, GOLDEN).equal


def test_string_value_changed(copy):
    edit(copy, lambda f: f["scene/group_names"].__setitem__(7, "lamp"))
    (d,) = diff_files(copy, GOLDEN).differences
    assert (d.path, d.index, d.a, d.b) == ("/scene/group_names", (7,), "lamp", "light")


def test_provenance_and_version_are_ignored(copy):
    def change(f):
        f["provenance"].attrs["timings"] = '{"scene": 99.0}'
        f.attrs["viscx_version"] = "9.9.9"

    edit(copy, change)
    assert diff_files(copy, GOLDEN).equal


def test_report_is_capped_but_counts_everything(copy, capsys):
    def change(f):
        for name in ("start", "end", "face", "next"):
            f[f"scene/half_edges/{name}"][0] += 1

    edit(copy, change)
    code, out, _ = run(["diff", str(copy), str(GOLDEN), "--max-report", "1"], capsys)
    assert code == 1 and "differ in 4 place(s)" in out
    assert "/scene/half_edges/start[0]" in out and "/scene/half_edges/end" not in out
    assert "... and 3 more" in out


def test_large_datasets_are_compared_in_slabs(copy, monkeypatch):
    monkeypatch.setattr(diffmod, "_BLOCK", 7)  # 2 rows of 3 per slab: 14 slabs for 28 vertices

    def change(f):
        f["scene/vertices"][20, 2] += 1.0
        f["scene/vertices"][27, 0] += 1.0

    edit(copy, change)
    (d,) = diff_files(copy, GOLDEN).differences
    assert (d.index, d.count, d.size) == ((20, 2), 2, 84)


def test_nan_in_the_same_place_is_equal(copy, tmp_path):
    other = tmp_path / "other.h5"
    edit(copy, lambda f: f["scene/face_area"].__setitem__(0, np.nan))
    shutil.copyfile(copy, other)
    assert diff_files(copy, other, rtol=0, atol=0).equal
    assert diff_files(copy, GOLDEN).total == 1


@pytest.mark.parametrize(
    "make, keyword",
    [
        (lambda p: p.write_text("not hdf5\n"), "not a readable HDF5 file"),
        (lambda p: h5py.File(p, "w").close(), "not one written by viscx"),
        (lambda p: None, "no such file"),
    ],
    ids=["text", "foreign-hdf5", "missing"],
)
def test_bad_input_exits_2(make, keyword, tmp_path, capsys):
    bad = tmp_path / "bad.h5"
    make(bad)
    for argv in (["diff", str(bad), str(GOLDEN)], ["diff", str(GOLDEN), str(bad)]):
        code, out, err = run(argv, capsys)
        assert code == 2 and out == "" and err.count("\n") == 1
        assert keyword in err and str(bad) in err


def test_negative_tolerance_is_a_usage_error(capsys):
    code, _, err = run(["diff", str(GOLDEN), str(GOLDEN), "--rtol", "-1"], capsys)
    assert code == 2 and err.count("\n") == 1 and "--rtol" in err
