"""Scoped queries on large meshes, timed as a user runs them (a fresh process from the OBJ):

* ``viscx query shadows SCENE.obj --light …`` (the light's V-cells, the answer as JSON),
  checked by the ray oracle of the tests (tests/query_oracle.py: area-uniform samples, lit
  per the answer's loops versus a shadow ray);
* with ``--area``: ``viscx build SCENE.obj --light-group light`` (the nodes and arcs of the
  light's families only, viscx/skeleton/scope.py, its nodes enumerated light-centred),
  then from that file ``viscx query discontinuities`` (from the OBJ it runs the same build
  in-process first: the sum is reported), ``viscx render`` at 512² from the OBJ (nothing
  built), and
  ``viscx formfactor groups SCENE.obj --from-group floor --to-group light``, each under
  ``prlimit --as=8000000000``; the mesh checked by the discontinuity oracle
  (tests/discontinuity_oracle.py) on the room's faces, the image against a Monte Carlo
  reference (tests/render_oracle.py, ``noise_check``) rendered in-process on the same
  mesh, the form factor against cosine-distributed rays (tests/oracles.py).

Scenes: the spheres in a room of benchmarks/scenes.py (122,892 triangles at subdivisions 5)
and, given ``--bunny PATH`` (the ``index.js`` of ``npm pack bunny``, not shipped with viscx),
the npm bunny standing on the floor of a room under a quad light.

    python benchmarks/scoped_queries.py --bunny /tmp/package/index.js [--subdivisions 5]
    python benchmarks/scoped_queries.py --area --bunny /tmp/package/index.js [--subdivisions 5]

Writes benchmarks/scoped_results.json (``--area``: scoped_light_results.json). CPU and peak
resident memory are the child process's (wall time is noisy on a shared machine).
"""

import argparse
import json
import os
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

#: The memory cap of the area-light runs (bytes of address space).
ADDRESS_SPACE = 8_000_000_000
#: Camera of the 512² renders: (eye, look-at, vertical fov) per scene.
CAMERAS = {"bunny_in_room": ((0.0, 9.0, 14.0), (0.0, 4.0, 0.0), 60.0),
           "spheres_in_room": ((0.0, 2.0, 9.5), (0.0, -1.0, 0.0), 70.0)}

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


def run_capped(args):
    """Run ``viscx ARGS`` in a fresh process under ``prlimit --as``: (wall s, CPU s, peak
    resident GB, exit status, standard error) of that process alone (``wait4``)."""
    cmd = ["prlimit", f"--as={ADDRESS_SPACE}", sys.executable, "-m", "viscx", *map(str, args)]
    t = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        err.seek(0)
        text = err.read().decode(errors="replace")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1e6, os.waitstatus_to_exitcode(status), text


def _timed(args):
    """``viscx ARGS`` under the memory cap: its row (wall, CPU, peak GB, exit, error)."""
    wall, cpu, peak, code, err = run_capped(args)
    return {"wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "peak_gb": round(peak, 2), "exit": code,
            **({"error": err.strip()[-300:]} if code else {})}


def area_light(name, obj, tmp, radiance=(10.0, 10.0, 10.0), seed=0, rays=4_000_000, size=512):
    """The scoped build of group ``light`` (``viscx build --light-group``), then from that file
    the discontinuity mesh and the 512² render, and from the OBJ the form factor floor →
    light, each timed; then checked: the mesh by the discontinuity oracle on the room's
    faces (2 points per region, every trace crossed), the image against a 64-sample Monte
    Carlo reference of the same pixels (``noise_check``), the form factor against
    ``rays`` cosine-distributed rays from the floor (within 4 sigma).

    ``viscx query discontinuities SCENE.obj`` runs the same scoped build in-process
    (nothing written) before the same query: its cost from the OBJ is the build's plus the
    query's (``*_from_obj``). The exact ``viscx render`` is timed from the OBJ itself: it
    builds nothing (:mod:`viscx.render.tiles`)."""
    from discontinuity_oracle import check_mesh
    from oracles import form_factor_monte_carlo
    from render_oracle import noise_check

    from viscx.queries.discontinuities import light_mesh, open_light_query
    from viscx.render.camera import Camera
    from viscx.render.image import render

    row = {"scene": name}
    built, out, png, ff = (Path(tmp) / f for f in ("light.h5", "mesh.json", "image.png", "ff.json"))
    row["build"] = _timed(["build", obj, "--light-group", "light", "-o", built])
    print(json.dumps(row), flush=True)
    if row["build"]["exit"]:
        return row
    row["discontinuities"] = _timed(["query", "discontinuities", built, "--light-group", "light", "-o", out])
    if row["discontinuities"]["exit"] == 0:
        answer = json.loads(out.read_text())
        row["discontinuities"].update(events=answer["events"], regions=sum(len(f["regions"]) for f in answer["faces"]))
    eye, at, fov = CAMERAS[name.split("(")[0]]
    # the exact render needs the scene only (viscx.render.tiles): from the OBJ, nothing built
    row["render_512"] = _timed(["render", obj, "--camera", ",".join(map(repr, eye)), "--look-at", ",".join(map(repr, at)),
                                "--fov", fov, "--light-group", "light", "--radiance", ",".join(map(repr, radiance)),
                                "--size", size, size, "-o", png])
    for query in ("discontinuities",):
        row[f"{query}_from_obj"] = {"cpu_s": round(row["build"]["cpu_s"] + row[query]["cpu_s"], 1),
                                    "wall_s": round(row["build"]["wall_s"] + row[query]["wall_s"], 1),
                                    "peak_gb": max(row["build"]["peak_gb"], row[query]["peak_gb"])}
    row["formfactor"] = _timed(["formfactor", "groups", obj, "--from-group", "floor", "--to-group", "light", "-o", ff])
    print(json.dumps(row), flush=True)
    cx = open_light_query(built, light_group="light")
    scene = cx.scene
    group = np.asarray(scene.group_names)[scene.face_group]
    if row["formfactor"]["exit"] == 0:
        exact = json.loads(ff.read_text())["F"]
        light = np.flatnonzero(group == "light")
        F, _ = form_factor_monte_carlo(scene, np.flatnonzero(group == "floor"), 1, rays, seed=seed)
        p = F[2 * light].sum() + F[2 * light + 1].sum()
        sigma = np.sqrt(p * (1 - p) / rays)
        row["formfactor"].update(F=exact, monte_carlo=p, sigma=sigma, ok=bool(abs(exact - p) <= 4 * sigma))
    if row["discontinuities"]["exit"] == 0:
        room = np.flatnonzero(np.isin(group, ["floor", "ceiling", "wall_x0", "wall_x1", "wall_z0", "wall_z1", "walls"]))
        mesh = light_mesh(cx, light_group="light", faces=room.tolist())
        res = check_mesh(scene, mesh, np.random.default_rng(seed), 1e-4 * scene.diagonal, samples=2)
        row["mesh_oracle"] = {k: (len(v) if isinstance(v, list) else v) for k, v in res.items()}
    if row["render_512"]["exit"] == 0:
        whole = light_mesh(cx, light_group="light")
        exact = np.load(png.with_suffix(".npy")).astype(np.float64)
        mc = render(scene, whole, Camera(eye, at, (0.0, 1.0, 0.0), fov, size, size), radiance=radiance, reference=64,
                    seed=seed)
        ok, details = noise_check(exact.reshape(-1, 3), mc.radiance.reshape(-1, 3), mc.stderr.reshape(-1, 3))
        row["render_oracle"] = {"ok": bool(ok), **details}
    print(json.dumps(row), flush=True)
    return row


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
    ap.add_argument("--area", action="store_true", help="discontinuities and render of the group light")
    ap.add_argument("--size", type=int, default=512, help="--area: the render's width and height")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if args.area:
        return main_area(args)
    args.out = args.out or str(HERE / "scoped_results.json")
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


def main_area(args):
    """The area-light queries (``--area``) on the bunny (given) and the spheres with a quad light."""
    scenes = []
    if args.bunny:
        scenes.append(("bunny_in_room", lambda: bunny_in_room(args.bunny)))
    scenes.append((f"spheres_in_room(subdivisions={args.subdivisions})",
                   lambda: spheres_in_room_soup(subdivisions=args.subdivisions, quad_light=True)))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, make) in enumerate(scenes):
            obj = Path(tmp) / f"scene{k}.obj"
            write_obj(obj, make())
            rows.append(area_light(name, obj, tmp, seed=k, size=args.size))
    Path(args.out or HERE / "scoped_light_results.json").write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
