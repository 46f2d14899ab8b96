"""Why a pair's cubature needs so many points at a tight tol: the anatomy of its error
estimate (docs/queries.md, "At the default tol").

For a pair of groups of the office (benchmarks/buildings.py; the first face of each, the
emitter's side that has occluders), two measurements:

* ``kinks``: the emitter's candidate kink segments (D1: :func:`viscx.queries.kinks.kink_segments`
  of the pair's :func:`viscx.queries.formfactor.kink_faces`; visibility not asked), clipped
  to the face's box less 1 mm, and each one's *measured* slope jump: the second difference
  ``(f(m − δn) + f(m + δn) − 2 f(m)) / δ`` of the pair's integrand F(x → visible J) across
  the segment (δ = 0.1 mm, n its normal in the plane) at 5 points along it, the median of
  their absolute values (a kink of slope jump s gives s; the smooth part O(δ)). A sample
  that jumps by more than 1 lies across a contact line (D0) and the segment is left out.
  Reported: how many segments, how many lie along the face's axes, and how few hold 50,
  90 and 99 % of the weight ``jump × length`` (the error of a rule across a kink line
  scales with it).
* ``leaves``: the pair's cubature (:func:`viscx.queries.formfactor.pair_form_factor` at
  ``--tol``), then each final leaf's true error against a reference, the leaf split
  ``--levels`` times more (4^levels triangles, Radon's rule on each, the leaf's occluder
  list): the sum of the estimates, of the absolute errors, the absolute sum of the errors
  (what the pair is off), their root sums of squares, the leaves whose error is above
  their estimate, and how many errors are positive.

    python benchmarks/estimate_anatomy.py --pairs wall_west:wall_east floor:ceiling --tol 1e-5
    python benchmarks/estimate_anatomy.py --pairs wall_west:wall_east --only leaves --levels 4

Prints one JSON line per pair and measurement.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: Distance of the second difference's points from the segment (m).
DELTA = 1e-4
#: Where along each segment its jump is measured (fractions of its length).
ALONG = (0.1, 0.3, 0.5, 0.7, 0.9)


def pair_setup(scene, group_i, group_j):
    """``(face_i, side_i, face_j, side_j, setup)``: the first face of each group (or the
    face of that number), the sides facing each other's centroid; None when that pair of
    sides has no occluder."""
    from viscx.queries import formfactor as ff

    fi, fj = (int(g) if g.isdigit() else int(scene.group_faces(g)[0]) for g in (group_i, group_j))
    ci, cj = (np.concatenate(scene.face_loops(f)).mean(axis=0) for f in (fi, fj))
    side = 1 if scene.face_normal[fi] @ (cj - ci) > 0 else -1
    st = 1 if scene.face_normal[fj] @ (ci - cj) > 0 else -1
    setup = ff.PairSetup(scene, fi, side, ff.face_target(scene, fj), st)
    return (fi, side, fj, st, setup) if not setup.empty and setup.occluders else None


def kink_weights(scene, fi, side, fj, setup):
    """The emitter's candidate kink segments and their measured jumps (module docstring).

    Returns
    -------
    a, b : (k, 2) float
        Their ends in the emitter's plane (:func:`viscx.queries.formfactor._emitter_pieces`' frame).
    jump : (k,) float
        Median absolute slope jump (0 for a segment across a contact line).
    listed : int
        Segments listed before clipping to the face.
    """
    from viscx.queries import formfactor as ff
    from viscx.queries import kinks as kk

    origin, eu, ev, _, pieces = ff._emitter_pieces(scene, fi, side)
    segs = np.asarray(kk.kink_segments(scene, fi, side, generators=kk.face_generators(
        scene, ff.kink_faces(scene, fi, side, [fj]))))
    two = np.stack([(segs - origin) @ eu, (segs - origin) @ ev], axis=-1)
    corners = np.concatenate(pieces)
    t0, t1 = ff.box_clip(two, corners.min(axis=0) + 1e-3, corners.max(axis=0) - 1e-3)
    kept = t1 > t0 + 1e-9
    d = two[kept, 1] - two[kept, 0]
    a, b = two[kept, 0] + t0[kept, None] * d, two[kept, 0] + t1[kept, None] * d
    d = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
    normal = np.stack([-d[:, 1], d[:, 0]], axis=1)
    jumps = []
    for s in ALONG:
        m = a + s * (b - a)
        p = np.concatenate([m - DELTA * normal, m, m + DELTA * normal])
        f = setup.f(origin + p[:, :1] * eu + p[:, 1:] * ev)
        k = len(m)
        jumps.append((f[:k] + f[2 * k:] - 2 * f[k:2 * k]) / DELTA)
    jumps = np.abs(np.array(jumps))
    return a, b, np.where((jumps > 1).any(axis=0), 0.0, np.median(jumps, axis=0)), len(segs)


def kinks_report(scene, fi, side, fj, setup):
    t = time.process_time()
    a, b, jump, listed = kink_weights(scene, fi, side, fj, setup)
    length = np.linalg.norm(b - a, axis=1)
    w = jump * length
    d = (b - a) / length[:, None]
    along_axes = np.abs(d).min(axis=1) < 1e-9
    order = np.argsort(-w)
    share = np.cumsum(w[order]) / w.sum()
    holding = {f"{q:g}": int(np.searchsorted(share, q)) + 1 for q in (0.5, 0.9, 0.99)}
    return {"listed": listed, "on_face": len(w), "along_axes": int(along_axes.sum()),
            "weight_along_axes": round(float(w[along_axes].sum() / w.sum()), 4),
            "segments_holding_weight": holding,
            "jump_quantiles_50_90_99_max": [float(f"{x:.3g}") for x in np.quantile(jump, [0.5, 0.9, 0.99, 1.0])],
            "cpu_s": round(time.process_time() - t, 1)}


def leaves_report(scene, fi, side, fj, st, tol, levels):
    from viscx.queries import formfactor as ff

    made = []
    init = ff.Cubature.__init__

    def spy(self, *args, **kwargs):
        init(self, *args, **kwargs)
        made.append(self)

    ff.Cubature.__init__ = spy
    try:
        t = time.process_time()
        r = ff.pair_form_factor(scene, fi, side, ff.face_target(scene, fj), st, tol=tol)
        cpu = time.process_time() - t
    finally:
        ff.Cubature.__init__ = init
    if not made or made[-1].leaves is None:
        return {"F": r.F, "estimate": r.error, "method": r.method, "note": "no three-level cubature"}
    cub = made[-1]
    tri, ptr, ids, _, kq, gq, est = cub.leaves
    fine = tri
    for _ in range(levels):
        fine = ff.split4(fine).reshape(-1, 3, 3)
    n = 4 ** levels
    fptr, fids = ff._sub_lists(ptr, ids, np.repeat(np.arange(len(tri)), n))
    t = time.process_time()
    ref = cub.rule(fine, fptr, fids).reshape(-1, n).sum(axis=1)
    e = gq.sum(axis=1) - ref  # absolute (area × F)
    d = kq.sum(axis=1) - gq.sum(axis=1)  # each leaf's last change, signed
    area = float(scene.face_area[fi])
    return {"F": r.F, "estimate": r.error, "points": r.evaluations, "cpu_s": round(cpu, 1), "leaves": len(tri),
            "reference_cpu_s": round(time.process_time() - t, 1),
            "sum_estimates": float(est.sum() / area), "sum_abs_errors": float(np.abs(e).sum() / area),
            "abs_sum_errors": float(abs(e.sum()) / area), "rss_errors": float(np.sqrt((e ** 2).sum()) / area),
            "rss_estimates": float(np.sqrt((est ** 2).sum()) / area),
            "abs_sum_changes": float(abs(d.sum()) / area), "rss_changes": float(np.sqrt((d ** 2).sum()) / area),
            "leaves_error_above_estimate": int((np.abs(e) > est).sum()), "positive_errors": int((e > 0).sum())}


def main(argv=None):
    from buildings import office
    from viscx.scene import build_scene

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--polygons", type=int, default=300)
    parser.add_argument("--pairs", nargs="+", default=["wall_west:wall_east"], metavar="FROM:TO")
    parser.add_argument("--tol", type=float, default=1e-5)
    parser.add_argument("--levels", type=int, default=4, help="the reference's extra levels per leaf")
    parser.add_argument("--only", choices=["kinks", "leaves"], default=None)
    args = parser.parse_args(argv)
    scene = build_scene(office(args.polygons, seed=0))
    for pair in args.pairs:
        gi, gj = pair.split(":")
        found = pair_setup(scene, gi, gj)
        if found is None:
            print(json.dumps({"pair": pair, "note": "no occluder between the sides facing each other"}), flush=True)
            continue
        fi, side, fj, st, setup = found
        head = {"pair": pair, "face_i": fi, "side_i": side, "face_j": fj, "occluders": len(setup.occluders)}
        if args.only in (None, "kinks"):
            print(json.dumps({**head, "kinks": kinks_report(scene, fi, side, fj, setup)}), flush=True)
        if args.only in (None, "leaves"):
            print(json.dumps({**head, "tol": args.tol, "leaves": leaves_report(scene, fi, side, fj, st, args.tol,
                                                                              args.levels)}), flush=True)


if __name__ == "__main__":
    main()
