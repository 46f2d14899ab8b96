"""Convex pieces of a plane cut along line segments: the arrangement of a face's critical
lines that the form-factor cubature integrates over (:func:`viscx.queries.formfactor.cut_along`).

Pieces are flat arrays, as trimesh keeps its paths: ``verts`` (V, 2) float64 the corners of
every piece one after the other, each counter-clockwise, and ``ptr`` (N + 1,) int64, piece k
at ``verts[ptr[k]:ptr[k + 1]]``.

A segment a → b cuts a piece when its line crosses the piece's interior (corners more than
``eps`` on both sides) along a chord that overlaps the segment itself by more than ``eps``
(a kink line stops where its two edges stop lining up). The parts of a cut piece take its
place; they are not cut again by the same segment. Segments are taken in order, so the
result depends on it only through the corners' rounding.
"""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _part(verts, lo, hi, s, sign, out, o):
    """The part of the convex piece ``verts[lo:hi]`` on the side ``sign`` of a line (``s``
    its corners' signed distances), written at ``out[o:]``: its corners in order and the
    points where its edges cross the line. Returns the number written."""
    k = hi - lo
    m = 0
    for i in range(k):
        r = (i + 1) % k
        hv = sign * s[i]
        hr = sign * s[r]
        if hv >= 0:
            out[o + m, 0] = verts[lo + i, 0]
            out[o + m, 1] = verts[lo + i, 1]
            m += 1
        if (hv > 0 and hr < 0) or (hv < 0 and hr > 0):
            t = hv / (hv - hr)
            out[o + m, 0] = verts[lo + i, 0] + (verts[lo + r, 0] - verts[lo + i, 0]) * t
            out[o + m, 1] = verts[lo + i, 1] + (verts[lo + r, 1] - verts[lo + i, 1]) * t
            m += 1
    return m


@njit(cache=True, nogil=True)
def _area2(p, lo, hi):
    """Signed area of the polygon ``p[lo:hi]`` (shoelace)."""
    a = 0.0
    k = hi - lo
    for i in range(k):
        r = lo + (i + 1) % k
        a += p[lo + i, 0] * p[r, 1] - p[r, 0] * p[lo + i, 1]
    return 0.5 * a


@njit(cache=True, nogil=True)
def cut_pieces(verts, ptr, owner, seg, length, eps, limit):
    """Convex pieces cut along segments, one segment after the other (module docstring).

    Parameters
    ----------
    verts : (V, 2) float64
    ptr : (N + 1,) int64
        The pieces, counter-clockwise.
    owner : (N,) int64
        A label per piece, which its parts keep (the triangle it was cut from).
    seg : (s, 2, 2) float64
        The segments' ends.
    length : (s,) float64
        Their lengths (segments of ``eps`` or less cut nothing).
    eps : float
        Distance below which a corner counts as on a line, and area (``eps²``) below which a
        part is dropped.
    limit : int
        Stop when there are more pieces than this (-1: no limit).

    Returns
    -------
    verts : (V', 2) float64
    ptr : (N' + 1,) int64
    owner : (N',) int64
    complete : bool
        False where ``limit`` stopped it (the arrays then hold the pieces so far).
    """
    n_max = 0
    for k in range(len(ptr) - 1):
        n_max = max(n_max, ptr[k + 1] - ptr[k])
    s = np.empty(n_max + 8)
    hit = np.zeros(len(ptr) - 1, np.bool_)
    for j in range(len(seg)):
        L = length[j]
        if L <= eps:
            continue
        a0, a1 = seg[j, 0, 0], seg[j, 0, 1]
        d0, d1 = (seg[j, 1, 0] - a0) / L, (seg[j, 1, 1] - a1) / L
        n = len(ptr) - 1
        if len(hit) < n:
            hit = np.zeros(2 * n, np.bool_)
        n_hit, extra = 0, 0
        for p in range(n):
            lo, hi = ptr[p], ptr[p + 1]
            k = hi - lo
            if len(s) < k:
                s = np.empty(2 * k)
            s_max, s_min = -np.inf, np.inf
            t_lo, t_hi = np.inf, -np.inf
            for i in range(k):
                x0, x1 = verts[lo + i, 0] - a0, verts[lo + i, 1] - a1
                s[i] = x0 * d1 - x1 * d0
                s_max = max(s_max, s[i])
                s_min = min(s_min, s[i])
            hit[p] = False
            if not (s_max > eps and s_min < -eps):
                continue
            for i in range(k):
                r = (i + 1) % k
                si, sr = s[i], s[r]
                if (si > 0) != (sr > 0) and si != sr:
                    ti = (verts[lo + i, 0] - a0) * d0 + (verts[lo + i, 1] - a1) * d1
                    tr = (verts[lo + r, 0] - a0) * d0 + (verts[lo + r, 1] - a1) * d1
                    tc = ti + (tr - ti) * si / (si - sr)
                    t_lo = min(t_lo, tc)
                    t_hi = max(t_hi, tc)
            if min(t_hi, L) - max(t_lo, 0.0) > eps:
                hit[p] = True
                n_hit += 1
                extra += k + 4
        if n_hit == 0:
            continue
        out = np.empty((len(verts) + extra, 2))
        out_ptr = np.empty(n + n_hit + 1, np.int64)
        out_owner = np.empty(n + n_hit, np.int64)
        o, q = 0, 0
        out_ptr[0] = 0
        for p in range(n):
            lo, hi = ptr[p], ptr[p + 1]
            if not hit[p]:
                out[o:o + hi - lo] = verts[lo:hi]
                o += hi - lo
                out_owner[q] = owner[p]
                q += 1
                out_ptr[q] = o
                continue
            for i in range(hi - lo):
                s[i] = (verts[lo + i, 0] - a0) * d1 - (verts[lo + i, 1] - a1) * d0
            for sign in (1.0, -1.0):
                m = _part(verts, lo, hi, s, sign, out, o)
                if m >= 3 and abs(_area2(out, o, o + m)) > eps * eps:
                    o += m
                    out_owner[q] = owner[p]
                    q += 1
                    out_ptr[q] = o
        verts, ptr, owner = out[:o], out_ptr[:q + 1], out_owner[:q]
        if limit >= 0 and q > limit:
            return verts, ptr, owner, False
    return verts, ptr, owner, True


@njit(cache=True, nogil=True)
def segments_crossing(seg, tri, eps):
    """(s, r) bool: which segments ``seg`` (s, 2, 2) float64 may cut which triangles ``tri``
    (r, 3, 2) float64: the segment's line leaves corners more than ``eps`` on both sides,
    and the triangle's extent along the line overlaps the segment by more than ``eps`` (a
    superset of the cuts of :func:`cut_pieces`, which asks the same of the chord)."""
    out = np.zeros((seg.shape[0], tri.shape[0]), np.bool_)
    for i in range(seg.shape[0]):
        ax, ay = seg[i, 0, 0], seg[i, 0, 1]
        ex, ey = seg[i, 1, 0] - ax, seg[i, 1, 1] - ay
        length = np.sqrt(ex * ex + ey * ey)
        if not length > eps:
            continue
        dx, dy = ex / length, ey / length
        for r in range(tri.shape[0]):
            s_lo, s_hi, t_lo, t_hi = np.inf, -np.inf, np.inf, -np.inf
            for k in range(3):
                rx, ry = tri[r, k, 0] - ax, tri[r, k, 1] - ay
                side = rx * dy - ry * dx
                along = rx * dx + ry * dy
                s_lo, s_hi = min(s_lo, side), max(s_hi, side)
                t_lo, t_hi = min(t_lo, along), max(t_hi, along)
            out[i, r] = s_hi > eps and s_lo < -eps and t_hi > eps and t_lo < length - eps
    return out


def pieces_to_flat(pieces):
    """A list of (k, 2) pieces as ``verts`` (V, 2) float64 and ``ptr`` (N + 1,) int64."""
    if not len(pieces):
        return np.zeros((0, 2)), np.zeros(1, np.int64)
    ptr = np.concatenate([[0], np.cumsum([len(p) for p in pieces])]).astype(np.int64)
    return np.ascontiguousarray(np.concatenate(pieces), np.float64), ptr


def flat_to_pieces(verts, ptr):
    """The inverse of :func:`pieces_to_flat`: a list of (k, 2) float64 arrays."""
    return [verts[ptr[k]:ptr[k + 1]] for k in range(len(ptr) - 1)]


def piece_centres(verts, ptr):
    """(N, 2) float64: the mean of each piece's corners (inside it: the pieces are convex)."""
    count = np.diff(ptr)
    return np.add.reduceat(verts, ptr[:-1], axis=0) / count[:, None]
