"""Lines in space: Plücker coordinates and the line constructions of visual events.

Plücker coordinates of the line through ``p`` with direction ``d`` are
``L = (d, m)`` with moment ``m = p × d``. They are homogeneous (any non-zero
multiple is the same line) and satisfy the Plücker relation ``d · m = 0``.

Two lines meet (or are parallel) exactly when their *side product* vanishes::

    side(a, b) = d_a · m_b + d_b · m_a

It is linear in each argument, which makes "meets line L" a linear condition
``(m_L, d_L) · X = 0`` on the unknown line X; this is what turns the visual
events into small linear-algebra problems:

* E4, a line meeting four lines: four linear conditions on X ∈ R⁶ leave a pencil
  X = αP + βQ (null space of a 4×6 matrix); the Plücker relation is a
  quadratic form in (α, β): 0, 1 or 2 real lines (Teller & Hohmeyer).
* VEE, a line through a point v meeting two lines: it lies in the plane through v
  and each line, so its direction is ``n1 × n2`` with ``n_i`` the normals of those
  planes.
* EEE, lines meeting three lines: for x1 on the first edge, the line through
  e1(x1) meeting the other two hits e2 at x2(x1), a linear-fractional function
  (lines meeting three skew lines form a regulus, which induces a projectivity
  between any two of its directrices).

All functions are vectorised over a leading axis and work in float64.
"""

import numpy as np
from numba import njit

from viscx.arrays import row_norms
from viscx.tolerances import PARALLEL_TOLERANCE


def plucker(points, directions):
    """Plücker coordinates of lines through ``points`` along ``directions``.

    Parameters
    ----------
    points, directions : (n, 3) float

    Returns
    -------
    (n, 6) float
        ``(d, p × d)``.
    """
    points = np.asarray(points, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    return np.concatenate([directions, np.cross(points, directions)], axis=-1)


def side(a, b):
    """Side product of Plücker lines: zero iff they meet (or are parallel).

    Parameters
    ----------
    a, b : (..., 6) float

    Returns
    -------
    (...) float
        Its sign tells on which side of each other two skew lines pass.
    """
    return np.einsum("...i,...i->...", a[..., :3], b[..., 3:]) + np.einsum("...i,...i->...", b[..., :3], a[..., 3:])


def point_direction(lines):
    """A point (the one closest to the origin) and the unit direction of Plücker lines.

    Parameters
    ----------
    lines : (n, 6) float
        With a non-zero direction part.

    Returns
    -------
    points, directions : (n, 3) float
    """
    d, m = lines[..., :3], lines[..., 3:]
    dd = np.einsum("...i,...i->...", d, d)[..., None]
    return np.cross(d, m) / dd, d / np.sqrt(dd)


def lines_through_four_lines(lines, rank_tol=1e-10, quadric_tol=1e-12):
    """The real lines meeting four given lines.

    Parameters
    ----------
    lines : (n, 4, 6) float
        Four Plücker lines per problem (any scale).
    rank_tol : float
        Below this residual (the condition rows are unit vectors) a condition
        depends on the others (e.g. four lines through one point, or of one
        regulus): a family of lines meets them and the problem is degenerate.
    quadric_tol : float
        When the Plücker relation vanishes on the whole null space to this
        absolute size (its basis is orthonormal), every line of the pencil
        X = αP + βQ is a real line meeting the four (e.g. three of them in a
        plane, the fourth crossing it): degenerate as well.

    Returns
    -------
    solutions : (n, 2, 6) float
        Up to two lines, direction part of unit length.
    valid : (n, 2) bool
        Which solutions are real lines (a double root gives one).
    degenerate : (n,) bool
        Problems with a family of solutions (no solution is reported for them).
    """
    lines = np.ascontiguousarray(lines, dtype=np.float64).reshape(-1, 4, 6)
    n = len(lines)
    solutions = np.zeros((n, 2, 6))
    valid = np.zeros((n, 2), dtype=bool)
    degenerate = np.zeros(n, dtype=bool)
    _four_lines_kernel(lines, rank_tol, quadric_tol, solutions, valid, degenerate)
    return solutions, valid, degenerate


@njit(cache=True, nogil=True)
def _orthogonalise(w, basis, k):
    """w minus its projection on the first k orthonormal rows of basis, twice (so
    that it is orthogonal to working precision), normalised; returns its norm."""
    for _ in range(2):
        for r in range(k):
            dot = 0.0
            for j in range(6):
                dot += w[j] * basis[r, j]
            for j in range(6):
                w[j] -= dot * basis[r, j]
    size = 0.0
    for j in range(6):
        size += w[j] * w[j]
    size = np.sqrt(size)
    if size > 0:
        for j in range(6):
            w[j] /= size
    return size


@njit(cache=True, nogil=True)
def _four_lines_kernel(lines, rank_tol, quadric_tol, solutions, valid, degenerate):
    rows = np.empty((4, 6))
    basis = np.empty((6, 6))
    w = np.empty(6)
    for i in range(lines.shape[0]):
        # "X meets L" is (m_L, d_L) · X = 0: the condition rows, unit length
        for k in range(4):
            size = 0.0
            for j in range(3):
                rows[k, j] = lines[i, k, 3 + j]
                rows[k, 3 + j] = lines[i, k, j]
            for j in range(6):
                size += rows[k, j] * rows[k, j]
            size = np.sqrt(size)
            for j in range(6):
                rows[k, j] = rows[k, j] / size if size > 0 else 0.0
        # orthonormal basis of the rows, the largest residual first (Gram-Schmidt
        # with pivoting: its last residual is the rank test) ...
        for k in range(4):
            best, best_size = k, -1.0
            for r in range(k, 4):
                size = 0.0
                for j in range(6):
                    size += rows[r, j] * rows[r, j]
                if size > best_size:
                    best, best_size = r, size
            for j in range(6):
                w[j] = rows[best, j]
                rows[best, j] = rows[k, j]
            if _orthogonalise(w, basis, k) <= rank_tol:
                degenerate[i] = True
                break
            basis[k] = w
            for r in range(k + 1, 4):
                dot = 0.0
                for j in range(6):
                    dot += rows[r, j] * w[j]
                for j in range(6):
                    rows[r, j] -= dot * w[j]
        if degenerate[i]:
            continue
        # ... then of its complement, P and Q, from the unit vectors farthest from it
        # (the residual of e_j has squared norm 1 - Σ_r basis[r, j]²)
        for k in range(4, 6):
            best, best_size = 0, -1.0
            for j in range(6):
                size = 1.0
                for r in range(k):
                    size -= basis[r, j] * basis[r, j]
                if size > best_size:
                    best, best_size = j, size
            for j in range(6):
                w[j] = 0.0
            w[best] = 1.0
            _orthogonalise(w, basis, k)
            basis[k] = w
        P, Q = basis[4], basis[5]
        # Plücker relation d · m = 0 on X = αP + βQ: the form [[a, h], [h, c]]
        a = P[0] * P[3] + P[1] * P[4] + P[2] * P[5]
        c = Q[0] * Q[3] + Q[1] * Q[4] + Q[2] * Q[5]
        h = 0.5 * (P[0] * Q[3] + P[1] * Q[4] + P[2] * Q[5] + Q[0] * P[3] + Q[1] * P[4] + Q[2] * P[5])
        if max(abs(a), max(abs(c), abs(h))) <= quadric_tol:
            degenerate[i] = True  # the whole pencil consists of lines
            continue
        # eigenvalues lo <= hi and eigenvectors (closed form of a 2x2 symmetric matrix)
        mean, rad = 0.5 * (a + c), np.hypot(0.5 * (a - c), h)
        lo, hi = mean - rad, mean + rad
        theta = 0.5 * np.arctan2(2 * h, a - c)
        v_hi0, v_hi1 = np.cos(theta), np.sin(theta)
        v_lo0, v_lo1 = -v_hi1, v_hi0
        scale = max(abs(lo), abs(hi))
        lo, hi = lo / scale, hi / scale
        # lo x² + hi y² = 0 has real solutions iff lo <= 0 <= hi
        if lo > quadric_tol or hi < -quadric_tol:
            continue
        x, y = np.sqrt(max(hi, 0.0)), np.sqrt(max(-lo, 0.0))
        for k in range(2):
            sign = 1.0 if k == 0 else -1.0
            alpha = x * v_lo0 + sign * y * v_hi0
            beta = x * v_lo1 + sign * y * v_hi1
            dn, xn = 0.0, 0.0
            for j in range(6):
                w[j] = alpha * P[j] + beta * Q[j]
                xn += w[j] * w[j]
                if j < 3:
                    dn += w[j] * w[j]
            dn, xn = np.sqrt(dn), np.sqrt(xn)
            if dn > PARALLEL_TOLERANCE * xn:
                for j in range(6):
                    solutions[i, k, j] = w[j] / dn
                valid[i, k] = True
        # a double root gives the same line twice: keep one
        if valid[i, 0] and valid[i, 1]:
            plus, minus = 0.0, 0.0
            for j in range(6):
                plus += (solutions[i, 0, j] - solutions[i, 1, j]) ** 2
                minus += (solutions[i, 0, j] + solutions[i, 1, j]) ** 2
            if min(plus, minus) < 1e-24:
                valid[i, 1] = False


def line_through_point_and_two_lines(points, lines1, lines2):
    """Direction of the line through each point meeting two lines.

    The line lies in the plane through ``v`` and ``L1`` and in the one through
    ``v`` and ``L2``; its direction is the cross product of their normals.
    The plane through v and the line (d, m) has normal ``m - v × d`` (the moment of
    the line about v).

    Parameters
    ----------
    points : (n, 3) float
    lines1, lines2 : (n, 6) float

    Returns
    -------
    directions : (n, 3) float
        Unit length; zero where the two planes coincide or a line passes
        through the point (degenerate: no unique line).
    """
    v = np.asarray(points, dtype=np.float64)
    n1 = lines1[:, 3:] - np.cross(v, lines1[:, :3])
    n2 = lines2[:, 3:] - np.cross(v, lines2[:, :3])
    d = np.cross(n1, n2)
    size = row_norms(d)
    scale = row_norms(n1) * row_norms(n2)
    ok = size > PARALLEL_TOLERANCE * scale
    out = np.zeros_like(d)
    out[ok] = d[ok] / size[ok, None]
    return out


def segment_parameter(line_points, line_dirs, seg_a, seg_b):
    """Where each line passes closest to each segment's supporting line.

    Parameters
    ----------
    line_points, line_dirs : (n, 3) float
    seg_a, seg_b : (n, 3) float
        Segments from a (x = 0) to b (x = 1).

    Returns
    -------
    x : (n,) float
        Parameter on the segment's line of the closest point (nan if parallel).
    distance : (n,) float
        Distance between the two lines there.
    """
    e = seg_b - seg_a
    w = seg_a - line_points
    a = np.einsum("ij,ij->i", line_dirs, line_dirs)
    b = np.einsum("ij,ij->i", line_dirs, e)
    c = np.einsum("ij,ij->i", e, e)
    d = np.einsum("ij,ij->i", line_dirs, w)
    f = np.einsum("ij,ij->i", e, w)
    den = a * c - b * b
    ok = den > 1e-14 * a * c
    x = np.where(ok, (b * d - a * f) / np.where(ok, den, 1.0), np.nan)
    s = np.where(ok, (d + b * x) / a, np.nan)
    gap = w + x[:, None] * e - s[:, None] * line_dirs
    return x, row_norms(gap)


def eee_line(e1a, e1b, line2, line3, x1):
    """The line through e1(x1) meeting two lines (the EEE family, parameterised by x1).

    Parameters
    ----------
    e1a, e1b : (n, 3) float
        First edge, e1(x) = e1a + x (e1b - e1a).
    line2, line3 : (n, 6) float
    x1 : (n,) float

    Returns
    -------
    points, directions : (n, 3) float
    """
    p = e1a + x1[:, None] * (e1b - e1a)
    return p, line_through_point_and_two_lines(p, line2, line3)


def eee_map(e1, e2, e3):
    """The linear-fractional map x2 = (a x1 + b) / (c x1 + d) of an EEE family.

    For x1 on edge e1, the line through e1(x1) meeting the lines of e2 and e3 hits
    the line of e2 at parameter x2. The map is a projectivity, fixed by three
    samples: (a, b, c, d) is the null vector of ``a x1 + b - x2 (c x1 + d) = 0``
    at x1 ∈ {0, 1/2, 1} (computed exactly by the constructions above).

    Parameters
    ----------
    e1, e2, e3 : (n, 2, 3) float
        Edges as endpoint pairs; x = 0 at the first, 1 at the second.

    Returns
    -------
    coeffs : (n, 4) float
        (a, b, c, d), normalised.
    orientation : (n,) int
        sign(dx2/dx1) = sign(ad - bc), constant along an arc (Hoberock et al. §4.2).
    """
    n = len(e1)
    L2 = plucker(e2[:, 0], e2[:, 1] - e2[:, 0])
    L3 = plucker(e3[:, 0], e3[:, 1] - e3[:, 0])
    rows = []
    for x1 in (0.0, 0.5, 1.0):
        p, d = eee_line(e1[:, 0], e1[:, 1], L2, L3, np.full(n, x1))
        x2, _ = segment_parameter(p, d, e2[:, 0], e2[:, 1])
        rows.append(np.stack([np.full(n, x1), np.ones(n), -x2 * x1, -x2], axis=1))
    system = np.stack(rows, axis=1)  # (n, 3, 4)
    _, _, vt = np.linalg.svd(system)
    coeffs = vt[:, -1]
    coeffs = coeffs / row_norms(coeffs)[:, None]
    a, b, c, d = coeffs.T
    return coeffs, np.sign(a * d - b * c).astype(np.int64)


def eee_x2(coeffs, x1):
    """Evaluate x2(x1) of :func:`eee_map`.

    Parameters
    ----------
    coeffs : (n, 4) float
    x1 : (n,) float
    """
    a, b, c, d = coeffs.T
    return (a * x1 + b) / (c * x1 + d)
