"""Discontinuity mesh and radiosity in flatland (Orti et al. §4.2, eq. 1).

Mesh
----
The complex's vertices are the visibility discontinuities: a free bitangent touches k1 at p
and k2 at q and ends on its tail and head objects; those four points cut the objects'
boundaries.  We also cut every polygon at its corners and every circle at its four
quadrant points, so that an element's outward normals span at most π/2 (this keeps the
set of exit points of a line family inside an element one arc, see below).  Positions on
object k are arc lengths s ∈ [0, L_k) counter-clockwise from the contact point of
piece 0 (a circle: angle·r from the +x axis; a polygon: from its first corner).

Element form factors from the complex
-------------------------------------
For the face a→b (oriented lines leaving O_a and next meeting O_b) and a fixed direction
θ, the face is the u-interval (lo(θ), hi(θ)) between its lower and upper chains (closed
forms on every edge).  As u grows the exit point from O_a moves monotonically (counter-
clockwise) along the forward half of ∂O_a, from the left tangent point to the right one,
and the entry point into O_b moves clockwise along its back half.  So the lines of the
face that leave element e ⊂ ∂O_a and meet element f ⊂ ∂O_b are, at θ, the interval

    (max(lo, u(e_start)), min(hi, u(e_end))) ∩ (max(·, u(f_end)), min(·, u(f_start)))

with u(x) = n(θ)·x for an element end x inside the forward (backward) half, or the tangent
u of O_a (O_b) when the element reaches past it.  Its length is the u-measure; the form
factor measure M_ef is its θ-integral.  Every bound is a sinusoid n(θ)·P + c, so the
integrand is smooth between the θ where two bounds cross (closed form, like the
bitangents), where a chain changes edge, where a polygon's support point changes, or
where an element end enters a half (θ = normal ± π/2).  We split at all those θ and use
Gauss–Legendre on each smooth piece (exponentially convergent; checked against the
complex's exact face areas: Σ_e,f M_ef = A_ab to 1e-9).

    F_ef = M_ef / (2 L_e),      L_e F_ef = L_f F_fe,      Σ_f F_ef + F_e,sky = 1.

Radiosity: B = E + ρ F B per element, solved by Gauss–Seidel iteration (Σ_f F_ef ≤ 1 and
ρ < 1 make it a contraction), compared in the tests with a dense ``numpy.linalg.solve``.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from viscx.errors import ViscxError
from viscx.flatland import kernels as K
from viscx.flatland.scene import SKY

TWO_PI = 2.0 * math.pi
HALF_PI = 0.5 * math.pi
_GL_X, _GL_W = np.polynomial.legendre.leggauss(6)


# ----------------------------------------------------------------------------- positions
def arc_position(scene, k, x, d=None, exit_side=False):
    """(N,) arc length s ∈ [0, L_k) of boundary points x (N, 2) of object k.  With ray
    directions d (N, 2): the point where the ray enters k (``exit_side``: leaves it), i.e.
    on an edge whose outward normal faces against d (along d) — on a segment both sides
    pass through x, and only the direction tells them apart."""
    A, cumG, cumS, perim = scene.pieces()
    s0, e0 = scene.vert_start[k], scene.vert_start[k + 1]
    v = scene.verts[s0:e0]
    if e0 - s0 == 1:
        ang = np.arctan2(x[:, 1] - v[0, 1], x[:, 0] - v[0, 0])
        return np.mod(ang, TWO_PI) * scene.radius[k]
    # closest edge (x lies on the boundary up to rounding)
    a, b = v, np.roll(v, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("nij,ij->ni", x[:, None, :] - a[None], ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
    proj = a[None] + t[..., None] * ab[None]
    dist = np.linalg.norm(x[:, None, :] - proj, axis=2)
    if d is not None:  # a tie between the two sides of a segment goes to the side the ray meets
        facing = d @ np.stack([ab[:, 1], -ab[:, 0]], 1).T                   # (N, m) d · outward normal
        wrong = facing < 0 if exit_side else facing > 0
        dist = dist + wrong * 1e-9 * (1.0 + np.abs(v).max())
    j = np.argmin(dist, axis=1)
    elen = np.linalg.norm(ab, axis=1)
    return np.mod(cumS[s0 + j] + t[np.arange(len(j)), j] * elen[j], perim[k])


def point_at(scene, k, s):
    """(N, 2) boundary points of object k at arc lengths s (N,)."""
    A, cumG, cumS, perim = scene.pieces()
    s0, e0 = scene.vert_start[k], scene.vert_start[k + 1]
    v = scene.verts[s0:e0]
    s = np.mod(s, perim[k])
    if e0 - s0 == 1:
        a = s / scene.radius[k]
        return v[0] + scene.radius[k] * np.stack([np.cos(a), np.sin(a)], axis=-1)
    cs = cumS[s0:e0]
    j = np.clip(np.searchsorted(cs, s, side="right") - 1, 0, e0 - s0 - 1)
    b = np.roll(v, -1, axis=0)
    elen = np.linalg.norm(b - v, axis=1)
    t = (s - cs[j]) / elen[j]
    return v[j] + t[:, None] * (b[j] - v[j])


def normal_angles(scene, k, s):
    """(N, 2) range [ψ0, ψ1] of outward normal angles at arc positions s (a polygon corner
    has a range, every other point a single normal)."""
    A, cumG, cumS, perim = scene.pieces()
    s0, e0 = scene.vert_start[k], scene.vert_start[k + 1]
    if e0 - s0 == 1:
        a = np.mod(s, perim[k]) / scene.radius[k]
        return np.stack([a, a], 1)
    cs = cumS[s0:e0]
    Ak = A[s0:e0]
    Aend = np.append(Ak[1:], Ak[0] + TWO_PI)
    s = np.mod(s, perim[k])
    j = np.clip(np.searchsorted(cs, s, side="right") - 1, 0, e0 - s0 - 1)
    at_corner = np.abs(s - cs[j]) <= 1e-12 * perim[k]
    # on edge j (between corner j and j+1) the normal is the piece boundary Aend[j]
    lo = np.where(at_corner, Ak[j], Aend[j])
    return np.stack([lo, Aend[j]], 1)


# ----------------------------------------------------------------------------- mesh
def discontinuity_mesh(cx):
    """Elements of every object cut at the complex's discontinuity points.

    Returns a dict: ``elem_obj`` (N,) int64, ``elem_s`` (N, 2) float64 arc-length range
    (s1 may exceed L_k when the element wraps past 0), ``elem_length`` (N,), ``obj_elem_start``
    (n+1,) int64 CSR, ``cut_obj`` / ``cut_s`` the discontinuity points used."""
    scene = cx.scene
    n = scene.n
    perim = scene.perimeters()
    pts_obj, pts_x = [], []
    if cx.n_vertices:
        pts_obj += [cx.v_obj[:, 0], cx.v_obj[:, 1]]
        pts_x += [cx.v_p, cx.v_q]
        for col, ends in ((cx.v_tail, cx.v_seg[:, :2]), (cx.v_head, cx.v_seg[:, 2:])):
            m = col >= 0
            pts_obj.append(col[m])
            pts_x.append(ends[m])
    pts_obj = np.concatenate(pts_obj) if pts_obj else np.zeros(0, np.int64)
    pts_x = np.concatenate(pts_x) if pts_x else np.zeros((0, 2))
    A, cumG, cumS, _ = scene.pieces()
    e_obj, e_s, cut_obj, cut_s = [], [], [], []
    starts = [0]
    for k in range(n):
        s0, e0 = scene.vert_start[k], scene.vert_start[k + 1]
        L = perim[k]
        fixed = np.arange(4) * L / 4 if e0 - s0 == 1 else cumS[s0:e0]
        disc = arc_position(scene, k, pts_x[pts_obj == k]) if np.any(pts_obj == k) else np.zeros(0)
        cut_obj.append(np.full(disc.shape, k))
        cut_s.append(disc)
        s = np.sort(np.mod(np.concatenate([fixed, disc]), L))
        keep = np.ones(s.shape, bool)
        keep[1:] = np.diff(s) > 1e-10 * L
        s = s[keep]
        if s.size > 1 and (s[0] + L - s[-1]) <= 1e-10 * L:
            s = s[:-1]
        e_s.append(np.stack([s, np.append(s[1:], s[0] + L)], 1))
        e_obj.append(np.full(s.shape, k))
        starts.append(starts[-1] + s.size)
    elem_s = np.concatenate(e_s)
    return dict(elem_obj=np.concatenate(e_obj).astype(np.int64), elem_s=elem_s, elem_length=elem_s[:, 1] - elem_s[:, 0],
                obj_elem_start=np.array(starts, np.int64), cut_obj=np.concatenate(cut_obj).astype(np.int64),
                cut_s=np.concatenate(cut_s))


# ----------------------------------------------------------------------------- sinusoids
def _crossings(P, c, lo, hi, P2=None, c2=None):
    """All θ ∈ [lo, hi] where a curve u = n(θ)·P_i + c_i crosses another of the same set
    (or, given P2, c2, one of the second set).

    n(θ)·(P_j − P_i) = c_i − c_j  ⇔  |w| sin(β − θ) = ρ (as for bitangents)."""
    if P2 is None:
        i, j = np.triu_indices(P.shape[0], 1)
        w, rho = P[j] - P[i], c[i] - c[j]
    else:
        w = (P2[None, :, :] - P[:, None, :]).reshape(-1, 2)
        rho = (c[:, None] - c2[None, :]).ravel()
    wn = np.hypot(w[:, 0], w[:, 1])
    ok = (wn > 1e-300) & (np.abs(rho) <= wn)
    roots = np.concatenate(K.sine_roots(w[ok], rho[ok]))
    return _in_range(roots, lo, hi)


def _in_range(angles, lo, hi):
    """Angles (mod 2π) brought into [lo, lo + 2π) and kept if ≤ hi."""
    t = lo + np.mod(np.asarray(angles) - lo, TWO_PI)
    return t[t <= hi]


@nb.njit(cache=True)
def _tangent_u_and_s(k, side, theta, vert_start, verts, radius, A, cumS, perimeter):
    """u of the tangency curve (k, side) at each θ, and the arc position of its tangent point."""
    N = theta.shape[0]
    u = np.empty(N)
    s = np.empty(N)
    sig = 1.0 if side == 1 else -1.0
    sh = HALF_PI if side == 1 else -HALF_PI
    for i in range(N):
        phi = theta[i] + sh
        j = K.support_index(k, phi, vert_start, A)
        nx, ny = -math.sin(theta[i]), math.cos(theta[i])
        u[i] = nx * verts[j, 0] + ny * verts[j, 1] + sig * radius[k]
        if vert_start[k + 1] - vert_start[k] == 1:
            s[i] = (phi % TWO_PI) * radius[k]
        else:
            s[i] = cumS[j]
    return u, s


def _arc_clip(s0, length, w0, wlen, L):
    """Intersection of arcs [s0, s0+length] and [w0, w0+wlen] on a circle of length L, as
    (start, len); len < 0 when empty (a single piece: their normal spans sum to < 2π)."""
    d = np.mod(s0 - w0, L)
    inside = d < wlen
    start_a, len_a = s0, np.minimum(length, wlen - d)
    d2 = np.mod(w0 - s0, L)
    start_b, len_b = w0, np.minimum(length - d2, wlen)
    start = np.where(inside, start_a, start_b)
    ln = np.where(inside, len_a, np.where(d2 < length, len_b, -1.0))
    return start, ln


def element_form_factors(cx, mesh, quiet=True):
    """Element form factors from the faces of the complex.

    Returns F (N, N + 1) float64 (column N: the blue sky)."""
    from viscx.progress import bar

    scene = cx.scene
    A, cumG, cumS, perim = scene.pieces()
    N = mesh["elem_obj"].shape[0]
    M = np.zeros((N, N + 1))
    args = (scene.vert_start, scene.verts, scene.radius, A, cumS, perim)
    nF = cx.n_faces
    with bar(total=nF, desc="element form factors", quiet=quiet, unit="face") as pb:
        for f in range(nF):
            pb.update()
            a, b = (int(x) for x in cx.f_pair[f])
            if not cx.f_bounded[f] or (a == SKY and b == SKY):
                continue
            _face_measures(cx, mesh, f, a, b, M, args)
    Le = mesh["elem_length"]
    F = M / (2.0 * Le[:, None])
    return F


def _face_measures(cx, mesh, f, a, b, M, args):
    scene = cx.scene
    A, cumG, cumS, perim = scene.pieces()
    N = mesh["elem_obj"].shape[0]
    est = mesh["obj_elem_start"]
    sl = slice(cx.f_edge_start[f], cx.f_edge_start[f + 1])
    ed, up, rev = cx.f_edge[sl], cx.f_edge_upper[sl], cx.f_edge_reversed[sl]
    # oriented edges of the face's representative (a reversed edge is its stored twin)
    eo = cx.e_obj[ed]
    es = np.where(rev, 1 - cx.e_side[ed], cx.e_side[ed])
    t0 = cx.e_theta[ed, 0] + np.where(rev, math.pi, 0.0)
    t1 = cx.e_theta[ed, 1] + np.where(rev, math.pi, 0.0)
    th_lo, th_hi = _theta_range(t0[up], t1[up])
    # bound curves, all sinusoids u = n(θ)·P + c: the tangency curves of a and b (they
    # bound an element clipped at a tangent point), the chain edges (each only over its
    # own θ-range), and the pencils of lines through the element ends
    breaks = [th_lo, th_hi]
    breaks += list(_in_range(np.concatenate([t0, t1]), th_lo, th_hi))

    def sinusoids(k, sides=(1, 0)):
        v = scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]]
        r = scene.radius[k]
        P_ = np.concatenate([v for _ in sides])
        c_ = np.concatenate([np.full(len(v), r if sd == 1 else -r) for sd in sides])
        return P_, c_

    Pab, cab = [np.zeros((0, 2))], [np.zeros(0)]
    for k in (a, b):
        if k >= 0:
            P_, c_ = sinusoids(k)
            Pab.append(P_); cab.append(c_)
            if len(P_) > 2:  # a polygon's support point changes
                Ak = A[scene.vert_start[k]:scene.vert_start[k + 1]]
                breaks += list(_in_range(np.concatenate([Ak - HALF_PI, Ak + HALF_PI]), th_lo, th_hi))
    Pab, cab = np.concatenate(Pab), np.concatenate(cab)
    ea = np.arange(est[a], est[a + 1]) if a >= 0 else np.zeros(0, np.int64)
    eb = np.arange(est[b], est[b + 1]) if b >= 0 else np.zeros(0, np.int64)
    if a >= 0:
        ea = ea[_elements_touched(scene, mesh, a, ea, eo, es, t0, t1, exit_side=True, args=args)]
    if b >= 0:
        eb = eb[_elements_touched(scene, mesh, b, eb, eo, es, t0, t1, exit_side=False, args=args)]
    ends_a = _element_ends(scene, mesh, a, ea)
    ends_b = _element_ends(scene, mesh, b, eb)
    for k, (xs, ss) in ((a, ends_a), (b, ends_b)):
        if k >= 0 and len(ss):
            nrm = normal_angles(scene, k, ss)
            breaks += list(_in_range(np.concatenate([nrm.ravel() - HALF_PI, nrm.ravel() + HALF_PI]), th_lo, th_hi))
    pen = np.concatenate([ends_a[0], ends_b[0]])
    Q = np.concatenate([Pab, pen])
    cQ = np.concatenate([cab, np.zeros(len(pen))])
    za, zb = np.zeros(len(ends_a[0])), np.zeros(len(ends_b[0]))
    breaks += list(_crossings(Pab, cab, th_lo, th_hi))
    breaks += list(_crossings(Pab, cab, th_lo, th_hi, pen, np.zeros(len(pen))))
    breaks += list(_crossings(ends_a[0], za, th_lo, th_hi, ends_b[0], zb))
    for i in range(len(eo)):
        P_, c_ = sinusoids(int(eo[i]), (int(es[i]),))
        lo_i = th_lo + np.mod(t0[i] - th_lo, TWO_PI)
        breaks += list(_crossings(P_, c_, lo_i, lo_i + (t1[i] - t0[i]), Q, cQ))
        if len(P_) > 1:
            Ak = A[scene.vert_start[eo[i]]:scene.vert_start[eo[i] + 1]]
            sh = HALF_PI if es[i] == 1 else -HALF_PI
            breaks += list(_in_range(Ak - sh, lo_i, lo_i + (t1[i] - t0[i])))
    # pieces at most 0.25 rad long: 6-point Gauss–Legendre is exact to degree 11, and a
    # sinusoid over 0.25 rad is then integrated to ~1e-20 relative
    breaks += list(np.linspace(th_lo, th_hi, int(np.ceil((th_hi - th_lo) / 0.25)) + 1))
    br = np.unique(np.clip(np.array(breaks), th_lo, th_hi))
    h = np.diff(br)
    keep = h > 1e-14
    mid, half = 0.5 * (br[1:] + br[:-1])[keep], 0.5 * h[keep]
    theta = (mid[:, None] + half[:, None] * _GL_X[None, :]).ravel()
    wts = (half[:, None] * _GL_W[None, :]).ravel()
    # the face at each node: the u-intervals between its chains (one per pair of a lower
    # and an upper edge over θ, paired by rank: a face can be several intervals at one θ,
    # e.g. the lines leaving a ground block to the sky on both sides of a panel's shadow)
    lo, hi = _chain_intervals(theta, ed, up, eo, es, t0, t1, args)
    ok = np.isfinite(lo[:, 0])
    if not np.any(ok):
        return
    theta, wts, lo, hi = theta[ok], wts[ok], lo[ok], hi[ok]
    nrm = np.stack([-np.sin(theta), np.cos(theta)], 1)
    # exit u-intervals of the elements of a, entry u-intervals of the elements of b
    Ua = _element_u(scene, mesh, a, ea, theta, nrm, exit_side=True, args=args) if a >= 0 else None
    Ub = _element_u(scene, mesh, b, eb, theta, nrm, exit_side=False, args=args) if b >= 0 else None
    whole = (np.full((len(theta), 1), -np.inf), np.full((len(theta), 1), np.inf))
    if Ua is None:
        Ua = whole
    if Ub is None:
        Ub = whole
    # drop elements that never meet the face: every θ-range where one does is a union of
    # the smooth pieces above, so it has nodes; an element without any has measure 0
    flo, fhi = lo[:, :1], np.nanmax(np.where(np.isfinite(hi), hi, np.nan), axis=1)[:, None]
    ka = np.any(np.minimum(Ua[1], fhi) > np.maximum(Ua[0], flo), axis=0) | (a < 0)
    kb = np.any(np.minimum(Ub[1], fhi) > np.maximum(Ub[0], flo), axis=0) | (b < 0)
    Ua = (Ua[0][:, ka], Ua[1][:, ka])
    Ub = (Ub[0][:, kb], Ub[1][:, kb])
    if a >= 0:
        ea = ea[ka]
    if b >= 0:
        eb = eb[kb]
    na, nb = Ua[0].shape[1], Ub[0].shape[1]
    meas = np.zeros((na, nb))
    step = max(1, 2_000_000 // max(1, na * nb))  # bounded memory
    for c0 in range(0, len(theta), step):
        c = slice(c0, c0 + step)
        low_ab = np.maximum(Ua[0][c, :, None], Ub[0][c, None, :])
        high_ab = np.minimum(Ua[1][c, :, None], Ub[1][c, None, :])
        for q in range(lo.shape[1]):
            low = np.maximum(lo[c, q, None, None], low_ab)
            high = np.minimum(hi[c, q, None, None], high_ab)
            meas += np.einsum("t,tij->ij", wts[c], np.maximum(high - low, 0.0))
    ia = ea if a >= 0 else None
    ib = eb if b >= 0 else None
    if ia is not None and ib is not None:
        M[np.ix_(ia, ib)] += meas
        M[np.ix_(ib, ia)] += meas.T
    elif ia is not None:
        M[ia, N] += meas[:, 0]
    else:
        M[ib, N] += meas[0, :]


def _theta_range(tu0, tu1):
    """[θ_lo, θ_hi]: the arc of directions covered by a face's upper edges (θ ranges
    [tu0, tu1], overlapping where the face is several u-intervals at one θ); the whole
    circle when they cover it."""
    s0 = np.mod(tu0, TWO_PI)
    ln = tu1 - tu0
    o = np.argsort(s0)
    S = np.concatenate([s0[o], s0[o] + TWO_PI])
    E = np.concatenate([(s0 + ln)[o], (s0 + ln)[o] + TWO_PI])
    cur = E[0]
    for i in range(1, S.shape[0]):
        if S[i] > cur + 1e-12:  # a gap: the face's arc starts here
            lo = float(s0[o][i % s0.shape[0]])  # the start itself, not S[i] − 2π rounded
            rel = np.mod(s0 - lo, TWO_PI)
            rel = np.where(rel > TWO_PI - 1e-12, 0.0, rel)
            return lo, lo + float(np.max(rel + ln))
        cur = max(cur, E[i])
    return 0.0, TWO_PI


def _chain_intervals(theta, ed, up, eo, es, t0, t1, args):
    """(T, Q) lower and upper bounds of the face's u-intervals at each θ node (padded
    with +inf / −inf; lo[:, 0] is inf where the face has no interval)."""
    rows, us, ups = [], [], []
    for i in range(len(ed)):
        m = np.nonzero(np.mod(theta - t0[i], TWO_PI) <= (t1[i] - t0[i]))[0]
        if m.size:
            rows.append(m)
            us.append(_tangent_u_and_s(int(eo[i]), int(es[i]), theta[m], *args)[0])
            ups.append(np.full(m.size, bool(up[i])))
    T = theta.shape[0]
    if not rows:
        return np.full((T, 1), np.inf), np.full((T, 1), -np.inf)
    r, u, isup = np.concatenate(rows), np.concatenate(us), np.concatenate(ups)
    out = []
    for flag, pad in ((False, np.inf), (True, -np.inf)):
        rr, uu = r[isup == flag], u[isup == flag]
        o = np.lexsort((uu, rr))
        rr, uu = rr[o], uu[o]
        rank = np.arange(rr.size) - np.searchsorted(rr, rr)
        Q = int(rank.max()) + 1 if rr.size else 1
        M = np.full((T, Q), pad)
        M[rr, rank] = uu
        out.append(M)
    lo, hi = out
    Q = max(lo.shape[1], hi.shape[1])
    lo = np.pad(lo, ((0, 0), (0, Q - lo.shape[1])), constant_values=np.inf)
    hi = np.pad(hi, ((0, 0), (0, Q - hi.shape[1])), constant_values=-np.inf)
    # a node where the chains do not pair up (on an edge end, by rounding) has no interval
    bad = np.isfinite(lo) != np.isfinite(hi)
    lo[np.any(bad, axis=1)] = np.inf
    hi[np.any(bad, axis=1)] = -np.inf
    return lo, hi


def _chord(scene, k, o, d):
    """(N,) t_in, t_out of lines o + t d with object k, clamped so that a grazing line
    (a face boundary tangent to k) still returns its touching point."""
    v = scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]]
    r = scene.radius[k]
    if len(v) == 1:
        c = v[0] - o
        bb = np.einsum("ij,ij->i", c, d)
        h = np.sqrt(np.maximum(r * r - (np.einsum("ij,ij->i", c, c) - bb * bb), 0.0))
        return bb - h, bb + h
    tin = np.full(len(o), -np.inf)
    tout = np.full(len(o), np.inf)
    for i in range(len(v)):
        a_, b_ = v[i], v[(i + 1) % len(v)]
        nrm = np.array([b_[1] - a_[1], -(b_[0] - a_[0])])
        num = (o - a_) @ nrm
        den = d @ nrm
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -num / den
        tout = np.where(den > 0, np.minimum(tout, t), tout)
        tin = np.where(den < 0, np.maximum(tin, t), tin)
    mid = 0.5 * (tin + tout)
    return np.minimum(tin, mid), np.maximum(tout, mid)


def _elements_touched(scene, mesh, k, idx, eo, es, t0, t1, exit_side, args):
    """(len(idx),) bool: elements of object k that the face's lines can leave from (exit
    side) or arrive at.  Along each boundary edge of the face the exit (entry) point on k
    moves monotonically (the back/forward rays of the tangent lines of a convex object
    sweep the plane without overlap), so the points reached form, per edge, the arc from
    its value at θ0 to its value at θ1 through its value at mid-edge; the face reaches the
    union of those arcs (its exit position is monotone in u between the chains)."""
    A, cumG, cumS, perim = scene.pieces()
    L = perim[k]
    f = np.array([1e-9, 0.5, 1.0 - 1e-9])
    th = (t0[:, None] + (t1 - t0)[:, None] * f[None, :])           # (E, 3)
    pos = np.empty(th.shape)
    for i in range(len(eo)):
        _, sk = _tangent_u_and_s(int(eo[i]), int(es[i]), th[i], *args)
        if eo[i] == k:
            pos[i] = np.mod(sk, L)
        else:
            d = np.stack([np.cos(th[i]), np.sin(th[i])], 1)
            o = point_at(scene, int(eo[i]), sk)
            tin, tout = _chord(scene, k, o, d)
            pos[i] = arc_position(scene, k, o + (tout if exit_side else tin)[:, None] * d, d, exit_side)
    s0, sm, s1 = pos[:, 0], pos[:, 1], pos[:, 2]
    fwd = np.mod(sm - s0, L) <= np.mod(s1 - s0, L)
    a0 = np.where(fwd, s0, s1)
    alen = np.where(fwd, np.mod(s1 - s0, L), np.mod(s0 - s1, L))
    margin = 1e-9 * L
    a0, alen = a0 - margin, alen + 2 * margin
    e0 = mesh["elem_s"][idx, 0]
    elen = mesh["elem_s"][idx, 1] - e0
    hit = (np.mod(e0[:, None] - a0[None, :], L) < alen[None, :]) | (np.mod(a0[None, :] - e0[:, None], L) < elen[:, None])
    return np.any(hit, axis=1)


def _element_ends(scene, mesh, k, idx):
    if k < 0:
        return np.zeros((0, 2)), np.zeros(0)
    s = mesh["elem_s"][idx, 0]
    return point_at(scene, k, s), s


def _element_u(scene, mesh, k, idx, theta, nrm, exit_side, args):
    """(T, Ne) lower and upper u of the lines whose exit (entry) point lies in each element."""
    A, cumG, cumS, perim = scene.pieces()
    L = perim[k]
    _, sL = _tangent_u_and_s(k, 0, theta, *args)   # tangent point of λ (k on the left)
    _, sR = _tangent_u_and_s(k, 1, theta, *args)   # tangent point of μ (k on the right)
    # exit half: ccw from the λ tangent point to the μ one; entry half: ccw from μ to λ
    w0 = sL if exit_side else sR
    w1 = sR if exit_side else sL
    wlen = np.mod(w1 - w0, L)
    wlen = np.where(wlen <= 0, L, wlen)
    s0 = mesh["elem_s"][idx, 0]
    ln = mesh["elem_s"][idx, 1] - s0
    st, cl = _arc_clip(s0[None, :], ln[None, :], w0[:, None], wlen[:, None], L)
    empty = cl < 0
    cl = np.maximum(cl, 0.0)
    x0 = point_at(scene, k, st.ravel()).reshape(st.shape + (2,))
    x1 = point_at(scene, k, (st + cl).ravel()).reshape(st.shape + (2,))
    u0 = np.einsum("tej,tj->te", x0, nrm)
    u1 = np.einsum("tej,tj->te", x1, nrm)
    lo, hi = (u0, u1) if exit_side else (u1, u0)
    lo = np.where(empty, np.inf, lo)
    hi = np.where(empty, -np.inf, hi)
    return lo, hi


# ----------------------------------------------------------------------------- radiosity
def solve_radiosity(F, emission, reflectance, tol=1e-13, max_iter=100000):
    """Gauss–Seidel for B = E + ρ F B (F: (N, N) element form factors, sky column dropped).

    Parameters
    ----------
    F : (N, N) float64 ; emission, reflectance : (N,) float64

    Returns B (N,) float64 and the number of sweeps."""
    B = emission.astype(float).copy()
    rF = reflectance[:, None] * F
    for it in range(1, max_iter + 1):
        delta = _gs_sweep(rF, emission, B)
        if delta <= tol * max(1.0, np.abs(B).max()):
            return B, it
    raise ViscxError("radiosity iteration did not converge")


@nb.njit(cache=True)
def _gs_sweep(rF, E, B):
    N = B.shape[0]
    delta = 0.0
    for i in range(N):
        acc = E[i]
        for j in range(N):
            acc += rF[i, j] * B[j]
        d = abs(acc - B[i])
        if d > delta:
            delta = d
        B[i] = acc
    return delta


def element_edges(scene, mesh):
    """(N,) int64: the boundary edge of its object each element lies on (edge j runs from
    corner j to corner j + 1; for a segment 0 is the side on the right of p0 → p1 and 1
    the side on its left); −1 for circles."""
    A, cumG, cumS, perim = scene.pieces()
    out = np.full(mesh["elem_obj"].shape[0], -1, np.int64)
    for k in range(scene.n):
        s0, e0 = scene.vert_start[k], scene.vert_start[k + 1]
        if e0 - s0 == 1:
            continue
        m = mesh["elem_obj"] == k
        mid = np.mod(0.5 * (mesh["elem_s"][m, 0] + mesh["elem_s"][m, 1]), perim[k])
        out[m] = np.searchsorted(cumS[s0:e0], mid, side="right") - 1
    return out


def radiosity(cx, quiet=True, sky_radiance=0.0):
    """Discontinuity mesh + element form factors + radiosity solution, as one dict of arrays
    (the ``mesh/`` group of the HDF5 file): the mesh arrays, ``elem_F`` (N, N + 1),
    ``elem_edge`` (N,) the boundary edge / segment side of each element (see
    :func:`element_edges`), ``elem_emission``, ``elem_reflectance``, ``elem_B`` (N,)
    radiosity, ``elem_H`` (N,) irradiance (incident flux per unit length: Σ_f F_ef B_f plus
    the sky's share F_e,sky B_sky), ``sky_radiance`` and ``iterations``.

    The blue sky can emit: with ``sky_radiance`` B_sky > 0 it is a uniform emitter at
    infinity, so B = E + ρ (F B + F_sky B_sky), i.e. the emission E + ρ F_sky B_sky in the
    same Gauss–Seidel solve (an outdoor layout's diffuse irradiance per element and side)."""
    if not (np.isfinite(sky_radiance) and sky_radiance >= 0):
        raise ViscxError("the sky radiance must be finite and >= 0")
    mesh = discontinuity_mesh(cx)
    F = element_form_factors(cx, mesh, quiet=quiet)
    k = mesh["elem_obj"]
    E = cx.scene.emission[k]
    rho = cx.scene.reflectance[k]
    sky = F[:, -1] * sky_radiance
    B, it = solve_radiosity(F[:, :-1], E + rho * sky, rho)
    H = F[:, :-1] @ B + sky
    mesh.update(elem_F=F, elem_edge=element_edges(cx.scene, mesh), elem_emission=E, elem_reflectance=rho,
                elem_B=B, elem_H=H, sky_radiance=np.float64(sky_radiance), iterations=np.int64(it))
    return mesh
