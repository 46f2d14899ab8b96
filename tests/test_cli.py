"""The command line: build, info, errors (the bad-input corpus is in test_bad_inputs.py)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLES

from viscx.cli import main


def run(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def test_build_then_info(tmp_path, capsys):
    out = tmp_path / "cornell.h5"
    code, stdout, err = run(["--quiet", "build", str(SAMPLES / "cornell_box.obj"), "-o", str(out)], capsys)
    assert code == 0 and out.exists() and err == ""
    code, stdout, _ = run(["info", str(out), "--json"], capsys)
    summary = json.loads(stdout)
    assert code == 0
    counts = summary["counts"]["scene"]
    # 16 quads, none merged (different groups or planes), 2 triangles each
    assert counts["faces"] == 16 and counts["triangles"] == 32
    assert summary["groups"]["light"] == 1 and summary["levels"] == ["scene", "V0", "V1", "V2"]
    assert summary["counts"]["V0"]["total"] > 0 and summary["counts"]["V1"]["total"] > 0
    assert summary["counts"]["V2"]["cells"] > 0 and summary["counts"]["V2"]["vertices"] == 28
    code, stdout, _ = run(["info", str(out)], capsys)
    assert code == 0 and "generator_edges" in stdout and "light (1 faces)" in stdout


def test_missing_file_is_one_line_exit_2(tmp_path, capsys):
    code, _, err = run(["build", str(tmp_path / "nope.obj"), "-o", str(tmp_path / "x.h5")], capsys)
    assert code == 2 and err.count("\n") == 1 and "no such file" in err
    assert not (tmp_path / "x.h5").exists()


def test_usage_error_is_one_line_exit_2(capsys):
    code, _, err = run(["build"], capsys)
    assert code == 2 and err.count("\n") == 1 and "Missing argument" in err


def test_console_script_end_to_end(tmp_path):
    """The console script's entry point in a process of its own: its arguments from sys.argv,
    a build written, its summary printed, exit 0 (the scene level: the levels above it are
    built in-process by tests/test_golden.py, and by a real process there too)."""
    out = tmp_path / "t.h5"
    done = subprocess.run(
        [sys.executable, "-c", "from viscx.cli import main; main()", "build", str(SAMPLES / "tetrahedra.obj"),
         "--levels", "-1", "-o", str(out)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0 and out.exists(), done.stderr
    assert "16 faces" in done.stdout


def test_info_counts_a_v0_level_by_kind(tmp_path, capsys):
    from viscx.formats.hdf5 import write_complex, write_nodes
    from viscx.scene import load_scene
    from viscx.skeleton.reference import reference_nodes

    scene = load_scene(SAMPLES / "tetrahedra.obj")
    nodes = reference_nodes(scene)
    out = tmp_path / "t.h5"
    write_complex(out, scene, levels={"V0": lambda g: write_nodes(g, nodes)})
    code, stdout, _ = run(["info", str(out), "--json"], capsys)
    counts = json.loads(stdout)["counts"]["V0"]
    assert code == 0 and counts == {"total": len(nodes), **nodes.counts(), "sites": len(nodes)}


@pytest.mark.parametrize("levels, expected", [(-1, ["scene"]), (0, ["scene", "V0"]), (1, ["scene", "V0", "V1"]),
                                              (2, ["scene", "V0", "V1", "V2"])])
def test_build_levels(levels, expected, tmp_path, capsys):
    from viscx.formats.hdf5 import ViscxFile, read_arcs, read_nodes, read_vcells
    from viscx.scene import load_scene
    from viscx.skeleton.reference import reference_nodes

    out = tmp_path / "t.h5"
    code, _, err = run(["--quiet", "build", str(SAMPLES / "tetrahedra.obj"), "--levels", str(levels), "-o", str(out)], capsys)
    assert code == 0, err
    with ViscxFile(out) as f:
        assert f.levels == expected
        if "V0" in expected:
            # the file's nodes are the brute-force reference's
            want = reference_nodes(load_scene(SAMPLES / "tetrahedra.obj"))
            got = read_nodes(f.h5["V0"])
            assert len(got) == len(want) and (got.generators == want.generators).all()
        if "V2" in expected:
            # one V-cell tiling per generator vertex, built on the file's own half-cells
            cells = read_vcells(f.h5["V2"])
            half_cells = read_arcs(f.h5["V1"]).half_cells
            assert len(np.unique(cells.vertex)) == 16 and cells.complete.all()
            assert np.abs(cells.element).max() <= len(half_cells)


def test_build_levels_out_of_range(tmp_path, capsys):
    code, _, err = run(["build", str(SAMPLES / "tetrahedra.obj"), "--levels", "3", "-o", str(tmp_path / "t.h5")], capsys)
    assert code == 2 and err.count("\n") == 1 and "--levels" in err
    assert not (tmp_path / "t.h5").exists()


def test_main_restores_what_it_installs(capsys):
    """``main`` turns signals into exceptions, hides their swallowed exceptions and ignores
    RuntimeWarnings while a command runs, and gives the caller (a notebook, a test) its own
    back afterwards, also when the command fails."""
    import signal
    import warnings

    def hook(info):
        pass

    def handler(signum, frame):
        pass

    before = {signal.SIGINT: signal.getsignal(signal.SIGINT)}
    unraisablehook = sys.unraisablehook
    try:
        sys.unraisablehook = hook
        signal.signal(signal.SIGTERM, handler)
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            filters = list(warnings.filters)
            for argv in (["--help"], ["build"], ["info", "/nonexistent/x.h5"]):
                run(argv, capsys)
                assert signal.getsignal(signal.SIGTERM) is handler and signal.getsignal(signal.SIGINT) is before[signal.SIGINT]
                assert sys.unraisablehook is hook and warnings.filters == filters, argv
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        sys.unraisablehook = unraisablehook


def test_help_imports_no_numeric_library():
    """``viscx --help`` and ``viscx build --help`` list the commands and options without
    importing numpy, numba, scipy, h5py, trimesh or embree (0.8 -> 0.1 CPU s for --help)."""
    heavy = ("numpy", "numba", "scipy", "h5py", "trimesh", "embreex")
    for argv in (["--help"], ["build", "--help"], ["diff", "--help"], ["render", "--help"]):
        script = f"import sys\nfrom viscx.cli import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n    pass\n" \
                 f"print([m for m in {heavy!r} if m in sys.modules])"
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
        assert done.stdout.splitlines()[-1] == "[]", (argv, done.stdout[-300:], done.stderr)


def test_a_matrix_imports_no_scipy_linalg_and_numba_still_has_blas(sample_build, tmp_path):
    """``viscx formfactor matrix`` loads its kernels without numba's BLAS probe, which
    imported scipy.linalg (~0.16 CPU s; :func:`viscx.cli.skip_numbas_blas_probe`), and
    numba still records BLAS as there, with its own probe back in place for the kernels
    that use it."""
    script = ("import sys\nfrom viscx.cli import main\n"
              f"try:\n    main(['--quiet', 'formfactor', 'matrix', {str(sample_build('two_triangles.obj'))!r}, "
              f"'-o', {str(tmp_path / 'F.h5')!r}])\nexcept SystemExit as exc:\n    assert exc.code in (0, None), exc.code\n"
              "import numba.np.arraymath as am, numba.np.linalg as la\n"
              "print('scipy.linalg' in sys.modules, am._HAVE_BLAS, am.ensure_blas is la.ensure_blas, "
              "la.ensure_blas.__module__)")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.stdout.splitlines()[-1].split() == ["False", "True", "True", "numba.np.linalg"], (done.stdout[-300:],
                                                                                                 done.stderr[-2000:])


def test_a_matrix_loads_its_kernels_without_numbas_registries(sample_build, tmp_path):
    """``viscx formfactor matrix`` loads its kernels from numba's cache without refreshing
    numba's contexts (:func:`viscx.cli.load_cached_kernels_without_registries`): numba's
    lowering registries (``numba.np.npyimpl``, ``numba.cpython.cmathimpl``) are never
    imported, the matrix is the one computed with them, and a kernel compiled afterwards in
    the same process still compiles (numba's compiler refreshes the contexts itself) and
    runs."""
    built = str(sample_build("two_triangles.obj"))
    script = ("import sys\nimport numpy as np\nfrom viscx.cli import main\n"
              f"try:\n    main(['--quiet', 'formfactor', 'matrix', {built!r}, '-o', {str(tmp_path / 'F.h5')!r}])\n"
              "except SystemExit as exc:\n    assert exc.code in (0, None), exc.code\n"
              "light = [m for m in ('numba.np.npyimpl', 'numba.cpython.cmathimpl') if m in sys.modules]\n"
              "from numba import njit\n"
              "f = njit(lambda a: np.sort(a)[::-1].copy())\n"
              "print(light, f(np.array([2.0, 3.0, 1.0])).tolist())")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.stdout.splitlines()[-1] == "[] [3.0, 2.0, 1.0]", (done.stdout[-300:], done.stderr[-2000:])
    # the same matrix through the API, in a process that never patched numba's cache
    script = ("from viscx.api import form_factor_matrix\nfrom viscx.formats.formfactors import write_matrix\n"
              f"from viscx.queries.visibility import open_query\nq = open_query({built!r})\n"
              f"write_matrix({str(tmp_path / 'G.h5')!r}, form_factor_matrix(q, tol=1e-6), q.scene)")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    import h5py

    with h5py.File(tmp_path / "F.h5") as a, h5py.File(tmp_path / "G.h5") as b:
        for name in ("indptr", "indices", "data", "error", "sky", "sky_error"):
            assert np.array_equal(a["formfactors"][name][:], b["formfactors"][name][:]), name


def test_numbas_cache_is_patched_only_where_it_is_the_one_expected(monkeypatch):
    """:func:`viscx.cli.load_cached_kernels_without_registries` replaces numba's
    ``Cache.load_overload`` only where its code refreshes the contexts and then loads (the
    layout it was written for), and only once."""
    from numba.core import caching

    from viscx.cli import load_cached_kernels_without_registries

    def other(self, sig, target_context):
        return self._load_overload(sig, target_context)

    monkeypatch.setattr(caching.Cache, "load_overload", other)
    load_cached_kernels_without_registries()
    assert caching.Cache.load_overload is other

    def expected(self, sig, target_context):
        target_context.refresh()
        return self._load_overload(sig, target_context)

    monkeypatch.setattr(caching.Cache, "load_overload", expected)
    load_cached_kernels_without_registries()
    patched = caching.Cache.load_overload
    assert patched is not expected and getattr(patched, "viscx", False)
    load_cached_kernels_without_registries()
    assert caching.Cache.load_overload is patched


def test_commands_run_with_one_blas_thread_unless_told():
    """The console script sets OPENBLAS_NUM_THREADS=1 (its threads spin on viscx's small
    products) and OMP_WAIT_POLICY=PASSIVE (numba's idle OpenMP threads sleep between kernels)
    before numpy loads, and keeps a value the user set."""
    import os

    names = ("OPENBLAS_NUM_THREADS", "OMP_WAIT_POLICY")
    script = ("import sys, os, viscx.__main__; "
              "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_WAIT_POLICY'], 'numpy' in sys.modules)")
    for given, expected in (((None, None), "1 PASSIVE False"), (("3", "ACTIVE"), "3 ACTIVE False")):
        env = {k: v for k, v in os.environ.items() if k not in names}
        env |= {k: v for k, v in zip(names, given) if v is not None}
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env)
        assert done.stdout.strip() == expected, done.stderr


def test_commands_let_the_heap_keep_freed_memory(monkeypatch, capsys, tmp_path):
    """Every command (not a --help) sets glibc's malloc to keep freed memory for reuse
    (viscx.memory.keep_freed_memory: fewer page faults, less system time), and the settings
    are taken where the C library is glibc."""
    import platform

    import viscx.memory

    calls = []
    monkeypatch.setattr(viscx.memory, "keep_freed_memory", lambda: calls.append(1))
    code, _, _ = run(["info", str(tmp_path / "missing.h5")], capsys)
    assert code == 2 and calls == [1]
    code, _, _ = run(["build", "--help"], capsys)
    assert code == 0 and calls == [1]
    monkeypatch.undo()
    if platform.libc_ver()[0] == "glibc":
        assert viscx.memory.keep_freed_memory()


def test_a_signal_waits_for_numba_to_let_go_of_its_compiler_lock():
    """A signal that arrives while numba compiles or loads a kernel (it holds its compiler
    lock) is raised when numba releases the lock, not inside it, where it would leave the
    kernel half loaded (a crash later, seen under load); elsewhere it is raised at once."""
    import signal

    from numba.core.compiler_lock import global_compiler_lock

    from viscx.cli import Terminated, _on_signal
    from viscx.formats.atomic import received_signals

    try:
        for signum, exception in ((signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, Terminated)):
            with pytest.raises(exception):
                _on_signal(signum, None)
            reached = False
            with pytest.raises(exception):
                with global_compiler_lock:
                    with global_compiler_lock:  # re-entrant: only the outermost release raises
                        _on_signal(signum, None)
                    reached = True
            assert reached and not global_compiler_lock.is_locked()
            with global_compiler_lock:  # nothing left pending
                pass
    finally:
        received_signals.clear()


def test_a_signal_inside_numbas_code_is_raised_again_outside_it():
    """A signal whose handler interrupts numba's own Python code (run inside a kernel call:
    an exception there left a returned tuple with an empty slot, and a segfault) is not
    raised there but delivered again moments later, and raised in viscx's code."""
    import signal
    import time

    import numba

    from viscx.cli import Terminated, _on_signal
    from viscx.formats.atomic import received_signals

    # a frame as numba's code would have: the handler's argument when it interrupts numba
    where = compile("import sys\nframe = sys._getframe()", str(Path(numba.__file__).parent / "core" / "x.py"), "exec")
    scope = {}
    exec(where, scope)
    previous = signal.signal(signal.SIGTERM, _on_signal)
    try:
        returned = []
        with pytest.raises(Terminated):
            # (the re-delivery may come at once on a loaded machine: inside this block)
            _on_signal(signal.SIGTERM, scope["frame"])  # deferred: no exception here
            returned.append(True)
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                time.sleep(0.001)  # delivered again, raised here (this file is not numba's)
        assert returned == [True] and received_signals[0] == signal.SIGTERM
        with pytest.raises(Terminated):
            _on_signal(signal.SIGTERM, sys._getframe())
    finally:
        signal.signal(signal.SIGTERM, previous)
        received_signals.clear()


def test_a_signal_while_the_handler_arranges_its_delivery_is_delivered_again(monkeypatch):
    """On a loaded machine the 5 ms re-delivery can arrive before ``_deliver_again`` returns,
    while the first handler (called in numba's code) is still on the stack: raising then would
    unwind through numba's frame, so it is delivered again too."""
    import signal

    import numba

    from viscx import cli
    from viscx.formats.atomic import received_signals

    where = compile("import sys\nframe = sys._getframe()", str(Path(numba.__file__).parent / "core" / "x.py"), "exec")
    scope = {}
    exec(where, scope)
    inside = []
    monkeypatch.setattr(cli, "_deliver_again", lambda signum: inside.append(sys._getframe().f_back))
    try:
        cli._on_signal(signal.SIGTERM, scope["frame"])
    finally:
        received_signals.clear()
    assert inside[0].f_code is cli._on_signal.__code__
    assert cli._in_numba(inside[0])  # a stack holding the handler: not raised there
    assert not cli._in_numba(sys._getframe())


def test_kernel_cache_files_change_one_process_at_a_time(tmp_path, monkeypatch):
    """Two saves of two signatures of one kernel at once (a cold cache, two processes
    compiling it): with numba's own ``IndexDataCacheFile.save`` both read an empty index,
    both name their data file ``.1``, and the index keeps one signature, whose file may
    hold the other's code (numba issues #4807 and #10128: a segfault when it is called).
    With :func:`viscx.cli.lock_kernel_cache_files` each signature reads back its own
    data. The two saves overlap for sure: reading the index pauses 0.2 s. (Threads, each
    with its own open lock file: ``flock`` locks them against each other as it does two
    processes.)"""
    import threading
    import time

    from numba.core import caching

    from viscx.cli import lock_kernel_cache_files

    cache_file = caching.IndexDataCacheFile
    for name in ("save", "load"):  # numba's own (a command run in this process locked them)
        monkeypatch.setattr(cache_file, name, getattr(getattr(cache_file, name), "__wrapped__", getattr(cache_file, name)))
    read = cache_file._load_index

    def slow_read(self):
        index = read(self)
        time.sleep(0.2)
        return index

    monkeypatch.setattr(cache_file, "_load_index", slow_read)

    def race(path):
        path.mkdir()
        files = [cache_file(str(path), "kernel", ("source", 1)) for _ in range(2)]
        saves = [threading.Thread(target=f.save, args=(key, key.upper())) for f, key in zip(files, "ab")]
        for t in saves:
            t.start()
        for t in saves:
            t.join()
        return {key: cache_file(str(path), "kernel", ("source", 1)).load(key) for key in "ab"}

    assert race(tmp_path / "numba") != {"a": "A", "b": "B"}
    lock_kernel_cache_files()
    assert getattr(cache_file.save, "viscx", False) and getattr(cache_file.load, "viscx", False)
    assert race(tmp_path / "locked") == {"a": "A", "b": "B"}
    first = cache_file.save
    lock_kernel_cache_files()  # once only
    assert cache_file.save is first
