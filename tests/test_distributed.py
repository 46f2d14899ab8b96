"""V1 and V2 built chunk by chunk into the file (:func:`viscx.pipeline.stream_arcs`,
:class:`viscx.formats.hdf5.ArcsAppender`; :mod:`viscx.skeleton.chunks`,
:class:`viscx.formats.hdf5.CellsAppender`), in this process or as dask tasks
(``viscx build --scheduler``): the same file as the whole levels built and written at once."""

import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLES, viscx_in_process

from viscx.formats import hdf5
from viscx.formats.diff import diff_files
from viscx.formats.hdf5 import complex_writer
from viscx.pipeline import build_complex, level_writers, stream_arcs, stream_two_cells
from viscx.skeleton import chunks, eecells
from viscx.skeleton.arcs import builder, events, pencils

# scenes with open chains, demoted loops, whole-sphere vertices and T-junctions between them
# (the default suite the first two: 3.8 of 7.3 CPU s)
SCENES = ["boxes_on_floor.obj", "room_with_door.obj", pytest.param("cornell_box.obj", marks=pytest.mark.slow),
          pytest.param("occluder_over_plane.ply", marks=pytest.mark.slow)]


@pytest.fixture(scope="module")
def built():
    """``built(scene)``: the complex of a sample scene, every level in memory (built once)."""
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = build_complex(SAMPLES / name, quiet=True)
        return cache[name]

    return get


def streamed(cx, path, runner=None):
    """Write ``cx``'s V0 from memory, its V1 built again chunk by chunk from its nodes and
    its V2 chunk by chunk from the arcs read back from the file (as `viscx build` does)."""
    with complex_writer(path, cx.scene, ["V0", "V1", "V2"], cx.options) as f:
        level_writers({"V0": cx.nodes})["V0"](f.create_group("V0", track_order=True))
        n_arcs = stream_arcs(cx.scene, cx.nodes, f.create_group("V1", track_order=True), runner)
        assert n_arcs == len(cx.arcs)
        arcs = chunks.stored_v2_arcs(f["V1"])
        return stream_two_cells(cx.scene, arcs, f.create_group("V2", track_order=True), runner)


@pytest.fixture
def tiny_chunks(monkeypatch):
    """Chunks of a few families, half-cells and squares, datasets written every few rows:
    every scene is many chunks and every large array many appends."""
    monkeypatch.setattr(builder, "FAMILY_CHUNK", 40)
    monkeypatch.setattr(events, "PLANAR_BLOCK", 1)  # a corner pair per block of planar events' crossings
    monkeypatch.setattr(pencils, "PLANE_EDGE_TESTS", 1)
    monkeypatch.setattr(chunks, "VCELL_CHUNK", 7)
    monkeypatch.setattr(chunks, "EECELL_CHUNK", 40)
    monkeypatch.setattr(eecells, "ARC_SLICE", 500)
    monkeypatch.setattr(eecells, "SQUARE_GROUP", 30)  # squares put in order a few e1's at a time
    monkeypatch.setattr(hdf5, "APPEND_BYTES", 512)


@pytest.mark.parametrize("scene", SCENES)
def test_streamed_levels_are_the_whole_levels(scene, built, tiny_chunks, tmp_path, monkeypatch):
    cx = built(scene)
    calls = []
    arcs_of_families = builder.arcs_of_families
    monkeypatch.setattr(builder, "arcs_of_families", lambda *a, **k: calls.append(1) or arcs_of_families(*a, **k))
    assert len(list(chunks.vcell_parts(cx.scene, cx.arcs))) > 2
    assert len(list(chunks.eecell_parts(cx.scene, cx.arcs))) > 1
    cx.save(tmp_path / "whole.h5")
    counts = streamed(cx, tmp_path / "chunks.h5")
    assert len(calls) > 2  # V1 in chunks of families
    assert counts == {"vcells": len(cx.vcells), "eecells": len(cx.eecells)}
    result = diff_files(tmp_path / "chunks.h5", tmp_path / "whole.h5", rtol=0, atol=0)
    assert result.equal, [d.describe() for d in result.differences[:5]]


def test_chunk_cuts_keep_vertices_and_squares_whole(built, tiny_chunks):
    cx = built("boxes_on_floor.obj")
    hc = cx.arcs.half_cells
    seen = []
    for part, vertices, shift in chunks.vcell_parts(cx.scene, cx.arcs):
        # the chunk's half-cells are the whole build's from `shift` on, of its vertices only
        n = len(part.half_cells)
        assert np.array_equal(part.half_cells.vertex, hc.vertex[shift: shift + n])
        assert np.array_equal(part.kind, cx.arcs.kind[hc.arc[shift: shift + n]])
        assert np.isin(part.half_cells.vertex, vertices).all()
        seen.append(vertices)
    seen = np.concatenate(seen)
    assert np.array_equal(seen, cx.scene.generator_vertices)  # each vertex in one chunk, in order
    squares = [np.unique(e1 * (1 << 32) + e2) for _, (_, e1, e2), _ in chunks.eecell_parts(cx.scene, cx.arcs)]
    assert len(np.unique(np.concatenate(squares))) == sum(map(len, squares))  # no square split


def test_v2_chunks_read_their_own_rows_of_the_file(built, tiny_chunks, tmp_path, monkeypatch):
    """V2 read from the file: each chunk of V-cells reads its own half-cells' rows and its
    VE arcs' (a run of consecutive arcs), the EE-cells' squares a slice of arcs at a time
    (the arcs' rows spilled with their incidences), never a whole dataset but the
    half-cells' vertices; the chunks are those made from V1 in memory."""
    import h5py

    cx = built("room_with_door.obj")
    cx.save(tmp_path / "whole.h5")
    monkeypatch.setattr(eecells, "ARC_SLICE", 97)
    reads = []
    read = h5py.Dataset.__getitem__

    def logged(self, key):
        values = read(self, key)
        reads.append((self.name.split("/V1/")[-1], len(values) if np.ndim(values) else 1))
        return values

    def same(a, b):
        return all(np.array_equal(getattr(a, name), getattr(b, name)) and getattr(a, name).dtype == getattr(b, name).dtype
                   for name in chunks.V2_ARC_ARRAYS) and all(
            np.array_equal(getattr(a.half_cells, name), getattr(b.half_cells, name))
            for name in a.half_cells.__dataclass_fields__)

    with h5py.File(tmp_path / "whole.h5", "r") as f, pytest.MonkeyPatch.context() as patch:
        patch.setattr(h5py.Dataset, "__getitem__", logged)
        stored = chunks.stored_v2_arcs(f["V1"])
        vparts = list(chunks.vcell_parts(cx.scene, stored))
        vreads, reads[:] = reads[:], []
        eparts = list(chunks.eecell_parts(cx.scene, stored))
    whole = list(chunks.vcell_parts(cx.scene, cx.arcs))
    assert len(vparts) == len(whole) > 2
    for (a, va, sa), (b, vb, sb) in zip(vparts, whole):
        assert sa == sb and np.array_equal(va, vb) and same(a, b)
    ewhole = list(chunks.eecell_parts(cx.scene, cx.arcs))
    assert len(eparts) == len(ewhole) > 2
    for (a, sq_a, ids_a), (b, sq_b, ids_b) in zip(eparts, ewhole):
        assert same(a, b) and np.array_equal(ids_a, ids_b) and all(map(np.array_equal, sq_a, sq_b))
        assert np.array_equal(a.kind, cx.arcs.kind[ids_a])  # (and not merely equal both ways)
    n_half, n_arcs = len(cx.arcs.half_cells), len(cx.arcs)
    big = max(np.diff(np.searchsorted(cx.arcs.half_cells.vertex, [v[0] for _, v, _ in whole] + [1 << 40])))
    assert [r for r in vreads if r[1] == n_half] == [("half_cells/vertex", n_half)]
    # every other read is of one chunk's rows (its VE arcs or its half-cells)
    assert max(r[1] for r in vreads if r[0] != "half_cells/vertex") <= 2 * big < n_half / 2
    assert max(r[1] for r in reads) <= eecells.ARC_SLICE < n_arcs / 2  # a slice of arcs at a time


def test_squares_found_in_slices_of_arcs_keep_the_order_of_one_call(built, monkeypatch):
    """square_chunks finds the incidences ARC_SLICE arcs at a time, spills them and puts
    them in order SQUARE_GROUP at a time: in order of square, each square's in
    arc_squares' order over all arcs (by block: EEE pairs, VE edges at w and
    T-junctions, XE; then by arc), and the same chunks, whatever the slices and groups
    (boxes_on_floor: EEE, VE and XE arcs in one square)."""
    cx = built("boxes_on_floor.obj")
    arc, e1, e2 = eecells.arc_squares(cx.scene, cx.arcs)
    whole = np.stack([arc, e1, e2], axis=1)[np.argsort(e1 * (1 << 32) + e2, kind="stable")]
    monkeypatch.setattr(eecells, "ARC_SLICE", 97)
    sliced = np.concatenate([np.stack(c, axis=1) for c in eecells.square_chunks(cx.scene, cx.arcs, 50)])
    assert np.array_equal(sliced, whole)
    # the chunks themselves (not only their concatenation) whatever the slices and groups of e1's
    monkeypatch.setattr(eecells, "ARC_SLICE", 1 << 18)
    monkeypatch.setattr(eecells, "SQUARE_GROUP", 1 << 22)
    one = list(eecells.square_chunks(cx.scene, cx.arcs, 50))
    assert len(one) > 3
    for slice_, group in ((97, 1), (97, 7), (23, 60)):
        monkeypatch.setattr(eecells, "ARC_SLICE", slice_)
        monkeypatch.setattr(eecells, "SQUARE_GROUP", group)
        chunked = list(eecells.square_chunks(cx.scene, cx.arcs, 50))
        assert len(chunked) == len(one)
        for a, b in zip(chunked, one):
            assert all(x.dtype == y.dtype and np.array_equal(x, y) for x, y in zip(a, b))
    # the arcs' rows carried with their incidences: the same chunks, each incidence with its arc's rows
    carried = list(eecells.square_chunks(cx.scene, cx.arcs, 50, carry=("kind", "generators", "interval")))
    assert len(carried) == len(one)
    for (arc_, e1_, e2_, kind, gens, interval), c in zip(carried, one):
        assert all(np.array_equal(x, y) for x, y in zip((arc_, e1_, e2_), c))
        assert np.array_equal(kind, cx.arcs.kind[arc_]) and np.array_equal(gens, cx.arcs.generators[arc_])
        assert np.array_equal(interval, cx.arcs.interval[arc_]) and interval.dtype == cx.arcs.interval.dtype
    # squares bounded by arcs of several kinds
    assert len(np.unique(np.stack([e1, e2, cx.arcs.kind[arc]], axis=1), axis=0)) > len(np.unique(e1 * (1 << 32) + e2))


def test_build_streams_v1_and_v2_into_the_file(tmp_path):
    """`viscx build` writes V1 and V2 chunk by chunk: the file equals the golden one, and
    to the bit the one written from every level in memory; the summary counts them from
    the file."""
    out = tmp_path / "t.h5"
    run = viscx_in_process("build", SAMPLES / "tetrahedra.obj", "-o", out)
    assert run.returncode == 0, run.stderr
    golden = Path(__file__).resolve().parent / "golden" / "tetrahedra.h5"
    assert diff_files(out, golden).equal
    cx = build_complex(SAMPLES / "tetrahedra.obj", quiet=True)
    cx.save(tmp_path / "whole.h5")
    assert diff_files(out, tmp_path / "whole.h5", rtol=0, atol=0).equal
    assert f"{len(cx.arcs)} arcs" in run.stdout
    assert f"{len(cx.vcells) + len(cx.eecells)} V- and EE-cells" in run.stdout


def test_a_scene_that_cast_rays_pickles(built):
    """A dask worker sends its copy of the scene to another worker after its tasks cast
    rays with it: the scene pickles without its ray tracer (embree's cannot be pickled),
    which is built again where it is read and casts the same."""
    import pickle

    scene = built("boxes_on_floor.obj").scene
    origins = np.tile(scene.bbox.mean(axis=0), (3, 1))
    directions = np.array([[0.0, -1.0, 0.0], [0.3, 0.2, 0.9], [-0.5, 0.1, 0.1]])
    face, t = scene.ray_caster.first_hit(origins, directions)
    assert np.any(face >= 0)  # (the floor at least)
    copy = pickle.loads(pickle.dumps(scene))
    assert copy._caster is None and scene._caster is not None
    assert np.array_equal(copy.vertices, scene.vertices)
    face2, t2 = copy.ray_caster.first_hit(origins, directions)
    assert np.array_equal(face2, face) and np.array_equal(t2, t)


def test_workers_without_scheduler_is_refused(tmp_path):
    run = viscx_in_process("build", SAMPLES / "two_triangles.obj", "-o", tmp_path / "t.h5", "--workers", "2")
    assert run.returncode == 2 and "--workers" in run.stderr and "--scheduler" in run.stderr
    assert "Traceback" not in run.stderr and not (tmp_path / "t.h5").exists()


def test_scheduler_without_dask_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import fails as if not installed
    run = viscx_in_process("build", SAMPLES / "two_triangles.obj", "-o", tmp_path / "t.h5", "--scheduler", "local")
    assert run.returncode == 2 and "pip install 'viscx[dask]'" in run.stderr
    assert "Traceback" not in run.stderr and not (tmp_path / "t.h5").exists()


# ---------------------------------------------------------------------------------------
# dask (optional): a local cluster of two worker processes


@pytest.fixture(scope="module")
def cluster():
    pytest.importorskip("dask.distributed")
    from viscx.distributed import Dask

    runner = Dask("local", workers=2)
    yield runner
    runner.close()


@pytest.fixture
def some_chunks(monkeypatch):
    """A few chunks a scene (one task each: the tiny chunks above would be thousands of
    round trips to the workers)."""
    monkeypatch.setattr(builder, "FAMILY_CHUNK", 3000)
    monkeypatch.setattr(chunks, "VCELL_CHUNK", 100)
    monkeypatch.setattr(chunks, "EECELL_CHUNK", 2000)


@pytest.mark.slow
@pytest.mark.parametrize("scene", SCENES)
def test_dask_chunks_give_the_same_file(scene, built, cluster, some_chunks, tmp_path):
    cx = built(scene)
    cx.save(tmp_path / "whole.h5")
    streamed(cx, tmp_path / "dask.h5", cluster)
    result = diff_files(tmp_path / "dask.h5", tmp_path / "whole.h5", rtol=0, atol=0)
    assert result.equal, [d.describe() for d in result.differences[:5]]
    assert len(cluster.peaks()) == 2


@pytest.mark.slow
@pytest.mark.parametrize("scene", sorted(p.name for p in SAMPLES.glob("*") if p.suffix in (".obj", ".ply")))
def test_build_on_a_local_cluster_equals_the_single_process_build(scene, tmp_path):
    pytest.importorskip("dask.distributed")
    one, two = tmp_path / "one.h5", tmp_path / "dask.h5"
    assert viscx_in_process("-q", "build", SAMPLES / scene, "-o", one).returncode == 0
    run = viscx_in_process("build", SAMPLES / scene, "-o", two, "--scheduler", "local", "--workers", "2")
    assert run.returncode == 0, run.stderr
    assert "dask: 2 workers" in run.stdout
    assert viscx_in_process("diff", "--rtol", "0", "--atol", "0", one, two).returncode == 0


@pytest.mark.slow
def test_city_streamed_and_on_a_local_cluster_equals_the_whole_build(tmp_path):
    """The 300-polygon city: `viscx build` (V1 and V2 streamed) and `viscx build --scheduler
    local --workers 2` against every level built in memory and written at once."""
    pytest.importorskip("dask.distributed")
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from dask_ladder import write_city

    city = write_city(300, tmp_path / "city300.obj")
    whole, one, two = tmp_path / "whole.h5", tmp_path / "one.h5", tmp_path / "dask.h5"
    build_complex(city, quiet=True).save(whole)
    assert viscx_in_process("-q", "build", city, "-o", one).returncode == 0
    assert viscx_in_process("-q", "build", city, "-o", two, "--scheduler", "local", "--workers", "2").returncode == 0
    for path in (one, two):
        run = viscx_in_process("diff", "--rtol", "0", "--atol", "0", path, whole)
        assert run.returncode == 0, run.stdout
