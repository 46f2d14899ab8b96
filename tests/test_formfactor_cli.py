"""``viscx formfactor`` as subcommands (point, faces, groups, matrix): the old one-command
style still gives the same answers, with one deprecation line on stderr; every --help of
the command line shows a shell example."""

import json

import click
import numpy as np
import pytest
from conftest import ROOT

from viscx.cli import cli, main

GOLDEN = ROOT / "tests" / "golden"
CORNELL = GOLDEN / "cornell_box.h5"
TWO = GOLDEN / "two_triangles.h5"


def run(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--quiet", *map(str, argv)])
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def without_seconds(text):
    """The JSON record without its timings (``seconds`` at any depth)."""
    def strip(v):
        return {k: strip(x) for k, x in v.items() if k != "seconds"} if isinstance(v, dict) else v
    return strip(json.loads(text))


@pytest.mark.parametrize("new, old", [
    (["point", CORNELL, "--point", "278,1,280", "--normal", "0,1,0", "--to-face", "15"],
     [CORNELL, "--point", "278,1,280", "--normal", "0,1,0", "--to-face", "15"]),
    (["faces", TWO, "--from-face", "0", "--to-face", "1", "--tol", "1e-5"],
     [TWO, "--from-face", "0", "--to-face", "1", "--tol", "1e-5"]),
    (["groups", TWO, "--from-group", "a", "--to-group", "b"],
     [TWO, "--from-group", "a", "--to-group", "b"]),
    # a face with a group: only the old form says it so
    (["groups", TWO, "--from-face", "0", "--to-group", "b"], [TWO, "--from-face", "0", "--to-group", "b"]),
])
def test_old_form_answers_as_the_subcommand_with_a_note(new, old, capsys):
    code, out_new, err_new = run(["formfactor", *new], capsys)
    assert code == 0 and err_new == "", err_new
    code, out_old, err_old = run(["formfactor", *old], capsys)
    assert code == 0, err_old
    assert without_seconds(out_old) == without_seconds(out_new)
    assert err_old.count("\n") == 1 and "deprecated" in err_old and f"viscx formfactor {new[0]} FILE" in err_old


def test_old_matrix_form(tmp_path, capsys):
    code, out_new, _ = run(["formfactor", "matrix", TWO, "-o", tmp_path / "new.h5"], capsys)
    assert code == 0
    code, out_old, err = run(["formfactor", TWO, "--matrix", "-o", tmp_path / "old.h5"], capsys)
    assert code == 0 and err.count("\n") == 1 and "viscx formfactor matrix FILE" in err
    new, old = without_seconds(out_new), without_seconds(out_old)
    assert new.pop("matrix").endswith("new.h5") and old.pop("matrix").endswith("old.h5") and new == old
    from viscx.formats.formfactors import read_matrix

    a, b = read_matrix(tmp_path / "old.h5"), read_matrix(tmp_path / "new.h5")
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a if k != "summary")


@pytest.mark.parametrize("argv, message", [
    ([CORNELL], "say which form factor"),  # no option names a form
    ([CORNELL, "--point", "1,2,3", "--from-face", "0"], "No such option '--from-face'"),  # two forms at once
    (["faces", CORNELL, "--from-face", "0", "--to-face", "1", "--tol", "0"], "--tol"),
    (["groups", CORNELL, "--from-group", "floor"], "--to-group"),
    (["faces", CORNELL, "--from-face", "3", "--to-face", "3"], "--from-face and --to-face are the same face"),
])
def test_bad_forms_say_what_to_give(argv, message, capsys):
    code, _, err = run(["formfactor", *argv], capsys)
    assert code == 2 and message in err, err
    assert err.strip().splitlines()[-1].startswith("viscx: error:") and "Traceback" not in err


def commands(group, path, ctx):
    """(path, command) of every command and subcommand."""
    yield path, group
    if isinstance(group, click.Group):
        for name in group.list_commands(ctx):
            yield from commands(group.get_command(ctx, name), [*path, name], ctx)


def test_every_help_has_a_shell_example():
    ctx = click.Context(cli, info_name="viscx")
    found = list(commands(cli, [], ctx))
    assert len(found) > 20 and ["formfactor", "matrix"] in [p for p, _ in found]
    for path, command in found:
        with click.Context(command, info_name=" ".join(["viscx", *path])) as c:
            text = command.get_help(c)
        examples = [line.strip() for line in text.splitlines() if line.strip().startswith("viscx ")]
        assert examples, f"'viscx {' '.join(path)} --help' shows no example"
        if path[:1] == ["formfactor"] and len(path) == 2:
            assert all(e.startswith(f"viscx formfactor {path[1]} ") or e.startswith("viscx build") for e in examples)


def loud(argv, capsys):
    """``run`` without ``--quiet``: the warnings shown."""
    with pytest.raises(SystemExit) as exc:
        main([*map(str, argv)])
    out, err = capsys.readouterr()
    return exc.value.code, out, err


@pytest.mark.parametrize("argv", [
    ["groups", CORNELL, "--from-group", "floor", "--to-group", "light"],
    ["faces", CORNELL, "--from-face", "15", "--to-face", "0"],
])
def test_a_pair_stopped_at_its_cap_says_so(argv, monkeypatch, capsys):
    """A pair whose refinement stops at MAX_CELLS before its estimate is within --tol: the
    record says ``tol_reached`` false, its error above tol, and one warning line says so
    (none with --quiet); at the same tol with the cap as shipped, the estimate is within
    tol and nothing is said."""
    from viscx.queries import formfactor as ff

    code, out, err = loud(["formfactor", *argv, "--tol", "1e-7"], capsys)
    record = json.loads(out)
    assert code == 0 and record["tol_reached"] is True and record["error"] <= 2 * 1e-7 and "warning" not in err, err
    monkeypatch.setattr(ff, "MAX_CELLS", 20)
    code, out, err = loud(["formfactor", *argv, "--tol", "1e-9"], capsys)
    record = json.loads(out)
    assert code == 0 and record["tol_reached"] is False and record["error"] > 1e-9
    lines = [line for line in err.splitlines() if "warning" in line]
    assert len(lines) == 1 and "above --tol 1e-09" in lines[0] and "20 triangles" in lines[0], err
    code, out, err = run(["formfactor", *argv, "--tol", "1e-9"], capsys)
    assert code == 0 and json.loads(out)["tol_reached"] is False and err == "", err


def test_matrix_entries_above_tol_are_counted(tmp_path, monkeypatch, capsys):
    """The matrix's summary reports its largest estimate; where entries stop above --tol
    (the rows' cap made small) one warning line counts them."""
    from viscx.formats.formfactors import read_matrix
    from viscx.queries import formfactor as ff

    monkeypatch.setattr(ff, "MAX_CELLS", 20)
    code, out, err = loud(["formfactor", "matrix", CORNELL, "--tol", "1e-9", "-o", tmp_path / "F.h5"], capsys)
    assert code == 0
    m = read_matrix(tmp_path / "F.h5")
    above = int((m["error"] > 1e-9 * (1 + 1e-9)).sum() + (m["sky_error"] > 1e-9 * (1 + 1e-9)).sum())
    lines = [line for line in err.splitlines() if "warning" in line]
    assert above > 0 and len(lines) == 1 and lines[0].startswith(f"viscx: warning: {above} of the matrix's error estimates"), err
    assert json.loads(out)["max_error_estimate"] > 1e-9
