"""Scoped point queries: ``viscx query shadows|visible SCENE_FILE`` builds only the point's
V-cells (nothing else of the complex) and answers exactly as from the full build.

The full builds are the golden files (tests/test_golden.py keeps them equal to a fresh
build); that the point's cells themselves are right is checked against the reference
enumerator and embree in tests/test_queries.py.
"""

import json
from pathlib import Path

import pytest
from conftest import SAMPLES, viscx_in_process
from test_queries import LIGHTS

from viscx.queries.shadows import shadows
from viscx.queries.visibility import open_query, view_from, visible_result

GOLDEN = Path(__file__).resolve().parent / "golden"


@pytest.mark.parametrize("name", sorted(LIGHTS))
def test_scoped_shadows_equal_full_build(name):
    """Every field of the shadows answer (lit loops, boundaries, areas, completeness)."""
    full = shadows(GOLDEN / (Path(name).stem + ".h5"), LIGHTS[name])[2]
    scoped = shadows(SAMPLES / name, LIGHTS[name])[2]
    assert scoped == full


def test_scoped_visible_equal_full_build():
    p = (278.0, 273.0, -800.0)
    answers = []
    for path in (GOLDEN / "cornell_box.h5", SAMPLES / "cornell_box.obj"):
        q = open_query(path)
        view, stored = view_from(q, p)
        answers.append(visible_result(q.scene, view, stored))
    assert answers[0] == answers[1]


def test_scoped_scene_options_apply():
    """--epsilon reaches the scoped build (the scene's epsilon is the one asked for)."""
    q = open_query(SAMPLES / "cornell_box.obj", epsilon=1e-3)
    assert q.scene.epsilon == 1e-3
    assert open_query(SAMPLES / "cornell_box.obj").scene.epsilon != 1e-3


def _viscx(*args):
    return viscx_in_process(*args)


def test_cli_scoped_shadows(tmp_path):
    out = tmp_path / "s.json"
    r = _viscx("query", "shadows", SAMPLES / "tetrahedra.obj", "--light", "5,5,5", "-o", out)
    assert r.returncode == 0, r.stderr
    assert json.loads(out.read_text()) == shadows(GOLDEN / "tetrahedra.h5", (5.0, 5.0, 5.0))[2]


@pytest.mark.parametrize("args,message", [
    (["shadows", "{h5}", "--light", "5,5,5", "--weld", "1e-6"], "--weld apply to scene files only"),
    (["visible", "{h5}", "--from", "5,5,5", "--epsilon", "1e-3"], "--epsilon apply to scene files only"),
    (["shadows", "{missing}", "--light", "5,5,5"], "missing.obj"),
])
def test_cli_scoped_errors(tmp_path, args, message):
    args = [a.format(h5=GOLDEN / "tetrahedra.h5", missing=tmp_path / "missing.obj") for a in args]
    r = _viscx("query", *args)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and message in r.stderr, r.stderr
