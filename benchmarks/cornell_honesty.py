"""Are the Cornell matrix's error estimates honest? Every row (and sky term) at ``--tol``
against the same rows at a tight ``--ref`` tolerance (default 1e-7), one process:

    python benchmarks/cornell_honesty.py --tol 1e-4 1e-6
    python benchmarks/cornell_honesty.py --tol 1e-4 1e-6 --reciprocal

``--reciprocal``: the rows as the matrix computes them (each pair in the rows of its smaller
face, :func:`viscx.queries.formfactor.computed_pairs`; a row then cuts its cells along the
kink lines of the columns it computes only), judged on the entries they compute and their
sky terms; the reference stays two-sided.

prints per tolerance the points, the CPU seconds of the rows, the largest |F − F_ref| /
estimate (an honest estimate keeps it below 1; the entries whose difference is within
1e-12, rounding, are not judged) and the entries off by more than their estimate plus the
reference's. The reference rows are kept in ``--cache`` (a pickle) to be reused. Reports,
never asserts (the slow test ``tests/test_kinks.py::test_cornell_rows_within_their_
estimates_of_tight_rows`` asserts it on the floor and back wall rows).
"""

import argparse
import json
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def rows(scene, tol, reciprocal=False):
    """{(face, side): row_form_factors(...)} of every side, the points and the CPU seconds."""
    from viscx.queries import formfactor as ff

    faces = np.arange(scene.n_faces)
    out, points = {}, 0
    c0 = time.process_time()
    for f in range(scene.n_faces):
        for s in ff.SIDES:
            out[f, s] = ff.row_form_factors(scene, f, s, faces, tol, reciprocal=reciprocal)
            points += out[f, s][3].get("evaluations", 0)
    return out, points, time.process_time() - c0


def judge(got, ref, computed=None):
    """(worst |F − F_ref| / estimate with its entry, the entries beyond estimate + reference's).
    ``computed``: {(face, side): (k,) the faces the row computes}, the others' entries not
    judged (reciprocal rows)."""
    worst, over = (0.0, None), []
    for key, r in got.items():
        tight = dict(zip(ref[key][0], zip(ref[key][1], ref[key][2])))
        entries = [(c, f, e, *tight.get(c, (0.0, 0.0))) for c, f, e in zip(r[0], r[1], r[2])]
        missing = set(tight) - set(r[0])
        if computed is not None:
            missing = {c for c in missing if c // 2 in computed[key]}
        entries += [(c, 0.0, 0.0, *tight[c]) for c in missing]
        entries.append(("sky", r[4], r[5], ref[key][4], ref[key][5]))
        for c, f, e, fr, er in entries:
            d = abs(f - fr)
            if d <= 1e-12:
                continue
            ratio = d / max(e, 1e-300)
            if ratio > worst[0]:
                worst = (ratio, {"row": [int(key[0]), int(key[1])], "column": str(c), "F": f, "ref": fr, "estimate": e})
            if d > e + er:
                over.append({"row": [int(key[0]), int(key[1])], "column": str(c), "off": d, "estimate": e})
    return worst, over


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tol", type=float, nargs="*", default=[1e-4, 1e-6])
    parser.add_argument("--ref", type=float, default=1e-7)
    parser.add_argument("--cache", type=Path, default=Path("/tmp/viscx_cornell_ref_rows.pkl"))
    parser.add_argument("--reciprocal", action="store_true", help="the matrix's rows (each pair from its smaller face)")
    args = parser.parse_args(argv)
    from viscx.queries import formfactor as ff
    from viscx.scene import load_scene

    scene = load_scene(str(ROOT / "sample_scenes" / "cornell_box.obj"))
    ff.load_row_kernels(scene)
    if args.cache.exists():
        ref = pickle.loads(args.cache.read_bytes())
    else:
        ref, points, sec = rows(scene, args.ref)
        args.cache.write_bytes(pickle.dumps(ref))
        print(json.dumps({"reference tol": args.ref, "points": points, "cpu": round(sec, 1)}), flush=True)
    for tol in args.tol:
        got, points, sec = rows(scene, tol, args.reciprocal)
        faces = np.arange(scene.n_faces)
        computed = {k: faces[ff.computed_pairs(scene, k[0], faces)] for k in got} if args.reciprocal else None
        (ratio, where), over = judge(got, ref, computed)
        print(json.dumps({"tol": tol, "points": points, "cpu": round(sec, 2), "worst_error_over_estimate": round(ratio, 3),
                          "worst": where, "beyond_estimates": over}), flush=True)


if __name__ == "__main__":
    sys.exit(main())
