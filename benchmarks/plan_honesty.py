"""Are the pair queries' error estimates honest on buildings: windows, doors, furniture?
``viscx formfactor faces`` (one side of face i → one side of face j:
:func:`viscx.queries.formfactor.pair_form_factor`) from a building's small axis-aligned
rectangles (sills, jambs, lintels, box sides: area under ``--max-area``) to every light
(``--pairs lights``) or to a sample of faces (``--pairs sample``), at ``--tol``, against a
product Gauss–Legendre quadrature of the pair's kernel (tests/oracles.py
``rectangle_product_gauss``: 8 × 8 points on ``--panels``² panels, cut along the outlines
of the emitter's parts lying on other faces, where the integrand jumps, and those parts
counted 0, as viscx counts them). An entry off by more than its estimate is judged again
on panels 2 and then 8 times as fine, and counted *beyond* only if it is beyond those too
(the quadrature converges slowly where a shadow's edge or a face's grazing edge crosses
its panels: a desk top's end → a desk panel was 11 times its estimate off the 64²
quadrature, 1.6 times off 128², within off 512²).

    python benchmarks/plan_honesty.py --scene plan --tol 1e-6
    python benchmarks/plan_honesty.py --scene room --pairs sample --sample 600 --seed 7 --part 0 --parts 2

Scenes (benchmarks/buildings.py): ``plan`` the 2 × 2 floor plan (doors, windows, pillars),
``plan1`` one room with four windows, ``room`` the furnished room, ``office`` an office of
``--polygons``. Prints one JSON line per pair side integrated by quadrature (F, estimate,
the quadrature, the ratio |F − Q| / estimate, CPU s) and a summary.
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


def building(name, polygons):
    """The polygon soup of a scene of ``--scene``."""
    from buildings import floor_plan, furnished_room, office

    return {"plan": lambda: floor_plan(),
            "plan1": lambda: floor_plan(rooms=(1, 1), doors=False, windows=True, pillars=0, seed=0),
            "room": lambda: furnished_room(),
            "office": lambda: office(polygons)}[name]()


def quadrature(scene, setup, face, panels):
    """F of the pair ``setup`` (:class:`viscx.queries.formfactor.PairSetup`) from side +1 of
    an axis-aligned rectangular ``face``, by the product Gauss quadrature on ``panels``²
    panels cut along the outlines of its contact cells."""
    from oracles import in_convex_cells, rectangle_product_gauss

    from viscx.queries import formfactor as ff

    loop = scene.face_loops(face)[0]
    lo, hi = loop.min(axis=0), loop.max(axis=0)
    axes = [d for d in range(3) if hi[d] - lo[d] > 1e-9 * scene.diagonal]
    cells, _ = ff.contact_cells(scene, face, 1)
    corners = np.concatenate(cells) if len(cells) else np.zeros((0, 3))
    edges = {}
    for a in axes:
        e = np.unique(np.concatenate([np.linspace(lo[a], hi[a], panels + 1), np.clip(corners[:, a], lo[a], hi[a])]))
        edges[a] = e[np.concatenate([[True], np.diff(e) > 1e-12 * scene.diagonal])]
    normal = scene.face_normal[face]
    skip = (lambda p: in_convex_cells(p, cells, normal) >= 0) if len(cells) else None
    return rectangle_product_gauss(setup.f, lo, hi, edges, 8, skip)


def pairs_of(scene, how, max_area, sample, seed):
    """The (emitter, receiver) pairs: the small rectangles → every light, or a sample."""
    names = [scene.group_names[g] for g in scene.face_group]
    lights = [f for f in range(scene.n_faces) if names[f].startswith("light")]
    small = [f for f in range(scene.n_faces) if f not in lights and scene.face_area[f] < max_area
             and len(scene.face_loops(f)) == 1 and len(scene.face_loops(f)[0]) == 4]
    if how == "lights":
        return [(f, j) for f in small for j in lights]
    rng = np.random.default_rng(seed)
    out = [(int(f), int(j)) for f, j in zip(rng.choice(small, 5 * sample), rng.integers(0, scene.n_faces, 5 * sample))
           if f != j]
    return out[:sample]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", choices=("plan", "plan1", "room", "office"), default="plan")
    parser.add_argument("--polygons", type=int, default=100, help="the office's")
    parser.add_argument("--tol", type=float, default=1e-6)
    parser.add_argument("--pairs", choices=("lights", "sample"), default="lights")
    parser.add_argument("--sample", type=int, default=600)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-area", type=float, default=2.0)
    parser.add_argument("--panels", type=int, default=64)
    parser.add_argument("--part", type=int, default=0)
    parser.add_argument("--parts", type=int, default=1)
    args = parser.parse_args(argv)

    from viscx.queries import formfactor as ff
    from viscx.scene import build_scene

    scene = build_scene(building(args.scene, args.polygons))
    names = [scene.group_names[g] for g in scene.face_group]
    pairs = pairs_of(scene, args.pairs, args.max_area, args.sample, args.seed)
    judged, beyond, worst, cpu = 0, [], (0.0, None), 0.0
    for k, (f, j) in enumerate(pairs):
        if k % args.parts != args.part:
            continue
        for t in (1, -1):
            start = time.process_time()
            r = ff.pair_form_factor(scene, f, 1, ff.face_target(scene, j), t, tol=args.tol)
            seconds = time.process_time() - start
            cpu += seconds
            if r.method != "quadrature" or r.F == 0:
                continue
            setup = ff.PairSetup(scene, f, 1, ff.face_target(scene, j), t)
            q = quadrature(scene, setup, f, args.panels)
            record = {"from": f, "to": j, "side": t, "groups": [names[f], names[j]], "F": r.F, "error": float(r.error),
                      "quadrature": q, "panels": args.panels, "cpu": round(seconds, 3)}
            for finer in (2, 8):  # judged again only where it is beyond
                if abs(r.F - q) <= r.error:
                    break
                q = quadrature(scene, setup, f, finer * args.panels)
                record.update(quadrature=q, panels=finer * args.panels)
            ratio = abs(r.F - q) / max(float(r.error), 1e-300)
            record["ratio"] = ratio
            judged += 1
            if ratio > 1:
                beyond.append((f, j, t))
            if ratio > worst[0]:
                worst = (ratio, (f, j, t))
            print(json.dumps(record), flush=True)
    print(json.dumps({"scene": args.scene, "tol": args.tol, "pairs": args.pairs, "judged": judged,
                      "beyond": len(beyond), "beyond_pairs": beyond, "worst_ratio": worst[0], "worst": worst[1],
                      "cpu_queries": round(cpu, 2)}))


if __name__ == "__main__":
    main()
