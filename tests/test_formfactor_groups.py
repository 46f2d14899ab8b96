"""Group-to-group form factors with reciprocity imposed (``group_to_group``): each face
pair computed once, in the rows of its face of smaller area, the other direction derived
as the matrix derives it (``derived_entries``). Judged against the two-sided path
(``reciprocal=False``, every pair computed from the emitting group) entry by entry within
the two estimates, and against Monte Carlo rays (tests/oracles.py)."""

import sys
from collections import defaultdict

import numpy as np
import pytest
from conftest import ROOT
from oracles import form_factor_monte_carlo

from viscx.queries import formfactor as ff
from viscx.scene import build_scene

sys.path.insert(0, str(ROOT / "benchmarks"))
from buildings import furnished_room  # noqa: E402

TOL = 1e-4


@pytest.fixture(scope="module")
def room():
    """35 polygons: a 4 x 3 x 3 m room, a light, a desk, a cabinet against a wall, a divider."""
    return build_scene(furnished_room(n_desks=1, n_cabinets=1, n_dividers=1, n_lights=1, size=(4, 3, 3), seed=0))


def entries(scene, a, b, reciprocal):
    """{(row, col): (F, error)} of the group query a → b (parts summed)."""
    out = defaultdict(lambda: [0.0, 0.0])
    for r, c, v, e in zip(*ff.group_entries(scene, scene.group_faces(a), scene.group_faces(b), 1, TOL, 1, reciprocal)):
        out[int(r), int(c)][0] += v
        out[int(r), int(c)][1] += e
    return out


def test_pairs_are_computed_from_their_smaller_face(room):
    """floor → desk0 is computed in the desk faces' rows (both sides, the floor their one
    receiver), not in the floor's; desk0 → floor in the desk faces' front rows alike; the
    two-sided path keeps the floor's row. The pairs computed for floor → desk0 alone need
    their estimates within tol · A_floor / A_j only; those desk0 → floor emits, tol."""
    floor, desk = room.group_faces("floor"), room.group_faces("desk0")
    rows = ff.group_rows(room, floor, 1, desk)
    assert rows and all(f in desk and list(r) == list(floor) for f, _, r, _ in rows)
    # derived only: each pair to tol A_floor / A_j, within tol once scaled by A_j / A_floor
    assert all(np.allclose(scale, room.face_area[floor] / room.face_area[f]) for f, _, _, scale in rows)
    back = ff.group_rows(room, desk, 1, floor)
    assert {(f, s) for f, s, *_ in rows} >= {(f, 1) for f, *_ in back}
    assert all(np.all(scale == 1.0) for *_, scale in back)
    two = ff.group_rows(room, floor, 1, desk, reciprocal=False)
    assert [(f, s) for f, s, *_ in two] == [(int(floor[0]), 1)] and np.all(two[0][3] == 1.0)


@pytest.mark.parametrize("a, b", [("floor", "desk0"), ("desk0", "floor"), ("desk0", "desk0"), ("light1", "cabinet0"),
                                  ("wall_west", "divider0")])
def test_reciprocal_entries_equal_the_two_sided_ones(room, a, b):
    """Every entry F_(i,+1)→(j,t) of the query, derived or computed, within the sum of its
    estimate and the two-sided one's of the entry computed from i; the estimates within
    tol (derived ones scaled by A_j / A_i ≤ 1); the groups' Σ A_i F alike."""
    one, two = entries(room, a, b, True), entries(room, a, b, False)
    for key in set(one) | set(two):  # an entry left out is 0 (from the floor, the desk boxes' inner sides: ~1e-7)
        (v, e), (w, d) = one.get(key, (0.0, 0.0)), two.get(key, (0.0, 0.0))
        assert e <= TOL and d <= TOL, key
        assert abs(v - w) <= e + d + 1e-12, (key, v, w, e, d)
    area = room.face_area
    flux = [sum(area[r // 2] * np.array(x) for (r, _), x in es.items()) for es in (one, two)]  # (A F, A error)
    assert abs(flux[0][0] - flux[1][0]) <= flux[0][1] + flux[1][1]


def test_floor_to_desk_against_monte_carlo(room):
    """floor → desk0 (derived from the desk's rows) within 4 σ of 10⁶ cosine-weighted rays
    from the floor."""
    floor, desk = room.group_faces("floor"), room.group_faces("desk0")
    g = ff.group_to_group(room, floor, desk, tol=TOL, workers=1)
    assert g["pairs"] == 18 and g["error"] <= 2 * 18 * TOL  # tol per pair and side
    est, _ = form_factor_monte_carlo(room, floor, 1, 1_000_000, seed=5)
    mc = float(est[np.concatenate([2 * desk, 2 * desk + 1])].sum())
    sigma = np.sqrt(mc * (1 - mc) / 1_000_000)
    assert abs(g["F"] - mc) < 4 * sigma + g["error"], (g, mc, sigma)


@pytest.mark.parametrize("a, b", [("ceiling", "divider0"), ("wall_west", "wall_south")])
def test_group_rows_are_cut_along_their_own_pairs_kinks(room, a, b):
    """A group query's row is cut along the kink lines of its own pairs only (``kink_faces``:
    the receivers, the faces lying on them, the faces in the pairs' shafts; the pair kernel
    sees no other face). The rows of these queries (the divider's front to the ceiling, the
    west wall to the south wall), past the limit with every receiver's kink lines (three
    levels), are cut along their own (two levels); each entry is within its estimate plus
    the reference's of the matrix's row (``row_form_factors``: ``point_views``, every
    receiver's kink lines) at a tol 10 times finer."""
    rows = ff.group_rows(room, room.group_faces(a), 1, room.group_faces(b))
    cut = [(f, s, r) for f, s, r, _ in rows if ff.cubature_cells(room, f, s, receivers=r)[2]
           and not ff.cubature_cells(room, f, s)[2]]
    assert cut
    for f, s, r in cut:
        cols, val, err, *_ = ff.emitter_row(room, f, s, r, TOL / 10, sky=False)
        ref_cols, ref, ref_err, *_ = ff.row_form_factors(room, f, s, r, TOL / 100, sky=False)
        assert list(cols) == list(ref_cols) and np.all(err <= TOL / 10)
        assert np.all(np.abs(val - ref) <= err + ref_err), (f, s, val, ref, err, ref_err)



@pytest.mark.parametrize("a, b, unit", [("wall_west", "wall_east", "points"), ("desk0", "floor", "rows")])
def test_progress_lines_leave_the_answer_alone(room, a, b, unit, monkeypatch, capsys):
    """Unless quiet, a group query shows its progress (log lines here, stderr being no
    terminal): a query of one row its points and its pair's estimate against its target
    after each refinement round, down to at most 1 at the end; a query of several rows the
    rows done. The answer is the quiet one's, bit for bit."""
    import viscx.progress as progress

    fa, fb = room.group_faces(a), room.group_faces(b)
    assert (len(ff.group_rows(room, fa, 1, fb)) == 1) == (unit == "points")
    quiet = ff.group_to_group(room, fa, fb, tol=TOL, workers=1)
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(progress, "QUIET_START", 0.0)
    monkeypatch.setattr(progress, "LOG_EVERY", 0.0)
    loud = ff.group_to_group(room, fa, fb, tol=TOL, workers=1, quiet=False)
    assert loud == quiet
    lines = [line for line in capsys.readouterr().err.splitlines() if "form factors:" in line]
    assert lines and all(unit in line for line in lines), lines
    if unit == "points":
        ratios = [float(line.split("estimate ")[1].split(" ×")[0]) for line in lines]
        counts = [int(line.split("form factors: ")[1].split(" points")[0]) for line in lines]
        assert ratios[-1] <= 1 < ratios[0] and counts == sorted(counts) and counts[-1] > 0, lines
    else:
        assert lines[-1].split("form factors: ")[1].startswith(f"{len(ff.group_rows(room, fa, 1, fb))}/"), lines


def test_group_form_factors_are_invariant_under_a_rotation(room):
    """The room turned by a generic rotation (no face along an axis: the boxes' and cells'
    axis-aligned bounds, the emitters' plane bases and start triangles all differ) and
    moved: every query's F within the two estimates of the upright room's."""
    import dataclasses

    soup = furnished_room(n_desks=1, n_cabinets=1, n_dividers=1, n_lights=1, size=(4, 3, 3), seed=0)
    a, b, c = 0.37, 1.13, -0.71
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    turned = build_scene(dataclasses.replace(soup, vertices=np.asarray(soup.vertices) @ (rz @ ry @ rx).T + [3.1, -2.2, 0.7]))
    assert turned.n_faces == room.n_faces
    for a, b in [("floor", "ceiling"), ("floor", "desk0"), ("desk0", "floor"), ("wall_west", "divider0"),
                 ("light1", "cabinet0"), ("wall_north", "wall_south")]:
        f0, f1 = (ff.group_to_group(s, s.group_faces(a), s.group_faces(b), tol=TOL, workers=1) for s in (room, turned))
        assert f0["pairs"] == f1["pairs"] and f0["F"] > 0, (a, b)
        assert abs(f0["F"] - f1["F"]) <= f0["error"] + f1["error"] + 1e-12, (a, b, f0, f1)
