"""First run: numba compiles a kernel only on a cache miss, and then viscx says so (one
notice, then a count); ``python -m viscx.warmup`` runs every command's kernels once."""

import subprocess
import sys
import textwrap

KERNEL = '''
from numba import njit


@njit(cache=True)
def twice(x):
    return 2 * x
'''

RUN = textwrap.dedent("""
    from viscx import progress
    progress.LOG_EVERY = progress.QUIET_START = 0.0
    progress.report_compilation()
    import viscx_fake_kernels
    assert viscx_fake_kernels.twice(21) == 42
""")


def _run(tmp_path):
    env = {"PYTHONPATH": str(tmp_path), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    import os

    return subprocess.run([sys.executable, "-c", RUN], capture_output=True, text=True, timeout=300,
                          env={**os.environ, **env})


def test_compilation_is_announced_only_on_a_cache_miss(tmp_path):
    (tmp_path / "viscx_fake_kernels.py").write_text(KERNEL)
    first = _run(tmp_path)
    assert first.returncode == 0, first.stderr
    lines = first.stderr.splitlines()
    assert sum(line.startswith("viscx: compiling numba kernels for their first use") for line in lines) == 1
    assert any(line.endswith("compiling kernels: 1 kernel (twice)") for line in lines), first.stderr
    second = _run(tmp_path)  # loaded from numba's cache: not a word
    assert second.returncode == 0 and second.stderr == "", second.stderr


def test_warm_up_runs_every_query():
    from viscx.warmup import warm_up

    assert warm_up() > 0
