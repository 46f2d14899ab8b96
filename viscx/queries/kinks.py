"""The lines of an emitter's plane across which a form-factor integrand has a kink (D1):
where, seen from the emitter's point x, two edges of the scene line up.

Why these lines
---------------
The matrix row of an emitter I integrates, for every receiver c, ``hidden_c(x)`` (what
the occluders hide of c from x; docs/queries.md, "The matrix row by row") and the sky
``1 − Σ_c F(x → visible c)``. Each is Lambert's contour sum over the visible parts seen
from x, which change combinatorially across the traces on I of visual events (the
discontinuity mesh of each receiver on I, Heckbert's D0/D1/D2). How the integrand
crosses such a trace depends on the sliver of image gained or lost there, at distance t
from the event plane:

* a vertex v's image crossing the image of an edge e (VE), v's own edges leaving v at
  finite angles to e: the sliver is a triangle of height ~t and width ~t, area ~t²: the
  integrand is C1 there (D2); likewise three edges' images meeting at a point (EEE);
* two edges a and e that lie in one plane Π (parallel, or on lines that meet): when x
  crosses Π the images of a and e pass over each other along their whole overlap: the
  sliver is a strip of width ~t, area ~t: a **kink** (D1; Heckbert's D1 events of
  parallel edges: a block's vertical edge lining up with a wall's). Two edges of one face
  are the case where Π is the face's plane: the face turns edge-on.

(D0, jumps, are the contact lines, where another face touches or crosses I:
:func:`viscx.queries.formfactor.contact_segments`.) A rule of degree 5 on a triangle a
kink line crosses has an error of the order of the slope jump × h³, and its estimate
from a finer level can miss a kink line that only clips a corner; on the triangles of a
cell that no D1 or D0 line crosses the integrands are C1, and the change of the rule
under subdivision is an honest error estimate (:class:`viscx.queries.formfactor.RowCubature`).

What is cut
-----------
For every pair of generator edges with a part in front of I (clipped to the front
half-space) whose lines lie in one plane Π (not I's plane, not one line), the line
L = Π ∩ plane(I), restricted to where the pair is an event: the points x of L from which
some line of Π through x meets both clipped edges (their images overlap). In Π's 2-D
coordinates (t along L, w ≥ 0 away from I) the ends of that set are where x is collinear
with an end of a and an end of b: L is cut at those (at most four) points and each piece
kept when, from its middle, the angular intervals of a and b overlap. Visibility is not
asked (an event hidden from I is cut too): more cells, never a kink inside one. The
events are found here and not from V1's arcs (:mod:`viscx.queries.discontinuities`)
because the integrands also kink where two *occluders'* edges line up (the sky column
behind the Cornell blocks, whose vertical edges line up with the walls'), which the
discontinuity mesh of a light leaves out, and because a row needs the D1 lines only
(its D2 traces would multiply the cells for nothing: the integrand is C1 across them).

But one bundle of D2 lines: where an edge touches the face at a point P (a jamb's edge at
a sill's corner), its VE lines all meet at P and the integrands are functions of the
direction from P alone there, the same picture at every size; a pair's cells are cut
along those (:func:`apex_segments`), so that every cell at P is a sector.
"""

import numpy as np
from numba import njit

from viscx.geometry.vec3 import axpy, cross, div, dot, row, set_row, sub


#: More generator segments in front of a face than this: no kink lines (None), the caller
#: keeps the cells without them. Their pairs are quadratic in number (10⁸ past 14,000), and
#: so many lines cut a face into far more than the cells a row is cut along
#: (:data:`viscx.queries.formfactor.MAX_KINK_CELLS`).
MAX_KINK_GENERATORS = 8_000
#: Pairs tested at once (memory linear in it).
PAIR_BLOCK = 1 << 19
#: The first block's pairs: the blocks double from it up to :data:`PAIR_BLOCK`, so that a
#: caller that only needs to know whether the lines are too many
#: (:func:`kink_segments`' ``past``) learns it from the first few.
FIRST_BLOCK = 1 << 15


def generator_segments(scene):
    """(g, 2, 3) float64: the ends of the scene's generator edges (cached)."""
    return scene.cached("generator_segments",
                        lambda s: s.vertices[s.half_edges.edge_vertices[s.generator_edges]].astype(np.float64))


def face_generators(scene, faces):
    """(k,) int64, sorted: the rows of :func:`generator_segments` that are edges of one of
    ``faces`` (k,) int64."""
    he = scene.half_edges
    edges = np.unique(he.edge[np.isin(he.face, np.asarray(faces, np.int64))])
    return np.flatnonzero(np.isin(scene.generator_edges, edges))


def sky_generators(scene, face):
    """(k,) int64, sorted: the rows of :func:`generator_segments` whose lines may make the
    kinks of the sky's integrand on either side of a face: every generator edge but those
    the sky is never seen beside from a point of the face.

    The sky column of a row (what x sees of no face) kinks where two edges a and b in one
    plane Π line up (module docstring): as x crosses Π the strip between their images,
    ~t wide, changes hands, and the sky's integrand kinks only if the sky owns the strip on
    one side of Π. The strip runs along both images, so the sky is then seen right beside
    a and beside b. An edge of exactly two faces f₁, f₂ has the sky beside it from no
    point x where the plane through x and the edge separates the two faces: then a ray
    from x passing just beside any interior point of the edge, on either side, meets f₁
    or f₂ there (or something nearer), never the sky. In the plane across the edge (u its
    direction, dᵢ the direction into fᵢ across it, mᵢ = dᵢ × u a normal of fᵢ) that is
    ((x − a) · m₁) ((x − a) · m₂) < 0: one sign for each, affine in x, so it holds on the
    whole face when it holds at its vertices (within 1e-9 of the scene's size: at most a
    sliver along the face's outline is left out), for both its sides (it asks where x is,
    not where it looks). The room's corners seen from inside
    (a concave dihedral) and a box's edges seen where both its faces face the point are
    such edges; a free edge (the open front of the Cornell box, a block's bottom) or one
    on an outline from some point of the side is kept. So the sky's kinks are among the
    pairs of the edges kept; :func:`viscx.queries.formfactor.cubature_cells` cuts a matrix
    row along these and its computed pairs' own (:func:`viscx.queries.formfactor.kink_faces`)."""
    he = scene.half_edges
    gen = scene.generator_edges
    count = np.bincount(he.edge, minlength=len(he.edge_vertices))[gen]
    two = np.flatnonzero(count == 2)
    if not len(two):
        return np.arange(len(gen), dtype=np.int64)
    order = np.argsort(he.edge, kind="stable")
    first = np.searchsorted(he.edge[order], gen[two])
    halves = np.stack([order[first], order[first + 1]], axis=1)  # (k, 2) the edge's two half-edges
    v = scene.vertices.astype(np.float64)
    a, b = v[he.edge_vertices[gen[two], 0]], v[he.edge_vertices[gen[two], 1]]
    u = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
    run = v[he.end[halves]] - v[he.start[halves]]  # (k, 2, 3) each half-edge's direction
    d = np.cross(scene.face_normal[he.face[halves]].astype(np.float64), run)  # into each face
    d /= np.linalg.norm(d, axis=2)[:, :, None]
    m = np.cross(d, u[:, None, :])  # (k, 2, 3)
    loops = np.concatenate(scene.face_loops(face))
    h = np.einsum("kid,pd->kip", m, loops) - np.einsum("kid,kd->ki", m, a)[:, :, None]  # (k, 2, p)
    tiny = 1e-9 * scene.diagonal
    split = ((h[:, 0].min(axis=1) >= -tiny) & (h[:, 1].max(axis=1) <= tiny)) | (
        (h[:, 0].max(axis=1) <= tiny) & (h[:, 1].min(axis=1) >= -tiny))
    keep = np.ones(len(gen), bool)
    keep[two[split]] = False
    return np.flatnonzero(keep).astype(np.int64)


def apex_segments(scene, face, side, generators, receivers):
    """The D2 lines of side ``side`` of a face that meet at an *apex*: a point P of the
    face (its closed outline) that a generator edge e with a part in front of the side
    touches or crosses (a jamb's edge at a window sill's corner, a box's edge on the floor).

    Seen from x near P, e's image tends to the great circle of the plane through e and the
    direction of x from P, so every integrand tends to a function g of that direction
    alone: it is homogeneous of degree 0 about P, and its events there are the lines through
    P where e lines up with a corner of what x sees (VE planes of e and a vertex v: D2
    away from P, all meeting at P). On a triangle with a vertex at P the picture is then the
    same at every size: a shadow wedge thinner than the angle between its nodes is missed by
    the triangle, its corner child and theirs (a sill's corner: the wall beside it hid the
    light from a wedge of 11–14° along the sill's edge, whose triangles, 6 times longer than
    wide, never had a node in it; a pair query was 2.7 times its estimate off at the default
    tol). Cut along these lines, every cell at P is a sector on which g is smooth.

    The vertices v taken: the ends in front of the side of the ``generators`` (k,) int64
    (rows of :func:`generator_segments`) that a receiver of ``receivers`` (r,) int64 is
    seen through from P (the ray from P through v meets the receiver at or past v: its own
    vertices and those of what may hide it; a corner of what is seen where an occluder's
    edge crosses a receiver's is left out). The line of (e, v) on the face is the half-line
    from P on the side of e away from v, up to where the segment from x to v passes e's far
    end (the shadow of that end: past it x sees v beside e, not across it).

    Returns
    -------
    (s, 2, 3) float64
        Segments from the apexes, in the face's plane.
    """
    generator = generator_segments(scene)[np.asarray(generators, np.int64)]
    n = side * scene.face_normal[face].astype(np.float64)
    c = float(n @ scene.face_loops(face)[0][0])
    tiny = 1e-9 * scene.diagonal
    height = generator @ n - c  # (g, 2)
    touch = np.flatnonzero((height.min(axis=1) <= tiny) & (height.max(axis=1) > tiny))
    if not len(touch):
        return np.zeros((0, 2, 3))
    seg, h = generator[touch], height[touch]
    top = np.argmax(h, axis=1)
    far_end = seg[np.arange(len(seg)), top]
    low, high = h.min(axis=1), h.max(axis=1)
    near_end = seg[np.arange(len(seg)), 1 - top]
    t = np.where(low >= -tiny, 0.0, -low / (high - low))
    apex = near_end + (far_end - near_end) * t[:, None]  # (t, 3) where e meets the face's plane
    keep = _on_face(scene, face, apex, 1e-8 * scene.diagonal)
    apex, far_end, high = apex[keep], far_end[keep], high[keep]
    v = np.unique(generator.reshape(-1, 3)[height.ravel() > tiny], axis=0)  # (m, 3) the ends in front
    if not len(apex) or not len(v):
        return np.zeros((0, 2, 3))
    seen = np.zeros((len(apex), len(v)), bool)
    for j in np.asarray(receivers, np.int64):
        seen |= _seen_through(scene, int(j), apex, v)
    a, k = np.nonzero(seen)  # the (apex, vertex) pairs whose lines are cut
    apex, far_end, high, v = apex[a], far_end[a], high[a], v[k]
    hv = v @ n - c
    # x on the face's plane in line with v and the point q of e at height min(h_top, h_v / 2):
    # on the (e, v) line, on the side of e away from v (q lies between x and v)
    hq = np.minimum(high, 0.5 * hv)
    q = apex + (far_end - apex) * (hq / high)[:, None]
    d = v + (q - v) * (hv / (hv - hq))[:, None] - apex
    length = np.linalg.norm(d, axis=1)
    # where x sees v past e's far end: the line from v through that end
    past = high < hv
    stop = v + (far_end - v) * (hv / np.where(past, hv - high, 1.0))[:, None]
    end = np.where(past[:, None], stop, apex + d * (2.0 * scene.diagonal / np.maximum(length, tiny))[:, None])
    ok = length > tiny
    return np.stack([apex[ok], end[ok]], axis=1)


def _on_face(scene, face, points, eps):
    """(p,) bool: the points (p, 3) (in the face's plane) within ``eps`` of the face's
    triangles (closed)."""
    tri = scene.vertices[scene.triangles[scene.triangle_face == face]].astype(np.float64)
    return np.any(_in_triangles(points, tri, eps), axis=1)


def _in_triangles(points, tri, eps):
    """(p, k) bool: whether each point (p, 3) lies in each triangle (k, 3, 3) (in its
    plane) up to ``eps``: on the inner side of every edge's line or within ``eps`` of it."""
    a, b = tri, np.roll(tri, -1, axis=1)  # (k, 3, 3) each edge
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    inward = np.cross(normal[:, None, :], b - a)  # (k, 3, 3)
    inward /= np.linalg.norm(inward, axis=2)[:, :, None]
    dist = np.einsum("ked,pd->pke", inward, points) - np.einsum("ked,ked->ke", inward, a)[None]
    return np.all(dist >= -eps, axis=2)


def _seen_through(scene, j, apex, v):
    """(t, m) bool: whether face j is met by the ray from each apex (t, 3) through each
    vertex v (m, 3) at or past v (within 1e-9 of the ray's length: its own vertices); by
    blocks of apexes (memory linear in the block: a floor's apexes × the ends in front)."""
    normal = scene.face_normal[j].astype(np.float64)
    c = float(normal @ scene.face_loops(j)[0][0])
    tri = scene.vertices[scene.triangles[scene.triangle_face == j]].astype(np.float64)
    out = np.zeros((len(apex), len(v)), bool)
    block = max(1, (1 << 18) // max(1, len(v) * len(tri)))
    for b in range(0, len(apex), block):
        p = apex[b:b + block]
        d = v[None] - p[:, None, :]  # (t, m, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (c - p @ normal)[:, None] / (d @ normal)
        hit = np.isfinite(s) & (s >= 1 - 1e-9)
        if np.any(hit):
            where = (p[:, None, :] + d * np.where(hit, s, 0.0)[:, :, None])[hit]
            hit[hit] = np.any(_in_triangles(where, tri, 1e-8 * scene.diagonal), axis=1)
            out[b:b + block] = hit
    return out


def _angles(x, t, w):
    """Angles (k, 2) in [0, π] of the points (t, w) (k, 2) seen from (x, 0) of L (k,)."""
    return np.arctan2(w, t - x[:, None])


def kink_segments(scene, face, side, generators=None, past=None):
    """The D1 lines of side ``side`` of a face (module docstring): pieces of the lines where
    the plane of two coplanar edges in front of the side crosses its plane, where the two
    edges line up seen from the point. ``generators``: only the pairs of these rows of
    :func:`generator_segments` (k,) int64 (default all): an integrand whose kernel sees
    only some faces (a pair's receiver and the occluders in its shaft) kinks only where
    two of their edges line up.

    ``past(segments (s, 2, 3)) -> bool``: whether these lines are already too many for the
    caller (:func:`viscx.queries.formfactor.emitter_cells`: they cut the face into more
    cells than its limit), asked of the lines of the pairs listed so far each time their
    number has doubled; True gives None at once. Lines are only added as pairs are: in a
    furnished room a box side's pairs are a million, their lines 10⁵, and the first
    :data:`FIRST_BLOCK` pairs' lines are already past the row's limit (office(1000): 1–3
    CPU s a row saved; a row whose lines are few lists them all, and gets the same ones).

    Returns
    -------
    (s, 2, 3) float64 or None
        Segments in the face's plane (their ends at most twice the scene's diagonal from
        the face: a piece running to infinity is cut there); None past
        :data:`MAX_KINK_GENERATORS` segments in front of the side, or when ``past`` says so.
    """
    seg = generator_segments(scene)
    if generators is not None:
        seg = seg[np.asarray(generators, np.int64)]
    n = side * scene.face_normal[face]
    c = float(n @ scene.face_loops(face)[0][0])
    tiny = 1e-9 * scene.diagonal
    h = seg @ n - c  # (g, 2) heights of the ends
    keep = np.flatnonzero(h.max(axis=1) > tiny)
    if len(keep) > MAX_KINK_GENERATORS:
        return None
    p, h = seg[keep], h[keep]
    # clip to the closed front half-space
    lo, hi = h[:, 0], h[:, 1]
    cut0, cut1 = lo < 0, hi < 0
    q = p.copy()
    q[cut0, 0] = p[cut0, 0] + (p[cut0, 1] - p[cut0, 0]) * (lo[cut0] / (lo[cut0] - hi[cut0]))[:, None]
    q[cut1, 1] = p[cut1, 1] + (p[cut1, 0] - p[cut1, 1]) * (hi[cut1] / (hi[cut1] - lo[cut1]))[:, None]
    d = p[:, 1] - p[:, 0]
    u = d / np.linalg.norm(d, axis=1)[:, None]
    centre = np.mean(scene.face_loops(face)[0], axis=0)
    starts, ends = [np.zeros((0, 3))], [np.zeros((0, 3))]
    done, asked = 0, 0
    total = len(p) * (len(p) - 1) // 2
    far = 2.0 * scene.diagonal
    for a0, a1 in _row_blocks(len(p), PAIR_BLOCK, FIRST_BLOCK):
        s0, s1 = _pair_kinks(n, c, tiny, p, q, u, centre, far, a0, a1)
        starts.append(s0)
        ends.append(s1)
        done += (a1 - a0) * (2 * len(p) - a0 - a1 - 1) // 2
        if past is not None and done < total and done >= 2 * asked:
            asked = done
            if past(merge_collinear(np.concatenate(starts), np.concatenate(ends), centre, scene.diagonal)):
                return None
    return merge_collinear(np.concatenate(starts), np.concatenate(ends), centre, scene.diagonal)


def load_kink_kernels():
    """Load (or compile) this module's numba kernels with the types :func:`kink_segments`
    calls them with, on nothing (a matrix's parent before it forks: once, not once in each
    worker; ~0.07 CPU s a process)."""
    none = np.zeros((0, 2, 3))
    _pair_kinks(np.array([0.0, 0.0, 1.0]), 0.0, 1.0, none, none, np.zeros((0, 3)), np.zeros(3), 1.0, 0, 0)
    merge_collinear(np.zeros((1, 3)), np.ones((1, 3)), np.zeros(3), 1.0)


def _row_blocks(g, size, first=None):
    """The pairs a < b of ``g`` segments as blocks ``(a0, a1)`` of whole rows a in
    [a0, a1) (each with its pairs b > a), of about ``size`` pairs, so that memory stays
    linear in the block, not quadratic in g; with ``first``, the blocks start at about that
    many pairs and double up to ``size``."""
    a0 = 0
    block = size if first is None else min(first, size)
    while a0 < g - 1:
        a1 = a0 + 1
        count = g - 1 - a0
        while a1 < g - 1 and count + (g - 1 - a1) <= block:
            count += g - 1 - a1
            a1 += 1
        yield a0, a1
        a0 = a1
        block = min(2 * block, size)


def _pair_kinks(n, c, tiny, p, q, u, centre, far, a0, a1):
    """The pieces ``(starts, ends)`` (s, 3) float64 each of the D1 lines of the segment
    pairs (a, b), a in [a0, a1) and b > a (:func:`kink_segments`; ``p`` (g, 2, 3) the
    segments, ``q`` them clipped to the front half-space, ``u`` (g, 3) their directions;
    ``centre`` (3,) the face's, ``far`` how far along L from it a piece may run)."""
    return _pair_kinks_compiled(np.asarray(n, np.float64), float(c), float(tiny), p, q, u, np.asarray(centre, np.float64),
                                float(far), int(a0), int(a1))


@njit(cache=True, nogil=True)
def _pair_kinks_compiled(n, c, tiny, p, q, u, centre, far, a0, a1):
    g = len(p)
    cap = 1024
    starts = np.empty((cap, 3))
    ends = np.empty((cap, 3))
    k = 0
    t = np.empty((2, 2))
    w = np.empty((2, 2))
    grid = np.empty(6)
    nv = (n[0], n[1], n[2])
    for a in range(a0, a1):
        pa, ua = _end(p, a, 0), row(u, a)
        for b in range(a + 1, g):
            # the plane Π of the two (unclipped) lines: normal ua × ub, or ua × (pb − pa)
            # when they are parallel
            w0, w1 = sub(_end(p, b, 0), pa), sub(_end(p, b, 1), pa)
            m = cross(ua, row(u, b))
            if np.sqrt(dot(m, m)) < 1e-9:
                m = cross(ua, w0)
            mn = np.sqrt(dot(m, m))
            if not mn > tiny:
                continue
            m = div(m, mn)
            if abs(dot(w0, m)) > tiny or abs(dot(w1, m)) > tiny:
                continue  # not in one plane
            dl = cross(m, nv)  # L's direction
            dn = np.sqrt(dot(dl, dl))
            if not dn > 1e-9:
                continue  # Π is I's plane, or parallel to it
            dl = div(dl, dn)
            up = cross(m, dl)  # in Π, across L, pointing away from I (up · n > 0)
            sg = np.sign(dot(up, nv))
            up = (up[0] * sg, up[1] * sg, up[2] * sg)
            s = dot(up, nv)  # sin of the angle between Π and I's plane
            # 2-D coordinates in Π: t = y · dl, w = height / s
            for x in range(2):
                e = a if x == 0 else b
                for y in range(2):
                    end = _end(q, e, y)
                    t[x, y] = dot(end, dl)
                    w[x, y] = max(dot(end, nv) - c, 0.0) / s
            # o: the point of L with o · dl = 0
            o = axpy(axpy(_end(q, a, 0), -t[0, 0], dl), -w[0, 0], up)
            # breakpoints: L ∩ the line through an end of a and an end of b, clipped to
            # far before and after the face's centre along L (NaN: none)
            ref = dot(centre, dl)
            lo, hi = ref - far, ref + far
            grid[0] = lo
            for i in range(2):
                for j in range(2):
                    dw = w[1, j] - w[0, i]
                    v = t[0, i] - w[0, i] * (t[1, j] - t[0, i]) / dw if abs(dw) > tiny else np.nan
                    grid[1 + 2 * i + j] = min(max(v, lo), hi) if v == v else np.nan
            grid[5] = hi
            # sorted, the NaNs last and then the far end: no piece
            for i in range(1, 6):
                v = grid[i]
                j = i
                while j > 0 and (grid[j - 1] != grid[j - 1] or (v == v and grid[j - 1] > v)):
                    grid[j] = grid[j - 1]
                    j -= 1
                grid[j] = v
            for i in range(6):
                if grid[i] != grid[i]:
                    grid[i] = hi
            for j in range(5):
                t0, t1 = grid[j], grid[j + 1]
                if not t1 - t0 > tiny:
                    continue
                mid = 0.5 * (t0 + t1)
                # each piece kept where, from its middle, the angular intervals of a and b overlap
                p0, p1 = np.arctan2(w[0, 0], t[0, 0] - mid), np.arctan2(w[0, 1], t[0, 1] - mid)
                r0, r1 = np.arctan2(w[1, 0], t[1, 0] - mid), np.arctan2(w[1, 1], t[1, 1] - mid)
                if not min(max(p0, p1), max(r0, r1)) - max(min(p0, p1), min(r0, r1)) > 1e-12:
                    continue
                if k == cap:
                    cap *= 2
                    starts = _grown(starts, cap)
                    ends = _grown(ends, cap)
                set_row(starts, k, axpy(o, t0, dl))
                set_row(ends, k, axpy(o, t1, dl))
                k += 1
    return starts[:k].copy(), ends[:k].copy()


@njit(cache=True, nogil=True)
def _end(seg, i, j):
    """End j of segment i of ``seg`` (k, 2, 3) as a tuple."""
    return (seg[i, j, 0], seg[i, j, 1], seg[i, j, 2])


@njit(cache=True, nogil=True)
def _grown(x, cap):
    out = np.empty((cap, x.shape[1]))
    out[:len(x)] = x
    return out


def merge_collinear(a, b, centre, scale):
    """Segments a → b ((k, 3) each) merged where they lie on one line (direction and
    position equal to 1e-9 of ``scale``) and overlap: the union of the pieces of each line
    (many edge pairs span one plane: the edges of one face, parallel edges of one box).

    Returns
    -------
    (s, 2, 3) float64
        The lines in the order of their keys (direction, then foot, rounded), each line's
        pieces in order along it.
    """
    if not len(a):
        return np.zeros((0, 2, 3))
    a, b = np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64)
    d, foot, key, t0, t1 = _line_keys(a, b, np.asarray(centre, np.float64), float(scale))
    line, first = _line_ids(key)
    rank = np.empty(len(first), np.int64)
    rank[np.lexsort(key[first].T[::-1])] = np.arange(len(first))
    return _merged_runs(rank[line], len(first), d, foot, t0, t1, 1e-9 * scale)


@njit(cache=True, nogil=True)
def _line_keys(a, b, centre, scale):
    """Each segment's line: its direction d (the first non-zero coordinate positive), its
    point nearest ``centre`` (the foot), the two rounded to 1e-9 (of ``scale``) as the
    line's key (k, 6) int64, and the segment's span t0 ≤ t1 along d from the foot."""
    k = len(a)
    d = np.empty((k, 3))
    foot = np.empty((k, 3))
    key = np.empty((k, 6), np.int64)
    t0 = np.empty(k)
    t1 = np.empty(k)
    for i in range(k):
        for j in range(3):
            d[i, j] = b[i, j] - a[i, j]
        norm = np.sqrt(d[i, 0] * d[i, 0] + d[i, 1] * d[i, 1] + d[i, 2] * d[i, 2])
        first = 0
        for j in range(3):
            d[i, j] /= norm
        for j in range(3):
            if abs(d[i, j]) > 1e-12:
                first = j
                break
        sg = np.sign(d[i, first])
        for j in range(3):
            d[i, j] *= sg
        s = (centre[0] - a[i, 0]) * d[i, 0] + (centre[1] - a[i, 1]) * d[i, 1] + (centre[2] - a[i, 2]) * d[i, 2]
        for j in range(3):
            foot[i, j] = a[i, j] + s * d[i, j]
            key[i, j] = np.int64(np.rint(d[i, j] * 1e9))
            key[i, 3 + j] = np.int64(np.rint((foot[i, j] - centre[j]) / scale * 1e9))
        ta = (a[i, 0] - foot[i, 0]) * d[i, 0] + (a[i, 1] - foot[i, 1]) * d[i, 1] + (a[i, 2] - foot[i, 2]) * d[i, 2]
        tb = (b[i, 0] - foot[i, 0]) * d[i, 0] + (b[i, 1] - foot[i, 1]) * d[i, 1] + (b[i, 2] - foot[i, 2]) * d[i, 2]
        t0[i] = min(ta, tb)
        t1[i] = max(ta, tb)
    return d, foot, key, t0, t1


@njit(cache=True, nogil=True)
def _line_ids(key):
    """Equal rows of ``key`` (k, 6) int64 as one line: each row's line (k,) int64, numbered
    in order of first appearance, and the first row of each (L,) int64 (a hash table)."""
    k = len(key)
    size = 1
    while size < 2 * k:
        size *= 2
    table = np.full(size, -1, np.int64)
    line = np.empty(k, np.int64)
    first = np.empty(k, np.int64)
    n = 0
    for i in range(k):
        h = np.uint64(1469598103934665603)
        for j in range(6):
            h = (h ^ np.uint64(key[i, j])) * np.uint64(1099511628211)
        slot = np.int64(h >> np.uint64(16)) & (size - 1)
        while True:
            r = table[slot]
            if r < 0:
                table[slot] = n
                first[n] = i
                line[i] = n
                n += 1
                break
            f = first[r]
            same = True
            for j in range(6):
                if key[f, j] != key[i, j]:
                    same = False
                    break
            if same:
                line[i] = r
                break
            slot = (slot + 1) & (size - 1)
    return line, first[:n].copy()


@njit(cache=True, nogil=True)
def _merged_runs(line, lines, d, foot, t0, t1, gap):
    """The union of each line's pieces (:func:`merge_collinear`): the pieces grouped by
    ``line`` (k,) int64 in [0, lines) in that order, along each line by t0 (ties in input
    order); a piece starts a new run where it begins more than ``gap`` past the run's end
    so far. Each run is ``foot + [t0, max t1] d`` of its first piece."""
    k = len(line)
    count = np.zeros(lines + 1, np.int64)
    for i in range(k):
        count[line[i] + 1] += 1
    for r in range(lines):
        count[r + 1] += count[r]
    order = np.empty(k, np.int64)
    fill = count[:-1].copy()
    for i in range(k):
        order[fill[line[i]]] = i
        fill[line[i]] += 1
    out = np.empty((k, 2, 3))
    m = 0
    for r in range(lines):
        # along t0, ties in input order (most lines have few pieces: insertion sort)
        if count[r + 1] - count[r] > 16:
            mine = order[count[r]:count[r + 1]]
            order[count[r]:count[r + 1]] = mine[np.argsort(t0[mine], kind="mergesort")]
        else:
            for x in range(count[r] + 1, count[r + 1]):
                i = order[x]
                y = x
                while y > count[r] and t0[order[y - 1]] > t0[i]:
                    order[y] = order[y - 1]
                    y -= 1
                order[y] = i
        i = order[count[r]]
        lo, hi = t0[i], t1[i]
        for x in range(count[r] + 1, count[r + 1] + 1):
            if x < count[r + 1] and not t0[order[x]] > hi + gap:
                hi = max(hi, t1[order[x]])
                continue
            for j in range(3):
                out[m, 0, j] = foot[i, j] + lo * d[i, j]
                out[m, 1, j] = foot[i, j] + hi * d[i, j]
            m += 1
            if x < count[r + 1]:
                i = order[x]
                lo, hi = t0[i], t1[i]
    return out[:m].copy()
