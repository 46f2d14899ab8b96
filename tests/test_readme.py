"""README.md as a newcomer reads it: every command block runs, in order, in one temporary
folder (with ``sample_scenes/`` and ``tests/golden/`` beside it, as in the repository),
so a README command that breaks fails the suite.

Lines starting with ``viscx`` run in this process through :func:`viscx.cli.main`, the
console script's entry point (a new interpreter per command would cost a second each);
any other line runs in bash with the environment's ``bin/`` first on the PATH. A
``make`` block is dry-run (``make -n``: its targets exist; ``make test`` would run this
very suite); ``.venv`` is the environment running the tests. The Python block (Library)
is executed. Outputs are checked to exist. ``viscx render`` lines without ``--size`` render
at a thumbnail size (:data:`THUMBNAIL`): the same code paths at a 30th of the pixels (the
README's images at full size: tests/test_render.py).
"""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

from viscx.cli import main

README = (ROOT / "README.md").read_text()
BLOCK = re.compile(r"^```(sh|python)\n(.*?)^```", re.S | re.M)


def blocks(kind):
    """The README's ``kind`` code blocks, in order: (first line number, text)."""
    return [(README[:m.start()].count("\n") + 1, m.group(2)) for m in BLOCK.finditer(README) if m.group(1) == kind]


def commands(text):
    """The block's commands: continuation lines joined, comments and blank lines dropped."""
    lines = text.replace("\\\n", " ").splitlines()
    return [shlex.split(line, comments=True) for line in lines if shlex.split(line, comments=True)]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A temporary folder laid out like the repository for the README's paths."""
    here = tmp_path_factory.mktemp("readme")
    (here / "sample_scenes").symlink_to(ROOT / "sample_scenes")
    (here / "tests").mkdir()
    (here / "tests" / "golden").symlink_to(ROOT / "tests" / "golden")
    (here / ".venv").symlink_to(sys.prefix)  # the environment running the tests, as `make venv` makes it
    return here


def run_viscx(argv, capsys):
    """``viscx argv`` in this process: (exit status, stdout, stderr)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def outputs(argv):
    """The files a command says it writes (``-o``)."""
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in ("-o", "--output")]


SH = blocks("sh")
THUMBNAIL = ["--size", "96", "96"]


def test_the_readme_has_its_blocks():
    assert len(SH) >= 10 and len(blocks("python")) == 1


@pytest.mark.parametrize("line,text", SH, ids=[f"line{line}" for line, _ in SH])
def test_command_block(line, text, folder, monkeypatch, capsys):
    monkeypatch.chdir(folder)
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    for argv in commands(text):
        if argv[0] == "make":
            done = subprocess.run(["make", "-n", "-C", str(ROOT), *argv[1:]], capture_output=True, text=True)
            assert done.returncode == 0, f"README line {line}: {' '.join(argv)}: {done.stderr}"
            continue
        if argv[:2] == ["source", ".venv/bin/activate"] and sys.prefix == sys.base_prefix:
            continue  # not run from a virtual environment: nothing to activate
        if argv[0] != "viscx" or set(argv) & {"|", "&&", ";"}:
            done = subprocess.run(["bash", "-ec", shlex.join(argv)], capture_output=True, text=True)
            assert done.returncode == 0, f"README line {line}: {' '.join(argv)}: {done.stderr}"
            continue
        expected = 0
        if "||" in argv:  # `viscx diff ... || exit 1`: the command itself must succeed
            argv = argv[:argv.index("||")]
        if argv[1] == "render" and "--size" not in argv:
            argv = [*argv, *THUMBNAIL]
        code, out, err = run_viscx(argv[1:], capsys)
        assert code == expected, f"README line {line}: {' '.join(argv)} exited {code}: {err}"
        assert "internal error" not in err
        for path in outputs(argv):
            assert (folder / path).exists(), f"README line {line}: {' '.join(argv)} did not write {path}"


def test_library_block(monkeypatch):
    monkeypatch.chdir(ROOT)
    (line, code), = blocks("python")
    namespace = {}
    exec(compile(code, f"README.md:{line}", "exec"), namespace)
    assert namespace["free"].shape == (1000,) and namespace["scene"].n_faces == 16


def test_the_console_script_is_in_the_environment(tmp_path):
    """What the README tells a newcomer to run: the environment's ``viscx``."""
    script = Path(sys.executable).parent / "viscx"
    assert script.exists(), "pip install -e . makes the console script beside the interpreter"
    done = subprocess.run([str(script), "--version"], capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.startswith("viscx")
