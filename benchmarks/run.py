"""viscx benchmarks: plain Python, no timing assertions (tests assert correctness).

    python benchmarks/run.py            # full run
    python benchmarks/run.py --quick    # a few minutes at most
    python benchmarks/run.py --budget 600   # skip ladder sizes predicted to exceed 600 s

Writes ``benchmarks/results.json`` and ``benchmarks/results.md`` (a Markdown
table, also printed). Sections grow with the project; each row is one measured
stage of one scene: wall time, a rate, peak memory and counts.
"""

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests"))

from scenes import spheres_in_room  # noqa: E402
from skeleton import peak_mb  # noqa: E402

from viscx.scene import load_scene  # noqa: E402




def timed(fn, *args, repeat=3, **kwargs):
    """Median wall time of ``repeat`` calls, and the last result."""
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn(*args, **kwargs)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), result


def surface_points(scene, n, rng):
    from oracles import sample_on_triangles

    return sample_on_triangles(scene.vertices, scene.triangles, n, rng)[0]


def bench_raycast(scene, name, n_rays, rng):
    """Free-segment tests between surface points and first hits along random directions."""
    caster = scene.ray_caster
    caster.first_hit(scene.vertices[:8], np.ones((8, 3)))  # compile numba, warm embree
    a, b = surface_points(scene, n_rays, rng), surface_points(scene, n_rays, rng)
    rows = []
    caster.stats.update(rays=0, float64_checks=0, recasts=0)
    seconds, free = timed(caster.free_segments, a, b)
    stats = dict(caster.stats)
    rows.append(
        {
            "section": "raycast",
            "scene": name,
            "stage": "free_segments (surface to surface)",
            "triangles": len(scene.triangles),
            "n": n_rays,
            "seconds": seconds,
            "rate": n_rays / seconds,
            "unit": "segments/s",
            "free_fraction": float(free.mean()),
            "float64_checks_per_ray": stats["float64_checks"] / stats["rays"],
            "recasts_per_ray": stats["recasts"] / stats["rays"],
            "peak_mb": peak_mb(),
        }
    )
    d = rng.normal(size=(n_rays, 3))
    caster.stats.update(rays=0, float64_checks=0, recasts=0)
    seconds, (face, _) = timed(caster.first_hit, a, d, tmin=scene.epsilon)
    stats = dict(caster.stats)
    rows.append(
        {
            "section": "raycast",
            "scene": name,
            "stage": "first_hit (surface, random direction)",
            "triangles": len(scene.triangles),
            "n": n_rays,
            "seconds": seconds,
            "rate": n_rays / seconds,
            "unit": "rays/s",
            "free_fraction": float((face < 0).mean()),
            "float64_checks_per_ray": stats["float64_checks"] / stats["rays"],
            "recasts_per_ray": stats["recasts"] / stats["rays"],
            "peak_mb": peak_mb(),
        }
    )
    return rows


def _row(section, scene, stage, triangles, n, seconds, rate, unit, note=""):
    return {"section": section, "scene": scene, "stage": stage, "triangles": triangles, "n": n,
            "seconds": seconds, "rate": rate, "unit": unit, "peak_mb": peak_mb(), "note": note}


def _cosine_directions(normal, n, rng):
    """(n, 3) directions cosine-distributed about ``normal`` (3,) (Malley's method)."""
    u1, u2 = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)], axis=1)
    t = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    t /= np.linalg.norm(t)
    return local @ np.stack([t, np.cross(normal, t), normal])


def bench_formfactors(n_rays, rng, tolerance=1e-3):
    """Exact form factors against embree Monte Carlo (cosine-weighted rays) reaching a
    relative error ``tolerance``: the Monte Carlo time is (1 - F) / (F tolerance²) rays
    at the measured ray rate (its standard error falls as 1/√N)."""
    import tempfile

    from viscx.geometry.formfactor import point_to_polygon, polygon_to_polygon

    # two unit squares, the second 1 above the first and shifted by 0.4: partly facing
    obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.4 0 1\nv 1.4 0 1\nv 1.4 1 1\nv 0.4 1 1\n"
    obj += "g lower\nf 1 2 3 4\ng upper\nf 5 8 7 6\n"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "squares.obj"
        path.write_text(obj)
        scene = load_scene(path)
    upper = next(k for k in range(scene.n_faces) if scene.face_loops(k)[0][:, 2].min() > 0.5)
    lower = 1 - upper
    loop_u, loop_l = scene.face_loops(upper), scene.face_loops(lower)
    up = np.array([0, 0, 1.0])
    caster = scene.ray_caster
    caster.first_hit(scene.vertices[:4], np.ones((4, 3)))  # warm up
    rows = []

    # point to polygon: Lambert's contour formula at many points, one call
    m = 100_000
    pts = np.column_stack([rng.random((m, 2)), np.zeros(m)])
    sec_exact, F = timed(point_to_polygon, pts, np.tile(up, (m, 1)), loop_u)
    p0 = np.array([0.5, 0.5, 0.0])
    d = _cosine_directions(up, n_rays, rng)
    sec_mc, (face, _) = timed(caster.first_hit, np.tile(p0 + 1e-9 * up, (n_rays, 1)), d, repeat=1)
    F0 = float(point_to_polygon(p0[None], up[None], loop_u)[0])
    F_mc = float(np.mean(face == upper))
    need = (1 - F0) / (F0 * tolerance**2) / (n_rays / sec_mc)
    per_point = sec_exact / m
    rows.append(_row("formfactor", "two squares", "point to polygon, exact (Lambert)", 2, m, sec_exact, m / sec_exact,
                     "points/s", f"F = {F0:.12f}"))
    rows.append(_row("formfactor", "two squares", "point to polygon, embree Monte Carlo", 2, n_rays, sec_mc,
                     n_rays / sec_mc, "rays/s",
                     f"F ~ {F_mc:.5f}; {tolerance:g} rel. error needs {need:.3g} s = {need / per_point:,.0f} x exact"))

    # polygon to polygon: the double contour integral against uniform points x cosine rays
    sec_exact, F = timed(polygon_to_polygon, loop_l, up, loop_u, -up)
    a = np.column_stack([rng.random((n_rays, 2)), np.full(n_rays, 1e-9)])
    sec_mc, (face, _) = timed(caster.first_hit, a, _cosine_directions(up, n_rays, rng), repeat=1)
    F_mc = float(np.mean(face == upper))
    need = (1 - F) / (F * tolerance**2) / (n_rays / sec_mc)
    rows.append(_row("formfactor", "two squares", "polygon to polygon, exact (contour integral)", 2, 1, sec_exact,
                     1 / sec_exact, "pairs/s", f"F = {F:.12f}"))
    rows.append(_row("formfactor", "two squares", "polygon to polygon, embree Monte Carlo", 2, n_rays, sec_mc,
                     n_rays / sec_mc, "rays/s",
                     f"F ~ {F_mc:.5f}; {tolerance:g} rel. error needs {need:.3g} s = {need / sec_exact:,.0f} x exact"))
    return rows


def bench_formfactor_matrix(sizes, tol, workdir):
    """``viscx formfactor matrix`` on the Cornell box and on offices of ``sizes`` polygons
    (benchmarks/buildings.py, built here with ``viscx build``): CPU seconds of the command
    and its children, peak memory, and the summary's accuracy (reciprocity, rows, largest
    error estimate). Peers (Radiance, pyviewfactor) run in a side environment:
    benchmarks/peers.py."""
    import resource
    import subprocess

    from buildings import office, write_obj

    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    scenes = [("cornell_box", ROOT / "sample_scenes" / "cornell_box.obj")]
    for n in sizes:
        path = workdir / f"office{n}.obj"
        write_obj(office(n, seed=0), path)
        scenes.append((f"office {n}", path))
    rows = []
    for name, obj in scenes:
        h5 = workdir / (Path(obj).stem + ".h5")
        if not h5.exists():
            subprocess.run([sys.executable, "-m", "viscx", "-q", "build", str(obj), "-o", str(h5)], check=True)
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "viscx", "-q", "formfactor", "matrix", str(h5), "--tol", str(tol),
                              "-o", str(workdir / (Path(obj).stem + "_F.h5"))], check=True, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        summary = json.loads(out.stdout)
        n_faces = summary["elements"] // 2
        rows.append(_row("formfactor matrix", name, f"--matrix --tol {tol:g}", 0, n_faces, cpu, n_faces / cpu, "faces/CPU s",
                         f"wall {wall:.1f} s; reciprocity {summary['reciprocity_max_error']:.1e}, rows ±"
                         f"{summary['row_sum_max_deviation']:.1e}, max estimate {summary['max_error_estimate']:.1e}"))
        rows[-1]["peak_mb"] = after.ru_maxrss / 1024
    return rows


def bench_formfactor_peers(side, quick, workdir):
    """Form factors side by side with Radiance and pyviewfactor against a Monte Carlo
    reference (benchmarks/formfactor_peers.py; also writes formfactor_results.md): the
    Cornell matrix and the office's group queries. The peers run in the side Python
    ``side``; without it they are skipped with a message and viscx and the reference
    still run (``quick``: the Cornell box only, 10⁶-ray reference, 10⁵ Radiance rays)."""
    from formfactor_peers import main as peers_main

    # the viscx matrix itself is timed by bench_formfactor_matrix: not run twice
    argv = ["--work", str(workdir), "--out", str(workdir), "--side", side or "", "--matrix-tol"]
    if quick:
        argv += ["--mc-matrix", "1000000", "--mc-pairs", "1000000", "--rays", "100000", "--skip", "office"]
    rows = []
    for r in peers_main(argv):
        n = r.get("entries", 1)
        rows.append(_row("formfactor peers", r["scene"], f"{r['query']}: {r['method']} {r['settings']}", 0, n, r["cpu"],
                         n / max(r["cpu"], 1e-9), "entries/CPU s",
                         (f"mean |Δ| {r['mean_abs']:.1e} ({r['mean_sigma']:.2f} σ), max {r['max_abs']:.1e} "
                          f"({r['max_sigma']:.2f} σ); " if "mean_abs" in r else "") + r.get("note", "")))
    return rows


def bench_render(size, mc_samples, runs=3, target=0.01):
    """The Cornell box's direct illumination at size × size: the exact render (the whole
    `viscx render` command, median of ``runs``), sparse reconstructions against it, and
    Monte Carlo (embree shadow rays) with ``mc_samples`` light samples per pixel; the
    Monte Carlo time to reach a relative RMSE ``target`` follows from its noise falling as
    1/√K (time ∝ K)."""
    import subprocess
    import tempfile

    from viscx.pipeline import build_file
    from viscx.queries.discontinuities import open_discontinuities
    from viscx.render.camera import Camera
    from viscx.render.image import render

    rows = []
    view = dict(eye=[278, 273, -800], look_at=[278, 273, 0], up=[0, 1, 0], fov=39.3, width=size, height=size)
    with tempfile.TemporaryDirectory() as tmp:
        h5 = Path(tmp) / "cornell.h5"
        build_file(ROOT / "sample_scenes" / "cornell_box.obj", h5, quiet=True)
        cmd = [sys.executable, "-m", "viscx", "-q", "render", str(h5), "--camera", "278,273,-800", "--look-at",
               "278,273,0", "--light-group", "light", "--size", str(size), str(size), "-o", str(Path(tmp) / "c.png")]
        subprocess.run(cmd, check=True)  # numba caches warm
        times = []
        for _ in range(runs):
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True)
            times.append(time.perf_counter() - t0)
        scene, mesh = open_discontinuities(h5, light_group="light")
    cam = Camera(**view)
    sec, exact = timed(render, scene, mesh, cam)
    px = size * size
    command = float(np.median(times))
    rows.append(_row("render", "cornell_box", f"exact {size}x{size}, whole command (Hoberock et al.: ~27 min at 512x512)",
                     32, px, command, px / command, "pixels/s",
                     f"runs {', '.join(f'{t:.2f}' for t in times)} s; in-process {sec:.2f} s "
                     f"(primary {exact.stats['primary_s']:.2f} s, {exact.stats['regions']} regions)"))
    lit = (exact.hits.face >= 0) & ~np.isin(exact.hits.face, mesh.light.faces)
    lit = lit.reshape(size, size)
    scale = float(np.sqrt(np.mean(exact.radiance[lit] ** 2)))
    for n in (100, 500, 1000):
        sec_s, sp = timed(render, scene, mesh, cam, samples=n, repeat=1)
        rmse = float(np.sqrt(np.mean((sp.radiance[lit] - exact.radiance[lit]) ** 2)))
        rows.append(_row("render", "cornell_box", f"sparse {n} samples, {size}x{size}", 32, sp.stats["evaluations"], sec_s,
                         sp.stats["evaluations"] / sec_s, "evaluations/s",
                         f"RMSE vs exact {rmse:.3g} ({rmse / scale:.2%} of RMS); {n} samples + {sp.stats['corners']} corners"))
    sec_mc, mc = timed(render, scene, mesh, cam, reference=mc_samples, repeat=1)
    rmse = float(np.sqrt(np.mean((mc.radiance[lit] - exact.radiance[lit]) ** 2)))
    k_need = mc_samples * (rmse / (target * scale)) ** 2
    t_need = sec_mc * k_need / mc_samples
    rows.append(_row("render", "cornell_box", f"Monte Carlo {mc_samples} light samples/pixel, {size}x{size}", 32,
                     mc.stats["rays"], sec_mc, mc.stats["rays"] / sec_mc, "rays/s",
                     f"RMSE vs exact {rmse:.3g} ({rmse / scale:.2%}); {target:.0%} RMSE needs ~{k_need:,.0f} samples/pixel "
                     f"= {t_need:,.0f} s = {t_need / sec:,.0f} x exact"))
    return rows


def bench_flatland(sizes):
    """Flatland build, and one object moved: update against rebuild (benchmarks/flatland.py)."""
    from flatland import measure

    rows = []
    for n, m, E, F, tb, tc, tf, tm, tr, (re, tot) in measure(sizes):
        rows.append(_row("flatland", f"{n} random circles", "build complex + form factors", 0, m, tb, m / tb,
                         "vertices/s", f"{E} edges, {F} faces"))
        rows.append(_row("flatland", f"{n} random circles", "move one object: update (vs rebuild)", 0, m, tm,
                         m / tm, "vertices/s",
                         f"rebuild {tr:.3f} s ({tr / tm:.2f} x); form factors recomputed {re:.0f} of {tot:.0f}"))
    return rows


def bench_fast_vs_reference(names):
    """V0 by the output-sensitive builder against the O(n⁴) reference enumeration, on
    the sample scenes small enough for the reference (same nodes asserted in tests)."""
    from viscx.skeleton.candidates import build_nodes
    from viscx.skeleton.reference import reference_nodes

    rows = []
    for name in names:
        scene = load_scene(ROOT / "sample_scenes" / name)
        build_nodes(scene)  # compile, warm the caches
        sec_fast, fast = timed(build_nodes, scene)
        sec_ref, ref = timed(reference_nodes, scene, repeat=1)
        same = "same nodes" if len(fast) == len(ref) else f"DIFFERENT: {len(fast)} vs {len(ref)} nodes"
        rows.append(_row("V0", name, "nodes, fast builder (vs reference)", len(scene.triangles), len(fast), sec_fast,
                         len(fast) / sec_fast, "nodes/s",
                         f"reference {sec_ref:.3g} s = {sec_ref / sec_fast:.1f} x fast; {same}"))
    return rows


def bench_skeleton(sizes, budget):
    """The V0/V1/V2 ladder of benchmarks/skeleton.py (Cornell box, random boxes cities):
    one row per scene and level, and the fitted growth exponents."""
    from skeleton import run_ladder

    results, growth = run_ladder(sizes, budget, report=lambda text: print(text.splitlines()[-1], flush=True))
    rows = []
    for r in results:
        if r.get("skipped"):
            rows.append({"section": "skeleton", "scene": r["scene"], "stage": "V0+V1+V2", "triangles": r["polygons"],
                         "n": 0, "seconds": float("nan"), "rate": 0.0, "unit": "", "peak_mb": peak_mb(),
                         "note": "skipped: " + r["skipped"]})
            continue
        n, a, v, ee = r["nodes"], r["arcs"], r["vcells"], r["eecells"]
        for stage, sec, count, unit, note in (
            ("V0 nodes", r["seconds_v0"], r["nodes_total"], "nodes/s",
             f"VV/VEE/E4 {n['VV']}/{n['VEE']}/{n['E4']}; {r['candidates_total']:,} candidates"),
            ("V1 arcs", r["seconds_v1"], a["EEE"] + a["VE"], "arcs/s", f"EEE/VE {a['EEE']}/{a['VE']}"),
            ("V2 V-cells", r["seconds_vcells"], v["cells"], "cells/s",
             f"complete vertices {v['complete_vertices']}/{v['vertices']}, open chains {v['open_chains']}"),
            ("V2 EE-cells", r["seconds_eecells"], ee["cells"], "cells/s",
             f"complete edge pairs {ee['complete_pairs']}/{ee['pairs']}, open chains {ee['open_chains']}"),
        ):
            rows.append({"section": "skeleton", "scene": r["scene"], "stage": stage, "triangles": r["polygons"],
                         "n": int(count), "seconds": sec, "rate": count / max(sec, 1e-9), "unit": unit,
                         "peak_mb": r["peak_mb"], "note": note})
    return rows, growth


def markdown(rows, machine):
    lines = [f"Machine: {machine}", "", "size: triangles, or polygons in the skeleton section; n: what the rate counts.", "",
             "| section | scene | stage | size | n | median s | rate | peak MB | note |", "|---|---|---|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(
            f"| {r['section']} | {r['scene']} | {r['stage']} | {r['triangles']:,} | {r['n']:,} | "
            f"{r['seconds']:.3g} | {r['rate']:,.0f} {r['unit']} | {r['peak_mb']:.0f} | {r.get('note', '')} |"
        )
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer rays and smaller scenes")
    parser.add_argument("--out", default=str(HERE), help="folder for results.json and results.md")
    parser.add_argument("--budget", type=float, default=1800.0,
                        help="skip skeleton ladder sizes predicted to take longer than this (s)")
    parser.add_argument("--side", default=None,
                        help="Python of a side environment with pyradiance and pyviewfactor (form-factor peers)")
    args = parser.parse_args()
    rng = np.random.default_rng(2026)
    n_rays = 200_000 if args.quick else 1_000_000
    machine = f"{platform.machine()}, {platform.python_implementation()} {platform.python_version()}, {_cores()} cores"

    rows = []
    cornell = load_scene(ROOT / "sample_scenes" / "cornell_box.obj")
    rows += bench_raycast(cornell, "cornell_box", n_rays, rng)
    t0 = time.perf_counter()
    big = spheres_in_room(subdivisions=4 if args.quick else 5)
    build_seconds = time.perf_counter() - t0
    rows.append(
        {
            "section": "scene",
            "scene": "spheres_in_room",
            "stage": "build_scene",
            "triangles": len(big.triangles),
            "n": len(big.triangles),
            "seconds": build_seconds,
            "rate": len(big.triangles) / build_seconds,
            "unit": "triangles/s",
            "peak_mb": peak_mb(),
        }
    )
    rows += bench_raycast(big, "spheres_in_room", n_rays, rng)
    rows += bench_formfactors(n_rays, rng)
    rows += bench_formfactor_matrix([] if args.quick else [300, 1000], 1e-4, Path(args.out) / "formfactor")
    rows += bench_formfactor_peers(args.side, args.quick, Path(args.out) / "formfactor")
    rows += bench_render(256 if args.quick else 512, 16 if args.quick else 64)
    rows += bench_flatland([10, 100, 300] if args.quick else [10, 100, 300, 1000])
    rows += bench_fast_vs_reference(["tetrahedra.obj", "cornell_box.obj"] if args.quick else
                                    ["two_triangles.obj", "tetrahedra.obj", "room_with_door.obj",
                                     "boxes_on_floor.obj", "cornell_box.obj"])
    skeleton_rows, growth = bench_skeleton([50, 100] if args.quick else [100, 300, 1000, 3000], budget=args.budget)
    rows += skeleton_rows

    table = markdown(rows, machine)
    table += "\n\nGrowth exponents (least squares on log-log over the random boxes ladder):\n\n"
    table += "\n".join(f"- {k}: {'n/a' if v is None else f'{v:.2f}'}" for k, v in growth.items())
    print(table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(
        json.dumps({"machine": machine, "quick": args.quick, "rows": rows, "growth": growth}, indent=2))
    (out / "results.md").write_text(table + "\n")


def _cores():
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


if __name__ == "__main__":
    main()
