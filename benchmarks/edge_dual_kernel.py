"""Edge-dual form factor prototype: the per-edge-point kernel (numba).

For a point y on a 3-D edge e (unit direction t), the inner integral

    S(y) = Σ_regions coef · ∮_{∂R} ln|x − y| (t · dx)        (∂R counter-clockwise about n_i)

over the emitter points x for which y is a point of the contour of the visible part of j
(see benchmarks/edge_dual.py for the derivation and the signs). A_i F = (1/2π) Σ_e ∫_e S dl.

Everything happens in a 2-D frame (o, u, v) of the emitter's plane: the regions are the
convex base (emitter ∩ half-planes) minus the central projections through y of the
occluder faces (below y: shadows on the emitter's plane; above y, for occluder edges:
the faces between y and j, projected back through y). Faces whose plane holds y are
skipped; back faces of closed solids are culled unless y lies on one of the solid's
faces or behind all of its faces' planes (inside it, when it is convex: intersecting
solids). An edge of j in the emitter's plane is seen along grazing rays: only the faces
lying in that plane block, by their exact 2-D shadows from y.

edge_values' mode: 0 the values; 1 the regions' areas (side 0 + 1000 × side 1, for
checks); 2 the point's base and polygons into the dbg arrays; 5 the number of polygons
only (the cost of the projections).
"""

import numpy as np
from numba import njit

MAXV = 320  # vertices of one clipped polygon (faces of up to MAXV − 16 vertices: edge_dual.Pair checks)


@njit(cache=True)
def _clip(poly, n, dims, m0, m1, m2, d, out):
    """Sutherland–Hodgman of a polygon poly[:n] (its first ``dims`` coordinates, 2 or 3)
    against m·p − d ≥ 0 into out; returns the count."""
    k = 0
    if n == 0:
        return 0
    px, py = poly[n - 1, 0], poly[n - 1, 1]
    pz = poly[n - 1, 2] if dims == 3 else 0.0
    fp = m0 * px + m1 * py
    if dims == 3:
        fp += m2 * pz
    fp -= d
    for a in range(n):
        qx, qy = poly[a, 0], poly[a, 1]
        qz = poly[a, 2] if dims == 3 else 0.0
        fq = m0 * qx + m1 * qy
        if dims == 3:
            fq += m2 * qz
        fq -= d
        if ((fq >= 0.0 and fp < 0.0) or (fq < 0.0 and fp >= 0.0)) and k < MAXV:
            s = fp / (fp - fq)
            out[k, 0] = px + s * (qx - px)
            out[k, 1] = py + s * (qy - py)
            if dims == 3:
                out[k, 2] = pz + s * (qz - pz)
            k += 1
        if fq >= 0.0 and k < MAXV:
            out[k, 0] = qx
            out[k, 1] = qy
            if dims == 3:
                out[k, 2] = qz
            k += 1
        px, py, pz, fp = qx, qy, qz, fq
    return k


@njit(cache=True)
def _cone_planes(y, loop, n, centre, planes, offsets):
    """The planes through y and each edge of a convex loop (n, 3), normals towards its
    ``centre`` (the cone from y over it, inwards): ``planes[a]`` · p ≥ ``offsets[a]``."""
    for a in range(n):
        b2 = (a + 1) % n
        p0, p1, p2 = loop[a, 0] - y[0], loop[a, 1] - y[1], loop[a, 2] - y[2]
        q0, q1, q2 = loop[b2, 0] - y[0], loop[b2, 1] - y[1], loop[b2, 2] - y[2]
        m0, m1, m2 = p1 * q2 - p2 * q1, p2 * q0 - p0 * q2, p0 * q1 - p1 * q0
        if m0 * (centre[0] - y[0]) + m1 * (centre[1] - y[1]) + m2 * (centre[2] - y[2]) < 0:
            m0, m1, m2 = -m0, -m1, -m2
        planes[a, 0], planes[a, 1], planes[a, 2] = m0, m1, m2
        offsets[a] = m0 * y[0] + m1 * y[1] + m2 * y[2]


@njit(cache=True)
def _add_pieces(total, pieces, iv, m, x0, y0, x1, y1, mode, yx, yy, h, tx, ty):
    """``total`` plus each piece [a, b] of ``iv[:m]`` of the segment (x0, y0) → (x1, y1) (in
    parameter along it): its closed-form log integral (``mode`` 0) or its signed area term
    (else, a debug mode), added in order; and ``pieces`` plus m."""
    for r in range(m):
        a, b = iv[r, 0], iv[r, 1]
        if mode == 0:
            total += _log_piece(x0 + a * (x1 - x0), y0 + a * (y1 - y0), x0 + b * (x1 - x0), y0 + b * (y1 - y0),
                                yx, yy, h, tx, ty)
        else:
            total += 0.5 * ((x0 + a * (x1 - x0)) * (y0 + b * (y1 - y0)) - (x0 + b * (x1 - x0)) * (y0 + a * (y1 - y0)))
        pieces += 1
    return total, pieces


@njit(cache=True)
def _on_face(p, f, occ_n, occ_c, occ_lo, occ_hi, occ_pts, eps, slack):
    """Whether the point p (3,) lies within eps of face f's plane and inside its convex loop:
    on the inner side of each edge, or outside by at most ``slack`` (a distance)."""
    if abs(occ_n[f, 0] * p[0] + occ_n[f, 1] * p[1] + occ_n[f, 2] * p[2] - occ_c[f]) > eps:
        return False
    return _loop_margin(p, occ_pts, occ_lo[f], occ_hi[f], occ_n[f]) >= -slack


@njit(cache=True)
def _loop_margin(p, pts, lo, hi, normal):
    """The least distance of the point p (3,) inside the edges of the convex loop
    ``pts[lo:hi]`` (counter-clockwise about ``normal``), each edge's line in the loop's plane:
    negative outside (edges of no length left out)."""
    least = np.inf
    for a in range(lo, hi):
        b2 = a + 1 if a + 1 < hi else lo
        ex = pts[b2] - pts[a]
        w = p - pts[a]
        cr0 = ex[1] * w[2] - ex[2] * w[1]
        cr1 = ex[2] * w[0] - ex[0] * w[2]
        cr2 = ex[0] * w[1] - ex[1] * w[0]
        le = np.sqrt(ex[0] ** 2 + ex[1] ** 2 + ex[2] ** 2)
        d = (cr0 * normal[0] + cr1 * normal[1] + cr2 * normal[2]) / le
        if d == d:
            least = min(least, d)
    return least


@njit(cache=True)
def _clip_half_plane(poly, n, a, b, c, work):
    """A 2-D polygon poly[:n] clipped in place to a x + b y + c ≥ 0; where the line is no
    line (|a| + |b| ≤ 1e-14) the sign of c keeps all of it or nothing. Returns the count."""
    if abs(a) + abs(b) > 1e-14:
        n = _clip2(poly, n, -a, -b, c, work)
        for k in range(n):
            poly[k, 0], poly[k, 1] = work[k, 0], work[k, 1]
    elif c <= 0.0:
        n = 0
    return n


@njit(cache=True)
def _clip_to_cone(poly, n, planes, offsets, k, sign, work):
    """A 3-D polygon poly[:n] clipped in place to sign · (planes[a] · p − offsets[a]) ≥ 0 for
    a < k (a cone from y, or with sign −1 its reflection through y); returns the count."""
    for a in range(k):
        if n < 3:
            break
        n = _clip(poly, n, 3, sign * planes[a, 0], sign * planes[a, 1], sign * planes[a, 2], sign * offsets[a], work)
        poly[:n] = work[:n]
    return n


@njit(cache=True)
def _clip3(poly, n, m, d, out):
    """:func:`_clip` of a 3-D polygon against m·p − d ≥ 0."""
    return _clip(poly, n, 3, m[0], m[1], m[2], d, out)


@njit(cache=True)
def _clip2(poly, n, ax, ay, b, out):
    """:func:`_clip` of a 2-D polygon against ax x + ay y ≤ b, i.e. −a·p + b ≥ 0 (the
    negations are exact: the same digits as b − a·p)."""
    return _clip(poly, n, 2, -ax, -ay, 0.0, -b, out)


@njit(cache=True)
def _area2(poly, n):
    s = 0.0
    for a in range(n):
        b = (a + 1) % n
        s += poly[a, 0] * poly[b, 1] - poly[b, 0] * poly[a, 1]
    return 0.5 * s


@njit(cache=True)
def _thickness(poly, n, tol):
    """Width of a convex polygon: the least over its edges of the farthest vertex from the edge's line."""
    best = 1e300
    for e in range(n):
        f = (e + 1) % n
        ex, ey = poly[f, 0] - poly[e, 0], poly[f, 1] - poly[e, 1]
        le = np.sqrt(ex * ex + ey * ey)
        if le <= tol:
            continue  # a vanishing edge: its direction is noise
        far = 0.0
        for a in range(n):
            d = abs((poly[a, 0] - poly[e, 0]) * ey - (poly[a, 1] - poly[e, 1]) * ex) / le
            if d > far:
                far = d
        if far < best:
            best = far
    return best


@njit(cache=True)
def _log_piece(px, py, qx, qy, yx, yy, h, tx, ty):
    """∫_p^q ln|x − y| (t · dx) along a straight piece (y above the plane by h)."""
    dx, dy = qx - px, qy - py
    L = np.sqrt(dx * dx + dy * dy)
    if L <= 0.0:
        return 0.0
    ex, ey = dx / L, dy / L
    wx, wy = yx - px, yy - py
    s0 = wx * ex + wy * ey
    cp = wx * ey - wy * ex
    c2 = cp * cp + h * h
    c = np.sqrt(c2)
    hi = L - s0
    lo = -s0
    gh = 0.0
    gl = 0.0
    if hi * hi + c2 > 0.0:
        gh = hi * np.log(hi * hi + c2)
    if lo * lo + c2 > 0.0:
        gl = lo * np.log(lo * lo + c2)
    val = 0.5 * (gh - gl) - (hi - lo)
    if c > 0.0:
        val += c * (np.arctan(hi / c) - np.arctan(lo / c))
    return val * (tx * ex + ty * ey)


@njit(cache=True)
def _cover(x0, y0, x1, y1, poly, n, same_ok, tol):
    """Parameter interval [a, b] of the segment (x0,y0)→(x1,y1) inside the open convex
    polygon poly[:n] (counter-clockwise); an edge of poly collinear with the segment and of
    the same direction counts as inside when ``same_ok``. Returns (a, b) with b ≤ a if none."""
    a, b = 0.0, 1.0
    dxs, dys = x1 - x0, y1 - y0
    ls = np.sqrt(dxs * dxs + dys * dys)
    if ls <= 0.0:
        return 1.0, 0.0
    for e in range(n):
        f = (e + 1) % n
        ex, ey = poly[f, 0] - poly[e, 0], poly[f, 1] - poly[e, 1]
        le = np.sqrt(ex * ex + ey * ey)
        if le <= 0.0:
            continue
        if le <= tol:
            continue  # a vanishing edge (a doubled vertex): its direction is noise
        nx, ny = -ey / le, ex / le  # inward (left) normal
        f0 = nx * (x0 - poly[e, 0]) + ny * (y0 - poly[e, 1])
        f1 = nx * (x1 - poly[e, 0]) + ny * (y1 - poly[e, 1])
        # collinear (the same test both ways round): parallel, and the lines within tol
        if abs(ex * dys - ey * dxs) <= 1e-9 * le * ls and abs(0.5 * (f0 + f1)) <= tol:
            if same_ok and ex * dxs + ey * dys > 0.0:
                continue
            return 1.0, 0.0
        # f(τ) = f0 + τ (f1 − f0) > tol
        if f0 > tol and f1 > tol:
            continue
        if f0 <= tol and f1 <= tol:
            return 1.0, 0.0
        tau = (tol - f0) / (f1 - f0)
        if f1 > f0:
            if tau > a:
                a = tau
        else:
            if tau < b:
                b = tau
        if b <= a:
            return 1.0, 0.0
    return a, b


@njit(cache=True)
def _subtract(iv, m, a, b, out):
    """Remove (a, b) from the sorted disjoint intervals iv[:m] (in place, out a scratch
    array); returns the count."""
    k = 0
    for r in range(m):
        lo, hi = iv[r, 0], iv[r, 1]
        if b <= lo or a >= hi:
            out[k, 0], out[k, 1] = lo, hi
            k += 1
            continue
        if a > lo:
            out[k, 0], out[k, 1] = lo, a
            k += 1
        if b < hi:
            out[k, 0], out[k, 1] = b, hi
            k += 1
    for r in range(k):
        iv[r, 0], iv[r, 1] = out[r, 0], out[r, 1]
    return k


@njit(cache=True)
def _region_integral(base, nb, polys, plen, npoly, yx, yy, h, tx, ty, tol, work, work2, mode, scratch):
    """∮ ln|x − y| t·dx over the boundary of (convex base) minus the union of the polygons,
    the polygons first clipped to the base. Returns (value, pieces)."""
    # clip the polygons to the base
    clipped, clen, bxs, iv, ivs = scratch
    bx0, by0, bx1, by1 = bxs[0], bxs[1], bxs[2], bxs[3]
    kk = 0
    for p in range(npoly):
        n = plen[p]
        for a in range(n):
            work[a, 0], work[a, 1] = polys[p, a, 0], polys[p, a, 1]
        for e in range(nb):
            f = (e + 1) % nb
            ex, ey = base[f, 0] - base[e, 0], base[f, 1] - base[e, 1]
            # inside: left of the edge: −ey (x − bx) + ex (y − by) ≥ 0  ⇔  ey x − ex y ≤ ey bx − ex by
            n = _clip2(work, n, ey, -ex, ey * base[e, 0] - ex * base[e, 1], work2)
            for a in range(n):
                work[a, 0], work[a, 1] = work2[a, 0], work2[a, 1]
            if n < 3:
                break
        if n < 3:
            continue
        # doubled vertices (within tol) merged
        m = 0
        for a in range(n):
            if m > 0 and abs(work[a, 0] - work[m - 1, 0]) <= tol and abs(work[a, 1] - work[m - 1, 1]) <= tol:
                continue
            work[m, 0], work[m, 1] = work[a, 0], work[a, 1]
            m += 1
        while m > 1 and abs(work[m - 1, 0] - work[0, 0]) <= tol and abs(work[m - 1, 1] - work[0, 1]) <= tol:
            m -= 1
        n = m
        if n < 3:
            continue
        if _area2(work, n) <= tol * tol or _thickness(work, n, tol) <= 8.0 * tol:
            continue  # a sliver (an edge of the base, or one seen edge-on): measure zero
        for a in range(n):
            clipped[kk, a, 0], clipped[kk, a, 1] = work[a, 0], work[a, 1]
        clen[kk] = n
        bx0[kk], by0[kk] = work[:n, 0].min(), work[:n, 1].min()
        bx1[kk], by1[kk] = work[:n, 0].max(), work[:n, 1].max()
        kk += 1
    total = 0.0
    pieces = 0
    # the base's edges, as they go, minus the polygons' interiors
    for e in range(nb):
        f = (e + 1) % nb
        x0, y0, x1, y1 = base[e, 0], base[e, 1], base[f, 0], base[f, 1]
        m = 1
        iv[0, 0], iv[0, 1] = 0.0, 1.0
        sx0, sx1, sy0, sy1 = min(x0, x1), max(x0, x1), min(y0, y1), max(y0, y1)
        for q in range(kk):
            if bx0[q] > sx1 + tol or bx1[q] < sx0 - tol or by0[q] > sy1 + tol or by1[q] < sy0 - tol:
                continue
            a, b = _cover(x0, y0, x1, y1, clipped[q], clen[q], False, tol)
            if b > a:
                m = _subtract(iv, m, a, b, ivs)
                if m == 0:
                    break
        total, pieces = _add_pieces(total, pieces, iv, m, x0, y0, x1, y1, mode, yx, yy, h, tx, ty)
    # the polygons' edges, reversed, minus the other polygons (a collinear edge of the same
    # direction of an earlier polygon covers it)
    for p in range(kk):
        n = clen[p]
        for e in range(n):
            f = (e + 1) % n
            x0, y0, x1, y1 = clipped[p, f, 0], clipped[p, f, 1], clipped[p, e, 0], clipped[p, e, 1]
            m = 1
            iv[0, 0], iv[0, 1] = 0.0, 1.0
            sx0, sx1, sy0, sy1 = min(x0, x1), max(x0, x1), min(y0, y1), max(y0, y1)
            for q in range(kk):
                if q == p:
                    continue
                if bx0[q] > sx1 + tol or bx1[q] < sx0 - tol or by0[q] > sy1 + tol or by1[q] < sy0 - tol:
                    continue
                # reversed edges: an earlier polygon's reversed edge has the same direction as
                # ours when their forward edges do
                a, b = _cover(x1, y1, x0, y0, clipped[q], clen[q], q < p, tol)
                if b > a:
                    m = _subtract(iv, m, 1.0 - b, 1.0 - a, ivs)
                    if m == 0:
                        break
            total, pieces = _add_pieces(total, pieces, iv, m, x0, y0, x1, y1, mode, yx, yy, h, tx, ty)
    return total, pieces


@njit(cache=True)
def edge_values(ys, kind, t, n1, c1, n2, c2,
                o, u, v, n_i, c_i, i2, i3,
                j3, n_j, c_j, s_j, j_cen,
                occ_pts, occ_lo, occ_hi, occ_n, occ_c, occ_closed, occ_solid, n_solids, eps, mode,
                dbg_base, dbg_polys, dbg_plen, dbg_n, graze):
    """S(y) at the points ys (m, 3) of one edge.

    kind: 0 an edge of j; 1 an occluder edge of one face (plane n1, c1, the edge running
    counter-clockwise about n1 along t); 2 an edge of two faces (the second n2, c2: its loop
    runs along −t).

    Returns (values (m,), flags (m,)): flags 1 where y lies in the emitter's plane (not
    handled: 0 returned), 0 else.
    """
    m_pts = ys.shape[0]
    out = np.zeros(m_pts)
    flags = np.zeros(m_pts, np.int64)
    nf = occ_lo.shape[0]
    ni = i2.shape[0]
    nj = j3.shape[0]
    work3 = np.empty((MAXV, 3))
    work3b = np.empty((MAXV, 3))
    work = np.empty((MAXV, 2))
    work2 = np.empty((MAXV, 2))
    polys = np.empty((2 * nf + 1, MAXV, 2))
    plen = np.zeros(2 * nf + 1, np.int64)
    base = np.empty((MAXV, 2))
    base2 = np.empty((MAXV, 2))
    hp = np.empty(6)  # half-planes of the regions (ax, ay, b) × 2
    tx = t[0] * u[0] + t[1] * u[1] + t[2] * u[2]
    ty = t[0] * v[0] + t[1] * v[1] + t[2] * v[2]
    scratch = (np.empty((2 * nf + 1, MAXV, 2)), np.zeros(2 * nf + 1, np.int64), np.empty((4, 2 * nf + 1)),
               np.empty((4096, 2)), np.empty((4097, 2)))
    cone_i = np.empty((ni, 3))
    cone_i_d = np.empty(ni)
    cone_j = np.empty((nj, 3))
    cone_j_d = np.empty(nj)
    neg_n_i = -n_i
    neg_sn_j = -s_j * n_j
    cen_i = np.zeros(3)
    for a in range(i3.shape[0]):
        cen_i += i3[a]
    cen_i /= i3.shape[0]
    for k in range(m_pts):
        y = ys[k]
        h = n_i[0] * y[0] + n_i[1] * y[1] + n_i[2] * y[2] - c_i
        grazing = False
        if h <= eps:
            if kind != 0 or h < -eps:
                flags[k] = 1
                continue
            # an edge of j in i's plane, seen along grazing rays: taken at y moved by
            # GRAZE into j (its limit; the error is O(GRAZE ln GRAZE))
            wx = n_j[1] * t[2] - n_j[2] * t[1]
            wy = n_j[2] * t[0] - n_j[0] * t[2]
            wz = n_j[0] * t[1] - n_j[1] * t[0]
            up = wx * n_i[0] + wy * n_i[1] + wz * n_i[2]
            if up <= 0.0:
                continue
            d = graze / up
            yj = np.array([y[0] + d * wx, y[1] + d * wy, y[2] + d * wz])  # just inside j
            h = 0.0
            grazing = True
            flags[k] = 2
            # covered: the point of j next to y lies under a face lying on j
            covered = False
            for f in range(nf):
                if _on_face(yj, f, occ_n, occ_c, occ_lo, occ_hi, occ_pts, eps, 0.0):
                    covered = True
                    break
            if covered:
                continue
        y0 = ys[k]
        yx = (y0[0] - o[0]) * u[0] + (y0[1] - o[1]) * u[1] + (y0[2] - o[2]) * u[2]
        yy = (y0[0] - o[0]) * v[0] + (y0[1] - o[1]) * v[1] + (y0[2] - o[2]) * v[2]
        hl = 0.0 if grazing else h  # the log integral at the point itself
        # ---- the base: i ∩ (x on j's side) [∩ the projection of j through y]
        nb = ni
        for a in range(ni):
            base[a, 0], base[a, 1] = i2[a, 0], i2[a, 1]
        nju = n_j[0] * u[0] + n_j[1] * u[1] + n_j[2] * u[2]
        njv = n_j[0] * v[0] + n_j[1] * v[1] + n_j[2] * v[2]
        njo = n_j[0] * o[0] + n_j[1] * o[1] + n_j[2] * o[2] - c_j
        dj = n_j[0] * y[0] + n_j[1] * y[1] + n_j[2] * y[2] - c_j
        upper = False
        if kind == 0:
            lim = 0.0
        else:
            if abs(dj) <= eps:
                # y on j's plane: the ray past y meets j at once where y is inside j
                inside = _loop_margin(y, j3, 0, nj, n_j) > eps
                if not inside:
                    continue
                lim = 0.0
            else:
                if s_j * dj < 0.0:
                    continue
                lim = s_j * dj
                upper = True
        # s_j (n_j·X − c_j) > lim   ⇔   −s_j (nju, njv)·x ≤ s_j njo − lim
        nb = _clip_half_plane(base, nb, s_j * nju, s_j * njv, s_j * njo - lim, work2)
        if upper and nb >= 3:
            # the ray from x through y meets j: planes through y and j's edges
            for a in range(nj):
                b2 = (a + 1) % nj
                pa = j3[a] - y
                pb = j3[b2] - y
                mm = np.array([pa[1] * pb[2] - pa[2] * pb[1], pa[2] * pb[0] - pa[0] * pb[2], pa[0] * pb[1] - pa[1] * pb[0]])
                ref = mm[0] * (j_cen[0] - y[0]) + mm[1] * (j_cen[1] - y[1]) + mm[2] * (j_cen[2] - y[2])
                sg = 1.0 if ref > 0 else -1.0
                # sg · mm · (y − X) > 0  ⇔  sg mm·X < sg mm·y ; X = o + x u + y v
                mu = mm[0] * u[0] + mm[1] * u[1] + mm[2] * u[2]
                mv = mm[0] * v[0] + mm[1] * v[1] + mm[2] * v[2]
                rhs = mm[0] * (y[0] - o[0]) + mm[1] * (y[1] - o[1]) + mm[2] * (y[2] - o[2])
                nb = _clip2(base, nb, sg * mu, sg * mv, sg * rhs, work2)
                for q in range(nb):
                    base[q, 0], base[q, 1] = work2[q, 0], work2[q, 1]
                if nb < 3:
                    break
        if nb < 3 or _thickness(base, nb, eps) <= 8.0 * eps:
            continue
        # ---- the polygons to take away: faces below y projected through y; above y (occluder
        # edges only) those between y and j
        npoly = 0
        if grazing:
            # along grazing rays (in i's plane) only the faces lying in i's plane block: each
            # with its 2-D shadow from y (the cone from y over it, beyond its front edges)
            for f in range(nf):
                lo, hi = occ_lo[f], occ_hi[f]
                nv = hi - lo
                flat = True
                for a in range(nv):
                    p = occ_pts[lo + a]
                    if abs(n_i[0] * p[0] + n_i[1] * p[1] + n_i[2] * p[2] - c_i) > eps:
                        flat = False
                        break
                if not flat:
                    continue
                for a in range(nv):
                    p = occ_pts[lo + a]
                    work2[a, 0] = (p[0] - o[0]) * u[0] + (p[1] - o[1]) * u[1] + (p[2] - o[2]) * u[2]
                    work2[a, 1] = (p[0] - o[0]) * v[0] + (p[1] - o[1]) * v[1] + (p[2] - o[2]) * v[2]
                if _area2(work2, nv) < 0.0:
                    for a in range(nv // 2):
                        tmp0, tmp1 = work2[a, 0], work2[a, 1]
                        work2[a, 0], work2[a, 1] = work2[nv - 1 - a, 0], work2[nv - 1 - a, 1]
                        work2[nv - 1 - a, 0], work2[nv - 1 - a, 1] = tmp0, tmp1
                cx, cy = 0.0, 0.0
                for a in range(nv):
                    cx += work2[a, 0] / nv
                    cy += work2[a, 1] / nv
                n = nb
                for a in range(nb):
                    work[a, 0], work[a, 1] = base[a, 0], base[a, 1]
                front = np.zeros(nv, np.bool_)
                for a in range(nv):
                    b2 = (a + 1) % nv
                    ex, ey = work2[b2, 0] - work2[a, 0], work2[b2, 1] - work2[a, 1]
                    # y outside this edge (on its right): a front edge; keep its left side
                    side = ex * (yy - work2[a, 1]) - ey * (yx - work2[a, 0])
                    front[a] = side < 0.0
                inside_all = True
                for a in range(nv):
                    if front[a]:
                        inside_all = False
                if inside_all:
                    continue  # y inside the polygon (covered; not expected here)
                for a in range(nv):
                    b2 = (a + 1) % nv
                    ex, ey = work2[b2, 0] - work2[a, 0], work2[b2, 1] - work2[a, 1]
                    if front[a] and n >= 3:
                        # left of the edge: −ey (x − ax) + ex (y − ay) ≥ 0 ⇔ ey x − ex y ≤ ey ax − ex ay
                        n = _clip2(work, n, ey, -ex, ey * work2[a, 0] - ex * work2[a, 1], base2)
                        for q in range(n):
                            work[q, 0], work[q, 1] = base2[q, 0], base2[q, 1]
                    # a tangent vertex (front and back edges meet at b2): the cone's side
                    if front[a] != front[b2] and n >= 3:
                        vx, vy = work2[b2, 0], work2[b2, 1]
                        lx, ly = vx - yx, vy - yy
                        # keep the centroid's side of the line y → v
                        sc = lx * (cy - yy) - ly * (cx - yx)
                        sg = 1.0 if sc > 0 else -1.0
                        # sg (lx (Y − yy) − ly (X − yx)) ≥ 0 ⇔ sg ly X − sg lx Y ≤ sg (ly yx − lx yy)
                        n = _clip2(work, n, sg * ly, -sg * lx, sg * (ly * yx - lx * yy), base2)
                        for q in range(n):
                            work[q, 0], work[q, 1] = base2[q, 0], base2[q, 1]
                if n < 3:
                    continue
                for a in range(n):
                    polys[npoly, a, 0], polys[npoly, a, 1] = work[a, 0], work[a, 1]
                plen[npoly] = n
                npoly += 1
        # a closed solid with y on one of its faces: rays from y into it leave through its
        # back faces, so those are not culled for this y
        touched = np.zeros(n_solids + 1, np.bool_)
        for f in range(nf if not grazing else 0):
            if occ_solid[f] >= 0 and _on_face(y, f, occ_n, occ_c, occ_lo, occ_hi, occ_pts, eps, eps):
                touched[occ_solid[f]] = True
        # a closed solid with y inside it (y behind all its faces' planes: its inside when it is
        # convex; solids may intersect, or a face may pass through one): rays from y leave
        # through its back faces, so those are not culled either
        outside = np.zeros(n_solids + 1, np.bool_)
        for f in range(nf if not grazing else 0):
            if occ_solid[f] < 0:
                continue
            dn = occ_n[f, 0] * y[0] + occ_n[f, 1] * y[1] + occ_n[f, 2] * y[2] - occ_c[f]
            if dn > eps:
                outside[occ_solid[f]] = True
        for q in range(n_solids):
            if not outside[q]:
                touched[q] = True
        # the planes through y and the edges of i (the cone over i, inwards) and of j
        _cone_planes(y, i3, ni, cen_i, cone_i, cone_i_d)
        _cone_planes(y, j3, nj, j_cen, cone_j, cone_j_d)
        for f in range(nf if not grazing else 0):
            dn = occ_n[f, 0] * y[0] + occ_n[f, 1] * y[1] + occ_n[f, 2] * y[2] - occ_c[f]
            if abs(dn) <= eps:
                continue  # y in the face's plane: the face is seen edge-on
            if occ_closed[f] and dn < 0.0 and not touched[occ_solid[f]]:
                continue  # a back face of a closed solid: its front faces cover it
            lo, hi = occ_lo[f], occ_hi[f]
            nv = hi - lo
            hmin, hmax = 1e300, -1e300
            for a in range(nv):
                p = occ_pts[lo + a]
                hh = n_i[0] * p[0] + n_i[1] * p[1] + n_i[2] * p[2] - c_i
                hmin = min(hmin, hh)
                hmax = max(hmax, hh)
            for part in range(2):
                if part == 0 and hmin >= h:
                    continue
                if part == 1 and (not upper or hmax <= h):
                    continue
                for a in range(nv):
                    work3[a] = occ_pts[lo + a]
                n = nv
                if part == 0:
                    # below y: h_p ≤ h − eps (n_i·p ≤ c_i + h − eps): a vertex at y's height would
                    # project to infinity (h / 0); the part cut off projects beyond ~h |p − y| / eps
                    n = _clip3(work3, n, neg_n_i, -(c_i + h - eps), work3b)
                    work3[:n] = work3b[:n]
                    # in the cone from y over i
                    n = _clip_to_cone(work3, n, cone_i, cone_i_d, ni, 1.0, work3b)
                else:
                    n = _clip3(work3, n, n_i, c_i + h + eps, work3b)
                    work3[:n] = work3b[:n]
                    # between y and j: j's side of j's plane ... up to j's plane
                    if n >= 3:
                        n = _clip3(work3, n, neg_sn_j, -s_j * c_j - lim, work3b)
                        work3[:n] = work3b[:n]
                    n = _clip_to_cone(work3, n, cone_j, cone_j_d, nj, 1.0, work3b)
                    n = _clip_to_cone(work3, n, cone_i, cone_i_d, ni, -1.0, work3b)  # the reflected cone: beyond y
                if n < 3:
                    continue
                # project through y onto i's plane, to 2-D
                for a in range(n):
                    p = work3[a]
                    hh = n_i[0] * p[0] + n_i[1] * p[1] + n_i[2] * p[2] - c_i
                    s = h / (h - hh)
                    X0 = y[0] + (p[0] - y[0]) * s - o[0]
                    X1 = y[1] + (p[1] - y[1]) * s - o[1]
                    X2 = y[2] + (p[2] - y[2]) * s - o[2]
                    work[a, 0] = X0 * u[0] + X1 * u[1] + X2 * u[2]
                    work[a, 1] = X0 * v[0] + X1 * v[1] + X2 * v[2]
                ar = _area2(work, n)
                if abs(ar) <= eps * eps:
                    continue
                if ar > 0:
                    for a in range(n):
                        polys[npoly, a, 0], polys[npoly, a, 1] = work[a, 0], work[a, 1]
                else:
                    for a in range(n):
                        polys[npoly, a, 0], polys[npoly, a, 1] = work[n - 1 - a, 0], work[n - 1 - a, 1]
                plen[npoly] = n
                npoly += 1
        # ---- the regions
        if mode == 5:
            out[k] = npoly  # the cost of the projections alone, and how many polygons
            continue
        if mode == 2:
            dbg_n[0] = nb
            dbg_n[1] = npoly
            for a in range(nb):
                dbg_base[a, 0], dbg_base[a, 1] = base[a, 0], base[a, 1]
            for q in range(npoly):
                dbg_plen[q] = plen[q]
                for a in range(plen[q]):
                    dbg_polys[q, a, 0], dbg_polys[q, a, 1] = polys[q, a, 0], polys[q, a, 1]
        if kind == 0:
            val, _ = _region_integral(base, nb, polys, plen, npoly, yx, yy, hl, tx, ty, eps, work, work2, mode, scratch)
            out[k] = s_j * val
            continue
        # silhouette regions: front of face 1 (and behind face 2): coefficient −1; behind face 1
        # (and in front of face 2): +1
        d1u = n1[0] * u[0] + n1[1] * u[1] + n1[2] * u[2]
        d1v = n1[0] * v[0] + n1[1] * v[1] + n1[2] * v[2]
        d1o = n1[0] * (o[0] - y[0]) + n1[1] * (o[1] - y[1]) + n1[2] * (o[2] - y[2])
        d2u = n2[0] * u[0] + n2[1] * u[1] + n2[2] * u[2]
        d2v = n2[0] * v[0] + n2[1] * v[1] + n2[2] * v[2]
        d2o = n2[0] * (o[0] - y[0]) + n2[1] * (o[1] - y[1]) + n2[2] * (o[2] - y[2])
        total = 0.0
        for side in range(2):
            sg1 = 1.0 if side == 0 else -1.0  # side 0: front of 1 (n1·(X − y) > 0)
            coef = -1.0 if side == 0 else 1.0
            n = nb
            for a in range(nb):
                base2[a, 0], base2[a, 1] = base[a, 0], base[a, 1]
            # sg1 n1·(X − y) ≥ 0 ⇔ −sg1 (d1u, d1v)·x ≤ sg1 d1o
            n = _clip_half_plane(base2, n, sg1 * d1u, sg1 * d1v, sg1 * d1o, work2)
            if kind == 2 and n >= 3:
                sg2 = -sg1  # the other face the other way
                n = _clip_half_plane(base2, n, sg2 * d2u, sg2 * d2v, sg2 * d2o, work2)
            if n < 3 or abs(_area2(base2, n)) <= eps * eps or _thickness(base2, n, eps) <= 8.0 * eps:
                continue
            val, _ = _region_integral(base2, n, polys, plen, npoly, yx, yy, hl, tx, ty, eps, work, work2, mode, scratch)
            if mode == 1:
                total += (1.0 if side == 0 else 1000.0) * val
                continue
            total += coef * val
        out[k] = total
    return out, flags
