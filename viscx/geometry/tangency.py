"""Tangency of lines at generator edges (design notes §2).

A line through a point of edge e is *tangent* at e when all faces of e lie on one
side of the plane spanned by the line and e: it touches the surface along e
without passing through it. A boundary edge (one face) always qualifies. A line
lying in a face's plane counts as tangent to it (it grazes that face).
"""

import numpy as np


def edge_face_directions(scene):
    """For every half-edge, the unit in-plane direction from its edge into its face.

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    (h, 3) float
        ``n_face × (end - start)``, normalised: faces lie on the left of their
        half-edges seen from the face normal.
    """
    he = scene.half_edges
    w = np.cross(scene.face_normal[he.face], scene.vertices[he.end] - scene.vertices[he.start])
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def edge_half_edges(scene):
    """CSR from undirected edges to their half-edges: (offsets (e + 1,), half-edges (h,))."""
    he = scene.half_edges
    order = np.argsort(he.edge, kind="stable")
    offsets = np.searchsorted(he.edge[order], np.arange(len(he.edge_vertices) + 1))
    return offsets, order


def tangent_at_edges(scene, edges, directions, angle_tol=1e-9):
    """Whether lines along ``directions`` through edges ``edges`` are tangent there.

    Parameters
    ----------
    scene : Scene
    edges : (n,) int
        Undirected edge ids.
    directions : (n, 3) float
        Line directions (any length, not parallel to the edge).
    angle_tol : float
        |sin| of the angle between a face and the line–edge plane below which the
        face counts as lying in that plane (the line grazes it).

    Returns
    -------
    tangent : (n,) bool
    degenerate : (n,) bool
        The line grazes a face of the edge.
    """
    offsets, order = edge_half_edges(scene)
    w = edge_face_directions(scene)
    ev = scene.half_edges.edge_vertices[edges]
    along = scene.vertices[ev[:, 1]] - scene.vertices[ev[:, 0]]
    m = np.cross(directions, along)
    size = np.linalg.norm(m, axis=1, keepdims=True)
    along_edge = size[:, 0] <= 1e-12 * np.linalg.norm(along, axis=1) * np.linalg.norm(directions, axis=1)
    m /= np.where(along_edge[:, None], 1.0, size)
    counts = offsets[edges + 1] - offsets[edges]
    owner = np.repeat(np.arange(len(edges)), counts)
    first = np.repeat(offsets[edges], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
    s = np.einsum("ij,ij->i", m[owner], w[order[first]])
    pos = np.zeros(len(edges), dtype=bool)
    neg = np.zeros(len(edges), dtype=bool)
    graze = np.zeros(len(edges), dtype=bool)
    np.logical_or.at(pos, owner, s > angle_tol)
    np.logical_or.at(neg, owner, s < -angle_tol)
    np.logical_or.at(graze, owner, np.abs(s) <= angle_tol)
    graze |= along_edge  # the line contains the edge: no plane is spanned
    return ~(pos & neg), graze


# Sides of a vertex along a direction (see classify_vertex_directions).
OUTSIDE, INSIDE, ON_SURFACE = 0, 1, 2


def vertex_corners(scene):
    """CSR from vertices to the face corners at them.

    The corner of half-edge ``h`` sits at ``start[h]`` between ``h`` (leaving) and
    the half-edge before it in its loop (arriving).

    Returns
    -------
    offsets : (n + 1,) int
    corners : (h,) int
        Half-edge ids, grouped by start vertex.
    prev : (h,) int
        The half-edge before each half-edge in its loop.
    """
    he = scene.half_edges
    prev = np.empty_like(he.next)
    prev[he.next] = np.arange(len(he.next))
    order = np.argsort(he.start, kind="stable")
    offsets = np.searchsorted(he.start[order], np.arange(scene.n_vertices + 1))
    return offsets, order, prev


def closed_fan(scene):
    """(n,) bool: vertices whose incident edges all have exactly two faces, consistently wound.

    Only around such a vertex does the surface separate a small ball into an
    inside (behind the face normals) and an outside.
    """
    he = scene.half_edges
    bad = (he.opp < 0) | (he.start[np.maximum(he.opp, 0)] != he.end)
    closed = np.ones(scene.n_vertices, dtype=bool)
    closed[he.start[bad]] = False
    closed[he.end[bad]] = False
    return closed


def classify_vertex_directions(scene, vertices, directions, angle_tol=1e-9):
    """On which side of the surface at each vertex a ray along each direction leaves.

    The face corners at v are arcs on the sphere of directions around v. The side
    of a direction d is read off the nearest point of that fan (the pseudo-normal
    test): if it lies inside a corner's arc the side is the sign of d · n for that
    face's normal n; if it is an edge direction shared by two corners, the sign of
    (d - e) · (n1 + n2). Faces' normals are taken to point out of the solid, so
    INSIDE means the ray enters the material at v. A vertex whose fan is not
    closed (boundary or non-manifold edges, inconsistent winding) encloses
    nothing: every direction is OUTSIDE.

    Parameters
    ----------
    scene : Scene
    vertices : (q,) int
    directions : (q, 3) float
    angle_tol : float
        Directions within this angle of the fan are ON_SURFACE (grazing).

    Returns
    -------
    (q,) int8
        OUTSIDE, INSIDE or ON_SURFACE.
    """
    vertices = np.asarray(vertices, dtype=np.int64)
    d = np.asarray(directions, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    he = scene.half_edges
    offsets, corners, prev = vertex_corners(scene)
    counts = offsets[vertices + 1] - offsets[vertices]
    owner = np.repeat(np.arange(len(vertices)), counts)
    h = corners[np.repeat(offsets[vertices], counts) + np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)]
    v = scene.vertices[he.start[h]]
    n = scene.face_normal[he.face[h]]
    a = scene.vertices[he.end[h]] - v  # leaving edge
    b = scene.vertices[he.start[prev[h]]] - v  # arriving edge, reversed
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    q = d[owner]
    # angles measured counter-clockwise about n from a: the corner spans [0, span]
    a_perp = np.cross(n, a)
    span = np.arctan2(np.einsum("ij,ij->i", b, a_perp), np.einsum("ij,ij->i", b, a)) % (2 * np.pi)
    qp = q - np.einsum("ij,ij->i", q, n)[:, None] * n
    angle = np.arctan2(np.einsum("ij,ij->i", qp, a_perp), np.einsum("ij,ij->i", qp, a)) % (2 * np.pi)
    in_arc = angle <= span
    dist_face = np.arcsin(np.clip(np.abs(np.einsum("ij,ij->i", q, n)), 0, 1))
    dist_a = np.arccos(np.clip(np.einsum("ij,ij->i", q, a), -1, 1))
    dist_b = np.arccos(np.clip(np.einsum("ij,ij->i", q, b), -1, 1))
    # candidate features: the arc's interior (face), its two end directions (edges)
    dist = np.where(in_arc, dist_face, np.inf)
    feature_dist = np.stack([dist, dist_a, dist_b], axis=1)
    best_feature = np.argmin(feature_dist, axis=1)
    best = feature_dist[np.arange(len(h)), best_feature]
    # nearest feature per query
    order = np.lexsort((best, owner))
    first = order[np.unique(owner[order], return_index=True)[1]]
    out = np.full(len(vertices), OUTSIDE, dtype=np.int8)
    qi = owner[first]
    on = best[first] <= angle_tol
    face_side = np.einsum("ij,ij->i", q[first], n[first])
    # an edge direction's pseudo-normal: its two faces' normals summed
    edge_h = np.where(best_feature[first] == 1, h[first], prev[h[first]])
    other = he.opp[edge_h]
    pseudo = n[first] + scene.face_normal[he.face[np.maximum(other, 0)]]
    e = np.where((best_feature[first] == 1)[:, None], a[first], b[first])
    edge_side = np.einsum("ij,ij->i", q[first] - e, pseudo)
    side = np.where(best_feature[first] == 0, face_side, edge_side)
    out[qi] = np.where(on, ON_SURFACE, np.where(side < 0, INSIDE, OUTSIDE))
    out[~closed_fan(scene)[vertices] & (out == INSIDE)] = OUTSIDE
    return out


def tangent_at_vertices(scene, vertices, directions, angle_tol=1e-9):
    """Whether the line through each vertex along each direction is tangent there.

    Faces are two-sided and space off the faces is free, so what matters is only
    whether the surface separates the line's two rays at v: tangent when both
    rays leave into the same region of v's fan (always, for an open fan); else
    the line crosses the surface at v and v blocks it on both sides (seed 000
    §4.1, "v is the up blocker"). Edges follow the same rule
    (:func:`tangent_at_edges`).

    Parameters
    ----------
    scene : Scene
    vertices : (q,) int
    directions : (q, 3) float

    Returns
    -------
    tangent : (q,) bool
    degenerate : (q,) bool
        A ray grazes the fan (lies within ``angle_tol`` of a face or edge at v).
    """
    plus = classify_vertex_directions(scene, vertices, directions, angle_tol)
    minus = classify_vertex_directions(scene, vertices, -np.asarray(directions, dtype=np.float64), angle_tol)
    degenerate = (plus == ON_SURFACE) | (minus == ON_SURFACE)
    return (plus == minus) & ~degenerate, degenerate
