"""The full build of the cities three ways: every level whole in memory, V1 and V2 streamed into
the file chunk by chunk, and V1's and V2's chunks on a local dask cluster (``viscx build
--scheduler local``).

    python benchmarks/dask_ladder.py --sizes 300 1000          # cities of random boxes
    python benchmarks/dask_ladder.py --sizes 1000 --workers 2 --modes streamed dask
    python benchmarks/dask_ladder.py --scene bunny.obj --modes streamed   # any scene file

Each build runs in a child process of its own (``prlimit --as`` caps it, ``--cap`` GB) from
the city written as OBJ: ``whole`` is the build as it was before V2 was streamed (every
level built in memory, then written: ``build_complex(...).save``), ``streamed`` and
``dask`` are ``viscx build`` (``--scheduler local --workers N``). Reports per build the
wall time, the CPU seconds of the process and of its children (the dask workers), the
peak resident memory of the building process (at the end of each stage, from the build's
log) and of each dask worker, and whether the
files are equal (``viscx diff --rtol 0 --atol 0`` against the first mode's). Prints JSON lines and writes
``benchmarks/dask_results.json``.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

# the child: one build, then its own peak memory and CPU, and its children's CPU, as JSON
_CHILD = r"""
import json, resource, sys
from viscx.cli import main
mode, scene, out, workers = sys.argv[1:5]
if mode == "whole":
    from viscx.pipeline import build_complex
    build_complex(scene).save(out)
else:
    args = ["build", scene, "-o", out] + (["--scheduler", "local", "--workers", workers] if mode == "dask" else [])
    try:
        main(args)
    except SystemExit as exc:
        assert not exc.code, exc.code
me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
print("RESULT " + json.dumps({"peak_gb": me.ru_maxrss * 1024 / 1e9, "cpu": me.ru_utime + me.ru_stime,
                              "children_cpu": kids.ru_utime + kids.ru_stime}))
"""


def write_city(n_polygons, path, seed=0):
    """The city of :func:`scenes.random_boxes` as an OBJ file (one polygon per face, vertices
    written exactly): what ``viscx build`` reads. Returns the path."""
    from scenes import random_boxes

    scene = random_boxes(n_polygons, seed=seed)
    lines, k = ["# viscx benchmark city (benchmarks/scenes.py random_boxes)", "o city"], 0
    for f in range(scene.n_faces):
        for j in range(scene.face_loop_offsets[f], scene.face_loop_offsets[f + 1]):
            idx = scene.loop_vertices[scene.loop_offsets[j]:scene.loop_offsets[j + 1]]
            lines += [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in scene.vertices[idx]]
            lines.append("f " + " ".join(str(k + 1 + i) for i in range(len(idx))))
            k += len(idx)
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


def run_build(mode, scene, out, workers, cap_gb):
    """One build in a child process: its row (wall, CPU, peaks) or the error it ended with."""
    cmd = ["prlimit", f"--as={int(cap_gb * 1e9)}", sys.executable, "-c", _CHILD, mode, str(scene), str(out), str(workers)]
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    row = {"mode": mode, "wall": time.perf_counter() - start}
    if done.returncode:
        return {**row, "error": done.stderr.strip().splitlines()[-1:] or [f"exit {done.returncode}"]}
    for line in done.stderr.splitlines():  # "[  64.7 s, peak 0.58 GB] build: V1 done in 30.8 s"
        if "] build: " in line and " done in " in line:
            stage = line.split("] build: ")[1].split(" done in ")[0]
            row.setdefault("stage_peak_gb", {})[stage] = float(line.split("peak ")[1].split(" GB")[0])
    for line in done.stdout.splitlines():
        if line.startswith("RESULT "):
            row.update(json.loads(line[len("RESULT "):]))
        if line.startswith("dask: "):  # "dask: 2 workers, peak memory 1.10, 1.20 GB"
            row["worker_peak_gb"] = [float(x) for x in line.split("peak memory ")[1].removesuffix(" GB").split(", ")]
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[300, 1000])
    parser.add_argument("--scene", help="a scene file built instead of the cities (e.g. scenes.bunny_in_room's OBJ)")
    parser.add_argument("--modes", nargs="+", default=["whole", "streamed", "dask"], choices=["whole", "streamed", "dask"])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--cap", type=float, default=7.0, help="address-space cap of each build, GB")
    parser.add_argument("--work", default="/tmp/viscx-dask-ladder", help="folder of the cities and builds")
    parser.add_argument("--out", default=str(HERE / "dask_results.json"))
    args = parser.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    for n in [None] if args.scene else args.sizes:
        city = Path(args.scene) if args.scene else write_city(n, work / f"city{n}.obj")
        first = None
        for mode in args.modes:
            out = work / f"{city.stem}_{mode}.h5"
            row = {"polygons" if n else "scene": n or city.name, **run_build(mode, city, out, args.workers, args.cap)}
            if "error" not in row:
                if first is None:
                    first = out
                else:
                    diff = subprocess.run([sys.executable, "-m", "viscx", "diff", "--rtol", "0", "--atol", "0", str(out),
                                           str(first)], capture_output=True)
                    row["equal_to"] = (first.stem.split("_")[-1], diff.returncode == 0)
            print(json.dumps(row), flush=True)
            rows.append(row)
    Path(args.out).write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
