"""Outputs never replace an input (same file, symbolic or hard link), streams (FIFOs,
character devices, ``-``) are written directly, regular files atomically, and the
temporaries of a writer killed by SIGKILL are removed by the next write."""

import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from viscx.cli import main
from viscx.formats.atomic import atomic_path, remove_stale_temporaries, temporary_name

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "tests" / "golden" / "cornell_box.h5"
FLAT = ROOT / "sample_scenes" / "flatland" / "three_circles.json"
LIGHT = "278,540,280"


def run(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--quiet", *map(str, args)])
    return exc.value.code, capsys.readouterr()


@pytest.fixture
def room(tmp_path):
    path = tmp_path / "room.h5"
    shutil.copyfile(GOLDEN, path)
    return path


def commands(room, out):
    return {
        "query shadows": ["query", "shadows", room, "--light", LIGHT, "-o", out],
        "query visible": ["query", "visible", room, "--from", LIGHT, "-o", out],
        "formfactor matrix": ["formfactor", "matrix", room, "-o", out],
        "formfactor point": ["formfactor", "point", room, "--point", "278,1,280", "--normal", "0,1,0", "--to-face", "15",
                             "-o", out],
        "render": ["render", room, "--camera", "278,273,-800", "--look-at", "278,273,0", "--light-group", "light",
                   "--size", "8", "8", "-o", out],
        "query discontinuities": ["query", "discontinuities", room, "--light-group", "light", "-o", out],
    }


@pytest.mark.parametrize("how", ["same", "symlink", "hardlink"])
@pytest.mark.parametrize("command", sorted(commands("", "")))
def test_output_that_is_the_input_is_refused(command, how, room, tmp_path, capsys):
    before = room.read_bytes()
    out = room
    if how == "symlink":
        out = tmp_path / "alias.h5"
        out.symlink_to(room)
    elif how == "hardlink":
        out = tmp_path / "hard.h5"
        os.link(room, out)
    code, captured = run(commands(room, out)[command], capsys)
    assert code == 2 and "is an input" in captured.err, captured.err
    assert room.read_bytes() == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_build_and_flatland_refuse_their_input(tmp_path, capsys):
    scene = tmp_path / "t.obj"
    shutil.copyfile(ROOT / "sample_scenes" / "tetrahedra.obj", scene)
    flat = tmp_path / "in.json"
    shutil.copyfile(FLAT, flat)
    for args, path in ((["build", scene, "-o", scene], scene), (["flatland", "build", flat, "-o", flat], flat),
                       (["flatland", "formfactor", flat, "-o", flat], flat)):
        before = path.read_bytes()
        code, captured = run(args, capsys)
        assert code == 2 and "is an input" in captured.err, captured.err
        assert path.read_bytes() == before


def test_flatland_move_in_place_and_not_onto_itself(tmp_path, capsys):
    cx = tmp_path / "three.h5"
    assert run(["flatland", "build", FLAT, "-o", cx], capsys)[0] == 0
    before = cx.read_bytes()
    code, captured = run(["flatland", "move", cx, "--object", "0", "--by", "0.01,0", "-o", cx], capsys)
    assert code == 2 and "is an input" in captured.err
    assert cx.read_bytes() == before
    code, captured = run(["flatland", "move", cx, "--object", "0", "--by", "0.01,0"], capsys)  # documented: in place
    assert code == 0, captured.err
    assert cx.read_bytes() != before


def test_fifo_is_written_directly(room, tmp_path, capsys):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(open(fifo, "rb").read()))
    reader.start()
    code, captured = run(["query", "visible", room, "--from", LIGHT, "-o", fifo], capsys)
    reader.join(60)
    assert code == 0, captured.err
    assert received and received[0].startswith(b"{")
    assert fifo.is_fifo()


def test_symlink_to_a_device_stays(room, tmp_path, capsys):
    link = tmp_path / "null"
    link.symlink_to("/dev/null")
    code, captured = run(["query", "visible", room, "--from", LIGHT, "-o", link], capsys)
    assert code == 0, captured.err
    assert link.is_symlink() and os.readlink(link) == "/dev/null"
    code, captured = run(["query", "visible", room, "--from", LIGHT, "-o", "-"], capsys)
    assert code == 0 and captured.out.startswith("{")
    assert not (Path.cwd() / "-").exists()


def test_hdf5_output_onto_a_device_is_refused(tmp_path, capsys):
    code, captured = run(["build", ROOT / "sample_scenes" / "tetrahedra.obj", "-o", "/dev/null", "--levels", "-1"],
                         capsys)
    assert code == 2 and "regular file" in captured.err


def test_symlink_to_a_file_writes_its_target(room, tmp_path, capsys):
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    assert run(["query", "visible", room, "--from", LIGHT, "-o", link], capsys)[0] == 0
    assert link.is_symlink() and target.read_text().startswith("{")


def test_temporaries_of_a_killed_writer_are_removed(tmp_path):
    """A writer killed by SIGKILL inside atomic_path leaves its temporary; the next write
    to the same path removes it, and keeps the temporary of a writer still running."""
    out = tmp_path / "out.h5"
    code = ("import os, signal, sys; from viscx.formats.atomic import atomic_path\n"
            "with atomic_path(sys.argv[1]) as tmp:\n"
            "    open(tmp, 'wb').write(b'half')\n"
            "    os.kill(os.getpid(), signal.SIGKILL)\n")
    killed = subprocess.run([sys.executable, "-c", code, str(out)])
    assert killed.returncode == -signal.SIGKILL
    stale = [p for p in tmp_path.iterdir() if p.name.startswith(".out.h5.tmp")]
    assert len(stale) == 1 and not out.exists()
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        busy = tmp_path / f".out.h5.tmp{live.pid}"
        busy.write_bytes(b"being written")
        with atomic_path(out) as tmp:
            tmp.write_bytes(b"whole")
        assert out.read_bytes() == b"whole"
        assert not stale[0].exists()
        assert busy.exists()
    finally:
        live.kill()
        live.wait()
    assert remove_stale_temporaries(out) == [busy]
    assert temporary_name(out).name == f".out.h5.tmp{os.getpid()}"
