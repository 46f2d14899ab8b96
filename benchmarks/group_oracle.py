"""Group-to-group form factors of a built scene against cosine-weighted Monte Carlo rays:
each ``FROM:TO`` query by :func:`viscx.queries.formfactor.group_to_group` at ``--tol``
(timed: CPU s of this process and its workers), and by ``--rays`` rays from the emitting
group's side (tests/oracles.py ``form_factor_monte_carlo``, embree first hits), each
emitter face getting rays in proportion to its area; a face's parts lying on other faces
(a shelf board's end on its upright) see what they lie on only, as viscx counts them
(``lying``: :func:`viscx.queries.formfactor.contact_cells`). ``z`` is the difference in
units of the two uncertainties together, √(σ² + estimate²).

    python benchmarks/buildings.py shelves -o shelves.obj && viscx build shelves.obj -o shelves.h5
    python benchmarks/group_oracle.py shelves.h5 --pairs light1:shelf0 shelf1:floor --rays 10000000
    python benchmarks/scenes.py tori -o tori.obj
    python benchmarks/group_oracle.py tori.obj --pairs light:floor --tol 1e-4

Prints one JSON line per query and nothing else.
"""

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))


def cpu_seconds():
    """CPU seconds of this process and its finished children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def monte_carlo(scene, emitters, side, receivers, rays, seed):
    """Area-weighted Monte Carlo F from side ``side`` of the emitter faces to both sides of
    the receiver faces: ``(F, sigma)``."""
    from oracles import form_factor_monte_carlo

    from viscx.queries import formfactor as ff

    area = scene.face_area[emitters]
    cols = np.concatenate([[2 * j, 2 * j + 1] for j in receivers])
    mc, var = 0.0, 0.0
    for f, a in zip(emitters, area):
        n = max(1, int(rays * a / area.sum()))
        lying = ff.contact_cells(scene, int(f), side)
        p = float(form_factor_monte_carlo(scene, [int(f)], side, n, seed=seed,
                                          lying=lying if len(lying[0]) else None)[0][cols].sum())
        mc += a * p / area.sum()
        var += (a / area.sum()) ** 2 * p * (1 - p) / n
    return mc, float(np.sqrt(var))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("file", help="a scene built by viscx build, or the scene file itself (as viscx formfactor takes)")
    parser.add_argument("--pairs", nargs="+", required=True, metavar="FROM:TO")
    parser.add_argument("--side", type=int, default=1, choices=(1, -1), help="the emitting side")
    parser.add_argument("--tol", type=float, default=1e-6)
    parser.add_argument("--rays", type=int, default=10_000_000, help="Monte Carlo rays per query (0: none)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)

    from viscx.queries import formfactor as ff
    from viscx.queries.visibility import open_query

    scene = open_query(args.file).scene
    for pair in args.pairs:
        a, b = pair.split(":")
        emitters = np.asarray(sorted(int(f) for f in scene.group_faces(a)), np.int64)
        receivers = np.asarray(sorted(int(f) for f in scene.group_faces(b)), np.int64)
        start = cpu_seconds()
        r = ff.group_to_group(scene, emitters, receivers, args.side, tol=args.tol)
        record = {"from": a, "to": b, "side": args.side, "F": r["F"], "error": r["error"],
                  "tol_reached": r["tol_reached"], "tol": args.tol, "cpu": round(cpu_seconds() - start, 2)}
        if args.rays:
            mc, sigma = monte_carlo(scene, emitters, args.side, receivers, args.rays, args.seed)
            record.update(monte_carlo=mc, sigma=sigma, rays=args.rays,
                          z=(r["F"] - mc) / float(np.sqrt(sigma ** 2 + r["error"] ** 2)))
        print(json.dumps(record), flush=True)


if __name__ == "__main__":
    main()
