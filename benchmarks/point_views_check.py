"""Record and compare :func:`viscx.geometry.occlusion.point_views` (the matrix row's
from-point kernel): its per-point CPU cost, and its outputs against those of another
version of the code on the very same inputs (reports, never asserts).

    python benchmarks/point_views_check.py record /tmp/pv      # on the reference version
    python benchmarks/point_views_check.py check /tmp/pv       # on the version to compare

``record`` saves, per case, the kernel's arguments and its outputs in ``DIR/<case>.npz``:

- ``cornell``: every call the Cornell box's matrix makes at ``--tol`` (default 1e-4; the
  cubature's real points, one emitting side after the other), captured from
  :func:`viscx.queries.formfactor.form_factor_matrix` on one process;
- ``office300``, ``office1000``: ``--points`` random points (default 300) on each of a few
  emitters of the office (benchmarks/buildings.py): the floor, a wall, a desk top, a light.

``matrix`` (with ``record``/``check`` as ``--matrix``): the Cornell box's whole matrix at
``--tol`` instead (one process), its dense F (sides and sky) saved or compared, and its CPU
seconds.

``check`` runs the current kernel on the saved inputs and prints per case the CPU µs per
point of both versions and the largest difference of the outputs (absolute: a point's
row, what it sees of every side and of the sky, sums to 1, so this is relative to it).
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
ROOT = HERE.parent


def _cornell_calls(tol):
    """[(args, hidden, seconds)] of every point_views call of the Cornell matrix."""
    from viscx.queries import formfactor as ff
    from viscx.scene import load_scene

    scene = load_scene(str(ROOT / "sample_scenes" / "cornell_box.obj"))
    calls = []
    kernel = ff.point_views

    def spy(*args):
        c0 = time.process_time()
        out = kernel(*args)
        calls.append((args, out, time.process_time() - c0))
        return out

    kernel(*_office_args(scene, 0, scene.vertices[:2]))  # compiled or loaded
    ff.point_views = spy
    try:
        ff.form_factor_matrix(scene, tol=tol, workers=1)
    finally:
        ff.point_views = kernel
    return calls


def _office_args(scene, face, points):
    from viscx.geometry.polygon import plane_basis
    from viscx.queries import formfactor as ff

    n_i = scene.face_normal[face]
    eu, ev = plane_basis(n_i)
    return (np.ascontiguousarray(points), n_i, eu, ev, *ff.scene_polygons(scene), int(face), 1e-9 * scene.diagonal,
            *ff.closed_boxes(scene))


def _office_calls(n_polygons, n_points, seed=1):
    from buildings import office

    from viscx.geometry.occlusion import point_views
    from viscx.scene import build_scene

    scene = build_scene(office(n_polygons, seed=0))
    rng = np.random.default_rng(seed)
    calls = []
    for group in ("floor", "wall_west", "desk0", "light1"):
        face = int(scene.group_faces(group)[0])
        tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
        w = rng.dirichlet([1, 1, 1], n_points)
        pts = np.einsum("gk,gkd->gd", w, tri[rng.integers(0, len(tri), n_points)])
        args = _office_args(scene, face, pts)
        point_views(args[0][:2], *args[1:])  # compiled or loaded
        c0 = time.process_time()
        out = point_views(*args)
        calls.append((args, out, time.process_time() - c0))
    return calls


def _save(path, calls):
    data = {}
    for k, (args, out, sec) in enumerate(calls):
        for a, v in enumerate(args):
            data[f"{k}_arg{a}"] = np.asarray(v)
        data[f"{k}_out"] = out
        data[f"{k}_sec"] = np.float64(sec)
    data["n_calls"] = np.int64(len(calls))
    data["n_args"] = np.int64(len(calls[0][0]))
    np.savez_compressed(path, **data)


def _load(path):
    z = np.load(path)
    out = []
    for k in range(int(z["n_calls"])):
        args = []
        for a in range(int(z["n_args"])):
            v = z[f"{k}_arg{a}"]
            args.append(v.item() if v.ndim == 0 else np.ascontiguousarray(v))
        if args[-1].ndim == 2 and args[-1].shape[1] == 4:  # recorded before boxes had an open flag
            args[-1] = np.ascontiguousarray(np.pad(args[-1], ((0, 0), (0, 1))))
        out.append((tuple(args), z[f"{k}_out"], float(z[f"{k}_sec"])))
    return out


def record(folder, tol, n_points, cases):
    folder.mkdir(parents=True, exist_ok=True)
    for case in cases:
        calls = _cornell_calls(tol) if case == "cornell" else _office_calls(int(case[6:]), n_points)
        _save(folder / f"{case}.npz", calls)
        n = sum(len(c[0][0]) for c in calls)
        print(json.dumps({"case": case, "points": n, "us_per_point": round(1e6 * sum(c[2] for c in calls) / n, 1)}),
              flush=True)


def check(folder, cases):
    from viscx.geometry.occlusion import point_views

    for case in cases:
        path = folder / f"{case}.npz"
        if not path.exists():
            continue
        calls = _load(path)
        point_views(calls[0][0][0][:2], *calls[0][0][1:])  # compiled or loaded
        n, sec_ref, sec, d_abs = 0, 0.0, 0.0, 0.0
        for args, ref, s in calls:
            c0 = time.process_time()
            out = point_views(*args)
            sec += time.process_time() - c0
            sec_ref += s
            n += len(args[0])
            d_abs = max(d_abs, float(np.abs(out - ref).max(initial=0.0)))
        print(json.dumps({"case": case, "points": n, "us_per_point_ref": round(1e6 * sec_ref / n, 1),
                          "us_per_point": round(1e6 * sec / n, 1), "max_abs_diff": d_abs}),
              flush=True)


def cornell_matrix(tol):
    """(dense (2n, 2n + 1) F with the sky last, CPU seconds) of the Cornell box's matrix."""
    from viscx.queries import formfactor as ff
    from viscx.scene import load_scene

    scene = load_scene(str(ROOT / "sample_scenes" / "cornell_box.obj"))
    ff.form_factor_matrix(scene, tol=1e-2, workers=1)  # compiled or loaded
    c0 = time.process_time()
    m = ff.form_factor_matrix(scene, tol=tol, workers=1)
    sec = time.process_time() - c0
    n = len(m.sky)
    dense = np.zeros((n, n + 1))
    for r in range(n):
        dense[r, m.indices[m.indptr[r]:m.indptr[r + 1]]] = m.data[m.indptr[r]:m.indptr[r + 1]]
    dense[:, n] = m.sky
    return dense, sec


def matrix(mode, folder, tol):
    path = folder / f"matrix_{tol:g}.npz"
    dense, sec = cornell_matrix(tol)
    if mode == "record":
        folder.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, F=dense, sec=sec)
        print(json.dumps({"case": f"cornell matrix tol {tol:g}", "cpu": round(sec, 2)}), flush=True)
        return
    ref = np.load(path)
    print(json.dumps({"case": f"cornell matrix tol {tol:g}", "cpu_ref": round(float(ref["sec"]), 2), "cpu": round(sec, 2),
                      "max_abs_diff": float(np.abs(dense - ref["F"]).max())}), flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=["record", "check"])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--tol", type=float, default=1e-4)
    parser.add_argument("--points", type=int, default=300)
    parser.add_argument("--cases", nargs="*", default=["cornell", "office300", "office1000"])
    parser.add_argument("--matrix", action="store_true", help="the Cornell matrix instead of the kernel's points")
    args = parser.parse_args(argv)
    if args.matrix:
        matrix(args.mode, args.folder, args.tol)
    elif args.mode == "record":
        record(args.folder, args.tol, args.points, args.cases)
    else:
        check(args.folder, args.cases)


if __name__ == "__main__":
    main()
