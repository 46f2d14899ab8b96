"""The npm bunny standing in a room under a quad light (:func:`scenes.bunny_in_room`), the
bunny decimated to growing triangle counts: V0, V1 and V2 CPU time and peak memory per
level, V0's stages, and the fraction of generator vertices and edge pairs whose cells are
complete (as ``benchmarks/buildings_skeleton.py`` reports for buildings).

    python benchmarks/bunny_skeleton.py /tmp/package/index.js 250 500 1000
    python benchmarks/bunny_skeleton.py /tmp/package/index.js 250 --levels 0   # V0 alone

``index.js`` is the npm package ``bunny`` (``npm pack bunny``; not shipped with viscx).
Decimation needs ``fast-simplification`` (:func:`scenes.decimate`); a size of 0 is the
whole bunny. Each size is built in a child process (its own peak memory); rows are printed
as JSON lines and appended to ``--out`` if given.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from buildings_skeleton import fractions, run_in_child  # noqa: E402
from scenes import bunny_in_room  # noqa: E402
from skeleton import peak_mb, run_skeleton  # noqa: E402

from viscx.scene import build_scene  # noqa: E402
from viscx.skeleton.candidates import fast_candidates, validate_in_chunks  # noqa: E402


def run_v0(scene, name):
    """V0 alone: candidates and validation, CPU seconds and peak MB."""
    stats = {}
    c0 = time.process_time()
    kind, gens, origins, dirs = fast_candidates(scene, stats=stats)
    c1 = time.process_time()
    nodes = validate_in_chunks(scene, kind, gens, origins, dirs)
    c2 = time.process_time()
    return {"scene": name, "polygons": int(scene.n_faces), "cpu_candidates": c1 - c0, "cpu_validation": c2 - c1,
            "cpu_v0": c2 - c0, "peak_mb_v0": peak_mb(), "candidates_total": int(len(kind)), "nodes": nodes.counts(),
            "stages": {k: (round(v, 3) if isinstance(v, float) else v) for k, v in stats.items()}}


def _child(path, triangles, levels, conn):
    name = f"bunny_in_room({triangles or 'whole'})"
    scene = build_scene(bunny_in_room(path, triangles=triangles or None))
    if levels == 0:
        conn.send(run_v0(scene, name))
        return
    row = run_skeleton(scene, name)
    conn.send(row | fractions(row))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bunny", help="index.js of the npm package bunny")
    parser.add_argument("sizes", nargs="*", type=int, default=[250, 500, 1000])
    parser.add_argument("--levels", type=int, choices=(0, 2), default=2, help="0: V0 alone; 2: V0, V1 and V2")
    parser.add_argument("--out", help="a JSON-lines file the rows are appended to")
    args = parser.parse_args(argv)
    for size in args.sizes:
        row = run_in_child(_child, args.bunny, size, args.levels)
        line = json.dumps({k: (round(v, 2) if isinstance(v, float) else v) for k, v in row.items()})
        print(line, flush=True)
        if args.out:
            with open(args.out, "a") as out:
                out.write(line + "\n")


if __name__ == "__main__":
    main()
