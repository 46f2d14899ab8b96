"""The discontinuity mesh of an area light on a large scene file, checked by the brute-force
oracle of the tests (tests/discontinuity_oracle.py) on sampled points.

    python benchmarks/discontinuity_check.py spheres.obj --light-group light
    python benchmarks/discontinuity_check.py spheres.obj --light-group light --mesh /tmp/spheres_mesh.pkl

The mesh is built as ``viscx query discontinuities FILE --light-group NAME`` builds it
(scoped to the light, in this process: CPU seconds and peak memory reported), or read from
``--mesh`` if that file exists (written there otherwise), or from ``--output``, what that
command wrote (.msgpack or .json). Checked: every receiver that is
not in a group named like ``sphere*``/``bunny`` (room faces: floor, walls, ceiling) and
``--faces`` receivers drawn at random among the others that hold traces; on each, at most
``--max-regions`` regions (4 points each, the same labels within a region) and
``--max-traces`` traces (a point on each side, different labels), as the tests' check
(:func:`check_mesh`) does, the oracle's occluders culled to the points' shafts to the light.
Prints one JSON object.
"""

import argparse
import json
import os
import pickle
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from discontinuity_oracle import check_mesh  # noqa: E402
from skeleton import peak_mb  # noqa: E402

from viscx.pipeline import scene_of  # noqa: E402
from viscx.queries.discontinuities import ReceiverMesh, Region, _face_frame, open_discontinuities  # noqa: E402
from viscx.scene.light import light_of  # noqa: E402

#: Margin (of the diagonal) between judged points and mesh lines, as in the tests.
MARGIN = 1e-4


def mesh_of_output(scene, data, light_group):
    """A DiscontinuityMesh-like object (what :func:`check_mesh` reads) from the query's
    output (the dict of :func:`viscx.queries.discontinuities.mesh_result`): 3-D points
    back in each receiver's frame."""
    from types import SimpleNamespace

    points, offsets = [[] for _ in range(data["events"])], None
    receivers = []
    for f in data["faces"]:
        u, v, o = frame = _face_frame(scene, f["face"])
        two = lambda p: np.stack([np.asarray(p) @ u, np.asarray(p) @ v], axis=1)  # noqa: E731
        for seg in f["segments"]:
            points[seg["event"]] = seg["points"]
        regions = [Region(two(g["outer"]), [two(h) for h in g["holes"]], g["area"]) for g in f["regions"]]
        receivers.append(ReceiverMesh(f["face"], np.array([seg["event"] for seg in f["segments"]], np.int64), regions,
                                      frame, np.array([c["edge"] for c in f["contacts"]], np.int64)))
    offsets = np.r_[0, np.cumsum([len(p) for p in points])].astype(np.int64)
    flat = np.array([q for p in points for q in p], np.float64).reshape(-1, 3)
    return SimpleNamespace(light=light_of(scene, None, light_group), offsets=offsets, points=flat,
                           receivers=receivers, snap=data["snap"], tolerance=data["tolerance"],
                           events=SimpleNamespace(arc=np.zeros(data["events"])))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--light-group", default="light")
    parser.add_argument("--mesh", help="a pickle of the mesh: read if it exists (the scene read again), else written")
    parser.add_argument("--output", help="the output of viscx query discontinuities (.msgpack or .json) to check")
    parser.add_argument("--faces", type=int, default=150, help="receivers drawn among the occluders' faces")
    parser.add_argument("--max-regions", type=int, default=60)
    parser.add_argument("--max-traces", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--show", type=int, default=5, help="failures printed of each kind")
    args = parser.parse_args(argv)
    row = {"scene": args.scene}
    if args.output:
        scene = scene_of(args.scene)
        if args.output.endswith(".json"):
            data = json.loads(Path(args.output).read_text())
        else:
            import msgpack

            data = msgpack.unpackb(Path(args.output).read_bytes(), strict_map_key=False)
        mesh = mesh_of_output(scene, data, args.light_group)
    elif args.mesh and Path(args.mesh).exists():
        scene = scene_of(args.scene)
        with open(args.mesh, "rb") as f:
            mesh = pickle.load(f)
    else:
        c0 = time.process_time()
        scene, mesh = open_discontinuities(args.scene, light_group=args.light_group)
        row |= {"cpu_mesh": round(time.process_time() - c0, 1), "peak_gb_mesh": round(peak_mb() / 1024, 2)}
        if args.mesh:
            with open(args.mesh, "wb") as f:
                pickle.dump(mesh, f, protocol=pickle.HIGHEST_PROTOCOL)
    row |= {"triangles": int(len(scene.triangles)), "events": int(len(mesh.events.arc)),
            "regions": int(sum(len(r.regions) for r in mesh.receivers))}
    rng = np.random.default_rng(args.seed)
    group = np.array([scene.group_names[g] for g in scene.face_group[[r.face for r in mesh.receivers]]])
    room = np.array([not (g.startswith("sphere") or g == "bunny") for g in group])
    faces = [r.face for r, k in zip(mesh.receivers, room) if k]
    others = [r.face for r, k in zip(mesh.receivers, room) if not k and len(r.events)]
    if others:
        faces += sorted(rng.choice(others, min(args.faces, len(others)), replace=False).tolist())
    c0 = time.process_time()
    res = check_mesh(scene, mesh, rng, MARGIN * scene.diagonal, samples=4, faces=faces,
                     max_regions=args.max_regions, max_traces=args.max_traces, cull=True)
    row |= {"cpu_oracle": round(time.process_time() - c0, 1), "receivers_checked": len(faces),
            "points": res["same_pairs"] + res["regions_sampled"] + 2 * res["cross_pairs"]}
    row |= check_row(res, args.show)
    print(json.dumps(row, default=str), flush=True)


def check_row(res, show=5):
    """The counts of :func:`check_mesh`'s result ``res`` as the row prints them, and its
    first ``show`` failures of each kind. Its ``regions`` (those of the receivers checked)
    is ``regions_checked``: the row's ``regions`` counts the whole mesh's. (Before, the
    checked receivers' count replaced it: the spheres' 257,609 regions were printed as the
    134,789 of the 66 receivers checked.)"""
    row = {("regions_checked" if k == "regions" else k): v for k, v in res.items() if isinstance(v, int)}
    row |= {k: len(v) for k, v in res.items() if isinstance(v, list)}
    row["cross_skipped_not_outline"] = sum(why != "on the outline" for *_, why in res["cross_skipped"])
    row["failures"] = {k: res[k][:show] for k in ("same_fail", "cross_fail", "dangling") if res[k]}
    skipped = [s for s in res["cross_skipped"] if s[-1] != "on the outline"]
    if skipped:
        row["failures"]["cross_skipped_not_outline"] = skipped[:show]
    return row


if __name__ == "__main__":
    main()
