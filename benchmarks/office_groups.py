"""Group-to-group form factors in the office (benchmarks/buildings.py): each query's value,
error estimate, CPU seconds (the worker processes included) and wall seconds, as
``viscx formfactor groups`` computes them (:func:`viscx.queries.formfactor.group_to_group`,
default workers: one per core). One JSON line per query, with what bounds its wall time on
quiet cores (the machine may be shared): the CPU seconds of the main process's own serial
work (``serial_cpu``: the rows' planning; for a query of one row, which runs in this
process, everything but its cubatures' kernel pieces), of those pieces (``threaded_cpu``,
shared by the threads), of each task the workers run (a row of a query of several: a face
side and the receivers it computes pairs with, each pair computed from its face of smaller
area and the other direction derived), the largest of them, and ``quiet_wall_estimate``:
the serial part, plus the pieces spread over the threads, plus the tasks handed out in
order to the first free of the workers, those still running once none is left sharing the
cores (their kernel pieces run on threads; the command's start-up, ~1 s, not included).

    python benchmarks/office_groups.py --polygons 300 --tol 1e-4
    python benchmarks/office_groups.py --pairs floor:light1 wall_west:wall_east

Without ``--pairs``: every ordered pair of the groups ``floor, ceiling, wall_*,
light1..4, desk0, cabinet0, divider0`` (the other desks and cabinets are alike).

``--rounds``: each refinement round of the pairs' three-level cubatures on standard error
(leaves, points so far, the estimate and its parts): how fast the estimate falls with the
points (docs/queries.md, "At the default tol").

    python benchmarks/office_groups.py --tol 1e-6 --pairs wall_west:wall_east --rounds

``--cli FILE``: the command line instead, as a user runs it: ``viscx --quiet formfactor
groups FILE --from-group A --to-group B --tol T``, one process per query (start-up
included), its wall seconds and CPU seconds (user + sys of the process and its workers),
stopped after ``--cap`` seconds (``"capped": true``); FILE an office built by viscx:

    python benchmarks/buildings.py office -n 300 -o office300.obj
    viscx build office300.obj -o office300.h5
    python benchmarks/office_groups.py --cli office300.h5 --tol 1e-6 --cap 30

Time it on quiet cores: the 10 s a query is meant to take is wall time on 2 cores.

``--kernels``: the per-point cost (CPU µs) of the two from-point kernels on this office
instead: ``point_views`` from the floor (a matrix row's integrand) and the pair kernel
(``blocked_form_factors``, all the pair's occluders, J's covered cells as holes as the
cubature has them) for a few group pairs, at 300 random points each.

    python benchmarks/office_groups.py --polygons 1000 --kernels
"""

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: The groups timed by default (one of each kind of furniture).
GROUPS = ["floor", "ceiling", "wall_west", "wall_east", "wall_south", "wall_north", "light1", "light2", "light3", "light4",
          "desk0", "cabinet0", "divider0"]


def cpu_seconds():
    """user + sys of this process and its waited-for children (the pool's workers)."""
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def kernel_costs(scene, n=300, seed=1):
    """{name: CPU µs per point} of point_views and of the pair kernel on the office."""
    import numpy as np

    from viscx.geometry.occlusion import point_views
    from viscx.geometry.polygon import plane_basis
    from viscx.queries import formfactor as ff

    rng = np.random.default_rng(seed)

    def points(face):
        tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
        w = rng.dirichlet([1, 1, 1], n)
        return np.ascontiguousarray(np.einsum("gk,gkd->gd", w, tri[rng.integers(0, len(tri), n)]))

    def per_point(f, pts):
        f(pts[:2])  # compiled or loaded
        c0 = time.process_time()
        f(pts)
        return round(1e6 * (time.process_time() - c0) / len(pts), 1)

    floor = int(scene.group_faces("floor")[0])
    n_i = scene.face_normal[floor]
    eu, ev = plane_basis(n_i)
    args = (*ff.scene_polygons(scene), floor, 1e-9 * scene.diagonal, *ff.closed_boxes(scene))
    out = {"faces": int(scene.n_faces),
           "point_views floor": per_point(lambda p: point_views(p, n_i, eu, ev, *args), points(floor))}
    for a, b in (("floor", "ceiling"), ("ceiling", "floor"), ("wall_west", "wall_east"), ("floor", "light1")):
        i, j = int(scene.group_faces(a)[0]), int(scene.group_faces(b)[0])
        target = ff.face_target(scene, j)
        target = ff.Target(target.loops + ff.covered_cells(scene, j, 1), target.normal, j)
        setup = ff.PairSetup(scene, i, 1, target, 1)
        ids = np.arange(len(setup.occluders), dtype=np.int64)
        ptr = np.array([0, len(ids)], np.int64)
        out[f"pair {a}->{b} ({len(ids)} occluders)"] = per_point(
            lambda p: setup.blocked(p, np.zeros(len(p), np.int64), ptr, ids), points(i))
    return out


#: Where each finished emitter row of a query is logged (:func:`timed_row`), and the
#: library's ``emitter_row`` it times.
ROW_LOG = [None]
EMITTER_ROW = [None]
#: The thread CPU seconds of each piece a cubature's kernels ran (:func:`timed_chunks`), and
#: the library's ``map_chunks`` it wraps.
PIECES = []
MAP_CHUNKS = [None]


def timed_row(scene, face, side, faces, tol, sky, threads=1):
    """:func:`viscx.queries.formfactor.emitter_row` (what a worker of :func:`group_to_group`
    runs, or the query's process for a query of one row) with its CPU seconds appended to
    ``ROW_LOG``."""
    c0 = time.process_time()
    out = EMITTER_ROW[0](scene, face, side, faces, tol, sky, threads)
    with open(ROW_LOG[0], "a") as f:
        f.write(json.dumps({"face": int(face), "side": int(side), "cpu": round(time.process_time() - c0, 3),
                            "pid": os.getpid()}) + "\n")
    return out


def timed_chunks(function, chunks, workers=None, progress=None):
    """``map_chunks`` with each chunk's thread CPU seconds appended to ``PIECES``."""
    def timed(chunk):
        c0 = time.thread_time()
        out = function(chunk)
        PIECES.append(time.thread_time() - c0)
        return out

    return MAP_CHUNKS[0](timed, chunks, workers, progress)


def makespan(tasks, workers):
    """Wall time of ``tasks`` (CPU seconds, in the order they are handed out) on ``workers``
    quiet cores, each task to the first worker free, and once none is left to hand out the
    tasks still running sharing the cores (a group query's rows run their kernel pieces on
    threads holding the pool's core tokens; their serial parts are taken as nil)."""
    queue, running, wall = list(tasks), [], 0.0
    while queue or running:
        while queue and len(running) < workers:
            running.append(queue.pop(0))
        rate = 1.0 if queue else workers / len(running)  # cores per running task
        step = min(running) / rate
        wall += step
        running = [t - step * rate for t in running if t - step * rate > 1e-12]
    return wall


#: The three-level cubature's error model, and each round's log (:func:`logged_estimates`).
ESTIMATES = [None]


def logged_estimates(self, tri, ptr, ids, q, kq, gq):
    """``Cubature.estimates`` printing, on standard error, each round's leaves, points so
    far and estimate (absolute, area × F) with its parts: leaves whose change grows
    (``4 |K − G|``), the others' ``|K − G|`` and ``|Q − K| / 12`` where each is the larger,
    and what the ``unresolved`` and ``unseen`` bounds add."""
    import numpy as np

    from viscx.queries import formfactor as ff

    err = ESTIMATES[0](self, tri, ptr, ids, q, kq, gq)
    kink = ff.kinked_three_level_error(q, kq, gq)
    coarse, fine = np.abs(q - kq.sum(axis=1)), np.abs(kq.sum(axis=1) - gq.sum(axis=1))
    grow = fine > coarse
    print(json.dumps({"leaves": len(tri), "points": self.evaluations, "estimate": float(err.sum()),
                      "grows": float(kink[grow].sum()), "fine": float(fine[~grow & (fine >= coarse / ff.KINK_LEVELS)].sum()),
                      "coarse": float(kink[~grow & (fine < coarse / ff.KINK_LEVELS)].sum()),
                      "bounds": float((err - kink).sum())}), file=sys.stderr, flush=True)
    return err


def cli_queries(path, pairs, tol, cap):
    """Each group query of ``pairs`` [(from, to)] on the command line, one process each
    (module docstring, ``--cli``): one JSON line per query."""
    import subprocess

    for a, b in pairs:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        w0 = time.perf_counter()
        argv = [sys.executable, "-m", "viscx", "--quiet", "formfactor", "groups", str(path), "--from-group", a,
                "--to-group", b, "--tol", repr(tol)]
        try:
            done = subprocess.run(argv, capture_output=True, text=True, timeout=cap)
            record, capped = (json.loads(done.stdout) if done.returncode == 0 else {"stderr": done.stderr.strip()}), False
        except subprocess.TimeoutExpired:
            record, capped = {}, True
        wall = time.perf_counter() - w0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
        print(json.dumps({"from": a, "to": b, "tol": tol, "wall": round(wall, 2), "cpu": round(cpu, 2), "capped": capped,
                          **{k: record[k] for k in ("F", "error", "tol_reached", "stderr") if k in record}}), flush=True)


def main(argv=None):
    from buildings import office

    from viscx.parallel import default_workers
    from viscx.queries import formfactor as ff
    from viscx.queries.formfactor import group_to_group
    from viscx.scene import build_scene

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--polygons", type=int, default=300)
    parser.add_argument("--tol", type=float, default=1e-4)
    parser.add_argument("--pairs", nargs="*", default=None, metavar="FROM:TO")
    parser.add_argument("--kernels", action="store_true", help="per-point cost of the kernels instead")
    parser.add_argument("--cli", default=None, metavar="FILE", help="time the command line on this built office instead")
    parser.add_argument("--cap", type=float, default=None, help="--cli: stop a query after this many seconds")
    parser.add_argument("--workers", type=int, default=None, help="default: one per core")
    parser.add_argument("--rounds", action="store_true",
                        help="log each refinement round of the three-level pair cubature on standard error")
    args = parser.parse_args(argv)
    pairs = [tuple(p.split(":")) for p in args.pairs] if args.pairs else [(a, b) for a in GROUPS for b in GROUPS if a != b]
    if args.cli:
        cli_queries(args.cli, pairs, args.tol, args.cap)
        return
    if args.rounds:
        ESTIMATES[0], ff.Cubature.estimates = ff.Cubature.estimates, logged_estimates
    scene = build_scene(office(args.polygons, seed=0))
    if args.kernels:
        print(json.dumps(kernel_costs(scene)), flush=True)
        return
    workers = default_workers(args.workers)
    EMITTER_ROW[0], ff.emitter_row = ff.emitter_row, timed_row  # group_to_group hands its workers this one
    MAP_CHUNKS[0], ff.map_chunks = ff.map_chunks, timed_chunks
    log = Path(tempfile.mkdtemp()) / "rows.jsonl"
    ROW_LOG[0] = str(log)
    for a, b in pairs:
        log.write_text("")
        PIECES.clear()
        c0, w0, s0 = cpu_seconds(), time.perf_counter(), time.process_time()
        r = group_to_group(scene, scene.group_faces(a), scene.group_faces(b), 1, args.tol, workers=args.workers)
        cpu, wall = cpu_seconds() - c0, time.perf_counter() - w0
        rows = [json.loads(line) for line in log.read_text().splitlines()]
        threaded = sum(PIECES)  # this process's pieces (a query of one row)
        serial = time.process_time() - s0 - threaded
        # the workers' tasks in the order _map_rows hands them out (the largest emitters first)
        area = scene.face_area
        tasks = [p["cpu"] for p in sorted(rows, key=lambda p: (-area[p["face"]], p["face"], -p["side"])) if p["pid"] != os.getpid()]
        print(json.dumps({"from": a, "to": b, "F": r["F"], "error": r["error"], "pairs": r["pairs"], "tol": args.tol,
                          "cpu": round(cpu, 2), "wall": round(wall, 2), "workers": workers, "serial_cpu": round(serial, 2),
                          "threaded_cpu": round(threaded, 2), "tasks": len(tasks),
                          "largest_task_cpu": round(max(tasks, default=0.0), 2),
                          "quiet_wall_estimate": round(serial + threaded / workers + makespan(tasks, workers), 2)}),
              flush=True)


if __name__ == "__main__":
    main()
