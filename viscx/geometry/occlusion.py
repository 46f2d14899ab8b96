"""From-point hidden-surface removal for form factors: the part of a target polygon J
that a point x sees past a few occluding polygons, and Lambert's formula over it.

Everything here is for one emitter/target pair whose occluders are known
(:mod:`viscx.queries.formfactor` prepares them). For a point x:

1. the occluders are clipped to the pyramid with apex x over the convex hull of
   J (Sutherland–Hodgman against the planes through x and the hull's edges), so
   every point left lies between x and J's plane and projects into the hull;
2. they are projected centrally through x onto J's plane (2-D coordinates of a
   basis of that plane whose normal faces x: a loop seen counter-clockwise from
   x is counter-clockwise in 2-D);
3. the visible part — J (non-zero winding) minus the union of the shadows — is cut
   into trapezoids by vertical slabs at every vertex and every crossing of two
   edges of different polygons, and Lambert's contour sum is taken over the
   trapezoids' boundaries (interior sides cancel; the sum is additive along a
   straight edge, so the cutting changes nothing but rounding).

The faces of a closed convex box that x is outside of (:func:`_outside`; the boxes from
:func:`viscx.queries.formfactor.closed_boxes`) enter as one convex polygon, the hull of
their clipped projections, and J's holes inside such a polygon are left out (the same
visible part, fewer edges). The sweep keeps its edges' order from slab to slab.

Nothing is sampled: the visible part is the exact polygon (float64 crossings),
the same set the point's V-cells give (tests/test_formfactor_queries.py checks
both against each other and against shadow rays).

Also here: :func:`blocked_form_factors`, the part of F(x → J) the occluders hide, each
point past its own subset of them, and :func:`shaft_meets`, which occluders meet the
convex hull of a cell of the emitter and J (the cubature of
:mod:`viscx.queries.formfactor` keeps per cell only those).
"""

import numpy as np
from numba import njit

TWO_PI = 2.0 * np.pi
#: Rotation (radians) of each wedge's 2-D basis in :func:`point_views`.
GENERIC_TURN = 0.4127319
#: The cones the front hemisphere is cut into in :func:`point_views` (at least 3: each must be
#: pointed, to project centrally on one plane), and the (generic) azimuth of the first one's side.
WEDGES = 3
GENERIC_AZIMUTH = 0.2917163
#: Height (in the wedge's plane, at unit distance from the point) below which a
#: region of the sweep does not reuse its owner from the previous slab (:func:`_wedge_view`).
MEMO_GAP = 1e-7
#: Distance (in the wedge's plane, at unit distance from the point: the wedge's
#: coordinates are within ±2) below which :func:`_wedge_view` takes two breaks of its
#: sweep for one and two edges for collinear: rounding, not geometry. Polygons clipped by the
#: same frustum plane, or sharing a clipped edge, give edges on one line up to ~1e-16 whose
#: "crossings" fall anywhere along it and whose breaks a few ulps apart make slabs of no
#: width (a third of the Cornell box's slabs); what either can change of F is below
#: SNAP × the slab's length / π per piece.
SNAP = 1e-14
#: Heights (at a slab's middle, in the wedge's plane at unit distance) closer than
#: this, of two edges collinear within SNAP, keep the order the edges had in the last slab
#: (:func:`_wedge_view`): edges on one line (polygons clipped by one frustum side)
#: otherwise swap by rounding from slab to slab, and each swap redoes every region between
#: it and the slab's real change. (Edges that cross are never tied: their order is exact.)
ORDER_TIE = 2e-15
#: Distance from a plane of the wedge (relative to the distance from the point)
#: within which :func:`_wedge_view` takes a vertex for one on it (a vertex the clipping
#: made there is within ~1e-16): an edge with both ends on one such plane lies on the
#: frustum's side, and no other edge (all in the frustum) crosses it but by rounding, so its
#: crossings are not looked for by the slab sweep, which sorts every slab (with the
#: whole-frustum copy, ~59 → ~57 µs a point on the Cornell box); :func:`_sweep_runs` needs
#: them (:func:`_wedge_view`).
RIM = 1e-13
#: Slope (|dv/du| in a wedge's 2-D basis) above which an edge is steep. The sweep
#: places the ends of an edge's runs by their u (:func:`_flush_owner`), and a steep edge's
#: height at a crossing's rounded u is off by |dv/du| × ulp(u): the boundary of a region has
#: a gap of that size where a steep edge meets another, and Lambert's sum over it is off by
#: about that much (a floor's edge at dv/du = 1.9e6 put 5.5e-12 into F, found against a
#: 40-digit contour integral of the visible floor). With a steep edge, the wedge's 2-D basis
#: is turned so that the vertical lies in the middle of the widest gap between the edges'
#: directions (:func:`_turn_from_steep`; n edges leave a gap of at least π / n, so the
#: steepest is then below ~0.64 n); below STEEP the gaps stay under ~2e-13, ~1e-15 of F.
STEEP = 1e3
#: Heights (at a slab's middle, relative to 1 + the two slopes) closer than this are rounding in
#: the order of :func:`_sweep_runs` (:func:`_above`): the vertices of a clipped, projected
#: polygon are off by a few ulps (~1e-15), and so are two edges from one vertex at a slab's
#: middle when the slab is ~1e-14 wide (64 SNAP: a margin over what was seen, ~1e-14).
ORDER_NOISE = 4 * SNAP
#: A box's plane whose outward normal n has n · n_i below this, n_i the emitter's front
#: normal (opposite to 1e-12), is the emitter's plane turned over when x lies on it: the
#: face of a box resting on the emitter (:func:`_outside_box`, and
#: :func:`viscx.queries.formfactor.back_faces`, which follows the same rule).
TURNED_OVER = -1.0 + 1e-12
#: Distance in u (in the wedge's plane) from a slab's left side within which two edges close
#: there whose lines meet are taken to meet at it (:func:`_above`): far beyond rounding of
#: a vertex (~1e-13 / the slopes' difference), far below any slab that matters.
ORDER_MEET = 1e-9
#: Edges in the whole scene (the room of one wedge's projected edges, :func:`point_views`)
#: from which the kernel is compiled with :func:`_sweep_runs`; below (the Cornell box, where
#: it is 0.6x slower), the kernel without its records runs (``sweep_kind`` None).
SWEEP_RUNS_FROM = 400
#: Mean active edges a slab from which a wedge is swept by :func:`_sweep_runs`
#: (output-sensitive: work per event, the regions next to it) instead of :func:`_sweep_slabs`
#: (work per slab in its active edges): the density, not the number of edges, says which is
#: cheaper. Against 400 edges a wedge before (2026-11-28): office(1000) points 7-9 % faster,
#: office(300)'s 6-12 %, one process on idle cores; with both cores busy, as in a matrix,
#: ~3 % (the whole office(1000) matrix too). 8 and 32 about as good, 64 worse than 400 edges.
RUNS_DENSITY = 16
#: Faces to sweep at a point (in front of it, not a box's back faces) from which :func:`_point_views`
#: first leaves out those in a box's shadow (:func:`_cull_shadowed`): office(1000) 1.7-1.85x faster a
#: point, office(300) 1.5x, office(100) 1.1x, office(60) even (61 against 63 µs); the Cornell box (16
#: faces) never culls (culling there gave the same speed, its outputs 3e-14 apart).
CULL_FROM = 32


@njit(cache=True)
def _clip_loop(poly, n_in, out, px, m):
    """Sutherland–Hodgman: the part of poly[:n_in] with (y - px)·m >= 0 into out; returns its size."""
    k = 0
    if n_in == 0:
        return 0
    prev = poly[n_in - 1]
    hp = (prev[0] - px[0]) * m[0] + (prev[1] - px[1]) * m[1] + (prev[2] - px[2]) * m[2]
    for i in range(n_in):
        cur = poly[i]
        hc = (cur[0] - px[0]) * m[0] + (cur[1] - px[1]) * m[1] + (cur[2] - px[2]) * m[2]
        if (hc >= 0) != (hp >= 0):
            t = hp / (hp - hc)
            for c in range(3):
                out[k, c] = prev[c] + t * (cur[c] - prev[c])
            k += 1
        if hc >= 0:
            for c in range(3):
                out[k, c] = cur[c]
            k += 1
        prev = cur
        hp = hc
    return k


@njit(cache=True)
def _clip_to_frustum(pts, lo, hi, x, planes, n_planes, buf_a, buf_b):
    """The loop ``pts[lo:hi]`` clipped to the planes through x (inward normals
    ``planes[:n_planes]``) into ``buf_a``; returns its size (0 when a plane has every vertex
    outside, or fewer than 3 are left). A loop inside every plane is copied as it is (what
    the clipping would give: each vertex kept, in order)."""
    inside = True
    for i in range(n_planes):
        out = True
        for q in range(lo, hi):
            if ((pts[q, 0] - x[0]) * planes[i, 0] + (pts[q, 1] - x[1]) * planes[i, 1]
                    + (pts[q, 2] - x[2]) * planes[i, 2]) >= 0:
                out = False
            else:
                inside = False
        if out:
            return 0
    if inside:
        for q in range(hi - lo):
            for c in range(3):
                buf_a[q, c] = pts[lo + q, c]
        return hi - lo
    return _clip_planes(pts, lo, hi, x, planes, n_planes, buf_a, buf_b, buf_a.shape[0] + 1)


@njit(cache=True)
def _clip_planes(pts, lo, hi, x, planes, n_planes, buf_a, buf_b, most):
    """The loop ``pts[lo:hi]`` clipped to each plane in turn into ``buf_a``; its size (0
    when fewer than 3 are left), -1 when a loop of more than ``most`` points would be
    clipped (each clip at most doubles it: a chain that is no convex loop could outgrow the
    buffers; a convex loop gains one point a plane)."""
    n_in = hi - lo
    for q in range(n_in):
        for c in range(3):
            buf_a[q, c] = pts[lo + q, c]
    for i in range(n_planes):
        if n_in > most:
            return -1
        n_in = _clip_loop(buf_a, n_in, buf_b, x, planes[i])
        for q in range(n_in):
            for c in range(3):
                buf_a[q, c] = buf_b[q, c]
        if n_in < 3:
            return 0
    return n_in


@njit(cache=True)
def _gamma_dot(x, pa, pb, n):
    """Γ · n of the directed edge pa → pb seen from x (Lambert's contour term)."""
    ax, ay, az = pa[0] - x[0], pa[1] - x[1], pa[2] - x[2]
    bx, by, bz = pb[0] - x[0], pb[1] - x[1], pb[2] - x[2]
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    size = np.sqrt(cx * cx + cy * cy + cz * cz)
    if size == 0.0:
        return 0.0
    theta = np.arctan2(size, ax * bx + ay * by + az * bz)
    return theta * (cx * n[0] + cy * n[1] + cz * n[2]) / size


@njit(cache=True)
def _to3(origin, eu, ev, u, v, out):
    for c in range(3):
        out[c] = origin[c] + u * eu[c] + v * ev[c]


@njit(cache=True)
def _flush(runs, e, seg_a, slope, origin, eu, ev, x, n_i, p0, p1):
    """Γ · n of edge e's current run of boundary pieces (then cleared)."""
    d, ua, ub = runs[e, 0], runs[e, 1], runs[e, 2]
    runs[e, 0] = 0
    va = seg_a[e, 1] + (ua - seg_a[e, 0]) * slope[e]
    vb = seg_a[e, 1] + (ub - seg_a[e, 0]) * slope[e]
    _to3(origin, eu, ev, ua, va, p0)
    _to3(origin, eu, ev, ub, vb, p1)
    if d > 0:
        return _gamma_dot(x, p0, p1, n_i)
    return _gamma_dot(x, p1, p0, n_i)


@njit(cache=True)
def _run(runs, e, d, u0, u1, seg_a, slope, origin, eu, ev, x, n_i, p0, p1):
    """Add the piece [u0, u1] of edge e (d = 1 bottom side, -1 top side) to its run; a run
    that cannot be extended is flushed first. Returns what was flushed."""
    out = 0.0
    if runs[e, 0] == d and runs[e, 2] == u0:
        runs[e, 2] = u1
        return 0.0
    if runs[e, 0] != 0:
        out = _flush(runs, e, seg_a, slope, origin, eu, ev, x, n_i, p0, p1)
    runs[e, 0] = d
    runs[e, 1] = u0
    runs[e, 2] = u1
    return out


@njit(cache=True)
def _crossing_u(seg_a, seg_b, e, f):
    """u of the crossing of segments e and f inside both (NaN if they do not cross; the
    caller has checked that their u ranges overlap)."""
    ax, ay, bx, by = seg_a[e, 0], seg_a[e, 1], seg_b[e, 0], seg_b[e, 1]
    cx, cy, dx, dy = seg_a[f, 0], seg_a[f, 1], seg_b[f, 0], seg_b[f, 1]
    if max(ay, by) < min(cy, dy) or max(cy, dy) < min(ay, by):
        return np.nan
    rx, ry = bx - ax, by - ay
    sx, sy = dx - cx, dy - cy
    den = rx * sy - ry * sx
    if den == 0.0:
        return np.nan
    t = ((cx - ax) * sy - (cy - ay) * sx) / den
    s = ((cx - ax) * ry - (cy - ay) * rx) / den
    if 0.0 < t < 1.0 and 0.0 < s < 1.0:
        return ax + t * rx
    return np.nan


@njit(cache=True)
def _has_vertical(seg_a, seg_b, seg_w, n_seg):
    """Whether an input edge is vertical in the projection (winding weight 0, a v extent
    at one u): the vertical sides of neighbouring slabs then do not cancel, and the sweeps
    sum whole trapezoids instead of joining runs along the edges."""
    for e in range(n_seg):
        if seg_w[e] == 0 and seg_a[e, 1] != seg_b[e, 1]:
            return True
    return False


@njit(cache=True)
def _slopes(seg_a, seg_b, n_seg, slope):
    """dv/du of every non-vertical edge into ``slope[:n_seg]`` (0 for a vertical one), once
    per sweep instead of once per slab (the same quotient, so the same heights)."""
    for e in range(n_seg):
        du = seg_b[e, 0] - seg_a[e, 0]
        slope[e] = (seg_b[e, 1] - seg_a[e, 1]) / du if du != 0.0 else 0.0


@njit(cache=True)
def _slab_edges(on, entry, n_on, u0, u1, seg_a, seg_b, hi_u, slope, act, act_v, act_v0, act_v1, tie):
    """The sweep's edges over the slab [u0, u1]: those of ``on[:n_on]`` that end before its
    middle are dropped, the others sorted by height at the middle, highest first (ties by
    ``entry``, the order in which they entered the sweep), into ``act`` (edge ids) with
    their heights at the middle, u0 and u1; ``on`` is left in that order. Returns
    ``(n_on, n_act)``, equal. ``hi_u`` (n,) and ``slope`` (n,) float64: each edge's right end
    and dv/du (:func:`_slopes`). With ``tie`` > 0, two edges collinear within :data:`SNAP`
    whose heights are within ``tie`` of each other are a tie, which keeps the order of ``on``
    (the last slab's, the new edges after it): their order is rounding (they have no
    crossing: :func:`_wedge_view`).

    The order is kept from slab to slab: edges do not cross inside a slab, so the previous
    slab's order differs from this one's only by the crossings at their common side and by
    the edges that entered (appended at the end). Insertion sort costs the length plus
    those changes, not the square of the length."""
    um = 0.5 * (u0 + u1)
    n_act = 0
    for r in range(n_on):
        e = on[r]
        if hi_u[e] <= um:
            continue
        vm = seg_a[e, 1] + (um - seg_a[e, 0]) * slope[e]
        j = n_act
        while j > 0 and (act_v[j - 1] < vm and (tie == 0.0 or act_v[j - 1] < vm - tie
                                                 or not _collinear(seg_a, seg_b, e, act[j - 1], SNAP))
                         or (tie == 0.0 and act_v[j - 1] == vm and entry[act[j - 1]] > entry[e])):
            act_v[j] = act_v[j - 1]
            act_v0[j] = act_v0[j - 1]
            act_v1[j] = act_v1[j - 1]
            act[j] = act[j - 1]
            j -= 1
        act_v[j] = vm
        act_v0[j] = seg_a[e, 1] + (u0 - seg_a[e, 0]) * slope[e]
        act_v1[j] = seg_a[e, 1] + (u1 - seg_a[e, 0]) * slope[e]
        act[j] = e
        n_act += 1
    for r in range(n_act):
        on[r] = act[r]
    return n_act, n_act


@njit(cache=True)
def _outside_box(x, n_i, box_planes, lo, hi, tiny):
    """Whether x (a point of the emitter, whose front side's unit normal is ``n_i``) lies
    strictly outside the closed convex box with the outward planes ``box_planes[lo:hi]``
    (n, c, open), and not within 2 tiny in front of any of them (a face that close is seen
    edge-on and skipped by the kernels, though rays could enter the box through it). The
    plane of an open box's missing face (``open`` non-zero) must have x behind it or within
    tiny of it (:func:`viscx.queries.formfactor.closed_boxes`: from there no ray enters the
    box through it).

    But a face lying on the emitter's plane, facing away from its front (a box resting on
    the floor: its bottom, with the floor's points within rounding of its plane, 3.6e-15 in
    front of it for a floor at y = -5), is no way in: a ray of the open front hemisphere
    leaves that plane at once, and meets the face only where x lies on it (the contact
    cells, under the box, where x is not outside anyway). Its plane is skipped there
    (:data:`TURNED_OVER`); else every box resting on the floor was, from the floor's
    points, taken as one they may be inside of, by rounding, half of the time: its back
    faces swept and its shadow not cast (four 64-sided pillars: 2.7 ms a point)."""
    out = False
    for k in range(lo, hi):
        s = box_planes[k, 0] * x[0] + box_planes[k, 1] * x[1] + box_planes[k, 2] * x[2] - box_planes[k, 3]
        if box_planes[k, 4] != 0.0:
            if s > tiny:
                return False
            continue
        if s > 2.0 * tiny:
            out = True
        elif s > 0.0:
            if box_planes[k, 0] * n_i[0] + box_planes[k, 1] * n_i[1] + box_planes[k, 2] * n_i[2] < TURNED_OVER:
                continue  # lying on the emitter's plane, facing away from its front
            return False
    return out


@njit(cache=True)
def _outside(x, n_i, b, box_state, box_ptr, box_planes, tiny):
    """Whether x is outside box b (-1: no box) (:func:`_outside_box`, decided once per
    point: ``box_state[b]`` 0 unknown, 1 yes, 2 no; the caller resets it). Then every ray
    from x that meets a face of the box that x is behind has entered the box before,
    through a face x is in front of (a ray leaves a closed solid through a face whose
    outward normal it goes along, and enters it through one it goes against): the box's
    front faces hide everything its back faces would."""
    if b < 0:
        return False
    if box_state[b] == 0:
        box_state[b] = 1 if _outside_box(x, n_i, box_planes, box_ptr[b], box_ptr[b + 1], tiny) else 2
    return box_state[b] == 1


@njit(cache=True)
def _casters(x, n_i, box_ptr, box_planes, box_state, tiny, score, s_x, casters):
    """The boxes that cast a shadow from x (:func:`_in_shadow`), the largest ``score`` first:
    ``casters[:n]`` (n returned). A box casts one when x is outside it (:func:`_outside`) and
    behind or on the plane of its missing face, if open (a ray could enter it there: no shadow
    is claimed). ``s_x`` (k,) float64 gets the signed distances n · x − c of x to the planes of
    every box x is outside of."""
    n = 0
    for b in range(box_ptr.shape[0] - 1):
        if not _outside(x, n_i, b, box_state, box_ptr, box_planes, tiny):
            continue
        shut = True
        for k in range(box_ptr[b], box_ptr[b + 1]):
            s = box_planes[k, 0] * x[0] + box_planes[k, 1] * x[1] + box_planes[k, 2] * x[2] - box_planes[k, 3]
            s_x[k] = s
            if box_planes[k, 4] != 0.0 and s > 0.0:
                shut = False
        if shut:
            casters[n] = b
            n += 1
    key = np.empty(n)
    for r in range(n):
        key[r] = -score[casters[r]]  # (a loop: an array expression would tie the cached kernel to numba's registries)
    order = np.argsort(key, kind="mergesort")
    casters[:n] = casters[:n][order]
    return n


@njit(cache=True)
def _in_shadow(pts, loop_lo, loop_hi, first, last, k0, k1, box_planes, s_x, margin, s_v, low):
    """Whether a polygon (loops ``first:last``) lies in the shadow of the convex box with the
    planes ``box_planes[k0:k1]`` (outward; ``s_x`` their n · x − c, x outside the box) with
    no part of it seen: nothing of it is seen from x, so the sweep can leave it out.

    The shadow S = {y : the segment x y meets the box} is convex (the cone from x over the
    box, behind each front plane — a plane x is in front of: a ray from x enters the box
    through the last front plane it crosses, Cyrus–Beck), so the polygon's convex hull H lies
    in it when its vertices do: v is in S when it is behind or on every front plane (the
    segment reaches the box before v: t_in = max over front planes of s_x / (s_x − s_v) ≤ 1)
    and the segment's entry point x + t_in (v − x) is behind or on every other plane. A point
    of H strictly inside S is hidden (its ray has entered the box's interior before it), and
    then so is H's whole relative interior (a convex set in a convex one, with one point in
    its interior), which leaves at most H's outline seen: no area. H's vertices' centroid is
    strictly inside S when some vertex lies more than ``margin`` behind each front plane (H
    in S; the centroid on the cone's side would put H in a plane through x, a polygon seen
    edge-on, which the kernel never sweeps). That excludes a polygon lying on a front face,
    which is seen: in the shadow's boundary, not inside it. The tests are the signs of the
    rounded planes' distances (no tolerance: a vertex rounded into S is within ~1e-15 of it).
    ``s_v`` (m,), ``low`` (m,) float64 work arrays (m ≥ k1 − k0)."""
    m = k1 - k0
    for j in range(m):
        low[j] = 0.0
    for L in range(first, last):
        for q in range(loop_lo[L], loop_hi[L]):
            t_in = 0.0
            for j in range(m):
                k = k0 + j
                s = box_planes[k, 0] * pts[q, 0] + box_planes[k, 1] * pts[q, 1] + box_planes[k, 2] * pts[q, 2] \
                    - box_planes[k, 3]
                if s_x[k] > 0.0:
                    if s > 0.0:
                        return False  # in front of a front plane: the segment misses the box
                    t_in = max(t_in, s_x[k] / (s_x[k] - s))
                    low[j] = min(low[j], s)
                s_v[j] = s
            for j in range(m):
                k = k0 + j
                if s_x[k] <= 0.0 and s_x[k] + t_in * (s_v[j] - s_x[k]) > 0.0:
                    return False  # the segment enters the front planes' region beside the box
    for j in range(m):
        if s_x[k0 + j] > 0.0 and low[j] >= -margin:
            return False  # the polygon lies on a front face (or within margin of its plane)
    return True


@njit(cache=True)
def _spheres(pts, loop_lo, loop_hi, first, poly_box, n_boxes):
    """Each polygon's vertex centroid ``poly_o`` (P, 3) and each box's bounding sphere
    (centre ``box_o`` (b, 3), the centroid of its faces' vertices, radius ``box_r`` (b,), −1 for
    a box none of whose faces is given) float64. Of a box some faces only may be given (a
    matrix row's, those with a point ahead of its plane): the sphere holds those, and so the
    part of the box ahead, all a ray of the front hemisphere can meet."""
    P = first.shape[0] - 1
    poly_o = np.zeros((P, 3))
    box_o = np.zeros((max(n_boxes, 1), 3))
    box_r = np.zeros(max(n_boxes, 1))
    count = np.zeros(max(n_boxes, 1))
    for p in range(P):
        if first[p] == first[p + 1]:
            continue  # (no loop: never swept)
        m = 0
        for q in range(loop_lo[first[p]], loop_hi[first[p]]):
            for c in range(3):
                poly_o[p, c] += pts[q, c]
            m += 1
        b = poly_box[p]
        for c in range(3):
            if b >= 0:
                box_o[b, c] += poly_o[p, c]
            poly_o[p, c] /= m
        if b >= 0:
            count[b] += m
    for b in range(n_boxes):
        if count[b] == 0:
            box_r[b] = -1.0  # none of its faces given (all behind the emitter's plane): casts nothing
            continue
        for c in range(3):
            box_o[b, c] /= count[b]
    for p in range(P):
        b = poly_box[p]
        if b < 0 or first[p] == first[p + 1]:
            continue
        for q in range(loop_lo[first[p]], loop_hi[first[p]]):
            d = np.sqrt((pts[q, 0] - box_o[b, 0]) ** 2 + (pts[q, 1] - box_o[b, 1]) ** 2 + (pts[q, 2] - box_o[b, 2]) ** 2)
            box_r[b] = max(box_r[b], d * (1.0 + 1e-12))
    return poly_o, box_o, box_r


@njit(cache=True)
def _cull_shadowed(x, n_i, sweep, pts, loop_lo, loop_hi, first, poly_box, poly_o, box_ptr, box_planes, box_o, box_r, box_state,
                   tiny, score, s_x, casters, cast_w, s_v, low):
    """Leave out of ``sweep`` every polygon in the shadow of a box from x (:func:`_in_shadow`),
    trying the boxes by decreasing ``score``. A polygon in a box's shadow has its centroid in
    the cone from x around the box's bounding sphere, and no nearer to x than the sphere: the
    pairs that fail either are not tested further."""
    n_cast = _casters(x, n_i, box_ptr, box_planes, box_state, tiny, score, s_x, casters)
    m = 0
    for r in range(n_cast):
        b = casters[r]
        if box_r[b] < 0.0:
            continue
        wx, wy, wz = box_o[b, 0] - x[0], box_o[b, 1] - x[1], box_o[b, 2] - x[2]
        d2 = wx * wx + wy * wy + wz * wz
        rr = box_r[b] * box_r[b]
        casters[m] = b
        if d2 <= rr:  # x in the sphere (outside the box): its cone is every direction
            cast_w[m, 0], cast_w[m, 1], cast_w[m, 2], cast_w[m, 3], cast_w[m, 4] = 0.0, 0.0, 0.0, -1.0, 0.0
        else:
            d = np.sqrt(d2)
            cast_w[m, 0], cast_w[m, 1], cast_w[m, 2] = wx / d, wy / d, wz / d
            cast_w[m, 3] = np.sqrt(1.0 - rr / d2) - 1e-9  # cos of the cone's half-angle, less a margin
            cast_w[m, 4] = (d - box_r[b]) * (1.0 - 1e-9)
        m += 1
    for p in range(first.shape[0] - 1):
        if not sweep[p]:
            continue
        ux, uy, uz = poly_o[p, 0] - x[0], poly_o[p, 1] - x[1], poly_o[p, 2] - x[2]
        du = np.sqrt(ux * ux + uy * uy + uz * uz)
        if du == 0.0:
            continue
        ux, uy, uz = ux / du, uy / du, uz / du
        for r in range(m):
            if ux * cast_w[r, 0] + uy * cast_w[r, 1] + uz * cast_w[r, 2] < cast_w[r, 3] or du < cast_w[r, 4]:
                continue
            b = casters[r]
            if b != poly_box[p] and _in_shadow(pts, loop_lo, loop_hi, first[p], first[p + 1], box_ptr[b], box_ptr[b + 1],
                                               box_planes, s_x, tiny, s_v, low):
                sweep[p] = False
                break


@njit(cache=True)
def _project(buf, n_in, x, hx, n_j, c_j, origin, eu, ev, tiny, out, first):
    """The points ``buf[:n_in]`` (inside the pyramid from x over J) projected centrally
    through x on J's plane, in its 2-D basis, into ``out[first:first + n_in]``."""
    for q in range(n_in):
        h = n_j[0] * buf[q, 0] + n_j[1] * buf[q, 1] + n_j[2] * buf[q, 2] - c_j
        den = hx - h
        if den <= 0:
            den = tiny  # only x itself (the apex) projects to infinity
        t = hx / den
        zx = x[0] + (buf[q, 0] - x[0]) * t - origin[0]
        zy = x[1] + (buf[q, 1] - x[1]) * t - origin[1]
        zz = x[2] + (buf[q, 2] - x[2]) * t - origin[2]
        out[first + q, 0] = zx * eu[0] + zy * eu[1] + zz * eu[2]
        out[first + q, 1] = zx * ev[0] + zy * ev[1] + zz * ev[2]


@njit(cache=True)
def points_behind_planes(points, planes, tol):
    """True when every point lies behind or on every plane, within ``tol``:
    ``n · p − c <= tol`` (a closed box's convexity test, :func:`viscx.queries.formfactor.closed_boxes`;
    a loop that stops at the first point in front, where the product of all points and
    all planes of a 20,480-face sphere is 1.6 GB).

    Parameters
    ----------
    points : (v, 3) float64
    planes : (p, 4+) float64
        ``(n, c, ...)`` per plane.
    tol : float
    """
    for k in range(planes.shape[0]):
        nx, ny, nz, c = planes[k, 0], planes[k, 1], planes[k, 2], planes[k, 3]
        for i in range(points.shape[0]):
            if points[i, 0] * nx + points[i, 1] * ny + points[i, 2] * nz - c > tol:
                return False
    return True


#: Above this many points :func:`_convex_hull` sorts by merge sort, not by insertion.
HULL_INSERTION = 32


@njit(cache=True)
def _convex_hull(pts, n, out):
    """Andrew's monotone chain: the convex hull of ``pts[:n]`` (2-D) counter-clockwise, as
    indices into ``out`` (size >= n + 1); returns its size (collinear points left out).
    The points are sorted in place by (u, v)."""
    if n > HULL_INSERTION:
        # a box of thousands of faces (a scanned convex solid): an O(n log n) sort, the
        # same order (ties in u and v are the same point)
        by_v = np.argsort(pts[:n, 1], kind="mergesort")
        order = by_v[np.argsort(pts[by_v, 0], kind="mergesort")]
        pts[:n] = pts[order]
    else:
        for i in range(1, n):  # insertion sort by (u, v): a few dozen points
            u, v = pts[i, 0], pts[i, 1]
            j = i
            while j > 0 and (pts[j - 1, 0] > u or (pts[j - 1, 0] == u and pts[j - 1, 1] > v)):
                pts[j, 0], pts[j, 1] = pts[j - 1, 0], pts[j - 1, 1]
                j -= 1
            pts[j, 0], pts[j, 1] = u, v
    if n < 3:
        return 0
    m = 0
    for i in range(n):  # lower chain
        while m >= 2 and _turn(pts, out[m - 2], out[m - 1], i) <= 0:
            m -= 1
        out[m] = i
        m += 1
    low = m + 1
    for i in range(n - 2, -1, -1):  # upper chain
        while m >= low and _turn(pts, out[m - 2], out[m - 1], i) <= 0:
            m -= 1
        out[m] = i
        m += 1
    return m - 1  # the last point is the first


@njit(cache=True)
def _turn(pts, a, b, c):
    return (pts[b, 0] - pts[a, 0]) * (pts[c, 1] - pts[a, 1]) - (pts[b, 1] - pts[a, 1]) * (pts[c, 0] - pts[a, 0])


@njit(cache=True)
def _drop_covered_hulls(seg_a, seg_b, seg_p, seg_w, n_seg, hull_first, n_hulls):
    """Leave out the boxes' shadows that lie inside another box's shadow (each a convex
    counter-clockwise polygon, the last edges of the arrays: hull k's from ``hull_first[k]``
    to the next hull's first edge or ``n_seg``): the union of the shadows, and so the visible
    part, is the same without them, while the sweep's work grows with the edges and their
    crossings (the office's north wall → floor: 8.7 of a point's ~40 box shadows lie inside
    another's; a desk's side panel in its top's, seen from above). A shadow is inside when
    each of its vertices is on or left of each edge of the other's (convex polygons: then
    all of it is); of two equal ones, the first is left out. Returns ``(n_seg, n_hulls)``,
    the arrays and ``hull_first`` compacted in order."""
    box = np.empty((n_hulls, 4))
    for k in range(n_hulls):
        last = hull_first[k + 1] if k + 1 < n_hulls else n_seg
        box[k, 0], box[k, 1], box[k, 2], box[k, 3] = np.inf, -np.inf, np.inf, -np.inf
        for e in range(hull_first[k], last):
            box[k, 0], box[k, 1] = min(box[k, 0], seg_a[e, 0]), max(box[k, 1], seg_a[e, 0])
            box[k, 2], box[k, 3] = min(box[k, 2], seg_a[e, 1]), max(box[k, 3], seg_a[e, 1])
    keep = np.ones(n_hulls, np.bool_)
    for k in range(n_hulls):
        k_last = hull_first[k + 1] if k + 1 < n_hulls else n_seg
        for m in range(n_hulls):
            if m == k or not keep[m]:
                continue
            if box[k, 0] < box[m, 0] or box[k, 1] > box[m, 1] or box[k, 2] < box[m, 2] or box[k, 3] > box[m, 3]:
                continue
            m_last = hull_first[m + 1] if m + 1 < n_hulls else n_seg
            inside = True
            for e in range(hull_first[k], k_last):
                for f in range(hull_first[m], m_last):
                    du, dv = seg_b[f, 0] - seg_a[f, 0], seg_b[f, 1] - seg_a[f, 1]
                    if du * (seg_a[e, 1] - seg_a[f, 1]) - dv * (seg_a[e, 0] - seg_a[f, 0]) < 0.0:
                        inside = False
                        break
                if not inside:
                    break
            if inside:
                keep[k] = False
                break
    out = hull_first[0]
    n_kept = 0
    for k in range(n_hulls):
        last = hull_first[k + 1] if k + 1 < n_hulls else n_seg
        first = hull_first[k]
        if not keep[k]:
            continue
        hull_first[n_kept] = out
        n_kept += 1
        for e in range(first, last):
            seg_a[out, 0], seg_a[out, 1] = seg_a[e, 0], seg_a[e, 1]
            seg_b[out, 0], seg_b[out, 1] = seg_b[e, 0], seg_b[e, 1]
            seg_p[out], seg_w[out] = seg_p[e], seg_w[e]
            out += 1
    return out, n_kept


@njit(cache=True)
def _drop_shadowed_holes(j_loop, seg_a, seg_b, seg_p, seg_w, n_seg, hull_first, n_hulls):
    """Leave out the holes of J (its loops after the first, J's edges first in the segment
    arrays) that lie inside one box's shadow (a convex counter-clockwise polygon; the
    hulls' edges run from ``hull_first[k]`` to the next hull's first edge or ``n_seg``):
    inside the shadow nothing of J is visible with or without the hole, outside nothing
    changes (a covered cell under a cabinet, inside the cabinet's shadow from every point
    above the floor). A hole on the shadow's boundary (that cell: the cabinet's bottom
    projects to itself) counts as inside within 1e-12 of the shadow's size: the sliver
    this may leave visible is below 1e-12 of F. Returns the new number of edges (the
    arrays compacted in order)."""
    out = j_loop[1]  # the outer loop stays
    for L in range(1, j_loop.shape[0] - 1):
        lo, hi = j_loop[L], j_loop[L + 1]
        u_lo, u_hi = np.inf, -np.inf
        v_lo, v_hi = np.inf, -np.inf
        for e in range(lo, hi):
            u_lo, u_hi = min(u_lo, seg_a[e, 0]), max(u_hi, seg_a[e, 0])
            v_lo, v_hi = min(v_lo, seg_a[e, 1]), max(v_hi, seg_a[e, 1])
        inside = False
        for k in range(n_hulls):
            first = hull_first[k]
            last = hull_first[k + 1] if k + 1 < n_hulls else n_seg
            bu_lo, bu_hi = np.inf, -np.inf
            bv_lo, bv_hi = np.inf, -np.inf
            for f in range(first, last):
                bu_lo, bu_hi = min(bu_lo, seg_a[f, 0]), max(bu_hi, seg_a[f, 0])
                bv_lo, bv_hi = min(bv_lo, seg_a[f, 1]), max(bv_hi, seg_a[f, 1])
            eps = 1e-12 * (bu_hi - bu_lo + bv_hi - bv_lo)
            if u_lo < bu_lo - eps or u_hi > bu_hi + eps or v_lo < bv_lo - eps or v_hi > bv_hi + eps:
                continue
            inside = True
            for e in range(lo, hi):
                for f in range(first, last):
                    du, dv = seg_b[f, 0] - seg_a[f, 0], seg_b[f, 1] - seg_a[f, 1]
                    if du * (seg_a[e, 1] - seg_a[f, 1]) - dv * (seg_a[e, 0] - seg_a[f, 0]) < -eps * (abs(du) + abs(dv)):
                        inside = False
                        break
                if not inside:
                    break
            if inside:
                break
        if inside:
            continue
        for e in range(lo, hi):
            seg_a[out, 0], seg_a[out, 1] = seg_a[e, 0], seg_a[e, 1]
            seg_b[out, 0], seg_b[out, 1] = seg_b[e, 0], seg_b[e, 1]
            seg_p[out], seg_w[out] = seg_p[e], seg_w[e]
            out += 1
    shift = j_loop[j_loop.shape[0] - 1] - out
    if shift == 0:
        return n_seg
    for k in range(n_hulls):
        hull_first[k] -= shift
    for e in range(j_loop[j_loop.shape[0] - 1], n_seg):
        seg_a[out, 0], seg_a[out, 1] = seg_a[e, 0], seg_a[e, 1]
        seg_b[out, 0], seg_b[out, 1] = seg_b[e, 0], seg_b[e, 1]
        seg_p[out], seg_w[out] = seg_p[e], seg_w[e]
        out += 1
    return out


@njit(cache=True)
def _polygon_crossings(seg_a, seg_b, seg_p, seg_w, n_seg, lo_u, hi_u, self_cross, brk, n_brk):
    """The crossings of the pair kernel's edges (``seg_*[:n_seg]``, ``lo_u, hi_u`` their u
    ranges) whose polygons ``seg_p`` differ, or are one that crosses itself
    (``self_cross``), appended to ``brk`` as breaks: ``(brk, n_brk)``. The edges of a
    polygon are consecutive (a run); two runs whose boxes are apart (strictly, in u or v)
    have no crossing, so their edges are not paired (the shadows of the office's boxes seen
    from a wall: ~140 edges in ~40 runs, most pairs of runs apart). Every other pair is
    tested where its u ranges overlap (closed), with :func:`_crossing_u` (NaN where the v
    ranges are apart, or no crossing inside both): the same pairs as every edge against
    every other, so the same breaks, in another order (the caller sorts them)."""
    run = np.empty(n_seg + 1, np.int64)
    n_run = 0
    for e in range(n_seg):
        if e == 0 or seg_p[e] != seg_p[e - 1]:
            run[n_run] = e
            n_run += 1
    run[n_run] = n_seg
    box = np.empty((n_run, 4))  # u lo, u hi, v lo, v hi of each run's edges
    for r in range(n_run):
        box[r, 0], box[r, 1], box[r, 2], box[r, 3] = np.inf, -np.inf, np.inf, -np.inf
        for e in range(run[r], run[r + 1]):
            box[r, 0], box[r, 1] = min(box[r, 0], lo_u[e]), max(box[r, 1], hi_u[e])
            box[r, 2] = min(box[r, 2], seg_a[e, 1], seg_b[e, 1])
            box[r, 3] = max(box[r, 3], seg_a[e, 1], seg_b[e, 1])
    for ra in range(n_run):
        pa = seg_p[run[ra]]
        for rb in range(ra, n_run):
            if rb != ra and (box[rb, 0] > box[ra, 1] or box[ra, 0] > box[rb, 1] or box[rb, 2] > box[ra, 3]
                             or box[ra, 2] > box[rb, 3]):
                continue
            if seg_p[run[rb]] == pa and self_cross[pa] == 0:
                continue
            for e in range(run[ra], run[ra + 1]):
                if seg_w[e] == 0:
                    continue
                for f in range(e + 1 if rb == ra else run[rb], run[rb + 1]):
                    if seg_w[f] == 0 or lo_u[f] > hi_u[e] or lo_u[e] > hi_u[f]:
                        continue
                    u = _crossing_u(seg_a, seg_b, min(e, f), max(e, f))
                    if u == u:
                        brk = _grow(brk, n_brk)
                        brk[n_brk] = u
                        n_brk += 1
    return brk, n_brk


@njit(cache=True)
def _visible_one(x, n_i, j2, j_loop, sel, origin, eu, ev, n_j, c_j, hull, occ, occ_loop, poly_loop,
                 poly_normal, poly_point, tiny, poly_box, box_ptr, box_planes, box_state, box_head, box_next, box_list,
                 hull_pts, hull_idx, seg_a, seg_b, seg_p, seg_w, buf_a, buf_b, brk, wind, act, act_v, act_v0, act_v1, p0,
                 p1, poly_solid, solid_open, occ_nb, occ_vid, occ_next, sw):
    """Form factor from (x, n_i) to the visible part of J past the occluder polygons ``sel``
    (their loops ``poly_loop[p]:poly_loop[p + 1]``; see the module docstring), and ``brk``
    (grown if it had to). The faces of a closed convex box x is outside of (``poly_box``,
    :func:`_outside`) are replaced by the convex hull of their projection; the faces of a
    closed solid (``poly_solid``, :func:`_solid_outlines`) by the outline of its front faces."""
    hx = n_j[0] * x[0] + n_j[1] * x[1] + n_j[2] * x[2] - c_j
    if hx <= 0:
        return 0.0, brk
    n_hull = hull.shape[0]
    # pyramid planes through x and the hull's edges, oriented inwards
    planes = np.empty((n_hull, 3))
    cen = np.zeros(3)
    for i in range(n_hull):
        for c in range(3):
            cen[c] += hull[i, c] / n_hull
    for i in range(n_hull):
        a = hull[i]
        b = hull[(i + 1) % n_hull]
        ax, ay, az = a[0] - x[0], a[1] - x[1], a[2] - x[2]
        bx, by, bz = b[0] - x[0], b[1] - x[1], b[2] - x[2]
        mx, my, mz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        if mx * (cen[0] - x[0]) + my * (cen[1] - x[1]) + mz * (cen[2] - x[2]) < 0:
            mx, my, mz = -mx, -my, -mz
        planes[i, 0], planes[i, 1], planes[i, 2] = mx, my, mz
    n_seg = 0
    # J's loops (2-D, outer counter-clockwise, holes clockwise): polygon 0
    for L in range(j_loop.shape[0] - 1):
        lo, hi = j_loop[L], j_loop[L + 1]
        for i in range(lo, hi):
            k = i + 1 if i + 1 < hi else lo
            seg_a[n_seg, 0], seg_a[n_seg, 1] = j2[i, 0], j2[i, 1]
            seg_b[n_seg, 0], seg_b[n_seg, 1] = j2[k, 0], j2[k, 1]
            seg_p[n_seg] = 0
            seg_w[n_seg] = 1
            n_seg += 1
    # surface patches: the outlines of their front (and open ones' back) faces first (every
    # face of a patch is then done with, unless they did not fit: then each on its own, below)
    n_seg, solids = _solid_outlines(x, sel, occ, occ_loop, poly_loop, poly_normal, poly_point, tiny, poly_solid,
                                    solid_open, occ_nb, occ_vid, occ_next, sw, planes, n_hull, hx, n_j, c_j, origin, eu,
                                    ev, seg_a, seg_b, seg_p, seg_w, n_seg, buf_a.shape[0])
    mark, self_cross = sw[0], sw[5]
    n_box = 0
    for r in range(sel.shape[0]):
        pid = sel[r]
        if solids and poly_solid[pid] >= 0:
            continue
        b = poly_box[pid]
        if _outside(x, n_i, b, box_state, box_ptr, box_planes, tiny):
            if ((x[0] - poly_point[pid, 0]) * poly_normal[pid, 0] + (x[1] - poly_point[pid, 1]) * poly_normal[pid, 1]
                    + (x[2] - poly_point[pid, 2]) * poly_normal[pid, 2]) <= tiny:
                continue  # a back face (or seen edge-on): the front faces' hull is the box's shadow
            if box_head[b] < 0:
                box_list[n_box] = b
                n_box += 1
            box_next[pid] = box_head[b]
            box_head[b] = pid
            continue
        for L in range(poly_loop[pid], poly_loop[pid + 1]):
            lo, hi = occ_loop[L], occ_loop[L + 1]
            side = ((x[0] - poly_point[pid, 0]) * poly_normal[pid, 0] + (x[1] - poly_point[pid, 1]) * poly_normal[pid, 1]
                    + (x[2] - poly_point[pid, 2]) * poly_normal[pid, 2])
            if abs(side) <= tiny:
                continue  # x in the occluder's plane: it is seen edge-on and hides nothing
            sgn = 1 if side > 0 else -1
            n_in = _clip_to_frustum(occ, lo, hi, x, planes, n_hull, buf_a, buf_b)
            if n_in < 3:
                continue
            _project(buf_a, n_in, x, hx, n_j, c_j, origin, eu, ev, tiny, seg_a, n_seg)
            first = n_seg
            for q in range(n_in):
                k = first + q + 1 if q + 1 < n_in else first
                seg_b[first + q, 0], seg_b[first + q, 1] = seg_a[k, 0], seg_a[k, 1]
                seg_p[first + q] = pid + 1
                seg_w[first + q] = sgn
            n_seg += n_in
    # a closed convex box x is outside of hides the central projection of its part inside
    # the pyramid: a convex set (the box cut by the pyramid's planes and the half-spaces the
    # occluders were clipped to), the convex hull of the projected vertices of its faces
    # clipped to the pyramid. Those of the front faces listed suffice: a ray from x that
    # meets the box enters it through a face x is in front of (by its outward normal, as
    # closed_boxes orients them), at a point of the ray's segment to J, inside the shaft, so
    # that face meets the shaft and is listed; the back faces are neither clipped nor
    # projected (a 256-sided column resting on the floor, which no outline takes: half of
    # its faces). One convex polygon instead of two or three faces (no shared edges).
    n_hulls = 0
    for k in range(n_box):
        b = box_list[k]
        n_pts = 0
        pid = box_head[b]
        head = pid
        while pid >= 0:
            for L in range(poly_loop[pid], poly_loop[pid + 1]):
                n_in = _clip_to_frustum(occ, occ_loop[L], occ_loop[L + 1], x, planes, n_hull, buf_a, buf_b)
                if n_in >= 3:
                    _project(buf_a, n_in, x, hx, n_j, c_j, origin, eu, ev, tiny, hull_pts, n_pts)
                    n_pts += n_in
            pid = box_next[pid]
        box_head[b] = -1
        box_state[b] = 0
        m = _convex_hull(hull_pts, n_pts, hull_idx)
        if m < 3:
            continue
        box_list[n_hulls] = n_seg  # (box_list[:k + 1] is done with: the hulls' first edges)
        n_hulls += 1
        for q in range(m):
            a, c = hull_idx[q], hull_idx[q + 1 if q + 1 < m else 0]
            seg_a[n_seg, 0], seg_a[n_seg, 1] = hull_pts[a, 0], hull_pts[a, 1]
            seg_b[n_seg, 0], seg_b[n_seg, 1] = hull_pts[c, 0], hull_pts[c, 1]
            seg_p[n_seg] = head + 1
            seg_w[n_seg] = 1  # counter-clockwise
            n_seg += 1
    for r in range(sel.shape[0]):
        b = poly_box[sel[r]]
        if b >= 0:
            box_state[b] = 0
        mark[sel[r]] = 0
    if n_hulls > 1:
        n_seg, n_hulls = _drop_covered_hulls(seg_a, seg_b, seg_p, seg_w, n_seg, box_list, n_hulls)
    if n_hulls and j_loop.shape[0] > 2:
        n_seg = _drop_shadowed_holes(j_loop, seg_a, seg_b, seg_p, seg_w, n_seg, box_list, n_hulls)
    # winding weights: an edge running right to left adds its polygon's sign below it
    lo_u = np.empty(n_seg)
    hi_u = np.empty(n_seg)
    brk, n_brk = _edge_windings(seg_a, seg_b, seg_w, n_seg, lo_u, hi_u, brk)
    # crossings of edges of different polygons (each pair once, its crossing computed from
    # the lower id)
    brk, n_brk = _polygon_crossings(seg_a, seg_b, seg_p, seg_w, n_seg, lo_u, hi_u, self_cross, brk, n_brk)
    us = np.sort(brk[:n_brk])
    has_vertical = _has_vertical(seg_a, seg_b, seg_w, n_seg)
    slope = np.empty(n_seg)
    _slopes(seg_a, seg_b, n_seg, slope)
    runs = np.zeros((n_seg, 3))  # per edge: direction (0 none), run start u, run end u
    # sweep: edges by their left end, an active list updated slab by slab
    act_e = np.empty(n_seg, np.int64)  # the slab's edges by height
    entry = np.empty(n_seg, np.int64)  # the order in which each edge entered the sweep
    n_live = 0
    for e in range(n_seg):
        if seg_w[e] != 0:
            act_v[n_live] = lo_u[e]
            act[n_live] = e
            n_live += 1
    by_live = np.argsort(act_v[:n_live])  # (ties broken as this sort does: the order of entry)
    for r in range(n_live):
        act_e[r] = act[by_live[r]]
    for r in range(n_live):
        act[r] = act_e[r]
    nxt = 0
    n_on = 0
    on = np.empty(n_live, np.int64)
    total = 0.0
    for k in range(n_brk - 1):
        u0, u1 = us[k], us[k + 1]
        if not u1 > u0:
            continue
        um = 0.5 * (u0 + u1)
        while nxt < n_live and lo_u[act[nxt]] < um:
            on[n_on] = act[nxt]
            entry[act[nxt]] = nxt
            n_on += 1
            nxt += 1
        # drop edges that ended, the others by height (descending)
        n_on, n_act = _slab_edges(on, entry, n_on, u0, u1, seg_a, seg_b, hi_u, slope, act_e, act_v, act_v0, act_v1, 0.0)
        if n_act < 2:
            continue
        # the scan reads the windings of the polygons of this slab's edges only: those
        # reset, not all the pair's occluders (a floor point's ~80 slabs against 247
        # occluders: a sixth of the kernel's time)
        for q in range(n_act):
            wind[seg_p[act_e[q]]] = 0
        busy = 0  # occluders with non-zero winding
        visible = False
        top = -1
        for q in range(n_act):
            e = act_e[q]
            p = seg_p[e]
            before = wind[p]
            wind[p] += seg_w[e]
            if p > 0:
                if before == 0 and wind[p] != 0:
                    busy += 1
                elif before != 0 and wind[p] == 0:
                    busy -= 1
            now = wind[0] != 0 and busy == 0
            if now and not visible:
                top = q
            elif visible and not now:
                if not has_vertical:
                    # bottom side left to right, top side right to left; the vertical sides
                    # cancel between neighbouring slabs (no input edge is vertical)
                    # (a run extended in place, the common case, costs no call)
                    e = act_e[q]
                    if runs[e, 0] == 1 and runs[e, 2] == u0:
                        runs[e, 2] = u1
                    else:
                        total += _run(runs, e, 1, u0, u1, seg_a, slope, origin, eu, ev, x, n_i, p0, p1)
                    e = act_e[top]
                    if runs[e, 0] == -1 and runs[e, 2] == u0:
                        runs[e, 2] = u1
                    else:
                        total += _run(runs, e, -1, u0, u1, seg_a, slope, origin, eu, ev, x, n_i, p0, p1)
                    visible = now
                    continue
                # trapezoid (u0, vb0) -> (u1, vb1) -> (u1, vt1) -> (u0, vt0), counter-clockwise
                _to3(origin, eu, ev, u0, act_v0[q], p0)
                _to3(origin, eu, ev, u1, act_v1[q], p1)
                total += _gamma_dot(x, p0, p1, n_i)
                _to3(origin, eu, ev, u1, act_v1[top], p0)
                total += _gamma_dot(x, p1, p0, n_i)
                _to3(origin, eu, ev, u0, act_v0[top], p1)
                total += _gamma_dot(x, p0, p1, n_i)
                _to3(origin, eu, ev, u0, act_v0[q], p0)
                total += _gamma_dot(x, p1, p0, n_i)
            visible = now
    if not has_vertical:
        for e in range(n_seg):
            if runs[e, 0] != 0:
                total += _flush(runs, e, seg_a, slope, origin, eu, ev, x, n_i, p0, p1)
    for e in range(n_seg):
        self_cross[seg_p[e]] = 0
    # counter-clockwise seen from x: Σ Γ points back at x, against n_i
    return -total / TWO_PI, brk


@njit(cache=True)
def _solid_outlines(x, sel, occ, occ_loop, poly_loop, poly_normal, poly_point, tiny, poly_solid, solid_open, occ_nb,
                    occ_vid, occ_next, sw, planes, n_hull, hx, n_j, c_j, origin, eu, ev, seg_a, seg_b, seg_p, seg_w, n_seg,
                    kmax):
    """The faces of surface patches among ``sel`` (``poly_solid`` >= 0: consistently
    oriented, every loop of a face whole (holes too), its edge q → ``occ_next[q]`` shared
    with occluder ``occ_nb[q]``, -1 if that is none of them; ``occ_vid`` the vertices' ids)
    as the outlines of their front faces and, on an open patch (``solid_open``), of their
    back faces, appended to the segments: the edges of a front (back) face whose neighbour
    is not a listed front (back) face, chained into loops (a back face's walked backwards),
    clipped to the pyramid and projected, one polygon per patch and side whose loops may
    cross each other. The front faces' projections are all counter-clockwise seen from x,
    the back faces' reversed too: their winding numbers add up, the shared edges cancel,
    and the non-zero winding of each outline is the union of its faces. A closed solid x
    is outside of needs its front faces only (``solid_open`` 0): a ray from x meeting a
    back face has entered the solid through a front face that meets the ray's segment to J,
    inside the shaft (listed); an open patch (a scan's shell) has no such front face behind
    its rim. Work arrays ``sw``: (mark (P,) 1 front, 2 back, 3 edge-on or hiding nothing;
    head (V,), link (n,), used (n,), rep (P,), self_cross (P + 1,), chain (n, 3), two clip
    buffers (2 n + 8, 3)).

    Returns
    -------
    n_seg : int
    done : bool
        False when there are none or an outline did not fit (the faces are left to the
        caller, each on its own, and the segments are as they were).
    """
    mark, self_cross = sw[0], sw[5]
    n_listed, n_front, n_back = 0, 0, 0
    for r in range(sel.shape[0]):
        pid = sel[r]
        if poly_solid[pid] < 0:
            continue
        n_listed += 1
        side = ((x[0] - poly_point[pid, 0]) * poly_normal[pid, 0] + (x[1] - poly_point[pid, 1]) * poly_normal[pid, 1]
                + (x[2] - poly_point[pid, 2]) * poly_normal[pid, 2])
        if side > tiny:
            mark[pid] = 1
            n_front += 1
        elif side < -tiny and solid_open[poly_solid[pid]]:
            mark[pid] = 2
            n_back += 1
        else:
            mark[pid] = 3
    if n_listed == 0:
        return n_seg, False
    start_seg = n_seg
    ok = True
    budget = (n_front + n_back) * kmax
    for which in (1, 2):
        if ok and (n_front if which == 1 else n_back):
            n_seg, ok = _outline_pass(which, x, sel, occ, occ_loop, poly_loop, poly_solid, occ_nb, occ_vid, occ_next, sw,
                                      planes, n_hull, hx, n_j, c_j, origin, eu, ev, tiny, seg_a, seg_b, seg_p, seg_w,
                                      n_seg, start_seg + budget)
    if not ok:
        for e in range(start_seg, n_seg):
            self_cross[seg_p[e]] = 0
        for r in range(sel.shape[0]):
            if poly_solid[sel[r]] >= 0:
                mark[sel[r]] = 0
        return start_seg, False
    return n_seg, True


@njit(cache=True)
def _outline_pass(which, x, sel, occ, occ_loop, poly_loop, poly_solid, occ_nb, occ_vid, occ_next, sw, planes, n_hull,
                  hx, n_j, c_j, origin, eu, ev, tiny, seg_a, seg_b, seg_p, seg_w, n_seg, seg_end):
    """One side's outlines for :func:`_solid_outlines`: the faces marked ``which`` (1 front,
    2 back: each edge walked backwards, from ``occ_next[q]`` to q), their edges without a
    neighbour marked the same chained into closed loops by their vertex ids. Returns
    ``n_seg, ok`` (False: a chain did not close, or the segments would pass ``seg_end``)."""
    mark, head, link, used, rep, self_cross = sw[0], sw[1], sw[2], sw[3], sw[4], sw[5]
    chain, cb_a, cb_b = sw[6], sw[7], sw[8]
    back = which == 2
    # the emitted edges, listed by their start vertex
    n_em = 0
    for r in range(sel.shape[0]):
        pid = sel[r]
        if poly_solid[pid] < 0 or mark[pid] != which:
            continue
        for q in range(occ_loop[poly_loop[pid]], occ_loop[poly_loop[pid + 1]]):  # every loop's edges
            nb = occ_nb[q]
            if nb >= 0 and mark[nb] == which:
                continue
            v = occ_vid[occ_next[q]] if back else occ_vid[q]
            link[q] = head[v]
            head[v] = q
            n_em += 1
    ok = True
    for r in range(sel.shape[0]):
        pid = sel[r]
        if not ok:
            break
        if poly_solid[pid] < 0 or mark[pid] != which:
            continue
        for q0 in range(occ_loop[poly_loop[pid]], occ_loop[poly_loop[pid + 1]]):
            nb = occ_nb[q0]
            if (nb >= 0 and mark[nb] == which) or used[q0]:
                continue
            # walk the loop from edge q0
            n_ch = 0
            q = q0
            start = occ_vid[occ_next[q0]] if back else occ_vid[q0]
            while True:
                used[q] = 1
                p = occ_next[q] if back else q
                for c in range(3):
                    chain[n_ch, c] = occ[p, c]
                n_ch += 1
                v = occ_vid[q] if back else occ_vid[occ_next[q]]
                if v == start:
                    break
                e = head[v]
                while e >= 0 and used[e]:
                    e = link[e]
                if e < 0 or n_ch >= n_em:
                    ok = False  # not a closed chain (cannot happen for a patch's faces)
                    break
                head[v] = link[e]
                q = e
            if not ok:
                break
            n_in = _clip_chain(chain, n_ch, x, planes, n_hull, cb_a, cb_b)
            if n_in < 0 or n_seg + n_in > seg_end:
                ok = False
                break
            if n_in < 3:
                continue
            s = poly_solid[pid]
            if rep[s] < 0:
                rep[s] = pid
            _project(cb_a, n_in, x, hx, n_j, c_j, origin, eu, ev, tiny, seg_a, n_seg)
            first = n_seg
            for k in range(n_in):
                m = first + k + 1 if k + 1 < n_in else first
                seg_b[first + k, 0], seg_b[first + k, 1] = seg_a[m, 0], seg_a[m, 1]
                seg_p[first + k] = rep[s] + 1
                seg_w[first + k] = 1
            self_cross[rep[s] + 1] = 1
            n_seg += n_in
    # reset the work arrays (the marks stay: the caller clears them)
    for r in range(sel.shape[0]):
        pid = sel[r]
        if poly_solid[pid] < 0:
            continue
        rep[poly_solid[pid]] = -1
        for q in range(occ_loop[poly_loop[pid]], occ_loop[poly_loop[pid + 1]]):
            head[occ_vid[q]] = -1
            used[q] = 0
    return n_seg, ok


@njit(cache=True)
def _clip_chain(chain, n, x, planes, n_planes, cb_a, cb_b):
    """A closed chain of points (an outline, not planar) clipped to the planes through x
    (Sutherland–Hodgman, each plane through x: the projection of the clipped chain is the
    projected chain clipped, winding numbers kept inside) into ``cb_a``; its size, -1 if it
    would outgrow the buffers."""
    return _clip_planes(chain, 0, n, x, planes, n_planes, cb_a, cb_b, cb_a.shape[0] // 2)


@njit(cache=True)
def _solid_buffers(occ, n_poly, occ_vid):
    """Work arrays of :func:`_solid_outlines`."""
    n = occ.shape[0]
    n_vid = 1
    for q in range(n):
        n_vid = max(n_vid, occ_vid[q] + 1)
    cap = 2 * n + 8
    return (np.zeros(n_poly, np.int64), np.full(n_vid, -1, np.int64), np.full(n, -1, np.int64), np.zeros(n, np.int64),
            np.full(n_poly, -1, np.int64), np.zeros(n_poly + 1, np.int64), np.empty((n + 1, 3)), np.empty((cap, 3)),
            np.empty((cap, 3)))


@njit(cache=True)
def _loops_of_polygons(occ_poly, n_poly):
    """(P + 1,) int64 offsets: the loops of polygon p are ``out[p]:out[p + 1]`` (loops sorted by polygon)."""
    out = np.zeros(n_poly + 1, np.int64)
    for L in range(occ_poly.shape[0]):
        out[occ_poly[L] + 1] += 1
    for p in range(n_poly):
        out[p + 1] += out[p]
    return out


@njit(cache=True)
def _buffers(j2, hull, occ_loop, n_poly):
    """Work arrays of :func:`_visible_one`, sized for every occluder at once."""
    n_hull = hull.shape[0]
    n_loops = occ_loop.shape[0] - 1
    kmax = 3
    for L in range(n_loops):
        kmax = max(kmax, occ_loop[L + 1] - occ_loop[L])
    kmax += n_hull + 2
    emax = j2.shape[0] + n_loops * kmax + 1
    return (np.empty((emax, 2)), np.empty((emax, 2)), np.empty(emax, np.int64), np.empty(emax, np.int64),
            np.empty((kmax, 3)), np.empty((kmax, 3)), np.empty(4 * emax), np.zeros(n_poly + 1, np.int64),
            np.empty(emax, np.int64), np.empty(emax), np.empty(emax), np.empty(emax), np.empty(3), np.empty(3),
            np.empty((emax, 2)), np.empty(emax + 1, np.int64))


@njit(cache=True)
def visible_form_factors(points, n_i, j2, j_loop, origin, eu, ev, n_j, c_j, hull, occ, occ_loop, occ_poly, poly_normal,
                         poly_point, tiny, poly_box, box_ptr, box_planes, poly_solid, solid_open, occ_nb, occ_vid, occ_next):
    """Form factors from differential areas (points, common normal n_i) to the part of J
    each point sees past the occluders.

    Parameters
    ----------
    points : (m, 3) float64
    n_i : (3,) float64
        Unit normal of the emitting side.
    j2 : (nj, 2) float64
        J's loops in the 2-D basis (origin, eu, ev) of its plane, outer loops
        counter-clockwise, holes clockwise; j_loop (l + 1,) int64 offsets.
    origin, eu, ev, n_j : (3,) float64
        The basis; ``(eu, ev, n_j)`` right-handed, n_j facing the points.
    c_j : float
        J's plane: ``n_j · y = c_j``; the points have ``n_j · x > c_j``.
    hull : (h, 3) float64
        Convex hull of J (3-D, in order).
    occ : (no, 3) float64
        Occluder loops (3-D), occ_loop (lo + 1,) int64 offsets, occ_poly (lo,) int64 their
        polygon (non-decreasing: a polygon's loops are consecutive).
    poly_normal, poly_point : (P, 3) float64
        Plane of each occluder polygon (loops counter-clockwise about the normal, holes clockwise).
    tiny : float
        Distance below which a point counts as in an occluder's plane.
    poly_box : (P,) int64
        The closed convex box each occluder is a face of (-1 none; its normal outward),
        ``box_ptr`` (b + 1,) int64 and ``box_planes`` (k, 5) float64 the boxes' planes
        (:func:`viscx.queries.formfactor.closed_boxes`): a point outside a box skips its
        faces as one convex polygon (:func:`_visible_one`).
    poly_solid : (P,) int64
        The surface patch each occluder is a face of, numbered from 0 (-1 none; the face's
        loops whole: :func:`viscx.queries.formfactor.surface_patches`); ``solid_open`` (s,)
        int64 0 for a closed solid every point is outside of (its normals outward), 1 for
        any other patch; ``occ_nb`` (no,) int64 the occluder across the edge from each loop
        vertex to the next (``occ_next`` (no,) int64, its index), -1 none; ``occ_vid`` (no,)
        int64 the vertices' ids (equal for one point). A patch's front faces, and an open
        one's back faces, enter as their outlines (:func:`_solid_outlines`).

    Returns
    -------
    (m,) float64
    """
    n_poly = poly_normal.shape[0]
    poly_loop = _loops_of_polygons(occ_poly, n_poly)
    sel = np.arange(n_poly)
    box_state = np.zeros(box_ptr.shape[0], np.int64)
    seg_a, seg_b, seg_p, seg_w, buf_a, buf_b, brk, wind, act, act_v, act_v0, act_v1, p0, p1, hull_pts, hull_idx = _buffers(
        j2, hull, occ_loop, n_poly)
    box_head = np.full(box_ptr.shape[0], -1, np.int64)
    box_next = np.empty(n_poly, np.int64)
    box_list = np.empty(box_ptr.shape[0], np.int64)
    sw = _solid_buffers(occ, n_poly, occ_vid)
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        out[i], brk = _visible_one(points[i], n_i, j2, j_loop, sel, origin, eu, ev, n_j, c_j, hull, occ, occ_loop,
                                   poly_loop, poly_normal, poly_point, tiny, poly_box, box_ptr, box_planes, box_state,
                                   box_head, box_next, box_list, hull_pts, hull_idx, seg_a, seg_b, seg_p, seg_w, buf_a, buf_b, brk, wind, act, act_v, act_v0, act_v1, p0, p1,
                                   poly_solid, solid_open, occ_nb, occ_vid, occ_next, sw)
    return out


@njit(cache=True, nogil=True)
def blocked_form_factors(points, point_group, group_ptr, group_occ, n_i, j2, j_loop, origin, eu, ev, n_j, c_j, hull, occ,
                         occ_loop, occ_poly, poly_normal, poly_point, tiny, poly_box, box_ptr, box_planes, poly_solid,
                         solid_open, occ_nb, occ_vid, occ_next):
    """The part of F(x → J) that the occluders hide, ``F(x → J) − F(x → visible part of J)``,
    each point seeing past its own group's occluders only.

    Parameters
    ----------
    points : (m, 3) float64
    point_group : (m,) int64
        The group of each point (a cell of the emitter whose shaft to J meets few occluders).
    group_ptr, group_occ : (g + 1,), (k,) int64
        The occluder polygons of group g: ``group_occ[group_ptr[g]:group_ptr[g + 1]]``.
    n_i, ... box_planes :
        As :func:`visible_form_factors`.

    Returns
    -------
    (m,) float64
        Zero for a point whose group has no occluder.
    """
    n_poly = poly_normal.shape[0]
    poly_loop = _loops_of_polygons(occ_poly, n_poly)
    none = np.zeros(0, np.int64)
    box_state = np.zeros(box_ptr.shape[0], np.int64)
    seg_a, seg_b, seg_p, seg_w, buf_a, buf_b, brk, wind, act, act_v, act_v0, act_v1, p0, p1, hull_pts, hull_idx = _buffers(
        j2, hull, occ_loop, n_poly)
    box_head = np.full(box_ptr.shape[0], -1, np.int64)
    box_next = np.empty(n_poly, np.int64)
    box_list = np.empty(box_ptr.shape[0], np.int64)
    sw = _solid_buffers(occ, n_poly, occ_vid)
    out = np.zeros(points.shape[0])
    for i in range(points.shape[0]):
        g = point_group[i]
        sel = group_occ[group_ptr[g]:group_ptr[g + 1]]
        if sel.shape[0] == 0:
            continue
        whole, brk = _visible_one(points[i], n_i, j2, j_loop, none, origin, eu, ev, n_j, c_j, hull, occ, occ_loop,
                                  poly_loop, poly_normal, poly_point, tiny, poly_box, box_ptr, box_planes, box_state,
                                  box_head, box_next, box_list, hull_pts, hull_idx, seg_a, seg_b, seg_p, seg_w, buf_a, buf_b, brk, wind, act, act_v, act_v0, act_v1, p0, p1,
                                   poly_solid, solid_open, occ_nb, occ_vid, occ_next, sw)
        seen, brk = _visible_one(points[i], n_i, j2, j_loop, sel, origin, eu, ev, n_j, c_j, hull, occ, occ_loop,
                                 poly_loop, poly_normal, poly_point, tiny, poly_box, box_ptr, box_planes, box_state,
                                 box_head, box_next, box_list, hull_pts, hull_idx, seg_a, seg_b, seg_p, seg_w, buf_a, buf_b, brk, wind, act, act_v, act_v0, act_v1, p0, p1,
                                   poly_solid, solid_open, occ_nb, occ_vid, occ_next, sw)
        out[i] = whole - seen
    return out


# --------------------------------------------------------------------------------------
# shafts: which occluders meet the convex hull of two planar polygons


@njit(cache=True)
def _separated_on(ax, ay, az, pa, pb, poly_pts, lo, hi, tol):
    """Whether the axis separates conv(pa ∪ pb) from conv(poly_pts[lo:hi]) by more than
    ``tol`` (a length; a zero axis separates nothing)."""
    size = np.sqrt(ax * ax + ay * ay + az * az)
    if size == 0.0:
        return False
    a_lo, a_hi = np.inf, -np.inf
    for k in range(pa.shape[0]):
        d = pa[k, 0] * ax + pa[k, 1] * ay + pa[k, 2] * az
        a_lo, a_hi = min(a_lo, d), max(a_hi, d)
    for k in range(pb.shape[0]):
        d = pb[k, 0] * ax + pb[k, 1] * ay + pb[k, 2] * az
        a_lo, a_hi = min(a_lo, d), max(a_hi, d)
    b_lo, b_hi = np.inf, -np.inf
    for k in range(lo, hi):
        d = poly_pts[k, 0] * ax + poly_pts[k, 1] * ay + poly_pts[k, 2] * az
        b_lo, b_hi = min(b_lo, d), max(b_hi, d)
    t = tol * size
    return b_hi <= a_lo + t or a_hi <= b_lo + t


@njit(cache=True)
def _boxes_apart(pa, pb, poly_pts, lo, hi, tol):
    """Whether the bounding box of pa ∪ pb and that of ``poly_pts[lo:hi]`` are more than
    ``tol`` apart along an axis."""
    for d in range(3):
        a_lo = min(pa[:, d].min(), pb[:, d].min())
        a_hi = max(pa[:, d].max(), pb[:, d].max())
        b_lo = poly_pts[lo:hi, d].min()
        b_hi = poly_pts[lo:hi, d].max()
        if b_hi <= a_lo + tol or a_hi <= b_lo + tol:
            return True
    return False


@njit(cache=True, nogil=True)
def shaft_boxes_meet(cells, target, cand_cell, cand_poly, poly_pts, poly_lo, poly_hi, tol):
    """The first test of :func:`shaft_meets` only (conservative: a superset of the
    polygons meeting the shaft): the candidates whose bounding box meets the shaft's.

    Returns
    -------
    (c,) bool
    """
    out = np.zeros(cand_cell.shape[0], np.bool_)
    for c in range(cand_cell.shape[0]):
        p = cand_poly[c]
        out[c] = not _boxes_apart(cells[cand_cell[c]], target, poly_pts, poly_lo[p], poly_hi[p], tol)
    return out


@njit(cache=True, nogil=True)
def shaft_meets(cells, cell_normal, target, target_normal, cand_cell, cand_poly, poly_pts, poly_lo, poly_hi,
                poly_normal, tol):
    """Which candidate polygons meet the interior of the *shaft* of a cell and the target:
    the convex hull of two convex planar polygons (every segment from one to the other lies
    in it). Exact separating-axis test of two convex sets: the hull's facet normals lie among
    the normals of the two polygons and of the planes through an edge of one and a vertex of
    the other; its edges among the polygons' edges and the segments between their vertices;
    a candidate (its vertices' convex hull: conservative for a non-convex one) is separated
    when one of these axes, its own normal, its in-plane edge normals or the cross products
    of the two sets of edges separates them by more than ``tol`` (touching is not meeting).

    Parameters
    ----------
    cells : (g, kc, 3) float64
        Convex polygons (vertices in order), e.g. triangles of the emitter; cell_normal (g, 3).
    target, target_normal : (kt, 3), (3,) float64
        The convex hull of the receiver (in order) and its plane's normal.
    cand_cell, cand_poly : (c,) int64
        Candidate pairs (cell, polygon).
    poly_pts : (n, 3) float64
        Vertices of the polygons, polygon p at ``poly_lo[p]:poly_hi[p]``; poly_normal (P, 3).
    tol : float

    Returns
    -------
    (c,) bool
    """
    out = np.zeros(cand_cell.shape[0], np.bool_)
    kt = target.shape[0]
    for c in range(cand_cell.shape[0]):
        pa = cells[cand_cell[c]]
        kc = pa.shape[0]
        p = cand_poly[c]
        lo, hi = poly_lo[p], poly_hi[p]
        if _boxes_apart(pa, target, poly_pts, lo, hi, tol):  # boxes first
            continue
        sep = False
        n = cell_normal[cand_cell[c]]
        if _separated_on(n[0], n[1], n[2], pa, target, poly_pts, lo, hi, tol):
            continue
        if _separated_on(target_normal[0], target_normal[1], target_normal[2], pa, target, poly_pts, lo, hi, tol):
            continue
        m = poly_normal[p]
        if _separated_on(m[0], m[1], m[2], pa, target, poly_pts, lo, hi, tol):
            continue
        # planes through an edge of one polygon and a vertex of the other
        for s in range(2):
            src, dst = (pa, target) if s == 0 else (target, pa)
            ks = src.shape[0]
            for e in range(ks):
                a, b = src[e], src[(e + 1) % ks]
                ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
                for v in range(dst.shape[0]):
                    wx, wy, wz = dst[v, 0] - a[0], dst[v, 1] - a[1], dst[v, 2] - a[2]
                    if _separated_on(ey * wz - ez * wy, ez * wx - ex * wz, ex * wy - ey * wx, pa, target, poly_pts,
                                     lo, hi, tol):
                        sep = True
                        break
                if sep:
                    break
            if sep:
                break
        if sep:
            continue
        # the candidate's in-plane edge normals, and cross products of edges
        for q in range(lo, hi):
            r = q + 1 if q + 1 < hi else lo
            fx, fy, fz = poly_pts[r, 0] - poly_pts[q, 0], poly_pts[r, 1] - poly_pts[q, 1], poly_pts[r, 2] - poly_pts[q, 2]
            if _separated_on(m[1] * fz - m[2] * fy, m[2] * fx - m[0] * fz, m[0] * fy - m[1] * fx, pa, target, poly_pts,
                             lo, hi, tol):
                sep = True
                break
            for e in range(kc + kt + kc * kt):
                if e < kc:
                    a, b = pa[e], pa[(e + 1) % kc]
                elif e < kc + kt:
                    a, b = target[e - kc], target[(e - kc + 1) % kt]
                else:
                    a, b = pa[(e - kc - kt) // kt], target[(e - kc - kt) % kt]
                ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
                if _separated_on(ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx, pa, target, poly_pts, lo, hi,
                                 tol):
                    sep = True
                    break
            if sep:
                break
        out[c] = not sep
    return out


@njit(cache=True)
def _segment_meets_box(ax, ay, bx, by, lo_u, lo_v, hi_u, hi_v):
    """Whether the 2-D segment (a, b) meets the closed box [lo, hi] (separating axes: the
    box's two and the segment's normal)."""
    if max(ax, bx) < lo_u or min(ax, bx) > hi_u or max(ay, by) < lo_v or min(ay, by) > hi_v:
        return False
    dx, dy = bx - ax, by - ay
    pos, neg = False, False
    for cu in (lo_u, hi_u):
        for cv in (lo_v, hi_v):
            s = dx * (cv - ay) - dy * (cu - ax)
            pos = pos or s >= 0.0
            neg = neg or s <= 0.0
    return pos and neg


@njit(cache=True)
def umbra_triangles(tri, hull, n_t, c_t, eu, ev, heights, sec_ptr, sec, margin):
    """(g,) bool: the triangles of an emitter from every point of which the whole of J is
    hidden by a closed solid, shown by one of its sections (``sec[sec_ptr[k]:sec_ptr[k + 1]]``,
    (s, 4) float64 segments ``(u_a, v_a, u_b, v_b)`` in the basis (eu, ev), by the plane
    parallel to J at height ``heights[k]`` above it: ``n_t · y = c_t + heights[k]``).

    A plane P strictly between a triangle T and J (every vertex of T higher than P by more
    than ``margin``) meets the segments from T to J in the convex hull of the points where
    the segments between their vertices (T's three, J's hull ``hull`` (h, 3)) cross it (the
    shaft conv(T ∪ J) cut by P: its vertices lie on edges of the shaft that cross P, and
    those join a vertex of T to one of J). If the box around those points (grown by
    ``margin``) meets no segment of the section, it lies wholly inside or wholly outside
    the solid's section; a ray from its centre along +u that crosses an odd number of
    segments says inside (the crossing points of an edge of the solid are computed once
    per edge by the caller, so the section's polylines share their vertices bit for bit
    and the half-open rule counts each crossing once). Then every segment from a point x
    of T to J passes through a point of P inside the solid; as x is outside it (the
    solid lies in the closed front half-space of T's plane, so a ray from x backwards meets
    none of its faces: even parity), the segment crosses a face of the solid before that
    point, strictly between x and J: the visible part of J from x is empty, and the hidden
    part is F(x → J), whole. Conservative: a triangle not shown so (a box meeting the
    section, a plane not between) is simply kept.

    Parameters
    ----------
    tri : (g, 3, 3) float64
    hull : (h, 3) float64
        J's convex hull (its vertices on the plane ``n_t · y = c_t``).
    n_t, eu, ev : (3,) float64
        J's normal (towards the triangles) and a basis of its plane.
    heights : (k,) float64
    sec_ptr : (k + 1,) int64
    margin : float
    """
    out = np.zeros(tri.shape[0], np.bool_)
    for i in range(tri.shape[0]):
        h = np.empty(3)
        for a in range(3):
            h[a] = tri[i, a, 0] * n_t[0] + tri[i, a, 1] * n_t[1] + tri[i, a, 2] * n_t[2] - c_t
        low = min(h[0], min(h[1], h[2]))
        for k in range(heights.shape[0]):
            hp = heights[k]
            if hp <= margin or low <= hp + margin or sec_ptr[k + 1] == sec_ptr[k]:
                continue
            lo_u, lo_v, hi_u, hi_v = np.inf, np.inf, -np.inf, -np.inf
            for a in range(3):
                s = 1.0 - hp / h[a]
                for b in range(hull.shape[0]):
                    pu, pv = 0.0, 0.0
                    for d in range(3):
                        p = tri[i, a, d] + s * (hull[b, d] - tri[i, a, d])
                        pu += p * eu[d]
                        pv += p * ev[d]
                    lo_u, hi_u = min(lo_u, pu), max(hi_u, pu)
                    lo_v, hi_v = min(lo_v, pv), max(hi_v, pv)
            lo_u, lo_v, hi_u, hi_v = lo_u - margin, lo_v - margin, hi_u + margin, hi_v + margin
            cu, cv = 0.5 * (lo_u + hi_u), 0.5 * (lo_v + hi_v)
            crossings = 0
            meets = False
            for s_ in range(sec_ptr[k], sec_ptr[k + 1]):
                ax, ay, bx, by = sec[s_, 0], sec[s_, 1], sec[s_, 2], sec[s_, 3]
                if _segment_meets_box(ax, ay, bx, by, lo_u, lo_v, hi_u, hi_v):
                    meets = True
                    break
                if (ay > cv) != (by > cv):
                    if ax + (cv - ay) / (by - ay) * (bx - ax) > cu:
                        crossings += 1
            if not meets and crossings % 2 == 1:
                out[i] = True
                break
    return out


# --------------------------------------------------------------------------------------
# a point's view of every polygon at once (one evaluation per point for a whole matrix row)


@njit(cache=True)
def _inside_plane(x, pts, loop_lo, loop_hi, first, last, normal):
    """Whether x (in the polygon's plane) lies inside the polygon's loops (even–odd rule in
    the plane, the coordinate of the normal's largest component dropped)."""
    k = 0
    if abs(normal[1]) > abs(normal[k]):
        k = 1
    if abs(normal[2]) > abs(normal[k]):
        k = 2
    a, b = (k + 1) % 3, (k + 2) % 3
    inside = False
    for L in range(first, last):
        lo, hi = loop_lo[L], loop_hi[L]
        for i in range(lo, hi):
            j = i + 1 if i + 1 < hi else lo
            ya, yb = pts[i, b] - x[b], pts[j, b] - x[b]
            if (ya > 0) != (yb > 0):
                xa, xb = pts[i, a] - x[a], pts[j, a] - x[a]
                if xa + (xb - xa) * ya / (ya - yb) > 0:
                    inside = not inside
    return inside


@njit(cache=True)
def _trapezoid(x, n_i, fa, fb, fc, u0, u1, vb0, vb1, vt0, vt1, p0, p1):
    """F from (x, n_i) to the trapezoid (u0, vb0), (u1, vb1), (u1, vt1), (u0, vt0) of a
    wedge's plane (points x + fc + u fa + v fb): Lambert's contour sum."""
    total = 0.0
    us = (u0, u1, u1, u0)
    vs = (vb0, vb1, vt1, vt0)
    for k in range(4):
        r = (k + 1) % 4
        for c in range(3):
            p0[c] = x[c] + fc[c] + us[k] * fa[c] + vs[k] * fb[c]
            p1[c] = x[c] + fc[c] + us[r] * fa[c] + vs[r] * fb[c]
        total += _gamma_dot(x, p0, p1, n_i)
    return abs(total) / TWO_PI


@njit(cache=True)
def _grow(a, n):
    if n < a.shape[0]:
        return a
    b = np.empty(2 * a.shape[0] + 16)
    b[:a.shape[0]] = a
    return b


@njit(cache=True, inline="always")
def _edge_windings(seg_a, seg_b, seg_w, n_seg, lo_u, hi_u, brk):
    """The sweep's edges (projected, u across the slabs) readied for it: each weight
    ``seg_w`` (n,) its polygon's sign, kept where the edge runs right to left (it adds the
    sign below it), negated left to right, 0 vertical (it bounds no slab); ``lo_u, hi_u``
    (n,) float its u range; each left end a break (``brk`` grown as needed). Returns
    ``brk, n_brk``."""
    n_brk = 0
    for e in range(n_seg):
        if seg_a[e, 0] > seg_b[e, 0]:
            pass
        elif seg_a[e, 0] < seg_b[e, 0]:
            seg_w[e] = -seg_w[e]
        else:
            seg_w[e] = 0
        lo_u[e] = min(seg_a[e, 0], seg_b[e, 0])
        hi_u[e] = max(seg_a[e, 0], seg_b[e, 0])
        brk = _grow(brk, n_brk)
        brk[n_brk] = seg_a[e, 0]
        n_brk += 1
    return brk, n_brk


@njit(cache=True)
def _flush_owner(runs, run_o, e, k, seg_a, slope, x, n_i, fa, fb, fc, col, seen, p0, p1):
    """Γ · n of edge e's current run on side k (0: the owner's region lies above it, run left
    to right; 1: below it, right to left) added to its owner's column (then cleared)."""
    ua, ub = runs[e, k, 0], runs[e, k, 1]
    va = seg_a[e, 1] + (ua - seg_a[e, 0]) * slope[e]
    vb = seg_a[e, 1] + (ub - seg_a[e, 0]) * slope[e]
    for c in range(3):
        p0[c] = x[c] + fc[c] + ua * fa[c] + va * fb[c]
        p1[c] = x[c] + fc[c] + ub * fa[c] + vb * fb[c]
    g = _gamma_dot(x, p0, p1, n_i) if k == 0 else _gamma_dot(x, p1, p0, n_i)
    seen[col[run_o[e, k]]] += g / TWO_PI
    run_o[e, k] = -1


@njit(cache=True, inline="always")
def _set_runs(runs, run_o, e, a, b, u0, seg_a, slope, x, n_i, fa, fb, fc, col, seen, p0, p1):
    """Edge e's runs from u0 on, with owner a above it and b below it (-1 none): side 0 runs
    for a, side 1 for b, none where both are one owner (the edge is inside its region); a run
    whose owner changes is flushed (:func:`_flush_owner`) at u0 and a new one opened. Inlined
    in both sweeps (numba's ``inline``): called, it cost them 20 % (office(1000), Cornell)."""
    for kk in range(2):
        o = (a if kk == 0 else b) if a != b else -1
        if run_o[e, kk] == o:
            continue
        if run_o[e, kk] >= 0:
            runs[e, kk, 1] = u0
            _flush_owner(runs, run_o, e, kk, seg_a, slope, x, n_i, fa, fb, fc, col, seen, p0, p1)
        if o >= 0:
            run_o[e, kk] = o
            runs[e, kk, 0] = u0


@njit(cache=True)
def _cover_key(p):
    """A 64-bit key of polygon p (splitmix64 of p): the XOR of the keys of a set of covering
    polygons tells, but for a 2^-64 chance, whether two sets are equal."""
    z = np.uint64(p + 1) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True)
def _collinear(seg_a, seg_b, e, f, tol):
    """Whether both ends of segment f lie within ``tol`` of segment e's line (a "crossing"
    of the two is rounding: :data:`SNAP`)."""
    rx, ry = seg_b[e, 0] - seg_a[e, 0], seg_b[e, 1] - seg_a[e, 1]
    size = tol * np.sqrt(rx * rx + ry * ry)
    h0 = rx * (seg_a[f, 1] - seg_a[e, 1]) - ry * (seg_a[f, 0] - seg_a[e, 0])
    h1 = rx * (seg_b[f, 1] - seg_a[e, 1]) - ry * (seg_b[f, 0] - seg_a[e, 0])
    return abs(h0) <= size and abs(h1) <= size


@njit(cache=True)
def _snap_breaks(us, n, tol):
    """The sorted breaks ``us[:n]`` without those within ``tol`` of the last one kept (in
    place, the first and the last kept); returns how many are left."""
    if n < 2:
        return n
    m = 1
    for k in range(1, n):
        if us[k] - us[m - 1] > tol:
            us[m] = us[k]
            m += 1
    if us[n - 1] > us[m - 1]:
        us[m - 1] = us[n - 1]  # the sweep still ends at the last break
    return m


@njit(cache=True)
def _kept(sure, act_v0, act_v1, q):
    """Whether region q of a slab (below edge q) keeps the owner it had in the last slab with
    the same bounding edges: sure then (``sure`` 1: one covering polygon or none; 2: more, and
    solid) and, if more, solid now (thicker than MEMO_GAP at both sides)."""
    if sure == 1:
        return True
    return sure == 2 and min(act_v0[q] - act_v0[q + 1], act_v1[q] - act_v1[q + 1]) > MEMO_GAP


@njit(cache=True)
def _steepest(seg_a, seg_b, n_seg):
    """max |dv/du| of the edges ``[seg_a, seg_b)[:n_seg]`` (inf for a vertical one; points
    of no length left out)."""
    most = 0.0
    for e in range(n_seg):
        du, dv = abs(seg_b[e, 0] - seg_a[e, 0]), abs(seg_b[e, 1] - seg_a[e, 1])
        if dv > most * du:
            most = np.inf if du == 0.0 else dv / du
    return most


@njit(cache=True)
def _turn_from_steep(seg_a, seg_b, n_seg, fa, fb, ang):
    """Turn the 2-D basis (fa, fb) of a wedge, and the edges' coordinates with it,
    so that the vertical lies in the middle of the widest gap between the edges' directions
    (angles mod π; ``ang`` (n,) float64 work): with n edges the widest gap is at least π / n,
    so no edge is steeper than about 2 n / π. Returns the turned basis (new arrays)."""
    n = 0
    for e in range(n_seg):
        du, dv = seg_b[e, 0] - seg_a[e, 0], seg_b[e, 1] - seg_a[e, 1]
        if du != 0.0 or dv != 0.0:
            t = np.arctan2(dv, du)
            ang[n] = t + np.pi if t < 0.0 else (0.0 if t >= np.pi else t)
            n += 1
    a = np.sort(ang[:n])
    mid, gap = 0.5 * (a[0] + a[n - 1] - np.pi), a[0] + np.pi - a[n - 1]
    for k in range(n - 1):
        if a[k + 1] - a[k] > gap:
            gap = a[k + 1] - a[k]
            mid = 0.5 * (a[k] + a[k + 1])
    # directions turned by phi = π/2 - mid: (u', v') = R(phi) (u, v), (fa', fb') = R(phi) (fa, fb)
    phi = 0.5 * np.pi - mid
    c, s = np.cos(phi), np.sin(phi)
    for e in range(n_seg):
        u, v = seg_a[e, 0], seg_a[e, 1]
        seg_a[e, 0], seg_a[e, 1] = c * u - s * v, s * u + c * v
        u, v = seg_b[e, 0], seg_b[e, 1]
        seg_b[e, 0], seg_b[e, 1] = c * u - s * v, s * u + c * v
    ta, tb = np.empty(3), np.empty(3)
    for k in range(3):
        ta[k] = c * fa[k] - s * fb[k]
        tb[k] = s * fa[k] + c * fb[k]
    return ta, tb


@njit(cache=True)
def _nearest(cover, n_cover, d, poly_normal, side, rank):
    """The polygon of ``cover[:n_cover]`` that the ray x + t d meets first (t = -side / (n · d)
    > 0 least), or -1.

    A tie (t within 1e-9) between two faces in one plane, one lying on the other, goes to
    the smaller on the larger's front side and to the larger on its back side
    (docs/queries.md, "Faces lying on faces"). Faces in different planes tie only where the
    ray meets both at once, at a common edge or vertex seen edge-on (a sliver of a region
    along it): the lesser t is the nearer there too, whatever the areas (the coplanar rule
    let a box's back face win such slivers from its front face: -4.1e-13 of F to the back
    face, tests/test_formfactor_boxes.py)."""
    now = -1
    best = np.inf
    for r in range(n_cover):
        pr = cover[r]
        dn = poly_normal[pr, 0] * d[0] + poly_normal[pr, 1] * d[1] + poly_normal[pr, 2] * d[2]
        if dn == 0.0:
            continue
        t = -side[pr] / dn
        if t <= 0:
            continue
        if now >= 0 and abs(t - best) <= 1e-9 * t and _coplanar(poly_normal, side, pr, now):
            big, small = (pr, now) if rank[pr] > rank[now] else (now, pr)
            now = small if side[big] > 0 else big
        elif t < best:
            best = t
            now = pr
    return now


@njit(cache=True)
def _coplanar(poly_normal, side, p, q):
    """Whether polygons p and q lie in one plane (to 1e-9), by their normals and their
    distances ``side`` from the point."""
    dot = poly_normal[p, 0] * poly_normal[q, 0] + poly_normal[p, 1] * poly_normal[q, 1] + poly_normal[p, 2] * poly_normal[q, 2]
    return abs(dot) >= 1.0 - 1e-9 and abs(abs(side[p]) - abs(side[q])) <= 1e-9 * max(abs(side[p]), abs(side[q]))


@njit(cache=True)
def _grow_int(a, n):
    """``a`` (k, ...) int64 with room for row n (twice as long, the rows kept)."""
    if n < a.shape[0]:
        return a
    shape = (2 * a.shape[0] + 16,) + a.shape[1:]
    b = np.empty(shape, np.int64)
    b[:a.shape[0]] = a
    return b


@njit(cache=True)
def _height(seg_a, slope, e, u):
    """Height v of edge e's line at u (the one formula of the sweep: equal heights compare equal)."""
    return seg_a[e, 1] + (u - seg_a[e, 0]) * slope[e]


@njit(cache=True)
def _above(seg_a, seg_b, slope, e, f, ve, u0, u1):
    """Whether edge e (height ``ve`` at the middle of the slab [u0, u1]) goes above edge f in
    the sweep's order over the slab. The order is kept from slab to slab and changed only at
    events (:func:`_sweep_runs`), so it must be right for as long as the two edges go on side
    by side, not only in this slab; the crossings at u0 (within SNAP after it) have been made,
    so two edges do not cross inside the slab. And it must be a total order: edges starting
    at one break are placed one after the other by binary search.

    Heights at the middle apart by more than :data:`ORDER_NOISE` tell. Closer, the edges are:

    - collinear within :data:`SNAP`, each on the other's line: they keep the order they had
      (they do not cross; an edge shorter than SNAP at a corner of the wedge lies on every
      line through that corner, but not the other way round);
    - meeting at u0: within ORDER_NOISE there, their lines meeting within :data:`ORDER_MEET`
      of it (a common vertex, a crossing at the break; the vertices of clipped, projected
      polygons are off by up to ~1e-13 at a corner of the wedge, so their heights at a
      narrow slab are rounding): their slopes tell, the greater above to the right (a total
      order on a fan of edges from one point, however short the edges);
    - else apart at u0, or nearly parallel, or converging to u1 (their slopes are rounding
      there): their height difference at the side of the slab where it is larger tells.

    (The slopes' rule alone, whenever the heights were within ORDER_NOISE, put F on the
    wrong side of nearly parallel or converging pairs for good, up to 3e-13 of a point's
    hemisphere on office(1000).)"""
    vf = _height(seg_a, slope, f, 0.5 * (u0 + u1))
    noise = ORDER_NOISE * (1.0 + abs(slope[e]) + abs(slope[f]))
    if abs(ve - vf) > noise:
        return ve > vf
    if _collinear(seg_a, seg_b, e, f, SNAP) and _collinear(seg_a, seg_b, f, e, SNAP):
        return False
    ds = slope[e] - slope[f]
    d0 = _height(seg_a, slope, e, u0) - _height(seg_a, slope, f, u0)
    if abs(d0) <= min(noise, abs(ds) * ORDER_MEET):
        return ds > 0.0
    d1 = _height(seg_a, slope, e, u1) - _height(seg_a, slope, f, u1)
    return d0 > 0.0 if abs(d0) >= abs(d1) else d1 > 0.0


@njit(cache=True)
def _heap_push(heap_k, heap_i, n, key, e, version):
    """Push (key, edge e, version) on the binary min-heap ``heap_k[:n]`` (keys, float64),
    ``heap_i[:n]`` ((e, version) rows, int64); returns the new size (the caller has made room)."""
    j = n
    while j > 0:
        i = (j - 1) >> 1
        if heap_k[i] <= key:
            break
        heap_k[j], heap_i[j, 0], heap_i[j, 1] = heap_k[i], heap_i[i, 0], heap_i[i, 1]
        j = i
    heap_k[j], heap_i[j, 0], heap_i[j, 1] = key, e, version
    return n + 1


@njit(cache=True)
def _heap_pop(heap_k, heap_i, n):
    """Remove the least key of the heap of :func:`_heap_push`; returns the new size."""
    n -= 1
    key, e, version = heap_k[n], heap_i[n, 0], heap_i[n, 1]
    j = 0
    while True:
        c = 2 * j + 1
        if c >= n:
            break
        if c + 1 < n and heap_k[c + 1] < heap_k[c]:
            c += 1
        if heap_k[c] >= key:
            break
        heap_k[j], heap_i[j, 0], heap_i[j, 1] = heap_k[c], heap_i[c, 0], heap_i[c, 1]
        j = c
    if n > 0:
        heap_k[j], heap_i[j, 0], heap_i[j, 1] = key, e, version
    return n


@njit(cache=True)
def _pinched(act, n_act, q, seg_a, slope, u, mark, dirty, n_dirty, slab):
    """Mark (``mark``, ``dirty``: :func:`_sweep_runs`) the regions next to edge position q,
    up and down, while they are thinner than :data:`MEMO_GAP` at u; returns the new count."""
    h = _height(seg_a, slope, act[q], u)
    j = q - 1
    while j >= 0:
        g = _height(seg_a, slope, act[j], u)
        if g - h > MEMO_GAP:
            break
        if mark[act[j]] != slab:
            mark[act[j]] = slab
            dirty[n_dirty] = act[j]
            n_dirty += 1
        h = g
        j -= 1
    h = _height(seg_a, slope, act[q], u)
    j = q + 1
    while j < n_act:
        g = _height(seg_a, slope, act[j], u)
        if h - g > MEMO_GAP:
            break
        if mark[act[j - 1]] != slab:
            mark[act[j - 1]] = slab
            dirty[n_dirty] = act[j - 1]
            n_dirty += 1
        h = g
        j += 1
    return n_dirty


@njit(cache=True)
def _solid_from(seg_a, slope, e, f, u1):
    """About the u (a little before) from which the region between edge e (above) and edge f
    (below), thinner than :data:`MEMO_GAP` somewhere in a slab ending at u1, is thicker than it
    at a slab's left side (their height difference is linear in u); inf if they do not part."""
    ds = slope[e] - slope[f]
    if not ds > 0.0:
        return np.inf
    t1 = _height(seg_a, slope, e, u1) - _height(seg_a, slope, f, u1)
    return u1 + 0.999999 * (MEMO_GAP - t1) / ds - 1e-12


@njit(cache=True)
def _sweep_slabs(x, n_i, fa, fb, fc, us, n_brk, seg_a, seg_b, seg_p, seg_w, n_seg, hi_u, lo_u, slope, live, n_live,
                 has_vertical, poly_normal, side, rank, col, seen, wind, cover, runs, run_o, p0, p1, fw, iw, key_w):
    """The sweep of :func:`_wedge_view` slab by slab: in each slab the active edges sorted
    (:func:`_slab_edges`, the last slab's order kept) and the regions between the first and the
    last edge that changed decided again (the others keep their owners); for a few active
    edges (the Cornell box's ~5-10) the cheaper one, :func:`_sweep_runs` the one for many.
    With ``has_vertical`` (a vertical edge: the vertical sides of neighbouring slabs do not
    cancel) every region of every slab is searched and whole trapezoids are summed: also the
    plain sweep both are checked against (``sweep_kind`` = 1 of :func:`point_views`).

    ``fw`` (3, e) float64, ``iw`` (14, e) int64 and ``key_w`` (e,) uint64 are work arrays."""
    # runs: per edge, bottom/top side: the current run's u range; run_o: its owner (-1 none)
    run_o[:n_seg] = -1
    # the owner of the region below each edge in the last slab, with the edge below it and
    # the covering polygons' signature (:func:`_cover_key`): a region bounded by the same two
    # edges in the next slab, covered by the same polygons, is the same open region (no edge
    # ends between them at the common side; not so across a vertical edge, which bounds no
    # slab), so its nearest polygon is too and is not searched again
    memo_below, memo_owner, memo_slab = iw[1], iw[2], iw[3]
    memo_key = key_w
    memo_slab[:n_seg] = -2
    on = iw[5]
    entry = iw[6]  # the order in which each edge entered the sweep
    act = iw[7]
    act_v, act_v0, act_v1 = fw[0], fw[1], fw[2]
    nxt = 0
    n_on = 0
    d = np.empty(3)
    # the last slab swept (event-local update): its edges top down and its regions' owners
    prev_act, prev_own, own = iw[8], iw[9], iw[10]
    prev_sure = iw[11]  # per region: 1 one covering polygon (or none),
    sure = iw[12]  # 2 more and solid, 0 a sliver (its owner is rounding)
    keep = iw[13]  # per region: its owner kept from the last slab
    stamp = iw[0]
    stamp[:n_seg] = -1
    prev_n = 0
    slab = 0  # slabs swept so far
    last_u1 = np.nan  # the right side of the last one
    for k in range(n_brk - 1):
        u0, u1 = us[k], us[k + 1]
        if not u1 > u0:
            continue
        um = 0.5 * (u0 + u1)
        while nxt < n_live and lo_u[live[nxt]] < um:
            on[n_on] = live[nxt]
            entry[live[nxt]] = nxt
            n_on += 1
            nxt += 1
        n_on, n_act = _slab_edges(on, entry, n_on, u0, u1, seg_a, seg_b, hi_u, slope, act, act_v, act_v0, act_v1, ORDER_TIE)
        if n_act < 2:
            continue
        if not has_vertical:
            # event-local: only the regions whose edges changed since the last slab are redone
            contiguous = last_u1 == u0 and prev_n >= 2
            lo, s = 0, 0
            if contiguous:
                m = min(n_act, prev_n)
                while lo < m and act[lo] == prev_act[lo]:
                    lo += 1
                while s < m - lo and act[n_act - 1 - s] == prev_act[prev_n - 1 - s]:
                    s += 1
            else:
                # a gap: every open run ends where the last slab did
                for r in range(prev_n):
                    e = prev_act[r]
                    for kk in range(2):
                        if run_o[e, kk] >= 0:
                            runs[e, kk, 1] = last_u1
                            _flush_owner(runs, run_o, e, kk, seg_a, slope, x, n_i, fa, fb, fc, col, seen, p0, p1)
            # regions above lo - 1 have the same edges above them (the same covering set), those
            # below n_act - s the same edges below (a vertical line crosses a closed outline with
            # net winding 0): both keep their owners
            # (if their owner is sure: one covering polygon, or more and the region solid now
            # and when searched; a sliver's owner is rounding, searched again as in MEMO_GAP)
            q0 = lo - 1 if lo > 0 else 0
            q1 = min(n_act - s - 1, n_act - 2)
            # the regions outside them that are not sure are redone too, each on its own (a
            # sliver far above the changed ones does not make all between them redone); a
            # kept region of one covering polygon or none holds no memo, as when searched
            r0, r1 = q0, q1
            for r in range(r0):
                keep[r] = _kept(prev_sure[r], act_v0, act_v1, r)
                if keep[r]:
                    own[r] = prev_own[r]
                    sure[r] = prev_sure[r]
                    if sure[r] == 1:
                        memo_slab[act[r]] = -2
                elif r < q0:
                    q0 = r
            for r in range(n_act - 2, r1, -1):
                keep[r] = _kept(prev_sure[r - n_act + prev_n], act_v0, act_v1, r)
                if keep[r]:
                    own[r] = prev_own[r - n_act + prev_n]
                    sure[r] = prev_sure[r - n_act + prev_n]
                    if sure[r] == 1:
                        memo_slab[act[r]] = -2
                elif r > q1:
                    q1 = r
            for r in range(r0, r1 + 1):
                keep[r] = False
            n_cover = 0
            key = np.uint64(0)
            for q in range(q1 + 1):
                p = seg_p[act[q]]
                before = wind[p]
                wind[p] += seg_w[act[q]]
                if before == 0 and wind[p] != 0:
                    cover[n_cover] = p
                    n_cover += 1
                    key ^= _cover_key(p)
                elif before != 0 and wind[p] == 0:
                    key ^= _cover_key(p)
                    for r in range(n_cover):
                        if cover[r] == p:
                            cover[r] = cover[n_cover - 1]
                            n_cover -= 1
                            break
                if keep[q]:
                    continue
                e = act[q]
                now = -1
                if n_cover == 1:
                    now = cover[0]
                elif n_cover > 1:
                    solid = min(act_v0[q] - act_v0[q + 1], act_v1[q] - act_v1[q + 1]) > MEMO_GAP
                    if solid and contiguous and memo_slab[e] >= 0 and memo_below[e] == act[q + 1] and memo_key[e] == key:
                        now = memo_owner[e]
                    else:
                        vm = 0.5 * (act_v[q] + act_v[q + 1])
                        for c in range(3):
                            d[c] = fc[c] + um * fa[c] + vm * fb[c]
                        now = _nearest(cover, n_cover, d, poly_normal, side, rank)
                    memo_slab[e] = slab if solid else -2
                    memo_below[e] = act[q + 1]
                    memo_key[e] = key
                    memo_owner[e] = now
                if n_cover <= 1:
                    memo_slab[e] = -2  # a memo holds only while its region goes on
                own[q] = now
                sure[q] = 1 if n_cover <= 1 else (2 if memo_slab[e] >= 0 else 0)
            for q in range(q1 + 1):
                wind[seg_p[act[q]]] = 0
            memo_slab[act[n_act - 1]] = -2  # no region below the lowest edge
            # the edges next to a redone region: their runs (side 0: the owner above, side 1: below)
            for q in range(q0, min(q1 + 2, n_act)):
                e = act[q]
                stamp[e] = slab
                _set_runs(runs, run_o, e, own[q - 1] if q > 0 else -1, own[q] if q < n_act - 1 else -1, u0, seg_a,
                          slope, x, n_i, fa, fb, fc, col, seen, p0, p1)
            if contiguous:
                # edges that ended at u0: their runs end there
                for r in range(lo, prev_n - s):
                    e = prev_act[r]
                    if stamp[e] != slab:
                        for kk in range(2):
                            if run_o[e, kk] >= 0:
                                runs[e, kk, 1] = u0
                                _flush_owner(runs, run_o, e, kk, seg_a, slope, x, n_i, fa, fb, fc, col, seen, p0, p1)
            for r in range(n_act):
                prev_act[r] = act[r]
            for q in range(n_act - 1):
                prev_own[q] = own[q]
                prev_sure[q] = sure[q]
            prev_n = n_act
            slab += 1
            last_u1 = u1
            continue
        # a vertical edge: every region of the slab searched, whole trapezoids summed
        n_cover = 0
        key = np.uint64(0)
        owner, top = -1, -1
        for q in range(n_act):
            p = seg_p[act[q]]
            before = wind[p]
            wind[p] += seg_w[act[q]]
            if before == 0 and wind[p] != 0:
                cover[n_cover] = p
                n_cover += 1
                key ^= _cover_key(p)
            elif before != 0 and wind[p] == 0:
                key ^= _cover_key(p)
                for r in range(n_cover):
                    if cover[r] == p:
                        cover[r] = cover[n_cover - 1]
                        n_cover -= 1
                        break
            # the region below edge q, down to edge q + 1: its nearest covering polygon
            now = -1
            if n_cover == 1 and q + 1 < n_act:
                now = cover[0]
            elif n_cover > 1 and q + 1 < n_act:
                vm = 0.5 * (act_v[q] + act_v[q + 1])
                for c in range(3):
                    d[c] = fc[c] + um * fa[c] + vm * fb[c]
                now = _nearest(cover, n_cover, d, poly_normal, side, rank)
            if now != owner:
                if owner >= 0:
                    seen[col[owner]] += _trapezoid(x, n_i, fa, fb, fc, u0, u1, act_v0[q], act_v1[q], act_v0[top],
                                                   act_v1[top], p0, p1)
                owner = now
                top = q
        for q in range(n_act):
            wind[seg_p[act[q]]] = 0
        slab += 1
        last_u1 = u1
    if not has_vertical:
        for e in range(n_seg):
            for k in range(2):
                if run_o[e, k] >= 0:
                    runs[e, k, 1] = last_u1
                    _flush_owner(runs, run_o, e, k, seg_a, slope, x, n_i, fa, fb, fc, col, seen, p0, p1)


@njit(cache=True)
def _sweep_runs(x, n_i, fa, fb, fc, us, n_brk, seg_a, seg_b, seg_p, seg_w, lo_u, hi_u, slope, live, n_live, cross,
                cross_e, n_cross, poly_normal, side, rank, col, seen, cover, cover_w, runs, run_o, p0, p1, sw, skey,
                pool, heap_k, heap_i):
    """The sweep of :func:`_wedge_view` without a vertical edge, output-sensitive: the
    active edges' order is kept from slab to slab and changed only at the events of each
    break (edges ending, crossings, edges starting), and only the regions next to an event
    are decided again; every other region keeps its covering polygons and its owner, and
    the runs of its edges go on.

    - Order: the edges ending at a break are dropped; each crossing at it re-sorts the edges
      between its two (by height at the slab's middle, :func:`_above`: those are the edges
      through the crossing point); the edges starting are placed by binary search. The order
      is the one :func:`_slab_edges` would give (edges do not cross inside a slab).
    - Regions are named by their top edge: the region below edge e (down to ``below[e]``)
      has its covering polygons with their winding (stored in ``pool``), their key
      (:func:`_cover_key`) and its owner. A region whose two edges stay neighbours is the
      same open region (no edge passes through it), so all of these hold. A new region's
      covering polygons are those of the region above it, with the polygon of the edge
      between them added or dropped (its winding changes by the edge's weight).
    - Owners: one covering polygon (or none) is sure; with more, the nearest one
      (:func:`_nearest`) is sure while the region is solid (thicker than :data:`MEMO_GAP` at
      both sides of the slab), searched again in every slab where it is not (a sliver's owner
      is rounding). A heap holds, per region not sure for good, the u where that check is due.
    - Runs (:func:`_flush_owner`) are opened and closed only on the edges next to a region
      decided again, and when an edge ends.

    ``sw`` (16, e) int64 and ``skey`` (2, e) uint64 are work arrays, ``cover``/``cover_w``
    (P,) int64; ``pool`` (k, 2), ``heap_k`` (k,) and ``heap_i`` (k, 2) grow (returned)."""
    act, pos, alive, by_hi = sw[0], sw[1], sw[2], sw[3]  # alive: 0 out, 1 in the order, 2 ending
    own, sure, below, version = sw[4], sw[5], sw[6], sw[7]  # per region, by its top edge
    cov_at, cov_n = sw[8], sw[9]  # its covering polygons: pool[cov_at : cov_at + cov_n]
    memo_below, memo_owner, memo_gen = sw[10], sw[11], sw[12]
    mark, dirty, span = sw[13], sw[14], sw[15]  # regions to decide: the slab their top edge was marked in
    tmark, touch = sw[16], sw[17]  # edges whose runs to update: the same
    succ = sw[18]  # the edge that goes on from each edge's right end (its loop's next in u)
    key_of, memo_key = skey[0], skey[1]
    order = np.argsort(hi_u[live[:n_live]])
    for r in range(n_live):
        e = live[r]
        by_hi[r] = live[order[r]]
        alive[e] = 0
        mark[e] = -1
        tmark[e] = -1
        memo_gen[e] = -1
        version[e] = 0
    by_cross = np.argsort(cross[:n_cross])
    d = np.empty(3)
    n_act, nxt, nend, ncx = 0, 0, 0, 0
    n_pool, n_heap = 0, 0
    gen = 0  # memos of an older generation (before a gap) do not hold
    reset = True  # every region to be decided (the first slab, or after a gap)
    swept = False  # whether the last slab had regions
    last_u1 = np.nan
    slab = 0
    for k in range(n_brk - 1):
        u0, u1 = us[k], us[k + 1]
        if not u1 > u0:
            continue
        um = 0.5 * (u0 + u1)
        n_dirty, n_touch = 0, 0
        # 1. edges ending: dropped; their runs end at u0, the edges each side are new neighbours
        ending = False
        while nend < n_live and hi_u[by_hi[nend]] <= um:
            e = by_hi[nend]
            nend += 1
            if alive[e] == 1:
                alive[e] = 2
                ending = True
        if ending:
            w = 0
            gap = False
            for r in range(n_act):
                e = act[r]
                if alive[e] == 2:
                    alive[e] = 0
                    for kk in range(2):
                        if run_o[e, kk] >= 0:
                            runs[e, kk, 1] = u0
                            _flush_owner(runs, run_o, e, kk, seg_a, slope, x, n_i, fa, fb, fc, col, seen, p0, p1)
                    n = succ[e]
                    if (n < 0 or alive[n] != 0 or seg_w[n] != seg_w[e] or not lo_u[n] < um < hi_u[n]
                            or (w > 0 and _above(seg_a, seg_b, slope, n, act[w - 1], _height(seg_a, slope, n, um), u0, u1))
                            or (r + 1 < n_act and (alive[act[r + 1]] != 1 or _above(
                                seg_a, seg_b, slope, act[r + 1], n, _height(seg_a, slope, act[r + 1], um), u0, u1)))):
                        gap = True
                        continue
                    # the polygon's boundary goes on through the vertex, the same way in u: the
                    # next edge takes this one's place, and the regions each side stay the same
                    alive[n] = 1
                    own[n], sure[n], below[n], version[n] = own[e], sure[e], below[e], version[e] + 1
                    cov_at[n], cov_n[n], key_of[n] = cov_at[e], cov_n[e], key_of[e]
                    memo_gen[n], memo_below[n], memo_owner[n], memo_key[n] = (memo_gen[e], memo_below[e],
                                                                              memo_owner[e], memo_key[e])
                    if w > 0:
                        below[act[w - 1]] = n
                    tmark[n] = slab
                    touch[n_touch] = n
                    n_touch += 1
                    if sure[n] == 0 and mark[n] != slab:  # (a sliver: decided again)
                        mark[n] = slab
                        dirty[n_dirty] = n
                        n_dirty += 1
                    e = n
                if gap:
                    gap = False
                    if w > 0 and mark[act[w - 1]] != slab:
                        mark[act[w - 1]] = slab
                        dirty[n_dirty] = act[w - 1]
                        n_dirty += 1
                    if w == 0 and mark[e] != slab:  # the top edge now (for the walk below)
                        mark[e] = slab
                        dirty[n_dirty] = e
                        n_dirty += 1
                act[w] = e
                pos[e] = w
                w += 1
            if gap and w > 0 and mark[act[w - 1]] != slab:  # the lowest edge: no region below it now
                mark[act[w - 1]] = slab
                dirty[n_dirty] = act[w - 1]
                n_dirty += 1
            n_act = w
        # 2. crossings at this break: the edges between the two of each (those through the
        # crossing point) re-sorted, spans that overlap merged
        n_span = 0
        while ncx < n_cross and cross[by_cross[ncx]] < u1:
            c = by_cross[ncx]
            ncx += 1
            e, f = cross_e[c, 0], cross_e[c, 1]
            if alive[e] == 1 and alive[f] == 1:
                a, b = min(pos[e], pos[f]), max(pos[e], pos[f])
                j = n_span
                while j > 0 and span[2 * j - 2] > a:  # by first position (few)
                    span[2 * j], span[2 * j + 1] = span[2 * j - 2], span[2 * j - 1]
                    j -= 1
                span[2 * j], span[2 * j + 1] = a, b
                n_span += 1
                if 2 * n_span + 2 > span.shape[0]:  # (many crossings at one break: one span)
                    for r in range(n_span):
                        span[1] = max(span[1], span[2 * r + 1])
                    n_span = 1
        r = 0
        while r < n_span:
            a, b = span[2 * r], span[2 * r + 1]
            r += 1
            while r < n_span and span[2 * r] <= b:
                b = max(b, span[2 * r + 1])
                r += 1
            top = act[a]
            for q in range(a + 1, b + 1):  # insertion sort: only the crossing edges move
                e = act[q]
                ve = _height(seg_a, slope, e, um)
                j = q
                while j > a and _above(seg_a, seg_b, slope, e, act[j - 1], ve, u0, u1):
                    act[j] = act[j - 1]
                    j -= 1
                act[j] = e
            if b == a + 1 and act[a] != top:
                # two edges swap: the regions above and below them stay (the region below
                # moves from the lower edge, f, to the other, e); the one between is new
                f, e = act[a], act[b]
                own[e], sure[e], below[e], version[e] = own[f], sure[f], below[f], version[e] + 1
                cov_at[e], cov_n[e], key_of[e] = cov_at[f], cov_n[f], key_of[f]
                memo_gen[e], memo_below[e], memo_owner[e], memo_key[e] = (memo_gen[f], memo_below[f],
                                                                          memo_owner[f], memo_key[f])
                pos[f], pos[e] = a, b
                if a > 0:
                    below[act[a - 1]] = f
                if (sure[e] == 0 or mark[f] == slab) and mark[e] != slab:  # (a sliver, or changed)
                    mark[e] = slab
                    dirty[n_dirty] = e
                    n_dirty += 1
                if mark[f] != slab:
                    mark[f] = slab
                    dirty[n_dirty] = f
                    n_dirty += 1
                continue
            for q in range(max(a - 1, 0), b + 1):
                e = act[q]
                pos[e] = q
                if mark[e] != slab:
                    mark[e] = slab
                    dirty[n_dirty] = e
                    n_dirty += 1
        # 3. edges starting: placed by binary search (below the edges they tie with)
        while nxt < n_live and lo_u[live[nxt]] < um:
            e = live[nxt]
            nxt += 1
            if hi_u[e] <= um or alive[e] == 1:
                continue  # shorter than SNAP (in no slab), or in its edge's place already
            ve = _height(seg_a, slope, e, um)
            lo, hi = 0, n_act
            while lo < hi:
                mid = (lo + hi) >> 1
                if _above(seg_a, seg_b, slope, e, act[mid], ve, u0, u1):
                    hi = mid
                else:
                    lo = mid + 1
            for q in range(n_act, lo, -1):
                act[q] = act[q - 1]
                pos[act[q]] = q
            act[lo] = e
            pos[e] = lo
            alive[e] = 1
            n_act += 1
            for f in (act[lo - 1] if lo > 0 else -1, e):
                if f >= 0 and mark[f] != slab:
                    mark[f] = slab
                    dirty[n_dirty] = f
                    n_dirty += 1
        if n_act < 2:
            # no region: every open run ends where the last slab with regions did
            if swept:
                for r in range(n_act):
                    for kk in range(2):
                        if run_o[act[r], kk] >= 0:
                            runs[act[r], kk, 1] = last_u1
                            _flush_owner(runs, run_o, act[r], kk, seg_a, slope, x, n_i, fa, fb, fc, col, seen,
                                         p0, p1)
            swept = False
            reset = True
            slab += 1
            continue
        if reset:
            gen += 1
            for r in range(n_act):
                e = act[r]
                if mark[e] != slab:
                    mark[e] = slab
                    dirty[n_dirty] = e
                    n_dirty += 1
            reset = False
        else:
            # regions pinched at u0 next to an event (their two edges meet there: on one
            # line, or within MEMO_GAP) may be covered otherwise than before though their
            # edges did not change (a vertex at u0 lying on coincident edges: a polygon starts,
            # ends or turns across them), and all below inherit their covering polygons
            for r in range(n_dirty):
                n_dirty = _pinched(act, n_act, pos[dirty[r]], seg_a, slope, u0, mark, dirty, n_dirty, slab)
        # 4. slivers that may be solid now: their owners searched again
        while n_heap > 0 and heap_k[0] <= u1:
            e, v = heap_i[0, 0], heap_i[0, 1]
            n_heap = _heap_pop(heap_k, heap_i, n_heap)
            if alive[e] != 1 or version[e] != v or mark[e] == slab:
                continue  # a region gone, or decided again anyway
            q = pos[e]
            if q >= n_act - 1 or act[q + 1] != below[e]:
                continue
            f = below[e]
            if not min(_height(seg_a, slope, e, u0) - _height(seg_a, slope, f, u0),
                       _height(seg_a, slope, e, u1) - _height(seg_a, slope, f, u1)) > MEMO_GAP:
                # not yet: due at the next slab (not again in this loop)
                if n_heap >= heap_k.shape[0]:
                    if n_heap >= heap_k.shape[0]:
                        heap_k = _grow(heap_k, n_heap)
                        heap_i = _grow_int(heap_i, n_heap)
                n_heap = _heap_push(heap_k, heap_i, n_heap, np.nextafter(u1, np.inf), e, v)
                continue
            mark[e] = slab
            dirty[n_dirty] = e
            n_dirty += 1
        # 5. the regions below the marked edges, top down; then the runs of their edges
        n_q = 0
        for r in range(n_dirty):
            e = dirty[r]
            if alive[e] == 1 and pos[e] < n_act - 1:
                span[n_q] = pos[e]
                n_q += 1
        span[:n_q].sort()
        for r in range(n_q):
            q = span[r]
            e, f = act[q], act[q + 1]
            n_cover = 0
            key = np.uint64(0)
            if q > 0:
                a = act[q - 1]
                n_cover = cov_n[a]
                for t in range(n_cover):
                    cover[t] = pool[cov_at[a] + t, 0]
                    cover_w[t] = pool[cov_at[a] + t, 1]
                key = key_of[a]
            p = seg_p[e]
            t = 0
            while t < n_cover and cover[t] != p:
                t += 1
            if t == n_cover:
                cover[t] = p
                cover_w[t] = seg_w[e]
                n_cover += 1
                key ^= _cover_key(p)
            else:
                cover_w[t] += seg_w[e]
                if cover_w[t] == 0:
                    cover[t] = cover[n_cover - 1]
                    cover_w[t] = cover_w[n_cover - 1]
                    n_cover -= 1
                    key ^= _cover_key(p)
            if n_pool + n_cover >= pool.shape[0]:
                pool = _grow_int(pool, n_pool + n_cover)
            cov_at[e], cov_n[e], key_of[e] = n_pool, n_cover, key
            for t in range(n_cover):
                pool[n_pool + t, 0] = cover[t]
                pool[n_pool + t, 1] = cover_w[t]
            n_pool += n_cover
            now = -1
            solid = False
            if n_cover == 1:
                now = cover[0]
            elif n_cover > 1:
                solid = min(_height(seg_a, slope, e, u0) - _height(seg_a, slope, f, u0),
                            _height(seg_a, slope, e, u1) - _height(seg_a, slope, f, u1)) > MEMO_GAP
                if solid and memo_gen[e] == gen and memo_below[e] == f and memo_key[e] == key:
                    now = memo_owner[e]
                else:
                    vm = 0.5 * (_height(seg_a, slope, e, um) + _height(seg_a, slope, f, um))
                    for c in range(3):
                        d[c] = fc[c] + um * fa[c] + vm * fb[c]
                    now = _nearest(cover, n_cover, d, poly_normal, side, rank)
                memo_gen[e] = gen if solid else -1
                memo_below[e] = f
                memo_key[e] = key
                memo_owner[e] = now
            else:
                memo_gen[e] = -1
            own[e] = now
            below[e] = f
            version[e] += 1
            sure[e] = 1 if n_cover <= 1 else (2 if solid else 0)
            if sure[e] == 0:
                due = _solid_from(seg_a, slope, e, f, u1)
                if due < np.inf:
                    if n_heap >= heap_k.shape[0]:
                        heap_k = _grow(heap_k, n_heap)
                        heap_i = _grow_int(heap_i, n_heap)
                    n_heap = _heap_push(heap_k, heap_i, n_heap, due, e, version[e])
            for g in (e, f):
                if tmark[g] != slab:
                    tmark[g] = slab
                    touch[n_touch] = g
                    n_touch += 1
        # the runs of the edges of those regions (side 0: the owner above, side 1: below; none
        # between two regions of one owner), and of an edge left at the top or the bottom
        for r in range(n_dirty):
            e = dirty[r]
            if alive[e] == 1 and pos[e] == n_act - 1 and tmark[e] != slab:
                tmark[e] = slab
                touch[n_touch] = e
                n_touch += 1
        for r in range(n_touch):
            e = touch[r]
            q = pos[e]
            _set_runs(runs, run_o, e, own[act[q - 1]] if q > 0 else -1, own[e] if q < n_act - 1 else -1, u0, seg_a,
                      slope, x, n_i, fa, fb, fc, col, seen, p0, p1)
        swept = True
        last_u1 = u1
        slab += 1
    for r in range(n_act):
        for kk in range(2):
            if run_o[act[r], kk] >= 0:
                runs[act[r], kk, 1] = last_u1
                _flush_owner(runs, run_o, act[r], kk, seg_a, slope, x, n_i, fa, fb, fc, col, seen, p0, p1)
    return pool, heap_k, heap_i


@njit(cache=True)
def _slab_density(lo_u, hi_u, live, n_live):
    """The mean number of edges a slab of the sweep crosses, over the slabs that start at the
    edges' left ends (the crossings' breaks not counted): each edge ``live[:n_live]`` (sorted by
    ``lo_u``) spans the left ends between its own ends (a binary search each)."""
    spans = 0
    for r in range(n_live):
        e = live[r]
        lo, hi = r + 1, n_live
        while lo < hi:
            mid = (lo + hi) >> 1
            if lo_u[live[mid]] < hi_u[e]:
                lo = mid + 1
            else:
                hi = mid
        spans += lo - r - 1
    return spans / max(n_live, 1)


@njit(cache=True)
def _wedge_view(x, n_i, fa, fb, fc, planes, n_planes, pts, loop_lo, loop_hi, loop_poly, poly_normal, poly_c, rank,
                side, use, col, seen, seg_a, seg_b, seg_p, seg_w, buf_a, buf_b, brk, wind, cover, cover_w, p0, p1, fw, iw,
                runs, run_o, rim, sw, skey, cross, cross_e, pool, heap_k, heap_i, sweep_kind):
    """Add to ``seen`` the visible part of every polygon through one wedge around x (the
    frustum ``planes`` through x, inward normals; :func:`_wedges`): each polygon clipped to
    the frustum and projected centrally on the wedge's plane, the slab sweep of
    :func:`_visible_one`, and in each trapezoid between two consecutive edges the polygon
    nearest along the ray through its centre (polygons do not cross: the front-most one of
    those covering a trapezoid is the same all over it).

    The sweep is output-sensitive (:func:`_sweep_runs`): from one break to the next only the
    edges at the break change (ending, crossing, starting), and only the regions next to them
    are decided again; an edge's runs (its owner above on side 0, below on side 1) stay open
    while its neighbouring owners do and are summed (Lambert) once, when they change or the
    edge ends; where a slab crosses fewer than :data:`RUNS_DENSITY` edges on the mean
    (:func:`_slab_density`), :func:`_sweep_slabs` is cheaper.
    With a vertical edge, every slab is swept whole and summed as trapezoids
    (:func:`_sweep_slabs`). ``sweep_kind`` (:func:`point_views`) chooses: 0 by size, 1 whole slabs
    always (the plain sweep, the tests' reference), 2 :func:`_sweep_runs` always, None the slab
    sweep only: a compiled version without the crossings' and the loops' records that only
    :func:`_sweep_runs` reads (numba prunes the branches on None), for scenes too small for it.

    ``fw`` (7, e) float64, ``iw`` (5, e) int64, ``runs`` (e, 2, 2) float64, ``run_o`` (e, 2)
    int64, ``rim`` (e,) int64, ``sw``, ``skey`` (:func:`_sweep_runs`) and ``cover_w`` (P,) int64
    are work arrays (allocated once per :func:`point_views` call), e at least the number of
    projected edges; ``brk``, ``cross`` (k,) float64, ``cross_e`` (k, 2) int64 (the crossings'
    u and edges), ``pool``, ``heap_k`` and ``heap_i`` grow, and are returned."""
    n_seg = 0
    loop_next = iw[5]  # the next edge of each edge's loop
    for L in range(loop_lo.shape[0]):
        p = loop_poly[L]
        if not use[p]:
            continue
        n_in = _clip_to_frustum(pts, loop_lo[L], loop_hi[L], x, planes, n_planes, buf_a, buf_b)
        if n_in < 3:
            continue
        first = n_seg
        for q in range(n_in):
            dx, dy, dz = buf_a[q, 0] - x[0], buf_a[q, 1] - x[1], buf_a[q, 2] - x[2]
            den = dx * fc[0] + dy * fc[1] + dz * fc[2]
            if den <= 1e-300:
                den = 1e-300  # x itself (a polygon through the apex)
            seg_a[first + q, 0] = (dx * fa[0] + dy * fa[1] + dz * fa[2]) / den
            seg_a[first + q, 1] = (dx * fb[0] + dy * fb[1] + dz * fb[2]) / den
            # the frustum's planes the vertex lies on (bits; within RIM of its distance)
            size = RIM * np.sqrt(dx * dx + dy * dy + dz * dz)
            bits = 0
            for k in range(n_planes):
                pk = planes[k]
                if abs(dx * pk[0] + dy * pk[1] + dz * pk[2]) <= size * np.sqrt(pk[0] * pk[0] + pk[1] * pk[1] + pk[2] * pk[2]):
                    bits |= 1 << k
            rim[first + q] = bits
        for q in range(n_in):
            k = first + q + 1 if q + 1 < n_in else first
            seg_b[first + q, 0], seg_b[first + q, 1] = seg_a[k, 0], seg_a[k, 1]
            seg_p[first + q] = p
            if sweep_kind is not None:  # (only the runs' sweep reads it)
                loop_next[first + q] = k
        for q in range(n_in):  # an edge with both ends on one plane lies on the frustum's side
            rim[first + q] = rim[first + q] & rim[first + q + 1 if q + 1 < n_in else first]
        n_seg += n_in
    if n_seg == 0:
        return brk, cross, cross_e, pool, heap_k, heap_i
    lo_u, hi_u = fw[0], fw[1]
    if _steepest(seg_a, seg_b, n_seg) > STEEP:
        fa, fb = _turn_from_steep(seg_a, seg_b, n_seg, fa, fb, lo_u)
    # winding weights (+1 right to left, -1 left to right, 0 vertical: bounds no slab)
    seg_w[:n_seg] = 1
    brk, n_brk = _edge_windings(seg_a, seg_b, seg_w, n_seg, lo_u, hi_u, brk)
    by_lo = np.argsort(lo_u[:n_seg])
    live = iw[1]  # the edges that bound slabs (not vertical), by their left ends
    n_live = 0
    for r in range(n_seg):
        if seg_w[by_lo[r]] != 0:
            live[n_live] = by_lo[r]
            n_live += 1
    has_vertical = _has_vertical(seg_a, seg_b, seg_w, n_seg)
    by_runs = False
    if sweep_kind is not None:
        has_vertical = has_vertical or sweep_kind == 1
        by_runs = not has_vertical and (sweep_kind == 2 or _slab_density(lo_u, hi_u, live, n_live) >= RUNS_DENSITY)
    # crossings of edges of different polygons: edges by their left ends, each against the
    # ones starting before it ends (their u and v ranges, polygon and weight copied in that
    # order first: the inner loop reads consecutive memory)
    s_lo, s_hi, s_vlo, s_vhi = fw[2], fw[3], fw[4], fw[5]
    s_p = iw[0]  # -1: a vertical edge (no crossing counted)
    n_cross = 0
    for r in range(n_seg):
        e = by_lo[r]
        s_lo[r], s_hi[r] = lo_u[e], hi_u[e]
        s_vlo[r], s_vhi[r] = min(seg_a[e, 1], seg_b[e, 1]), max(seg_a[e, 1], seg_b[e, 1])
        # an edge on the frustum's side crosses none inside it (every other lies in the
        # frustum) but by rounding: the slab sweep, which sorts every slab, does without
        # those crossings; the runs' sweep keeps its order from break to break and must see
        # every change of it, a rounding crossing too (a face clipped 1e-4 from the point,
        # its vertices off by 1e-11 of their distance, crossed a wall's edge on the wedge's
        # side 1e-11 from its corner, unseen: the wall's edge stayed below the face's for
        # good, 0.186 of F to the sky on office(1000), tests/test_sweep_runs.py)
        s_p[r] = seg_p[e] if seg_w[e] != 0 and (by_runs or rim[e] == 0) else -1
    for r in range(n_seg):
        pe = s_p[r]
        if pe < 0:
            continue
        he, vlo, vhi = s_hi[r], s_vlo[r], s_vhi[r]
        for r2 in range(r + 1, n_seg):
            if s_lo[r2] > he:
                break
            pf = s_p[r2]
            if pf == pe or pf < 0:
                continue
            # v ranges apart: no crossing (the common case, tested before the call)
            if vhi < s_vlo[r2] or s_vhi[r2] < vlo:
                continue
            u = _crossing_u(seg_a, seg_b, by_lo[r], by_lo[r2])
            if u == u and not _collinear(seg_a, seg_b, by_lo[r], by_lo[r2], SNAP):
                brk = _grow(brk, n_brk)
                brk[n_brk] = u
                n_brk += 1
                if sweep_kind is not None:  # (only the runs' sweep reads them)
                    cross = _grow(cross, n_cross)
                    cross_e = _grow_int(cross_e, n_cross)
                    cross[n_cross] = u
                    cross_e[n_cross, 0], cross_e[n_cross, 1] = by_lo[r], by_lo[r2]
                    n_cross += 1
    us = np.sort(brk[:n_brk])
    n_brk = _snap_breaks(us, n_brk, SNAP)
    slope = fw[6]
    _slopes(seg_a, seg_b, n_seg, slope)
    if not by_runs:
        _sweep_slabs(x, n_i, fa, fb, fc, us, n_brk, seg_a, seg_b, seg_p, seg_w, n_seg, hi_u, lo_u, slope, live, n_live,
                     has_vertical, poly_normal, side, rank, col, seen, wind, cover, runs, run_o, p0, p1, fw[2:5],
                     sw[:14], skey[0])
        return brk, cross, cross_e, pool, heap_k, heap_i
    # each edge's successor in u: the loop's next edge (a→b left to right) or its previous one
    # (right to left) when it goes on the same way, -1 else
    succ = sw[18]
    succ[:n_seg] = -1
    for e in range(n_seg):
        if seg_w[e] < 0 and seg_w[loop_next[e]] < 0:
            succ[e] = loop_next[e]
        elif seg_w[e] > 0 and seg_w[loop_next[e]] > 0:
            succ[loop_next[e]] = e
    run_o[:n_seg] = -1
    pool, heap_k, heap_i = _sweep_runs(x, n_i, fa, fb, fc, us, n_brk, seg_a, seg_b, seg_p, seg_w, lo_u, hi_u, slope,
                                       live, n_live, cross, cross_e, n_cross, poly_normal, side, rank, col, seen,
                                       cover, cover_w, runs, run_o, p0, p1, sw, skey, pool, heap_k, heap_i)
    return brk, cross, cross_e, pool, heap_k, heap_i


@njit(cache=True)
def _wedges(n_i, eu, ev):
    """The front hemisphere of (n_i, eu, ev) cut into :data:`WEDGES` pointed cones through the
    point: ``frames`` (WEDGES, 3, 3) float64, each cone's (fa, fb, fc) (its 2-D basis and the
    direction of its plane of projection), and ``planes`` (WEDGES, 3, 3) float64, the inward
    normals of its three sides.

    Wedge k lies between the azimuths θ_k and θ_k+1 (θ_k = GENERIC_AZIMUTH + 2πk / WEDGES
    about n_i, a_k the horizontal direction at θ_k): it is {r: r·n_i ≥ 0, r on the inner
    sides of the planes through n_i and a_k, a_k+1}, its extreme rays n_i, a_k, a_k+1. It is
    projected centrally on the plane at unit distance along fc, the direction at equal
    angles from the three (fc ∝ cos(α / 2)² n_i + (a_k + a_k+1) / 2, α = 2π / WEDGES): the
    extreme rays are then at 63.4° from fc (|u|, |v| < 2.1 in the plane, 120° of azimuth)."""
    m = WEDGES
    frames = np.empty((m, 3, 3))
    planes = np.empty((m, 3, 3))
    az = np.empty((m + 1, 3))
    nz = np.empty((m + 1, 3))  # the inward normal, towards larger azimuth, of the plane through n_i and a_k
    for k in range(m + 1):
        th = GENERIC_AZIMUTH + 2.0 * np.pi * k / m
        ct, st = np.cos(th), np.sin(th)
        for c in range(3):
            az[k, c] = ct * eu[c] + st * ev[c]
            nz[k, c] = -st * eu[c] + ct * ev[c]
    h = np.cos(np.pi / m) ** 2
    for k in range(m):
        for c in range(3):
            planes[k, 0, c] = n_i[c]
            planes[k, 1, c] = nz[k, c]
            planes[k, 2, c] = -nz[k + 1, c]
            frames[k, 2, c] = h * n_i[c] + 0.5 * (az[k, c] + az[k + 1, c])
            frames[k, 0, c] = az[k + 1, c] - az[k, c]
        fcv, fav = frames[k, 2], frames[k, 0]
        fcv /= np.sqrt(fcv[0] * fcv[0] + fcv[1] * fcv[1] + fcv[2] * fcv[2])
        fav /= np.sqrt(fav[0] * fav[0] + fav[1] * fav[1] + fav[2] * fav[2])
        frames[k, 1, 0] = fcv[1] * fav[2] - fcv[2] * fav[1]
        frames[k, 1, 1] = fcv[2] * fav[0] - fcv[0] * fav[2]
        frames[k, 1, 2] = fcv[0] * fav[1] - fcv[1] * fav[0]
    # each wedge's 2-D basis turned by a generic angle: the cone's sides and the edges of an
    # axis-aligned scene are not vertical in 2-D, so the sweep needs no vertical sides
    ca, sa = np.cos(GENERIC_TURN), np.sin(GENERIC_TURN)
    for k in range(WEDGES):
        for c in range(3):
            fa, fb = frames[k, 0, c], frames[k, 1, c]
            frames[k, 0, c] = ca * fa + sa * fb
            frames[k, 1, c] = -sa * fa + ca * fb
    return frames, planes


@njit(cache=True, nogil=True)
def _point_views(points, n_i, eu, ev, pts, loop_lo, loop_hi, loop_poly, poly_normal, poly_c, rank, skip, tiny, poly_box,
                 box_ptr, box_planes, sweep_kind, emax, cull_from):
    """The kernel of :func:`point_views`; ``sweep_kind`` None or an int: numba compiles one version
    each (with None, none of the records only :func:`_sweep_runs` reads: :func:`_wedge_view`);
    ``emax`` the room for one wedge's projected edges; ``cull_from`` :data:`CULL_FROM`."""
    P = poly_normal.shape[0]
    n_loops = loop_lo.shape[0]
    first = np.zeros(P + 1, np.int64)
    for L in range(n_loops):
        first[loop_poly[L] + 1] += 1
    for p in range(P):
        first[p + 1] += first[p]
    kmax = 3
    for L in range(n_loops):
        kmax = max(kmax, loop_hi[L] - loop_lo[L])
    kmax += 8
    seg_a, seg_b = np.empty((emax, 2)), np.empty((emax, 2))
    seg_p, seg_w = np.empty(emax, np.int64), np.empty(emax, np.int64)
    buf_a, buf_b = np.empty((kmax, 3)), np.empty((kmax, 3))
    brk = np.empty(4 * emax)
    wind = np.zeros(P, np.int64)
    cover = np.empty(P, np.int64)
    col = np.empty(P, np.int64)
    side = np.empty(P)
    use = np.zeros(P, np.bool_)
    sweep = np.zeros(P, np.bool_)
    box_state = np.zeros(box_ptr.shape[0], np.int64)
    n_boxes = box_ptr.shape[0] - 1
    score, casters, s_x = np.zeros(max(n_boxes, 1)), np.empty(max(n_boxes, 1), np.int64), np.empty(box_planes.shape[0])
    k_box = 1
    for b in range(n_boxes):
        k_box = max(k_box, box_ptr[b + 1] - box_ptr[b])
    s_v, low = np.empty(k_box), np.empty(k_box)
    poly_o, box_o, box_r = _spheres(pts, loop_lo, loop_hi, first, poly_box, n_boxes)
    cast_w = np.empty((max(n_boxes, 1), 5))
    seen = np.zeros(2 * P)
    p0, p1 = np.empty(3), np.empty(3)
    fw, iw = np.empty((7, emax)), np.empty((6, emax), np.int64)
    runs, run_o, rim = np.empty((emax, 2, 2)), np.empty((emax, 2), np.int64), np.empty(emax, np.int64)
    sw, skey, cover_w = np.empty((19, emax), np.int64), np.empty((2, emax), np.uint64), np.empty(P, np.int64)
    cross, cross_e = np.empty(emax), np.empty((emax, 2), np.int64)
    pool, heap_k, heap_i = np.empty((4 * emax, 2), np.int64), np.empty(emax), np.empty((emax, 2), np.int64)
    frames, planes = _wedges(n_i, eu, ev)
    hidden = np.zeros((points.shape[0], 2 * P + 1))
    for i in range(points.shape[0]):
        x = points[i]
        contact = -1
        for p in range(P):
            use[p] = False
            if p == skip:
                continue
            s = poly_normal[p, 0] * x[0] + poly_normal[p, 1] * x[1] + poly_normal[p, 2] * x[2] - poly_c[p]
            side[p] = s
            if abs(s) <= tiny:
                dn = poly_normal[p, 0] * n_i[0] + poly_normal[p, 1] * n_i[1] + poly_normal[p, 2] * n_i[2]
                # the smaller of two faces lying on each other touches the larger's front with
                # its side facing it: the larger's front, the smaller's side against it
                if rank[skip] > rank[p]:
                    touching = (poly_normal[skip, 0] * n_i[0] + poly_normal[skip, 1] * n_i[1]
                                + poly_normal[skip, 2] * n_i[2]) > 0
                else:
                    touching = dn < 0
                if touching and _inside_plane(x, pts, loop_lo, loop_hi, first[p], first[p + 1], poly_normal[p]):
                    contact = 2 * p + (1 if dn > 0 else 0)
                continue
            col[p] = 2 * p + (0 if s > 0 else 1)
            # unoccluded: Lambert over the loops clipped to the front hemisphere
            total = 0.0
            ahead = False
            for L in range(first[p], first[p + 1]):
                lo, hi = loop_lo[L], loop_hi[L]
                n_in = hi - lo
                for q in range(n_in):
                    for c in range(3):
                        buf_a[q, c] = pts[lo + q, c]
                n_in = _clip_loop(buf_a, n_in, buf_b, x, n_i)
                if n_in < 3:
                    continue
                ahead = True
                for q in range(n_in):
                    r = q + 1 if q + 1 < n_in else 0
                    total += _gamma_dot(x, buf_b[q], buf_b[r], n_i)
            if ahead:
                use[p] = True
                hidden[i, col[p]] = abs(total) / TWO_PI
        if contact >= 0:
            hidden[i, contact] = -1.0  # it sees that side only: all else it would see is hidden
            continue
        n_sweep = 0
        for p in range(P):
            sweep[p] = use[p] and not (side[p] < 0 and _outside(x, n_i, poly_box[p], box_state, box_ptr, box_planes, tiny))
            n_sweep += sweep[p]
        if n_sweep >= cull_from and n_boxes > 0:
            # the faces in a box's shadow are not swept (:func:`_in_shadow`): the boxes that
            # look largest (their front faces' unoccluded F) are tried first
            score[:] = 0.0
            for p in range(P):
                if use[p] and side[p] > 0 and poly_box[p] >= 0:
                    score[poly_box[p]] += hidden[i, col[p]]
            _cull_shadowed(x, n_i, sweep, pts, loop_lo, loop_hi, first, poly_box, poly_o, box_ptr, box_planes, box_o, box_r,
                           box_state, tiny, score, s_x, casters, cast_w, s_v, low)
        box_state[:] = 0
        for k in range(WEDGES):
            brk, cross, cross_e, pool, heap_k, heap_i = _wedge_view(
                x, n_i, frames[k, 0], frames[k, 1], frames[k, 2], planes[k], 3, pts, loop_lo, loop_hi, loop_poly,
                poly_normal, poly_c, rank, side, sweep, col, seen, seg_a, seg_b, seg_p, seg_w, buf_a, buf_b, brk, wind,
                cover, cover_w, p0, p1, fw, iw, runs, run_o, rim, sw, skey, cross, cross_e, pool, heap_k, heap_i,
                sweep_kind)
        sky = 1.0
        for p in range(P):
            if use[p]:
                hidden[i, col[p]] -= seen[col[p]]
                sky -= seen[col[p]]
                seen[col[p]] = 0.0
        hidden[i, 2 * P] = max(sky, 0.0)
    return hidden


def point_views(points, n_i, eu, ev, pts, loop_lo, loop_hi, loop_poly, poly_normal, poly_c, rank, skip, tiny, poly_box, box_ptr,
                box_planes, sweep_kind=0, cull_from=None):
    """What each point of an emitter sees of every polygon side, and what is hidden of it:
    a from-point hidden-surface computation over the whole scene at once, so that a matrix
    row costs one evaluation per point, not one per receiver.

    For x (normal n_i, the emitting side), every polygon p (but ``skip``, the emitter) is
    seen from side s = sign(n_p · x − c_p) (column ``2 p`` for its front, ``2 p + 1`` its
    back). The front hemisphere is cut into :data:`WEDGES` = 3 pointed cones through x (120°
    of azimuth each, from the horizon to n_i: fewer pieces to clip and sweep than the five
    faces of a hemicube, 57 → 45 µs a point on the Cornell matrix; :func:`_wedges`); in each,
    the polygons are clipped, projected centrally and swept (:func:`_wedge_view`): every
    trapezoid of the sweep goes to the nearest polygon covering it, and F to it is Lambert's contour sum of the trapezoid (F
    depends only on the solid angle, so the projected region gives the same value).

    What a point sees follows what hides it: before the sweep, every face that lies in the
    shadow of a closed convex box from x (the box's front faces hide it: :func:`_in_shadow`,
    exact) is left out of it, and all of its F is hidden (office(1000): of ~213 faces to
    sweep a point, ~96 left out, of the ~119 seen nowhere; :func:`_cull_shadowed`).

    Faces lying on faces (docs/queries.md): of two overlapping polygons in one plane, the
    smaller lies on the larger's front. A point of the larger's front inside the smaller
    sees the smaller's side facing it with F = 1 and nothing else, and so does a point of
    the smaller's side against the larger (it sees the larger's front); seen from elsewhere,
    the smaller covers the larger on the larger's front side, the larger the smaller on
    its back side.

    Returns ``hidden`` (m, 2P + 1) float64: for every column, ``F(x → polygon side clipped
    to the front hemisphere) − F(x → its visible part)`` (≥ 0 up to rounding; −1 at a
    contact column, whose unoccluded F is 0), and last what x sees of no polygon (the sky:
    1 − Σ seen, F to the whole hemisphere being 1).

    Parameters
    ----------
    points : (m, 3) float64
    n_i, eu, ev : (3,) float64
        The emitting side's unit normal and a right-handed basis of its plane.
    pts : (n, 3) float64
        Loop vertices; loop L at ``pts[loop_lo[L]:loop_hi[L]]`` of polygon ``loop_poly[L]``
        (non-decreasing), outer loops counter-clockwise about the polygon's normal, holes
        clockwise.
    poly_normal : (P, 3) float64; poly_c : (P,) float64
        Planes ``poly_normal[p] · y = poly_c[p]``.
    rank : (P,) int64
        Order of the polygons by area (0 the smallest): which of two overlapping polygons in
        one plane lies on the other.
    skip : int
        The emitter's polygon (never seen).
    tiny : float
        Distance below which x counts as in a polygon's plane.
    poly_box, box_ptr, box_planes : (P,) int64, (b + 1,) int64, (k, 5) float64
        The closed convex box of each polygon (-1 none) and the boxes' planes
        (:func:`viscx.queries.formfactor.closed_boxes`): the back faces of a box x is
        outside of are not swept (:func:`_outside`; their front faces hide them: what x
        sees of them is 0, all of their unoccluded F is hidden).
    sweep_kind : int
        Which sweep (:func:`_wedge_view`): 0 by the edges' density (the default), 1 every slab
        whole (the plain sweep, a reference for tests), 2 the output-sensitive one always.
        With 0 and fewer edges in the whole scene than :data:`SWEEP_RUNS_FROM` (the Cornell
        box), the kernel compiled without :func:`_sweep_runs`' records runs (``None``): the
        crossings' records in the loop over edge pairs cost the slab sweep ~8 % there.
    cull_from : int, optional
        The number of faces to sweep at a point from which those in a box's shadow are left
        out first (default :data:`CULL_FROM`; the tests compare with a number never reached).
    """
    # room for one wedge's projected edges: a loop clipped to the frustum has at most 5 more
    emax = 1 + int(np.sum(loop_hi - loop_lo)) + 5 * loop_lo.shape[0]
    if sweep_kind == 0 and emax <= SWEEP_RUNS_FROM:
        sweep_kind = None  # no wedge reaches SWEEP_RUNS_FROM edges
    return _point_views(points, n_i, eu, ev, pts, loop_lo, loop_hi, loop_poly, poly_normal, poly_c, rank, skip, tiny,
                        poly_box, box_ptr, box_planes, sweep_kind, emax, CULL_FROM if cull_from is None else int(cull_from))
