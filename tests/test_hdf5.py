"""The HDF5 container: round trip and atomic writing."""

import os

import h5py
import numpy as np
import pytest
from conftest import SAMPLES, sample_scene_paths

from viscx.formats.atomic import temporary_name
from viscx.formats.hdf5 import FORMAT_VERSION, ViscxFile, read_scene, write_complex
from viscx.scene import load_scene


def assert_same_scene(a, b):
    for name in (
        "vertices triangles triangle_face face_loop_offsets loop_offsets loop_vertices face_normal face_offset "
        "face_area face_group face_material material_kd material_ke"
    ).split():
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and np.array_equal(x, y), name
    for name in "start end face next opp edge loop edge_vertices edge_is_generator vertex_is_generator".split():
        assert np.array_equal(getattr(a.half_edges, name), getattr(b.half_edges, name)), name
    assert a.group_names == b.group_names and a.material_names == b.material_names
    assert a.epsilon == b.epsilon and a.weld_tolerance == b.weld_tolerance and a.sha256 == b.sha256


@pytest.mark.parametrize("path", sample_scene_paths(), ids=lambda p: p.name)
def test_round_trip(path, tmp_path):
    scene = load_scene(path)
    out = tmp_path / "x.h5"
    write_complex(out, scene, options={"epsilon": scene.epsilon}, timings={"scene": 1.0})
    back = read_scene(out)
    assert_same_scene(scene, back)
    with ViscxFile(out) as f:
        assert f.h5.attrs["format"] == "viscx" and f.h5.attrs["format_version"] == FORMAT_VERSION
        assert f.levels == ["scene"] and f.timings == {"scene": 1.0}
        assert len(f.h5.attrs["scene_sha256"]) == 64


def test_levels_are_written_by_their_writers(tmp_path):
    scene = load_scene(sample_scene_paths()[0])
    out = tmp_path / "x.h5"
    write_complex(out, scene, levels={"V0": lambda g: g.create_dataset("kind", data=np.arange(3))})
    with h5py.File(out) as f:
        assert list(f["V0/kind"][()]) == [0, 1, 2]


@pytest.mark.parametrize("interruption", [KeyboardInterrupt, RuntimeError, SystemExit])
def test_interrupted_write_leaves_nothing(tmp_path, interruption):
    scene = load_scene(sample_scene_paths()[0])
    out = tmp_path / "x.h5"

    def failing_level(group):
        group.create_dataset("partial", data=np.zeros(10))
        assert temporary_name(out).exists()  # it really was being written
        raise interruption()

    with pytest.raises(interruption):
        write_complex(out, scene, levels={"V0": failing_level})
    assert os.listdir(tmp_path) == []


def test_failed_write_keeps_the_previous_file(tmp_path):
    scene = load_scene(sample_scene_paths()[0])
    out = tmp_path / "x.h5"
    write_complex(out, scene)
    before = out.read_bytes()

    def failing_level(group):
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        write_complex(out, scene, levels={"V0": failing_level})
    assert out.read_bytes() == before and os.listdir(tmp_path) == ["x.h5"]


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda f: f.attrs.__delitem__("levels"), "missing attribute 'levels'"),
        (lambda f: f.attrs.__setitem__("options", "{not json"), "not JSON"),
        (lambda f: (f["scene"].__delitem__("face_group"), f["scene"].create_dataset("face_group", data=np.zeros((2, 2), int))), "face_group"),
        (lambda f: (f["scene"].__delitem__("triangles"), f["scene"].create_dataset("triangles", data=np.full((32, 3), 999))), "triangles"),
    ],
    ids=["no-levels", "options-not-json", "wrong-shape", "index-out-of-range"],
)
def test_damaged_files_are_refused(tmp_path, damage, message):
    from viscx.errors import ViscxError

    scene = load_scene(SAMPLES / "cornell_box.obj")
    out = tmp_path / "x.h5"
    write_complex(out, scene)
    with h5py.File(out, "r+") as f:
        damage(f)
    with pytest.raises(ViscxError, match=message):
        read_scene(out)


def test_nodes_round_trip(tmp_path):
    from viscx.formats.hdf5 import read_nodes, write_nodes
    from viscx.skeleton.reference import reference_nodes

    scene = load_scene(SAMPLES / "cornell_box.obj")
    nodes = reference_nodes(scene)
    out = tmp_path / "x.h5"
    write_complex(out, scene, levels={"V0": lambda g: write_nodes(g, nodes)})
    with ViscxFile(out) as f:
        assert f.levels == ["scene", "V0"]
        back = read_nodes(f.h5["V0"])
    for name in nodes.__dataclass_fields__:
        a, b = getattr(nodes, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), name


# -- compression (viscx build --compression) ---------------------------------------------

@pytest.fixture(scope="module")
def coded(tmp_path_factory):
    """The Cornell box built once and written with each coder (``BuiltComplex.save``, what
    ``viscx build --compression`` calls; the command itself: the README's blocks): {coder: path}."""
    from viscx.pipeline import build_complex

    folder = tmp_path_factory.mktemp("coded")
    cx = build_complex(SAMPLES / "cornell_box.obj", quiet=True)
    paths = {}
    for compression in ("none", "gzip", "lzf"):
        paths[compression] = folder / f"{compression}.h5"
        cx.save(paths[compression], compression=compression)
    return paths


def _diff(a, b, *tolerance):
    from viscx.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["diff", str(a), str(b), *tolerance])
    return exc.value.code


@pytest.mark.parametrize("compression", ["gzip", "lzf"])
def test_compression_changes_no_content(compression, coded, capsys):
    """Every coder stores the same values (bit for bit) as no coder, which matches the
    golden file; the filters are the ones asked for: large datasets chunked by whole rows,
    shuffled when integer, and at least twice smaller."""
    from conftest import ROOT

    from viscx.formats.hdf5 import COMPRESS_MIN_SIZE, COMPRESSIONS

    assert _diff(coded["none"], ROOT / "tests" / "golden" / "cornell_box.h5") == 0
    assert _diff(coded[compression], coded["none"], "--rtol", "0", "--atol", "0") == 0, capsys.readouterr().out
    stored, raw = 0, 0

    def check(name, obj):
        nonlocal stored, raw
        if not isinstance(obj, h5py.Dataset) or obj.dtype.kind == "O":
            return
        coder = COMPRESSIONS[compression] if obj.size >= COMPRESS_MIN_SIZE else None
        assert obj.compression == (coder[0] if coder else None), name
        if coder:
            assert obj.shuffle == (obj.dtype.kind != "f") and obj.chunks[1:] == obj.shape[1:], name
            assert obj.compression_opts == coder[1], name
            stored, raw = stored + obj.id.get_storage_size(), raw + obj.nbytes

    with h5py.File(coded[compression], "r") as f:
        f.visititems(check)
    assert raw > 300_000 and stored < raw / 2
    with h5py.File(coded["none"], "r") as f:
        assert all(f[name].compression is None for name in ("V1/ends", "V1/generator_points"))


def test_unknown_compression_is_refused(tmp_path):
    from viscx.errors import ViscxError

    with pytest.raises(ViscxError, match="unknown compression 'zstd'"):
        write_complex(tmp_path / "x.h5", load_scene(SAMPLES / "two_triangles.obj"), compression="zstd")
    assert not list(tmp_path.iterdir())
