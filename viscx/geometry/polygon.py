"""Planar polygons: normals, projection to 2-D, triangulation."""

import numpy as np


def newell_normal(points):
    """Area vector of a closed polygon by Newell's method.

    For a planar polygon the result is ``2 * area * n`` with ``n`` the unit normal
    on the side from which the polygon is counter-clockwise; for a slightly
    non-planar one it is the normal of the best-fitting plane, which is why it is
    used instead of a cross product of two edges.

    Parameters
    ----------
    points : (k, 3) float

    Returns
    -------
    (3,) float
    """
    p = np.asarray(points, dtype=np.float64)
    q = np.concatenate((p[1:], p[:1]))  # np.roll(p, -1, axis=0), without its axis handling
    # p × q by components, the same operations as np.cross (bit-identical), without its
    # axis handling, which costs more than the products on the short loops of faces
    c = np.empty_like(p)
    c[:, 0] = p[:, 1] * q[:, 2] - p[:, 2] * q[:, 1]
    c[:, 1] = p[:, 2] * q[:, 0] - p[:, 0] * q[:, 2]
    c[:, 2] = p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]
    return c.sum(axis=0)


def newell_normals(points, offsets):
    """The Newell normal (:func:`newell_normal`) of every loop of a flat array, each the
    same bits as :func:`newell_normal` of that loop: its terms summed in order (as numpy
    sums the rows of a (k, 3) array; ``np.add.reduceat`` does not), the loops of one length
    at a time (a scanned mesh's 10⁵ triangles in a few array operations).

    Parameters
    ----------
    points : (m, 3) float
        The loops' vertices, loop j ``points[offsets[j]:offsets[j + 1]]``.
    offsets : (l + 1,) int

    Returns
    -------
    (l, 3) float64
    """
    p = np.asarray(points, dtype=np.float64)
    offsets = np.asarray(offsets, dtype=np.int64)
    starts, sizes = offsets[:-1], np.diff(offsets)
    nxt = np.arange(len(p)) + 1
    nxt[offsets[1:][sizes > 0] - 1] = starts[sizes > 0]  # the last vertex of a loop goes to its first
    q = p[nxt]
    c = np.empty_like(p)
    c[:, 0] = p[:, 1] * q[:, 2] - p[:, 2] * q[:, 1]
    c[:, 1] = p[:, 2] * q[:, 0] - p[:, 0] * q[:, 2]
    c[:, 2] = p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]
    out = np.zeros((len(sizes), 3))
    for k in np.unique(sizes[sizes > 0]):
        loops = np.flatnonzero(sizes == k)
        terms = c[starts[loops][:, None] + np.arange(k)]  # (loops, k, 3)
        acc = terms[:, 0].copy()
        for t in range(1, k):
            acc += terms[:, t]
        out[loops] = acc
    return out


def plane_basis(normal):
    """Two unit vectors ``(u, v)`` with ``(u, v, normal)`` right-handed orthonormal.

    Parameters
    ----------
    normal : (3,) float, unit length
    """
    n = np.asarray(normal, dtype=np.float64)
    helper = np.eye(3)[np.argmin(np.abs(n))]
    u = _cross3(helper, n)
    u /= np.linalg.norm(u)
    return u, _cross3(n, u)


def _cross3(a, b):
    """(3,) float64: a × b of two 3-vectors, the same operations as np.cross (bit-identical)
    without its axis handling (plane_basis runs once per face, pair and row)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def signed_area_2d(points):
    """Shoelace signed area of a 2-D polygon, positive when counter-clockwise.

    Parameters
    ----------
    points : (k, 2) float
    """
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def is_convex_2d(points):
    """True when a counter-clockwise 2-D polygon turns left (or goes straight) at every vertex.

    Parameters
    ----------
    points : (k, 2) float
    """
    a = np.roll(points, 1, axis=0)
    c = np.roll(points, -1, axis=0)
    cross = (points[:, 0] - a[:, 0]) * (c[:, 1] - points[:, 1]) - (points[:, 1] - a[:, 1]) * (c[:, 0] - points[:, 0])
    return bool(np.all(cross >= 0))


def ear_clip(points):
    """Triangulate a simple (or weakly simple: a keyhole) counter-clockwise 2-D polygon by ear clipping, O(k³) worst case.

    Parameters
    ----------
    points : (k, 2) float

    Returns
    -------
    (k - 2, 3) int
        Triangles as indices into ``points``, counter-clockwise. Collinear
        (zero-area) ears are clipped last, so a polygon with collinear vertices
        still gets ``k - 2`` triangles; callers drop degenerate ones.
    """
    idx = list(range(len(points)))
    out = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    def inside(p, a, b, c, closed):
        if closed:
            return cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0
        # strictly inside, or on the new diagonal c–a (the sides a–b, b–c are the polygon's own)
        on_diagonal = cross(c, a, p) == 0 and min(a[0], c[0]) <= p[0] <= max(a[0], c[0]) and min(a[1], c[1]) <= p[1] <= max(a[1], c[1])
        return (cross(a, b, p) > 0 and cross(b, c, p) > 0 and cross(c, a, p) > 0) or on_diagonal

    # passes, most careful first: (convex corners only, other points on the ear's
    # border block it); then collinear corners; then only points strictly inside
    # block it (a vertex touching another edge in a weakly simple polygon)
    passes = ((True, True), (False, True), (True, False))
    guard = 0
    while len(idx) > 3 and guard < 4 * len(points) ** 2:
        guard += 1
        clipped = False
        for strict, closed in passes:
            for k in range(len(idx)):
                i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
                a, b, c = points[i0], points[i1], points[i2]
                turn = cross(a, b, c)
                if turn < 0 or (strict and turn == 0):
                    continue
                # a keyhole (bridged hole) repeats vertices: copies of the ear's own
                # corners are not inside it
                others = (
                    points[j]
                    for j in idx
                    if j not in (i0, i1, i2) and not any(np.array_equal(points[j], q) for q in (a, b, c))
                )
                if turn > 0 and any(inside(p, a, b, c, closed) for p in others):
                    continue
                out.append((i0, i1, i2))
                del idx[k]
                clipped = True
                break
            if clipped:
                break
        if not clipped:  # not simple: fall back to a fan so that nothing is lost
            break
    if len(idx) >= 3:
        out.extend((idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1))
    return np.asarray(out, dtype=np.int64).reshape(-1, 3)


def triangulate_polygons(vertices, offsets, indices):
    """Triangulate a CSR list of (possibly non-convex, non-planar) 3-D polygons.

    Convex polygons are fanned (vectorised per polygon size); the others are
    projected on their Newell plane and ear-clipped.

    Parameters
    ----------
    vertices : (n, 3) float
    offsets : (p + 1,) int
    indices : (m,) int

    Returns
    -------
    triangles : (t, 3) int
        Vertex indices, oriented like their polygon.
    triangle_polygon : (t,) int
        The polygon each triangle came from.
    """
    sizes = np.diff(offsets)
    tris, owner = [], []
    for k in np.unique(sizes):
        polys = np.flatnonzero(sizes == k)
        loops = indices[offsets[polys][:, None] + np.arange(k)]  # (q, k)
        if k == 3:
            tris.append(loops)
            owner.append(polys)
            continue
        pts = vertices[loops]  # (q, k, 3)
        normal = np.cross(pts, np.roll(pts, -1, axis=1)).sum(axis=1)
        nrm = np.linalg.norm(normal, axis=1)
        normal = normal / np.where(nrm > 0, nrm, 1.0)[:, None]
        # convex iff every corner turns the same way as the Newell normal
        e_in = pts - np.roll(pts, 1, axis=1)
        e_out = np.roll(pts, -1, axis=1) - pts
        turn = np.einsum("qkj,qj->qk", np.cross(e_in, e_out), normal)
        convex = np.all(turn >= -1e-12 * np.maximum(1.0, np.abs(turn).max(axis=1, keepdims=True)), axis=1)
        fan = loops[convex]
        if len(fan):
            j = np.arange(1, k - 1)
            tris.append(np.stack([np.repeat(fan[:, :1], k - 2, axis=1), fan[:, j], fan[:, j + 1]], axis=2).reshape(-1, 3))
            owner.append(np.repeat(polys[convex], k - 2))
        for q in np.flatnonzero(~convex):
            u, v = plane_basis(normal[q])
            p2 = np.stack([pts[q] @ u, pts[q] @ v], axis=1)
            ears = ear_clip(p2)
            tris.append(loops[q][ears])
            owner.append(np.full(len(ears), polys[q]))
    if not tris:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    triangles = np.concatenate(tris).astype(np.int64)
    triangle_polygon = np.concatenate(owner).astype(np.int64)
    order = np.argsort(triangle_polygon, kind="stable")
    return triangles[order], triangle_polygon[order]
