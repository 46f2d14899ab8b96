"""Interrupt safety: SIGTERM or SIGINT during `viscx build` leaves neither the output nor its
temporary file, and the exit status says what happened (143 terminated, 130 interrupted).

The scene is an icosphere of 81 920 triangles, built to the scene level only: about 1.5 s of scene stage and 0.3 s of
writing, long enough to catch the build in either stage by polling.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

EXIT = {signal.SIGTERM: 143, signal.SIGINT: 130}
MESSAGE = {signal.SIGTERM: "viscx: terminated", signal.SIGINT: "viscx: interrupted"}
TOO_FAST = "the build finished before it could be interrupted: make the test scene bigger"


@pytest.fixture(scope="module")
def big_scene(tmp_path_factory):
    trimesh = pytest.importorskip("trimesh")
    path = tmp_path_factory.mktemp("scene") / "sphere.ply"
    trimesh.creation.icosphere(subdivisions=6).export(path)
    return path


def start_build(scene, out):
    # SIGINT is ignored by processes started in the background of a non-interactive shell,
    # and Python then installs no KeyboardInterrupt handler: restore the default first
    return subprocess.Popen(
        [sys.executable, "-X", "faulthandler", "-m", "viscx", "--quiet", "build", str(scene), "--levels", "-1", "-o", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def cpu_seconds(pid):
    """User + system CPU time of a live process (Linux /proc), 0 once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def wait_for(condition, process, timeout=60):
    """Poll until ``condition()`` holds; fail if the build ends first."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert process.poll() is None, f"{TOO_FAST}\n{process.stderr.read()}"
        assert time.monotonic() < deadline, "the build never got there"
        time.sleep(0.005)


def assert_clean_exit(process, signum, folder):
    _, err = process.communicate(timeout=60)
    assert process.returncode == EXIT[signum], err
    # (click prints an empty line before re-raising Ctrl-C as Abort; hence strip())
    assert err.strip().splitlines() == [MESSAGE[signum]], err
    assert sorted(p.name for p in folder.iterdir()) == [], "left behind after the signal"


# Each signal in one stage by default (SIGTERM while writing, SIGINT in the scene stage: both
# exit statuses, both stages), the other two pairs under slow: a build of the big scene is
# 2-4 CPU s.
@pytest.mark.parametrize("signum", [signal.SIGTERM, pytest.param(signal.SIGINT, marks=pytest.mark.slow)],
                         ids=["SIGTERM", "SIGINT"])
def test_signal_while_writing(signum, big_scene, tmp_path):
    """Signalled while the temporary output file exists: the temporary file is removed."""
    out = tmp_path / "sphere.h5"
    process = start_build(big_scene, out)
    wait_for(lambda: any(tmp_path.glob(".sphere.h5.tmp*")), process)
    process.send_signal(signum)
    assert_clean_exit(process, signum, tmp_path)


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc for CPU times")
@pytest.mark.parametrize("signum", [pytest.param(signal.SIGTERM, marks=pytest.mark.slow), signal.SIGINT],
                         ids=["SIGTERM", "SIGINT"])
def test_signal_while_building_the_scene(signum, big_scene, tmp_path, startup_cpu):
    """Signalled in the scene stage, before anything is written: nothing appears."""
    out = tmp_path / "sphere.h5"
    process = start_build(big_scene, out)
    # working, not importing: past the CPU time a whole tiny build takes
    wait_for(lambda: cpu_seconds(process.pid) > startup_cpu + 0.3, process)
    assert not list(tmp_path.iterdir()), f"already writing; {TOO_FAST}"
    process.send_signal(signum)
    assert_clean_exit(process, signum, tmp_path)


@pytest.fixture(scope="module")
def startup_cpu(tmp_path_factory):
    """CPU seconds of a complete build of the smallest sample scene (mostly imports)."""
    from conftest import SAMPLES

    out = tmp_path_factory.mktemp("tiny") / "t.h5"
    process = start_build(SAMPLES / "two_triangles.obj", out)
    used = 0.0
    while process.poll() is None:
        used = max(used, cpu_seconds(process.pid))
        time.sleep(0.005)
    assert process.returncode == 0, process.stderr.read()
    return used
