"""Brute-force oracle of the discontinuity mesh: which features bound the part of an
area light a point sees.

Independent of the complex: it uses only the scene's triangles and the light's outline.
From a receiver point x, every occluder triangle T hides the points y of the light for
which the segment xy meets T; on a light edge y(t) = a + t (b - a) that is an interval
of t cut out by four linear sign conditions (y beyond T's plane, and the ray x→y inside
T's three edge wedges): exact polygon clipping of the light's outline, one edge at a
time. The union of the hidden intervals on each light edge gives the *labels* of x:

* ``("v", w)`` for each light vertex w that x sees;
* ``("x", l, e)`` for each point where the boundary of the visible part of the light
  meets light edge l, cast by occluder edge e (the triangle edge bounding the hidden
  interval there; ``("p", l, F)`` when it is face F's plane crossing the light).

These are exactly the features the light-involving events change (a light vertex
appears behind an occluder edge: VE; an occluder vertex's image crosses a light edge:
VE; two occluder edges' images cross on a light edge: EEE; the receiver's horizon and
an occluder edge's image cross on a light edge: a receiver-plane event). Events between
occluders alone (inside the light's image) do not change them; they are not part of the
mesh.

The light is **one-sided**, as in ``viscx render``: it emits from the front of its faces
(the side their normals point to). A point on or behind the planes of all the light's
faces sees nothing of it: its labels are ``{("behind",)}``.
"""

from pathlib import Path

import numpy as np

#: The golden files (viscx build of the sample scenes).
GOLDEN = Path(__file__).resolve().parent / "golden"

#: Parameter slack when merging hidden intervals on a light edge and testing ends.
TSLACK = 1e-9
#: The labels of a point that sees the back of the light only (nothing).
BEHIND = frozenset({("behind",)})


def _det(a, b, c):
    return np.einsum("...i,...i->...", a, np.cross(b, c))


def oracle_setup(scene, light_faces):
    """Light outline edges (vertex ids, edge ids) and triangle-edge → scene-edge table."""
    he = scene.half_edges
    in_light = np.zeros(scene.n_faces + 1, bool)
    in_light[light_faces] = True
    other = np.where(he.opp >= 0, he.face[np.maximum(he.opp, 0)], -1)
    outline = in_light[he.face] & ~((he.opp >= 0) & in_light[other])
    ledge = np.unique(he.edge[outline])
    lverts = he.edge_vertices[ledge]
    table = {(int(a), int(b)): k for k, (a, b) in enumerate(he.edge_vertices)}
    tri = scene.triangles
    tri_edge = np.array([[table.get((min(t[i], t[(i + 1) % 3]), max(t[i], t[(i + 1) % 3])), -1) for i in range(3)]
                         for t in tri.tolist()], np.int64).reshape(-1, 3)
    return {"ledge": ledge, "lverts": lverts, "tri_edge": tri_edge, "light_faces": np.asarray(light_faces)}


def labels_at(scene, setup, x, receiver):
    """The label set (frozenset) of the light's visible part from point x on face ``receiver``."""
    return labels_of(scene, setup, np.asarray(x, dtype=np.float64)[None], receiver)[0]


def shaft_triangles(scene, setup, points):
    """(t,) bool: the scene's triangles that may meet a segment from one of ``points``
    ((m, 3) float, in front of the light) to a point of the light: those not wholly
    outside one face plane of the pyramid conv(x ∪ hull of the light), for some x. Every
    other triangle hides nothing from any of the points (its hidden intervals are empty),
    so the labels are those of all triangles. For a light whose faces are not in one
    plane: every triangle."""
    lf = setup["light_faces"]
    n, off = scene.face_normal[lf], scene.face_offset[lf]
    ids = np.unique(setup["lverts"])
    y = scene.vertices[ids]
    flat = np.all(np.abs(n - n[0]) <= 1e-12) and np.all(np.abs(y @ n[0] - off[0]) <= 1e-9 * scene.diagonal)
    if not flat or len(ids) < 3:
        return np.ones(len(scene.triangles), bool)
    from scipy.spatial import ConvexHull

    u = np.cross(n[0], [1.0, 0, 0] if abs(n[0][0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(n[0], u)
    hull = y[ConvexHull(np.stack([y @ u, y @ v], axis=1)).vertices]  # counter-clockwise about n
    centre = hull.mean(axis=0)
    slack = 1e-9 * scene.diagonal
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    # first the box of the points and the light: a triangle outside it meets no pyramid
    ends = np.concatenate([points, y])
    corners = scene.vertices[scene.triangles]
    rows = np.flatnonzero(np.all((corners.max(axis=1) >= ends.min(axis=0) - slack)
                                 & (corners.min(axis=1) <= ends.max(axis=0) + slack), axis=1))
    corners = corners[rows]
    kept = np.zeros(len(rows), bool)
    for x in points:
        outside = np.zeros(len(rows), bool)
        # the light's plane: beyond it from x, nothing of xy
        side = np.sign(n[0] @ x - off[0])
        outside |= (side * (corners @ n[0] - off[0]) < -slack).all(axis=1)
        for a, b in zip(hull, np.roll(hull, -1, axis=0)):
            m = np.cross(a - x, b - x)
            m *= np.sign(m @ (centre - x))  # the pyramid's inside: positive
            outside |= ((corners - x) @ m < -slack * np.linalg.norm(m)).all(axis=1)
        kept |= ~outside
    out = np.zeros(len(scene.triangles), bool)
    out[rows[kept]] = True
    return out


def labels_of(scene, setup, points, receiver, chunk=64, cull=False):
    """:func:`labels_at` of each point ((m, 3) float, all on face ``receiver``): a list of
    frozensets. The clipping is computed for ``chunk`` points at once (arrays of
    (points, triangles, light edges, 4) constraints), the union of the hidden intervals
    point by point. ``cull``: each chunk against the triangles of its points' shafts
    alone (:func:`shaft_triangles`; the same labels, for scenes of 10⁵ triangles)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lf = setup["light_faces"]
    if cull is True:
        out = []
        for c in range(0, len(points), chunk):
            part = points[c:c + chunk]
            out += labels_of(scene, setup, part, receiver, chunk, cull=shaft_triangles(scene, setup, part))
        return out
    tri_ok = ~np.isin(scene.triangle_face, np.r_[lf, receiver])
    if cull is not False:  # a mask of the triangles that may hide something
        tri_ok &= cull
    T = scene.vertices[scene.triangles[tri_ok]]  # (t, 3, 3)
    A = scene.vertices[setup["lverts"][:, 0]]  # (k, 3)
    B = scene.vertices[setup["lverts"][:, 1]]
    nrm = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    # the plane constraint's value at the light edges' ends does not depend on x, its sign does
    plane = [np.einsum("ti,tki->tk", nrm, y[None, :, :] - T[:, None, 0]) for y in (A, B)]
    # the receiver's own edges lie in x's plane: their images are one line, so which of
    # them casts a crossing is a tie; they are one label
    own = set(scene.half_edges.edge[scene.half_edges.face == receiver].tolist())
    tables = (setup["tri_edge"][tri_ok], scene.triangle_face[tri_ok], own)
    # a point on or behind the planes of all the light's faces sees nothing of it
    behind = [bool(np.all(scene.face_normal[lf] @ p - scene.face_offset[lf] <= TSLACK * scene.diagonal)) for p in points]
    front = points[~np.array(behind, bool).reshape(-1)]
    out = []
    for c in range(0, len(front), chunk):
        x = front[c:c + chunk, None, None, :]  # (m, 1, 1, 3)
        sigma = np.sign(_det(T[None, :, 0] - x[:, 0], T[None, :, 1] - x[:, 0], T[None, :, 2] - x[:, 0]))  # (m, t)
        px = np.einsum("...i,...i->...", nrm[None], x[:, 0] - T[None, :, 0])

        def cons(y, plane):  # (k, 3) -> (m, t, k, 4) constraint values (>= 0 inside the hidden set)
            y = y[None, None, :, :]
            c = [sigma[..., None] * _det(T[None, :, None, i] - x, T[None, :, None, (i + 1) % 3] - x, y - x) for i in range(3)]
            c.append(-np.sign(px)[..., None] * plane[None])
            return np.stack(c, axis=-1)

        c0, c1 = cons(A, plane[0]), cons(B, plane[1])
        slope = c1 - c0
        with np.errstate(divide="ignore", invalid="ignore"):
            root = -c0 / slope
        inc, dec = slope > 0, slope < 0
        flat_bad = (slope == 0) & (c0 < 0)
        # a light edge in the triangle's plane (a light face's neighbour): segments to it end on
        # the triangle's boundary and are not hidden by it
        scale = (np.abs(c0).max(axis=(1, 2, 3), initial=0.0) + np.abs(c1).max(axis=(1, 2, 3), initial=0.0) + 1e-300)[:, None, None]
        flat_bad[..., 3] |= (np.abs(c0[..., 3]) <= 1e-12 * scale) & (np.abs(c1[..., 3]) <= 1e-12 * scale)
        lo_cand = np.where(inc, root, -np.inf)
        hi_cand = np.where(dec, root, np.inf)
        lo_k, hi_k = np.argmax(lo_cand, axis=-1), np.argmin(hi_cand, axis=-1)
        lo = np.maximum(np.take_along_axis(lo_cand, lo_k[..., None], -1)[..., 0], 0.0)
        hi = np.minimum(np.take_along_axis(hi_cand, hi_k[..., None], -1)[..., 0], 1.0)
        ok = (sigma != 0)[..., None] & (px != 0)[..., None] & ~flat_bad.any(axis=-1) & (hi - lo > TSLACK)
        out += [_union_labels(setup, tables, ok[i], lo[i], hi[i], lo_k[i], hi_k[i]) for i in range(len(x))]
    seen = iter(out)
    return [BEHIND if b else next(seen) for b in behind]


def _union_labels(setup, tables, ok, lo, hi, lo_k, hi_k):
    """The labels of one point from its hidden intervals ((t, k) each: triangle t on light
    edge k, ``ok`` where it hides a part [lo, hi], bounded by constraints lo_k, hi_k)."""
    tedge, tface, own = tables

    def lab(t, k):
        if k == 3:
            return ("p", int(tface[t]))
        e = int(tedge[t, k])
        return ("e", -2 if e in own else e)

    labels = set()
    nk = ok.shape[1]
    covered0 = np.zeros(nk, bool)
    covered1 = np.zeros(nk, bool)
    for l in range(nk):
        ts = np.flatnonzero(ok[:, l])
        if not len(ts):
            continue
        iv = sorted(zip(lo[ts, l], hi[ts, l], ts))
        merged = []
        for a, b, t in iv:
            if merged and a <= merged[-1][1] + TSLACK:
                if b > merged[-1][1]:
                    merged[-1][1], merged[-1][3] = b, lab(t, hi_k[t, l])
            else:
                merged.append([a, b, lab(t, lo_k[t, l]), lab(t, hi_k[t, l])])
        for a, b, la, lb in merged:
            if a <= TSLACK:
                covered0[l] = True
            else:
                labels.add(("x", int(setup["ledge"][l])) + la)
            if b >= 1 - TSLACK:
                covered1[l] = True
            else:
                labels.add(("x", int(setup["ledge"][l])) + lb)
    hidden = set(setup["lverts"][covered0, 0].tolist()) | set(setup["lverts"][covered1, 1].tolist())
    for w in np.unique(setup["lverts"]).tolist():
        if w not in hidden:
            labels.add(("v", int(w)))
    return frozenset(labels)


def _seg_dist(q, a, b):
    """Distance from 2-D points q (m, 2) to segments a, b (k, 2): (m, k). (By coordinate
    planes, (m, k) each: the oracle's hot spot; the (m, k, 2) form's values to the bit at
    2.3x the speed.)"""
    ab = b - a
    dx, dy = q[:, 0, None] - a[None, :, 0], q[:, 1, None] - a[None, :, 1]
    t = np.clip((dx * ab[:, 0] + dy * ab[:, 1]) / np.maximum(np.einsum("kj,kj->k", ab, ab), 1e-300), 0, 1)
    dx -= t * ab[:, 0]
    dy -= t * ab[:, 1]
    return np.sqrt(dx * dx + dy * dy)


def _crossings(q, a, b):
    """(m, k) bool: the ray from each point q (m, 2) towards +x crosses edge a -> b (k, 2)."""
    cond = (a[None, :, 1] > q[:, None, 1]) != (b[None, :, 1] > q[:, None, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = a[None, :, 0] + (q[:, None, 1] - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (b[None, :, 1] - a[None, :, 1])
    return cond & (q[:, None, 0] < xc)


def _edges(loops):
    """The edges (a, b) of closed 2-D loops."""
    return np.concatenate(loops), np.concatenate([np.roll(lp, -1, axis=0) for lp in loops])


def _parity(q, loops):
    return np.count_nonzero(_crossings(q, *_edges(loops)), axis=1) % 2 == 1


def _first_far(q, a, b, margin, count, chunk=64):
    """The first ``count`` points of q farther than ``margin`` from every segment a -> b,
    in order (``q[_seg_dist(q, a, b).min(axis=1) > margin][:count]``, by chunks)."""
    kept = []
    for k in range(0, len(q), chunk):
        part = q[k:k + chunk]
        kept.append(part[_seg_dist(part, a, b).min(axis=1) > margin])
        if sum(map(len, kept)) >= count:
            break
    return np.concatenate(kept)[:count] if kept else q[:0]


def _straddles(q, a, b):
    """(c, k) bool: the segment between each point pair q (c, 2, 2) crosses segment a -> b
    (k, 2) (each pair's ends strictly on both sides of the other's line, both ways)."""
    p0, p1 = q[:, None, 0], q[:, None, 1]

    def side(o, d, x):
        return d[..., 0] * (x[..., 1] - o[..., 1]) - d[..., 1] * (x[..., 0] - o[..., 0])

    ab = (b - a)[None]
    s0, s1 = side(a[None], ab, p0), side(a[None], ab, p1)
    t0, t1 = side(p0, p1 - p0, a[None]), side(p0, p1 - p0, b[None])
    return (s0 * s1 < 0) & (t0 * t1 < 0)


#: Where along a trace (fractions of its length) the crossing check is tried, in order.
CROSS_AT = (0.5, 0.3, 0.7, 0.15, 0.85, 0.05, 0.95, 0.01, 0.99)


def _crossing_points(a, b, margin):
    """Point pairs across a 2-D polyline (chords a, b: (c, 2) each) at each of
    :data:`CROSS_AT`, offset ±margin along its normal: (len(CROSS_AT), 2, 2)."""
    length = np.linalg.norm(b - a, axis=1)
    cum = np.r_[0.0, np.cumsum(length)]
    at = np.asarray(CROSS_AT) * cum[-1]
    c = np.clip(np.searchsorted(cum, at, side="right") - 1, 0, len(a) - 1)
    # a zero-length chord has no normal: take the nearest chord with one
    ok = np.flatnonzero(length > 0)
    if not len(ok):
        return np.zeros((0, 2, 2))
    c = ok[np.clip(np.searchsorted(ok, c), 0, len(ok) - 1)]
    w = np.clip((at - cum[c]) / length[c], 0, 1)
    d = (b[c] - a[c]) / length[c, None]
    m = a[c] + w[:, None] * (b[c] - a[c])
    n2 = np.stack([-d[:, 1], d[:, 0]], axis=1)
    return np.stack([m + margin * n2, m - margin * n2], axis=1)


def check_mesh(scene, mesh, rng, margin, samples=4, faces=None, max_regions=None, max_traces=None, cull=False):
    """Compare a DiscontinuityMesh with the oracle.

    Same region: ``samples`` random points per region, at least ``margin`` from every
    mesh line, contact and outline; every pair must have equal labels. Crossing: every
    trace, at its middle (by length), offset ±margin along its normal; where those points
    are outside the face or within margin/2 of another line, at the first of
    :data:`CROSS_AT` where they are not, then the same with margin/4, preferring a place
    where the pair crosses no other line (where lines meet at a small angle, one far
    enough from the pair's points can still run between them, and its change may undo
    this one's); labels must differ and the points be in different regions. A trace with
    no such place is listed in ``cross_skipped`` (face, event, why: "on the outline" for a
    trace along the face's outline, which has no other side). Trace ends inside the face farther
    than the mesh's snap distance from every other line are listed in ``dangling``
    (face, event, point, distance).

    For large meshes: ``faces`` (receivers to check, default all), ``max_regions`` and
    ``max_traces`` (per receiver, drawn by ``rng`` when there are more), ``cull``
    (:func:`labels_of`). With the defaults ``rng`` draws exactly as before.

    Returns
    -------
    dict of counts and the failures (lists of tuples).
    """
    setup = oracle_setup(scene, mesh.light.faces)
    wanted = None if faces is None else set(int(f) for f in faces)
    out = {"same_pairs": 0, "same_agree": 0, "cross_pairs": 0, "cross_agree": 0, "regions": 0,
           "regions_sampled": 0, "same_fail": [], "cross_fail": [], "cross_same_region": 0,
           "cross_skipped": [], "dangling": []}
    for r in mesh.receivers:
        if wanted is not None and r.face not in wanted:
            continue
        u, v, o = r.frame
        outline = [np.stack([lp @ u, lp @ v], axis=1) for lp in scene.face_loops(r.face)]
        # the outline and the contact edges (D0 lines) are lines of no event (owner -1)
        ce = scene.vertices[scene.half_edges.edge_vertices[r.contacts]]
        a = [np.concatenate(outline), np.stack([ce[:, 0] @ u, ce[:, 0] @ v], axis=1)]
        b = [np.concatenate([np.roll(lp, -1, axis=0) for lp in outline]),
             np.stack([ce[:, 1] @ u, ce[:, 1] @ v], axis=1)]
        owner = [np.full(len(a[0]) + len(a[1]), -1)]
        for k in r.events:
            p = mesh.points[mesh.offsets[k]:mesh.offsets[k + 1]]
            q = np.stack([p @ u, p @ v], axis=1)
            a.append(q[:-1])
            b.append(q[1:])
            owner.append(np.full(len(q) - 1, k))
        a, b, owner = np.concatenate(a), np.concatenate(b), np.concatenate(owner)

        # every region's edges at once, for the region holding a point: the first of
        # odd parity (the region's edges it crosses)
        region_edges = [_edges([g.outer, *g.holes]) for g in r.regions]
        ra = np.concatenate([e[0] for e in region_edges]) if region_edges else np.zeros((0, 2))
        rb = np.concatenate([e[1] for e in region_edges]) if region_edges else np.zeros((0, 2))
        rid = np.repeat(np.arange(len(region_edges)), [len(e[0]) for e in region_edges])

        def region_of(q):
            if not r.regions:
                return np.full(len(q), -1)
            hits = _crossings(q, ra, rb)
            odd = np.stack([np.bincount(rid[h], minlength=len(r.regions)) % 2 == 1 for h in hits]).reshape(len(q), -1)
            return np.where(odd.any(axis=1), np.argmax(odd, axis=1), -1)

        out["regions"] += len(r.regions)
        # the points to label: each sampled region's, then each crossed trace's pair (all
        # labelled at once below)
        sampled = []
        chosen = range(len(r.regions))
        if max_regions is not None and len(r.regions) > max_regions:
            chosen = np.sort(rng.choice(len(r.regions), max_regions, replace=False))
        for j in chosen:
            g = r.regions[j]
            lo, hi = g.outer.min(axis=0), g.outer.max(axis=0)
            q = lo + (hi - lo) * rng.uniform(size=(400, 2))
            q = q[_parity(q, [g.outer, *g.holes])]
            q = _first_far(q, a, b, margin, samples)
            if len(q) >= 2:
                sampled.append((j, q))
        # every trace ends on another line (or runs out of the face): a dangling end
        # leaves one region on both sides of the trace
        for k in r.events:
            rows = np.flatnonzero(owner == k)
            ends = np.stack([a[rows[0]], b[rows[-1]]])
            inside = _parity(ends, outline)
            gap = _seg_dist(ends, a[owner != k], b[owner != k]).min(axis=1)
            for e in np.flatnonzero(inside & (gap > mesh.snap)):
                out["dangling"].append((r.face, int(k), r.to3(ends[e]).tolist(), float(gap[e])))
        nb = len(np.concatenate(outline))
        crossed = []
        traces = r.events
        if max_traces is not None and len(traces) > max_traces:
            traces = traces[np.sort(rng.choice(len(traces), max_traces, replace=False))]
        for k in traces:
            rows = np.flatnonzero(owner == k)
            others = owner != k
            why, pick, fallback = "zero length", None, None
            for off in (margin, 0.25 * margin):  # a trace close to the outline: nearer
                q = _crossing_points(a[rows], b[rows], off)
                if not len(q):
                    break
                inside = _parity(q.reshape(-1, 2), outline).reshape(-1, 2).all(axis=1)
                near = _seg_dist(q.reshape(-1, 2), a[others], b[others]).min(axis=1).reshape(-1, 2).min(axis=1)
                good = inside & (near >= 0.5 * off)
                # preferably a pair crossing this trace alone: where lines meet at a small
                # angle, a pair far enough from the others can still straddle one of them
                alone = good & ~_straddles(q, a[others], b[others]).any(axis=1)
                if alone.any():
                    pick = q[np.argmax(alone)]
                    break
                if good.any() and fallback is None:
                    fallback = q[np.argmax(good)]
                why = "outside" if not inside.any() else "near another line"
            if pick is None:
                pick = fallback
            if pick is None:
                # a trace along the receiver's outline has no other side to cross to
                mid = 0.5 * (a[rows] + b[rows])
                if _seg_dist(mid, a[:nb], b[:nb]).min(axis=1).max() <= mesh.snap:
                    why = "on the outline"
                out["cross_skipped"].append((r.face, int(k), why))
                continue
            q = pick
            out["cross_pairs"] += 1
            reg = region_of(q)
            if reg[0] == reg[1]:
                out["cross_same_region"] += 1
            crossed.append((k, q))
        pieces = [q for _, q in sampled] + [q for _, q in crossed]
        labs = iter(labels_of(scene, setup, r.to3(np.concatenate(pieces)), r.face, cull=cull) if pieces else [])
        for j, q in sampled:
            out["regions_sampled"] += 1
            first = next(labs)
            for i in range(1, len(q)):
                out["same_pairs"] += 1
                other = next(labs)
                if other == first:
                    out["same_agree"] += 1
                else:
                    out["same_fail"].append((r.face, j, r.to3(q[0]).tolist(), r.to3(q[i]).tolist(), first ^ other))
        for k, q in crossed:
            if next(labs) != next(labs):
                out["cross_agree"] += 1
            else:
                out["cross_fail"].append((r.face, int(k), r.to3(q.mean(axis=0)).tolist()))
    return out
