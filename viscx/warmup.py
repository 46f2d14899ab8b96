"""Compile viscx's numba kernels ahead of their first use: ``python -m viscx.warmup``.

The kernels are compiled with ``cache=True``: the first run after an install (or after a
change of their source) compiles them, about a minute of CPU, and later runs load them
from the cache. ``make venv`` (and so ``make demo`` and ``make test``) runs this module,
so that a user's first ``viscx build`` is as fast as the next.

It builds a small scene with every level and a free point, and runs each query once
(point views, the discontinuity mesh, the three renderers, the form factors) and the
flatland commands, in a temporary folder: the same calls the commands make, so the same kernel signatures.
"""

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: A floor, a box standing on it (contacts), a block touching the box's side (the pencils
#: of a touched plane), a tilted panel above them (skew edges) and a square light under
#: the ceiling, facing down: a few hundred nodes.
SCENE = """\
v 0 0 0
v 0 0 4
v 4 0 4
v 4 0 0
v 1 0 1
v 1 0 2
v 2 0 2
v 2 0 1
v 1 1 1
v 1 1 2
v 2 1 2
v 2 1 1
v 2.5 1.5 1.5
v 3.5 1.8 1.7
v 3.4 2.0 3.0
v 2.4 1.7 2.8
v 1.5 3 1.5
v 2.5 3 1.5
v 2.5 3 2.5
v 1.5 3 2.5
g floor
f 1 2 3 4
g box
f 9 10 11 12
f 5 9 12 8
f 8 12 11 7
f 7 11 10 6
f 6 10 9 5
g panel
f 13 14 15 16
g light
f 17 18 19 20
v 2 0 1
v 2 0 1.8
v 2 0.7 1.8
v 2 0.7 1
v 2.6 0 1
v 2.6 0 1.8
v 2.6 0.7 1.8
v 2.6 0.7 1
g block
f 21 24 28 25
f 22 26 27 23
f 24 23 27 28
f 25 28 27 26
"""

#: Two unit squares facing each other and a small triangle between them: the form-factor
#: matrix (``viscx formfactor matrix``: a row of every receiver at once).
MATRIX = """\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 0 1 1
v 1 1 1
v 1 0 1
v 0.3 0.3 0.5
v 0.6 0.35 0.5
v 0.45 0.7 0.55
f 1 2 3 4
f 5 6 7 8
f 9 10 11
"""


#: A flatland scene (``viscx flatland``): a lamp, a convex polygon and a two-sided segment.
FLATLAND = """\
{"objects": [
  {"name": "lamp", "type": "circle", "center": [0, 0], "radius": 1, "emission": 1.0},
  {"name": "block", "type": "polygon", "points": [[2.5, -0.5], [3.5, -0.2], [3.2, 1.0]], "reflectance": 0.5},
  {"name": "wall", "type": "segment", "points": [[-1, 3], [3, 3.5]], "reflectance": 0.4}
]}
"""
#: A row of three equal squares: lines along their tops touch all three (degenerate
#: layouts take the perturbation kernels of :func:`viscx.flatland.complex.resolve_degenerate`).
FLATLAND_ROW = """\
{"objects": [
  {"type": "polygon", "points": [[0, 0], [1, 0], [1, 1], [0, 1]], "emission": 1.0},
  {"type": "polygon", "points": [[2, 0], [3, 0], [3, 1], [2, 1]], "reflectance": 0.5},
  {"type": "polygon", "points": [[4, 0], [5, 0], [5, 1], [4, 1]], "reflectance": 0.5}
]}
"""


def warm_up_flatland(folder):
    """``viscx flatland build``, ``radiosity`` and ``move`` on :data:`FLATLAND` and
    :data:`FLATLAND_ROW` in ``folder``."""
    from viscx.flatland.complex import build
    from viscx.flatland.dynamic import move
    from viscx.flatland.mesh import radiosity
    from viscx.flatland.scene import load_scene

    for k, text in enumerate((FLATLAND, FLATLAND_ROW)):
        path = Path(folder) / f"flatland{k}.json"
        path.write_text(text)
        complex_ = build(load_scene(path), quiet=True)
        radiosity(complex_, quiet=True, sky_radiance=1.0)
        move(complex_, 1, 0.25, -0.1)


def warm_up():
    """Run every kernel once; returns the seconds it took."""
    from viscx.pipeline import build_file
    from viscx.queries.discontinuities import open_discontinuities
    from viscx.queries.formfactor import face_to_face, form_factor_matrix, load_row_kernels, point_to_faces
    from viscx.queries.shadows import shadows
    from viscx.queries.visibility import open_query, view_from
    from viscx.render.camera import Camera
    from viscx.render.image import render
    from viscx.scene import load_scene

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="viscx-warmup-") as folder:
        obj, h5 = Path(folder) / "scene.obj", Path(folder) / "scene.h5"
        obj.write_text(SCENE)
        light = np.array([2.0, 2.5, 2.0])
        build_file(obj, h5, quiet=True, points=light[None])
        query = open_query(h5)
        view_from(query, light)  # from the file's point
        view_from(query, np.array([0.5, 2.0, 3.5]))  # computed on demand
        shadows(h5, light)
        point_to_faces(query, [3.0, 0.001, 3.0], [0, 1, 0], range(query.scene.n_faces))
        face_to_face(query.scene, 0, 7, tol=1e-5)
        matrix = Path(folder) / "matrix.obj"
        matrix.write_text(MATRIX)
        form_factor_matrix(load_scene(matrix), tol=1e-3, workers=1)  # in this process: its cache, not a fork's
        load_row_kernels(load_scene(matrix), every_sweep=True)  # a room's sweep too
        scene, mesh = open_discontinuities(h5, light_group="light")
        camera = Camera([2.0, 1.5, -4.0], [2.0, 1.0, 2.0], [0, 1, 0], 45.0, 24, 24)
        for options in ({}, {"samples": 40}, {"reference": 2}):
            render(scene, mesh, camera, radiance=[1.0, 1.0, 1.0], **options)
        warm_up_flatland(folder)
    return time.perf_counter() - start


def main():
    from viscx.progress import report_compilation

    report_compilation()
    seconds = warm_up()
    print(f"viscx: kernels compiled and cached ({seconds:.0f} s)", file=sys.stderr)


if __name__ == "__main__":
    main()
