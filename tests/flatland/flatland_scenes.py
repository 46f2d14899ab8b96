"""Scene generators shared by the flatland tests."""

import numpy as np

from viscx.flatland.scene import make_scene


def random_circles(n, seed=0, gap=0.05, rmin=0.3, rmax=1.0, density=4.0):
    rng = np.random.default_rng(seed)
    side = np.sqrt(n) * density
    cs, objs = [], []
    while len(objs) < n:
        c = rng.uniform(0, side, 2)
        r = rng.uniform(rmin, rmax)
        if all(np.hypot(*(c - c2)) > r + r2 + gap for c2, r2 in cs):
            cs.append((c, r))
            objs.append({"type": "circle", "center": c.tolist(), "radius": float(r),
                         "emission": float(rng.uniform(0, 1) < 0.2), "reflectance": float(rng.uniform(0.1, 0.9))})
    return make_scene(objs)


def random_polygon(rng, center, radius, m=None):
    m = m or int(rng.integers(3, 8))
    a = np.sort(rng.uniform(0, 2 * np.pi, m))
    rr = radius * rng.uniform(0.6, 1.0)
    return np.stack([center[0] + rr * np.cos(a), center[1] + rr * np.sin(a)], 1)


def random_mixed(n, seed=0, density=4.0):
    """Disjoint circles and convex polygons (each inside a disjoint bounding disk)."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(n) * density
    cs, objs = [], []
    while len(objs) < n:
        c = rng.uniform(0, side, 2)
        r = rng.uniform(0.4, 1.2)
        if all(np.hypot(*(c - c2)) > r + r2 + 0.05 for c2, r2 in cs):
            cs.append((c, r))
            if rng.uniform() < 0.5:
                o = {"type": "circle", "center": c.tolist(), "radius": float(r)}
            else:
                o = {"type": "polygon", "points": random_polygon(rng, c, r).tolist()}
            o.update(emission=float(rng.uniform() < 0.3), reflectance=float(rng.uniform(0.1, 0.9)))
            objs.append(o)
    return make_scene(objs)


def occluded_scene():
    """Five mixed objects with mutual occlusions (the hand-made Monte Carlo scene)."""
    return make_scene([
        {"type": "circle", "center": [0, 0], "radius": 1, "emission": 1.0, "reflectance": 0.2, "name": "lamp"},
        {"type": "circle", "center": [6, 0.5], "radius": 1.2, "reflectance": 0.7},
        {"type": "polygon", "points": [[2.5, -0.5], [3.5, -0.2], [3.2, 1.0], [2.6, 0.8]], "reflectance": 0.5},
        {"type": "circle", "center": [3, 3], "radius": 0.7, "reflectance": 0.6},
        {"type": "polygon", "points": [[1, -3], [4, -3.5], [3, -2]], "reflectance": 0.4},
    ])
