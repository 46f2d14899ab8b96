"""Are the matrix rows' error estimates honest? Each entry of the rows of a furnished office
(benchmarks/buildings.py) at ``--tol`` against the same rows computed finer (``--ref-tol``,
first triangles ``--ref-split`` times smaller: the nodes that many times denser, so a kink or a
shadow between the coarse rows' nodes is seen), and counted *beyond* where
``|F − F_ref| > E + E_ref + 1e-14`` (its estimate plus the reference's; 1e-14 is the
contour integrals' rounding, F ∈ [0, 1]).

``--rows three-level`` takes the rows on :class:`ThreeLevelRowCubature` at the
coarse start (the emitters with more kink cells than they may be cut into), ``all`` every
row the matrix integrates (not the closed-form ones; the default). With ``--reciprocal`` each row holds
the pairs the matrix computes in it (:func:`viscx.queries.formfactor.computed_pairs`): what
the matrix reports (a derived entry's error and estimate are the computed one's times
A_a / A_b). The reference rows are cached in ``--cache`` (a pickle, keyed by the office, the
row and its options) as they are computed, as they cost minutes.

    python benchmarks/formfactor_honesty.py --polygons 100 --tol 1e-4 --cache /tmp/ref100.pkl

Prints one JSON line per row (CPU s, points, entries beyond) and a summary: entries,
beyond, the worst ratio ``|F − F_ref| / (E + E_ref)`` and the largest difference.
"""

import argparse
import json
import pickle
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def timed_row(scene, face, side, tol, split=1.0, reciprocal=False):
    """:func:`viscx.queries.formfactor.row_form_factors` of every face (with ``reciprocal``,
    the pairs the matrix computes in this row), its CPU s in ``counts["cpu"]``, the first
    triangles ``split`` times smaller than the default."""
    from viscx.queries import formfactor as ff

    faces = np.arange(scene.n_faces, dtype=np.int64)
    saved = ff.MIN_SPLIT, ff.THREE_LEVEL_SPLIT
    ff.MIN_SPLIT, ff.THREE_LEVEL_SPLIT = saved[0] * split, saved[1] * split
    try:
        c0 = time.process_time()
        r = ff.row_form_factors(scene, face, side, faces, tol, reciprocal=reciprocal)
        r[3]["cpu"] = time.process_time() - c0
        return r
    finally:
        ff.MIN_SPLIT, ff.THREE_LEVEL_SPLIT = saved


def compare(row, ref, floor=1e-14):
    """[(element or "sky", F, F_ref, |F − F_ref|, E, E_ref)] of a row's entries (and sky)
    beyond their estimates plus the reference's (+ ``floor``), and the worst ratio."""
    a = dict(zip(row[0].tolist(), zip(row[1], row[2])))
    b = dict(zip(ref[0].tolist(), zip(ref[1], ref[2])))
    a["sky"], b["sky"] = (row[4], row[5]), (ref[4], ref[5])
    beyond, worst = [], 0.0
    for c in sorted(set(a) | set(b), key=str):
        (fa, ea), (fb, eb) = a.get(c, (0.0, 0.0)), b.get(c, (0.0, 0.0))
        d = abs(fa - fb)
        worst = max(worst, d / max(ea + eb + floor, 1e-300))
        if d > ea + eb + floor:
            beyond.append((c, float(fa), float(fb), float(d), float(ea), float(eb)))
    return beyond, worst, len(a)


def main(argv=None):
    from buildings import office
    from office_matrix import row_classes

    from viscx.queries import formfactor as ff
    from viscx.scene import build_scene

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--polygons", type=int, default=100)
    parser.add_argument("--tol", type=float, default=1e-4)
    parser.add_argument("--ref-tol", type=float, default=1e-6)
    parser.add_argument("--ref-split", type=float, default=4.0)
    parser.add_argument("--rows", choices=("three-level", "all"), default="all")
    parser.add_argument("--reciprocal", action="store_true",
                        help="the rows as the matrix computes them: only the pairs whose other face is larger")
    parser.add_argument("--cache", default=None, help="the reference's pickle (read if it holds these rows)")
    args = parser.parse_args(argv)
    scene = build_scene(office(args.polygons, seed=0))
    classes = row_classes(scene)
    rows = [r for r, c in sorted(classes.items()) if c not in ("box inner", "lying")]
    if args.rows == "three-level":
        rows = [(f, s) for f, s in rows if not ff.cubature_cells(scene, f, s)[2]]
    rows.sort(key=lambda r: (scene.face_area[r[0]], r))  # the cheap rows first: a stopped run says most
    cached = pickle.load(open(args.cache, "rb")) if args.cache and Path(args.cache).exists() else {}
    entries, beyond, worst, diff, cpu, points = 0, 0, 0.0, 0.0, 0.0, 0
    for r in rows:
        key = (args.polygons, r, args.ref_tol, args.ref_split, args.reciprocal)
        if key not in cached:
            cached[key] = timed_row(scene, *r, args.ref_tol, args.ref_split, args.reciprocal)
            if args.cache:
                pickle.dump(cached, open(args.cache, "wb"))
        ref = cached[key]
        got = timed_row(scene, *r, args.tol, reciprocal=args.reciprocal)
        b, w, n = compare(got, ref)
        entries, beyond, worst = entries + n, beyond + len(b), max(worst, w)
        diff = max(diff, max((x[3] for x in b), default=0.0))
        cpu, points = cpu + got[3]["cpu"], points + got[3]["evaluations"]
        print(json.dumps({"row": [int(r[0]), int(r[1])], "class": classes[r], "cpu": round(got[3]["cpu"], 2),
                          "points": got[3]["evaluations"], "ref_cpu": round(ref[3]["cpu"], 2),
                          "worst_ratio": round(w, 3), "beyond": [list(x) for x in b]}), flush=True)
    print(json.dumps({"polygons": args.polygons, "tol": args.tol, "ref_tol": args.ref_tol, "ref_split": args.ref_split,
                      "rows": len(rows), "entries": entries, "beyond": beyond, "worst_ratio": worst,
                      "largest_difference_beyond": diff,
                      "reciprocal": args.reciprocal, "cpu": round(cpu, 1), "points": int(points)}), flush=True)


if __name__ == "__main__":
    main()
