"""V0 (nodes), V1 (arcs) and V2 (V-cells, EE-cells) benchmark ladder: the skeleton builders on growing scenes.

    python benchmarks/skeleton.py                       # Cornell box, boxes 100 … 3000
    python benchmarks/skeleton.py --sizes 100 300       # a shorter ladder
    python benchmarks/skeleton.py --budget 600          # skip sizes predicted to exceed 600 s

For each scene: V0 wall time (candidates + validation), candidate and node counts
per kind, the time of each V0 stage, V1 wall time and arc counts per kind, V2
wall time (V-cells, EE-cells) and cell counts; then the growth exponents of time against polygons and against nodes (least squares
on log-log). Prints a table and writes
``benchmarks/skeleton_results.json``. A size whose predicted time (from the
exponent fitted so far) exceeds ``--budget`` seconds is recorded as skipped. Each city
is built in a child process whose data segment is limited to the machine's memory less
2 GB: a size that runs out of memory is recorded as such (with the stage it reached) and
the ladder goes on.
"""

import argparse
import json
import multiprocessing
import os
import platform
import resource
import sys
import time
from pathlib import Path

# as `viscx build` runs (viscx/cli): one BLAS thread, idle OpenMP threads asleep (set before
# numpy loads; spawned children inherit them): their spinning is not the builders' CPU time
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from scenes import random_boxes  # noqa: E402

from viscx.scene import load_scene  # noqa: E402
from viscx.skeleton.candidates import fast_candidates, validate_in_chunks  # noqa: E402
from viscx.skeleton.arcs import build_arcs  # noqa: E402
from viscx.skeleton.nodes import E4, VEE, VV  # noqa: E402
from viscx.skeleton.eecells import build_eecells  # noqa: E402
from viscx.skeleton.vcells import build_vcells  # noqa: E402

KINDS = {"E4": E4, "VEE": VEE, "VV": VV}


def peak_mb():
    """This process's peak resident memory (MB): Linux's VmHWM, which a spawned child
    starts afresh (its ru_maxrss starts at the parent's resident size at the fork)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_skeleton(scene, name, stage=None):
    """Build V0 once, timing candidates and validation separately, then V1 and V2 (V-cells,
    EE-cells). ``stage`` (a one-item list), if given, holds the name of the stage running."""
    stage = [None] if stage is None else stage
    stats = {}
    cpu, peaks = [time.process_time()], []  # CPU seconds (all threads) and peak MB after each level

    def level_done():
        cpu.append(time.process_time())
        peaks.append(peak_mb())

    t0 = time.perf_counter()
    stage[0] = "V0 candidates"
    kind, gens, origins, dirs = fast_candidates(scene, stats=stats)
    t1 = time.perf_counter()
    stage[0] = "V0 validation"
    nodes = validate_in_chunks(scene, kind, gens, origins, dirs)
    t2 = time.perf_counter()
    level_done()
    stage[0] = "V1 arcs"
    arcs = build_arcs(scene, nodes)
    t3 = time.perf_counter()
    level_done()
    stage[0] = "V2 V-cells"
    vcells = build_vcells(scene, arcs)
    t4 = time.perf_counter()
    stage[0] = "V2 EE-cells"
    eecells = build_eecells(scene, arcs)
    t5 = time.perf_counter()
    level_done()
    row = {
        "scene": name,
        "polygons": int(scene.n_faces),
        "generator_edges": int(len(scene.generator_edges)),
        "generator_vertices": int(len(scene.generator_vertices)),
        "seconds": t5 - t0,
        "seconds_v0": t2 - t0,
        "seconds_candidates": t1 - t0,
        "seconds_validation": t2 - t1,
        "seconds_v1": t3 - t2,
        "seconds_v2": t5 - t3,
        "seconds_vcells": t4 - t3,
        "seconds_eecells": t5 - t4,
        "vcells": vcells.counts(),
        "eecells": eecells.counts(),
        "arcs": arcs.counts(),
        "candidates": {k: int(np.count_nonzero(kind == v)) for k, v in KINDS.items()},
        "nodes": nodes.counts(),
        "stages": {k: (round(v, 3) if isinstance(v, float) else v) for k, v in stats.items()},
        "peak_mb": peak_mb(),
        "cpu_v0": cpu[1] - cpu[0],
        "cpu_v1": cpu[2] - cpu[1],
        "cpu_v2": cpu[3] - cpu[2],
        "peak_mb_v0": peaks[0],
        "peak_mb_v1": peaks[1],
        "peak_mb_v2": peaks[2],
    }
    row["candidates_total"] = int(len(kind))
    row["nodes_total"] = int(len(nodes))
    return row


def _skeleton_child(size, conn):
    """Child process of :func:`run_isolated`: one city's row, or how it ran out of memory."""
    limit = int((machine_memory_gb() - 2.0) * 1024**3)
    resource.setrlimit(resource.RLIMIT_DATA, (limit, limit))  # MemoryError, not the OOM killer
    stage = [None]
    name = f"random_boxes({size})"
    scene = random_boxes(size, seed=0)
    try:
        conn.send(run_skeleton(scene, name, stage))
    except MemoryError:
        conn.send({"scene": name, "skipped": f"out of memory in {stage[0]} (> {limit / 1024**3:.1f} GB)",
                   "peak_mb": peak_mb()})


def run_isolated(size):
    """:func:`run_skeleton` on random_boxes(size) in a child process (spawned: forking
    after OpenMP has run is unsafe; the numba kernels load from their cache), its data
    segment limited to the machine's memory less 2 GB, so that a size that does not fit
    is reported and the ladder goes on."""
    spawn = multiprocessing.get_context("spawn")
    parent, child = spawn.Pipe(duplex=False)
    proc = spawn.Process(target=_skeleton_child, args=(size, child))
    proc.start()
    child.close()
    try:
        row = parent.recv()
    except EOFError:  # the child died without a word
        row = None
    proc.join()
    if row is None:
        row = {"scene": f"random_boxes({size})", "skipped": f"the build died (exit code {proc.exitcode})"}
    return row


def machine_memory_gb():
    """The machine's physical memory (GB)."""
    return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 1024**3


def fit_exponent(x, y):
    """Slope of log y against log x (least squares), None with fewer than two points."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = (x > 0) & (y > 0)
    if ok.sum() < 2:
        return None
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0])


def table(rows):
    head = (
        f"{'scene':<22}{'polys':>7}{'V0 s':>9}{'cand s':>9}{'valid s':>9}{'V1 s':>9}{'V2 s':>8}"
        f"{'cand VV/VEE/E4':>26}{'nodes VV/VEE/E4':>24}{'arcs EEE/VE':>16}{'V-cells':>9}{'complete':>11}{'EE-cells':>10}{'complete pairs':>16}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        if r.get("skipped"):
            lines.append(f"{r['scene']:<22}{r['polygons']:>7}   skipped: {r['skipped']}")
            continue
        c, n, a, v, ee = r["candidates"], r["nodes"], r["arcs"], r["vcells"], r["eecells"]
        lines.append(
            f"{r['scene']:<22}{r['polygons']:>7}{r['seconds_v0']:>9.2f}{r['seconds_candidates']:>9.2f}"
            f"{r['seconds_validation']:>9.2f}{r['seconds_v1']:>9.2f}{r['seconds_v2']:>8.2f}"
            f"{c['VV']:>9}/{c['VEE']:>8}/{c['E4']:>7}{n['VV']:>8}/{n['VEE']:>7}/{n['E4']:>7}{a['EEE']:>9}/{a['VE']:>6}"
            f"{v['cells']:>9}{v['complete_vertices']:>6}/{v['vertices']:<5}"
            f"{ee['cells']:>10}{ee['complete_pairs']:>9}/{ee['pairs']:<6}"
        )
    return "\n".join(lines)


def run_ladder(sizes, budget, report=print):
    """The Cornell box, then random boxes cities of the given sizes (a size predicted
    to take longer than ``budget`` seconds, or more than the machine's memory, is
    recorded as skipped: both extrapolated from the sizes measured so far).

    Returns
    -------
    rows : list of dict
        One per scene (:func:`run_skeleton`; skipped sizes carry "skipped").
    growth : dict
        Fitted growth exponents over the measured cities.
    """
    fast_candidates(random_boxes(20, seed=1))  # compile the numba kernels outside the timings
    rows = [run_skeleton(load_scene(ROOT / "sample_scenes" / "cornell_box.obj"), "cornell_box")]
    report(table(rows[-1:]))
    ladder = []
    for size in sizes:
        scene = random_boxes(size, seed=0)
        name = f"random_boxes({size})"
        if len(ladder) >= 2:
            polys = [r["polygons"] for r in ladder]
            ratio = scene.n_faces / ladder[-1]["polygons"]
            predicted = ladder[-1]["seconds"] * ratio ** fit_exponent(polys, [r["seconds"] for r in ladder])
            # memory by the last two sizes: a fixed base (the interpreter, numba) flattens the small ones
            memory = ladder[-1]["peak_mb"] * ratio ** fit_exponent(polys[-2:], [r["peak_mb"] for r in ladder[-2:]]) / 1024
            skip = []
            if predicted > budget:
                skip.append(f"predicted {predicted:.0f} s > budget {budget:.0f} s")
            if memory > machine_memory_gb():
                skip.append(f"predicted peak {memory:.0f} GB > {machine_memory_gb():.0f} GB of memory")
            if skip:
                rows.append({"scene": name, "polygons": int(scene.n_faces), "skipped": "; ".join(skip)})
                report(table(rows[-1:]))
                continue
        polygons = int(scene.n_faces)
        del scene  # the child builds its own
        rows.append(run_isolated(size))
        rows[-1]["polygons"] = polygons
        report(table(rows[-1:]))
        if not rows[-1].get("skipped"):
            ladder.append(rows[-1])

    polys = [r["polygons"] for r in ladder]
    secs = [r["seconds"] for r in ladder]
    nodes = [r["nodes_total"] for r in ladder]
    growth = {
        "time_vs_polygons": fit_exponent(polys, secs),
        "v0_time_vs_polygons": fit_exponent(polys, [r["seconds_v0"] for r in ladder]),
        "v1_time_vs_polygons": fit_exponent(polys, [r["seconds_v1"] for r in ladder]),
        "v2_time_vs_polygons": fit_exponent(polys, [r["seconds_v2"] for r in ladder]),
        "time_vs_nodes": fit_exponent(nodes, secs),
        "nodes_vs_polygons": fit_exponent(polys, nodes),
        "candidates_vs_polygons": fit_exponent(polys, [r["candidates_total"] for r in ladder]),
    }
    return rows, growth


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[100, 300, 1000, 3000])
    parser.add_argument("--budget", type=float, default=1800.0, help="skip sizes predicted to take longer (s)")
    parser.add_argument("--out", default=str(HERE / "skeleton_results.json"))
    args = parser.parse_args(argv)
    rows, growth = run_ladder(args.sizes, args.budget, report=lambda text: print(text, flush=True))
    print()
    print(table(rows))
    print()
    for k, v in growth.items():
        print(f"growth exponent {k}: {'n/a' if v is None else f'{v:.2f}'}")
    result = {
        "machine": {"platform": platform.platform(), "python": platform.python_version(), "cpus": os.cpu_count()},
        "rows": rows,
        "growth": growth,
    }
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
