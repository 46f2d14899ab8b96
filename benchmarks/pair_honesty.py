"""Are the pair cubature's error estimates honest? ``viscx formfactor faces`` (one side of
face i to face j: :func:`viscx.queries.formfactor.face_to_face`) on occluded pairs of a
furnished office (benchmarks/buildings.py) or the Cornell box, at each ``--tol``, against
the emitter side's matrix row (:func:`viscx.queries.formfactor.row_form_factors`, whose
estimates are honest: benchmarks/formfactor_honesty.py) at ``--ref-tol`` with first
triangles ``--ref-split`` times smaller (its :func:`formfactor_honesty.timed_row`), entry
by entry (each side of j): beyond where ``|F − F_ref| > E + E_ref + 1e-14``.

The pairs: every occluded pair (the pair has occluders in its shaft) of the emitter sides
``--emitters`` (default: one or two of each kind of face), at most ``--per-emitter`` of
them, picked to cover the pair classes (``part(i) → part(j)``, "touching" where the two
faces meet: a desk's panel and the floor). With ``--mc K`` the pairs of the first
``--mc-pairs`` emitters are also checked against K cosine rays from the emitter
(tests/oracles.py ``form_factor_monte_carlo``, embree), as a check of the reference and
of the pairs themselves (within 4 σ); the rays from the emitter's points lying on other
faces (``contact_cells``) count on the side they lie on, as viscx counts them (cast,
they would pass into the box the point lies on: wall → floor came out 0.0038 too high,
through a cabinet's bottom lying on the floor). Entries fewer than 10 rays hit are not
judged (2 rays of 10⁷ from a desk panel reached the inside of the desk top it touches:
points within the ray caster's ``tmin`` of the top's underside).

    python benchmarks/pair_honesty.py --scene office --polygons 100 --tol 1e-4 1e-6 --cache /tmp/pairs100.pkl
    python benchmarks/pair_honesty.py --scene cornell --tol 1e-4 1e-6 --mc 10000000

Prints one JSON line per pair and tolerance (CPU s, points, worst ratio, entries beyond),
then a summary per tolerance and class: pairs, entries, beyond, the worst ratio
``|F − F_ref| / (E + E_ref)`` and its pair, CPU s. The reference rows are cached in
``--cache`` as they are computed.
"""

import argparse
import json
import pickle
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests"))


def face_part(scene, f):
    """What face f is: its group's kind (``floor``, ``wall``, ``light``, ``cabinet``, ...;
    the Cornell box's groups as named), a desk's ``desk top`` / ``desk panel``, and
    ``… edge`` for a face thinner than 6 cm (a desk top's, a panel's or a divider's
    narrow sides, seen at grazing angles)."""
    name = scene.group_names[scene.face_group[f]]
    if scene.diagonal > 100:  # the Cornell box, in millimetres
        return name
    name = name.rstrip("0123456789").split("_")[0]
    lo, hi = ff_box(scene, f)
    thin = np.sort(hi - lo)[1] < 0.06
    if name == "desk":
        # a top's faces lie within its 3 cm height (its narrow sides) or are horizontal and large
        top = hi[1] - lo[1] < 0.06 and (not thin or abs(scene.face_normal[f][1]) < 0.5)
        name = "desk top" if top else "desk panel"
    return name + (" edge" if thin and name not in ("floor", "ceiling") else "")


def ff_box(scene, f):
    from viscx.queries import formfactor as ff

    lo, hi = ff.face_boxes(scene)
    return lo[f], hi[f]


def touching(scene, i, j):
    """Whether faces i and j meet (their outlines within 1e-9 of the scene's size: a desk's
    panel standing on the floor, a cabinet against a wall)."""
    tiny = 1e-9 * scene.diagonal
    # a vertex of one on the other's plane and inside its box (convex faces: enough here)
    for p, q in ((i, j), (j, i)):
        pts, n = np.concatenate(scene.face_loops(p)), scene.face_normal[q]
        c = float(n @ scene.face_loops(q)[0][0])
        lo, hi = ff_box(scene, q)
        on = (np.abs(pts @ n - c) <= tiny) & np.all((pts >= lo - tiny) & (pts <= hi + tiny), axis=1)
        if np.any(on):
            return True
    return False


def pair_class(scene, i, j):
    return f"{face_part(scene, i)} → {face_part(scene, j)}" + (" touching" if touching(scene, i, j) else "")


def occluded_receivers(scene, face, side):
    """(k,) int64: the faces j such that side ``side`` of ``face`` and some side of j face
    each other with an occluder in their shaft (the pairs the cubature integrates)."""
    from viscx.queries import formfactor as ff

    fj, sj = ff.facing_sides(scene, face, side, np.arange(scene.n_faces, dtype=np.int64))
    out = set()
    for j, t in zip(fj.tolist(), sj.tolist()):
        setup = ff.PairSetup(scene, face, side, ff.face_target(scene, j), t)
        if not setup.empty and setup.occluders:
            out.add(j)
    return np.array(sorted(out), np.int64)


def default_emitters(scene):
    """One or two sides of each kind of face (office) or every side (Cornell box) that have
    occluded pairs: [(face, side)]."""
    from viscx.queries import formfactor as ff

    parts = defaultdict(list)
    for f in range(scene.n_faces):
        for s in ff.SIDES:
            if ff.closed_form_row(scene, f, s, np.zeros(0, np.int64), sky=False) is None:
                parts[face_part(scene, f)].append((f, s))
    out = [r for rows in parts.values() for r in (rows if scene.diagonal > 100 else rows[:2])]
    return sorted(out, key=lambda r: (scene.face_area[r[0]], r))  # the cheap rows first: a stopped run says most


def pick(scene, emitter, receivers, n, rng):
    """At most ``n`` of the receivers, one of each class first (in a random order), then at random."""
    by_class = defaultdict(list)
    for j in rng.permutation(receivers).tolist():
        by_class[pair_class(scene, emitter[0], j)].append(j)
    chosen, rounds = [], list(by_class.values())
    while len(chosen) < n and any(rounds):
        for r in rounds:
            if r and len(chosen) < n:
                chosen.append(r.pop(0))
    return sorted(chosen)


def timed_pair(scene, face, side, j, tol):
    """:func:`viscx.queries.formfactor.face_to_face` of (face, side) → j, with its CPU s
    and points."""
    from viscx.queries import formfactor as ff

    c0 = time.process_time()
    r = ff.face_to_face(scene, face, j, side_i=side, tol=tol)
    r["cpu"] = time.process_time() - c0
    r["points"] = sum(p["evaluations"] for p in r["sides"].values())
    return r


def judge(pair, ref, j, floor=1e-14):
    """[(side name, F, E, F_ref, E_ref, |F − F_ref|)] of both sides of j, and the worst
    ``|F − F_ref| / (E + E_ref + floor)``."""
    row = dict(zip(ref[0].tolist(), zip(ref[1].tolist(), ref[2].tolist())))
    out, worst = [], 0.0
    for name, k in (("front", 0), ("back", 1)):
        p = pair["sides"][name]
        fr, er = row.get(2 * j + k, (0.0, 0.0))
        d = abs(p["F"] - fr)
        worst = max(worst, d / (p["error"] + er + floor))
        out.append((name, p["F"], p["error"], fr, er, d))
    return out, worst


def main(argv=None):
    from formfactor_honesty import timed_row

    from viscx.queries import formfactor as ff
    from viscx.scene import build_scene, load_scene

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", choices=("office", "cornell"), default="office")
    parser.add_argument("--polygons", type=int, default=100)
    parser.add_argument("--tol", type=float, nargs="+", default=[1e-4, 1e-6])
    parser.add_argument("--ref-tol", type=float, default=1e-7)
    parser.add_argument("--ref-split", type=float, default=4.0)
    parser.add_argument("--emitters", nargs="*", default=None, metavar="FACE:SIDE",
                        help="emitter sides (side 1 front, -1 back); default one or two of each kind")
    parser.add_argument("--per-emitter", type=int, default=20)
    parser.add_argument("--mc", type=int, default=0, help="cosine rays per emitter for the Monte Carlo check")
    parser.add_argument("--mc-pairs", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cache", default=None, help="the reference rows' pickle (read if it holds them)")
    args = parser.parse_args(argv)
    if args.scene == "office":
        from buildings import office

        scene = build_scene(office(args.polygons, seed=0))
    else:
        scene = load_scene(str(ROOT / "sample_scenes" / "cornell_box.obj"))
    ff.load_row_kernels(scene)
    rng = np.random.default_rng(args.seed)
    emitters = ([tuple(int(v) for v in e.split(":")) for e in args.emitters] if args.emitters is not None
                else default_emitters(scene))
    cached = pickle.load(open(args.cache, "rb")) if args.cache and Path(args.cache).exists() else {}
    stats = {tol: defaultdict(lambda: {"pairs": 0, "entries": 0, "beyond": 0, "worst": 0.0, "worst_pair": None,
                                       "cpu": 0.0, "points": 0}) for tol in args.tol}
    mc_left = args.mc_pairs
    for emitter in emitters:
        receivers = occluded_receivers(scene, *emitter)
        if not len(receivers):
            continue
        key = (args.scene, args.polygons, emitter, args.ref_tol, args.ref_split)
        if key not in cached:
            cached[key] = timed_row(scene, *emitter, args.ref_tol, args.ref_split)
            if args.cache:
                pickle.dump(cached, open(args.cache, "wb"))
        ref = cached[key]
        chosen = pick(scene, emitter, receivers, args.per_emitter, rng)
        got = {}  # (j, tol): the pair
        for j in chosen:
            cls = pair_class(scene, emitter[0], j)
            for tol in args.tol:
                pair = got[j, tol] = timed_pair(scene, *emitter, j, tol)
                entries, worst = judge(pair, ref, j)
                beyond = [e for e in entries if e[5] > e[2] + e[4] + 1e-14]
                s = stats[tol][cls]
                s["pairs"] += 1
                s["entries"] += 2
                s["beyond"] += len(beyond)
                s["cpu"] += pair["cpu"]
                s["points"] += pair["points"]
                if worst > s["worst"]:
                    s["worst"], s["worst_pair"] = worst, [emitter[0], emitter[1], j]
                print(json.dumps({"pair": [emitter[0], emitter[1], int(j)], "class": cls, "tol": tol,
                                  "cpu": round(pair["cpu"], 3), "points": pair["points"],
                                  "ref_cpu": round(ref[3]["cpu"], 2), "F": pair["F"], "error": pair["error"],
                                  "worst_ratio": round(worst, 3), "beyond": [list(e) for e in beyond]}), flush=True)
        if args.mc and mc_left > 0:
            from oracles import form_factor_monte_carlo

            mc_left -= 1
            F, sigma = form_factor_monte_carlo(scene, [emitter[0]], emitter[1], args.mc, seed=args.seed,
                                               lying=ff.contact_cells(scene, *emitter))
            row = dict(zip(ref[0].tolist(), ref[1].tolist()))
            for j in chosen:
                for k, name in enumerate(("front", "back")):
                    values = {"ref": row.get(2 * j + k, 0.0),
                              **{f"tol {t:g}": got[j, t]["sides"][name]["F"] for t in args.tol}}
                    if F[2 * j + k] == 0 and max(abs(v) for v in values.values()) < 1e-12:
                        continue
                    record = {"monte_carlo": [emitter[0], emitter[1], int(j), k], "rays": args.mc,
                              "mc": float(F[2 * j + k]), "sigma": float(sigma[2 * j + k]), **values}
                    if F[2 * j + k] * args.mc >= 10:  # else too few rays for σ to mean much
                        record["z"] = {n: round((v - float(F[2 * j + k])) / float(sigma[2 * j + k]), 2)
                                       for n, v in values.items()}
                    print(json.dumps(record), flush=True)
    for tol, by_class in stats.items():
        total = {"pairs": 0, "entries": 0, "beyond": 0, "worst": 0.0, "cpu": 0.0, "points": 0}
        for cls, s in sorted(by_class.items()):
            print(json.dumps({"tol": tol, "class": cls, **{k: (round(v, 3) if isinstance(v, float) else v)
                                                            for k, v in s.items()}}), flush=True)
            for k in ("pairs", "entries", "beyond", "cpu", "points"):
                total[k] += s[k]
            total["worst"] = max(total["worst"], s["worst"])
        print(json.dumps({"scene": args.scene, "polygons": args.polygons, "tol": tol, "ref_tol": args.ref_tol,
                          "ref_split": args.ref_split, **{k: (round(v, 3) if isinstance(v, float) else v)
                                                          for k, v in total.items()}}), flush=True)


if __name__ == "__main__":
    main()
