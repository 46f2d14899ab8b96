"""Files built with ``viscx build --point``: the free points are generator vertices
n_vertices + k, so every reader of vertex ids must know them. Each query on such a file
answers as on the file built without the point (the point blocks nothing), and the
point's own V-cells can be drawn."""

import numpy as np
import pytest
from conftest import ROOT, SAMPLES

from viscx.formats.hdf5 import ViscxFile, read_arcs, read_vcells
from viscx.pipeline import build_file
from viscx.queries.discontinuities import open_discontinuities
from viscx.queries.formfactor import point_to_faces
from viscx.queries.visibility import open_query
from viscx.render.camera import Camera
from viscx.render.image import render

PLAIN = ROOT / "tests" / "golden" / "cornell_box.h5"
LIGHT = [278.0, 540.0, 280.0]


@pytest.fixture(scope="module")
def with_point(tmp_path_factory):
    """The Cornell box built with the README's point light (generator vertex 28)."""
    out = tmp_path_factory.mktemp("points") / "cornell.h5"
    build_file(SAMPLES / "cornell_box.obj", out, quiet=True, points=np.array([LIGHT]))
    return out


def test_the_file_holds_arcs_of_the_point(with_point):
    # what the readers must cope with: VE arcs and V-cells whose vertex is past the scene's
    with ViscxFile(with_point) as f:
        nv = f.read_scene().n_vertices
        arcs, cells = read_arcs(f.h5["V1"]), read_vcells(f.h5["V2"])
    assert nv == 28
    assert np.any(arcs.generators[arcs.kind == 1, 0] == nv) and np.any(cells.vertex == nv)


def test_discontinuity_mesh_ignores_the_point(with_point, sample_build):
    """The point's VE families are not events of the area light: the mesh is the plain build's
    (this machine's, to the bit: not the golden file's)."""
    _, mesh = open_discontinuities(with_point, light_group="light")
    _, plain = open_discontinuities(sample_build("cornell_box.obj"), light_group="light")
    for name in ("arc", "end", "face", "kind", "generators", "light_feature"):
        assert np.array_equal(getattr(mesh.events, name), getattr(plain.events, name)), name
    assert np.array_equal(mesh.offsets, plain.offsets) and np.array_equal(mesh.points, plain.points)
    assert [len(r.regions) for r in mesh.receivers] == [len(r.regions) for r in plain.receivers]


def test_render_ignores_the_point(with_point):
    camera = Camera([278, 273, -800], [278, 273, 0], [0, 1, 0], 39.3, 48, 48)
    images = [render(*open_discontinuities(path, light_group="light"), camera).radiance for path in (with_point, PLAIN)]
    assert np.array_equal(images[0], images[1]) and images[0].max() > 0


def test_form_factor_from_the_stored_point_equals_on_demand(with_point):
    """From the point: its stored V-cells (file) against V-cells computed on demand (plain file)."""
    stored = point_to_faces(open_query(with_point), LIGHT, [0, -1, 0], range(16))
    demand = point_to_faces(open_query(PLAIN), LIGHT, [0, -1, 0], range(16))
    assert stored["source"] == "file" and demand["source"] == "on demand"
    assert stored["F"] == pytest.approx(demand["F"], abs=1e-12)
    assert np.allclose([r["F"] for r in stored["faces"]], [r["F"] for r in demand["faces"]], atol=1e-12)


def test_plot_the_point_vcells(with_point, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from viscx.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["plot", "vcells", str(with_point), "--vertex", "28", "-o", str(tmp_path / "p.png")])
    out = capsys.readouterr().out
    with ViscxFile(with_point) as f:
        n_cells = int(np.sum(read_vcells(f.h5["V2"]).vertex == 28))
    assert exc.value.code == 0 and out.startswith(f"{n_cells} V-cells of vertex 28") and (tmp_path / "p.png").exists()
