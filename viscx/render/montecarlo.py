"""Monte Carlo direct illumination (the reference the exact render is compared with).

Per shading point x (normal n on the seen side, reflectance ρ), K points y_k uniform by area
on the light (total area A), each tested for a free segment x–y_k by the scene's ray caster:

    L(x) ≈ ρ/π · A/K · Σ_k Le(y_k) V(x, y_k) cos θ_x cos θ_y / r²,

with its standard error s/√K from the sample standard deviation s of the K terms. The
estimator is unbiased; its noise falls as 1/√K (what the exact render does not have).
"""

import numpy as np

#: Segments tested per batch.
CHUNK_RAYS = 1_000_000


def light_triangles(scene, faces):
    """Triangles of the light faces (``faces`` sorted): corners (t, 3, 3), index into
    ``faces`` (t,), area (t,)."""
    pick = np.flatnonzero(np.isin(scene.triangle_face, faces))
    corners = scene.vertices[scene.triangles[pick]]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    return corners, np.searchsorted(faces, scene.triangle_face[pick]), area


def sample_light(corners, area, n, rng):
    """``n`` points uniform by area on the triangles: (n, 3) points and (n,) triangle ids."""
    cdf = np.cumsum(area)
    tri = np.minimum(np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right"), len(area) - 1)
    a, b = rng.random(n), rng.random(n)
    flip = a + b > 1.0
    a[flip], b[flip] = 1.0 - a[flip], 1.0 - b[flip]
    c = corners[tri]
    return c[:, 0] + a[:, None] * (c[:, 1] - c[:, 0]) + b[:, None] * (c[:, 2] - c[:, 0]), tri


def reference_radiance(lighting, face, side, points, samples, seed=0, progress=None):
    """Monte Carlo estimate of :func:`viscx.render.direct.shade`'s radiance.

    Parameters
    ----------
    lighting : viscx.render.direct.DirectLighting
        Scene, light, radiance and reflectances (its discontinuity mesh is not used).
    face, side : (n,) int64
    points : (n, 3) float64
    samples : int
        Light samples per point (K).
    seed : int
    progress : callable, optional
        Called with the number of points done after each batch.

    Returns
    -------
    mean : (n, 3) float64
    stderr : (n, 3) float64
        Standard error of each mean (s/√K).
    """
    scene, em = lighting.scene, lighting.emitter
    faces = np.asarray(em.light.faces)
    corners, tri_light, tri_area = light_triangles(scene, faces)
    total_area = float(tri_area.sum())
    light_normal = scene.face_normal[faces]
    caster = scene.ray_caster
    rng = np.random.default_rng(seed)
    n = len(face)
    mean = np.zeros((n, 3))
    stderr = np.zeros((n, 3))
    hit = np.flatnonzero(face >= 0)
    per = max(1, CHUNK_RAYS // samples)
    for lo in range(0, len(hit), per):
        idx = hit[lo:lo + per]
        m = len(idx)
        x = np.repeat(points[idx], samples, axis=0)
        nx = np.repeat(side[idx, None] * scene.face_normal[face[idx]], samples, axis=0)
        y, tri = sample_light(corners, tri_area, m * samples, rng)
        k = tri_light[tri]
        d = y - x
        r2 = np.einsum("ij,ij->i", d, d)
        cos_x = np.einsum("ij,ij->i", nx, d)
        cos_y = -np.einsum("ij,ij->i", light_normal[k], d)
        own = np.repeat(face[idx], samples) == faces[k]
        term = np.where((cos_x > 0) & (cos_y > 0) & ~own, cos_x * cos_y / np.maximum(r2, 1e-300) ** 2, 0.0)
        live = np.flatnonzero(term > 0)
        if len(live):
            free = caster.free_segments(x[live], y[live])
            term[live[~free]] = 0.0
        # (m·K, 3): ρ/π · A · Le · V cos cos / r²
        rho = np.repeat(lighting.kd[face[idx]], samples, axis=0)
        contrib = (term * total_area / np.pi)[:, None] * em.radiance[k] * rho
        contrib = contrib.reshape(m, samples, 3)
        mean[idx] = contrib.mean(axis=1)
        if samples > 1:
            stderr[idx] = contrib.std(axis=1, ddof=1) / np.sqrt(samples)
        if progress is not None:
            progress(m)
    for f in np.unique(face[hit]):
        on = hit[face[hit] == f]
        for s in (-1, 1):
            sel = on[side[on] == s]
            mean[sel] += lighting.emitted(f, s)[None, :]
    return mean, stderr
