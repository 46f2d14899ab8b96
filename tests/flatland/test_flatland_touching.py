"""Touching objects (docs/flatland.md, "Touching objects"): the limit of a closing gap.

Every scene here has contacts — edges lying on edges (a box on the ground, boxes side by
side, a panel lying flat), points on edges (a panel's end on the ground, a circle on the
ground, panels resting on posts) and corners on corners (the joints of an open
polyline) — and builds without ``--perturb``.  The oracle is the independent exact
integration of ``flatland_oracles`` with contacts taken as the limit of a gap
(:func:`exact_F_touching`), itself checked against the same scenes with gaps of 10⁻⁷ and
10⁻⁸ (linear convergence), and crossed strings for the unobstructed circle."""

import math

import numpy as np
import pytest
from flatland_oracles import circle_on_edge_measure, exact_F_graded, exact_F_touching
from flatland_scenes import corners_of

from viscx.errors import ViscxError
from viscx.flatland.complex import build
from viscx.flatland.scene import SEGMENT, make_scene

GROUND = {"type": "polygon", "points": [[-5, -1], [5, -1], [5, 0], [-5, 0]], "name": "ground"}


def box(x0, y0, w, h, name):
    return {"type": "polygon", "points": [[x0, y0], [x0 + w, y0], [x0 + w, y0 + h], [x0, y0 + h]], "name": name}


def box_on_ground(gap=0.0):
    return make_scene([GROUND, box(0.0, gap, 1.0, 1.0, "box")])


def boxes_side_by_side():
    return make_scene([GROUND, box(-1.5, 0.0, 1.0, 1.0, "a"), box(-0.5, 0.0, 1.5, 0.6, "b"),
                       box(2.0, 0.3, 0.5, 0.5, "floating")])


def panel_on_ground():
    return make_scene([GROUND, {"type": "segment", "points": [[-1.0, 0.0], [1.0, 0.9]], "name": "panel"},
                       box(2.0, 0.0, 0.5, 1.5, "wall")])


def panels_on_posts(n=2):
    """Rows of panels resting on posts standing on the ground: each panel's lower end on
    its post's top corner, its upper part on a taller post's top corner."""
    objs = [dict(GROUND, points=[[-2, -1], [3 * n + 2, -1], [3 * n + 2, 0], [-2, 0]])]
    c, s = math.cos(math.radians(25)), math.sin(math.radians(25))
    for i in range(n):
        x = 3.0 * i
        objs.append(box(x, 0.0, 0.1, 0.8, f"post{i}"))
        objs.append({"type": "segment", "points": [[x, 0.8], [x + 2 * c, 0.8 + 2 * s]], "name": f"panel{i}"})
    return make_scene(objs)


def flat_segment_and_polyline():
    return make_scene([GROUND, {"type": "segment", "points": [[-4, 0], [-2.5, 0]], "name": "mat"},
                       {"type": "polyline", "points": [[-1, 0.5], [0, 1.5], [1, 1.0], [2.5, 1.0]], "name": "fence"},
                       box(0.5, 0.0, 0.5, 0.4, "stone")])


SCENES = {"box-on-ground": box_on_ground, "boxes-side-by-side": boxes_side_by_side,
          "panel-on-ground": panel_on_ground, "panels-on-posts": panels_on_posts,
          "flat-segment-and-polyline": flat_segment_and_polyline}


SLOW = ("panels-on-posts", "flat-segment-and-polyline")  # the oracle takes 24 s and 7 s on every pair


@pytest.mark.parametrize("name,pairs", [(n, "all") for n in sorted(SCENES) if n not in SLOW]
                         + [(n, "contacts") for n in SLOW]
                         + [pytest.param(n, "all", marks=pytest.mark.slow) for n in SLOW])
def test_touching_scenes_exact(name, pairs):
    """Every form factor (``contacts``: of the touching pairs, both ways) equals the
    exact integration with contacts as closing gaps (1e-9); both methods agree and every
    row with the sky sums to 1 (1e-9)."""
    scene = SCENES[name]()
    assert scene.contacts().size
    cx = build(scene)
    assert np.max(np.abs(cx.F_area - cx.F_strings)) < 1e-9
    assert np.max(np.abs(cx.F_area.sum(axis=1) - 1.0)) < 1e-9
    objs = corners_of(scene)
    todo = ([(i, j) for i in range(scene.n) for j in range(scene.n) if i != j] if pairs == "all"
            else [(int(a), int(b)) for a, b in scene.contacts()] + [(int(b), int(a)) for a, b in scene.contacts()])
    for i, j in todo:
        assert abs(exact_F_touching(objs, i, j) - cx.F_area[i, j]) < 1e-9, (scene.names[i], scene.names[j])


def test_contact_oracle_is_the_limit_of_a_gap():
    """The oracle's contact rule (a point of an edge contact sees the other object straight
    ahead) is the limit of the gap: with the box raised by 1e-7 and 1e-8 the plain exact
    integration differs from the touching value by c·gap (the difference shrinks ten-fold
    with the gap), and the complex of the touching scene equals that limit."""
    cx = build(box_on_ground())
    for i, j in ((0, 1), (1, 0)):
        diff = [exact_F_graded(corners_of(box_on_ground(g)), i, j, rel=1e-10) - cx.F_area[i, j] for g in (1e-7, 1e-8)]
        assert abs(diff[0]) < 1e-7 and abs(diff[1]) < 1e-8, diff
        assert 8.0 < diff[0] / diff[1] < 12.0, diff


def test_contact_faces_see_each_other():
    """A box standing on the ground: its bottom sees only the ground (F = 1 from the
    contact), its sides see the ground by crossed strings; the perimeter keeps the contact."""
    cx = build(box_on_ground())
    side = lambda a: (1 + a - math.hypot(1, a)) / 2  # noqa: E731  side of height 1 → ground strip of length a
    assert abs(cx.F_area[1, 0] - (1.0 + side(5.0) + side(4.0)) / 4.0) < 1e-12
    assert abs(cx.scene.perimeters()[1] - 4.0) < 1e-15


def test_circle_on_the_ground_crossed_strings():
    """A circle touching the ground block (a point contact on a curve): crossed strings in
    the limit, both directions."""
    c, r = (0.7, 1.3), 1.3
    scene = make_scene([GROUND, {"type": "circle", "center": list(c), "radius": r, "name": "ball"}])
    cx = build(scene)
    M = circle_on_edge_measure(c, r, (-5, 0), (5, 0))
    assert abs(cx.F_area[1, 0] - M / (4 * math.pi * r)) < 1e-12
    assert abs(cx.F_area[0, 1] - M / (2 * scene.perimeters()[0])) < 1e-12
    assert np.max(np.abs(cx.F_area.sum(axis=1) - 1.0)) < 1e-12


def test_polyline_pieces():
    """An open polyline becomes its pieces, touching at the joints."""
    scene = flat_segment_and_polyline()
    names = [scene.names[k] for k in range(scene.n) if scene.kind[k] == SEGMENT]
    assert names == ["mat", "fence[0]", "fence[1]", "fence[2]"]
    assert {(scene.names[a], scene.names[b]) for a, b in scene.contacts()} >= {("fence[0]", "fence[1]"),
                                                                                ("fence[1]", "fence[2]")}


@pytest.mark.parametrize("objs,msg", [
    ([GROUND, box(0, -0.1, 1, 1, "sunk")], "overlap"),
    ([{"type": "segment", "points": [[0, 0], [2, 0]]}, {"type": "segment", "points": [[1, 0], [3, 0]]}],
     "lie along each other"),
])
def test_overlaps_refused(objs, msg):
    with pytest.raises(ViscxError, match=msg):
        build(make_scene(objs))
