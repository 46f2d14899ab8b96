"""numba kernels of flatland: support functions, tangency curves, bitangents, ray queries.

Conventions (used everywhere in :mod:`viscx.flatland`)
------------------------------------------------------
An *oriented* line is (θ, u): direction d(θ) = (cos θ, sin θ), left normal
n(θ) = (−sin θ, cos θ), points x with n·x = u (Orti et al. §3.2's duality
−x sin θ + y cos θ = u).  θ ∈ [0, 2π) for oriented lines; the unoriented line (θ, u) is
the oriented line (θ + π, −u).  The measure dθ du is the motion-invariant measure of lines.

Object k has two *tangency curves* (Orti et al.'s λ and μ):

    side R (object on the right of the line):  u = μ_k(θ) =  h_k(θ + π/2)
    side L (object on the left):               u = λ_k(θ) = −h_k(θ − π/2)

On a piece where support point v (radius r) is active, both read u = n(θ)·v + σ r with
σ = +1 (R) or −1 (L), and the tangent point is p = v + σ r n(θ).

Side codes: ``R = 1``, ``L = 0`` (so σ = 2·side − 1).
"""

import math

import numba as nb
import numpy as np

TWO_PI = 2.0 * math.pi
HALF_PI = 0.5 * math.pi
R_SIDE, L_SIDE = 1, 0


# ----------------------------------------------------------------------------- support
@nb.njit(cache=True)
def piece_at(k, phi, vert_start, A):
    """(turns, p, j): φ = p + turns·2π with p in [A_s, A_s + 2π) up to rounding, and j the
    global index of object k's support piece holding p (a circle: (0, φ, s)).

    The turns and the piece are decided together: φ an ulp below A_s + 2nπ gives
    p = φ − (n − 1)·2π, which may round up to A_s + 2π — that p is counted as the next
    turn's start (piece s), never as piece s with the turn before, which put G_k and
    S_k (:func:`antideriv_h`, :func:`contact_length`) off by a whole perimeter."""
    s, e = vert_start[k], vert_start[k + 1]
    if e - s == 1:
        return 0, phi, s
    a0 = A[s]
    turns = math.floor((phi - a0) / TWO_PI)
    p = phi - turns * TWO_PI
    if p >= a0 + TWO_PI:
        turns += 1
        p -= TWO_PI
    j = s
    for i in range(s + 1, e):
        if A[i] <= p:
            j = i
        else:
            break
    return turns, p, j


@nb.njit(cache=True)
def support_index(k, phi, vert_start, A):
    """Global index of the support point of object k active in direction φ."""
    return piece_at(k, phi, vert_start, A)[2]


@nb.njit(cache=True)
def antideriv_h(k, phi, vert_start, verts, radius, A, cumG, perimeter):
    """G_k(φ): an antiderivative of the support function h_k (continuous in φ ∈ ℝ).

    Circle: h = c·e(φ) + r  ⇒  G = c·(sin φ, −cos φ) + r φ.
    Polygon: on piece j, h = v_j·e(φ); G = (whole turns)·L + cumG_j + v_j·(S(φ) − S(A_j)),
    S(φ) = (sin φ, −cos φ); one whole turn integrates h to the perimeter L (Cauchy)."""
    s, e = vert_start[k], vert_start[k + 1]
    if e - s == 1:
        c = verts[s]
        return c[0] * math.sin(phi) - c[1] * math.cos(phi) + radius[k] * phi
    turns, p, j = piece_at(k, phi, vert_start, A)
    v = verts[j]
    aj = A[j]
    return (turns * perimeter[k] + cumG[j]
            + v[0] * (math.sin(p) - math.sin(aj)) - v[1] * (math.cos(p) - math.cos(aj)))


@nb.njit(cache=True)
def contact_length(k, phi, vert_start, verts, radius, A, cumS, perimeter):
    """S_k(φ): boundary length travelled by the contact point of direction φ (continuous
    from the right, increasing; S(φ + 2π) = S(φ) + L).  Circle: r φ; polygon: the contact
    point sits on corner j for the whole piece j and jumps by an edge length between pieces."""
    s, e = vert_start[k], vert_start[k + 1]
    if e - s == 1:
        return radius[k] * phi
    turns, p, j = piece_at(k, phi, vert_start, A)
    return turns * perimeter[k] + cumS[j]


# ----------------------------------------------------------------------------- chords
@nb.njit(cache=True)
def chord(k, ox, oy, dx, dy, kind, vert_start, verts, radius):
    """Parameters (t_in, t_out) where the line o + t d crosses object k; t_in > t_out if it
    misses.  Circle: solve |o + t d − c|² = r².  Polygon (CCW): Cyrus–Beck clipping against
    the half-planes ν_j·(x − v_j) ≤ 0 with outward edge normals ν_j."""
    s, e = vert_start[k], vert_start[k + 1]
    if kind[k] == 0:
        cx, cy = verts[s, 0] - ox, verts[s, 1] - oy
        b = cx * dx + cy * dy
        perp2 = cx * cx + cy * cy - b * b
        r = radius[k]
        if perp2 >= r * r:
            return 1.0, -1.0
        h = math.sqrt(r * r - perp2)
        return b - h, b + h
    tin, tout = -np.inf, np.inf
    for i in range(s, e):
        i2 = i + 1 if i + 1 < e else s
        nx = verts[i2, 1] - verts[i, 1]
        ny = -(verts[i2, 0] - verts[i, 0])
        num = nx * (ox - verts[i, 0]) + ny * (oy - verts[i, 1])
        den = nx * dx + ny * dy
        if den == 0.0:
            if num > 0.0:
                return 1.0, -1.0
        elif den > 0.0:
            t = -num / den
            if t < tout:
                tout = t
        else:
            t = -num / den
            if t > tin:
                tin = t
    return tin, tout


@nb.njit(cache=True)
def depth(k, ox, oy, dx, dy, kind, vert_start, verts, radius):
    """How deep the line o + t d cuts into object k: min(u − λ, μ − u) with u = n·o and
    [λ, μ] the object's extent along the line's normal n (support values); ≤ 0 when the
    line misses or only touches k.  This is the ε-visibility test: a line blocks only
    where it enters an object's interior by more than ε, so grazing contacts (a line
    along an edge, through a corner, tangent to a circle, along a segment) never block,
    whatever the rounding.  Unlike the chord length it is positive for a segment (a
    two-sided object of zero area) that the line crosses."""
    nx, ny = -dy, dx
    u = nx * ox + ny * oy
    s, e = vert_start[k], vert_start[k + 1]
    lo, hi = np.inf, -np.inf
    for i in range(s, e):
        p = nx * verts[i, 0] + ny * verts[i, 1]
        lo = min(lo, p)
        hi = max(hi, p)
    r = radius[k]
    return min(u - (lo - r), (hi + r) - u)


@nb.njit(cache=True)
def touch_param(k, ox, oy, dx, dy, vert_start, verts):
    """Parameter t along the line o + t d of the support point of object k nearest the
    line (a circle: its centre's foot), where a line grazing k touches it."""
    nx, ny = -dy, dx
    u = nx * ox + ny * oy
    best, t = np.inf, 0.0
    for i in range(vert_start[k], vert_start[k + 1]):
        off = abs(nx * verts[i, 0] + ny * verts[i, 1] - u)
        if off < best:
            best, t = off, dx * (verts[i, 0] - ox) + dy * (verts[i, 1] - oy)
    return t


# ----------------------------------------------------------------------------- grid
def build_grid(bboxes, target_per_cell=2.0):
    """A uniform grid over the objects' bounding boxes (CSR cell → objects).

    Parameters
    ----------
    bboxes : (n, 4) float  xmin, ymin, xmax, ymax

    Returns
    -------
    origin (2,) float64, cell (float), shape (2,) int64, cell_start (nx*ny+1,) int64,
    cell_items (K,) int64
    """
    n = bboxes.shape[0]
    lo = bboxes[:, :2].min(axis=0)
    hi = bboxes[:, 2:].max(axis=0)
    ext = np.maximum(hi - lo, 1e-12)
    # every box padded by 1e-8 of the extent (above the 1e-9 line tolerance): a line passing
    # within the tolerance of an object visits one of its cells (first_hit's grazing test)
    bboxes = bboxes + 1e-8 * ext.max() * np.array([-1.0, -1.0, 1.0, 1.0])
    lo = lo - 1e-6 * ext.max()
    ext = ext + 2e-6 * ext.max()
    ncell = max(1.0, n / target_per_cell)
    cell = math.sqrt(ext[0] * ext[1] / ncell)
    cell = max(cell, ext.max() / 2048.0)
    nx = max(1, int(math.ceil(ext[0] / cell)))
    ny = max(1, int(math.ceil(ext[1] / cell)))
    i0 = np.clip(((bboxes[:, 0] - lo[0]) / cell).astype(np.int64), 0, nx - 1)
    i1 = np.clip(((bboxes[:, 2] - lo[0]) / cell).astype(np.int64), 0, nx - 1)
    j0 = np.clip(((bboxes[:, 1] - lo[1]) / cell).astype(np.int64), 0, ny - 1)
    j1 = np.clip(((bboxes[:, 3] - lo[1]) / cell).astype(np.int64), 0, ny - 1)
    # every object's block of cells [i0, i1] × [j0, j1], enumerated without a Python loop
    wi, wj = i1 - i0 + 1, j1 - j0 + 1
    objs = np.repeat(np.arange(n, dtype=np.int64), wi * wj)
    local = np.arange(objs.size) - np.repeat(np.cumsum(wi * wj) - wi * wj, wi * wj)
    ii = i0[objs] + local // wj[objs]
    jj = j0[objs] + local % wj[objs]
    cells = jj * nx + ii
    order = np.lexsort((objs, cells))
    cells, objs = cells[order], objs[order]
    cell_start = np.searchsorted(cells, np.arange(nx * ny + 1)).astype(np.int64)
    return lo.astype(np.float64), float(cell), np.array([nx, ny], dtype=np.int64), cell_start, objs


@nb.njit(cache=True)
def first_hit(ox, oy, dx, dy, skip1, skip2, limit, eps, stamp, stamp_id,
              origin, cell, shape, cell_start, cell_items, kind, vert_start, verts, radius, tol, graze):
    """First object crossed by the ray o + t d, t > 0 (objects skip1, skip2 ignored).

    ``graze`` (1,) float64: lowered to the parameter t > 0 of every object visited that
    the ray passes without blocking within ``tol`` of touching it, but not touching it to
    rounding (depth in [−tol, eps], |depth| > 1e-3 tol: a third object near the line;
    one on it makes the pairs' candidates copies of the line, grouped as such).

    Walks the grid cells along the ray (Amanatides–Woo).  An object counts when the line
    cuts deeper than ``eps`` into it (:func:`depth`; grazing contacts are not hits) and it
    ends beyond t = eps.  Stops
    early and returns as soon as a hit with t_in < ``limit`` is certain to be the first
    one below the current cell (used for 'is [0, limit] free').

    Returns (object or −1, t_in)."""
    nx, ny = shape[0], shape[1]
    # entry into the grid box
    x0, y0 = origin[0], origin[1]
    x1, y1 = x0 + nx * cell, y0 + ny * cell
    tmin, tmax = 0.0, np.inf
    if dx != 0.0:
        ta, tb = (x0 - ox) / dx, (x1 - ox) / dx
        if ta > tb:
            ta, tb = tb, ta
        tmin, tmax = max(tmin, ta), min(tmax, tb)
    elif ox < x0 or ox > x1:
        return -1, np.inf
    if dy != 0.0:
        ta, tb = (y0 - oy) / dy, (y1 - oy) / dy
        if ta > tb:
            ta, tb = tb, ta
        tmin, tmax = max(tmin, ta), min(tmax, tb)
    elif oy < y0 or oy > y1:
        return -1, np.inf
    if tmin > tmax:
        return -1, np.inf
    px, py = ox + tmin * dx, oy + tmin * dy
    ix = min(max(int((px - x0) / cell), 0), nx - 1)
    iy = min(max(int((py - y0) / cell), 0), ny - 1)
    stepx = 1 if dx > 0 else -1
    stepy = 1 if dy > 0 else -1
    if dx != 0.0:
        nxt = x0 + (ix + (1 if dx > 0 else 0)) * cell
        tx = (nxt - ox) / dx
        dtx = cell / abs(dx)
    else:
        tx, dtx = np.inf, np.inf
    if dy != 0.0:
        nyt = y0 + (iy + (1 if dy > 0 else 0)) * cell
        ty = (nyt - oy) / dy
        dty = cell / abs(dy)
    else:
        ty, dty = np.inf, np.inf
    best, best_t = -1, np.inf
    while True:
        c = iy * nx + ix
        for q in range(cell_start[c], cell_start[c + 1]):
            k = cell_items[q]
            if k == skip1 or k == skip2 or stamp[k] == stamp_id:
                continue
            stamp[k] = stamp_id
            dep = depth(k, ox, oy, dx, dy, kind, vert_start, verts, radius)
            if dep <= eps:  # a line touching k (a corner, an edge, a tangent circle) passes it
                if dep >= -tol and abs(dep) > 1e-3 * tol:  # (touching to rounding: a copy of the line)
                    tg = touch_param(k, ox, oy, dx, dy, vert_start, verts)
                    if 0.0 < tg < graze[0]:
                        graze[0] = tg
                continue
            tin, tout = chord(k, ox, oy, dx, dy, kind, vert_start, verts, radius)
            if tout > eps:
                if tin < best_t:
                    best, best_t = k, tin
        t_exit = min(tx, ty)
        # a later cell cannot hold a nearer hit (an object crossing the ray before t_exit
        # overlaps a visited cell); a hit before `limit` already answers 'blocked'
        if best >= 0 and (best_t <= t_exit or best_t < limit):
            return best, best_t
        if t_exit > tmax:
            return best, best_t
        if tx < ty:
            ix += stepx
            tx += dtx
            if ix < 0 or ix >= nx:
                return best, best_t
        else:
            iy += stepy
            ty += dty
            if iy < 0 or iy >= ny:
                return best, best_t


# ----------------------------------------------------------------------------- bitangents
@nb.njit(cache=True)
def _piece_bounds(k, side, theta, vert_start, A):
    """Active support point of tangency curve (k, side) at θ and the θ where its piece ends."""
    shift = HALF_PI if side == 1 else -HALF_PI
    phi = theta + shift
    _, p, j = piece_at(k, phi, vert_start, A)
    s, e = vert_start[k], vert_start[k + 1]
    if e - s == 1:
        return j, np.inf
    end = A[j + 1] if j + 1 < e else A[s] + TWO_PI
    return j, theta + (end - p)


@nb.njit(cache=True)
def _next_piece(k, j, vert_start, A):
    """The piece after j on object k (cyclic) and its angular width."""
    s, e = vert_start[k], vert_start[k + 1]
    j2 = j + 1 if j + 1 < e else s
    end = A[j2 + 1] if j2 + 1 < e else A[s] + TWO_PI
    return j2, end - A[j2]


def sine_roots(w, rho):
    """The two θ with n(θ)·w = ρ, n(θ) = (−sin θ, cos θ), for many (w, ρ): as in
    :func:`pair_bitangents`, n(θ)·w = |w| sin(β − θ), so θ = β − asin(ρ/|w|) or
    θ = β − π + asin(ρ/|w|) (ρ/|w| clipped to [−1, 1]; |w| = 0 gives β − asin(ρ)).

    Parameters
    ----------
    w : (N, 2) float
    rho : (N,) float

    Returns
    -------
    (N,) float, (N,) float
    """
    wn = np.hypot(w[:, 0], w[:, 1])
    beta = np.arctan2(w[:, 1], w[:, 0])
    q = np.arcsin(np.clip(rho / np.where(wn > 0, wn, 1.0), -1.0, 1.0))
    return beta - q, beta - math.pi + q


@nb.njit(cache=True)
def pair_bitangents(a, b, sa, sb, vert_start, verts, radius, A, out_theta, out_va, out_vb, tol):
    """The oriented common tangents of objects a, b with a on side sa and b on side sb.

    On a θ-piece where support points va, vb are active, u_a = u_b reads
    n(θ)·w = ρ with w = v_b − v_a, ρ = σ_a r_a − σ_b r_b; writing w = |w|(cos β, sin β),
    n(θ)·w = |w| sin(β − θ), so θ = β − asin(ρ/|w|) or θ = β − π + asin(ρ/|w|).
    A root counts if it lies in the piece (a tolerance ``tol`` on the ends, duplicates
    at piece ends merged).  Disjoint convex objects have exactly two such lines.

    Returns the number of roots written to out_theta / out_va / out_vb (≤ 4)."""
    sig_a = 2.0 * sa - 1.0
    sig_b = 2.0 * sb - 1.0
    rho = sig_a * radius[a] - sig_b * radius[b]
    theta = 0.0
    cnt = 0
    guard = 0
    ja, ea = _piece_bounds(a, sa, 0.0, vert_start, A)
    jb, eb = _piece_bounds(b, sb, 0.0, vert_start, A)
    # walk the merged pieces of both curves by index (no re-location from θ, which
    # rounding could stall at a piece end)
    while theta < TWO_PI and guard < 100000:
        guard += 1
        hi = min(ea, eb, TWO_PI)
        wx, wy = verts[jb, 0] - verts[ja, 0], verts[jb, 1] - verts[ja, 1]
        wn = math.hypot(wx, wy)
        if wn > 0.0 and abs(rho) <= wn:
            beta = math.atan2(wy, wx)
            q = math.asin(rho / wn)
            for cand in (beta - q, beta - math.pi + q):
                # bring the root next to the piece [theta, hi)
                t = theta + (cand - theta) % TWO_PI
                if t > TWO_PI - tol + theta:
                    t -= TWO_PI
                if t >= theta - tol and t < hi + tol:
                    tt = t % TWO_PI
                    dup = False
                    for c in range(cnt):
                        dd = abs(out_theta[c] - tt)
                        if dd < 1e3 * tol or TWO_PI - dd < 1e3 * tol:
                            dup = True
                    if not dup and cnt < out_theta.shape[0]:
                        out_theta[cnt] = tt
                        out_va[cnt] = ja
                        out_vb[cnt] = jb
                        cnt += 1
        theta = hi
        if ea <= hi:
            ja, wa = _next_piece(a, ja, vert_start, A)
            ea += wa
        if eb <= hi:
            jb, wb = _next_piece(b, jb, vert_start, A)
            eb += wb
    return cnt


@nb.njit(cache=True)
def all_bitangents(pa, pb, vert_start, verts, radius, A, tol):
    """Candidate bitangents of the object pairs (pa[i], pb[i]): for combos (R, R) (outer)
    and (R, L) (inner) the two oriented roots each, i.e. the 4 unoriented common tangents.

    Returns theta (4P,), va (4P,), vb (4P,), count (2P,) (roots found per pair and combo;
    anything but 2 is a degeneracy the caller reports)."""
    P = pa.shape[0]
    theta = np.full(4 * P, np.nan)
    va = np.full(4 * P, -1, np.int64)
    vb = np.full(4 * P, -1, np.int64)
    count = np.zeros(2 * P, np.int64)
    tt = np.empty(4)
    ja = np.empty(4, np.int64)
    jb = np.empty(4, np.int64)
    for i in range(P):
        for combo in range(2):
            sb = 1 if combo == 0 else 0
            c = pair_bitangents(pa[i], pb[i], 1, sb, vert_start, verts, radius, A, tt, ja, jb, tol)
            count[2 * i + combo] = c
            # deterministic order: by θ
            if c >= 2 and tt[1] < tt[0]:
                tt[0], tt[1] = tt[1], tt[0]
                ja[0], ja[1] = ja[1], ja[0]
                jb[0], jb[1] = jb[1], jb[0]
            for r in range(min(c, 2)):
                o = 4 * i + 2 * combo + r
                theta[o] = tt[r]
                va[o] = ja[r]
                vb[o] = jb[r]
    return theta, va, vb, count


@nb.njit(cache=True)
def classify_bitangents(theta, oa, ob, sa, sb, va, vb, todo, eps, tol, origin, cell, shape, cell_start,
                        cell_items, kind, vert_start, verts, radius):
    """For each candidate i with todo[i]: is the bitangent segment free, and which objects
    end its maximal free segment?

    The oriented line at θ_i touches oa at p = v_a + σ_a r_a n and ob at q likewise.  The
    segment between p and q must not cut any third object deeper than eps; the
    tail is the first object behind the first tangent point, the head the first one
    beyond the second (−1: the blue sky).

    Returns free (bool), first (which of a/b is first along d: 0 → a), tail, head,
    tail_t, head_t (distance from the first/second tangent point to the blocker), blocker
    (an object cutting the segment of a blocked candidate, −1 if free: the dynamic update
    re-tests a blocked candidate only when its blocker moves), graze (a free candidate
    whose maximal free segment passes within ``tol`` of touching a third object: a
    degenerate line up to the tolerance, see complex.degenerate_lines)."""
    N = theta.shape[0]
    graze = np.zeros(N, np.bool_)
    g = np.empty(1)
    free = np.zeros(N, np.bool_)
    a_first = np.zeros(N, np.bool_)
    tail = np.full(N, -2, np.int64)
    head = np.full(N, -2, np.int64)
    tail_t = np.zeros(N)
    head_t = np.zeros(N)
    blocker = np.full(N, -1, np.int64)
    stamp = np.zeros(kind.shape[0], np.int64)
    sid = 0
    for i in range(N):
        if not todo[i]:
            continue
        th = theta[i]
        dx, dy = math.cos(th), math.sin(th)
        nx, ny = -dy, dx
        ga = 2.0 * sa[i] - 1.0
        gb = 2.0 * sb[i] - 1.0
        px = verts[va[i], 0] + ga * radius[oa[i]] * nx
        py = verts[va[i], 1] + ga * radius[oa[i]] * ny
        qx = verts[vb[i], 0] + gb * radius[ob[i]] * nx
        qy = verts[vb[i], 1] + gb * radius[ob[i]] * ny
        L = (qx - px) * dx + (qy - py) * dy
        if L < 0.0:
            px, py, qx, qy = qx, qy, px, py
            L = -L
            a_first[i] = False
        else:
            a_first[i] = True
        sid += 1
        g[0] = np.inf
        k, t = first_hit(px, py, dx, dy, oa[i], ob[i], L - eps, eps, stamp, sid,
                         origin, cell, shape, cell_start, cell_items, kind, vert_start, verts, radius, tol, g)
        if k >= 0 and t < L - eps:
            blocker[i] = k
            continue
        free[i] = True
        head[i] = k
        head_t[i] = t - L if k >= 0 else np.inf
        graze[i] = g[0] < (t if k >= 0 else np.inf)
        sid += 1
        g[0] = np.inf
        k2, t2 = first_hit(px, py, -dx, -dy, oa[i], ob[i], -np.inf, eps, stamp, sid,
                           origin, cell, shape, cell_start, cell_items, kind, vert_start, verts, radius, tol, g)
        tail[i] = k2
        tail_t[i] = t2 if k2 >= 0 else np.inf
        graze[i] |= g[0] < (t2 if k2 >= 0 else np.inf)
    return free, a_first, tail, head, tail_t, head_t, blocker, graze


@nb.njit(cache=True)
def contact_length_at(k, phi, j_forced, vert_start, verts, radius, A, cumS, perimeter):
    """S_k(φ) with the contact point forced onto support point j_forced (−1: none).

    At a degenerate direction (a polygon edge on the line) both corners of the edge touch
    it; the vertex's tangent point names the one used, and the edge's arc length must
    start or end there too, or the string sum (method b) misses the edge length."""
    s, e = vert_start[k], vert_start[k + 1]
    if e - s == 1 or j_forced < 0:
        return contact_length(k, phi, vert_start, verts, radius, A, cumS, perimeter)
    turns, p, j = piece_at(k, phi, vert_start, A)
    if j_forced != j:
        # the forced corner is the piece after j (φ at j's end) or before it (at its
        # start): decided by the nearer end, since a segment's two pieces meet at both
        end = A[j + 1] if j + 1 < e else A[s] + TWO_PI
        if end - p < p - A[j]:
            if j == e - 1:
                turns += 1
        elif j == s:
            turns -= 1
    return turns * perimeter[k] + cumS[j_forced]


@nb.njit(cache=True)
def edge_integrals(obj, side, th0, th1, vert_start, verts, radius, A, cumG, cumS, perimeter, j0, j1):
    """Per edge (an arc of the tangency curve (obj, side) over θ ∈ [θ0, θ1]):

    I = ∫ u dθ  exactly:  side R: u = h(θ + π/2) ⇒ I = G(θ1 + π/2) − G(θ0 + π/2);
                          side L: u = −h(θ − π/2) ⇒ I = −(G(θ1 − π/2) − G(θ0 − π/2));
    s = the boundary length swept by the tangent point (Orti et al.'s d_c(e)), from support
        point j0 to j1 (the end vertices' tangent points; −1 for a loop).

    Returns I (E,), s (E,)."""
    E = obj.shape[0]
    I = np.empty(E)
    s = np.empty(E)
    for i in range(E):
        k = obj[i]
        sh = HALF_PI if side[i] == 1 else -HALF_PI
        g = (antideriv_h(k, th1[i] + sh, vert_start, verts, radius, A, cumG, perimeter)
             - antideriv_h(k, th0[i] + sh, vert_start, verts, radius, A, cumG, perimeter))
        I[i] = g if side[i] == 1 else -g
        s[i] = (contact_length_at(k, th1[i] + sh, j1[i], vert_start, verts, radius, A, cumS, perimeter)
                - contact_length_at(k, th0[i] + sh, j0[i], vert_start, verts, radius, A, cumS, perimeter))
    return I, s


# ----------------------------------------------------------------------------- degeneracies
@nb.njit(cache=True)
def _local_u(l, tau, xa, xb, right, c):
    """u of entry l's tangency curve at the local angle τ (see :func:`local_arrangement`)."""
    x = (xa[l] if tau > 0.0 else xb[l]) if right[l] else (xb[l] if tau > 0.0 else xa[l])
    return c[l] - x * tau


@nb.njit(cache=True)
def _crosses(l, tau, u, xa, xb, right, c, mate):
    """Whether the line (τ, u) crosses the object of entry l: below its right-side curve
    or above its left-side one; between both for an object lying along the line (a
    segment: two entries, ``mate`` the other one)."""
    f = _local_u(l, tau, xa, xb, right, c)
    inside = u < f if right[l] else u > f
    m = mate[l]
    if m < 0 or not inside:
        return inside
    g = _local_u(m, tau, xa, xb, right, c)
    return u < g if right[m] else u > g


@nb.njit(cache=True)
def local_arrangement(xa, xb, right, c, mate):
    """The simple vertices that a degenerate free line splits into under a symbolic
    perturbation (the objects touching one maximal free segment, pushed off it).

    Near the degenerate line ℓ* = (θ*, u*), in the local dual coordinates τ = θ − θ*
    (infinitesimal) and u − u*, the tangency curve of an object touching ℓ* along the
    interval [a, b] of positions on ℓ* (a = b for a point contact) is to first order

        right side (R):  f(τ) = c − a τ  (τ > 0),  c − b τ  (τ < 0)   (a max of two lines)
        left side  (L):  f(τ) = c − b τ  (τ > 0),  c − a τ  (τ < 0)   (a min)

    (d/dθ n(θ)·x = −d·x, and the support point of the interval is its end that maximises
    (R) or minimises (L) n·x), where c is the perturbation: each object is pushed off ℓ*
    by c (c < 0 for R, > 0 for L).  A line (τ, u) crosses an R entry iff u < f(τ), an L
    entry iff u > f(τ).  For two entries i < j (positions along ℓ*, intervals disjoint)
    f_i − f_j increases with τ, so they have exactly one common tangent near ℓ*; it is a
    vertex iff no entry between them is crossed, and its tail (head) is the nearest entry
    before i (after j) that it crosses, or the segment's own tail (head) if none.

    Parameters
    ----------
    xa, xb : (m,) float64  contact intervals along ℓ*, sorted, disjoint (b_i < a_{i+1})
    right : (m,) bool  side R
    c : (m,) float64  the push (generic: no two equal for one side)
    mate : (m,) int64  for an object lying along ℓ* (a segment), the index of its entry on
        the other side (adjacent), else −1; it is translated across ℓ* by c (both
        entries), and crossing it means lying between its two curves

    Returns (i, j, tau, tail, head, i_at_b, j_at_b): the free pairs, their local angle,
    tail / head entries (−1: the segment's own), and whether the tangent point is the
    interval's end b (else a)."""
    m = xa.shape[0]
    cap = m * (m - 1) // 2
    oi = np.empty(cap, np.int64)
    oj = np.empty(cap, np.int64)
    ot = np.empty(cap)
    otl = np.empty(cap, np.int64)
    ohd = np.empty(cap, np.int64)
    obi = np.empty(cap, np.bool_)
    obj_ = np.empty(cap, np.bool_)
    # the tail / head searches dominate (O(m) per free pair): for lines without an object
    # along them, entry l is crossed iff sgn_l (f_l(τ) − u) > 0 (R: u < f, L: u > f)
    plain = True
    for l in range(m):
        if mate[l] >= 0:
            plain = False
    x_pos = np.where(right, xa, xb)
    x_neg = np.where(right, xb, xa)
    sgn = np.where(right, 1.0, -1.0)
    cnt = 0
    for i in range(m):
        for j in range(i + 1, m):
            if mate[i] == j:
                continue
            g0 = c[i] - c[j]
            if g0 < 0.0:  # root at τ > 0
                xi = xa[i] if right[i] else xb[i]
                xj = xa[j] if right[j] else xb[j]
            else:
                xi = xb[i] if right[i] else xa[i]
                xj = xb[j] if right[j] else xa[j]
            tau = -g0 / (xj - xi)
            u = c[i] - xi * tau
            free = True
            if plain:
                xs = x_pos if tau > 0.0 else x_neg
                for l in range(i + 1, j):
                    if sgn[l] * ((c[l] - xs[l] * tau) - u) > 0.0:
                        free = False
                        break
            else:
                for l in range(i + 1, j):
                    if l != mate[i] and l != mate[j] and _crosses(l, tau, u, xa, xb, right, c, mate):
                        free = False
                        break
            if not free:
                continue
            if plain:  # no object along the line: the test of _crosses, branch-free
                xs = x_pos if tau > 0.0 else x_neg
                tl = -1
                for l in range(i - 1, -1, -1):
                    if sgn[l] * ((c[l] - xs[l] * tau) - u) > 0.0:
                        tl = l
                        break
                hd = -1
                for l in range(j + 1, m):
                    if sgn[l] * ((c[l] - xs[l] * tau) - u) > 0.0:
                        hd = l
                        break
            else:
                tl = -1
                for l in range(i - 1, -1, -1):
                    if l != mate[i] and _crosses(l, tau, u, xa, xb, right, c, mate):
                        tl = l
                        break
                hd = -1
                for l in range(j + 1, m):
                    if l != mate[j] and _crosses(l, tau, u, xa, xb, right, c, mate):
                        hd = l
                        break
            oi[cnt] = i
            oj[cnt] = j
            ot[cnt] = tau
            otl[cnt] = tl
            ohd[cnt] = hd
            obi[cnt] = xi == xb[i]
            obj_[cnt] = xj == xb[j]
            cnt += 1
    return oi[:cnt], oj[:cnt], ot[:cnt], otl[:cnt], ohd[:cnt], obi[:cnt], obj_[:cnt]


@nb.njit(cache=True)
def line_hits(ox, oy, dx, dy, eps, kind, vert_start, verts, radius):
    """Every object the whole line o + t d cuts deeper than eps (:func:`depth`), with its
    chord (t_in, t_out), in object order.  O(n): used once per degenerate line (a line
    touching several objects), instead of one grid walk per pair of touched objects."""
    n = kind.shape[0]
    hk = np.empty(n, np.int64)
    ti = np.empty(n)
    to = np.empty(n)
    cnt = 0
    for k in range(n):
        if depth(k, ox, oy, dx, dy, kind, vert_start, verts, radius) > eps:
            a, b = chord(k, ox, oy, dx, dy, kind, vert_start, verts, radius)
            hk[cnt] = k
            ti[cnt] = a
            to[cnt] = b
            cnt += 1
    return hk[:cnt], ti[:cnt], to[:cnt]


@nb.njit(cache=True)
def merge_ranks(cur, th, tau, occ, ncur, nth, ntau, nocc):
    """For each new incidence key (ncur, nth, ntau, nocc)[i], the number of keys of the
    lexicographically sorted (cur, th, tau, occ) smaller than it: where it goes when the
    two sorted lists are merged (binary search; O(new · log N))."""
    N = cur.shape[0]
    M = ncur.shape[0]
    out = np.empty(M, np.int64)
    for i in range(M):
        lo, hi = 0, N
        while lo < hi:
            j = (lo + hi) // 2
            if cur[j] != ncur[i]:
                less = cur[j] < ncur[i]
            elif th[j] != nth[i]:
                less = th[j] < nth[i]
            elif tau[j] != ntau[i]:
                less = tau[j] < ntau[i]
            else:
                less = occ[j] < nocc[i]
            if less:
                lo = j + 1
            else:
                hi = j
        out[i] = lo
    return out


@nb.njit(cache=True)
def curve_links(cur, inc):
    """Incidences sorted by curve (``cur``) with ids ``inc``: the next and previous position
    on the same curve (cyclic) and the sorted position of every incidence id (one pass)."""
    N = cur.shape[0]
    nxt = np.empty(N, np.int64)
    prv = np.empty(N, np.int64)
    posof = np.empty(N, np.int64)
    s = 0
    for p in range(N):
        posof[inc[p]] = p
        if p + 1 == N or cur[p + 1] != cur[p]:  # p ends the curve that starts at s
            for q in range(s, p):
                nxt[q] = q + 1
                prv[q + 1] = q
            nxt[p] = s
            prv[s] = p
            s = p + 1
    return nxt, prv, posof


# ----------------------------------------------------------------------------- topology arrays
@nb.njit(cache=True)
def vertex_incidences(posof, prv, x_after, z_after, comp, e_new, f_new, m):
    """The stored edges and faces of the m vertices (occurrence o = 0) in one pass (the
    arithmetic of :func:`complex.vertex_edges` and :func:`complex.six_faces`, without
    their (m, ·) temporaries).

    Parameters
    ----------
    posof : (2N,) int64  sorted position of every incidence (occ + role · 2m)
    prv : (N,) int64  previous position on the same curve
    x_after, z_after : (2m,) bool  per occurrence (:func:`complex.occurrences`)
    comp : (3N,) int64  face component of every slot (3 · position + slot)
    e_new : (N,) int64  stored edge of every position; f_new : (C,) int64 face of every component

    Returns v_edges (m, 4) int64 (k1 before, k1 after, k2 before, k2 after), v_faces (m, 6)
    int64 ((t,k1), (k1,k2), (t,k2), (k1,h), (t,h), (k2,h))."""
    n_occ = 2 * m
    v_edges = np.empty((m, 4), np.int64)
    v_faces = np.empty((m, 6), np.int64)
    for v in range(m):
        e1a = posof[v]
        e1b = prv[e1a]
        e2a = posof[v + n_occ]
        e2b = prv[e2a]
        X, Y = (e1a, e1b) if x_after[v] else (e1b, e1a)
        Z = e2a if z_after[v] else e2b
        v_edges[v, 0] = e_new[e1b]
        v_edges[v, 1] = e_new[e1a]
        v_edges[v, 2] = e_new[e2b]
        v_edges[v, 3] = e_new[e2a]
        v_faces[v, 0] = f_new[comp[3 * X]]
        v_faces[v, 1] = f_new[comp[3 * X + 1]]
        v_faces[v, 2] = f_new[comp[3 * X + 2]]
        v_faces[v, 3] = f_new[comp[3 * Y + 1]]
        v_faces[v, 4] = f_new[comp[3 * Y + 2]]
        v_faces[v, 5] = f_new[comp[3 * Z + 1]]
    return v_edges, v_faces


@nb.njit(cache=True)
def csr_rows(start, vals, rows, lut, shift):
    """The CSR lists of ``rows`` (R,) int64, in that order: (start (R + 1,), values); a
    row's list is vals[start[r]:start[r + 1]].  With a non-empty ``lut``, every value v
    (packed as id << shift | flags) is renumbered on the way: lut[v >> shift] << shift |
    the flags.  One pass of slice copies (a gather of the lists by np.repeat, then the
    renumbering, cost a few temporaries of the total length)."""
    R = rows.shape[0]
    new_start = np.empty(R + 1, np.int64)
    new_start[0] = 0
    for i in range(R):
        r = rows[i]
        new_start[i + 1] = new_start[i] + start[r + 1] - start[r]
    out = np.empty(new_start[R], vals.dtype)
    remap = lut.shape[0] > 0
    low = (1 << shift) - 1
    for i in range(R):
        s = start[rows[i]]
        if remap:
            for j in range(new_start[i], new_start[i + 1]):
                v = vals[s + j - new_start[i]]
                out[j] = lut[v >> shift] << shift | (v & low)
        else:
            out[new_start[i]:new_start[i + 1]] = vals[s:s + new_start[i + 1] - new_start[i]]
    return new_start, out


@nb.njit(cache=True)
def splice_rows(old, keep, ins, new):
    """The rows of ``old`` (N, w) where ``keep`` (N,) bool, in order, with row t of ``new``
    (M, w) placed after the first ins[t] kept rows (``ins`` ascending, as from
    :func:`merge_ranks`): a sorted array after a local change, by row copies (numpy's
    gathers and scatters by index cost several times more per row)."""
    N, M, w = old.shape[0], new.shape[0], old.shape[1]
    kept = 0
    for i in range(N):
        if keep[i]:
            kept += 1
    out = np.empty((kept + M, w), old.dtype)
    j = r = t = 0  # rows written, kept rows written, new rows written
    for i in range(N):
        if not keep[i]:
            continue
        while t < M and ins[t] == r:
            for c in range(w):  # element loops: a row slice per row costs more than the copy
                out[j, c] = new[t, c]
            j += 1
            t += 1
        for c in range(w):
            out[j, c] = old[i, c]
        j += 1
        r += 1
    while t < M:
        for c in range(w):
            out[j, c] = new[t, c]
        j += 1
        t += 1
    return out
