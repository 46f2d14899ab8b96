"""Flatland benchmark: build time and complex size for random circle scenes and for
uniform PV arrays (degenerate: every panel tip on one line), and the dynamic updates (one
object moved, removed, inserted; in memory and on a complex read from its file) against a
rebuild from scratch.

    python benchmarks/flatland.py            # 10, 100, 300, 1000 circles; 10, 100, 1000 rows
    python benchmarks/flatland.py 10 100     # chosen sizes (circles and rows)
    python benchmarks/flatland.py --updates 1000   # move / remove / insert only
    python benchmarks/flatland.py --pvfactors /work/side-flatland/bin/python 3 10 30 100 300

``--pvfactors PYTHON``: a side-by-side with pvfactors (solarfactors), installed in a SIDE
environment (never a viscx dependency) whose interpreter is PYTHON, run there as a
subprocess: its view-factor matrix of an ordered PV array against viscx's form factors of
the same geometry (panels as segments, its ground as a segment from x = −100 to 100).

CPU times (user + sys of this process, ``time.process_time``: the machine is shared), best
of a few runs for the small sizes, medians of 7 moves; no assertions.  The first call
compiles/loads the numba kernels and is excluded (a warm-up build runs first).
"""

import json
import subprocess
import sys
import time

import numpy as np

from viscx.flatland.complex import build, candidates, classify, default_eps
from viscx.flatland.dynamic import move
from viscx.flatland.scene import make_scene


def random_circles(n, seed=0, density=4.0):
    """n disjoint circles, radii in [0.3, 1], in a square of side 4·√n (about 10 % covered)."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(n) * density
    centres, radii = np.zeros((0, 2)), np.zeros(0)
    while len(radii) < n:
        c = rng.uniform(0, side, 2)
        r = rng.uniform(0.3, 1.0)
        if len(radii) == 0 or np.all(np.hypot(*(centres - c).T) > radii + r + 0.05):
            centres = np.vstack([centres, c])
            radii = np.append(radii, r)
    return make_scene([{"type": "circle", "center": c.tolist(), "radius": float(r)} for c, r in zip(centres, radii)])


def panel_rows(n, pitch=3.0, width=2.0, tilt=25.0, height=1.0):
    """n identical panels (segments) tilted by ``tilt`` degrees at a constant pitch above a
    ground block: the layout of a PV plant, degenerate (all tips on one line)."""
    c, s = np.cos(np.radians(tilt)), np.sin(np.radians(tilt))
    objs = [{"type": "segment", "points": [[i * pitch, height], [i * pitch + width * c, height + width * s]]}
            for i in range(n)]
    objs.append({"type": "polygon", "points": [[-5, -1], [n * pitch + 5, -1], [n * pitch + 5, 0], [-5, 0]]})
    return make_scene(objs)


def timed(f, repeat=1):
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.process_time()
        out = f()
        best = min(best, time.process_time() - t)
    return best, out


def measure(sizes, make=None, step=0.5, moves=7):
    """One row per size: (n, vertices, edges, faces, build s, candidates s, freeness s,
    median move s, median rebuild s, (mean form factors recomputed, mean total), zone, split).

    ``moves`` random moves of one object from the built complex (timed only: the tests
    check equality with a rebuild); zone: medians of vertices out / in, edges
    and face slots re-derived, and how many moves were local (not rebuilt); split: the
    median CPU seconds of the move's stages (candidates, vertices, topology)."""
    make = make or (lambda n: random_circles(n, seed=n))
    build(random_circles(5))  # warm-up: numba cache
    move(build(random_circles(5)), 0, 0.01, 0.0)
    rows = []
    for n in sizes:
        scene = make(n)
        rep = 3 if n <= 300 else 1
        t_build, cx = timed(lambda: build(scene), rep)
        # stage split of the build
        eps = default_eps(scene)
        t_cand, cand = timed(lambda: candidates(scene))
        t_cls, cls = timed(lambda: classify(scene, cand, eps))
        rng = np.random.default_rng(1)
        t_moves, t_rebuilds, recomputed, zone, split = [], [], [], [], []
        for _ in range(moves):
            while True:
                k = int(rng.integers(n))
                dx, dy = rng.uniform(-step, step, 2)
                try:
                    t_m, (moved, stats) = timed(lambda: move(cx, k, dx, dy))
                    break
                except Exception:
                    continue
            t_r, _ = timed(lambda: build(moved.scene, eps=cx.eps))
            t_moves.append(t_m)
            t_rebuilds.append(t_r)
            recomputed.append((stats.formfactors_recomputed, stats.formfactors_total))
            zone.append((stats.zone_vertices_removed, stats.zone_vertices_added, stats.zone_edges, stats.zone_slots,
                         stats.local))
            split.append([stats.seconds.get(s_, np.nan) for s_ in ("candidates", "vertices", "topology")])
        ff = np.mean([a for a, b in recomputed]), np.mean([b for a, b in recomputed])
        z = np.array(zone, float)
        rows.append((n, cx.n_vertices, cx.n_edges, cx.n_faces, t_build, t_cand, t_cls, np.median(t_moves),
                     np.median(t_rebuilds), ff, (*np.median(z[:, :4], axis=0), int(z[:, 4].sum()), len(zone)),
                     np.median(np.array(split), axis=0)))
    return rows


def measure_updates(sizes, make=None, step=0.5, samples=5):
    """Move, remove and insert against a rebuild, in memory and on a file: per size and
    operation, medians over ``samples`` random objects of the CPU seconds of the update
    of the built complex, of the same update of the complex read back from its file (the
    read itself, which the update group makes O(file) numpy, timed apart), and of a
    rebuild of the new scene; and how many updates were local.  A removal takes object k
    out; the insertion puts that same object back (appended) into the complex without it.

    Returns rows (n, op, memory s, file s, read s, rebuild s, local, samples)."""
    import tempfile
    from pathlib import Path

    from viscx.flatland.dynamic import insert, remove
    from viscx.formats.flatland import read_any, write_any

    make = make or (lambda n: random_circles(n, seed=n))
    build(random_circles(5))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            cx = build(make(n))
            src = Path(tmp) / f"c{n}.h5"
            write_any(src, cx)
            rng = np.random.default_rng(2)
            got = {op: [] for op in ("move", "remove", "insert")}
            for i in range(samples):
                k = int(rng.integers(n))
                dx, dy = rng.uniform(-step, step, 2)
                obj = cx.scene.to_json()["objects"][k]
                obj["name"] = "again"
                gone = remove(cx, k)[0]
                gone_file = Path(tmp) / f"g{n}_{i}.h5"
                write_any(gone_file, gone)
                for op, base, path, f in (("move", cx, src, lambda c: move(c, k, dx, dy)),
                                          ("remove", cx, src, lambda c: remove(c, k)),
                                          ("insert", gone, gone_file, lambda c: insert(c, obj))):
                    try:
                        t_mem, (new, stats) = timed(lambda: f(base))
                    except Exception:
                        continue
                    t_read, read = timed(lambda: read_any(path))
                    t_file, (new_f, stats_f) = timed(lambda: f(read))
                    t_rb, _ = timed(lambda: build(new.scene, eps=cx.eps))
                    got[op].append((t_mem, t_file, t_read, t_rb, stats.local and stats_f.local))
            for op, vals in got.items():
                v = np.array(vals, float)
                rows.append((n, op, *np.median(v[:, :4], axis=0), int(v[:, 4].sum()), len(vals)))
    return rows


def table_updates(rows):
    print(f"{'n':>5} {'op':>7} {'memory s':>9} {'ratio':>6} {'file s':>8} {'ratio':>6} {'(read s)':>9} "
          f"{'rebuild s':>9} {'local':>6}")
    for n, op, tm, tf, tr, tb, loc, cnt in rows:
        print(f"{n:>5} {op:>7} {tm:>9.3f} {tb / tm:>6.1f} {tf:>8.3f} {tb / tf:>6.1f} {tr:>9.3f} {tb:>9.3f} "
              f"{loc:>3}/{cnt:<2}")


def main(sizes):
    for title, make, ns in (("random circles", None, sizes or [10, 100, 300, 1000]),
                            ("uniform rows (segments) above a ground block", panel_rows, sizes or [10, 100, 1000])):
        print(title)
        table(measure(ns, make, step=0.5 if make is None else 0.2))
        print(title + ": move, remove, insert (medians), in memory and on a file")
        table_updates(measure_updates(ns, make, step=0.5 if make is None else 0.2))


def table(rows):
    head = (f"{'n':>5} {'vertices':>9} {'edges':>8} {'faces':>7} {'build s':>8} {'(cand s':>8} {'free s)':>8} "
            f"{'move s':>8} {'rebuild s':>9} {'ratio':>6} {'FF recomputed / total':>22} "
            f"{'zone: v out/in, edges, slots':>30} {'local':>6} {'move split s (cand/vert/topo)':>30}")
    print(head)
    for n, m, E, F, tb, tc, tf, tm, tr, (a, b), (vo, vi, ze, zs, loc, mv), sp in rows:
        print(f"{n:>5} {m:>9} {E:>8} {F:>7} {tb:>8.3f} {tc:>8.3f} {tf:>8.3f} {tm:>8.3f} {tr:>9.3f} {tr / tm:>6.1f} "
              f"{a:>10.1f} / {b:<10.1f} {vo:>7.0f} / {vi:<5.0f} {ze:>6.0f} {zs:>8.0f} {loc:>3}/{mv:<2} "
              f"{sp[0]:>9.3f} {sp[1]:>9.3f} {sp[2]:>9.3f}")


# pvfactors side: geometry, view-factor matrix timed, and per-row aggregates (both sides of
# each row together, weighted by length: the object form factors viscx computes)
_PVF = r"""
import json, sys, time
import numpy as np
from pvfactors.geometry import OrderedPVArray
from pvfactors.viewfactors import VFCalculator
n, width, height, tilt, gcr = json.loads(sys.argv[1])
params = dict(n_pvrows=n, pvrow_height=height, pvrow_width=width, axis_azimuth=0.0, surface_tilt=tilt,
              surface_azimuth=90.0, solar_zenith=30.0, solar_azimuth=90.0, gcr=gcr)
pv = OrderedPVArray.fit_from_dict_of_scalars(params)
t = time.process_time()
vf = VFCalculator().build_ts_vf_matrix(pv)[:, :, 0]
dt = time.process_time() - t
length = np.array([float(s.length[0]) for s in pv.all_ts_surfaces] + [0.0])
ground = [s.index for s in pv.ts_ground.all_ts_surfaces]
rows = [[s.index for s in r.front.all_ts_surfaces + r.back.all_ts_surfaces] for r in pv.ts_pvrows]
targets = rows + [ground, [vf.shape[0] - 1]]
F = np.zeros((n, n + 2))
for i, src in enumerate(rows):
    w = length[src] / length[src].sum()
    for j, dst in enumerate(targets):
        F[i, j] = float(w @ vf[np.ix_(src, dst)].sum(axis=1))
ends = [r.full_pvrow_coords.as_array[:, :, 0].tolist() for r in pv.ts_pvrows]
print(json.dumps({"seconds": dt, "F": F.tolist(), "ends": ends}))
"""


def pvfactors_side_by_side(python, sizes, width=2.0, height=1.5, tilt=25.0, gcr=0.4):
    """Rows: (n, pvfactors s, viscx s, max |ΔF| over rows → rows, ground, sky) or the
    error pvfactors stopped with.  CPU seconds of the view-factor step on each side."""
    out = []
    for n in sizes:
        r = subprocess.run(["prlimit", "--as=7000000000", python, "-c", _PVF, json.dumps([n, width, height, tilt, gcr])],
                           capture_output=True, text=True)
        if r.returncode != 0:
            out.append((n, r.stderr.strip().splitlines()[-1][:80] if r.stderr.strip() else f"exit {r.returncode}",
                        None, None))
            continue
        doc = json.loads(r.stdout)
        objs = [{"type": "segment", "points": e} for e in doc["ends"]]
        objs.append({"type": "segment", "points": [[-100.0, 0.0], [100.0, 0.0]], "name": "ground"})
        scene = make_scene(objs)
        t, cx = timed(lambda: build(scene))
        F = cx.F_area[:n]
        # pvfactors sees only the ground's top: lines leaving a row never reach its underside
        ours = np.concatenate([F[:, :n], F[:, n:n + 1], F[:, -1:]], axis=1)
        out.append((n, doc["seconds"], t, float(np.max(np.abs(ours - np.array(doc["F"]))))))
    return out


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--pvfactors":
        build(random_circles(5))
        print(f"{'rows':>5} {'pvfactors s':>12} {'viscx s':>8} {'max |dF|':>9}")
        for n, a, b, d in pvfactors_side_by_side(sys.argv[2], [int(x) for x in sys.argv[3:]] or [3, 10, 30, 100]):
            if b is None:
                print(f"{n:>5} {a}")
            else:
                print(f"{n:>5} {a:>12.3f} {b:>8.3f} {d:>9.2e}")
        sys.exit(0)
    if len(sys.argv) > 1 and sys.argv[1] == "--updates":
        for title, make in (("random circles", None), ("uniform rows (segments) above a ground block", panel_rows)):
            print(title + ": move, remove, insert (medians), in memory and on a file")
            table_updates(measure_updates([int(x) for x in sys.argv[2:]] or [1000], make,
                                          step=0.5 if make is None else 0.2))
        sys.exit(0)
    main([int(x) for x in sys.argv[1:]])
