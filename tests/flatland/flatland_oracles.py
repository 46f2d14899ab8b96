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


# ----------------------------------------------------------------------------- exact (polygons)
_GL16 = np.polynomial.legendre.leggauss(16)


def _edges(P):
    """Directed boundary edges (start, end) of a ccw polygon; a 2-corner 'polygon' (a
    segment) gives its two sides, with opposite outward normals."""
    return [(P[i], P[(i + 1) % len(P)]) for i in range(len(P))]


def _point_to_edge(x, e0, e1, f0, f1, blockers):
    """(N,) ∫_f V cos cos / (2r) dy from points x (N, 2) of edge e to edge f, blockers a
    list of corner arrays: ½ Σ (sin b − sin a) over the directions (angles from e's
    outward normal, in (−π/2, π/2)) under which f's front is the first thing seen."""
    t = (e1 - e0) / np.hypot(*(e1 - e0))
    nu = np.array([t[1], -t[0]])
    tf = (f1 - f0) / np.hypot(*(f1 - f0))
    nuf = np.array([tf[1], -tf[0]])
    N = len(x)

    def ang(p):  # (N,) angle of direction x → p from nu, in (−π, π]
        w = p[None, :] - x
        return np.arctan2(w @ t, w @ nu)

    def span(B):  # angular interval of a convex set (< π wide), unwrapped around its centre
        ac = ang(B.mean(axis=0))
        rel = np.stack([np.angle(np.exp(1j * (ang(p) - ac))) for p in B], 1)
        return ac + rel.min(1), ac + rel.max(1)

    flo, fhi = span(np.stack([f0, f1]))
    lo, hi = np.full(N, 0.0), np.full(N, 0.0)
    for shift in (-2 * np.pi, 0.0, 2 * np.pi):   # the part of f's interval in e's front
        s_, e_ = np.maximum(flo + shift, -np.pi / 2), np.minimum(fhi + shift, np.pi / 2)
        better = (e_ - s_) > (hi - lo)
        lo, hi = np.where(better, s_, lo), np.where(better, e_, hi)
    faces = (x - f0) @ nuf > 0                      # f shows its front to x
    ok = faces & (hi > lo)
    starts, ends = [], []
    for B in blockers:
        blo, bhi = span(B)
        # in front of f?  along the middle direction of the overlap, k's entry before f
        for shift in (-2 * np.pi, 0.0, 2 * np.pi):
            s_, e_ = np.maximum(blo + shift, lo), np.minimum(bhi + shift, hi)
            mid = 0.5 * (s_ + e_)
            d = np.cos(mid)[:, None] * nu + np.sin(mid)[:, None] * t
            den = d @ nuf
            with np.errstate(divide="ignore", invalid="ignore"):
                tf_hit = ((f0[None, :] - x) @ nuf) / den
            tin = _ray_entry(B, x, d)
            # an object lying on f (touching it, met at the same t) hides it when it is on
            # f's front side (a segment lying on f counts so): the limit of a closing gap
            tie = 1e-12 * (1.0 + np.abs(tf_hit))
            on_front = (B.mean(axis=0) - f0) @ nuf >= -1e-12 * (1.0 + np.abs(B).max())
            with np.errstate(invalid="ignore"):
                front = (e_ > s_) & ((tin < tf_hit - tie) | (on_front & (tin <= tf_hit + tie)))
            starts.append(np.where(front, s_, np.inf))
            ends.append(np.where(front, e_, -np.inf))
    vis = np.zeros(N)
    if starts:
        S = np.stack(starts, 1); E = np.stack(ends, 1)
        o = np.argsort(S, axis=1)
        S = np.take_along_axis(S, o, 1); E = np.take_along_axis(E, o, 1)
        run = lo.copy()
        for k in range(S.shape[1]):
            gap = np.isfinite(S[:, k]) & (S[:, k] > run)
            g1 = np.minimum(S[:, k], hi)
            vis += np.where(gap & (g1 > run), 0.5 * (np.sin(g1) - np.sin(run)), 0.0)
            run = np.where(np.isfinite(S[:, k]), np.maximum(run, np.minimum(E[:, k], hi)), run)
        vis += np.where(hi > run, 0.5 * (np.sin(hi) - np.sin(run)), 0.0)
    else:
        vis = 0.5 * (np.sin(hi) - np.sin(lo))
    return np.where(ok, vis, 0.0)


def _ray_entry(B, o, d):
    """(N,) entry parameter of rays o + t d into the convex polygon (or segment) B."""
    if len(B) == 2:  # a segment: where the ray crosses it (inf if it misses)
        a, b = B
        w = b - a
        den = d[:, 0] * w[1] - d[:, 1] * w[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            tt = ((a[0] - o[:, 0]) * w[1] - (a[1] - o[:, 1]) * w[0]) / den
            ss = ((a[0] - o[:, 0]) * d[:, 1] - (a[1] - o[:, 1]) * d[:, 0]) / den
        return np.where((ss >= 0) & (ss <= 1) & (tt > 0), tt, np.inf)
    tin, tout = chords((1, B, 0.0), o, d)
    return np.where(tin < tout, tin, np.inf)


def _meets(B, pts):
    """Whether convex polygon B meets the convex hull of pts (separating axes: the normals
    of B's edges and of every segment between two of the points)."""
    axes = [np.roll(B, -1, 0) - B] if len(B) > 1 else []
    axes.append((pts[None, :, :] - pts[:, None, :]).reshape(-1, 2))
    ax = np.concatenate(axes)
    ax = np.stack([ax[:, 1], -ax[:, 0]], 1)
    ax = ax[np.hypot(ax[:, 0], ax[:, 1]) > 0]
    pb, pp = B @ ax.T, pts @ ax.T
    return not np.any((pb.min(0) > pp.max(0)) | (pp.min(0) > pb.max(0)))


def exact_F_polygons(objects, i, j, rel=1e-12):
    """F_ij between polygons / segments (corner arrays, ccw; 2 corners = a two-sided
    segment) with every other object as an occluder, by exact visibility of edge pairs
    and analytic inner integrals (point → visible parts of an edge: ½ Σ Δ sin), the
    outer integral by 16-point Gauss–Legendre between the points of edge e where two
    relevant corners align with it (the visible parts are smooth in between), halved
    until two levels agree to ``rel``.  Independent of viscx.flatland."""
    Li = sum(np.hypot(*(b - a)) for a, b in _edges(objects[i]))
    return sum(exact_F_part(objects, i, j, e0, e1, rel) * np.hypot(*(e1 - e0)) for e0, e1 in _edges(objects[i])) / Li


def exact_F_part(objects, i, j, e0, e1, rel=1e-12, ref=None):
    """F from the piece e0 → e1 of an edge of object i (outward normal on its right) to
    object j (all its edges), occluded by every other object.  Converged when two levels
    agree to ``rel`` × ``ref`` (default the piece's length; a tiny piece of a longer edge
    passes the edge's length, since next to a touching corner its integrand is only
    computed to ~1e-16 / the distance to that corner; a piece shorter than 1e-6 × ref is
    taken after 7 halvings whatever they give: it weighs < 1e-6 of the edge)."""
    total = 0.0
    le = np.hypot(*(e1 - e0))
    for f0, f1 in _edges(objects[j]):
        hull = np.vstack([e0, e1, f0, f1])
        blockers = [B for k, B in enumerate(objects) if k not in (i, j) and _meets(B, hull)]
        corners = np.vstack([f0, f1] + blockers)
        # breakpoints: where the lines through two corners (or f's line) cross e
        t = (e1 - e0) / le
        brk = [0.0, le]
        pairs = [(corners[a], corners[b]) for a in range(len(corners)) for b in range(a + 1, len(corners))]
        for c1, c2 in pairs + [(f0, f1)]:
            w = c2 - c1
            den = t[0] * w[1] - t[1] * w[0]
            if abs(den) < 1e-300:
                continue
            s = ((c1[0] - e0[0]) * w[1] - (c1[1] - e0[1]) * w[0]) / den
            if 0 < s < le:
                brk.append(s)
        # and under every corner (the integrand peaks there: smooth but narrow when close)
        foot = (corners - e0) @ t
        brk += list(foot[(foot > 0) & (foot < le)])
        brk = np.unique(brk)

        def integral(br):
            a, b = br[:-1], br[1:]
            s = (0.5 * (a + b))[:, None] + (0.5 * (b - a))[:, None] * _GL16[0][None, :]
            w = (0.5 * (b - a))[:, None] * _GL16[1][None, :]
            x = e0 + s.ravel()[:, None] * t
            return float(np.sum(w.ravel() * _point_to_edge(x, e0, e1, f0, f1, blockers)))

        prev = integral(brk)
        for _ in range(7):
            brk = np.unique(np.concatenate([brk, 0.5 * (brk[1:] + brk[:-1])]))
            cur = integral(brk)
            if abs(cur - prev) <= rel * (le if ref is None else ref) or (ref is not None and le < 1e-6 * ref):
                break
            prev = cur
        else:
            raise AssertionError(f"oracle did not converge ({cur!r} after {prev!r} before the last halving)")
        total += cur
    return total / le


# ----------------------------------------------------------------------------- exact (touching)
def _contact_pieces(objects, i, e0, e1, tol=1e-12):
    """Contacts of the edge e0 → e1 of object i: [(s0, s1, k)] the intervals of arc length
    along it where an edge of object k lies on it facing it (opposite direction)."""
    le = np.hypot(*(e1 - e0))
    t = (e1 - e0) / le
    scale = 1.0 + max(np.abs(B).max() for B in objects)
    out = []
    for k, B in enumerate(objects):
        if k == i:
            continue
        for g0, g1 in _edges(B):
            off = [abs(t[0] * (g[1] - e0[1]) - t[1] * (g[0] - e0[0])) for g in (g0, g1)]
            if max(off) > tol * scale or (g1 - g0) @ t >= 0:
                continue
            a, b = sorted(((g0 - e0) @ t, (g1 - e0) @ t))
            a, b = max(a, 0.0), min(b, le)
            if b > a + tol * scale:
                out.append((a, b, k))
    return out


def exact_F_touching(objects, i, j, rel=1e-12):
    """F_ij like :func:`exact_F_polygons` for objects that may touch, as the limit of a
    closing gap: a point of an edge of i lying on an edge of k that faces it (an edge
    contact) sees k alone, straight ahead over its whole half-plane (F = 1 to k); the
    rest of the edge is integrated as usual (contacts at points have measure 0, and a
    touching object is an ordinary occluder there).  Independent of viscx.flatland."""
    Li = sum(np.hypot(*(b - a)) for a, b in _edges(objects[i]))
    return sum(exact_F_touching_part(objects, i, j, e0, e1, rel) * np.hypot(*(e1 - e0))
               for e0, e1 in _edges(objects[i])) / Li


def exact_F_touching_part(objects, i, j, e0, e1, rel=1e-12):
    """:func:`exact_F_touching` from the piece e0 → e1 of an edge of object i (an element)."""
    le = np.hypot(*(e1 - e0))
    t = (e1 - e0) / le
    cuts = _contact_pieces(objects, i, e0, e1)
    brk = np.unique(np.concatenate([_graded_breaks(objects, i, e0, e1, True), [c[0] for c in cuts],
                                    [c[1] for c in cuts]]))
    total = 0.0
    for a, b in zip(brk[:-1], brk[1:]):
        mid = 0.5 * (a + b)
        on = [k for s0, s1, k in cuts if s0 <= mid <= s1]
        if on:
            total += (b - a) * (on[0] == j)
        else:
            total += (b - a) * exact_F_part(objects, i, j, e0 + a * t, e0 + b * t, rel, le)
    return total / le


def circle_on_edge_measure(c, r, A, B):
    """Measure of the lines meeting both a circle (c, r) and a convex object whose edge A → B
    the circle touches at an interior point, the circle above the edge's line, nothing
    else in the way: L_int − L_ext (crossed strings in the limit of a closing gap) =
    2πr + |AB| − (tangent from A + tangent from B + the arc of the hull between them)."""
    c, A, B = (np.asarray(x, float) for x in (c, A, B))

    def far_tangent(X, sign):  # tangent length and the angle of the tangent point away from AB
        w = X - c
        D = np.hypot(*w)
        return math.sqrt(D * D - r * r), math.atan2(w[1], w[0]) + sign * math.acos(r / D)

    # the circle lies left of A → B (counter-clockwise); B's far tangent point comes first
    tA, aA = far_tangent(A, -1.0)
    tB, aB = far_tangent(B, +1.0)
    arc = r * ((aA - aB) % (2 * math.pi))
    return 2 * math.pi * r + np.hypot(*(B - A)) - tA - tB - arc


def _graded_breaks(objects, i, e0, e1, touching=False):
    """Arc lengths along the edge e0 → e1 of object i: its ends, the feet of the other
    objects' corners (``touching``: only those on the edge's line) and points 10⁻¹ …
    10⁻¹⁰ of its length on either side of them (where the integrand varies on the scale
    of a small gap, or has a log-singular slope next to a touching corner)."""
    le = np.hypot(*(e1 - e0))
    t = (e1 - e0) / le
    corners = np.vstack([B for k, B in enumerate(objects) if k != i])
    if touching:
        off = np.abs(t[0] * (corners[:, 1] - e0[1]) - t[1] * (corners[:, 0] - e0[0]))
        corners = corners[off <= 1e-12 * (1.0 + np.abs(corners).max())]
    foot = (corners - e0) @ t
    grade = le * 10.0 ** -np.arange(1, 11)
    brk = np.concatenate([[0.0, le], foot, (foot[:, None] + grade).ravel(), (foot[:, None] - grade).ravel()])
    return np.unique(brk[(brk >= 0) & (brk <= le)])


def exact_F_graded(objects, i, j, rel=1e-12):
    """:func:`exact_F_polygons` with each edge of i split at :func:`_graded_breaks`: for
    nearly touching objects (a gap of 10⁻⁸), whose integrand varies on the gap's scale."""
    Li = sum(np.hypot(*(b - a)) for a, b in _edges(objects[i]))
    total = 0.0
    for e0, e1 in _edges(objects[i]):
        t = (e1 - e0) / np.hypot(*(e1 - e0))
        brk = _graded_breaks(objects, i, e0, e1)
        for a, b in zip(brk[:-1], brk[1:]):
            total += (b - a) * exact_F_part(objects, i, j, e0 + a * t, e0 + b * t, rel, np.hypot(*(e1 - e0)))
    return total / Li
