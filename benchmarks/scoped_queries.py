"""Scoped point queries on large meshes: ``viscx query shadows SCENE.obj --light …`` timed as a
user runs it (a fresh process: reading the OBJ, cleaning the scene, the light's V-cells, the
answer written as JSON), then the answer checked by the ray oracle of the tests
(tests/query_oracle.py: area-uniform samples, lit per the answer's loops versus a shadow ray).

Scenes: the spheres in a room of benchmarks/scenes.py (122,892 triangles at subdivisions 5)
and, given ``--bunny PATH`` (the ``index.js`` of ``npm pack bunny``, not shipped with viscx),
the npm bunny standing on the floor of a room under a quad light.

    python benchmarks/scoped_queries.py --bunny /tmp/package/index.js [--subdivisions 5]

Writes benchmarks/scoped_results.json. CPU and peak resident memory are the child process's
(wall time is noisy on a shared machine).
"""

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from scenes import BUNNY_LIGHT, SPHERES_LIGHT, bunny_in_room, spheres_in_room_soup, write_obj  # noqa: E402

#: Samples closer than this fraction of the diagonal to a loop are not judged (as the tests).
BAND = 1e-5


def run_shadows(obj, light, out):
    """Run the CLI in a fresh process; wall s, CPU s (user + sys) and peak resident GB."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    cmd = [sys.executable, "-m", "viscx", "query", "shadows", str(obj), "--light", ",".join(map(repr, light)), "-o", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {r.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, after.ru_maxrss / 1e6  # the largest child so far: run the scenes smallest first


def oracle(obj, light, answer, samples, seed):
    """The tests' ray oracle on the CLI's answer (its lit loops and boundaries per face)."""
    from query_oracle import judge

    from viscx.queries.visibility import FaceView
    from viscx.scene import load_scene

    scene = load_scene(obj)
    faces = [FaceView(face=f["face"], polygons=[(np.asarray(loop), []) for loop in f["lit"]],
                      boundary=np.asarray(f["boundary"]).reshape(-1, 2, 3), complete=f["complete"])
             for f in answer["faces"]]

    class View:  # what judge reads of a PointView
        pass

    view = View()
    view.faces = faces
    return judge(scene, view, np.asarray(light), samples, np.random.default_rng(seed), BAND * scene.diagonal)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bunny", help="index.js of the npm package bunny (npm pack bunny)")
    ap.add_argument("--subdivisions", type=int, default=5)
    ap.add_argument("--samples", type=int, default=200_000)
    ap.add_argument("--out", default=str(HERE / "scoped_results.json"))
    args = ap.parse_args()
    scenes = []
    if args.bunny:
        scenes.append(("bunny_in_room", lambda: bunny_in_room(args.bunny), BUNNY_LIGHT))
    scenes.append((f"spheres_in_room(subdivisions={args.subdivisions})",
                   lambda: spheres_in_room_soup(subdivisions=args.subdivisions), SPHERES_LIGHT))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, make, light) in enumerate(scenes):
            soup = make()
            obj, out = Path(tmp) / f"scene{k}.obj", Path(tmp) / f"shadows{k}.json"
            write_obj(obj, soup)
            wall, cpu, peak = run_shadows(obj, light, out)
            answer = json.loads(out.read_text())
            check = oracle(obj, light, answer, args.samples, seed=k)
            row = {"scene": name, "triangles": int((np.diff(soup.polygon_offsets) - 2).sum()),
                   "light": list(light), "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "peak_gb": round(peak, 2),
                   "cells": answer["cells"], "complete": answer["complete"],
                   **{key: check[key] for key in ("samples", "judged", "agreement", "area_error")},
                   "disagree_faces": check["disagree_faces"][:20]}
            print(json.dumps(row), flush=True)
            rows.append(row)
    Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
