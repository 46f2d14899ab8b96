"""Small random scenes for property tests: tetrahedra and boxes, optionally axis-aligned
and standing on a floor (the degenerate contacts of architectural scenes)."""

import numpy as np
from conftest import soup


def random_tetrahedra(rng, count):
    """``count`` disjoint random tetrahedra (closed, outward) in a 10-unit box."""
    vertices, polygons, groups, centers = [], [], [], []
    while len(centers) < count:
        c = rng.uniform(0, 10, 3)
        r = rng.uniform(0.8, 2.0)
        if any(np.linalg.norm(c - q) < r + s + 0.2 for q, s in centers):
            continue
        centers.append((c, r))
        pts = c + r * _unit_rows(rng.normal(size=(4, 3)))
        if np.linalg.det(pts[1:] - pts[0]) < 0:
            pts[[1, 2]] = pts[[2, 1]]
        base = len(vertices)
        vertices += pts.tolist()
        for tri in ((0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)):
            polygons.append([base + i for i in tri])
            groups.append(len(centers) - 1)
    return soup(vertices, polygons, groups)


def random_boxes(rng, count, axis_aligned, on_floor):
    """``count`` boxes (six quads each), rotated about y unless ``axis_aligned``; standing
    on a 14 × 14 floor quad at y = 0 when ``on_floor``, else floating."""
    vertices, polygons, groups = [], [], []
    if on_floor:
        vertices += [[-2, 0, -2], [12, 0, -2], [12, 0, 12], [-2, 0, 12]]
        polygons.append([0, 3, 2, 1])
        groups.append(0)
    placed = []
    while len(placed) < count:
        size = rng.uniform(0.5, 2.5, 3)
        center = rng.uniform(0, 10, 3)
        center[1] = size[1] / 2 if on_floor else center[1]
        radius = np.linalg.norm(size) / 2
        if any(np.linalg.norm(center - q) < radius + s + 0.1 for q, s in placed):
            continue
        placed.append((center, radius))
        angle = 0.0 if axis_aligned else rng.uniform(0, np.pi / 2)
        rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
        corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]) * size
        corners = corners @ rot.T + center
        if axis_aligned:
            corners = np.round(corners, 3)  # exact, shared coordinates: the degenerate case
        base = len(vertices)
        vertices += corners.tolist()
        for quad in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
            polygons.append([base + i for i in quad])
            groups.append(len(placed))
    return soup(vertices, polygons, groups)


def general_position_scene(seed):
    """Random tetrahedra (odd seeds) or rotated floating boxes (even seeds): general
    position (the V- and EE-cell oracles' random scenes)."""
    from viscx.scene import build_scene

    rng = np.random.default_rng(seed)
    if seed % 2:
        return build_scene(random_tetrahedra(rng, int(rng.integers(2, 4))))
    return build_scene(random_boxes(rng, int(rng.integers(1, 3)), axis_aligned=False, on_floor=False))


def _unit_rows(x):
    return x / np.linalg.norm(x, axis=1, keepdims=True)
