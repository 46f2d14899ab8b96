"""Scene loading (JSON, SVG, DXF), error messages, file formats and the CLI."""

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from viscx.errors import ViscxError
from viscx.flatland.complex import build
from viscx.flatland.scene import load_scene
from viscx.formats.flatland import read_hdf5, read_msgpack, write_hdf5, write_msgpack

SAMPLES = __import__("pathlib").Path(__file__).resolve().parents[2] / "sample_scenes" / "flatland"


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def svg(body):
    return f'<svg xmlns="http://www.w3.org/2000/svg">{body}</svg>'


def test_svg_shapes_and_materials(tmp_path):
    p = write(tmp_path, "s.svg", svg(
        '<circle id="c" cx="0" cy="0" r="1" emission="2" reflectance="0.3"/>'
        '<rect id="r" x="3" y="0" width="1" height="2" data-reflectance="0.1"/>'
        '<polygon id="t" points="0,5 2,5 1,7"/>'
        '<path id="p" d="M 5 5 l 2 0 v 2 h -2 z"/>'))
    sc = load_scene(p)
    assert sc.names == ["c", "r", "t", "p"]
    assert list(sc.kind) == [0, 1, 1, 1]
    assert sc.emission[0] == 2 and sc.reflectance[0] == 0.3 and sc.reflectance[1] == 0.1
    assert np.allclose(sc.perimeters(), [2 * np.pi, 6, 2 + 2 * np.sqrt(5), 8])


@pytest.mark.parametrize("body,msg", [
    ('<ellipse id="e" cx="0" cy="0" rx="1" ry="2"/>', "ellipses are not supported"),
    ('<path id="q" d="M 0 0 C 1 1 2 2 3 0 Z"/>', "curved"),
    ('<polygon id="v" points="0,0 4,0 4,4 2,1 0,4"/>', "'v' is not convex"),
    ('<circle id="a" cx="0" cy="0" r="1"/><circle id="b" cx="1.5" cy="0" r="1"/>', "'a' and 'b' overlap"),
    ('<rect id="rr" x="0" y="0" width="1" height="1" rx="0.2"/>', "rounded"),
    ('<circle id="c" cx="0" cy="0" r="1" transform="scale(2)"/>', "transforms"),
])
def test_svg_errors(tmp_path, body, msg):
    with pytest.raises(ViscxError, match=msg):
        load_scene(write(tmp_path, "bad.svg", svg(body)))


@pytest.mark.parametrize("doc,msg", [
    ({"objects": [{"type": "circle", "center": [0, 0], "radius": -1}]}, "radius > 0"),
    ({"objects": [{"type": "blob"}]}, "unknown type"),
    ({"objects": [{"type": "polygon", "points": [[0, 0], [1, 1], [2, 2]]}]}, "non-collinear"),
    ({"objects": [{"type": "circle", "center": [0, 0], "radius": 1, "reflectance": 1.5}]}, "reflectance"),
    ({"objects": [{"name": "x", "type": "polygon", "points": [[0, 0], [2, 0], [2, 2], [0, 2]]},
                  {"name": "y", "type": "circle", "center": [2.5, 1], "radius": 0.6}]}, "'x' and 'y' overlap"),
    ({"things": []}, "'objects' list"),
])
def test_json_errors(tmp_path, doc, msg):
    with pytest.raises(ViscxError, match=msg):
        load_scene(write(tmp_path, "bad.json", json.dumps(doc)))


def test_dxf_plan(tmp_path):
    import trimesh
    from trimesh.path.entities import Line

    verts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [3, 0], [4, 0], [4.5, 1], [3, 1.5]], float)
    p = trimesh.path.Path2D(entities=[Line(points=[0, 1, 2, 3, 0]), Line(points=[4, 5, 6, 7, 4])], vertices=verts)
    f = tmp_path / "plan.dxf"
    f.write_text(trimesh.path.exchange.dxf.export_dxf(p))
    sc = load_scene(f)
    assert sc.n == 2 and np.allclose(sc.perimeters()[0], 4)
    cx = build(sc)
    assert np.max(np.abs(cx.F_area - cx.F_strings)) < 1e-9
    # a non-convex outline is named
    p2 = trimesh.path.Path2D(entities=[Line(points=[0, 1, 2, 3, 4, 0])],
                             vertices=np.array([[0, 0], [4, 0], [4, 4], [2, 1], [0, 4]], float))
    f2 = tmp_path / "bad.dxf"
    f2.write_text(trimesh.path.exchange.dxf.export_dxf(p2))
    with pytest.raises(ViscxError, match="outline0' is not convex"):
        load_scene(f2)


def test_hdf5_msgpack_roundtrip_and_determinism(tmp_path):
    sc = load_scene(SAMPLES / "mixed.json")
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    write_hdf5(a, build(sc))
    write_hdf5(b, build(load_scene(SAMPLES / "mixed.json")))
    assert a.read_bytes() == b.read_bytes()
    cx = read_hdf5(a)
    with h5py.File(a) as f:
        assert f.attrs["format"] == "viscx-flatland"
        assert set(f) == {"scene", "vertices", "edges", "faces", "formfactors", "update"}
        # every stored maximal free segment is finite
        assert np.all(np.isfinite(f["vertices/seg"][()]))
    write_msgpack(tmp_path / "c.msgpack", cx)
    cm = read_msgpack(tmp_path / "c.msgpack")
    for k in cx.arrays:
        assert np.array_equal(cx.arrays[k], cm.arrays[k])


def run(*args):
    from viscx.cli import cli
    from viscx.cli.flatland import flatland

    if "flatland" not in cli.commands and "flatland" not in getattr(cli, "lazy_commands", {}):
        cli.add_command(flatland)
    return CliRunner().invoke(cli, ["--quiet", "flatland", *map(str, args)])


def test_cli_build_formfactor_radiosity_move_plot(tmp_path):
    out = tmp_path / "three.h5"
    r = run("build", SAMPLES / "three_circles.json", "-o", out)
    assert r.exit_code == 0, r.output
    assert "vertices" in r.output and out.exists()
    r = run("formfactor", out)
    assert r.exit_code == 0 and "max |F_area - F_strings|" in r.output
    r = run("formfactor", out, "--method", "area", "-o", tmp_path / "F.json")
    doc = json.loads((tmp_path / "F.json").read_text())
    assert np.allclose(np.sum(doc["F"], axis=1), 1)
    r = run("radiosity", out, "-o", tmp_path / "rad.h5")
    assert r.exit_code == 0, r.output
    with h5py.File(tmp_path / "rad.h5") as f:
        assert "mesh" in f and f["mesh/elem_B"].shape[0] > 0
    r = run("move", out, "--object", "lamp", "--by", "0.3,-0.2", "-o", tmp_path / "moved.h5")
    assert r.exit_code == 0, r.output
    assert "form factors recomputed:" in r.output
    moved = read_hdf5(tmp_path / "moved.h5")
    rebuilt = build(moved.scene, eps=moved.eps)
    assert np.allclose(moved.F_area, rebuilt.F_area, atol=1e-12)
    pytest.importorskip("matplotlib")
    r = run("plot", tmp_path / "rad.h5", "-o", tmp_path / "fig.png")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "fig.png").stat().st_size > 1000


def test_cli_bad_input_is_one_line_error(tmp_path):
    from viscx.cli import main
    from viscx.cli.flatland import flatland
    from viscx.cli import cli

    if "flatland" not in cli.commands and "flatland" not in getattr(cli, "lazy_commands", {}):
        cli.add_command(flatland)
    bad = write(tmp_path, "bad.svg", svg('<ellipse id="e" cx="0" cy="0" rx="1" ry="2"/>'))
    for argv in (["flatland", "build", str(bad), "-o", str(tmp_path / "x.h5")],
                 ["flatland", "move", str(bad), "--object", "0", "--by", "1"],
                 ["flatland", "formfactor", str(tmp_path / "missing.h5")]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
    assert not (tmp_path / "x.h5").exists()


def test_cli_rows_of_segments_with_sky(tmp_path):
    """The layout a PV engineer draws: a uniform row of panels as segments, built without
    --perturb, with a sky radiance: per-side irradiance printed; a negative radiance is a
    one-line error (exit 2) and writes nothing."""
    from flatland_scenes import panel_rows

    from viscx.cli import cli, main
    from viscx.cli.flatland import flatland

    if "flatland" not in cli.commands and "flatland" not in getattr(cli, "lazy_commands", {}):
        cli.add_command(flatland)
    scene = write(tmp_path, "rows.json", json.dumps(panel_rows(3, thick=0).to_json()))
    r = CliRunner().invoke(flatland, ["radiosity", str(scene), "--sky-radiance", "1", "-o", str(tmp_path / "r.h5")])
    assert r.exit_code == 0, r.output
    assert "right side" in r.output and "left side" in r.output
    with h5py.File(tmp_path / "r.h5") as f:
        F = f["mesh/elem_F"][()]
        assert np.max(np.abs(F.sum(axis=1) - 1)) < 1e-9
        assert float(f["mesh/sky_radiance"][()]) == 1.0
    with pytest.raises(SystemExit) as exc:
        main(["flatland", "radiosity", str(scene), "--sky-radiance", "-1", "-o", str(tmp_path / "bad.h5")])
    assert exc.value.code == 2
    assert not (tmp_path / "bad.h5").exists()


def test_cli_insert_and_remove(tmp_path):
    """`insert` (inline JSON, a scene file) and `remove` update the file; the result equals
    a rebuild of its scene; bad specs, name clashes and overlaps are one-line errors (exit
    2) that leave the file as it was."""
    from viscx.cli import cli, main
    from viscx.cli.flatland import flatland

    if "flatland" not in cli.commands and "flatland" not in getattr(cli, "lazy_commands", {}):
        cli.add_command(flatland)
    out = tmp_path / "three.h5"
    assert run("build", SAMPLES / "three_circles.json", "-o", out).exit_code == 0
    r = run("insert", out, "--object", '{"type": "circle", "center": [2, 6], "radius": 0.5, "name": "pot"}')
    assert r.exit_code == 0, r.output
    assert "inserted 'pot'" in r.output and "zone:" in r.output
    shed = write(tmp_path, "shed.json", json.dumps({"objects": [
        {"type": "polyline", "points": [[-6, 0], [-6, 2], [-4, 3]], "name": "shed"}]}))
    r = run("insert", out, "--object", shed, "-o", tmp_path / "shed.h5")
    assert r.exit_code == 0, r.output
    assert "'shed[0]', 'shed[1]'" in r.output
    r = run("remove", tmp_path / "shed.h5", "--object", "left")
    assert r.exit_code == 0, r.output
    for path, names in ((out, ["lamp", "left", "right", "pot"]),
                        (tmp_path / "shed.h5", ["lamp", "right", "pot", "shed[0]", "shed[1]"])):
        got = read_hdf5(path)
        assert got.scene.names == names
        rebuilt = build(got.scene, eps=got.eps)
        for name in rebuilt.arrays:
            assert np.allclose(got.arrays[name], rebuilt.arrays[name], rtol=1e-12, atol=1e-12, equal_nan=True), name
    before = out.read_bytes()
    for argv in (["insert", str(out), "--object", "{bad"], ["insert", str(out), "--object", "pot.txt"],
                 ["insert", str(out), "--object", '{"type": "circle", "center": [2, 6], "radius": 0.1, "name": "x"}'],
                 ["insert", str(out), "--object", '{"type": "circle", "center": [9, 9], "radius": 0.1, "name": "pot"}'],
                 ["remove", str(out), "--object", "nope"]):
        with pytest.raises(SystemExit) as exc:
            main(["flatland", *argv])
        assert exc.value.code == 2
    assert out.read_bytes() == before
