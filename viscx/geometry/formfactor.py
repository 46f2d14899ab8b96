"""Exact point-to-polygon form factors (Lambert's formula).

The form factor from a differential area at x (unit normal n) to a polygon P is
the fraction of the energy x emits (cosine-weighted over the hemisphere) that
reaches P. For a polygon seen entirely on the front side of x, Lambert's contour
formula gives it exactly (Baum, Rushmeier & Winget 1989; Hoberock et al. §7.4):

    F = (1 / 2π) Σ_i  Γ_i · n,     Γ_i = θ_i (r_i × r_{i+1}) / |r_i × r_{i+1}|

with r_i the polygon's vertices relative to x, θ_i the angle between r_i and
r_{i+1}, the loop running counter-clockwise as seen from x. It is Stokes'
theorem on the unit sphere: the projected solid angle of the spherical polygon.
A polygon with holes sums its loops with their orientations (holes run the
other way), which is also how the visible part of a light (outer loops and
holes, from the visibility complex) is integrated.

The orientation of the loops does not have to be known: the sum is computed
for the loop as given and its absolute value taken, since the projected solid
angle of a polygon in front of x is positive. Polygons that cross the plane of
x must be clipped to its front half-space first (:func:`clip_to_hemisphere`).
"""

import functools

import numpy as np

from viscx.geometry.polygon import newell_normal


def loop_contour_sum(points, normals, loop):
    """Σ Γ_i · n of one closed loop for many receiver points.

    Parameters
    ----------
    points : (m, 3) float
    normals : (m, 3) float
        Unit normals at the points.
    loop : (k, 3) float
        Loop vertices in order.

    Returns
    -------
    (m,) float
        Signed: the loop's orientation seen from each point decides the sign.
    """
    r = loop[None, :, :] - points[:, None, :]  # (m, k, 3)
    r_next = np.roll(r, -1, axis=1)
    cross = np.cross(r, r_next)
    size = np.linalg.norm(cross, axis=2)
    dot = np.einsum("mkj,mkj->mk", r, r_next)
    theta = np.arctan2(size, dot)  # angle between r_i and r_i+1, stable at both ends
    with np.errstate(invalid="ignore", divide="ignore"):
        gamma = np.where(size[..., None] > 0, cross * (theta / size)[..., None], 0.0)
    return np.einsum("mkj,mj->m", gamma, normals)


def point_to_polygon(points, normals, loops):
    """Form factor from differential areas to a polygon with holes, unoccluded.

    Parameters
    ----------
    points : (m, 3) float
    normals : (m, 3) float
        Unit normals.
    loops : list of (k, 3) float
        The outer loop first, then the holes, wound oppositely (as viscx stores
        faces). The polygon must lie in front of every point (see
        :func:`clip_to_hemisphere`).

    Returns
    -------
    (m,) float
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    total = sum(loop_contour_sum(points, normals, np.asarray(loop, dtype=np.float64)) for loop in loops)
    return np.abs(total) / (2 * np.pi)


def clip_to_hemisphere(loop, point, normal):
    """The part of a planar loop in front of the plane through ``point`` (Sutherland–Hodgman).

    Parameters
    ----------
    loop : (k, 3) float
    point, normal : (3,) float

    Returns
    -------
    (k', 3) float
        Possibly empty.
    """
    loop = np.asarray(loop, dtype=np.float64)
    height = (loop - point) @ normal
    out = []
    for i in range(len(loop)):
        j = (i + 1) % len(loop)
        a, b, ha, hb = loop[i], loop[j], height[i], height[j]
        if ha >= 0:
            out.append(a)
        if (ha >= 0) != (hb >= 0):
            out.append(a + (b - a) * (ha / (ha - hb)))
    return np.asarray(out).reshape(-1, 3)


# -- polygon to polygon, unoccluded ----------------------------------------------------------
#
# Stokes' theorem turns the double area integral into a double contour integral
# (Sparrow 1963):
#
#     A_i F_ij = (1 / 2π) ∮_i ∮_j ln r  dr_i · dr_j
#
# with both contours run counter-clockwise about their own polygon's normal (the
# normals facing each other). Per pair of edges a (of i) and b (of j), with unit
# directions u_a, u_b, the inner integral along b has a closed form: for a point
# x at height h from b's line and projection t0 on it,
#
#     ∫_0^L ln |x - b(t)| dt = G(L - t0) - G(-t0),
#     G(y) = ½ (y ln(y² + h²) - 2y) + h atan(y / h)        (G(y) = y ln|y| - y at h = 0),
#
# and the outer one along a is Gauss–Legendre on sub-intervals that shrink
# geometrically toward a's ends, where the integrand has its (integrable)
# logarithmic singularities when the polygons touch (a shared edge or vertex).

_GL = {n: np.polynomial.legendre.leggauss(n) for n in (6, 10)}


@functools.lru_cache(maxsize=None)
def _panel_grade(level_lo, level_hi):
    """(m,) float, read-only: panel ends on [0, 1], halving toward 0 ``level_lo`` times and
    toward 1 ``level_hi`` times (0, 2^-(level_lo+1), …, 1/4, 1/2, 3/4, …, 1 − 2^-(level_hi+1), 1);
    cached: the levels are small integers (:data:`LEVELS` at most)."""
    def grade(levels):  # (levels + 2,): 0, 2^-(levels+1), …, 1/4, 1/2
        return np.concatenate([[0.0], 0.5 ** np.arange(levels + 1, 1, -1), [0.5]])

    g = np.concatenate([grade(level_lo), 1 - grade(level_hi)[-2::-1]])
    g.flags.writeable = False
    return g


def _graded_panels(knots, levels):
    """The Gauss–Legendre panels of every edge of a polygon: on each interval between
    consecutive knots of an edge, panels refined geometrically toward both its ends, toward
    knot k ``levels[k]`` times (where the integrand may be singular: the ends of the edge
    and every interior cut; a knot far from the other polygon needs fewer levels, see
    :func:`_knot_levels`). Intervals shorter than 1e-14 of the edge are skipped. ``knots``,
    ``levels``: one (k,) array per edge. Returns the panels' ends ``lo, hi`` (p,) float64
    and their edge (p,) int64, edge by edge."""
    lo, hi, edge = [], [], []
    for e, (t, lev) in enumerate(zip(knots, levels)):
        span = t[-1] - t[0]
        for k in range(len(t) - 1):
            if t[k + 1] - t[k] <= 1e-14 * span:
                continue
            ends = t[k] + (t[k + 1] - t[k]) * _panel_grade(int(lev[k]), int(lev[k + 1]))
            lo.append(ends[:-1])
            hi.append(ends[1:])
            edge.append(np.full(len(ends) - 1, e, np.int64))
    if not lo:
        return np.zeros(0), np.zeros(0), np.zeros(0, np.int64)
    return np.concatenate(lo), np.concatenate(hi), np.concatenate(edge)


def _panel_nodes(lo, hi, order):
    """Gauss–Legendre nodes and weights of ``order`` points on each panel [lo, hi] (p,):
    (p · order,) each, panel by panel."""
    x_gl, w_gl = _GL[order]
    half = (hi - lo) / 2
    nodes = (lo + half)[:, None] + half[:, None] * x_gl[None, :]
    weights = half[:, None] * w_gl[None, :]
    return nodes.ravel(), weights.ravel()


#: Most levels of the geometric grading toward a knot (an edge's end, a cut): the
#: smallest panel is 2^-41 of the interval where the polygons touch there.
LEVELS = 40


def _knot_levels(points, p, q, span):
    """(k,) int: the grading levels toward each knot (points (k, 3) on the edges of i, each
    with ``span`` (k,), the longer of its two intervals) for the log kernel of the other
    polygon's edges ``p → q`` (nb, 3): the singularities of the outer integrand are where x
    meets those edges, so a knot at distance D from them needs panels down to D / 4 only
    (the panel [0, D / 4] is then at least 3 D / 4 from every singularity: Gauss–Legendre
    converges there as fast as on the panels above it); :data:`LEVELS` where D = 0
    (touching polygons)."""
    d = q - p
    dd = np.einsum("ij,ij->i", d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip(np.where(dd > 0, np.einsum("kij,ij->ki", points[:, None, :] - p[None], d) / dd, 0.0), 0.0, 1.0)
    dist = np.linalg.norm(points[:, None, :] - p[None] - s[..., None] * d[None], axis=2).min(axis=1)
    with np.errstate(divide="ignore"):
        need = np.ceil(np.log2(2 * span / dist))
    return np.where(dist > 0, np.clip(np.nan_to_num(need, posinf=LEVELS), 0, LEVELS), LEVELS).astype(np.int64)


def _near_cuts(a0, u_a, len_a, p, q):
    """Parameters on each edge a of i (``a0, u_a`` (na, 3), ``len_a`` (na,)) where the
    other polygon comes close (its vertices' projections and the closest points of its
    edges ``p → q`` (nb, 3), within a quarter of a's length): the places where the inner
    integral's log kernel is (nearly) singular. ``t, keep`` (na, 2 nb): the parameters and
    which are cuts."""
    w0 = p[None] - a0[:, None]  # (na, nb, 3)
    # vertices
    t_v = np.einsum("kij,kj->ki", w0, u_a)
    dist_v = np.linalg.norm(w0 - t_v[..., None] * u_a[:, None], axis=2)
    # closest points of the segments p-q to the line of a (sampled where they cross its neighbourhood)
    d = q - p
    b_ = u_a @ d.T  # (na, nb)
    c_ = np.einsum("ij,ij->i", d, d)[None]
    d_ = t_v
    e_ = np.einsum("ij,kij->ki", d, w0)
    den = c_ - b_ * b_
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip(np.where(den > 1e-14 * c_, (b_ * d_ - e_) / den, 0.0), 0.0, 1.0)
    y = w0 + s[..., None] * d[None]  # relative to a0
    t_s = np.einsum("kij,kj->ki", y, u_a)
    dist_s = np.linalg.norm(y - t_s[..., None] * u_a[:, None], axis=2)
    t, dist = np.concatenate([t_v, t_s], axis=1), np.concatenate([dist_v, dist_s], axis=1)
    return t, (dist < 0.25 * len_a[:, None]) & (t > 0) & (t < len_a[:, None])


def _log_distance_integral(x, start, direction, length):
    """∫_0^length ln |x - (start + t direction)| dt for points x and segments, closed form,
    every point against every segment.

    Parameters
    ----------
    x : (m, 3) float
    start, direction : (k, 3) float
        Segment starts and unit directions.
    length : (k,) float

    Returns
    -------
    value, size : (m, k) float
        The integrals and the magnitude of the two terms they are the difference of
        (what their rounding error scales with).
    """
    w = x[:, None, :] - start[None, :, :]
    t0 = np.einsum("mkj,kj->mk", w, direction)
    # the distance to the line as the length of w's perpendicular part (√(|w|² − t0²)
    # loses half the digits where x is close to the line: edges at 1e-6 above the other
    # polygon's plane, as a block's side clipped at the floor)
    h = np.linalg.norm(w - t0[..., None] * direction[None, :, :], axis=2)

    def G(y):
        with np.errstate(divide="ignore", invalid="ignore"):
            log_term = np.where(y * y + h * h > 0, y * np.log(y * y + h * h), 0.0)
            atan_term = np.where(h > 0, h * np.arctan(y / np.where(h > 0, h, 1.0)), 0.0)
        return 0.5 * log_term - y + atan_term

    g1, g0 = G(length[None, :] - t0), G(-t0)
    return g1 - g0, np.abs(g1) + np.abs(g0)


def _edges(loops):
    """(start (k, 3), unit direction (k, 3), length (k,)) of every non-degenerate edge of
    some loops."""
    if not loops:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    a = np.concatenate([np.asarray(l, dtype=np.float64) for l in loops])
    b = np.concatenate([np.roll(np.asarray(l, dtype=np.float64), -1, axis=0) for l in loops])
    length = np.linalg.norm(b - a, axis=1)
    keep = length > 0
    return a[keep], (b - a)[keep] / length[keep, None], length[keep]


def _oriented(loops, normal, separate=False):
    """Outer loop counter-clockwise about the normal, holes the other way round; and the
    area they enclose. ``separate``: every loop is an outer loop of its own (disjoint
    polygons, their areas added)."""
    out, area = [], 0.0
    for k, loop in enumerate(loops):
        loop = np.asarray(loop)
        loop = loop.astype(np.result_type(loop.dtype, np.float64))  # float64, or wider when given
        signed = newell_normal(loop) @ normal  # 2 × its area about the normal (float64)
        outer = k == 0 or separate
        if (signed > 0) != outer:
            loop = loop[::-1]
        out.append(loop)
        area += abs(signed) / 2 * (1 if outer else -1)
    return out, area


#: Points of the outer contour integral per block of (point, edge of j) pairs: bounds the
#: memory of one evaluation of the inner closed forms.
_BLOCK = 200_000


def polygon_to_polygon_orders(loops_i, normal_i, loops_j, normal_j, orders=(10,), separate=False):
    """:func:`polygon_to_polygon` with each Gauss–Legendre order of ``orders`` on the same
    graded panels, and a bound on their rounding errors. Every node of every edge of i meets every edge of j
    at once (numpy, in blocks of :data:`_BLOCK` pairs).

    Σ_a Σ_b cos(u_a, u_b) ∫_a ∫_b ln r: the inner integrals in closed form at the outer
    nodes, summed per edge a with its weights, then over the pairs of edges that are not
    perpendicular (those contribute nothing). The terms cancel (the integrals of ln r are
    ~ length × ln(size) each, F A_i their small sum): the rounding bound is 64 ε times the
    sum of their magnitudes (/ 2π A_i).

    ``separate``: the loops of i are disjoint polygons of their own (each counter-clockwise,
    no holes): F from their union (the contour sums are linear in the loops).

    Returns
    -------
    values : (len(orders),) float64
    rounding : float
    """
    normal_i, normal_j = np.asarray(normal_i, dtype=np.float64), np.asarray(normal_j, dtype=np.float64)
    li, area_i = _oriented(loops_i, normal_i, separate)
    lj, _ = _oriented(loops_j, normal_j)
    a0, u_a, len_a = _edges(li)
    b0, u_b, len_b = _edges(lj)
    cos_ab = u_a @ u_b.T  # (na, nb)
    cos_ab = np.where(np.abs(cos_ab) > 1e-15, cos_ab, 0.0)  # perpendicular edges contribute nothing
    p = np.concatenate(lj) if lj else np.zeros((0, 3))
    q = np.concatenate([np.roll(l, -1, axis=0) for l in lj]) if lj else np.zeros((0, 3))
    out, size = [], 0.0
    cut_t, cut = _near_cuts(a0, u_a, len_a, p, q)
    knots, spans = [], []
    for k in range(len(a0)):
        t = np.unique(np.concatenate([[0.0, len_a[k]], cut_t[k, cut[k]]]))
        gap = np.diff(t)
        knots.append(t)
        spans.append(np.concatenate([gap[:1], np.maximum(gap[:-1], gap[1:]), gap[-1:]]))  # the longer adjacent interval
    sizes = np.cumsum([len(t) for t in knots])[:-1]
    points = np.concatenate([a0[k] + t[:, None] * u_a[k] for k, t in enumerate(knots)]) if knots else np.zeros((0, 3))
    levels = np.split(_knot_levels(points, p, q, np.concatenate(spans) if spans else np.zeros(0)), sizes)
    # the nodes of every order at once (the same panels), run by run: row o · na + k of
    # per / mag sums order o's nodes on edge k of i
    p_lo, p_hi, p_edge = _graded_panels(knots, levels)
    xs, ws, runs = [], [], []
    for o, order in enumerate(orders):
        s, w = _panel_nodes(p_lo, p_hi, order)
        edge = np.repeat(p_edge, order)
        xs.append(a0[edge] + s[:, None] * u_a[edge])
        ws.append(w)
        runs.append(o * len(a0) + edge)
    x, w, run = (np.concatenate(v) for v in (xs, ws, runs))
    per = np.zeros((len(orders) * len(a0), len(b0)), x.dtype)  # Σ_nodes of a  w ∫_b ln r
    mag = np.zeros((len(orders) * len(a0), len(b0)))  # Σ_nodes of a  |w| (|G(L − t0)| + |G(−t0)|)
    step = max(1, _BLOCK // max(len(b0), 1))
    for lo in range(0, len(x), step):
        sl = slice(lo, lo + step)
        value, terms = _log_distance_integral(x[sl], b0, u_b, len_b)
        e = run[sl]
        starts = np.flatnonzero(np.concatenate([[True], e[1:] != e[:-1]]))  # the nodes run edge by edge
        per[e[starts]] += np.add.reduceat(w[sl, None] * value, starts, axis=0)
        mag[e[starts]] += np.add.reduceat(np.abs(w[sl, None]) * terms, starts, axis=0)
    for o in range(len(orders)):
        rows = slice(o * len(a0), (o + 1) * len(a0))
        out.append((cos_ab * per[rows]).sum() / (2 * np.pi * area_i))  # float64, or wider when given
        size = max(size, float((np.abs(cos_ab) * mag[rows]).sum()) / (2 * np.pi * area_i))
    return np.array(out), 64 * np.finfo(np.float64).eps * size


def polygon_to_polygon(loops_i, normal_i, loops_j, normal_j, order=10):
    """Unoccluded form factor F_ij between two planar polygons (holes allowed).

    Parameters
    ----------
    loops_i, loops_j : list of (k, 3) float
        Outer loop first, then holes (wound oppositely to the outer loop).
    normal_i, normal_j : (3,) float
        Unit normals; polygon j must lie in front of i and i in front of j
        (their planes may meet only along their boundary).
    order : int
        Gauss–Legendre points per panel (6 or 10); panels are graded toward the ends of
        every edge of i and toward where j comes close to it.

    Returns
    -------
    float
    """
    return float(polygon_to_polygon_orders(loops_i, normal_i, loops_j, normal_j, (order,))[0][0])
