"""The row kernel's shadow cull (:func:`viscx.geometry.occlusion.point_views` leaves out of its
sweep the faces in a closed box's shadow from the point): its speed, its effect on the
outputs, and an embree oracle (reports, never asserts).

    python benchmarks/shadow_cull_check.py --polygons 1000 --points 40 --rays 64

On ``--points`` random points of each of the office's floor, west wall, first desk top and
first light and of 12 random box faces (benchmarks/buildings.py): the kernel's CPU µs a point
with the cull and without (``cull_from`` never reached; runs alternated), the largest
difference of their outputs, and per point the faces swept without the cull, those seen
(more than 1e-15 of F) and those the cull leaves out. Then, every ``--step``-th point, rays
from the point to ``--rays`` random points of each face left out (embree,
:class:`viscx.raycast.RayCaster`): every one should be stopped before the face; and, as a
control, to the faces seen above 1e-4 (most should reach them).
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

NEVER = 1 << 40


def calls(scene, n_points, seed=1):
    """[(args of point_views)] on the sampled points of 16 emitters."""
    from viscx.geometry.polygon import plane_basis
    from viscx.queries import formfactor as ff

    rng = np.random.default_rng(seed)
    face_box = ff.closed_boxes(scene)[0]
    faces = [int(scene.group_faces(g)[0]) for g in ("floor", "wall_west", "desk0", "light1")]
    faces += [int(f) for f in rng.choice(np.flatnonzero(face_box >= 0), 12, replace=False)]
    out = []
    for face in faces:
        tri = scene.vertices[scene.triangles[scene.triangle_face == face]]
        w = rng.dirichlet([1, 1, 1], n_points)
        pts = np.einsum("gk,gkd->gd", w, tri[rng.integers(0, len(tri), n_points)])
        n_i = scene.face_normal[face]
        eu, ev = plane_basis(n_i)
        out.append((np.ascontiguousarray(pts), n_i, eu, ev, *ff.scene_polygons(scene), face, 1e-9 * scene.diagonal,
                    *ff.closed_boxes(scene)))
    return out


def faces_at(args, i, hidden):
    """For point i: (faces swept without the cull, faces the cull leaves out, faces seen)."""
    from viscx.geometry import occlusion as oc
    from viscx.geometry.formfactor import clip_to_hemisphere, point_to_polygon

    points, n_i, _, _, pts, lo, hi, loop_poly, normal, c, _, skip, tiny, poly_box, ptr, planes = args
    x = points[i]
    P, nb = len(normal), len(ptr) - 1
    first = np.searchsorted(loop_poly, np.arange(P + 1)).astype(np.int64)
    side = normal @ x - c
    state = np.zeros(nb + 1, np.int64)
    unocc = np.zeros(P)
    swept = np.zeros(P, bool)
    for p in range(P):
        if p == skip or abs(side[p]) <= tiny:
            continue
        loops = [clip_to_hemisphere(pts[lo[L]:hi[L]], x, n_i) for L in range(first[p], first[p + 1])]
        loops = [loop for loop in loops if len(loop) >= 3]
        if loops:
            unocc[p] = point_to_polygon(x, n_i, loops)[0]
            swept[p] = not (side[p] < 0 and oc._outside(x, poly_box[p], state, ptr, planes, tiny))
    score = np.zeros(max(nb, 1))
    for p in np.flatnonzero(swept & (side > 0) & (poly_box >= 0)):
        score[poly_box[p]] += unocc[p]
    sweep = swept.copy()
    poly_o, box_o, box_r = oc._spheres(pts, lo, hi, first, poly_box, nb)
    k = int(np.diff(ptr).max(initial=1))
    oc._cull_shadowed(x, sweep, pts, lo, hi, first, poly_box, poly_o, ptr, planes, box_o, box_r, np.zeros(nb + 1, np.int64),
                      tiny, score, np.empty(len(planes)), np.empty(max(nb, 1), np.int64), np.empty((max(nb, 1), 5)),
                      np.empty(k), np.empty(k))
    seen = unocc - hidden[2 * np.arange(P) + (side <= 0)]
    return np.flatnonzero(swept), np.flatnonzero(swept & ~sweep), np.flatnonzero(swept & (seen > 1e-15)), seen


def main(argv=None):
    from buildings import office

    from viscx.geometry.occlusion import point_views
    from viscx.raycast import RayCaster
    from viscx.scene import build_scene

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--polygons", type=int, default=1000)
    parser.add_argument("--points", type=int, default=40, help="a face")
    parser.add_argument("--runs", type=int, default=2, help="of each version")
    parser.add_argument("--step", type=int, default=8, help="the oracle on every step-th point")
    parser.add_argument("--rays", type=int, default=64, help="a face")
    args = parser.parse_args(argv)
    scene = build_scene(office(args.polygons, seed=0))
    work = calls(scene, args.points)
    n = sum(len(a[0]) for a in work)
    point_views(work[0][0][:2], *work[0][1:])  # compiled or loaded
    sec = {0: 0.0, NEVER: 0.0}
    for r in range(args.runs):
        for cull_from in ((0, NEVER) if r % 2 == 0 else (NEVER, 0)):
            c0 = time.process_time()
            outs = [point_views(*a, cull_from=cull_from) for a in work]
            sec[cull_from] += time.process_time() - c0
            if cull_from == 0:
                with_cull = outs
            else:
                without = outs
    print(json.dumps({"polygons": args.polygons, "points": n, "us_with_cull": round(1e6 * sec[0] / n / args.runs, 1),
                      "us_without": round(1e6 * sec[NEVER] / n / args.runs, 1),
                      "max_abs_diff": max(float(np.abs(a - b).max(initial=0.0)) for a, b in zip(with_cull, without))}),
          flush=True)
    caster = RayCaster(scene.vertices, scene.triangles, scene.triangle_face, 1e-9 * scene.diagonal)
    rng = np.random.default_rng(7)
    tot = {"points": 0, "swept": 0, "seen": 0, "left_out": 0, "left_out_seen_max": 0.0, "rays": 0, "rays_through": 0,
           "control_faces": 0, "control_reached": 0}
    for a, h in zip(work, without):
        for i in range(0, len(a[0]), args.step):
            if (h[i] == -1.0).any():
                continue  # a contact point sees one face only
            x, n_i = a[0][i], a[1]
            swept, out, seen_faces, seen = faces_at(a, i, h[i])
            tot["points"] += 1
            tot["swept"] += len(swept)
            tot["seen"] += len(seen_faces)
            tot["left_out"] += len(out)
            tot["left_out_seen_max"] = max(tot["left_out_seen_max"], float(seen[out].max(initial=0.0)))
            control = [f for f in seen_faces if seen[f] > 1e-4][:10]
            for group, faces in (("out", out), ("control", control)):
                for f in faces:
                    tri = scene.vertices[scene.triangles[scene.triangle_face == f]]
                    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
                    pick = rng.choice(len(tri), args.rays, p=area / area.sum())
                    y = np.einsum("gk,gkd->gd", rng.dirichlet([1, 1, 1], args.rays), tri[pick])
                    y = y[(y - x) @ n_i > 1e-9]
                    if not len(y):
                        continue
                    d = y - x
                    dist = np.linalg.norm(d, axis=1)
                    face, _ = caster.first_hit(np.repeat(x[None], len(y), 0), d, tmin=1e-7, tmax=dist * (1 - 1e-7))
                    if group == "out":
                        tot["rays"] += len(y)
                        tot["rays_through"] += int(np.sum(face < 0))
                    else:
                        tot["control_faces"] += 1
                        tot["control_reached"] += int(np.any(face < 0))
    per = {k: round(tot[k] / max(tot["points"], 1), 1) for k in ("swept", "seen", "left_out")}
    print(json.dumps({**tot, "per_point": per}), flush=True)


if __name__ == "__main__":
    main()
