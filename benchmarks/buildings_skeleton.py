"""The skeleton of furnished buildings (benchmarks/buildings.py): V0, V1 and V2 CPU time and
peak memory per level, and the fraction of generator vertices and edge pairs whose cells
are complete (docs/skeleton.md, "Furnished buildings").

    python benchmarks/buildings_skeleton.py                      # office(600) and two plans
    python benchmarks/buildings_skeleton.py office:300:1 plan:2:2

A scene is ``office:N[:SEED]`` (:func:`buildings.office`, about N polygons) or
``plan:NX:NZ[:SEED]`` (:func:`buildings.floor_plan`, doors, windows, a pillar). Each is
built in a child process (its own peak memory); rows are printed as JSON lines and
written to ``benchmarks/buildings_results.json``.
"""

import argparse
import json
import multiprocessing
import os
import sys
from pathlib import Path

# as `viscx build` runs (viscx/cli; before numpy loads): their spinning is not the builders' CPU
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from buildings import floor_plan, office  # noqa: E402
from skeleton import run_skeleton  # noqa: E402

from viscx.scene import build_scene  # noqa: E402

DEFAULT = ["office:600", "plan:2:1", "plan:2:2"]


def scene_of(spec):
    """The soup of a scene spec (module docstring)."""
    kind, *args = spec.split(":")
    args = [int(a) for a in args]
    if kind == "office":
        return office(args[0], seed=args[1] if len(args) > 1 else 0)
    if kind == "plan":
        return floor_plan((args[0], args[1]), seed=args[2] if len(args) > 2 else 0)
    raise ValueError(f"unknown scene {spec!r} (office:N[:SEED] or plan:NX:NZ[:SEED])")


def fractions(row):
    v, e = row["vcells"], row["eecells"]
    return {"vertices_complete": [v["complete_vertices"], v["vertices"]],
            "ee_pairs_complete": [e["complete_pairs"], e["pairs"]]}


def _child(spec, conn):
    from viscx.memory import keep_freed_memory

    keep_freed_memory()  # as `viscx build` runs (viscx/cli)
    row = run_skeleton(build_scene(scene_of(spec)), spec)
    conn.send(row | fractions(row))


def run_one(spec):
    return run_in_child(_child, spec)


def run_in_child(target, *args):
    """``target(*args, conn)`` in a spawned process (its own peak memory): what it sends."""
    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=target, args=(*args, child))
    proc.start()
    row = parent.recv()
    proc.join()
    return row


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=DEFAULT)
    parser.add_argument("--out", default=str(HERE / "buildings_results.json"))
    args = parser.parse_args(argv)
    rows = []
    for spec in args.scenes:
        row = run_one(spec)
        rows.append(row)
        keep = ("scene", "polygons", "cpu_v0", "cpu_v1", "cpu_v2", "peak_mb_v0", "peak_mb_v1", "peak_mb_v2",
                "vertices_complete", "ee_pairs_complete")
        print(json.dumps({k: (round(row[k], 2) if isinstance(row[k], float) else row[k]) for k in keep}), flush=True)
    Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
