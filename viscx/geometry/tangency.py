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
        face counts as lying in that plane (on both sides).

    Returns
    -------
    (n,) bool
    """
    offsets, order = edge_half_edges(scene)
    w = edge_face_directions(scene)
    ev = scene.half_edges.edge_vertices[edges]
    along = scene.vertices[ev[:, 1]] - scene.vertices[ev[:, 0]]
    m = np.cross(directions, along)
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    counts = offsets[edges + 1] - offsets[edges]
    owner = np.repeat(np.arange(len(edges)), counts)
    first = np.repeat(offsets[edges], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
    s = np.einsum("ij,ij->i", m[owner], w[order[first]])
    pos = np.zeros(len(edges), dtype=bool)
    neg = np.zeros(len(edges), dtype=bool)
    np.logical_or.at(pos, owner, s > angle_tol)
    np.logical_or.at(neg, owner, s < -angle_tol)
    return ~(pos & neg)
