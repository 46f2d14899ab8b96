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


def panel_rows(n, pitch=3.0, width=2.0, tilt=25.0, height=1.0, thick=1e-3, ground=True):
    """A uniform PV array: n identical panels tilted by ``tilt`` degrees at a constant pitch
    above a ground block (every panel tip on one line, every panel foot on another).
    ``thick`` = 0 makes each panel a segment, else a thin quad."""
    c, s = np.cos(np.radians(tilt)), np.sin(np.radians(tilt))
    objs = []
    for i in range(n):
        p0 = np.array([i * pitch, height])
        p1 = p0 + width * np.array([c, s])
        if thick == 0:
            objs.append({"type": "segment", "points": [p0.tolist(), p1.tolist()], "name": f"row{i}"})
        else:
            off = thick * np.array([-s, c])
            objs.append({"type": "polygon", "points": [p0.tolist(), p1.tolist(), (p1 + off).tolist(), (p0 + off).tolist()],
                         "name": f"row{i}"})
    if ground:
        objs.append({"type": "polygon", "points": [[-5, -1], [n * pitch + 5, -1], [n * pitch + 5, 0], [-5, 0]],
                     "name": "ground"})
    return make_scene(objs)


def square_grid(n=20, pitch=3.0, side=1.0):
    """n × n axis-aligned square columns on a lattice (rows, columns and lattice lines of
    every rational slope touch many corners or edges at once)."""
    return make_scene([{"type": "polygon", "points": [[i * pitch, j * pitch], [i * pitch + side, j * pitch],
                                                      [i * pitch + side, j * pitch + side], [i * pitch, j * pitch + side]],
                        "name": f"col{i}_{j}"} for i in range(n) for j in range(n)])


def corners_of(scene):
    """[(m, 2) corners] of every (polygon or segment) object."""
    return [scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]].copy() for k in range(scene.n)]
