"""Edge-dual form factors (prototype, not product code): F_ij with occlusion integrated
over the edges of the visible contour, exactly over the emitter.

For x on emitter i (unit normal n_i) Lambert's formula gives

    g(x) = (1/2π) ∮_{∂V(x)} ((y − x) × dy) · n_i / |y − x|²,

∂V(x) the contour of j's visible part, oriented so that g ≥ 0: at a point y of it, with
t its direction and w a direction from y into V, det[y − x, t, w] > 0. The contour can be
taken as pieces of 3-D edges (the integrand is invariant along rays from x): edges of j
that x sees, and occluder edges that are silhouettes from x with j visible right behind.
Swapping the integrals,

    A_i F_ij = (1/2π) Σ_e ∫_{y ∈ e} Σ_σ ∫_{x ∈ R_e^σ(y)} σ ((y − x) × t) · n_i / |y − x|² dA_x dl_y.

Inner integral: ((y − x) × t) · n_i / |y − x|² = −∇_x ln|x − y| · (t × n_i), and for a
constant in-plane vector a, ∫_R ∇f · a dA = ∮_{∂R} f (a · ν) dl with ν = τ × n_i the outer
normal of a boundary running counter-clockwise (τ) about n_i; (t × n_i) · (τ × n_i) = t · τ,
so ∫_R σ (...) dA = −σ ∮_{∂R} ln|x − y| t · dx (closed form on straight pieces).

Orientations (w for each kind of edge, loops counter-clockwise about their normals):
* an edge of j: w = n_j × t (into j), σ = sign((y − x) · n_j) = −s_j for x on j's side
  s_j: coefficient +s_j. Unoccluded this is the contour formula
  A_i F = (1/2π) ∮_{∂i} ∮_{∂j} ln r dx · dy;
* an occluder edge of face f: the face lies towards n_f × t, V on the other side:
  σ = sign(n_f · (x − y)): coefficient −1 where x is in front of f, +1 behind; an edge of
  two faces of a closed solid (f1 along t, f2 along −t) counts where x is in front of exactly
  one (front of f1: −1; front of f2: +1, in f1's t).

Per point y (benchmarks/edge_dual_kernel.py): R is the convex base (i ∩ j's side [∩ the
projection of j through y and the silhouette half-planes, for occluder edges]) minus the
projections through y of the occluder faces below y (shadows) and, for occluder edges,
of those between y and j. Faces whose plane holds y are skipped (edge-on), and so are the
back faces of closed solids (their front faces cover the same rays) unless y lies on a
face of that solid or behind all its faces' planes (rays from y into it, or from inside it,
leave through its back faces: intersecting solids). The pair's solids
are taken whole. An edge of j in i's plane sees along grazing rays: only the faces lying
in i's plane block, by their 2-D shadows. Occluder edges in i's plane are skipped (counted
as flagged): they are never on the visible contour.

Results and what had to change from the first sketch: docs/queries.md, "Along the edges,
exactly over the emitter".

Outer integral: adaptive Gauss–Kronrod (7, 15) on every edge, one global budget: the
estimate is Σ |K − G| over the final intervals, the worst intervals split.

Usage:
  python benchmarks/edge_dual.py unoccluded
  python benchmarks/edge_dual.py small [--tol 1e-9]
  python benchmarks/edge_dual.py office FILE PAIR... [--tol 1e-6]   (PAIR: i:j, faces)
  python benchmarks/edge_dual.py groups FILE.obj GROUP:GROUP... [--tol 1e-4 1e-6] [--max-cpu 600]
"""

import argparse
import heapq
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from edge_dual_kernel import MAXV, edge_values  # noqa: E402

# Gauss–Kronrod (7, 15) on [−1, 1]
_XK = np.array([0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
                0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
                0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
                0.207784955007898467600689403773245, 0.000000000000000000000000000000000])
_WK = np.array([0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
                0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
                0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
                0.204432940075298892414161999234649, 0.209482141084727828012999174891714])
_WG = np.array([0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
                0.381830050505118944950369775488975, 0.417959183673469387755102040816327])
NODES = np.concatenate([-_XK[:-1], _XK[::-1]])  # 15 nodes, ascending
WK15 = np.concatenate([_WK[:-1], _WK[::-1]])
WG7 = np.zeros(15)
WG7[[1, 3, 5, 7, 9, 11, 13]] = np.concatenate([_WG[:3], [_WG[3]], _WG[2::-1]])


def _loops_of(scene, face):
    from viscx.queries.formfactor import scene_polygons

    pts, lo, hi, lp, *_ = scene_polygons(scene)
    return [pts[lo[k]:hi[k]] for k in np.flatnonzero(lp == face)]


def _convex(loop, normal):
    p = np.asarray(loop)
    e = np.roll(p, -1, axis=0) - p
    cr = np.cross(e, np.roll(e, -1, axis=0)) @ normal
    return bool(np.all(cr >= -1e-12 * np.max(np.abs(p))))


class Pair:
    """The geometry of one pair (emitter i, side 1, to the side of j facing it) for the kernel."""

    def __init__(self, scene, i, j, occluders="shaft", skip_zero=False):
        from viscx.queries.formfactor import pair_occluders, scene_polygons

        self.scene, self.i, self.j = scene, i, j
        n_i = scene.face_normal[i].astype(np.float64)
        c_i = float(scene.face_offset[i]) if hasattr(scene, "face_offset") else float(n_i @ _loops_of(scene, i)[0][0])
        li, lj = _loops_of(scene, i), _loops_of(scene, j)
        if len(li) != 1 or len(lj) != 1:
            raise NotImplementedError("faces with holes")
        i3, j3 = np.ascontiguousarray(li[0]), np.ascontiguousarray(lj[0])
        n_j = scene.face_normal[j].astype(np.float64)
        c_j = float(n_j @ j3[0])
        c_i = float(n_i @ i3[0])
        if not (_convex(i3, n_i) and _convex(j3, n_j)):
            raise NotImplementedError("non-convex i or j")
        dist = i3 @ n_j - c_j
        if dist.max() > 1e-12 and dist.min() < -1e-12:
            raise NotImplementedError("i on both sides of j's plane")
        s_j = 1.0 if dist.max() > 1e-12 else -1.0
        hj = j3 @ n_i - c_i
        if hj.min() < -1e-9:
            raise NotImplementedError("j behind i's plane")
        o = i3[0].copy()
        u = i3[1] - i3[0]
        u /= np.linalg.norm(u)
        v = np.cross(n_i, u)
        self.frame = (o, u, v, n_i, c_i)
        self.i2 = np.ascontiguousarray(np.stack([(i3 - o) @ u, (i3 - o) @ v], axis=1))
        self.i3, self.j3, self.n_j, self.c_j, self.s_j = i3, j3, n_j, c_j, s_j
        self.area_i = float(abs(_area(self.i2)))
        pts, lo, hi, lp, nrm, off, _ = scene_polygons(scene)
        self.eps = 1e-9 * float(scene.diagonal)
        self.graze = 1e-8 * float(scene.diagonal)  # how far into j an edge of j in i's plane is taken
        # partners: the face holding each edge the other way
        key = lambda p: tuple(np.round(p, 7))  # noqa: E731
        owner = {}
        for k in range(len(lo)):
            f = int(lp[k])
            loop = pts[lo[k]:hi[k]]
            for a in range(len(loop)):
                owner[(key(loop[a]), key(loop[(a + 1) % len(loop)]))] = f
        # connected components of the faces through their shared edges (closed solids)
        parent = list(range(scene.n_faces))

        def find(a):
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        for (ka, kb), f in owner.items():
            g = owner.get((kb, ka))
            if g is not None:
                parent[find(f)] = find(g)
        comp = np.array([find(f) for f in range(scene.n_faces)])
        if occluders == "shaft":
            occ = pair_occluders(scene, [i3], n_i, c_i, [j3], s_j * n_j, s_j * c_j, {i, j})
            faces = {int(f) for _, _, f in occ}
            # with the rest of their solids (a box's bottom lying on i is on the shaft's boundary)
            faces |= {int(f) for f in np.flatnonzero(np.isin(comp, comp[sorted(faces)]))} if faces else set()
            faces = sorted(faces - {i, j})
        else:
            faces = [f for f in range(scene.n_faces) if f not in (i, j)]
        self.faces = faces
        o_pts, o_lo, o_hi, o_n, o_c, o_closed = [], [], [], [], [], []
        edges = []
        fset = set(faces)
        at = 0
        for f in faces:
            ks = np.flatnonzero(lp == f)
            if len(ks) != 1:
                raise NotImplementedError("occluder with holes")
            loop = pts[lo[ks[0]]:hi[ks[0]]]
            if len(loop) > MAXV - 16:
                raise NotImplementedError(f"occluder of {len(loop)} vertices (the kernel's MAXV is {MAXV})")
            closed = True
            for a in range(len(loop)):
                pa, pb = loop[a], loop[(a + 1) % len(loop)]
                g = owner.get((key(pb), key(pa)))
                if g is None:
                    closed = False
                if g is not None and g in fset and g < f:
                    continue  # integrated from g
                L = float(np.linalg.norm(pb - pa))
                if L <= self.eps:
                    continue
                t = (pb - pa) / L
                if g is None:
                    edges.append((1, pa, pb, t, nrm[f], off[f], nrm[f], off[f], f, -1))
                else:
                    edges.append((2, pa, pb, t, nrm[f], off[f], nrm[g], off[g], f, g))
            o_pts.append(loop)
            o_lo.append(at)
            at += len(loop)
            o_hi.append(at)
            o_n.append(nrm[f])
            o_c.append(off[f])
            o_closed.append(closed)
        for a in range(len(j3)):
            pa, pb = j3[a], j3[(a + 1) % len(j3)]
            L = float(np.linalg.norm(pb - pa))
            edges.append((0, pa, pb, (pb - pa) / L, n_j, c_j, n_j, c_j, j, -1))
        # edges whose integrand is zero all along, dropped before any evaluation: an edge along
        # n_i ((y − x) × t) · n_i = 0), and an occluder edge lying in i's plane (never on the
        # visible contour; the kernel would flag its every point)
        self.edges_all = len(edges)
        self.edges_along_n = sum(1 for ed in edges if abs(float(ed[3] @ n_i)) >= 1.0 - 1e-12)
        self.edges_in_plane = sum(1 for ed in edges if ed[0] != 0 and max(abs(float(ed[1] @ n_i) - c_i),
                                                                         abs(float(ed[2] @ n_i) - c_i)) <= self.eps)
        # and an edge of two faces that is a silhouette from no point of i (i in front of both
        # faces' planes, or behind both, up to eps: the regions of both signs are empty)
        def _never(ed):
            if ed[0] != 2:
                return False
            for sg in (1.0, -1.0):
                poly = i3
                for m, c in ((sg * ed[4], sg * ed[5]), (-sg * ed[6], -sg * ed[7])):
                    poly = _clip_poly(poly, m, c - self.eps)
                    if len(poly) < 3:
                        break
                if len(poly) >= 3:
                    return False
            return True

        self.edges_never = sum(1 for ed in edges if _never(ed)) if skip_zero else 0
        if skip_zero:
            edges = [ed for ed in edges if abs(float(ed[3] @ n_i)) < 1.0 - 1e-12 and not (
                ed[0] != 0 and max(abs(float(ed[1] @ n_i) - c_i), abs(float(ed[2] @ n_i) - c_i)) <= self.eps)
                and not _never(ed)]
        self.edges = edges
        roots = {}
        solid = np.array([roots.setdefault(comp[f], len(roots)) if c else -1 for f, c in zip(faces, o_closed)], np.int64)
        self.occ = (np.ascontiguousarray(np.concatenate(o_pts)) if o_pts else np.zeros((0, 3)),
                    np.array(o_lo, np.int64), np.array(o_hi, np.int64),
                    np.ascontiguousarray(np.array(o_n, np.float64).reshape(-1, 3)),
                    np.array(o_c, np.float64), np.array(o_closed, np.bool_), solid, len(roots))
        self.j_cen = j3.mean(axis=0)
        self.evaluations = 0
        nf = len(self.occ[1])
        self._nodbg = (np.zeros((1, 2)), np.zeros((1, 1, 2)), np.zeros(1, np.int64), np.zeros(2, np.int64))
        self.dbg = (np.zeros((64, 2)), np.zeros((2 * nf + 1, MAXV, 2)), np.zeros(2 * nf + 1, np.int64), np.zeros(2, np.int64))
        self.flagged = 0
        self.grazing = 0

    def values(self, e, ys, mode=0):
        kind, pa, pb, t, n1, c1, n2, c2, f, g = self.edges[e]
        o, u, v, n_i, c_i = self.frame
        val, flags = edge_values(np.ascontiguousarray(ys), kind, np.asarray(t, np.float64), np.asarray(n1, np.float64),
                                 float(c1), np.asarray(n2, np.float64), float(c2), o, u, v, n_i, c_i, self.i2, self.i3,
                                 self.j3, self.n_j, self.c_j, self.s_j, self.j_cen, *self.occ, self.eps, mode,
                                 *(self.dbg if mode == 2 else self._nodbg), self.graze)
        self.evaluations += len(ys)
        self.flagged += int((flags == 1).sum())
        self.grazing += int((flags == 2).sum())
        return val


def _clip_poly(poly, m, c):
    """The part of a 3-D convex polygon with m·p ≥ c."""
    out = []
    n = len(poly)
    for a in range(n):
        p, q = poly[a - 1], poly[a]
        fp, fq = float(m @ p) - c, float(m @ q) - c
        if fq >= 0:
            if fp < 0:
                out.append(p + fp / (fp - fq) * (q - p))
            out.append(q)
        elif fp >= 0:
            out.append(p + fp / (fp - fq) * (q - p))
    return out


def _area(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def integrate(pair, tol, init_len=None, max_evals=20_000_000, log=None, left=0.5, max_cpu=None):
    """A_i F by adaptive G7/K15 on every edge; tol absolute in F. Returns a dict."""
    t0 = time.process_time()
    scale = 1.0 / (2 * np.pi * pair.area_i)
    budget = tol / scale  # in the units of Σ ∫ S dl
    # intervals: (edge, a, b) in arc length
    todo = []
    for e, (kind, pa, pb, *_rest) in enumerate(pair.edges):
        L = float(np.linalg.norm(pb - pa))
        k = 1 if init_len is None else max(1, int(np.ceil(L / init_len)))
        s = np.linspace(0.0, L, k + 1)
        todo.extend((e, s[m], s[m + 1]) for m in range(k))
    done_K, done_err = [], []
    live = []  # (−err, counter, edge, a, b, K)
    count = 0
    rounds = []
    while True:
        # evaluate the intervals of todo, edge by edge
        by_edge = {}
        for e, a, b in todo:
            by_edge.setdefault(e, []).append((a, b))
        for e, ivs in by_edge.items():
            kind, pa, pb, t, *_ = pair.edges[e]
            ab = np.array(ivs)
            mid, half = (ab[:, 0] + ab[:, 1]) / 2, (ab[:, 1] - ab[:, 0]) / 2
            s = mid[:, None] + half[:, None] * NODES[None, :]
            ys = pa[None, :] + s.reshape(-1)[:, None] * t[None, :]
            f = pair.values(e, ys).reshape(len(ivs), 15)
            K = half * (f @ WK15)
            G = half * (f @ WG7)
            for m in range(len(ivs)):
                err = abs(K[m] - G[m])
                count += 1
                heapq.heappush(live, (-err, count, e, ivs[m][0], ivs[m][1], K[m]))
        todo = []
        total_err = -sum(x[0] for x in live)
        value = sum(x[5] for x in live)
        rounds.append((pair.evaluations, value * scale, total_err * scale))
        if log:
            log(f"  evals {pair.evaluations:>10,d}  F {value * scale:.10f}  est {total_err * scale:.2e}  "
                f"intervals {len(live):,d}  cpu {time.process_time() - t0:.1f}")
        stopped = max_cpu is not None and time.process_time() - t0 > max_cpu
        if total_err <= budget or pair.evaluations >= max_evals or stopped:
            break
        # split the worst intervals until what is left is `left` times the budget
        rest = total_err
        while live and rest > left * budget:
            err_neg, _, e, a, b, K = heapq.heappop(live)
            rest += err_neg
            m = (a + b) / 2
            todo.append((e, a, m))
            todo.append((e, m, b))
    per_edge, edge_err, edge_n = {}, {}, {}
    for x in live:
        per_edge[x[2]] = per_edge.get(x[2], 0.0) + x[5]
        edge_err[x[2]] = edge_err.get(x[2], 0.0) - x[0]
        edge_n[x[2]] = edge_n.get(x[2], 0) + 1
    if log:
        for e in sorted(edge_err, key=lambda e: -edge_err[e])[:8]:
            kind, pa, pb, *_r = pair.edges[e]
            log(f"    edge {e} kind {kind} {np.round(pa, 3)} -> {np.round(pb, 3)} faces {_r[-2]},{_r[-1]}: "
                f"F part {per_edge[e] * scale:+.3e} est {edge_err[e] * scale:.2e} intervals {edge_n[e]}")
    nonzero = sum(1 for v in per_edge.values() if abs(v) > 0)
    cpu = time.process_time() - t0
    return {"F": value * scale, "error": total_err * scale, "evaluations": pair.evaluations, "edges": len(pair.edges),
            "edges_nonzero": nonzero, "intervals": len(live), "cpu_s": cpu,
            "us_per_eval": 1e6 * cpu / max(pair.evaluations, 1), "stopped": bool(stopped), "flagged": pair.flagged, "grazing": pair.grazing, "rounds": rounds,
            "per_edge": per_edge}


# ---------------------------------------------------------------- validation scenes

def _build(polys, names=None):
    from viscx.scene import PolygonSoup, build_scene

    verts, faces = [], []
    for p in polys:
        faces.append(list(range(len(verts), len(verts) + len(p))))
        verts.extend(np.asarray(p, float).tolist())
    sizes = [len(p) for p in faces]
    names = names or [f"p{k}" for k in range(len(faces))]
    return build_scene(PolygonSoup(vertices=np.asarray(verts, np.float64),
                                   polygon_offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
                                   polygon_vertices=np.concatenate([np.asarray(p) for p in faces]).astype(np.int64),
                                   polygon_group=np.arange(len(faces), dtype=np.int64), group_names=names))


def rect(c, a, b):
    """Rectangle c, c + a, c + a + b, c + b (normal a × b)."""
    c, a, b = (np.asarray(x, float) for x in (c, a, b))
    return [c, c + a, c + a + b, c + b]


def box(lo, hi):
    """The six faces of an axis-aligned box, normals outwards."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    d = hi - lo
    X, Y, Z = np.array([d[0], 0, 0]), np.array([0, d[1], 0]), np.array([0, 0, d[2]])
    return [rect(lo, Y, X), rect(lo + Z, X, Y),  # −z, +z
            rect(lo, X, Z), rect(lo + Y, Z, X),  # −y, +y
            rect(lo, Z, Y), rect(lo + X, Y, Z)]  # −x, +x


def unoccluded_checks():
    from viscx.geometry.formfactor import polygon_to_polygon

    cases = {
        "parallel squares (facing, 1 apart)": (rect([0, 0, 0], [1, 0, 0], [0, 1, 0]),
                                                 rect([0, 0, 1], [0, 1, 0], [1, 0, 0])),
        "parallel, offset, different sizes": (rect([0, 0, 0], [2, 0, 0], [0, 1, 0]),
                                              rect([0.5, 0.3, 0.7], [0, 1.5, 0], [0.8, 0, 0])),
        "perpendicular, sharing an edge": (rect([0, 0, 0], [1, 0, 0], [0, 1, 0]),
                                            rect([0, 0, 0], [0, 0, 1], [1, 0, 0])),
        "perpendicular, apart": (rect([0, 0, 0], [1, 0, 0], [0, 2, 0]),
                                 rect([1.3, 0.2, 0.4], [0, 0, 1.2], [0, 1, 0])),
        "tilted, apart": (rect([0, 0, 0], [1, 0, 0], [0, 1, 0]),
                          rect([0.2, 1.4, 0.3], [0.6, 0.1, 0.5], [-0.3, -0.2, 0.9])),
    }
    out = {}
    for name, (pi, pj) in cases.items():
        scene = _build([pi, pj])
        ref = polygon_to_polygon([np.asarray(pi)], scene.face_normal[0], [np.asarray(pj)], scene.face_normal[1])
        pair = Pair(scene, 0, 1)
        r = integrate(pair, 1e-13)
        out[name] = {"F": r["F"], "ref": ref, "diff": r["F"] - ref, "est": r["error"], "evals": r["evaluations"],
                     "flagged": r["flagged"]}
        print(f"{name:40s} F {r['F']:.14f} ref {ref:.14f} diff {r['F'] - ref:+.2e} est {r['error']:.1e} "
              f"evals {r['evaluations']} flagged {r['flagged']}", flush=True)
    return out


def small_scenes():
    """Small occluded scenes: (name, polygons, i, j)."""
    S = []
    sq_i = rect([0, 0, 0], [1, 0, 0], [0, 1, 0])  # normal +z
    sq_j = rect([0, 0, 1], [0, 1, 0], [1, 0, 0])  # normal −z, at z = 1
    S.append(("square occluder between parallel squares",
              [sq_i, sq_j, rect([0.3, 0.2, 0.5], [0.5, 0, 0], [0, 0.4, 0])], 0, 1))
    floor = rect([0, 0, 0], [4, 0, 0], [0, 4, 0])
    light = rect([1.5, 1.5, 3], [0, 1, 0], [1, 0, 0])  # normal −z
    # (with the box at [1.2, 2.0] × [1.0, 2.2] face_to_face(floor → light) returns inf on this
    # version: an emitter cell of zero area; the light → floor direction of that scene is below)
    S.append(("box on a floor under a light", [floor, light] + box([0.6, 1.0, 0.0], [1.4, 2.2, 0.9]), 0, 1))
    S.append(("box on a floor under a light (light to floor)", [floor, light] + box([1.2, 1.0, 0.0], [2.0, 2.2, 0.9]), 1, 0))
    S.append(("occluder touching the emitter (panel standing on i)",
              [sq_i, sq_j] + box([0.2, 0.45, 0.0], [0.8, 0.55, 0.6]), 0, 1))
    S.append(("occluder touching the receiver (box hanging from j)",
              [sq_i, sq_j] + box([0.3, 0.1, 0.6], [0.7, 0.5, 1.0]), 0, 1))
    S.append(("a face lying on the receiver (box's top on j)",
              [sq_i, sq_j] + box([0.1, 0.3, 0.7], [0.6, 0.9, 1.0]), 0, 1))
    S.append(("a box on a floor lit from a tilted panel", [floor, rect([2.5, 0.2, 2.0], [0, 1.5, 0.6], [1.2, 0, 0])]
              + box([1.2, 1.0, 0.0], [2.0, 2.2, 0.9]), 0, 1))
    wall = rect([0, 0, 0], [0, 1, 0], [1, 0, 0])  # z = 0, normal −z... (y × x)
    wall = rect([0, 0, 0], [1, 0, 0], [0, 1, 0])  # z = 0, normal +z: the emitter
    ground = rect([0, 0, 0], [0, 0, 1], [1, 0, 0])  # y = 0, normal +y, sharing the edge along x
    S.append(("receiver sharing an edge with i, a box against i on j",
              [wall, ground] + box([0.3, 0.0, 0.0], [0.6, 0.4, 0.25]), 0, 1))
    S.append(("receiver sharing an edge with i, a box on j apart from i",
              [wall, ground] + box([0.3, 0.0, 0.2], [0.6, 0.4, 0.45]), 0, 1))
    S.append(("two boxes, one stacked on the other, a loose panel",
              [floor, light] + box([0.5, 0.5, 0.0], [1.5, 2.0, 1.0]) + box([0.7, 0.8, 1.0], [1.3, 1.6, 1.4])
              + [rect([2.2, 0.5, 1.5], [0.8, 0, 0], [0, 0.9, 0.2])], 0, 1))
    return S


def small_checks(tol, ref_tol):
    from viscx.queries.formfactor import face_to_face

    out = {}
    for name, polys, i, j in small_scenes():
        scene = _build(polys)
        ref = face_to_face(scene, i, j, side_i=1, tol=ref_tol)
        pair = Pair(scene, i, j)
        r = integrate(pair, tol)
        d = r["F"] - ref["F"]
        ok = abs(d) <= r["error"] + ref["error"] + 1e-12
        out[name] = {"F": r["F"], "est": r["error"], "ref": ref["F"], "ref_est": ref["error"], "diff": d,
                     "within": bool(ok), "evals": r["evaluations"], "flagged": r["flagged"], "cpu_s": r["cpu_s"]}
        print(f"{name:52s} F {r['F']:.12f} est {r['error']:.1e} | ref {ref['F']:.12f} est {ref['error']:.1e} | "
              f"diff {d:+.2e} {'ok' if ok else 'OUT'} evals {r['evaluations']} flagged {r['flagged']}", flush=True)
    return out


def office(path, pairs, tols, init_len, max_evals):
    import viscx

    scene = viscx.open(path).scene
    out = {}
    for spec in pairs:
        i, j = (int(x) for x in spec.split(":"))
        for tol in tols:
            pair = Pair(scene, i, j)
            print(f"{i} -> {j} tol {tol:g}: {len(pair.edges)} edges, {len(pair.faces)} occluders", flush=True)
            r = integrate(pair, tol, init_len=init_len, max_evals=max_evals, log=lambda s: print(s, flush=True))
            r.pop("per_edge")
            out[f"{i}:{j}@{tol:g}"] = r
            print(json.dumps({k: v for k, v in r.items() if k != "rounds"}), flush=True)
    return out


def groups(path, pairs, tols, init_len, max_evals, max_cpu=None, skip_zero=False):
    """Group pairs (gi:gj, group names) of a scene file (OBJ, ...): A_gi F = Σ over the face
    pairs A_i F_ij, each pair integrated at tol × A_i / A_gi (so the group's F is within tol)."""
    from viscx.scene import load_scene

    t0 = time.process_time()
    scene = load_scene(path)
    load_cpu = time.process_time() - t0
    out = {"file": str(path), "faces": int(scene.n_faces), "load_cpu_s": load_cpu}
    for spec in pairs:
        gi, gj = spec.split(":")
        fi = [int(f) for f in scene.group_faces(gi)]
        fj = [int(f) for f in scene.group_faces(gj)]
        print(f"{gi} ({len(fi)} faces) -> {gj} ({len(fj)} faces)", flush=True)
        for tol in tols:
            t1 = time.process_time()
            parts = []
            for i in fi:
                for j in fj:
                    pair = Pair(scene, i, j, skip_zero=skip_zero)
                    parts.append((i, j, pair))
            a_tot = sum(p.area_i for _, _, p in parts) / max(len(fj), 1)
            setup = time.process_time() - t1
            AF, err, rec = 0.0, 0.0, []
            for i, j, pair in parts:
                print(f"  {i} -> {j} tol {tol:g}: {len(pair.edges)} edges integrated of {pair.edges_all} "
                      f"({pair.edges_along_n} along n_i, {pair.edges_in_plane} in i's plane, {pair.edges_never} never silhouettes), {len(pair.faces)} occluders, "
                      f"setup cpu {setup:.1f}", flush=True)
                r = integrate(pair, tol * a_tot / pair.area_i, init_len=init_len, max_evals=max_evals,
                              log=lambda s_: print(s_, flush=True), max_cpu=max_cpu)
                r.pop("per_edge")
                AF += r["F"] * pair.area_i
                err += r["error"] * pair.area_i
                rec.append({"i": i, "j": j, "edges_all": pair.edges_all, "edges_along_n": pair.edges_along_n,
                            "edges_in_plane": pair.edges_in_plane, "edges_never": pair.edges_never, "occluders": len(pair.faces), **r})
            res = {"F": AF / a_tot, "error": err / a_tot, "setup_cpu_s": setup,
                   "cpu_s": sum(r["cpu_s"] for r in rec), "evaluations": sum(r["evaluations"] for r in rec),
                   "edges": sum(r["edges"] for r in rec), "edges_all": sum(r["edges_all"] for r in rec), "edges_nonzero": sum(r["edges_nonzero"] for r in rec),
                   "stopped": any(r.get("stopped") for r in rec), "pairs": rec}
            res["us_per_eval"] = 1e6 * res["cpu_s"] / max(res["evaluations"], 1)
            out[f"{spec}@{tol:g}"] = res
            print(json.dumps({k: v for k, v in res.items() if k != "pairs"}), flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=["unoccluded", "small", "office", "groups"])
    ap.add_argument("file", nargs="?")
    ap.add_argument("pairs", nargs="*")
    ap.add_argument("--tol", type=float, nargs="+", default=[1e-9])
    ap.add_argument("--ref-tol", type=float, default=1e-9)
    ap.add_argument("--init-len", type=float, default=None)
    ap.add_argument("--max-evals", type=int, default=20_000_000)
    ap.add_argument("--max-cpu", type=float, default=None, help="stop a pair's integration after this many CPU s")
    ap.add_argument("--skip-zero", action="store_true", help="groups: drop the edges along n_i and the occluder edges in i's plane")
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    if a.what == "unoccluded":
        res = unoccluded_checks()
    elif a.what == "small":
        res = small_checks(a.tol[0], a.ref_tol)
    elif a.what == "groups":
        res = groups(a.file, a.pairs, a.tol, a.init_len, a.max_evals, a.max_cpu, a.skip_zero)
    else:
        res = office(a.file, a.pairs, a.tol, a.init_len, a.max_evals)
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1, default=float))


if __name__ == "__main__":
    main()
