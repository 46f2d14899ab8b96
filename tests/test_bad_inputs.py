"""The bad-input corpus (tests/bad_inputs/README.md is the manifest): exit 2 with one line on
stderr naming the problem and the file, no traceback, no output or temporary file left; or a
documented success.

Every case runs in-process (fast), with warnings turned into errors and WARNING log records
counted, because in a real process both would reach stderr. One case of each kind of outcome
also runs through the real command (``python -m viscx``) in parallel subprocesses (more with
``-m slow``).
"""

import logging
import re
import subprocess
import sys
from pathlib import Path

import pytest

from viscx.cli import main

HERE = Path(__file__).resolve().parent
CORPUS = HERE / "bad_inputs"
REFERENCE = HERE / "golden" / "two_triangles.h5"
NOT_INPUTS = {"README.md", "make_binary.py"}


def manifest():
    """Rows of the README table as ``(file, command, exit code, keyword)``, one per command."""
    rows = []
    for line in (CORPUS / "README.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 5 or not cells[0].startswith("`"):
            continue
        name, commands, _, code, keyword = cells
        for command in commands.split(","):
            rows.append((name.strip("`"), command.strip(), int(code), keyword))
    return rows


CASES = manifest()


def argv(name, command, out):
    path = str(CORPUS / name)
    return {
        "build": ["build", path, "-o", str(out)],
        "info": ["info", path],
        "diff": ["diff", path, str(REFERENCE)],
        "flatland": ["flatland", "build", path, "-o", str(out)],
        "flatread": ["flatland", "formfactor", path],
    }[command]


def check(name, code, keyword, returncode, stderr, out_dir):
    """The assertions every case must pass, whichever way it was run."""
    left = sorted(p.name for p in out_dir.iterdir())
    assert "Traceback" not in stderr
    if code == 0:
        assert returncode == 0 and stderr == "", stderr
        return
    assert returncode == code, stderr
    assert stderr.count("\n") == 1 and stderr.endswith("\n"), f"not one line: {stderr!r}"
    assert keyword.lower() in stderr.lower(), stderr
    assert Path(name).stem in stderr, f"the message does not name the file: {stderr!r}"
    assert left == [], f"left behind: {left}"


def test_corpus_is_large_and_fully_documented():
    listed = {name for name, *_ in CASES}
    present = {p.name for p in CORPUS.iterdir() if p.name not in NOT_INPUTS and p.suffix != ".mtl"}
    assert listed == present, f"undocumented: {present - listed}, missing: {listed - present}"
    assert len(present) >= 30


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("name, command, code, keyword", CASES, ids=[f"{c[1]}-{c[0]}" for c in CASES])
def test_in_process(name, command, code, keyword, tmp_path, capsys, caplog, monkeypatch):
    monkeypatch.chdir(tmp_path)  # anything written by accident lands in the checked folder
    out = tmp_path / "out.h5"
    with caplog.at_level(logging.WARNING), pytest.raises(SystemExit) as exc:
        main(["--quiet", *argv(name, command, out)])
    _, err = capsys.readouterr()
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == []
    if code == 0 and command == "build":
        assert exc.value.code == 0 and out.exists(), err
        out.unlink()
    check(name, code, keyword, exc.value.code, err, tmp_path)


# Through the real command and a real stderr (every case also runs in-process above): one
# case of each kind of outcome, a file no reader takes, a scene the checks refuse, an HDF5
# file the HDF5 library refuses (its C library writes to the real stderr) and a documented
# success; ``-m slow`` adds a case of each other reader and check (an interpreter's start-up
# each, a second of CPU).
SUBPROCESS = [
    ("empty.obj", "build"),
    ("self_intersecting_polygon.obj", "build"),
    ("truncated.h5", "info"),
    ("non_manifold_fan.obj", "build"),
]
SUBPROCESS_SLOW = [
    ("binary_garbage.ply", "build"),
    ("overflowing_bbox.obj", "build"),
    ("truncated.stl", "build"),
    ("future_version.h5", "diff"),
]


def run_all(cases, tmp_path_factory):
    """Start every case at once (they are dominated by start-up), then collect them:
    {(name, command): (exit status, stderr, folder, expected code, keyword)}."""
    expected = {(name, command): (code, keyword) for name, command, code, keyword in CASES}
    runs = {}
    for name, command in cases:
        folder = tmp_path_factory.mktemp(Path(name).stem)
        process = subprocess.Popen(
            [sys.executable, "-m", "viscx", *argv(name, command, folder / "out.h5")],
            cwd=folder,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        runs[name, command] = (process, folder, *expected[name, command])
    results = {}
    for key, (process, folder, code, keyword) in runs.items():
        _, err = process.communicate(timeout=120)
        results[key] = (process.returncode, err, folder, code, keyword)
    return results


@pytest.fixture(scope="module")
def subprocess_runs(tmp_path_factory):
    return run_all(SUBPROCESS, tmp_path_factory)


@pytest.fixture(scope="module")
def slow_subprocess_runs(tmp_path_factory):
    return run_all(SUBPROCESS_SLOW, tmp_path_factory)


def check_run(returncode, err, folder, code, keyword, name):
    if code == 0:
        assert returncode == 0 and (folder / "out.h5").exists(), err
        (folder / "out.h5").unlink()
    check(name, code, keyword, returncode, err, folder)


@pytest.mark.parametrize("name, command", SUBPROCESS, ids=[f"{c}-{n}" for n, c in SUBPROCESS])
def test_real_command(name, command, subprocess_runs):
    check_run(*subprocess_runs[name, command], name)


@pytest.mark.slow
@pytest.mark.parametrize("name, command", SUBPROCESS_SLOW, ids=[f"{c}-{n}" for n, c in SUBPROCESS_SLOW])
def test_real_command_of_other_readers(name, command, slow_subprocess_runs):
    check_run(*slow_subprocess_runs[name, command], name)


def test_documented_successes_write_a_readable_file(tmp_path, capsys):
    for name, command, code, _ in CASES:
        if code != 0 or command != "build":
            continue
        out = tmp_path / re.sub(r"\W", "_", name)
        with pytest.raises(SystemExit) as exc:
            main(["--quiet", "build", str(CORPUS / name), "-o", str(out)])
        assert exc.value.code == 0
        with pytest.raises(SystemExit) as exc:
            main(["info", str(out)])
        assert exc.value.code == 0, capsys.readouterr().err
