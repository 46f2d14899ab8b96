"""Form factors from a viscx file: point to face (exact, seed 000 §7.4), face to face with
occlusion (quadrature with an error estimate), groups, and the sparse matrix of a scene.

Sides
-----
Faces are two-sided blockers, so a form factor is between *sides*: ``F[(i, s), (j, t)]``
is the fraction of the energy leaving side s of face i (cosine-weighted about that side's
normal, ``s * face_normal[i]`` with s = +1 front, -1 back) that first arrives on side t of
face j. With sides, reciprocity ``A_i F[(i,s),(j,t)] = A_j F[(j,t),(i,s)]`` holds exactly and
every side's row sums to 1 with its sky term (what leaves the scene). A face "to face j"
(``--to-face``) counts both sides of j.

Point to face
-------------
The visible part of face j from the point, from the point's V-cells (the file's, or
computed on demand: :func:`viscx.queries.visibility.view_from`), clipped to the point's
front hemisphere, then Lambert's contour formula over its loops (outer loops and holes):
exact up to float64.

Face to face
------------
``A_i F_ij = ∫_{x ∈ I} F(x → part of J visible from x) dx``. First the pair is reduced to
what can matter: I clipped to the half-space on side t of J's plane (I', the points that
see that side), J clipped to the front half-space of side s of I (J'), and the occluders:
every other face, clipped to both half-spaces, that meets the interior of the convex hull
of I' ∪ J' (separating-axis test; a face only touching the hull blocks no segment from I'
to J'). No occluder: the exact double contour integral of unoccluded polygons
(:func:`viscx.geometry.formfactor.polygon_to_polygon`). Otherwise: iterated adaptive
Gauss–Kronrod quadrature over I':

* the integrand at x is exact: the visible part of J' from x by polygon clipping against
  the occluders' central projections (:func:`viscx.geometry.occlusion.visible_form_factors`,
  a from-point hidden-surface computation, checked against the V-cells on samples), then
  Lambert;
* lines of I' (its 2-D basis' first axis): each line is cut at its *events*, the
  parameters where the visible part's combinatorial structure changes (VE and EEE
  events, crossings of occluder planes: :func:`viscx.geometry.occlusion.line_events`), so
  the integrand is analytic on every piece; each piece gets a 7/15-point Gauss–Kronrod
  pair, bisected while |K15 − G7| exceeds its share of the tolerance;
* across the lines (their offset y), the same pair on intervals cut at the vertices of I',
  bisected likewise.

The reported ``error`` is the sum of |K15 − G7| over the accepted outer intervals plus the
inner estimates carried through the outer weights: an estimate of the error of the 7-point
rule, so conservative for the 15-point values that are returned.
"""

import functools
import itertools
import time
from dataclasses import dataclass

import numpy as np

from viscx.errors import ViscxError
from viscx.geometry.formfactor import clip_to_hemisphere, point_to_polygon, polygon_to_polygon
from viscx.geometry.occlusion import line_events, visible_form_factors
from viscx.geometry.polygon import newell_normal, plane_basis

#: Default target on the absolute error of one form factor (a pair, a group) ...
DEFAULT_TOL = 1e-8
#: ... and of each entry of the matrix.
MATRIX_TOL = 1e-7

# Gauss–Kronrod 7/15 (QUADPACK qk15): nodes on [-1, 1], Kronrod and Gauss weights
_XGK = np.array([0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
                 0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
                 0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
                 0.207784955007898467600689403773245, 0.0])
_WGK = np.array([0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
                 0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
                 0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
                 0.204432940075298892414161999234649, 0.209482141084727828012999174891714])
_WG = np.array([0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
                0.381830050505118944950369775488975, 0.417959183673469387755102040816327])
GK_X = np.concatenate([-_XGK[:-1], _XGK[::-1]])  # 15 nodes, ascending
GK_WK = np.concatenate([_WGK[:-1], _WGK[::-1]])
GK_WG = np.zeros(15)
GK_WG[[1, 3, 5]] = _WG[:3]
GK_WG[[13, 11, 9]] = _WG[:3]
GK_WG[7] = _WG[3]

#: Rotation of J's 2-D basis (radians), away from any axis a modeller would use.
GENERIC_ANGLE = 0.5873926
#: Rotation of the receiver's lines (radians).
GENERIC_ANGLE_I = 0.3217505
#: The outer intervals start no longer than this fraction of the receiver's extent.
MIN_SPLIT = 8

#: Bisection depth limits (outer, inner); a piece at the limit is accepted with its estimate.
MAX_DEPTH = (40, 40)


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def oriented_loops(loops, normal):
    """Loops with the outer (first) counter-clockwise about ``normal`` and holes clockwise."""
    out = []
    for k, loop in enumerate(loops):
        loop = np.asarray(loop, dtype=np.float64)
        if (newell_normal(loop) @ normal > 0) != (k == 0):
            loop = loop[::-1]
        out.append(loop)
    return out


def clip_loops(loops, normal, offset):
    """The loops' parts with ``normal · y >= offset`` (Sutherland–Hodgman per loop; holes
    stay holes, degenerate bridges along the cut cancel in every contour or winding sum)."""
    point = np.asarray(normal) * offset
    out = []
    for k, loop in enumerate(loops):
        part = clip_to_hemisphere(loop, point, normal)
        if len(part) >= 3:
            out.append(part)
        elif k == 0:
            return []
    return out


def loops_area(loops, normal):
    """Signed area about ``normal`` (outer counter-clockwise positive, holes negative)."""
    return 0.5 * float(sum(newell_normal(loop) @ normal for loop in loops)) if loops else 0.0


@dataclass
class Target:
    """A polygon to receive: a face or a virtual polygon (the sky's box faces).

    Attributes
    ----------
    loops : list of (k, 3) float64
        Outer loop first, then holes.
    normal : (3,) float64
        Its geometric normal (side +1).
    face : int
        Face id, -1 for a virtual polygon (no face is excluded from its occluders).
    """

    loops: list
    normal: np.ndarray
    face: int = -1


def face_target(scene, face):
    return Target(scene.face_loops(face), scene.face_normal[face].copy(), int(face))


def sky_targets(scene):
    """The six faces of the scene's bounding box enlarged by 5 % of its diagonal, normals
    inwards: every ray that meets no face leaves through exactly one of them, so the form
    factor to them is the sky term (a virtual closed box; they block nothing)."""
    lo, hi = scene.bbox
    m = 0.05 * scene.diagonal
    lo, hi = lo - m, hi + m
    out = []
    for axis in range(3):
        for sign, plane in ((1.0, lo[axis]), (-1.0, hi[axis])):
            a, b = (axis + 1) % 3, (axis + 2) % 3
            quad = np.zeros((4, 3))
            quad[:, axis] = plane
            quad[:, a] = [lo[a], hi[a], hi[a], lo[a]]
            quad[:, b] = [lo[b], lo[b], hi[b], hi[b]]
            n = np.zeros(3)
            n[axis] = sign
            out.append(Target(oriented_loops([quad], n), n, -1))
    return out


# --------------------------------------------------------------------------------------
# occluders of a pair


def _separated(hull_pts, hull_edges, hull_normals, poly, poly_normal, tol):
    """Separating-axis test of a convex polytope (points, edges, facet normals) and the
    convex hull of a planar polygon; touching (overlap below tol) counts as separated."""
    pe = np.roll(poly, -1, axis=0) - poly
    axes = [hull_normals, poly_normal[None], np.cross(poly_normal[None], pe)]
    cross = np.cross(hull_edges[:, None, :], pe[None, :, :]).reshape(-1, 3)
    axes.append(cross)
    axes = np.concatenate(axes)
    size = np.linalg.norm(axes, axis=1)
    keep = size > 1e-12 * size.max()
    axes = axes[keep] / size[keep, None]
    pa = hull_pts @ axes.T
    pb = poly @ axes.T
    return bool(np.any((pb.max(axis=0) <= pa.min(axis=0) + tol) | (pa.max(axis=0) <= pb.min(axis=0) + tol)))


def shaft_occluders(pts, occluders, tol):
    """The occluders that meet the interior of the convex hull of ``pts`` (the shaft of
    every segment between two point sets whose hull points these are).

    Parameters
    ----------
    pts : (k, 3) float64
    occluders : list of (loops, normal)
        Planar polygons, outer loop first.
    tol : float
        Overlap below which a polygon only touching the hull is left out.

    Returns
    -------
    list of (loops, normal)
        The ones kept, in their order; ``[]`` when the hull is flat (nothing passes).
    """
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError):
        return []  # flat: the two sets are coplanar, nothing passes between them
    simp = hull.simplices
    edges = np.concatenate([pts[simp[:, 1]] - pts[simp[:, 0]], pts[simp[:, 2]] - pts[simp[:, 1]], pts[simp[:, 0]] - pts[simp[:, 2]]])
    hnormals = hull.equations[:, :3]
    hp = pts[hull.vertices]
    lo, hi = hp.min(axis=0) - tol, hp.max(axis=0) + tol
    out = []
    for loops, nk in occluders:
        outer = loops[0]
        if np.any(outer.min(axis=0) > hi) or np.any(outer.max(axis=0) < lo):
            continue
        if not _separated(hp, edges, hnormals, outer, nk, tol):
            out.append((loops, nk))
    return out


def face_boxes(scene):
    """Bounding boxes of the faces' outer loops, ``(lo, hi)`` (f, 3) float64 each (cached)."""
    cached = getattr(scene, "_viscx_face_boxes", None)
    if cached is None:
        start = scene.loop_offsets[scene.face_loop_offsets[:-1]]
        pts = scene.vertices[scene.loop_vertices]
        cached = (np.minimum.reduceat(pts, start, axis=0), np.maximum.reduceat(pts, start, axis=0))
        scene._viscx_face_boxes = cached
    return cached


def pair_occluders(scene, pts, n_i, c_i, n_t, c_t, exclude):
    """Faces that may block a segment from I' to J' (hull points ``pts``): clipped to the
    front of I and the receiving side of J, meeting the interior of the hull.

    Returns
    -------
    list of (loops, normal)
        Clipped loops (outer counter-clockwise about the face normal, holes clockwise).
    """
    tol = 1e-9 * scene.diagonal
    lo, hi = pts.min(axis=0) - tol, pts.max(axis=0) + tol
    box_lo, box_hi = face_boxes(scene)
    near = np.flatnonzero(np.all(box_lo <= hi, axis=1) & np.all(box_hi >= lo, axis=1))
    clipped = []
    for k in near:
        if k in exclude:
            continue
        nk = scene.face_normal[k]
        loops = clip_loops(clip_loops(oriented_loops(scene.face_loops(k), nk), n_i, c_i), n_t, c_t)
        if loops and abs(loops_area(loops, nk)) > tol * tol:
            clipped.append((loops, nk))
    return shaft_occluders(pts, clipped, tol)


# --------------------------------------------------------------------------------------
# one pair of sides


@dataclass
class PairResult:
    """F from side ``side_i`` of face i to side ``side_j`` of a target, with its error estimate."""

    F: float
    error: float
    method: str  # "none" (they cannot see each other), "contour" (unoccluded, exact), "quadrature"
    occluders: int = 0
    evaluations: int = 0
    lines: int = 0
    seconds: float = 0.0


class PairSetup:
    """Everything x-independent of a pair (I side s, J side t) for the quadrature."""

    def __init__(self, scene, face_i, side_i, target, side_t):
        self.scene = scene
        self.area_i = float(scene.face_area[face_i])
        n_i = side_i * scene.face_normal[face_i]
        loops_i = oriented_loops(scene.face_loops(face_i), n_i)
        c_i = float(n_i @ loops_i[0][0])
        n_t = side_t * np.asarray(target.normal, dtype=np.float64)
        loops_t = oriented_loops(target.loops, n_t)
        c_t = float(n_t @ loops_t[0][0])
        tiny = 1e-9 * scene.diagonal
        self.tiny = tiny
        self.n_i, self.c_i, self.n_t, self.c_t = n_i, c_i, n_t, c_t
        self.I = clip_loops(loops_i, n_t, c_t + tiny)
        self.J = clip_loops(loops_t, n_i, c_i)
        self.empty = (
            not self.I or not self.J
            or loops_area(self.I, n_i) <= tiny * tiny
            or loops_area(self.J, n_t) <= tiny * tiny
            or max(float(np.max(l @ n_i)) for l in self.J) - c_i <= tiny
            or max(float(np.max(l @ n_t)) for l in self.I) - c_t <= tiny
        )
        if self.empty:
            self.occluders = []
            return
        exclude = {face_i, target.face}
        pts = np.concatenate(self.I + self.J)
        self.occluders = pair_occluders(scene, pts, n_i, c_i, n_t, c_t, exclude)

    # -- the quadrature's data ----------------------------------------------------------
    @functools.cached_property
    def frame(self):
        """J' in a 2-D basis of its plane: ``(origin, eu, ev, j2, j_loop, hull2, hull3)``."""
        from scipy.spatial import ConvexHull

        eu, ev = plane_basis(self.n_t)
        # a generic rotation of the basis: no edge of an axis-aligned scene is vertical in
        # 2-D, so the slab sweep needs no vertical sides (viscx.geometry.occlusion)
        c, s_ = np.cos(GENERIC_ANGLE), np.sin(GENERIC_ANGLE)
        eu, ev = c * eu + s_ * ev, -s_ * eu + c * ev
        origin = self.J[0][0].copy()
        j2 = [np.stack([(l - origin) @ eu, (l - origin) @ ev], axis=1) for l in self.J]
        allj = np.ascontiguousarray(np.concatenate(j2))
        j_loop = np.concatenate([[0], np.cumsum([len(l) for l in j2])]).astype(np.int64)
        h = ConvexHull(allj).vertices  # counter-clockwise in 2-D
        return origin, eu, ev, allj, j_loop, np.ascontiguousarray(allj[h]), np.ascontiguousarray(np.concatenate(self.J)[h])

    def kernel_for(self, occluders):
        """The arrays of :func:`viscx.geometry.occlusion.visible_form_factors` with these
        occluders (the pair's, or a subset that is known to be enough for some points)."""
        origin, eu, ev, allj, j_loop, _, hull3 = self.frame
        occ, occ_loop, occ_poly, pn, pp = [], [0], [], [], []
        for k, (loops, nk) in enumerate(occluders):
            for loop in loops:
                occ.append(loop)
                occ_loop.append(occ_loop[-1] + len(loop))
                occ_poly.append(k)
            pn.append(nk)
            pp.append(loops[0][0])
        return dict(
            n_i=self.n_i, j2=allj, j_loop=j_loop, origin=origin, eu=eu, ev=ev, n_j=self.n_t, c_j=self.c_t, hull=hull3,
            occ=np.ascontiguousarray(np.concatenate(occ) if occ else np.zeros((0, 3))), occ_loop=np.asarray(occ_loop, np.int64),
            occ_poly=np.asarray(occ_poly, np.int64), poly_normal=np.asarray(pn, np.float64).reshape(-1, 3),
            poly_point=np.asarray(pp, np.float64).reshape(-1, 3), tiny=self.tiny,
        )

    def arrays(self):
        n_t = self.n_t
        origin, eu, ev, _, _, hull2, _ = self.frame
        self.kernel = self.kernel_for(self.occluders)
        # features for the events: vertices and (deduplicated) edges, labelled by polygon
        vert, vlab, ea, eb, elab = [], [], [], [], []
        seen = set()
        q = 1e-7 * self.scene.diagonal

        def add(loop, label):
            for a, b in zip(loop, np.roll(loop, -1, axis=0)):
                ka, kb = tuple(np.round(a / q).astype(np.int64)), tuple(np.round(b / q).astype(np.int64))
                if ka == kb:
                    continue
                key = (min(ka, kb), max(ka, kb))
                if key not in seen:
                    seen.add(key)
                    ea.append(a)
                    eb.append(b)
                    elab.append(label)
                if ka not in seen:
                    seen.add(ka)
                    vert.append(a)
                    vlab.append(label)

        for loop in self.J:
            add(loop, 0)
        for k, (loops, _) in enumerate(self.occluders):
            for loop in loops:
                add(loop, k + 1)
        ea, eb, elab = np.asarray(ea).reshape(-1, 3), np.asarray(eb).reshape(-1, 3), np.asarray(elab, np.int64)
        ne = len(ea)
        tri = np.array(list(itertools.combinations(range(ne), 3)), np.int64).reshape(-1, 3)
        if len(tri):
            # no two J edges (coplanar: their transversals cross J's plane at one point), no shared endpoints
            j_count = (elab[tri] == 0).sum(axis=1)
            ends = np.stack([ea, eb], axis=1)  # (ne, 2, 3)
            keep = j_count <= 1
            for p, r in ((0, 1), (0, 2), (1, 2)):
                d = np.linalg.norm(ends[tri[:, p]][:, :, None, :] - ends[tri[:, r]][:, None, :, :], axis=3)
                keep &= d.min(axis=(1, 2)) > q
            tri = tri[keep]
        self.events = dict(
            vert=np.asarray(vert), vert_poly=np.asarray(vlab, np.int64), edge_a=ea, edge_b=eb, edge_poly=elab,
            triples=tri, poly_normal=self.kernel["poly_normal"], poly_point=self.kernel["poly_point"], n_j=n_t,
            c_j=self.c_t, origin=origin, eu=eu, ev=ev, hull2=np.ascontiguousarray(hull2), slack=1e-9,
        )
        # I' in its own 2-D basis
        # lines of I' in a generic direction: event lines of axis-aligned features are not
        # parallel to them (where one is, the outer integrand has a kink along a whole line)
        iu, iv = plane_basis(self.n_i)
        c, s_ = np.cos(GENERIC_ANGLE_I), np.sin(GENERIC_ANGLE_I)
        self.iu, self.iv = c * iu + s_ * iv, -s_ * iu + c * iv
        self.io = self.I[0][0].copy()
        self.i2 = [np.stack([(l - self.io) @ self.iu, (l - self.io) @ self.iv], axis=1) for l in self.I]

    def outer_cuts(self):
        """Offsets of lines through the points of I' where the outer integrand may be
        singular: occluder vertices touching I (corners of contact lines, where jumps of
        the integrand end) and the VV points, where the line through a vertex of J' and a
        vertex of an occluder meets I' (corners of umbrae and penumbrae). Cuts closer than
        1e-3 of the extent are merged."""
        e = self.events
        vert, lab = e["vert"], e["vert_poly"]
        h = vert @ self.n_i - self.c_i
        pts = [vert[np.abs(h) <= self.tiny * 10]]
        jv, ov = vert[lab == 0], vert[lab > 0]
        if len(ov):
            a = np.repeat(jv, len(ov), axis=0)
            b = np.tile(ov, (len(jv), 1))
            ha, hb = a @ self.n_i - self.c_i, b @ self.n_i - self.c_i
            ok = np.abs(ha - hb) > self.tiny
            a, b, ha, hb = a[ok], b[ok], ha[ok], hb[ok]
            pts.append(a + (ha / (ha - hb))[:, None] * (b - a))
        pts = np.concatenate(pts)
        u, v = (pts - self.io) @ self.iu, (pts - self.io) @ self.iv
        box = np.concatenate(self.i2)
        inside = (u >= box[:, 0].min()) & (u <= box[:, 0].max()) & (v >= box[:, 1].min()) & (v <= box[:, 1].max())
        v = np.unique(v[inside])
        span = box[:, 1].max() - box[:, 1].min()
        return v[np.concatenate([[True], np.diff(v) > 1e-3 * span])] if len(v) else v

    def f(self, points, kernel=None):
        """F from differential areas at ``points`` (m, 3) on I to the part of J' each sees;
        ``kernel``: :meth:`kernel_for` a subset of the occluders (default all, :meth:`arrays`)."""
        k = self.kernel if kernel is None else kernel
        return visible_form_factors(np.ascontiguousarray(points), k["n_i"], k["j2"], k["j_loop"], k["origin"], k["eu"], k["ev"],
                                    k["n_j"], k["c_j"], k["hull"], k["occ"], k["occ_loop"], k["occ_poly"], k["poly_normal"],
                                    k["poly_point"], k["tiny"])

    def line_intervals(self, y):
        """Parameter intervals of I' along the line v = y (non-zero winding)."""
        us, ws = [], []
        for l in self.i2:
            a, b = l, np.roll(l, -1, axis=0)
            up = (a[:, 1] <= y) & (b[:, 1] > y)
            down = (b[:, 1] <= y) & (a[:, 1] > y)
            cross = up | down
            t = (y - a[cross, 1]) / (b[cross, 1] - a[cross, 1])
            us.append(a[cross, 0] + t * (b[cross, 0] - a[cross, 0]))
            ws.append(np.where(up[cross], 1, -1))
        u = np.concatenate(us)
        w = np.concatenate(ws)
        order = np.argsort(u, kind="stable")
        u, w = u[order], w[order]
        run = np.cumsum(w)
        out = []
        start = None
        for k in range(len(u)):
            inside = run[k] != 0
            if inside and start is None:
                start = u[k]
            elif not inside and start is not None:
                if u[k] > start:
                    out.append((start, u[k]))
                start = None
        return out

    def pieces(self, y):
        """Inner pieces of the line v = y: its intervals cut at the events. (p, 2) float."""
        e = self.events
        out = []
        for a, b in self.line_intervals(y):
            x0 = self.io + y * self.iv + a * self.iu
            length = b - a
            s = line_events(x0, self.iu, length, e["vert"], e["vert_poly"], e["edge_a"], e["edge_b"], e["edge_poly"],
                            e["triples"], e["poly_normal"], e["poly_point"], e["n_j"], e["c_j"], e["origin"], e["eu"],
                            e["ev"], e["hull2"], e["slack"])
            cuts = np.unique(np.concatenate([[0.0, length], s]))
            cuts = cuts[np.concatenate([[True], np.diff(cuts) > 1e-12 * length])]
            cuts[-1] = length
            out.append(np.stack([a + cuts[:-1], a + cuts[1:]], axis=1))
        return np.concatenate(out) if out else np.zeros((0, 2))


def _gk(f_values, half):
    """Kronrod value and |K - G| of rows of 15 values on intervals of half-width ``half``."""
    k = f_values @ GK_WK * half
    g = f_values @ GK_WG * half
    return k, np.abs(k - g)


def _inner(setup, ys, density):
    """∫ f along the lines v = ys over I': values, error estimates, evaluations.

    ``density``: accepted inner error per unit length."""
    pieces, owner = [], []
    for k, y in enumerate(ys):
        p = setup.pieces(y)
        pieces.append(p)
        owner.append(np.full(len(p), k))
    pieces = np.concatenate(pieces) if pieces else np.zeros((0, 2))
    owner = np.concatenate(owner) if owner else np.zeros(0, np.int64)
    value = np.zeros(len(ys))
    error = np.zeros(len(ys))
    evals = 0
    depth = 0
    while len(pieces):
        a, b = pieces[:, 0], pieces[:, 1]
        half = 0.5 * (b - a)
        s = (a + half)[:, None] + half[:, None] * GK_X[None, :]
        yy = np.asarray(ys)[owner]
        pts = setup.io + yy[:, None, None] * setup.iv + s[:, :, None] * setup.iu
        fv = setup.f(pts.reshape(-1, 3)).reshape(-1, 15)
        evals += fv.size
        kv, ke = _gk(fv, half)
        ok = (ke <= density * (b - a)) | (depth >= MAX_DEPTH[1])
        np.add.at(value, owner[ok], kv[ok])
        np.add.at(error, owner[ok], ke[ok])
        mid = a + half
        rest = ~ok
        pieces = np.concatenate([np.stack([a[rest], mid[rest]], axis=1), np.stack([mid[rest], b[rest]], axis=1)])
        owner = np.concatenate([owner[rest], owner[rest]])
        depth += 1
    return value, error, evals


def _quadrature(setup, tol):
    """Iterated adaptive Gauss–Kronrod over I' (see the module docstring)."""
    setup.arrays()
    area_i = setup.area_i
    budget = tol * area_i  # on ∫ f
    ys_all = np.unique(np.concatenate([l[:, 1] for l in setup.i2]))
    y_range = ys_all[-1] - ys_all[0]
    area_ip = loops_area(setup.I, setup.n_i)
    density = 0.1 * budget / area_ip
    cuts = setup.outer_cuts()
    cuts = cuts[(cuts > ys_all[0]) & (cuts < ys_all[-1])]
    ys_all = np.unique(np.concatenate([ys_all, cuts, np.linspace(ys_all[0], ys_all[-1], MIN_SPLIT + 1)]))
    ys_all = ys_all[np.concatenate([[True], np.diff(ys_all) > 1e-9 * y_range])]
    intervals = np.stack([ys_all[:-1], ys_all[1:]], axis=1)
    intervals = intervals[intervals[:, 1] > intervals[:, 0]]
    total, err_outer, err_inner, evals, lines = 0.0, 0.0, 0.0, 0, 0
    depth = 0
    while len(intervals):
        a, b = intervals[:, 0], intervals[:, 1]
        half = 0.5 * (b - a)
        ys = ((a + half)[:, None] + half[:, None] * GK_X[None, :]).reshape(-1)
        g, ge, n = _inner(setup, ys, density)
        evals += n
        lines += len(ys)
        g, ge = g.reshape(-1, 15), ge.reshape(-1, 15)
        kv, ke = _gk(g, half)
        inner = ge @ GK_WK * half
        ok = (ke <= 0.9 * budget * (b - a) / y_range) | (depth >= MAX_DEPTH[0])
        total += kv[ok].sum()
        err_outer += ke[ok].sum()
        err_inner += inner[ok].sum()
        mid = a + half
        rest = ~ok
        intervals = np.concatenate([np.stack([a[rest], mid[rest]], axis=1), np.stack([mid[rest], b[rest]], axis=1)])
        depth += 1
    return total / area_i, (err_outer + err_inner) / area_i, evals, lines


def pair_form_factor(scene, face_i, side_i, target, side_t, tol=DEFAULT_TOL):
    """F from side ``side_i`` (+1 front, -1 back) of face i to side ``side_t`` of a target.

    Returns
    -------
    PairResult
    """
    t0 = time.perf_counter()
    setup = PairSetup(scene, face_i, side_i, target, side_t)
    if setup.empty:
        return PairResult(0.0, 0.0, "none", seconds=time.perf_counter() - t0)
    if not setup.occluders:
        value, err = contour_form_factor(setup.I, setup.n_i, setup.J, setup.n_t)
        scale = loops_area(setup.I, setup.n_i) / setup.area_i
        return PairResult(value * scale, err * scale, "contour", seconds=time.perf_counter() - t0)
    value, err, evals, lines = _quadrature(setup, tol)
    return PairResult(value, err, "quadrature", len(setup.occluders), evals, lines, time.perf_counter() - t0)


def contour_form_factor(loops_i, n_i, loops_j, n_j):
    """Unoccluded F_ij by the double contour integral, with the change between two node
    sets (10- and 14-point Gauss–Legendre panels) as its error estimate."""
    from viscx.geometry import formfactor as ff

    value = polygon_to_polygon(loops_i, n_i, loops_j, n_j)
    coarse = polygon_to_polygon(loops_i, n_i, loops_j, n_j, order=6)
    return value, abs(value - coarse)


# --------------------------------------------------------------------------------------
# many pairs: faces, groups, the matrix

SIDES = (1, -1)  # element 2 f + 0: front of face f, 2 f + 1: its back


def face_to_face(scene, face_i, target_face, side_i=1, tol=DEFAULT_TOL):
    """F from one side of face i to face j (both of its sides).

    Returns
    -------
    dict
        ``F``, ``error``, per-side ``sides`` (front/back of j: F, error, method, ...).
    """
    target = face_target(scene, target_face)
    parts = {}
    for name, t in (("front", 1), ("back", -1)):
        parts[name] = pair_form_factor(scene, face_i, side_i, target, t, tol=tol)
    return {
        "F": float(sum(p.F for p in parts.values())),
        "error": float(sum(p.error for p in parts.values())),
        "sides": {name: _pair_dict(p) for name, p in parts.items()},
    }


def _pair_dict(p):
    return {"F": float(p.F), "error": float(p.error), "method": p.method, "occluders": p.occluders,
            "evaluations": int(p.evaluations), "lines": int(p.lines), "seconds": round(p.seconds, 4)}


def group_to_group(scene, faces_i, faces_j, side_i=1, tol=DEFAULT_TOL):
    """Area-weighted F from side ``side_i`` of the faces_i to (both sides of) the faces_j:
    ``Σ_i A_i Σ_j F_ij / Σ_i A_i``. A face in both sets does not see itself (planar)."""
    area = scene.face_area
    total, err, n = 0.0, 0.0, 0
    for i in faces_i:
        for j in faces_j:
            if i == j:
                continue
            r = face_to_face(scene, int(i), int(j), side_i=side_i, tol=tol)
            total += area[i] * r["F"]
            err += area[i] * r["error"]
            n += 1
    a = float(area[list(faces_i)].sum())
    return {"F": total / a, "error": err / a, "pairs": n}


@dataclass
class Matrix:
    """Form factors between all sides of all faces (sparse), with the sky term.

    Element ``2 f`` is the front of face f (its normal side), ``2 f + 1`` its back.

    Attributes
    ----------
    indptr, indices : CSR structure (2n + 1,), (nnz,) int64
    data, error : (nnz,) float64
        F and its error estimate.
    sky, sky_error : (2n,) float64
        F to the sky (the enlarged bounding box, :func:`sky_targets`).
    area : (n,) float64
    method_counts : dict
    seconds : float
    """

    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray
    error: np.ndarray
    sky: np.ndarray
    sky_error: np.ndarray
    area: np.ndarray
    method_counts: dict
    seconds: float
    tol: float

    def dense(self):
        n = len(self.indptr) - 1
        out = np.zeros((n, n))
        for r in range(n):
            out[r, self.indices[self.indptr[r]:self.indptr[r + 1]]] = self.data[self.indptr[r]:self.indptr[r + 1]]
        return out

    def row_sums(self):
        """Σ_j F + sky per element (1 for every side, up to the error)."""
        rows = np.repeat(np.arange(len(self.sky)), np.diff(self.indptr))
        return np.bincount(rows, weights=self.data, minlength=len(self.sky)) + self.sky

    def reciprocity_error(self):
        """max |A_a F_ab - A_b F_ba| / min(A_a, A_b) over element pairs (F units of the smaller face)."""
        d = self.dense()
        a = np.repeat(self.area, 2)
        flux = a[:, None] * d
        diff = np.abs(flux - flux.T) / np.minimum(a[:, None], a[None, :])
        return float(diff.max()) if diff.size else 0.0

    def summary(self):
        rows = self.row_sums()
        return {
            "elements": int(len(self.sky)),
            "nonzeros": int(len(self.data)),
            "reciprocity_max_error": self.reciprocity_error(),
            "row_sum_min": float(rows.min()),
            "row_sum_max": float(rows.max()),
            "row_sum_max_deviation": float(np.abs(rows - 1).max()),
            "max_error_estimate": float(max(self.error.max(initial=0.0), self.sky_error.max(initial=0.0))),
            "tol": self.tol,
            "methods": self.method_counts,
            "seconds": round(self.seconds, 3),
        }


def form_factor_matrix(scene, tol=DEFAULT_TOL, quiet=True):
    """F between every pair of sides, each entry computed independently (reciprocity is
    checked, not imposed), plus every side's sky term."""
    from viscx.progress import bar

    t0 = time.perf_counter()
    n = scene.n_faces
    targets = [face_target(scene, j) for j in range(n)]
    sky = sky_targets(scene)
    rows, cols, vals, errs = [], [], [], []
    sky_v, sky_e = np.zeros(2 * n), np.zeros(2 * n)
    counts = {}
    with bar(total=2 * n, desc="form factors", quiet=quiet, unit="side") as progress:
        for i in range(n):
            for si, side_i in enumerate(SIDES):
                row = 2 * i + si
                for j in range(n):
                    if j == i:
                        continue
                    for sj, side_j in enumerate(SIDES):
                        r = pair_form_factor(scene, i, side_i, targets[j], side_j, tol=tol)
                        counts[r.method] = counts.get(r.method, 0) + 1
                        if r.method != "none" and r.F != 0.0:
                            rows.append(row)
                            cols.append(2 * j + sj)
                            vals.append(r.F)
                            errs.append(r.error)
                for box in sky:
                    r = pair_form_factor(scene, i, side_i, box, 1, tol=tol)
                    counts["sky " + r.method] = counts.get("sky " + r.method, 0) + 1
                    sky_v[row] += r.F
                    sky_e[row] += r.error
                progress.update(1)
    rows = np.asarray(rows, np.int64)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=2 * n))]).astype(np.int64)
    order = np.lexsort([cols, rows])
    return Matrix(indptr, np.asarray(cols, np.int64)[order], np.asarray(vals)[order], np.asarray(errs)[order], sky_v, sky_e,
                  scene.face_area.astype(np.float64).copy(), counts, time.perf_counter() - t0, float(tol))


# --------------------------------------------------------------------------------------
# point to face (seed 000 §7.4)


def point_to_faces(query, point, normal, faces):
    """Exact F from a differential area (point, normal) to each face, over the part of the
    face the point sees: the point's V-cells (:func:`viscx.queries.visibility.view_from`),
    clipped to the front hemisphere, then Lambert's formula.

    Returns
    -------
    dict
        ``F`` (sum over ``faces``), per face ``F`` and visible area, ``complete``, ``source``.
    """
    from viscx.queries.visibility import view_from

    n = np.asarray(normal, dtype=np.float64).reshape(3)
    size = float(np.linalg.norm(n))
    if not np.isfinite(size) or size == 0.0:
        raise ViscxError("--normal must be a non-zero vector")
    n = n / size
    p = np.asarray(point, dtype=np.float64).reshape(3)
    t0 = time.perf_counter()
    view, stored = view_from(query, p)
    per = []
    for f in faces:
        fv = view.faces[int(f)]
        loops = [clip_to_hemisphere(loop, p, n) for loop in fv.loops]
        loops = [loop for loop in loops if len(loop) >= 3]
        value = float(point_to_polygon([p], [n], loops)[0]) if loops else 0.0
        per.append({"face": int(f), "F": value, "visible_area": fv.area(), "complete": bool(fv.complete)})
    return {
        "F": float(sum(r["F"] for r in per)),
        "from": p.tolist(),
        "normal": n.tolist(),
        "faces": per,
        "method": "V-cells + Lambert (exact)",
        "complete": bool(view.complete),
        "source": "file" if stored else "on demand",
        "seconds": round(time.perf_counter() - t0, 4),
    }
