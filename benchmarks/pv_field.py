"""Bifacial view factors of a PV field: rows of tilted panels on posts over the ground
(benchmarks/buildings.py ``pv_field``), the regular layout PV engineers model.

For the middle row: its back → the ground (the light its back gets from the ground), its
front → the next row and its back → the row behind (the rows' mutual shading), and the
ground → that row's posts; each a ``viscx formfactor groups`` query
(:func:`viscx.queries.formfactor.group_to_group`) at ``--tol``, timed (CPU s of this
process and its workers), against cosine-weighted Monte Carlo rays from the emitting side
(benchmarks/group_oracle.py ``monte_carlo``: embree first hits, a post's foot on the ground
counted as viscx counts a face lying on a face; ``--rays``): the difference in units of
the two uncertainties together, √(σ² + estimate²).

    python benchmarks/pv_field.py --rows 6 --tol 1e-6 --rays 10000000

Prints one JSON line per query and nothing else.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))


def queries(scene, middle):
    """(name, emitting faces, side, receiving faces) of the middle row's queries."""
    def group(name):
        return [int(f) for f in scene.group_faces(name)]

    return [(f"row{middle} back -> ground", group(f"row{middle}"), -1, group("ground")),
            (f"row{middle} front -> row{middle + 1}", group(f"row{middle}"), 1, group(f"row{middle + 1}")),
            (f"row{middle} back -> row{middle - 1}", group(f"row{middle}"), -1, group(f"row{middle - 1}")),
            (f"ground -> post{middle}", group("ground"), 1, group(f"post{middle}"))]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rows", type=int, default=6)
    parser.add_argument("--posts", type=int, default=4, help="posts under each row")
    parser.add_argument("--tol", type=float, default=1e-6)
    parser.add_argument("--rays", type=int, default=10_000_000, help="Monte Carlo rays per query (0: none)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--only", type=int, nargs="*", help="the queries to run, by their index (default all)")
    args = parser.parse_args(argv)

    from buildings import pv_field
    from group_oracle import cpu_seconds, monte_carlo

    from viscx.queries import formfactor as ff
    from viscx.scene import build_scene

    scene = build_scene(pv_field(rows=args.rows, posts=args.posts))
    for k, (name, emitters, side, receivers) in enumerate(queries(scene, args.rows // 2)):
        if args.only and k not in args.only:
            continue
        start = cpu_seconds()
        r = ff.group_to_group(scene, emitters, receivers, side, tol=args.tol)
        record = {"query": name, "F": r["F"], "error": r["error"], "tol_reached": r["tol_reached"],
                  "tol": args.tol, "cpu": round(cpu_seconds() - start, 2)}
        if args.rays:
            mc, sigma = monte_carlo(scene, np.asarray(emitters, np.int64), side, receivers, args.rays, args.seed)
            record.update(monte_carlo=mc, sigma=sigma,
                          z=(r["F"] - mc) / float(np.sqrt(sigma ** 2 + r["error"] ** 2)))
        print(json.dumps(record), flush=True)


if __name__ == "__main__":
    main()
