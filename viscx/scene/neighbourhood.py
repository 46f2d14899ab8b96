"""The surface around a point: every face touching it, as the wedge it makes there.

A face touching a point p is, in a small ball around p, a planar wedge with
apex p: a corner (p is one of its vertices), a half-plane (p lies on one of its
edges) or the whole plane (p lies inside it). This is found geometrically
(within the weld tolerance), so it sees faces the half-edge structure does not
connect: a block's bottom edge lying on a floor, a wall's corner on another
wall's edge (a T-junction).

A wedge is given by its first ray ``a`` (unit, in the face's plane), its face's
unit normal ``n`` and its angle ``span``: it sweeps counter-clockwise about n
from a by span (2π for the whole plane).
"""

from dataclasses import dataclass

import numpy as np


@dataclass
class Wedges:
    """Wedges around query points, as a CSR list.

    Attributes
    ----------
    offsets : (q + 1,) int
        Wedges of point i are ``offsets[i]:offsets[i + 1]``.
    face : (k,) int
    first : (k, 3) float
        Unit first ray ``a``.
    normal : (k, 3) float
    span : (k,) float
        In (0, 2π]; 2π for a point inside the face.
    """

    offsets: np.ndarray
    face: np.ndarray
    first: np.ndarray
    normal: np.ndarray
    span: np.ndarray


def incident_faces(scene):
    """Faces touching each vertex and each edge through the half-edge structure.

    Returns
    -------
    vertex_offsets : (n + 1,) int
    vertex_faces : (k,) int
    edge_offsets : (e + 1,) int
    edge_faces : (k',) int
    """
    he = scene.half_edges

    def table(owner, face, size):
        pairs = np.unique(np.stack([owner, face], axis=1), axis=0)
        return np.searchsorted(pairs[:, 0], np.arange(size + 1)), pairs[:, 1]

    vo, vf = table(he.start, he.face, scene.n_vertices)
    eo, ef = table(he.edge, he.face, len(he.edge_vertices))
    return vo, vf, eo, ef


def faces_near(scene, points, tol):
    """(point, face) pairs with the point within ``tol`` of the closed face, sorted."""
    point, tri = scene.ray_caster.exact.triangles_near(points, tol)
    if len(point) == 0:
        return point, point.copy()
    pairs = np.unique(np.stack([point, scene.triangle_face[tri]], axis=1), axis=0)
    return pairs[:, 0], pairs[:, 1]


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def surface_wedges(scene, points):
    """Every face touching each point, as the wedge it makes there.

    Parameters
    ----------
    scene : Scene
    points : (q, 3) float

    Returns
    -------
    Wedges
    """
    tol = scene.weld_tolerance
    he = scene.half_edges
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    owner, face = faces_near(scene, points, tol)
    # the nearest boundary half-edge of each face to its point
    first = scene.loop_offsets[scene.face_loop_offsets[face]]
    last = scene.loop_offsets[scene.face_loop_offsets[face + 1]]
    counts = last - first
    pair = np.repeat(np.arange(len(face)), counts)
    h = np.repeat(first, counts) + np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    a, b = scene.vertices[he.start[h]], scene.vertices[he.end[h]]
    p = points[owner[pair]]
    ab = b - a
    s = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    dist = np.linalg.norm(p - a - s[:, None] * ab, axis=1)
    order = np.lexsort((dist, pair))
    best = order[np.searchsorted(pair[order], np.arange(len(face)))] if len(face) else order
    h_best, s_best, d_best = h[best], s[best], dist[best]
    length = np.linalg.norm(ab[best], axis=1)

    n = scene.face_normal[face]
    first_ray = np.empty((len(face), 3))
    span = np.empty(len(face))
    # inside the face: the whole plane
    inside = d_best > tol
    u = np.cross(n[inside], np.eye(3)[np.argmin(np.abs(n[inside]), axis=1)])
    first_ray[inside] = _unit(u) if len(u) else u
    span[inside] = 2 * np.pi
    # at a corner: between the edge leaving it and the one arriving (reversed)
    prev = np.empty_like(he.next)
    prev[he.next] = np.arange(len(he.next))
    at_start = ~inside & (s_best * length <= tol)
    at_end = ~inside & ~at_start & ((1 - s_best) * length <= tol)
    corner_h = np.where(at_end, he.next[h_best], h_best)
    corner = at_start | at_end
    ch = corner_h[corner]
    leave = _unit(scene.vertices[he.end[ch]] - scene.vertices[he.start[ch]])
    arrive = _unit(scene.vertices[he.start[prev[ch]]] - scene.vertices[he.start[ch]])
    nc = n[corner]
    first_ray[corner] = leave
    span[corner] = np.arctan2(np.einsum("ij,ij->i", arrive, np.cross(nc, leave)), np.einsum("ij,ij->i", arrive, leave)) % (2 * np.pi)
    # on an edge: the half-plane on the face's side (faces lie left of their half-edges)
    edge = ~inside & ~corner
    first_ray[edge] = _unit(ab[best][edge])
    span[edge] = np.pi
    offsets = np.searchsorted(owner, np.arange(len(points) + 1))
    return Wedges(offsets=offsets, face=face, first=first_ray, normal=n, span=span)
