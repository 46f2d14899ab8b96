"""Cleaning a triangle soup: welding, degenerate and duplicate triangles."""

import numpy as np

from viscx.arrays import first_of_rows


def weld_vertices(vertices, tolerance):
    """Merge vertices closer than ``tolerance`` (transitively).

    Every cluster is represented by its lowest-index member, whose coordinates
    are kept exactly (no averaging: coordinates that were equal stay equal).
    Surviving vertices keep their relative order, so ids are stable.

    Parameters
    ----------
    vertices : (n, 3) float
    tolerance : float
        Absolute distance; 0 merges only identical positions.

    Returns
    -------
    welded : (k, 3) float
    remap : (n,) int
        New index of every old vertex.
    """
    # scipy imported here, not with the module: ~0.3 CPU s of every command that only
    # loads a built file (the queries, the form factors) and never welds
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(vertices)
    if n == 0:
        return vertices.copy(), np.zeros(0, dtype=np.int64)
    pairs = cKDTree(vertices).query_pairs(r=max(float(tolerance), 0.0), output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    # representative of each cluster: its smallest member
    representative = np.full(label.max() + 1, n, dtype=np.int64)
    np.minimum.at(representative, label, np.arange(n))
    keep = np.unique(representative)  # sorted: relative order preserved
    new_id = np.empty(n, dtype=np.int64)
    new_id[keep] = np.arange(len(keep))
    return vertices[keep].copy(), new_id[representative[label]]


def triangle_normals(vertices, triangles):
    """Unit normals and areas of triangles.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int

    Returns
    -------
    normals : (t, 3) float
        Zero for zero-area triangles.
    areas : (t,) float
    """
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    cross = np.cross(b - a, c - a)
    length = np.linalg.norm(cross, axis=1)
    normals = cross / np.where(length > 0, length, 1.0)[:, None]
    return normals, 0.5 * length


def degenerate_triangles(vertices, triangles, tolerance):
    """Mask of triangles that are thinner than ``tolerance`` (or repeat a vertex).

    The thickness of a triangle is twice its area over its longest side: its
    smallest height.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int
    tolerance : float

    Returns
    -------
    (t,) bool
    """
    repeated = (
        (triangles[:, 0] == triangles[:, 1]) | (triangles[:, 1] == triangles[:, 2]) | (triangles[:, 0] == triangles[:, 2])
    )
    _, areas = triangle_normals(vertices, triangles)
    p = vertices[triangles]
    longest = np.max(np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2), axis=1)
    thickness = 2.0 * areas / np.where(longest > 0, longest, 1.0)
    return repeated | (thickness <= tolerance)


def duplicate_triangles(triangles):
    """Mask of triangles that repeat an earlier one's vertex set (either orientation).

    Parameters
    ----------
    triangles : (t, 3) int

    Returns
    -------
    (t,) bool
        True for every repeat after the first occurrence.
    """
    if len(triangles) == 0:
        return np.zeros(0, dtype=bool)
    key = np.sort(triangles, axis=1)
    first = first_of_rows(key)
    mask = np.ones(len(triangles), dtype=bool)
    mask[first] = False
    return mask


def crossing_polygons(vertices, offsets, indices, triangles, triangle_polygon, tolerance):
    """Mask of input polygons whose edges cross (bow-ties and the like).

    A simple polygon's triangles add up to the area it encloses (half the length
    of its Newell vector); where edges cross, part of it winds the other way, so
    its triangles cover more than it encloses. Non-planarity changes the two only
    to second order, hence the 1e-3 relative slack; differences thinner than
    ``tolerance`` along the perimeter are ignored (such slivers are dropped later).

    Parameters
    ----------
    vertices : (n, 3) float
    offsets : (p + 1,) int
    indices : (m,) int
        The polygons, as in :class:`viscx.scene.PolygonSoup`.
    triangles : (t, 3) int
    triangle_polygon : (t,) int
        Their triangulation (:func:`viscx.geometry.polygon.triangulate_polygons`).
    tolerance : float

    Returns
    -------
    (p,) bool
    """
    p = len(offsets) - 1
    sizes = np.diff(offsets)
    if np.all(sizes <= 3):  # triangles cannot cross themselves (the common case for big meshes)
        return np.zeros(p, dtype=bool)
    owner = np.repeat(np.arange(p), sizes)
    # relative to each polygon's first vertex: cross products of far-away coordinates cancel badly
    pts = vertices[indices] - vertices[indices[offsets[:-1]]][owner]
    nxt = np.arange(len(indices)) + 1
    nxt[offsets[1:] - 1] = offsets[:-1]
    cross = np.cross(pts, pts[nxt])
    newell = np.stack([np.bincount(owner, weights=cross[:, i], minlength=p) for i in range(3)], axis=1)
    enclosed = 0.5 * np.linalg.norm(newell, axis=1)
    perimeter = np.bincount(owner, weights=np.linalg.norm(pts[nxt] - pts, axis=1), minlength=p)
    _, areas = triangle_normals(vertices, triangles)
    covered = np.bincount(triangle_polygon, weights=areas, minlength=p)
    return covered - enclosed > 1e-3 * covered + tolerance * perimeter
