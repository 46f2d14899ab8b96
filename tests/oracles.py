"""Independent reference implementations for tests (slow, simple, float64)."""

import numpy as np


def segment_hits_reference(starts, ends, vertices, triangles, bary_slack=0.0):
    """Brute force: does each closed segment meet each closed triangle?

    Written independently of viscx.raycast: the segment is tested against the
    triangle's plane by signed distances, and the crossing point against the
    triangle by edge-function signs (not Möller–Trumbore). ``bary_slack`` grows
    (> 0) or shrinks (< 0) every triangle by that fraction of its size, to find
    segments whose answer is decided by a hair.

    Parameters
    ----------
    starts, ends : (n, 3) float
    vertices : (v, 3) float
    triangles : (t, 3) int

    Returns
    -------
    hit : (n, t) bool
    s : (n, t) float
        Fraction along the segment where its line crosses the triangle's plane.
    """
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    d0 = np.einsum("tj,ntj->nt", normal, starts[:, None, :] - a[None])
    d1 = np.einsum("tj,ntj->nt", normal, ends[:, None, :] - a[None])
    # a segment lying in a triangle's plane (within rounding) grazes it, never crosses it
    scale = 1e-12 * (1.0 + np.abs(vertices).max())
    in_plane = (np.abs(d0) <= scale) & (np.abs(d1) <= scale)
    crosses = (np.sign(d0) * np.sign(d1) <= 0) & (d0 != d1) & ~in_plane
    s = np.where(crosses, d0 / np.where(crosses, d0 - d1, 1.0), 0.0)
    point = starts[:, None, :] + s[..., None] * (ends - starts)[:, None, :]
    size = np.linalg.norm(b - a, axis=1) + np.linalg.norm(c - b, axis=1) + np.linalg.norm(a - c, axis=1)
    inside = np.ones_like(crosses)
    for p, q in ((a, b), (b, c), (c, a)):
        edge = q - p
        # inward normal of the edge within the triangle's plane
        inward = np.cross(normal, edge)
        inward /= np.linalg.norm(inward, axis=1, keepdims=True)
        dist = np.einsum("tj,ntj->nt", inward, point - p[None])
        inside &= dist >= -bary_slack * size[None]
    return crosses & inside, np.where(crosses, s, np.nan)


def first_face_reference(origins, directions, tmax, vertices, triangles, triangle_face, tie=1e-12):
    """Brute force first hit on ``[0, tmax]``.

    Returns
    -------
    face : (n,) int
        A first face, -1 for none.
    t : (n,) float
    tied : (n, f) bool
        Every face hit at the first distance (overlapping coplanar faces tie).
    """
    d = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    ends = origins + d * tmax[:, None]
    hit, s = segment_hits_reference(origins, ends, vertices, triangles)
    s = np.where(hit, s, np.inf)
    first = np.argmin(s, axis=1)
    best = s[np.arange(len(origins)), first]
    face = np.where(np.isfinite(best), triangle_face[first], -1)
    tied_tri = np.isfinite(best)[:, None] & (s <= best[:, None] + tie)
    tied = np.zeros((len(origins), triangle_face.max() + 1), dtype=bool)
    rows, cols = np.nonzero(tied_tri)
    tied[rows, triangle_face[cols]] = True
    return face, best * tmax, tied


def sample_on_triangles(vertices, triangles, n, rng):
    """Uniform random points on a triangle set: (points (n, 3), triangle (n,))."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tri = rng.choice(len(triangles), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    flip = r1 + r2 > 1
    r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
    return a[tri] + r1[:, None] * (b[tri] - a[tri]) + r2[:, None] * (c[tri] - a[tri]), tri


def assert_cells_round_trip(tmp_path, scene, cells, write, read, where):
    """Write 2-cells into a viscx file's V2 group and read them back: every array equal,
    dtypes included. ``where`` picks the group to read from the open file."""
    from viscx.formats.hdf5 import ViscxFile, write_complex

    out = tmp_path / "x.h5"
    # an empty V1 beside: a file listing V2 needs the V1 group its readers bound V2 by
    write_complex(out, scene, levels={"V1": lambda g: None, "V2": lambda g: write(g, cells)})
    with ViscxFile(out) as f:
        back = read(where(f.h5))
    for field in cells.__dataclass_fields__:
        a, b = getattr(cells, field), getattr(back, field)
        assert a.dtype == b.dtype and np.array_equal(a, b), field


def cosine_directions(normals, rng):
    """Directions cosine-distributed about each unit normal (Malley's method: uniform points
    of the unit disc lifted to the hemisphere): (n, 3) for ``normals`` (n, 3)."""
    n = len(normals)
    u1, u2 = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    # a tangent frame per normal: cross with the axis least aligned with it
    axis = np.zeros_like(normals)
    axis[np.arange(n), np.argmin(np.abs(normals), axis=1)] = 1.0
    a = np.cross(normals, axis)
    a /= np.linalg.norm(a, axis=1)[:, None]
    b = np.cross(normals, a)
    return (r * np.cos(phi))[:, None] * a + (r * np.sin(phi))[:, None] * b + np.sqrt(1 - u1)[:, None] * normals


def in_convex_cells(points, cells, normal, tol=1e-12):
    """(n,) int64: for each point (n, 3) in the plane of the convex cells (list of (k, 3),
    wound either way about ``normal``), the first cell it lies in (boundary included), -1
    none."""
    out = np.full(len(points), -1, np.int64)
    if not len(points):
        return out
    # each cell tests only the points in its span along the points' widest axis (a wall
    # with a shelf's back on it has 1,225 cells: all against all took minutes a 10⁶ rays)
    axis = int(np.argmax(np.ptp(points, axis=0)))
    order = np.argsort(points[:, axis], kind="stable")
    key = points[order, axis]
    slack = 1e-9 * (float(np.ptp(points, axis=0).max()) + 1.0)
    for c, cell in enumerate(cells):
        lo, hi = np.searchsorted(key, [cell[:, axis].min() - slack, cell[:, axis].max() + slack])
        idx = order[lo:hi]
        idx = idx[out[idx] < 0]
        p = points[idx]
        side = np.stack([np.cross(b - a, p - a) @ normal for a, b in zip(cell, np.roll(cell, -1, axis=0))])
        inside = np.all(side >= -tol, axis=0) | np.all(side <= tol, axis=0)
        out[idx[inside]] = c
    return out


def rectangle_product_gauss(kernel, lo, hi, edges, points=8, skip=None, chunk=200_000):
    """∫ over an axis-aligned rectangle [lo, hi] (3,) float (one axis flat) of ``kernel``
    (points (n, 3) -> (n,) float), over the rectangle's area: product Gauss–Legendre rules
    of ``points`` points on the panels between ``edges``, {axis: (k,) float from lo to hi}
    for its two other axes. ``skip(points) -> (n,) bool``: points whose value counts 0 (an
    emitter's parts lying on other faces, which see only those: put their outlines among
    the edges, or the integrand jumps inside a panel). An oracle independent of viscx's
    cubature (its nodes, levels, cuts and estimates); converged where two panel counts
    agree."""
    g, w = np.polynomial.legendre.leggauss(points)
    (a, ea), (b, eb) = sorted(edges.items())
    nodes = [(0.5 * (e[1:] - e[:-1])[:, None] * g + 0.5 * (e[1:] + e[:-1])[:, None]).ravel() for e in (ea, eb)]
    weights = [(0.5 * (e[1:] - e[:-1])[:, None] * w).ravel() for e in (ea, eb)]
    pa, pb = np.meshgrid(*nodes, indexing="ij")
    pts = np.tile(np.asarray(lo, np.float64), (pa.size, 1))
    pts[:, a], pts[:, b] = pa.ravel(), pb.ravel()
    values = np.concatenate([kernel(pts[k:k + chunk]) for k in range(0, len(pts), chunk)])
    if skip is not None:
        values = np.where(skip(pts), 0.0, values)
    return float(np.outer(*weights).ravel() @ values) / float((hi[a] - lo[a]) * (hi[b] - lo[b]))


def form_factor_monte_carlo(scene, faces, side, k, seed=0, chunk=1 << 20, lying=None):
    """Form factors from one side of a set of faces to every face side and the sky, by ``k``
    cosine-weighted rays from area-uniform points of the faces (embree first hits), in
    batches of ``chunk`` rays. Independent of viscx's exact code: only the ray caster.

    A ray from side ``side`` (+1 front, -1 back) of the emitters reaching face j arrives
    on the side of j whose normal faces it (t = +1 when d · n_j < 0).

    Parameters
    ----------
    scene : viscx.scene.Scene
    faces : (m,) int
        Emitting faces, area-weighted (one face: its row).
    side : int
    k : int
    seed : int
    lying : (cells, elements), optional
        For one emitting face: its parts lying on other faces (convex cells (k, 3) in its
        plane, and the element ``2 j + (0 front, 1 back)`` each lies on). A point of such a
        cell sees that side only (viscx's convention, docs/queries.md "Faces lying on
        faces"): its ray counts there, where a ray cast from it would pass through the face
        it lies on (tmin) into what is behind (a box's inside, and through its bottom's
        tie with the floor onto the floor).

    Returns
    -------
    F : (2 n_faces + 1,) float64
        Estimates, index 2 j for the front of face j, 2 j + 1 for its back, the last the sky.
    sigma : (2 n_faces + 1,) float64
        Their standard errors √(F (1 − F) / k) (the counts are binomial).
    """
    faces = np.atleast_1d(np.asarray(faces, dtype=np.int64))
    pick = np.flatnonzero(np.isin(scene.triangle_face, faces))
    tris, tri_face = scene.triangles[pick], scene.triangle_face[pick]
    rng = np.random.default_rng(seed)
    counts = np.zeros(2 * scene.n_faces + 1, dtype=np.int64)
    for lo in range(0, k, chunk):
        m = min(chunk, k - lo)
        p, t = sample_on_triangles(scene.vertices, tris, m, rng)
        n = side * scene.face_normal[tri_face[t]]
        d = cosine_directions(n, rng)
        face, _ = scene.ray_caster.first_hit(p, d, tmin=scene.epsilon)
        hit = face >= 0
        back = np.einsum("ij,ij->i", d[hit], scene.face_normal[face[hit]]) > 0
        slot = np.full(m, 2 * scene.n_faces)
        slot[hit] = 2 * face[hit] + back
        if lying is not None and len(lying[0]):
            cell = in_convex_cells(p, lying[0], n[0])
            slot[cell >= 0] = np.asarray(lying[1])[cell[cell >= 0]]
        counts += np.bincount(slot, minlength=len(counts))
    F = counts / k
    return F, np.sqrt(F * (1 - F) / k)
