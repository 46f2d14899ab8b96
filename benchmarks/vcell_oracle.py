"""The V-cells of a few vertices of a large scene checked by the ray oracle of the tests,
without the full build: V0 and V1 scoped to those vertices (:class:`viscx.skeleton.scope.Scope`:
every VE family of the vertices, with every event on them, as the full build has them),
the V-cells of their boundary elements alone (a vertex's cells depend on its own elements
only), then :func:`test_vcells.ray_oracle` on the complete ones.

    python benchmarks/vcell_oracle.py bunny.obj --vertices 967            # one vertex
    python benchmarks/vcell_oracle.py bunny.obj --sample 100 --seed 1     # 100 random ones

(the whole npm bunny in its room, ``benchmarks/scenes.py`` ``bunny_in_room`` written with
``write_obj``: its vertex 967 once located every direction in two cells, found this way in
8 CPU s where the full build takes about 2,000). The scoped build's memory grows with the
vertices built together (on the whole bunny 1.6 GB for 10, 9.9 to 11.9 GB for 100), so
they are built ``--batch`` at a time. Prints one JSON line: the vertices, the scoped
builds' CPU seconds, complete vertices, judged and agreeing directions and the first
disagreements.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from test_vcells import ray_oracle  # noqa: E402

from viscx.scene import load_scene  # noqa: E402
from viscx.skeleton import vcells  # noqa: E402
from viscx.skeleton.arcs import build_arcs  # noqa: E402
from viscx.skeleton.candidates import build_nodes  # noqa: E402
from viscx.skeleton.scope import Scope  # noqa: E402


def scoped_vcells(scene, vertices):
    """(arcs, vcells) of the given generator vertices ((k,) int) alone: V0 and V1 scoped to
    them, the V-cells of their own boundary elements."""
    scope = Scope.of(scene, vertices)
    arcs = build_arcs(scene, build_nodes(scene, scope=scope), scope=scope)
    real = vcells.boundary_elements

    def theirs(scene, arcs):
        el = real(scene, arcs)
        return el.take(np.flatnonzero(np.isin(el.vertex, vertices)))

    vcells.boundary_elements = theirs
    try:
        return arcs, vcells.build_vcells(scene, arcs, vertices=vertices)
    finally:
        vcells.boundary_elements = real


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", help="a scene file (OBJ, PLY, ...)")
    parser.add_argument("--vertices", default="", help="comma-separated vertex ids")
    parser.add_argument("--sample", type=int, default=0, help="this many random generator vertices too")
    parser.add_argument("--seed", type=int, default=1, help="seed of the sample")
    parser.add_argument("--directions", type=int, default=500, help="random directions per vertex")
    parser.add_argument("--batch", type=int, default=10, help="vertices per scoped build")
    args = parser.parse_args(argv)
    scene = load_scene(args.scene)
    chosen = [int(v) for v in args.vertices.split(",") if v]
    if args.sample:
        chosen += np.random.default_rng(args.seed).choice(scene.generator_vertices, args.sample, replace=False).tolist()
    vertices = np.unique(np.asarray(chosen, np.int64))
    cpu, cells, judged, agreed, wrong, done = 0.0, 0, 0, 0, [], []
    for k in range(0, len(vertices), args.batch):
        c = time.process_time()
        arcs, vc = scoped_vcells(scene, vertices[k: k + args.batch])
        cpu += time.process_time() - c
        complete = np.unique(vc.vertex[vc.complete])
        j, a, w = ray_oracle(scene, arcs, vc, complete, n=args.directions, seed=k)
        cells, judged, agreed = cells + len(vc), judged + j, agreed + a
        wrong += w
        done += complete.tolist()
    print(json.dumps({"vertices": len(vertices), "cpu_scoped_build": round(cpu, 1), "complete": len(done),
                      "incomplete": np.setdiff1d(vertices, done).tolist(), "cells": cells,
                      "directions": args.directions, "judged": judged, "agreed": agreed, "wrong": wrong[:10]}))


if __name__ == "__main__":
    main()
