"""Independent oracles for flatland tests: plain numpy, no viscx.flatland kernels.

- Monte Carlo line sampling: uniform oriented lines (θ, u) in a disk around the scene;
  for each line every object's chord, sorted along the line, gives the free segments
  a → b; the measure of the lines leaving a for b estimates 2 L_a F_ab.
- Closed-form crossed strings for two circles (Hottel / Sylvester: the measure of the
  lines meeting two disjoint convex sets is L_int − L_ext).
- Crossed strings for two convex polygons from scipy's convex hull and a brute-force
  search of the inner tangents through corner pairs.
"""

import math

import numpy as np
from scipy.spatial import ConvexHull


def objects_of(scene):
    """[(kind, verts, r)] read straight from the scene arrays."""
    out = []
    for k in range(scene.n):
        v = scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]]
        out.append((int(scene.kind[k]), v.copy(), float(scene.radius[k])))
    return out


def perimeter(obj):
    kind, v, r = obj
    if kind == 0:
        return 2 * math.pi * r
    return float(np.sum(np.hypot(*(np.roll(v, -1, 0) - v).T)))


def chords(obj, o, d):
    """(N,) t_in, t_out of lines o + t d through one object (t_in = inf when missed)."""
    kind, v, r = obj
    if kind == 0:
        c = v[0] - o
        b = c[:, 0] * d[:, 0] + c[:, 1] * d[:, 1]
        perp2 = np.einsum("ij,ij->i", c, c) - b * b
        h = np.sqrt(np.maximum(r * r - perp2, 0.0))
        hit = perp2 < r * r
        return np.where(hit, b - h, np.inf), np.where(hit, b + h, -np.inf)
    tin = np.full(o.shape[0], -np.inf)
    tout = np.full(o.shape[0], np.inf)
    m = len(v)
    for i in range(m):
        a, b = v[i], v[(i + 1) % m]
        nrm = np.array([b[1] - a[1], -(b[0] - a[0])])
        num = (o - a) @ nrm
        den = d @ nrm
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -num / den
        tout = np.where(den > 0, np.minimum(tout, t), tout)
        tin = np.where(den < 0, np.maximum(tin, t), tin)
        bad = (den == 0) & (num > 0)
        tin = np.where(bad, np.inf, tin)
    hit = tin < tout
    return np.where(hit, tin, np.inf), np.where(hit, tout, -np.inf)


def sampled_lines(scene, n_lines, seed, chunk=250_000):
    """Uniform oriented lines (θ, u) through the disk of radius Rb around the scene, in
    chunks: yields (o (M, 2), d (M, 2), t_in (M, n), t_out (M, n), order (M, n) objects
    sorted by entry, hit (M, n) whether the j-th of them is met, and the measure 4π Rb of
    all the sampled lines)."""
    objs = objects_of(scene)
    n = len(objs)
    pts = np.concatenate([o[1] for o in objs])
    rad = max(o[2] for o in objs)
    center = 0.5 * (pts.min(0) + pts.max(0))
    Rb = np.max(np.hypot(*(pts - center).T)) + rad + 1e-9
    rng = np.random.default_rng(seed)
    done = 0
    while done < n_lines:
        M = min(chunk, n_lines - done)
        th = rng.uniform(0, 2 * math.pi, M)
        u = rng.uniform(-Rb, Rb, M)
        d = np.stack([np.cos(th), np.sin(th)], 1)
        o = center + u[:, None] * np.stack([-d[:, 1], d[:, 0]], 1)
        tin = np.empty((M, n)); tout = np.empty((M, n))
        for k, ob in enumerate(objs):
            tin[:, k], tout[:, k] = chords(ob, o, d)
        order = np.argsort(tin, axis=1, kind="stable")
        hit = np.isfinite(np.take_along_axis(tin, order, 1))
        yield o, d, tin, tout, order, hit, 4 * math.pi * Rb
        done += M


def monte_carlo_F(scene, n_lines=1_000_000, seed=0, chunk=250_000):
    """Monte Carlo form factors: F (n, n+1) and its standard error (n, n+1)."""
    objs = objects_of(scene)
    n = len(objs)
    counts = np.zeros((n, n + 1))
    measure = 0.0
    for o, d, tin, tout, order, hit, measure in sampled_lines(scene, n_lines, seed, chunk):
        N = len(o)
        for j in range(n):
            a = order[:, j]
            ok = hit[:, j]
            b = np.where(hit[:, j + 1], order[:, j + 1], n) if j + 1 < n else np.full(N, n)
            np.add.at(counts, (a[ok], b[ok]), 1.0)
    Lp = np.array([perimeter(ob) for ob in objs])
    scale = measure / (2 * Lp)[:, None]
    p = counts / n_lines
    return p * scale, np.sqrt(p * (1 - p) / n_lines) * scale



def crossed_strings_circles(c1, r1, c2, r2):
    """F_12 for two unoccluded circles: (L_int − L_ext) / (2 L_1)."""
    D = math.dist(c1, c2)
    L_int = 2 * math.sqrt(D * D - (r1 + r2) ** 2) + (r1 + r2) * (2 * math.pi - 2 * math.acos((r1 + r2) / D))
    e = math.acos((r1 - r2) / D)
    L_ext = 2 * math.sqrt(D * D - (r1 - r2) ** 2) + r1 * (2 * math.pi - 2 * e) + r2 * 2 * e
    return (L_int - L_ext) / (2 * 2 * math.pi * r1)


def _hull_perimeter(points):
    h = ConvexHull(points)
    p = points[h.vertices]
    return float(np.sum(np.hypot(*(np.roll(p, -1, 0) - p).T)))


def crossed_strings_polygons(P, Q):
    """F_PQ for two unoccluded convex polygons (corner arrays), brute force.

    L_ext: perimeter of the hull of both.  L_int: the crossed belt, which is the boundary
    of hull(P ∪ {X}) plus that of hull(Q ∪ {X}), X the crossing point of the two inner
    common tangents (found among the lines through corner pairs that separate P and Q)."""
    inner = []
    for a in P:
        for b in Q:
            d = b - a
            nrm = np.array([-d[1], d[0]])
            sp = (P - a) @ nrm
            sq = (Q - a) @ nrm
            tol = 1e-12 * (1 + np.abs(P).max() + np.abs(Q).max()) ** 2
            if (np.all(sp <= tol) and np.all(sq >= -tol)) or (np.all(sp >= -tol) and np.all(sq <= tol)):
                inner.append((a, b))
    assert len(inner) == 2, inner
    (a1, b1), (a2, b2) = inner
    # X = a1 + s (b1 − a1) = a2 + t (b2 − a2)
    M = np.array([b1 - a1, -(b2 - a2)]).T
    s, _ = np.linalg.solve(M, a2 - a1)
    X = a1 + s * (b1 - a1)
    L_int = _hull_perimeter(np.vstack([P, X])) + _hull_perimeter(np.vstack([Q, X]))
    L_ext = _hull_perimeter(np.vstack([P, Q]))
    LP = float(np.sum(np.hypot(*(np.roll(P, -1, 0) - P).T)))
    return (L_int - L_ext) / (2 * LP)


def arc_positions(obj, x):
    """Arc length of boundary points x (N, 2): circles from the +x axis, polygons from
    their first corner, counter-clockwise (the documented viscx convention)."""
    kind, v, r = obj
    if kind == 0:
        return np.mod(np.arctan2(x[:, 1] - v[0, 1], x[:, 0] - v[0, 0]), 2 * math.pi) * r
    m = len(v)
    best = np.full(len(x), np.inf)
    pos = np.zeros(len(x))
    acc = 0.0
    for i in range(m):
        a, b = v[i], v[(i + 1) % m]
        ab = b - a
        L = math.hypot(*ab)
        t = np.clip((x - a) @ ab / (L * L), 0, 1)
        dist = np.hypot(*(a + t[:, None] * ab - x).T)
        better = dist < best
        best = np.where(better, dist, best)
        pos = np.where(better, acc + t * L, pos)
        acc += L
    return pos


def monte_carlo_elements(scene, elem_obj, elem_s, n_lines=1_000_000, seed=0, chunk=250_000):
    """Monte Carlo element form factors (N, N+1) and standard errors, by exit / entry
    positions of the sampled lines' free segments."""
    objs = objects_of(scene)
    n = len(objs)
    N = len(elem_obj)
    counts = np.zeros((N, N + 1))
    # per object: element starts (sorted) for the position → element lookup
    starts = {k: (np.nonzero(elem_obj == k)[0], elem_s[elem_obj == k, 0]) for k in range(n)}

    def elem_of(k, s):
        ids, st = starts[k]
        j = np.searchsorted(st, s, side="right") - 1
        return ids[j % len(ids)]  # before the first start: the wrapping last element

    measure = 0.0
    for o, d, tin, tout, order, hit, measure in sampled_lines(scene, n_lines, seed, chunk):
        for j in range(n):
            ok = hit[:, j]
            a = order[ok, j]
            rows = np.nonzero(ok)[0]
            x_exit = o[rows] + tout[rows, a][:, None] * d[rows]
            ea = np.empty(len(rows), np.int64)
            for k in range(n):
                mk = a == k
                if mk.any():
                    ea[mk] = elem_of(k, arc_positions(objs[k], x_exit[mk]))
            if j + 1 < n:
                nh = hit[rows, j + 1]
            else:
                nh = np.zeros(len(rows), bool)
            fb = np.full(len(rows), N)
            if nh.any():
                rr = rows[nh]
                b = order[rr, j + 1]
                y = o[rr] + tin[rr, b][:, None] * d[rr]
                eb = np.empty(len(rr), np.int64)
                for k in range(n):
                    mk = b == k
                    if mk.any():
                        eb[mk] = elem_of(k, arc_positions(objs[k], y[mk]))
                fb[nh] = eb
            np.add.at(counts, (ea, fb), 1.0)
    Le = elem_s[:, 1] - elem_s[:, 0]
    scale = measure / (2 * Le)[:, None]
    p = counts / n_lines
    return p * scale, np.sqrt(p * (1 - p) / n_lines) * scale
