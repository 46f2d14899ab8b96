"""viscx benchmarks: plain Python, no timing assertions (tests assert correctness).

    python benchmarks/run.py            # full run
    python benchmarks/run.py --quick    # a few minutes at most

Writes ``benchmarks/results.json`` and ``benchmarks/results.md`` (a Markdown
table, also printed). Sections grow with the project; each row is one measured
stage of one scene: wall time, a rate, peak memory and counts.
"""

import argparse
import json
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests"))

from scenes import spheres_in_room  # noqa: E402

from viscx.scene import load_scene  # noqa: E402


def peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


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


def markdown(rows, machine):
    lines = [f"Machine: {machine}", "", "| section | scene | stage | triangles | n | median s | rate | peak MB |", "|---|---|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(
            f"| {r['section']} | {r['scene']} | {r['stage']} | {r['triangles']:,} | {r['n']:,} | "
            f"{r['seconds']:.3f} | {r['rate']:,.0f} {r['unit']} | {r['peak_mb']:.0f} |"
        )
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer rays and smaller scenes")
    parser.add_argument("--out", default=str(HERE), help="folder for results.json and results.md")
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

    table = markdown(rows, machine)
    print(table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps({"machine": machine, "quick": args.quick, "rows": rows}, indent=2))
    (out / "results.md").write_text(table + "\n")


def _cores():
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


if __name__ == "__main__":
    main()
