"""Form factors side by side: viscx, Radiance and pyviewfactor against a Monte Carlo reference
(reports, never asserts).

Scenes: the Cornell box's matrix (every pair of face sides) and group-to-group queries in a
~300-polygon office (benchmarks/buildings.py). Each method's CPU seconds and its error
against an independent Monte Carlo (tests/oracles.py ``form_factor_monte_carlo``: cosine-
weighted embree rays from area-uniform points, first hits counted per face side), whose
standard error σ = √(F (1 − F) / N) per entry (F at least 1/N) is stated, so an error is
also given in σ of the reference.

- viscx: the ``viscx formfactor`` command (``--matrix -o F.npz``; ``--from-group A
  --to-group B``), CPU of the process (user + sys).
- Radiance (``rfluxmtx``, from the ``pyradiance`` wheel, its bundled binaries): the sender
  is the emitting side (rays leave a sender polygon against its normal, so it is written
  reversed), every receiver a ``glow`` polygon counted on its front only, once per
  orientation (two runs: front and back sides), ``-ab 0``; other faces black. N rays per
  emitting side (matrix) or per emitting group, ``-c N``.
- pyviewfactor: the exact unoccluded factor per pair of polygons (its contour integral),
  times all-or-nothing visibility from one centroid-to-centroid ray against the scene
  (``get_obstruction``); exact only for unoccluded pairs.

Radiance and pyviewfactor run in a SIDE environment (never viscx dependencies), given by
``--side PYTHON`` (default ``/work/side-ffbench/bin/python`` if it exists); without one,
or when a peer does not import there, that peer is skipped with a message:

    python3 -m venv /work/side-ffbench && /work/side-ffbench/bin/pip install pyradiance pyviewfactor
    python benchmarks/formfactor_peers.py --side /work/side-ffbench/bin/python

Writes ``benchmarks/formfactor_results.json`` and ``benchmarks/formfactor_results.md``.
"""

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests"))

DEFAULT_SIDE = Path("/work/side-ffbench/bin/python")
#: Group pairs of the office: (from group, to group), from the front sides of the first.
OFFICE_PAIRS = [("floor", "light1"), ("wall_west", "wall_east"), ("desk0", "light1")]

# --------------------------------------------------------------------------------------
# the side process: reads a job (JSON) and prints results (JSON); runs with the side Python

SIDE = r'''
import json, os, resource, subprocess, sys, tempfile, time
import numpy as np

job = json.load(open(sys.argv[1]))
polys = [np.asarray(p, dtype=float) for p in job["polygons"]]  # outer loops, counter-clockwise about the normal
normals = np.asarray(job["normals"], dtype=float)


def cpu_children():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def cpu_self():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def rad_polygon(mod, name, loop):
    return f"{mod} polygon {name} 0 0 {3 * len(loop)} " + " ".join(f"{v:.9g}" for v in loop.ravel()) + "\n"


def area_of(loop):
    return 0.5 * np.linalg.norm(np.cross(loop[1:-1] - loop[0], loop[2:] - loop[0]).sum(axis=0))


def radiance_face(e, side, recv, rays, tmp, env):
    """F (len(recv), 2) from side ``side`` of face ``e`` to the front/back of ``recv``, by
    ``rays`` rays. Face e is left out of the scene: a planar face hides nothing from
    itself, and rays would meet their own start."""
    sender = "#@rfluxmtx h=u u=0.267,0.534,0.802\n" + rad_polygon("void", "s", polys[e] if side < 0 else polys[e][::-1])
    open(os.path.join(tmp, "sender.rad"), "w").write(sender)
    live = [j for j in recv if j != e]
    others = [f for f in range(len(polys)) if f not in set(recv) | {e}]
    system = "void plastic black 0 0 5 0 0 0 0 0\n" + "".join(rad_polygon("black", f"b{f}", polys[f]) for f in others)
    open(os.path.join(tmp, "system.rad"), "w").write(system)
    out = np.zeros((len(polys), 2))
    for k, t in enumerate((1, -1)):
        text = "".join(f"#@rfluxmtx h=u u=Y\nvoid glow g{j} 0 0 4 1 1 1 0\n" + rad_polygon(f"g{j}", f"r{j}", polys[j] if t > 0 else polys[j][::-1])
                       for j in live)
        open(os.path.join(tmp, "receivers.rad"), "w").write(text)
        res = subprocess.run(["rfluxmtx", "-c", str(rays), "-ab", "0", "-h", "-fa", "sender.rad", "receivers.rad", "system.rad"],
                             cwd=tmp, env=env, capture_output=True, text=True)
        if res.returncode:
            raise RuntimeError(res.stderr[-500:])
        out[live, k] = np.array(res.stdout.split(), dtype=float)[0::3]
    return out[list(recv)]


def radiance(emit, side, recv, rays, tmp):
    """F (len(recv), 2) from side ``side`` of faces ``emit`` (area-weighted, ``rays`` rays
    per face) to the front/back of ``recv``."""
    import pyradiance
    binpath = os.path.join(os.path.dirname(pyradiance.__file__), "bin")
    env = dict(os.environ, PATH=binpath + os.pathsep + os.environ["PATH"],
               RAYPATH="." + os.pathsep + os.path.join(os.path.dirname(pyradiance.__file__), "lib"))
    area = np.array([area_of(polys[e]) for e in emit])
    return sum(a * radiance_face(e, side, recv, rays, tmp, env) for a, e in zip(area, emit)) / area.sum()


def pyviewfactor_F(emit, side, recv, pre):
    """F (len(recv), 2) by pyviewfactor, area-weighted over ``emit``; and the count of facing
    polygon pairs it called obstructed."""
    import pyvista as pv
    import pyviewfactor as pvf

    def cell(loop):
        return pv.PolyData(loop, faces=[len(loop), *range(len(loop))])

    area = np.array([area_of(p) for p in polys])
    out = np.zeros((len(recv), 2))
    blocked = 0
    for e in emit:
        ce = cell(polys[e] if side > 0 else polys[e][::-1])
        for k, j in enumerate(recv):
            if j == e:
                continue
            for m, t in enumerate((1, -1)):
                cr = cell(polys[j] if t > 0 else polys[j][::-1])
                if not pvf.get_visibility(cr, ce)[0]:
                    continue
                free = pvf.get_obstruction(cr, ce, pre)[0]
                if free:
                    out[k, m] += area[e] * pvf.compute_viewfactor(cr, ce)
                else:
                    blocked += 1
    return out / area[emit].sum(), blocked


results = []
peers = job["peers"]
pre = None
if "pyviewfactor" in peers:
    import pyvista as pv
    import pyviewfactor as pvf
    sizes = [len(p) for p in polys]
    faces = np.concatenate([[len(p), *range(o, o + len(p))] for p, o in zip(polys, np.cumsum([0] + sizes[:-1]))])
    pre = pvf.FaceMeshPreprocessor(pv.PolyData(np.concatenate(polys), faces=faces).triangulate())
with tempfile.TemporaryDirectory() as tmp:
    for q in job["queries"]:
        if "radiance" in peers:
            for rays in job["rays"]:
                c0 = cpu_children()
                F = radiance(q["emit"], q["side"], q["recv"], rays, tmp)
                results.append({"query": q["id"], "method": "radiance", "rays": rays, "cpu": cpu_children() - c0, "F": F.tolist()})
        if "pyviewfactor" in peers:
            c0 = cpu_self()
            F, blocked = pyviewfactor_F(q["emit"], q["side"], q["recv"], pre)
            results.append({"query": q["id"], "method": "pyviewfactor", "cpu": cpu_self() - c0, "F": F.tolist(), "blocked": blocked})
        print(json.dumps({"progress": q["id"]}), file=sys.stderr, flush=True)
print(json.dumps(results))
'''


def side_peers(python):
    """The peers that import in the side Python (a list, maybe empty), with a message for
    each one skipped."""
    if python is None or not Path(python).exists():
        print(f"side environment {python or '(none)'} not found: Radiance and pyviewfactor skipped "
              "(python3 -m venv /work/side-ffbench && /work/side-ffbench/bin/pip install pyradiance pyviewfactor)")
        return []
    found = []
    for peer, module in (("radiance", "pyradiance"), ("pyviewfactor", "pyviewfactor")):
        ok = subprocess.run([str(python), "-c", f"import {module}"], capture_output=True).returncode == 0
        if ok:
            found.append(peer)
        else:
            print(f"{module} does not import in {python}: {peer} skipped")
    return found


def run_side(python, peers, scene, queries, rays, workdir):
    """Radiance and pyviewfactor on ``queries`` (dicts id, emit, side, recv) in the side Python."""
    loops = [scene.face_loops(f)[0].tolist() for f in range(scene.n_faces)]
    job = {"polygons": loops, "normals": scene.face_normal.tolist(), "queries": queries, "rays": rays, "peers": peers}
    path = Path(workdir) / "side_job.json"
    path.write_text(json.dumps(job))
    script = Path(workdir) / "side.py"
    script.write_text(SIDE)
    out = subprocess.run([str(python), str(script), str(path)], capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"side process failed: {out.stderr[-2000:]}")
    return json.loads(out.stdout)


# --------------------------------------------------------------------------------------
# viscx and the reference


def viscx_cli(*args):
    """Run ``viscx -q ARGS``: (stdout, CPU seconds of the process)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run([sys.executable, "-m", "viscx", "-q", *map(str, args)], check=True, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return out.stdout, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def sigma_of(F, n):
    """Binomial standard error of Monte Carlo estimates F of n rays (F at least 1/n, so an
    entry the reference never hit still has a scale)."""
    F = np.asarray(F, dtype=float)
    return np.sqrt(np.maximum(F, 1.0 / n) * (1 - np.minimum(F, 1 - 1.0 / n)) / n)


def errors(value, ref, sigma):
    """Mean and max |value − ref|, and in σ, over the entries where either is non-zero."""
    value, ref, sigma = (np.asarray(a, dtype=float).ravel() for a in (value, ref, sigma))
    on = (value != 0) | (ref != 0)
    d = np.abs(value - ref)[on]
    z = d / sigma[on]
    return {"entries": int(on.sum()), "mean_abs": float(d.mean()), "max_abs": float(d.max()),
            "mean_sigma": float(z.mean()), "max_sigma": float(z.max())}


def cornell(args, side_python, peers, work):
    """The matrix: viscx ``--matrix``, the reference row of every side, the peers per side."""
    from oracles import form_factor_monte_carlo

    from viscx.scene import load_scene

    obj = ROOT / "sample_scenes" / "cornell_box.obj"
    scene = load_scene(obj)
    n = scene.n_faces
    h5 = work / "cornell_box.h5"
    if not h5.exists():
        viscx_cli("build", obj, "-o", h5)
    rows = []
    cache = work / f"cornell_reference_{args.mc_matrix}.npz"  # reused by a rerun in the same --work
    if cache.exists():
        ref, mc_cpu = np.load(cache)["ref"], float(np.load(cache)["cpu"])
    else:
        t0 = time.process_time()
        ref = np.array([form_factor_monte_carlo(scene, [e // 2], 1 - 2 * (e % 2), args.mc_matrix, seed=e)[0]
                        for e in range(2 * n)])[:, :2 * n]  # (2n, 2n) side to side (the sky left out)
        mc_cpu = time.process_time() - t0
        np.savez(cache, ref=ref, cpu=mc_cpu)
    sigma = sigma_of(ref, args.mc_matrix)
    rows.append({"scene": "Cornell box", "query": f"matrix, {2 * n} x {2 * n} sides", "method": "Monte Carlo reference",
                 "settings": f"{args.mc_matrix:.0e} rays per side", "cpu": mc_cpu,
                 "note": f"σ up to {sigma.max():.1e} (mean {sigma[ref > 0].mean():.1e} over the {int((ref > 0).sum())} entries hit)"})
    for tol in args.matrix_tol:
        out, cpu = viscx_cli("formfactor", h5, "--matrix", "--tol", tol, "-o", work / "cornell_F.npz")
        summary = json.loads(out)
        m = np.load(work / "cornell_F.npz")
        F = np.zeros((2 * n, 2 * n))
        for r in range(2 * n):
            F[r, m["indices"][m["indptr"][r]:m["indptr"][r + 1]]] = m["data"][m["indptr"][r]:m["indptr"][r + 1]]
        rows.append({"scene": "Cornell box", "query": f"matrix, {2 * n} x {2 * n} sides", "method": "viscx",
                     "settings": f"--matrix --tol {tol:g}", "cpu": cpu, **errors(F, ref, sigma),
                     "note": f"reciprocity {summary['reciprocity_max_error']:.1e}, rows ±{summary['row_sum_max_deviation']:.1e}, "
                             f"largest estimate {summary['max_error_estimate']:.1e}"})
    if peers:
        queries = [{"id": e, "emit": [e // 2], "side": 1 - 2 * (e % 2), "recv": list(range(n))} for e in range(2 * n)]
        got = run_side(side_python, peers, scene, queries, args.rays, work)
        for method, rays in [("radiance", r) for r in args.rays] + [("pyviewfactor", None)]:
            mine = [g for g in got if g["method"] == method and g.get("rays") == rays]
            if not mine:
                continue
            F = np.zeros((2 * n, 2 * n))
            for g in mine:
                F[g["query"]] = np.asarray(g["F"]).ravel()  # (n, 2) -> 2 j + (back)
            cpu = sum(g["cpu"] for g in mine)
            note = ""
            if method == "pyviewfactor":
                note = f"{sum(g['blocked'] for g in mine)} facing polygon pairs called blocked (centroid ray), counted 0"
            rows.append({"scene": "Cornell box", "query": f"matrix, {2 * n} x {2 * n} sides",
                         "method": "Radiance rfluxmtx" if method == "radiance" else "pyviewfactor",
                         "settings": f"-c {rays:.0e} per side, -ab 0" if rays else "exact unoccluded × centroid ray",
                         "cpu": cpu, **errors(F, ref, sigma), "note": note})
    return rows


def office_rows(args, side_python, peers, work):
    """Group-to-group queries in the office, each against its own reference."""
    from buildings import office, write_obj
    from oracles import form_factor_monte_carlo

    from viscx.scene import load_scene

    obj = write_obj(office(args.office, seed=0), work / f"office{args.office}.obj")
    scene = load_scene(obj)
    h5 = work / f"office{args.office}.h5"
    if not h5.exists():
        viscx_cli("build", obj, "-o", h5)
    name = f"office, {scene.n_faces} polygons"
    rows, queries = [], []
    refs = []
    for k, (a, b) in enumerate(OFFICE_PAIRS):
        emit, recv = [int(f) for f in scene.group_faces(a)], [int(f) for f in scene.group_faces(b)]
        t0 = time.process_time()
        est, _ = form_factor_monte_carlo(scene, emit, 1, args.mc_pairs, seed=100 + k)
        ref = float(sum(est[2 * j] + est[2 * j + 1] for j in recv))
        sigma = float(sigma_of(ref, args.mc_pairs))
        refs.append((ref, sigma))
        q = f"{a} → {b}"
        rows.append({"scene": name, "query": q, "method": "Monte Carlo reference", "settings": f"{args.mc_pairs:.0e} rays",
                     "cpu": time.process_time() - t0, "F": ref, "note": f"σ = {sigma:.1e}"})
        out, cpu = viscx_cli("formfactor", h5, "--from-group", a, "--to-group", b, "--tol", args.tol)
        r = json.loads(out)
        rows.append({"scene": name, "query": q, "method": "viscx", "settings": f"--tol {args.tol:g}", "cpu": cpu,
                     "F": r["F"], **errors(r["F"], ref, sigma), "note": f"estimate {r['error']:.1e}"})
        queries.append({"id": k, "emit": emit, "side": 1, "recv": recv})
    if peers:
        got = run_side(side_python, peers, scene, queries, args.rays, work)
        for g in got:
            k = g["query"]
            ref, sigma = refs[k]
            F = float(np.sum(g["F"]))
            a, b = OFFICE_PAIRS[k]
            note = ""
            if g["method"] == "pyviewfactor":
                note = f"{g['blocked']} facing polygon pairs called blocked (centroid ray)"
            rows.append({"scene": name, "query": f"{a} → {b}",
                         "method": "Radiance rfluxmtx" if g["method"] == "radiance" else "pyviewfactor",
                         "settings": f"-c {g['rays']:.0e}, -ab 0" if g["method"] == "radiance" else "exact unoccluded × centroid ray",
                         "cpu": g["cpu"], "F": F, **errors(F, ref, sigma), "note": note})
    order = {"Monte Carlo reference": 0, "viscx": 1, "Radiance rfluxmtx": 2, "pyviewfactor": 3}
    return sorted(rows, key=lambda r: (r["query"], order[r["method"]]))


def markdown(rows, machine):
    lines = [f"Machine: {machine}", "",
             "CPU s: user + sys of the method (its child processes included). Errors against the Monte Carlo "
             "reference of the same query, over the entries where either is non-zero; in σ: |Δ| / σ of the "
             "reference entry (σ = √(F (1 − F) / N), F at least 1/N).", "",
             "| scene | query | method | settings | CPU s | F | mean \\|Δ\\| | max \\|Δ\\| | mean \\|Δ\\|/σ | max \\|Δ\\|/σ | note |",
             "|---|---|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        f = lambda k, fmt: format(r[k], fmt) if k in r else ""  # noqa: E731
        lines.append(f"| {r['scene']} | {r['query']} | {r['method']} | {r['settings']} | {r['cpu']:.3g} | {f('F', '.6f')} | "
                     f"{f('mean_abs', '.1e')} | {f('max_abs', '.1e')} | {f('mean_sigma', '.2f')} | {f('max_sigma', '.2f')} | "
                     f"{r.get('note', '')} |")
    return "\n".join(lines)


def main(argv=None):
    """Run, print and write the table; returns its rows."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--side", default=str(DEFAULT_SIDE) if DEFAULT_SIDE.exists() else None,
                        help="Python of the side environment with pyradiance and pyviewfactor")
    parser.add_argument("--mc-matrix", type=int, default=4_000_000, help="reference rays per side (Cornell matrix)")
    parser.add_argument("--mc-pairs", type=int, default=10_000_000, help="reference rays per group query (office)")
    parser.add_argument("--rays", type=int, nargs="+", default=[100_000, 1_000_000], help="Radiance rays (-c)")
    parser.add_argument("--matrix-tol", type=float, nargs="*", default=[1e-6, 1e-4],
                        help="viscx --tol of the Cornell --matrix runs (none: the matrix is not run)")
    parser.add_argument("--tol", type=float, default=1e-4, help="viscx --tol of the office queries")
    parser.add_argument("--office", type=int, default=300, help="office size, polygons")
    parser.add_argument("--skip", nargs="*", default=[], choices=["cornell", "office"])
    parser.add_argument("--work", default=None, help="folder for the scenes and files (default: a temporary one)")
    parser.add_argument("--out", default=str(HERE), help="folder for formfactor_results.json and .md")
    args = parser.parse_args(argv)
    peers = side_peers(args.side or None)
    machine = (f"{platform.machine()}, {platform.python_implementation()} {platform.python_version()}, "
               f"{len(os.sched_getaffinity(0))} cores, shared with other jobs")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.work or tmp)
        work.mkdir(parents=True, exist_ok=True)
        rows = []
        if "cornell" not in args.skip:
            rows += cornell(args, args.side, peers, work)
        if "office" not in args.skip:
            rows += office_rows(args, args.side, peers, work)
    table = markdown(rows, machine)
    print(table)
    out = Path(args.out)
    (out / "formfactor_results.json").write_text(json.dumps({"machine": machine, "peers": peers, "rows": rows}, indent=2))
    (out / "formfactor_results.md").write_text(table + "\n")
    return rows


if __name__ == "__main__":
    main()
