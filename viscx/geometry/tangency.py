"""Tangency of lines at generators (design notes §2, docs/skeleton.md).

Faces are two-sided and all space off the faces is free. A line through a point
p of the surface is *tangent* there (it may pass on) when the surface does not
separate its two rays at p; otherwise it crosses the surface at p and is
blocked there on both sides.

The test is one rule for every situation. Every face touching p is, near p, a
planar wedge with apex p (a corner, a half-plane, or the whole plane:
:mod:`viscx.scene.neighbourhood`). Shift the line sideways by a tiny vector u;
the shifted line meets a wedge exactly when u lies in the wedge's projection
along the line onto the plane ⊥ d, an angular interval of directions about d.
So the surface separates the line's rays at p — every shifted line hits it —
exactly when those intervals cover the whole circle.

* At an edge with two faces this is the classic test: tangent iff both faces lie
  on one side of the plane spanned by the line and the edge (their projected
  half-planes then overlap instead of covering the circle).
* At a vertex it holds for any fan, open or closed, manifold or not.
* It sees faces the half-edge structure does not connect: a block's bottom edge
  lying inside a floor, a wall's corner on another wall's edge.

A line lying on a touching face near p (within ``angle_tol`` of its plane and
inside its wedge), or along an edge at p, is *degenerate* (grazing); callers
decide what grazing means (docs/skeleton.md).
"""

import numpy as np
from numba import njit

from viscx.scene.neighbourhood import surface_wedges

TWO_PI = 2 * np.pi


@njit(cache=True)
def _separation(offsets, first, normal, span, directions, angle_tol):
    q = directions.shape[0]
    blocked = np.zeros(q, dtype=np.bool_)
    degenerate = np.zeros(q, dtype=np.bool_)
    for i in range(q):
        d = directions[i] / np.sqrt((directions[i] ** 2).sum())
        helper = np.zeros(3)
        helper[np.argmin(np.abs(d))] = 1.0
        e1 = np.cross(d, helper)
        e1 /= np.sqrt((e1 ** 2).sum())
        e2 = np.cross(d, e1)
        k0, k1 = offsets[i], offsets[i + 1]
        starts = np.empty(k1 - k0)
        lengths = np.empty(k1 - k0)
        m = 0
        full = False
        for k in range(k0, k1):
            n = normal[k]
            a = first[k]
            sp = span[k]
            nxa = np.cross(n, a)
            c = (n * d).sum()
            whole = sp >= TWO_PI - 1e-12
            b = np.cos(sp) * a + np.sin(sp) * nxa
            if not whole:
                # the line runs along one of the wedge's edges
                if np.sqrt((np.cross(a, d) ** 2).sum()) <= angle_tol or np.sqrt((np.cross(b, d) ** 2).sum()) <= angle_tol:
                    degenerate[i] = True
            if abs(c) <= angle_tol:
                # d lies in the face's plane: the line lies on the face if ±d is in the wedge
                for sign in (1.0, -1.0):
                    ang = np.arctan2(sign * (d * nxa).sum(), sign * (d * a).sum()) % TWO_PI
                    if whole or ang <= sp + angle_tol or ang >= TWO_PI - angle_tol:
                        degenerate[i] = True
                continue
            if whole:
                full = True
                continue
            ta = np.arctan2((a * e2).sum(), (a * e1).sum())
            tb = np.arctan2((b * e2).sum(), (b * e1).sum())
            # the projection along d keeps the wedge's orientation iff n · d > 0
            if c > 0:
                starts[m] = ta % TWO_PI
                lengths[m] = (tb - ta) % TWO_PI
            else:
                starts[m] = tb % TWO_PI
                lengths[m] = (ta - tb) % TWO_PI
            if sp > np.pi and lengths[m] <= np.pi:  # rounding at a reflex wedge
                lengths[m] = TWO_PI - lengths[m]
            m += 1
        if full:
            blocked[i] = True
            continue
        if m == 0:
            continue
        # do the intervals cover the circle? sweep from the smallest start, with copies shifted by 2π
        order = np.argsort(starts[:m])
        s = np.concatenate((starts[:m][order], starts[:m][order] + TWO_PI))
        ln = np.concatenate((lengths[:m][order], lengths[:m][order]))
        reach = s[0] + ln[0]
        for j in range(1, 2 * m):
            if s[j] > reach + angle_tol:
                break
            reach = max(reach, s[j] + ln[j])
        blocked[i] = reach >= s[0] + TWO_PI - angle_tol
    return blocked, degenerate


def tangent_at_points(scene, points, directions, angle_tol=1e-9):
    """Whether the line through each point along each direction passes there.

    Parameters
    ----------
    scene : Scene
    points : (q, 3) float
        Points of the surface (vertices, points of edges).
    directions : (q, 3) float

    Returns
    -------
    tangent : (q,) bool
        The surface does not separate the line's two rays at the point (faces
        the line lies on are left out of that decision).
    degenerate : (q,) bool
        The line lies on a face touching the point, or along an edge there.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    directions = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    w = surface_wedges(scene, points)
    blocked, degenerate = _separation(
        w.offsets, np.ascontiguousarray(w.first), np.ascontiguousarray(w.normal), w.span, directions, angle_tol
    )
    return ~blocked, degenerate


def tangent_at_vertices(scene, vertices, directions, angle_tol=1e-9):
    """:func:`tangent_at_points` at vertices; the wedges of a vertex repeated in the
    queries are found once.

    Parameters
    ----------
    vertices : (q,) int
    directions : (q, 3) float
    """
    unique, which = np.unique(np.asarray(vertices, dtype=np.int64), return_inverse=True)
    which = which.reshape(-1)
    w = surface_wedges(scene, scene.vertices[unique])
    count = np.diff(w.offsets)[which]
    offsets = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
    rows = np.repeat(w.offsets[which], count) + np.arange(offsets[-1]) - np.repeat(offsets[:-1], count)
    directions = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    blocked, degenerate = _separation(
        offsets, np.ascontiguousarray(w.first[rows]), np.ascontiguousarray(w.normal[rows]), w.span[rows], directions,
        angle_tol,
    )
    return ~blocked, degenerate


def tangent_at_edges(scene, edges, directions, points=None, angle_tol=1e-9):
    """:func:`tangent_at_points` at points of edges.

    Parameters
    ----------
    edges : (q,) int
        Undirected edge ids.
    directions : (q, 3) float
    points : (q, 3) float, optional
        Where each line meets its edge (default: the edge's midpoint). It
        matters where the edge runs partly across another face.
    """
    if points is None:
        ev = scene.half_edges.edge_vertices[np.asarray(edges, dtype=np.int64)]
        points = 0.5 * (scene.vertices[ev[:, 0]] + scene.vertices[ev[:, 1]])
    return tangent_at_points(scene, points, directions, angle_tol)
