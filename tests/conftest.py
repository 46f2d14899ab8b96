import contextlib
import io
import os
import subprocess
import sys
from pathlib import Path

# One BLAS thread per test process (set before numpy is imported; pytest-xdist's workers and
# the tests' subprocesses inherit it): OpenBLAS's threads spin while they wait for work, and
# beside make test's other worker they only took its CPU (shared machine: test_render.py 22.8
# -> 13.1 CPU s, the 512 x 512 sparse render 2.7-8.8 -> 0.6 s; V0-V2 builds unchanged).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# Idle OpenMP threads (numba's threading layer here, for its parallel kernels) sleep instead of
# spinning: spinning only took the other worker's core (shared machine: test_buildings' door and
# T-junction tests 15.8 -> 12.7 CPU s, test_vcells' random scenes 12.4 -> 11.6; the results
# do not depend on it).
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import pytest
from hypothesis import settings  # noqa: E402

# Hypothesis: the default suite draws the same examples on every run (CI must not turn red on
# an example no one has seen locally; a stop went red so). VISCX_HYPOTHESIS=explore draws fresh
# random examples (and keeps failures in the example database): run it when changing a kernel,
# and add what it finds as an @example.
settings.register_profile("ci", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("VISCX_HYPOTHESIS", "ci"))

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "sample_scenes"
sys.path.insert(0, str(Path(__file__).resolve().parent))


#: The longest test files, run first: ``make test`` hands whole files to its two pytest-xdist
#: workers (``--dist loadscope``: a file's module fixtures built once; with
#: ``--no-loadscope-reorder``, in this order, not by their number of tests), so a long file
#: started last would leave one worker idle at the end. Measured (per cent of the summed test
#: time of make test, 296 CPU s, shared machine, VISCX_TEST_CPU): 7.7, 7.4, 7.2, 6.6, 6.2, 3.2,
#: 3.1, 2.9, 2.9, 2.8, 2.8, 2.8, 2.5, 2.3, 2.3, 2.2, 2.1, 2.1 (the rest 2.0 or less).
LONGEST_FIRST = ["test_formfactor_queries.py", "test_discontinuities.py", "test_eecells.py", "test_vcells.py",
                 "test_buildings.py", "test_interrupt.py", "test_render.py", "test_fast_nodes.py",
                 "test_bad_inputs.py", "test_readme.py", "test_arcs.py", "test_fuzz.py", "test_golden.py",
                 "test_flatland_update.py", "test_queries.py", "test_kinks.py", "test_nodes.py",
                 "test_flatland_dynamic.py"]


def pytest_collection_modifyitems(items):
    """Run the files of :data:`LONGEST_FIRST` first, in that order (a stable sort: the tests of
    a file keep their order)."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(scope="session")
def sample_build(tmp_path_factory):
    """``sample_build(scene)``: the path of a ``viscx build`` of the sample scene ``scene``
    (a file name in sample_scenes/), made once per test process.

    Tests that want a full build bit for bit equal to what this machine computes take it from
    here, not from tests/golden/: the golden files may have been written on another machine
    (another CPU's vector units round the last bits of some sums differently, ~1e-15), and
    tests/test_golden.py holds them equal to a fresh build within `viscx diff`'s tolerances.
    """
    from viscx.cli import main

    folder = tmp_path_factory.mktemp("sample_builds")
    built = {}

    def build(scene):
        if scene not in built:
            out = folder / (Path(scene).stem + ".h5")
            with pytest.raises(SystemExit) as exc:
                main(["--quiet", "build", str(SAMPLES / scene), "-o", str(out)])
            assert exc.value.code == 0 and out.exists()
            built[scene] = out
        return built[scene]

    return build


def sample_scene_paths():
    """Every 3-D sample scene shipped in sample_scenes/."""
    return sorted(p for p in SAMPLES.glob("*") if p.suffix.lower() in (".obj", ".ply"))


@pytest.fixture(scope="module")
def office60():
    """The 58-polygon furnished office (benchmarks/buildings.py), built once a module (a
    module's own ``office60`` takes precedence)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from buildings import office

    from viscx.scene import build_scene

    return build_scene(office(60, seed=0))


@pytest.fixture(scope="module")
def cornell():
    """The sample Cornell box as a scene, loaded once a module (a module's own ``cornell``,
    a built file in some, takes precedence)."""
    from viscx.scene import load_scene

    return load_scene(ROOT / "sample_scenes" / "cornell_box.obj")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def soup(vertices, polygons, groups=None, names=None):
    """A PolygonSoup from a vertex list and a list of polygons (vertex index lists)."""
    from viscx.scene import PolygonSoup

    sizes = [len(p) for p in polygons]
    groups = np.zeros(len(polygons), dtype=np.int64) if groups is None else np.asarray(groups)
    names = names or [f"g{i}" for i in range(int(groups.max()) + 1)]
    return PolygonSoup(
        vertices=np.asarray(vertices, dtype=np.float64),
        polygon_offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        polygon_vertices=np.concatenate([np.asarray(p) for p in polygons]).astype(np.int64),
        polygon_group=groups.astype(np.int64),
        group_names=names,
    )


def viscx_in_process(*args, text=True):
    """``viscx args`` in this process through the console script's entry point
    (:func:`viscx.cli.main`), without a new interpreter's second of start-up and imports; for
    tests of a command's behaviour, not of the process (the real command:
    tests/test_bad_inputs.py). Returns a CompletedProcess (returncode, stdout, stderr: text,
    or bytes with ``text=False``)."""
    from viscx.cli import main

    out, err = (io.TextIOWrapper(io.BytesIO(), encoding="utf-8", write_through=True) for _ in range(2))
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([*map(str, args)])
            code = 0
        except SystemExit as exc:
            code = exc.code
    out, err = out.buffer.getvalue(), err.buffer.getvalue()
    return subprocess.CompletedProcess(args, code, out.decode() if text else out, err.decode() if text else err)


#: ``VISCX_TEST_CPU=path``: write the CPU seconds (user + system, of the test process and the
#: subprocesses it waited for) of each test's set-up, call and tear-down to ``path`` as
#: tab-separated lines ``nodeid  seconds`` (one file per pytest-xdist worker: ``path.gw0``, …).
#: Wall-clock ``--durations`` mislead on a shared machine; this is what a test costs the suite.
CPU_LOG = os.environ.get("VISCX_TEST_CPU")


def _cpu_seconds():
    import resource

    return sum(r.ru_utime + r.ru_stime for r in map(resource.getrusage, (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)))


if CPU_LOG:
    _CPU = {}

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        start = _cpu_seconds()
        yield
        _CPU[item.nodeid] = _CPU.get(item.nodeid, 0.0) + _cpu_seconds() - start

    def pytest_sessionfinish(session):
        worker = os.environ.get("PYTEST_XDIST_WORKER")
        with open(f"{CPU_LOG}.{worker}" if worker else CPU_LOG, "w") as log:
            log.writelines(f"{nodeid}\t{seconds:.3f}\n" for nodeid, seconds in _CPU.items())
