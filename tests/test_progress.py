"""Progress of a build when stderr is not a terminal (CI, nohup, a pipe): log lines with
elapsed time and peak memory, at least one every HEARTBEAT seconds while a stage runs;
out of memory as one line naming the stage; the printed total counts each stage once."""

import json
import re
import subprocess
import sys
import textwrap
import time

import pytest
from conftest import SAMPLES

from viscx import progress
from viscx.cli import main

LINE = re.compile(r"^\[\s*([0-9.]+) s, peak ([0-9.]+) GB\] (.*)$")


def test_heartbeat_is_at_most_30_seconds():
    """The first line by QUIET_START + HEARTBEAT at the latest, then one at least every HEARTBEAT."""
    assert progress.HEARTBEAT <= 30 and progress.QUIET_START <= 30 and progress.LOG_EVERY <= progress.HEARTBEAT


def test_a_short_run_writes_no_progress(tmp_path, capsys):
    """Before QUIET_START nothing is written: a quick command's stderr is its result or error."""
    with pytest.raises(SystemExit) as exc:
        main(["build", str(SAMPLES / "two_triangles.obj"), "--levels", "0", "-o", str(tmp_path / "t.h5")])
    assert exc.value.code == 0 and capsys.readouterr().err == ""


def test_a_silent_stage_still_writes_lines(tmp_path):
    """A fake V0 that sleeps 2.5 s without reporting, the heartbeat shortened to 0.4 s:
    stderr (a pipe) gets a line at least every 0.4 s (+ the thread's 0.1 s tick)."""
    script = textwrap.dedent(f"""
        import time
        from viscx import pipeline, progress
        from viscx.cli import main
        progress.HEARTBEAT = 0.4
        progress.QUIET_START = 0.0
        name, nodes = pipeline.LEVELS[0]

        def slow_nodes(scene, built, quiet):
            time.sleep(2.5)
            return nodes(scene, built, quiet)

        pipeline.LEVELS[0] = (name, slow_nodes)
        main(["build", {str(SAMPLES / "two_triangles.obj")!r}, "--levels", "0", "-o", {str(tmp_path / "t.h5")!r}])
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = [LINE.match(line) for line in done.stderr.splitlines()]
    assert all(lines), done.stderr
    stamps = [float(m.group(1)) for m in lines]
    messages = [m.group(3) for m in lines]
    assert all(float(m.group(2)) > 0 for m in lines)
    start = messages.index("build: V0 started")
    end = next(i for i, m in enumerate(messages) if m.startswith("build: V0 done in"))
    assert sum("V0 still running" in m for m in messages[start:end]) >= 4
    # a missed heartbeat would leave a gap of 0.8 s or more, a silent stage one of 2.5 s; the
    # slack is for a loaded machine (0.70 s seen at load 14)
    assert max(b - a for a, b in zip(stamps[start:end + 1], stamps[start + 1:end + 1])) <= 0.4 + 0.35
    assert messages[-1].startswith("build: write done in")


def test_log_bar_writes_its_count_at_most_every_log_every(monkeypatch, capsys):
    monkeypatch.setattr(progress, "LOG_EVERY", 0.2)
    monkeypatch.setattr(progress, "QUIET_START", 0.0)
    with progress.bar(total=5, desc="arcs", unit="chunk") as b:  # capsys' stderr is no terminal
        assert isinstance(b, progress.LogBar)
        b.update()
        time.sleep(0.25)
        b.update(2)
        b.update()  # too soon after the last line
    err = capsys.readouterr().err.splitlines()
    assert err[-1].endswith("arcs: 3/5 chunks")
    with progress.bar(total=5, desc="quiet", quiet=True) as b:
        b.update()
    assert capsys.readouterr().err == ""


def test_out_of_memory_is_one_line_naming_the_stage(tmp_path, monkeypatch, capsys):
    from viscx import pipeline

    def no_memory(scene, built, quiet):
        raise MemoryError()

    monkeypatch.setattr(pipeline, "LEVELS", [pipeline.LEVELS[0], ("V1", no_memory), *pipeline.LEVELS[2:]])
    # (with an output, V1 is built into the file: pipeline.stream_arcs)
    monkeypatch.setattr(pipeline, "stream_arcs", lambda *args: no_memory(None, None, None))
    out = tmp_path / "t.h5"
    with pytest.raises(SystemExit) as exc:
        main(["-q", "build", str(SAMPLES / "two_triangles.obj"), "-o", str(out)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1, err
    assert "out of memory in the V1 stage" in err and "--levels 0" in err and "smaller scene" in err
    assert not out.exists() and not list(tmp_path.iterdir())


def test_printed_total_counts_each_stage_once(tmp_path, capsys):
    out = tmp_path / "t.h5"
    start = time.perf_counter()
    with pytest.raises(SystemExit):
        main(["build", str(SAMPLES / "tetrahedra.obj"), "-o", str(out)])
    wall = time.perf_counter() - start
    total = float(re.search(r"\(([0-9.]+) s\)$", capsys.readouterr().out.strip()).group(1))
    with pytest.raises(SystemExit):
        main(["info", str(out), "--json"])
    timings = json.loads(capsys.readouterr().out)["timings"]
    assert "V2 V-cells" in timings  # V2's parts are stored beside V2
    assert sum(timings[k] for k in ("scene", "V0", "V1", "V2")) - 0.005 <= total <= wall + 0.005  # printed to 0.01 s
