"""The office's form-factor matrix (benchmarks/buildings.py) by row class: where the time goes
and what the whole matrix costs.

Each side of the office is one row of ``viscx formfactor matrix``
(:func:`viscx.queries.formfactor.form_factor_matrix`); its class says which path computes it:

* ``box inner``: the inner side of a face of an empty closed box (a cabinet, a desk's top or
  panel, a divider): closed form (contour integrals to the box's other faces);
* ``lying``: a side lying wholly on other faces (a cabinet's bottom on the floor): closed form;
* ``box outer``: the outer side of a box face, by the row cubature;
* ``shell``: floor, ceiling, walls (both sides), by the row cubature (outer sides see the sky);
* ``light``: the light quads (both sides), by the row cubature.

Without ``--whole``: ``--sample`` rows per class, one process, each row's CPU seconds (one JSON
line per row, then a summary per class with the extrapolation to all the class's rows).
With ``--whole``: the whole matrix as the CLI computes it (``--workers`` processes, a row's
points on the cores the others leave idle): CPU seconds (workers included), wall seconds,
peak RSS (this process and, separately, the largest worker), reciprocity and row sums, per
class the rows' CPU seconds, the five largest rows (CPU seconds, and the serial part no
other core can take) and the balance (:func:`balance`): the wall time on quiet cores
is about the larger of CPU / cores and the largest row's serial part plus the rest of it
over the cores (on a shared machine the measured wall time says little).

    python benchmarks/office_matrix.py --polygons 300 --tol 1e-4 --sample 5
    python benchmarks/office_matrix.py --polygons 300 --tol 1e-4 --whole --workers 2
    python benchmarks/office_matrix.py --polygons 1000 --tol 1e-4 --whole --row-log rows.jsonl
"""

import argparse
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def cpu_seconds():
    """user + sys of this process and its waited-for children (the pool's workers)."""
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def row_classes(scene):
    """{(face, side): class name} for every side (the module's docstring)."""
    from viscx.queries import formfactor as ff

    face_box = ff.closed_boxes(scene)[0]
    empty = ff.empty_boxes(scene)
    names = scene.group_names
    out = {}
    for f in range(scene.n_faces):
        group = names[scene.face_group[f]]
        for s in ff.SIDES:
            if s == -1 and face_box[f] >= 0 and empty[face_box[f]]:
                kind = "box inner"
            elif ff.closed_form_row(scene, f, s, np.zeros(0, np.int64), sky=False) is not None:
                kind = "lying"
            elif face_box[f] >= 0:
                kind = "box outer"
            elif group.startswith("light"):
                kind = "light"
            else:
                kind = "shell"
            out[(f, s)] = kind
    return out


#: Where each finished row of ``--whole`` is logged (one JSON line, appended by the workers).
ROW_LOG = [None]


def timed_row(scene, face, side, faces, tol, sky, threads=1, reciprocal=True):
    """:func:`viscx.queries.formfactor.row_form_factors` (each pair from its smaller face, as
    the CLI's matrix: ``reciprocal``) with its CPU seconds in ``counts``:
    ``cpu`` all of the row's threads, ``serial`` its calling thread's alone (with threads,
    its points run on the others, so this is the part no other core can take; a line in
    ``ROW_LOG`` too, so that a run stopped early still says what it did)."""
    from viscx.queries.formfactor import row_form_factors

    c0, s0 = time.process_time(), time.thread_time()
    cols, vals, errs, counts, sky_v, sky_e = row_form_factors(scene, face, side, faces, tol, sky, reciprocal=reciprocal,
                                                              threads=threads)
    cpu, serial = time.process_time() - c0, time.thread_time() - s0
    if ROW_LOG[0]:
        with open(ROW_LOG[0], "a") as f:
            f.write(json.dumps({"face": int(face), "side": int(side), "area": round(float(scene.face_area[face]), 4),
                                "cpu": round(cpu, 3), "serial": round(serial, 3), "row_sum": float(vals.sum() + sky_v)})
                    + "\n")
    return cols, vals, errs, {**counts, "cpu": cpu, "serial": serial}, sky_v, sky_e


def balance(cpu, serial, workers):
    """What bounds the wall time of a matrix on ``workers`` quiet cores, from its rows' CPU
    seconds ``cpu`` and their serial parts ``serial`` (:func:`timed_row`): the whole CPU
    over the cores, and the largest row's least wall time (its serial part plus the rest
    on all the cores); the wall time is about the larger of the two (plus what the workers
    lose to one another)."""
    cpu, serial = np.asarray(cpu), np.asarray(serial)
    least = serial + (cpu - serial) / workers
    k = int(np.argmax(least))
    return {"cpu_over_cores": round(float(cpu.sum()) / workers, 1), "largest_row_cpu": round(float(cpu.max()), 1),
            "largest_row_least_wall": round(float(least[k]), 1), "its_serial_cpu": round(float(serial[k]), 1),
            "quiet_wall_estimate": round(max(float(cpu.sum()) / workers, float(least[k])), 1)}


def main(argv=None):
    from buildings import office

    from viscx.parallel import default_workers
    from viscx.queries import formfactor as ff
    from viscx.scene import build_scene

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--polygons", type=int, default=300)
    parser.add_argument("--tol", type=float, default=1e-4)
    parser.add_argument("--sample", type=int, default=5, help="rows per class (without --whole)")
    parser.add_argument("--whole", action="store_true", help="the whole matrix")
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0, help="of the sample")
    parser.add_argument("--classes", default=None, help="without --whole: only these classes (comma-separated)")
    parser.add_argument("--row-log", default=None, help="--whole: append each finished row here (JSON lines)")
    parser.add_argument("--save", default=None, help="--whole: the matrix's arrays to this .npz (to compare runs: "
                        "the same on any number of workers, bit for bit)")
    args = parser.parse_args(argv)
    ROW_LOG[0] = args.row_log
    c0 = time.process_time()
    scene = build_scene(office(args.polygons, seed=0))
    classes = row_classes(scene)
    kinds = sorted(set(classes.values()))
    members = {k: [r for r, c in classes.items() if c == k] for k in kinds}
    print(json.dumps({"faces": int(scene.n_faces), "sides": len(classes), "classes": {k: len(v) for k, v in members.items()},
                      "setup_cpu": round(time.process_time() - c0, 2)}), flush=True)
    faces = np.arange(scene.n_faces, dtype=np.int64)
    if not args.whole:
        rng = np.random.default_rng(args.seed)
        small = min(members.get("box outer", [(0, 1)]), key=lambda r: scene.face_area[r[0]])
        ff.row_form_factors(scene, *small, faces, args.tol)  # the kernels compiled or loaded
        for k in kinds if args.classes is None else [c for c in args.classes.split(",") if c in members]:
            rows = members[k]
            pick = [rows[i] for i in sorted(rng.choice(len(rows), min(args.sample, len(rows)), replace=False))]
            cpu = []
            for f, s in pick:
                r = timed_row(scene, f, s, faces, args.tol, True)
                cpu.append(r[3]["cpu"])
                print(json.dumps({"class": k, "face": int(f), "side": int(s), "area": round(float(scene.face_area[f]), 4),
                                  "cpu": round(cpu[-1], 3), "row_sum": float(r[1].sum() + r[4]),
                                  "max_error": float(r[2].max(initial=r[5]))}), flush=True)
            print(json.dumps({"class": k, "rows": len(rows), "sampled": len(pick), "mean_cpu": round(float(np.mean(cpu)), 3),
                              "extrapolated_cpu": round(float(np.mean(cpu)) * len(rows), 1)}), flush=True)
        return
    c0, w0 = cpu_seconds(), time.perf_counter()
    tasks, summation = ff.matrix_rows(scene)  # as the CLI's matrix: a closed room's floor row from its sum
    rows = [(f, s) for f, s, _ in tasks]
    from viscx.progress import bar

    with bar(total=len(rows), desc="form factors", quiet=False, unit="side") as progress:
        results = ff._map_rows(timed_row, scene, tasks, args.tol, True, args.workers,
                               progress=lambda: progress.update(1), threads=True)
    wall, cpu = time.perf_counter() - w0, cpu_seconds() - c0
    m = ff.assemble_matrix(scene, results, args.tol, wall, reciprocal=True, summation=summation)
    per = {}
    for (f, s), r in zip(rows, results):
        per.setdefault(classes[(f, s)], []).append(r[3]["cpu"])
    workers = min(default_workers(args.workers), len(rows))
    largest = sorted(range(len(rows)), key=lambda k: -results[k][3]["cpu"])[:5]
    if args.save:
        np.savez(args.save, **{k: getattr(m, k) for k in ("indptr", "indices", "data", "error", "sky", "sky_error")})
    summary = m.summary()
    summary.pop("methods")
    print(json.dumps({
        "polygons": args.polygons, "faces": int(scene.n_faces), "tol": args.tol, "workers": args.workers,
        "cpu": round(cpu, 1), "wall": round(wall, 1),
        "peak_rss_gb_main": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6, 3),
        "peak_rss_gb_worker": round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6, 3),
        "classes": {k: {"rows": len(v), "cpu": round(float(np.sum(v)), 1), "max_row_cpu": round(float(np.max(v)), 2)}
                    for k, v in per.items()},
        "largest_rows": [{"face": rows[k][0], "side": rows[k][1], "class": classes[rows[k]],
                          "cpu": round(results[k][3]["cpu"], 1), "serial": round(results[k][3]["serial"], 1)}
                         for k in largest],
        "balance": balance([r[3]["cpu"] for r in results], [r[3]["serial"] for r in results], workers),
        **summary}), flush=True)


if __name__ == "__main__":
    main()
