"""The discontinuity-mesh lines that lie in a face's plane and so are not arcs of V1:
receiver-plane events, and the light's plane (one-sided lights).

Receiver-plane events
---------------------
When the light straddles the plane P of a receiver f, a point x of f sees the light
clipped by its *horizon*: a light point y just behind P is seen from x through the
solid f bounds (or past whatever lies behind P), one just in front of it is not. The
image of P from x is the fixed line P ∩ plane(light), which meets the light's outline
at the points H (light edge l ∩ P). An occluder edge e whose image crosses H changes
how the visible part meets l there: either the gap between the horizon and e's hidden
interval closes, or the end of the hidden interval changes from the horizon to e. At
the event x, C (e ∩ P, or an occluder vertex w lying in P) and H are collinear: the
critical line is the line HC, in P, and the event's trace on f is the part of the ray
from C away from H where

* the segment x→H, pushed infinitesimally to the front of P, is free apart from
  touching the occluder at C (the line grazes the occluder there: the occluder's
  sections by P that end at C lie on one side of it),
* for C on an edge e crossing P (``RPE``), the same segment pushed behind P is *not*
  free (it is blocked: the horizon's hidden interval on l ends at H; when nothing
  hides the back side of H, e's image moves along l continuously and nothing
  changes). For C a vertex (``RPV``) nothing is asked of the back when the occluder
  at C lies in front of P (a panel hinged on the receiver's edge, whose edge in P
  ends at C; a vertex touching P): C's image crossing l changes which of C's edges
  bound the hidden part of l next to H, and whether H ends one; when the occluder at
  C reaches both sides of P, the event is where either side is free
  (:func:`front_decides`).

(And the same with front and back exchanged, for a receiver seen from both sides: a lone
face. A face of a closed solid is seen only from the solid's side the light is on: from
the other side x→H stays in the solid until it crosses it again, and is blocked; ``sides``
of :func:`receiver_plane_events`.)
These lines lie in P, so P's own faces and every face with an edge in P are grazed:
instead of casting rays, everything is decided exactly in P's 2-D coordinates. Each
triangle T of a face other than f and the light's faces is replaced by its *section*
seen from the front, the limit of T ∩ P⁺: the segment T ∩ P when T crosses P, T's
vertices or edge in P when T touches P from the front, nothing when it lies in P or
behind it. A segment in P⁺ is blocked where its line crosses a section.

The light's plane
-----------------
The light emits from the front of its faces (the side their normals point to, as in
``viscx render``). Points on or behind the planes of all the light's faces see nothing
of it: the light's plane crossing a receiver is a mesh line (the boundary of "sees the
light's front"), and the traces behind it are dropped (they change nothing there).
"""

import numpy as np
from numba import njit

#: Kinds of the events computed here (V1's arcs are EEE = 0 and VE = 1).
RP_EDGE, RP_VERTEX, LIGHT_PLANE = 2, 3, 4
#: Section end features: a scene edge crossing P, a vertex in P, a triangle's inner
#: diagonal (inside a face: never a critical point).
END_EDGE, END_VERTEX, END_INNER = 0, 1, -1
#: Candidate lines × sections per block (bounds temporary memory).
PAIR_BLOCK = 2_000_000


def light_planes(scene, light, snap):
    """The distinct planes of the light's faces.

    Returns
    -------
    normal : (k, 3) float64, offset : (k,) float64
        Plane ``normal · x = offset``, front where ``normal · x > offset``.
    face : (k,) int64
        A light face in each plane.
    """
    n = scene.face_normal[light.faces]
    c = scene.face_offset[light.faces]
    same = (n @ n.T > 1 - 1e-12) & (np.abs(c[:, None] - c[None, :]) <= snap)
    first = np.argmax(same, axis=1) == np.arange(len(n))
    return n[first], c[first], light.faces[first]


def front_distance(points, planes):
    """Signed distance in front of the light: the largest over its planes (``planes`` of
    :func:`light_planes`), (m,) float64 for points (m, 3); > 0 where a point is in front
    of some light face's plane."""
    n, c, _ = planes
    return (points @ n.T - c[None, :]).max(axis=1)


def clip_to_front(offsets, points, planes, snap):
    """The parts of polylines in front of the light (exact for a planar light: the
    distance is linear along a chord).

    Parameters
    ----------
    offsets : (m + 1,) int64
    points : (p, 3) float64
        Polyline k is ``points[offsets[k]:offsets[k + 1]]``.
    planes : tuple
        ``(normal (k, 3), offset (k,), face (k,))`` of :func:`light_planes`.
    snap : float
        Pieces not longer than this, or not reaching farther than this in front of the
        light (a receiver lying in its plane sees it edge-on), are dropped.

    Returns
    -------
    row : (q,) int64
        The polyline each piece comes from (one polyline may give several pieces).
    offsets : (q + 1,) int64
    points : (r, 3) float64
    """
    m = len(offsets) - 1
    count = np.diff(offsets)
    owner = np.repeat(np.arange(m), count)
    last = np.zeros(len(points), bool)
    last[offsets[1:][count > 0] - 1] = True
    ia = np.flatnonzero(~last)
    ib = ia + 1
    g = front_distance(points, planes)
    ga, gb = g[ia], g[ib]
    keep = (ga > 0) | (gb > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        cut = ga / (ga - gb)  # where the chord crosses the plane (g = 0)
    ta = np.where(ga > 0, 0.0, cut)
    tb = np.where(gb > 0, 1.0, cut)
    ia, ib, ta, tb = ia[keep], ib[keep], ta[keep], tb[keep]
    if not len(ia):
        return np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros((0, 3))
    a = points[ia] + ta[:, None] * (points[ib] - points[ia])
    b = points[ia] + tb[:, None] * (points[ib] - points[ia])
    # a kept chord continues the previous one when they share a point that was not cut
    cont = np.r_[False, (ib[:-1] == ia[1:]) & (tb[:-1] == 1.0) & (ta[1:] == 0.0)]
    piece = np.cumsum(~cont) - 1
    q = int(piece[-1]) + 1 if len(piece) else 0
    row = owner[ia[~cont]]
    ends = np.r_[np.flatnonzero(np.diff(piece)), len(piece) - 1] if q else np.zeros(0, np.int64)
    pts = np.concatenate([a, b[ends]])
    pid = np.concatenate([piece, piece[ends]])
    rank = np.concatenate([np.arange(len(piece)), np.full(len(ends), len(piece))])
    order = np.lexsort([rank, pid])
    pts, pid = pts[order], pid[order]
    off = np.r_[0, np.cumsum(np.bincount(pid, minlength=q))].astype(np.int64)
    inner = pid[1:] == pid[:-1]
    length = np.bincount(pid[1:][inner], weights=np.linalg.norm(np.diff(pts, axis=0), axis=1)[inner], minlength=q)
    # pieces that only graze the light's plane
    reach = np.full(q, -np.inf)
    np.maximum.at(reach, pid, front_distance(pts, planes))
    good = (length > snap) & (reach > snap)
    sel = np.flatnonzero(good)
    if len(sel) == q:
        return row, off, pts
    take = np.repeat(good, np.diff(off))
    off = np.r_[0, np.cumsum(np.diff(off)[good])].astype(np.int64)
    return row[sel], off, pts[take]


def triangle_edge_ids(scene):
    """(t, 3) int64: scene edge of each triangle edge (i, i+1), -1 for inner diagonals."""
    ev = scene.half_edges.edge_vertices
    nv = scene.n_vertices
    tri = scene.triangles.astype(np.int64)
    a, b = tri, np.roll(tri, -1, axis=1)
    key = np.minimum(a, b) * nv + np.maximum(a, b)
    table = ev[:, 0].astype(np.int64) * nv + ev[:, 1]
    order = np.argsort(table)
    pos = np.clip(np.searchsorted(table[order], key), 0, len(table) - 1)
    hit = table[order][pos] == key
    return np.where(hit, order[pos], -1)


def plane_sections(scene, d, rows, tri_edge, basis):
    """Sections of triangles by a plane P, seen from its front (module docstring).

    Parameters
    ----------
    d : (v,) float64
        Signed distance of every vertex to P (front > 0), values within snap set to 0.
    rows : (r,) int
        Triangles that count, ascending.
    tri_edge : (t, 3) int64
        :func:`triangle_edge_ids`.
    basis : (u, v), (3,) float64 each

    Returns
    -------
    seg : (b, 2, 2) float64
        Sections in P's 2-D coordinates (both ends equal for a vertex touching P).
    end_kind : (b, 2) int64
        END_EDGE, END_VERTEX or END_INNER.
    end_id : (b, 2) int64
        The edge or vertex id.
    """
    tri = scene.triangles[rows].astype(np.int64)
    s = d[tri]  # (t, 3)
    # (a triangle wholly in front has no section point: only those reaching P)
    ok = (s.max(axis=1) > 0) & (s.min(axis=1) <= 0)
    tri, s, te = tri[ok], s[ok], tri_edge[rows[ok]]
    V = scene.vertices
    sj = np.roll(s, -1, axis=1)
    pj = V[np.roll(tri, -1, axis=1)]
    with np.errstate(divide="ignore", invalid="ignore"):
        w = s / (s - sj)
        crossing = V[tri] + w[..., None] * (pj - V[tri])  # (t, 3, 3) on edge (i, i+1)
    cand = np.concatenate([crossing, V[tri]], axis=1)  # (t, 6, 3)
    valid = np.concatenate([s * sj < 0, s == 0], axis=1)
    kind = np.concatenate([np.where(te >= 0, END_EDGE, END_INNER), np.full_like(tri, END_VERTEX)], axis=1)
    ids = np.concatenate([te, tri], axis=1)
    n_valid = valid.sum(axis=1)
    # at most two section points per triangle (it is not in P); one: a vertex touching P
    pick = np.argsort(~valid, axis=1, kind="stable")[:, :2]
    pick[:, 1] = np.where(n_valid >= 2, pick[:, 1], pick[:, 0])
    keep = n_valid >= 1
    pick = pick[keep]
    r = np.flatnonzero(keep)[:, None]
    p3 = cand[r, pick]  # (b, 2, 3)
    u, v = basis
    seg = np.stack([p3 @ u, p3 @ v], axis=-1)
    return seg, kind[r, pick], ids[r, pick]


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _line_hits(h, u, seg, snap):
    """Where lines h + t u (u unit) cross sections transversally.

    h, u : (n, 2); seg : (b, 2, 2). Returns t : (n, b) float64 (inf where a section does
    not cross the line, or only touches it within ``snap``).
    """
    p, q = seg[None, :, 0] - h[:, None], seg[None, :, 1] - h[:, None]
    sp, sq = _cross2(u[:, None], p), _cross2(u[:, None], q)
    tp, tq = np.einsum("nj,nbj->nb", u, p), np.einsum("nj,nbj->nb", u, q)
    strict = ((sp > snap) & (sq < -snap)) | ((sp < -snap) & (sq > snap))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = tp + (tq - tp) * sp / (sp - sq)
    return np.where(strict, t, np.inf)


def clip_lines_to_polygon(p0, u, lo, hi, loops, snap):
    """The parts of 2-D lines inside a polygon (even-odd).

    Parameters
    ----------
    p0, u : (n, 2) float64
        Lines p0 + t u, t in [lo, hi].
    lo, hi : (n,) float64
    loops : list of (k, 2) float64

    Returns
    -------
    row : (q,) int64, t0 : (q,) float64, t1 : (q,) float64
        Pieces longer than ``snap`` (u unit) of line ``row``.
    """
    a = np.concatenate(loops)
    b = np.concatenate([np.roll(lp, -1, axis=0) for lp in loops])
    e = b - a
    den = _cross2(u[:, None], e[None])  # (n, k)
    r = a[None] - p0[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cross2(r, e[None]) / den
        s = _cross2(r, u[:, None]) / den
    t = np.where((den != 0) & (s >= 0) & (s <= 1) & (t > lo[:, None]) & (t < hi[:, None]), t, np.nan)
    brk = np.sort(np.concatenate([lo[:, None], hi[:, None], t], axis=1), axis=1)  # nan last
    t0, t1 = brk[:, :-1], brk[:, 1:]
    ok = np.isfinite(t0) & np.isfinite(t1) & (t1 - t0 > snap)
    row, col = np.nonzero(ok)
    t0, t1 = t0[row, col], t1[row, col]
    mid = p0[row] + (0.5 * (t0 + t1))[:, None] * u[row]
    straddle = (a[None, :, 1] > mid[:, None, 1]) != (b[None, :, 1] > mid[:, None, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = a[None, :, 0] + (mid[:, None, 1] - a[None, :, 1]) * e[None, :, 0] / e[None, :, 1]
    inside = np.count_nonzero(straddle & (mid[:, None, 0] < xc), axis=1) % 2 == 1
    return row[inside], t0[inside], t1[inside]


def pierces(left, right):
    """Whether the line HC passes C through the occluder there, from the numbers of
    sections ending at C on each side of it.

    Near C the sections ending there are rays from C that cut the plane (seen from the
    front) into sectors. The line leaves C in two directions: towards H, through the
    sector the segment HC runs in, which is free (the caller asks that no section
    crosses HC, and H is on the light's outline), and towards x. A ray crossed on the
    way round from one direction to the other is where a closed surface is entered or
    left, so the sector towards x is free as well when an even number of rays lie on
    either side, and inside the solid when an odd number do.

    * All sections on one side (an occluder's vertex in P, a panel hinged on the
      receiver's edge): the line grazes, as before.
    * One on each side (a convex vertex whose section by P the line runs into): pierced.
    * Two on each side: a saddle of a closed surface at one of the receiver's own
      vertices (a scanned mesh: the receiver's two neighbours across its edges at C rise
      in front of P, two more faces of the fan cross P at C on the side of H). Between
      them the line runs above the receiver and through the free sector towards H: x→H
      passes C beside one lobe of the surface or the other, and which of C's edges ends
      the hidden part of the light edge next to H changes across the line (the RPV
      event). Before, such a line was taken as pierced: the bunny's faces lacked these
      lines (tests/test_discontinuities.py::test_saddle_at_the_receivers_vertex).

    Parameters
    ----------
    left, right : (n,) int
        Sections ending at C strictly on each side of the line.

    Returns
    -------
    (n,) bool
    """
    left, right = np.asarray(left), np.asarray(right)
    return (left > 0) & (right > 0) & ((left % 2 == 1) | (right % 2 == 1))


def _graze_interval(h, u, tC, seg, back, front_free, snap):
    """Where along lines h + t u (through H at t = 0 and C at t = tC) a receiver point x
    has a receiver-plane event: x→H grazes at C and is otherwise free in front, and
    blocked behind unless ``front_free``.

    Parameters
    ----------
    h, u : (n, 2) float64
        H and the unit direction towards C.
    tC : (n,) float64
    seg, back : (b, 2, 2), (b', 2, 2) float64
        Sections seen from the front and from behind (:func:`plane_sections`).
    front_free : (n,) bool
        C's event needs nothing behind (:func:`front_decides`).

    Returns
    -------
    lo, hi : (n,) float64
        The event's parameter interval (lo = inf: none).
    """
    C = h + tC[:, None] * u
    near0 = np.linalg.norm(seg[None, :, 0] - C[:, None], axis=-1) <= snap
    at_c = near0 | (np.linalg.norm(seg[None, :, 1] - C[:, None], axis=-1) <= snap)
    # the line passes C through the occluder unless it grazes it there: sections ending
    # at C on one side of it only, or an even number on each side (a closed surface
    # saddled at C, a vertex of the receiver itself: :func:`pierces`)
    other = np.where(near0[..., None], seg[None, :, 1], seg[None, :, 0])
    side = _cross2(u[:, None], other - h[:, None])
    pierced = pierces(np.count_nonzero(at_c & (side > snap), axis=1), np.count_nonzero(at_c & (side < -snap), axis=1))
    t = np.where(at_c, np.inf, _line_hits(h, u, seg, snap))
    t = np.where(t > snap, t, np.inf)  # sections through H itself (the light's neighbours)
    hidden = pierced | (t < tC[:, None] + snap).any(axis=1)
    hi = np.where(t >= tC[:, None] + snap, t, np.inf).min(axis=1)
    # behind P the segment x→H must be blocked (the horizon's hidden interval ends at H),
    # unless C is a vertex (front_decides)
    tb = _line_hits(h, u, back, snap) if len(back) else np.full((len(h), 1), np.inf)
    lo = np.maximum(tC, np.where(tb > snap, tb, np.inf).min(axis=1))
    lo[front_free] = tC[front_free]
    lo[hidden] = np.inf
    return lo, hi


def front_decides(kind, ids, back_kind, back_ids, sigma):
    """The critical points C whose event holds wherever x→H is free in front, whatever
    lies behind P: the vertices.

    Why: seen from x, the light edge l next to H has a front half (in P⁺) and a back
    half, and the sections ending at C decide both halves next to H.

    * C on an edge e crossing P (RPE): e's image crosses l next to H on the front half
      on one side of the line HC, on the back half on the other: the label (l, e)
      stays. What changes is H itself, an end of a hidden interval on one side only
      when exactly one half is blocked by other occluders: free in front and blocked
      behind in this pass, the other way round in the other pass (σ = −1).
    * C a vertex of an occluder: its edges leaving P are different edges, so which of
      them bound the hidden part of l next to H changes (C's image crosses l: the VE
      event of C and l, whose one line meeting f lies in P); and when C ends a section
      lying in P (an edge of a face touching P, such as a panel hinged on the
      receiver's edge), whether x→H crosses it decides whether H ends a hidden
      interval, cast by that edge. The labels change wherever a half that changes is
      not blocked by other occluders. If no section seen from behind ends at C (the
      occluder lies in front of P), only the front half changes: the event is where
      the front is free. If sections on both sides end at C, both halves change: the
      event is where either half is free; this pass (σ = +1) takes where the front is
      free, the pass σ = −1 (its behind-blocked rule) where its front is free and ours
      blocked, so the two do not overlap.

    Parameters
    ----------
    kind, ids : (n,) int64
        Each C's feature (END_EDGE or END_VERTEX, scene id).
    back_kind, back_ids : (b,) int64
        The end features of the sections seen from behind.
    sigma : float
        +1 or −1: which side of P is the front in this pass.

    Returns
    -------
    (n,) bool
    """
    behind = np.isin(ids, back_ids[back_kind == END_VERTEX])
    return (kind == END_VERTEX) & (~behind | (sigma > 0))


def receiver_plane_events(scene, light, f, basis, outline, snap, tri_edge=None, sides=(1.0, -1.0)):
    """Receiver-plane events on receiver f (module docstring).

    Parameters
    ----------
    f : int
    basis : (u, v), (3,) float64 each
        f's 2-D frame (a point q is ``origin + q[0] u + q[1] v``).
    outline : list of (k, 2) float64
        f's loops in 2-D.
    tri_edge : (t, 3) int64, optional
        :func:`triangle_edge_ids` (computed when not given).
    sides : tuple of float
        The passes σ to run: the sides of P (σ times f's normal) taken as the front, from
        which x→H may reach the light (both for a lone face; for a face of a closed solid,
        the side the light is on: :func:`viscx.queries.discontinuities.lit_sides`).

    Returns
    -------
    kind : (m,) int64
        RP_EDGE (C on an occluder edge) or RP_VERTEX (an occluder vertex in P).
    occluder : (m,) int64
        The edge or vertex id of C.
    light_edge : (m,) int64
        The light edge l through H.
    ends : (m, 2, 2) float64
        The trace in f's 2-D coordinates, from the end nearer C.
    """
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2, 2)))
    n, c = scene.face_normal[f], scene.face_offset[f]
    ev = scene.half_edges.edge_vertices
    la, lb = ev[light.edges, 0], ev[light.edges, 1]
    dl = scene.vertices[light.vertices] @ n - c
    if not ((dl > snap).any() and (dl < -snap).any()):
        return empty  # the light does not straddle P: no horizon on it
    d = scene.vertices @ n - c
    d[np.abs(d) <= snap] = 0.0
    cut = d[la] * d[lb] < 0  # light edges strictly crossing P
    if not cut.any():
        return empty
    if tri_edge is None:
        tri_edge = triangle_edge_ids(scene)
    u3, v3 = basis
    Va, Vb = scene.vertices[la[cut]], scene.vertices[lb[cut]]
    w = d[la[cut]] / (d[la[cut]] - d[lb[cut]])
    H3 = Va + w[:, None] * (Vb - Va)
    H = np.stack([H3 @ u3, H3 @ v3], axis=1)
    H_edge = light.edges[cut]
    corners = np.concatenate(outline)
    centre = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
    disc = centre, float(np.linalg.norm(corners - centre, axis=1).max()) + 2 * snap
    # A trace is the ray beyond C, clipped to f, and what decides it (C, the sections
    # crossed between H and f) lies in the hull of H and f, inside the box of the light
    # and f: the triangles outside that box (with a margin) are left out. (A section
    # beyond f only ends a trace past f, or blocks behind past f: either way the part
    # on f is the same.)
    tri_lo, tri_hi = _triangle_boxes(scene)
    ends = np.concatenate([scene.vertices[light.vertices], *scene.face_loops(f)])
    box_lo, box_hi = ends.min(axis=0) - 4 * snap, ends.max(axis=0) + 4 * snap
    # (only triangles reaching P have a section, from either side: plane_sections keeps
    # no other)
    rows = _boxes_meeting(tri_lo, tri_hi, box_lo, box_hi, scene.triangles, d)
    owner = scene.triangle_face[rows]
    rows = rows[~np.isin(owner, light.faces) & (owner != f)]
    out = []
    for sigma in sides:
        seg, ekind, eid = plane_sections(scene, sigma * d, rows, tri_edge, basis)
        back, bkind, bid = plane_sections(scene, -sigma * d, rows, tri_edge, basis)
        if not len(seg):
            continue
        # critical points C: section ends on scene edges or vertices, each feature once
        ends, ek, ei = seg.reshape(-1, 2), ekind.ravel(), eid.ravel()
        sel = ek != END_INNER
        ends, ek, ei = ends[sel], ek[sel], ei[sel]
        _, first = np.unique(ek * (max(scene.n_vertices, len(ev)) + 1) + ei, return_index=True)
        C, ck, ci = ends[first], ek[first], ei[first]
        free = front_decides(ck, ci, bkind.ravel(), bid.ravel(), sigma)
        hh, cc = np.repeat(np.arange(len(H)), len(C)), np.tile(np.arange(len(C)), len(H))
        vec = C[cc] - H[hh]
        tC = np.linalg.norm(vec, axis=1)
        far = tC > snap
        hh, cc, vec, tC = hh[far], cc[far], vec[far], tC[far]
        udir = vec / tC[:, None]
        # the trace is the ray beyond C, clipped to f: only rays from C that reach f's
        # bounding disc (centre m, radius R) can leave one (the others are cut away below)
        m, R = disc
        w = m - H[hh]
        along = np.einsum("ij,ij->i", w, udir)
        off2 = np.einsum("ij,ij->i", w, w) - along ** 2
        reach = (off2 <= R * R) & (tC <= along + np.sqrt(np.maximum(R * R - off2, 0.0)) + snap)
        hh, cc, tC, udir = hh[reach], cc[reach], tC[reach], udir[reach]
        if not len(hh):
            continue
        h0 = H[hh]
        lo, t_end = np.empty(len(hh)), np.empty(len(hh))
        step = max(1, PAIR_BLOCK // (len(seg) + len(back)))
        for a in range(0, len(hh), step):
            sl = slice(a, a + step)
            lo[sl], t_end[sl] = _graze_interval(h0[sl], udir[sl], tC[sl], seg, back, free[cc[sl]], snap)
        keep = np.isfinite(lo) & (lo < t_end - snap)
        if not keep.any():
            continue
        k = np.flatnonzero(keep)
        row, t0, t1 = clip_lines_to_polygon(h0[k], udir[k], lo[k], t_end[k], outline, snap)
        k = k[row]
        out.append((np.where(ck[cc[k]] == END_EDGE, RP_EDGE, RP_VERTEX), ci[cc[k]], H_edge[hh[k]],
                    np.stack([h0[k] + t0[:, None] * udir[k], h0[k] + t1[:, None] * udir[k]], axis=1)))
    if not out:
        return empty
    return tuple(np.concatenate(x) for x in zip(*out))


@njit(cache=True)
def _boxes_meeting(lo, hi, box_lo, box_hi, triangles, d):
    """(r,) int64, ascending: the triangles whose boxes (lo, hi (t, 3)) meet the box
    [box_lo, box_hi] and that reach the plane P (signed distances ``d`` of their
    vertices: some on each side of it, or one side and on it); one pass, no (t, 3)
    temporaries: it runs once per receiver."""
    out = np.empty(lo.shape[0], np.int64)
    k = 0
    for i in range(lo.shape[0]):
        if (hi[i, 0] >= box_lo[0] and hi[i, 1] >= box_lo[1] and hi[i, 2] >= box_lo[2]
                and lo[i, 0] <= box_hi[0] and lo[i, 1] <= box_hi[1] and lo[i, 2] <= box_hi[2]):
            s0, s1, s2 = d[triangles[i, 0]], d[triangles[i, 1]], d[triangles[i, 2]]
            s_min, s_max = min(s0, s1, s2), max(s0, s1, s2)
            if (s_max > 0 and s_min <= 0) or (s_min < 0 and s_max >= 0):
                out[k] = i
                k += 1
    return out[:k]


def _triangle_boxes(scene):
    """(lo, hi): the bounding box of every scene triangle, (t, 3) float each (cached)."""
    def boxes(scene):
        corners = scene.vertices[scene.triangles]
        return corners.min(axis=1), corners.max(axis=1)

    return scene.cached("triangle_boxes", boxes)


def light_plane_lines(scene, planes, f, basis, origin, outline, snap):
    """Where the light's planes cross receiver f: the boundary of the part of f in front
    of the light (on each plane, the part where no other light plane has f in front).

    Returns
    -------
    face : (m,) int64
        The light face of each line's plane.
    ends : (m, 2, 2) float64
        f's 2-D coordinates.
    """
    n, c, lface = planes
    u3, v3 = basis
    loops3 = scene.face_loops(f)
    verts = np.concatenate(loops3)
    dv = verts @ n.T - c[None, :]  # (k, planes)
    straddle = (dv > snap).any(axis=0) & (dv < -snap).any(axis=0)
    j = np.flatnonzero(straddle)
    if not len(j):
        return np.zeros(0, np.int64), np.zeros((0, 2, 2))
    # plane j in f's coordinates: a · q = b
    a = np.stack([n[j] @ u3, n[j] @ v3], axis=1)
    b = c[j] - n[j] @ origin
    na = np.linalg.norm(a, axis=1)
    p0 = a * (b / na ** 2)[:, None]
    udir = np.stack([-a[:, 1], a[:, 0]], axis=1) / na[:, None]
    big = 4.0 * scene.diagonal + np.abs(p0).max()
    lo, hi = np.full(len(j), -big), np.full(len(j), big)
    # other planes i: their distance along the line is h0 + t h1 <= 0
    h0 = (origin + p0[:, :1] * u3 + p0[:, 1:] * v3) @ n.T - c[None, :]  # (j, planes)
    h1 = (udir[:, :1] * u3 + udir[:, 1:] * v3) @ n.T
    other = np.arange(len(n))[None, :] != j[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -h0 / h1
    hi = np.minimum(hi, np.where(other & (h1 > 0), root, np.inf).min(axis=1))
    lo = np.maximum(lo, np.where(other & (h1 < 0), root, -np.inf).max(axis=1))
    dead = (other & (h1 == 0) & (h0 > 0)).any(axis=1)
    lo[dead] = hi[dead]
    row, t0, t1 = clip_lines_to_polygon(p0, udir, lo, hi, outline, snap)
    return lface[j[row]], np.stack([p0[row] + t0[:, None] * udir[row], p0[row] + t1[:, None] * udir[row]], axis=1)
