"""Segments (two-sided panels and walls) as objects, from JSON, SVG and DXF."""

import json

import numpy as np
import pytest
from flatland_oracles import exact_F_polygons, monte_carlo_F
from flatland_scenes import corners_of, panel_rows

from viscx.errors import ViscxError
from viscx.flatland.complex import build
from viscx.flatland.scene import SEGMENT, load_scene, make_scene


def assert_exact(scene, cx):
    """Both methods agree, rows sum to 1, every F_ij equals the exact integration."""
    assert np.max(np.abs(cx.F_area - cx.F_strings)) < 1e-9
    assert np.max(np.abs(cx.F_area.sum(axis=1) - 1.0)) < 1e-9
    objs = corners_of(scene)
    worst = max(abs(exact_F_polygons(objs, i, j) - cx.F_area[i, j])
                for i in range(scene.n) for j in range(scene.n) if i != j)
    assert worst < 1e-9, worst


@pytest.fixture(scope="module")
def rows_of_segments():
    scene = panel_rows(5, thick=0)
    return scene, build(scene)


def test_rows_of_segments_exact(rows_of_segments):
    """A uniform row of panels as segments: every form factor equals the exact
    integration (both sides of every panel, occluded by the others) to 1e-9."""
    scene, cx = rows_of_segments
    assert np.all(scene.kind[:-1] == SEGMENT)
    # two-sided: the perimeter is twice the length
    assert np.allclose(scene.perimeters()[:-1], 4.0)
    assert_exact(scene, cx)


def test_segments_monte_carlo():
    """Random lines cross a segment with a chord of length 0: the oracle counts them by
    the crossing point; the complex agrees within 4σ on a mixed scene."""
    scene = make_scene([
        {"type": "segment", "points": [[0, 0], [2, 0.5]]},
        {"type": "segment", "points": [[0.5, 1.5], [2.5, 1.2]]},
        {"type": "circle", "center": [4, 1], "radius": 0.5},
        {"type": "polygon", "points": [[1, -2], [2, -2], [1.5, -1]]},
    ])
    cx = build(scene)
    F, sigma = _mc_with_segments(scene)
    z = np.abs(cx.F_area - F) / np.maximum(sigma, 1e-12)
    assert np.all(z < 4.0), z


def _mc_with_segments(scene):
    """Monte Carlo with segments widened into thin quads of width 1e-9 (the oracle's chord
    code needs an area; the form factors move by O(1e-9))."""
    objs = []
    for k in range(scene.n):
        v = scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]]
        if scene.kind[k] == SEGMENT:
            d = v[1] - v[0]
            off = 5e-10 * np.array([-d[1], d[0]]) / np.hypot(*d)
            objs.append({"type": "polygon", "points": [v[0] - off, v[1] - off, v[1] + off, v[0] + off]})
        elif scene.kind[k] == 0:
            objs.append({"type": "circle", "center": v[0], "radius": scene.radius[k]})
        else:
            objs.append({"type": "polygon", "points": v})
    for o in objs:
        o["points" if "points" in o else "center"] = np.asarray(o.get("points", o.get("center"))).tolist()
    return monte_carlo_F(make_scene(objs), n_lines=1_000_000, seed=21)


def test_segments_in_every_format(tmp_path, rows_of_segments):
    """The same panels as JSON segments, SVG lines / polylines / open paths and DXF lines
    give the same complex."""
    scene, cx = rows_of_segments
    v = corners_of(scene)
    (tmp_path / "a.json").write_text(json.dumps(scene.to_json()))
    body = []
    for k in range(scene.n - 1):
        (x0, y0), (x1, y1) = v[k].tolist()
        if k % 3 == 0:
            body.append(f'<line id="row{k}" x1="{x0!r}" y1="{y0!r}" x2="{x1!r}" y2="{y1!r}"/>')
        elif k % 3 == 1:
            body.append(f'<polyline id="row{k}" points="{x0!r},{y0!r} {x1!r},{y1!r}"/>')
        else:
            body.append(f'<path id="row{k}" d="M {x0!r} {y0!r} L {x1!r} {y1!r}"/>')
    g = v[-1]
    body.append('<polygon id="ground" points="' + " ".join(f"{x!r},{y!r}" for x, y in g.tolist()) + '"/>')
    (tmp_path / "a.svg").write_text('<svg xmlns="http://www.w3.org/2000/svg">' + "".join(body) + "</svg>")
    import trimesh
    from trimesh.path.entities import Line

    verts = np.concatenate(v)
    ents, at = [], 0
    for k in range(scene.n):
        m = len(v[k])
        pts = list(range(at, at + m)) + ([at] if m > 2 else [])
        ents.append(Line(points=pts))
        at += m
    (tmp_path / "a.dxf").write_text(trimesh.path.exchange.dxf.export_dxf(trimesh.path.Path2D(entities=ents,
                                                                                            vertices=verts)))
    for name in ("a.json", "a.svg", "a.dxf"):
        sc = load_scene(tmp_path / name)
        assert sc.n == scene.n and int(np.sum(sc.kind == SEGMENT)) == scene.n - 1, name
        got = build(sc)
        # objects may come in another order from the DXF: compare sorted rows
        key = lambda s: np.lexsort(np.array([c.mean(0) for c in corners_of(s)]).T)  # noqa: E731
        a, b = key(sc), key(scene)
        Fa = got.F_area[np.ix_(a, np.append(a, sc.n))]
        Fb = cx.F_area[np.ix_(b, np.append(b, scene.n))]
        assert np.max(np.abs(Fa - Fb)) < 1e-12, name


@pytest.mark.parametrize("obj,msg", [
    ({"type": "segment", "points": [[0, 0]]}, "at least 2 points"),
    ({"type": "segment", "points": [[1, 1], [1, 1]]}, "coincide"),
])
def test_segment_errors(obj, msg):
    with pytest.raises(ViscxError, match=msg):
        make_scene([obj])


@pytest.mark.parametrize("scene", [
    panel_rows(4, tilt=0.0, thick=0),                                       # flat panels: one line
    make_scene([{"type": "segment", "points": [[2 * i, 2 * j], [2 * i + 1, 2 * j + 1]]}  # lattice diagonals
                for i in range(3) for j in range(3)]),
], ids=["flat-rows", "segment-lattice"])
def test_segments_along_a_shared_line_exact(scene):
    """Segments lying along a line that other objects touch (flat panels in one row,
    collinear fence pieces): both sides of each touch it; resolved by translating the
    segment across the line, exact to 1e-9."""
    cx = build(scene)
    assert_exact(scene, cx)
