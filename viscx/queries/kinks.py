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
"""

import numpy as np

from viscx.arrays import unique_rows


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
    for a, b in _pair_blocks(len(p), PAIR_BLOCK, FIRST_BLOCK):
        s0, s1 = _pair_kinks(scene, face, n, c, tiny, p, q, u, a, b)
        starts.append(s0)
        ends.append(s1)
        done += len(a)
        if past is not None and done < total and done >= 2 * asked:
            asked = done
            if past(merge_collinear(np.concatenate(starts), np.concatenate(ends), centre, scene.diagonal)):
                return None
    return merge_collinear(np.concatenate(starts), np.concatenate(ends), centre, scene.diagonal)


def _pair_blocks(g, size, first=None):
    """The pairs a < b of ``g`` segments as ``(a, b)`` (k,) int64 blocks of about ``size``
    pairs (whole rows a), so that memory stays linear in the block, not quadratic in g;
    with ``first``, the blocks start at about that many pairs and double up to ``size``."""
    a0 = 0
    block = size if first is None else min(first, size)
    while a0 < g - 1:
        a1 = a0 + 1
        count = g - 1 - a0
        while a1 < g - 1 and count + (g - 1 - a1) <= block:
            count += g - 1 - a1
            a1 += 1
        a = np.repeat(np.arange(a0, a1), g - 1 - np.arange(a0, a1))
        b = np.concatenate([np.arange(i + 1, g) for i in range(a0, a1)])
        yield a, b
        a0 = a1
        block = min(2 * block, size)


def _pair_kinks(scene, face, n, c, tiny, p, q, u, a, b):
    """The pieces ``(starts, ends)`` (s, 3) float64 each of the D1 lines of the segment
    pairs ``(a[i], b[i])`` (:func:`kink_segments`; ``p`` the segments, ``q`` them clipped to
    the front half-space, ``u`` their directions)."""
    # the plane of the two (unclipped) lines: normal ua × ub, or ua × (pb − pa) when parallel
    w0 = p[b, 0] - p[a, 0]
    m = np.cross(u[a], u[b])
    par = np.linalg.norm(m, axis=1) < 1e-9
    m[par] = np.cross(u[a[par]], w0[par])
    mn = np.linalg.norm(m, axis=1)
    ok = mn > tiny
    m[ok] /= mn[ok, None]
    ok &= np.abs(np.einsum("ij,ij->i", w0, m)) <= tiny
    ok &= np.abs(np.einsum("ij,ij->i", p[b, 1] - p[a, 0], m)) <= tiny
    dl = np.cross(m, n)  # L's direction
    dn = np.linalg.norm(dl, axis=1)
    ok &= dn > 1e-9  # Π is not I's plane (nor parallel to it)
    a, b, m, dl = a[ok], b[ok], m[ok], dl[ok] / dn[ok, None]
    if not len(a):
        return np.zeros((0, 3)), np.zeros((0, 3))
    up = np.cross(m, dl)  # in Π, across L, pointing away from I (up · n > 0)
    up *= np.sign(np.einsum("ij,j->i", up, n))[:, None]
    s = np.einsum("ij,j->i", up, n)  # sin of the angle between Π and I's plane
    # 2-D coordinates in Π: t = y · dl, w = height / s (the origin o on L with o · dl = 0)
    ends = np.stack([q[a], q[b]], axis=1)  # (k, 2 edges, 2 ends, 3)
    t = np.einsum("kxyd,kd->kxy", ends, dl)
    w = np.maximum(np.einsum("kxyd,d->kxy", ends, n) - c, 0.0) / s[:, None, None]
    # o: the point of L with o · dl = 0 (pa = o + t dl + w up for a's first end pa)
    pa = ends[:, 0, 0]
    o = pa - t[:, 0, 0, None] * dl - w[:, 0, 0, None] * up
    # breakpoints: L ∩ the line through an end of a and an end of b
    ta, wa = t[:, 0][:, :, None], w[:, 0][:, :, None]
    tb, wb = t[:, 1][:, None, :], w[:, 1][:, None, :]
    dw = wb - wa
    with np.errstate(divide="ignore", invalid="ignore"):
        br = np.where(np.abs(dw) > tiny, ta - wa * (tb - ta) / dw, np.nan).reshape(-1, 4)
    # pieces of L between the breakpoints, from far before to far after the face
    ref = np.mean(scene.face_loops(face)[0], axis=0) @ dl.T  # (k,) the face's centre along L
    far = 2.0 * scene.diagonal
    br = np.clip(br, (ref - far)[:, None], (ref + far)[:, None])
    grid = np.sort(np.concatenate([(ref - far)[:, None], br, (ref + far)[:, None]], axis=1), axis=1)
    grid = np.where(np.isnan(grid), (ref + far)[:, None], grid)  # NaNs sort last: no piece
    t0, t1 = grid[:, :-1], grid[:, 1:]
    mid = 0.5 * (t0 + t1)  # (k, 5)
    ang_a = np.sort(np.arctan2(w[:, 0][:, None, :], t[:, 0][:, None, :] - mid[:, :, None]), axis=2)
    ang_b = np.sort(np.arctan2(w[:, 1][:, None, :], t[:, 1][:, None, :] - mid[:, :, None]), axis=2)
    overlap = np.minimum(ang_a[..., 1], ang_b[..., 1]) - np.maximum(ang_a[..., 0], ang_b[..., 0])
    live = (overlap > 1e-12) & (t1 - t0 > tiny)
    k, j = np.nonzero(live)
    return o[k] + t0[k, j, None] * dl[k], o[k] + t1[k, j, None] * dl[k]


def merge_collinear(a, b, centre, scale):
    """Segments a → b ((k, 3) each) merged where they lie on one line (direction and
    position equal to 1e-9 of ``scale``) and overlap: the union of the pieces of each line
    (many edge pairs span one plane: the edges of one face, parallel edges of one box).

    Returns
    -------
    (s, 2, 3) float64
    """
    if not len(a):
        return np.zeros((0, 2, 3))
    d = b - a
    d /= np.linalg.norm(d, axis=1)[:, None]
    # one direction per line: the first non-zero coordinate positive
    first = np.argmax(np.abs(d) > 1e-12, axis=1)
    d *= np.sign(d[np.arange(len(d)), first])[:, None]
    foot = a + np.einsum("kj,kj->k", centre - a, d)[:, None] * d  # the line's point nearest the centre
    key = np.round(np.concatenate([d, (foot - centre) / scale], axis=1) * 1e9).astype(np.int64)
    _, line = unique_rows(key)
    ta, tb = np.einsum("kj,kj->k", a - foot, d), np.einsum("kj,kj->k", b - foot, d)
    t0, t1 = np.minimum(ta, tb), np.maximum(ta, tb)
    order = np.lexsort((t0, line))
    line, t0, t1, d, foot = line[order], t0[order], t1[order], d[order], foot[order]
    # a piece starts a new run where its line changes or it begins past the run's end so far
    big = 4.0 * (np.abs(t1).max() + np.abs(t0).max() + 1.0)
    reach = np.maximum.accumulate(t1 + big * line)  # the running end within each line
    start = np.ones(len(t0), bool)
    start[1:] = (line[1:] != line[:-1]) | (t0[1:] + big * line[1:] > reach[:-1] + 1e-9 * scale)
    lo = t0[start]
    hi = np.maximum.reduceat(t1, np.flatnonzero(start))
    d, foot = d[start], foot[start]
    return np.stack([foot + lo[:, None] * d, foot + hi[:, None] * d], axis=1)
