"""Group-to-group form factors in the office (benchmarks/buildings.py): each query's value,
error estimate, CPU seconds (the worker processes included) and wall seconds, as
``viscx formfactor groups`` computes them (:func:`viscx.queries.formfactor.group_to_group`,
default workers: one per core). One JSON line per query.

    python benchmarks/office_groups.py --polygons 300 --tol 1e-4
    python benchmarks/office_groups.py --pairs floor:light1 wall_west:wall_east

Without ``--pairs``: every ordered pair of the groups ``floor, ceiling, wall_*,
light1..4, desk0, cabinet0, divider0`` (the other desks and cabinets are alike).
"""

import argparse
import json
import resource
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: The groups timed by default (one of each kind of furniture).
GROUPS = ["floor", "ceiling", "wall_west", "wall_east", "wall_south", "wall_north", "light1", "light2", "light3", "light4",
          "desk0", "cabinet0", "divider0"]


def cpu_seconds():
    """user + sys of this process and its waited-for children (the pool's workers)."""
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def main(argv=None):
    from buildings import office

    from viscx.queries.formfactor import group_to_group
    from viscx.scene import build_scene

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--polygons", type=int, default=300)
    parser.add_argument("--tol", type=float, default=1e-4)
    parser.add_argument("--pairs", nargs="*", default=None, metavar="FROM:TO")
    args = parser.parse_args(argv)
    scene = build_scene(office(args.polygons, seed=0))
    pairs = [tuple(p.split(":")) for p in args.pairs] if args.pairs else [(a, b) for a in GROUPS for b in GROUPS if a != b]
    for a, b in pairs:
        c0, w0 = cpu_seconds(), time.perf_counter()
        r = group_to_group(scene, scene.group_faces(a), scene.group_faces(b), 1, args.tol)
        print(json.dumps({"from": a, "to": b, "F": r["F"], "error": r["error"], "pairs": r["pairs"], "tol": args.tol,
                          "cpu": round(cpu_seconds() - c0, 2), "wall": round(time.perf_counter() - w0, 2)}), flush=True)


if __name__ == "__main__":
    main()
