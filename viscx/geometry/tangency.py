"""Tangency of lines at generators (design decisions, Vocabulary: docs/references.md, docs/skeleton.md).

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

This module works on wedges alone (pure arrays); the wedges of a scene's vertices, edges
and surface points, and the tests there, are :mod:`viscx.scene.neighbourhood`'s
(:func:`~viscx.scene.neighbourhood.tangent_at_vertices` and its siblings).
"""

import numpy as np
from numba import njit

from viscx.tolerances import ANGLE_TOLERANCE

TWO_PI = 2 * np.pi


@njit(cache=True)
def _angle_about(x0, x1, x2, e1, e2):
    """Angle of x in the plane spanned by the orthonormal e1, e2."""
    return np.arctan2(x0 * e2[0] + x1 * e2[1] + x2 * e2[2], x0 * e1[0] + x1 * e1[1] + x2 * e1[2])


@njit(cache=True, nogil=True)
def _separation(lo_rows, hi_rows, first, normal, span, directions, angle_tol):
    """Scalar code with buffers allocated once: it runs for every sample of every family.
    The wedges of point i are rows ``lo_rows[i]:hi_rows[i]``.

    The wedges' rays are snapped before they are projected: rays of two wedges within
    ``angle_tol`` (chord) of each other are one ray of the surface (the edge two faces
    of a fan share, or a foreign face's edge through the point), and must project to
    one angle. Computed apart (the end ray is rebuilt from the first ray and the span,
    about 1e-15 off), a ray within δ of the line's direction projects with an error of
    about 1e-15 / δ: 2e-9 rad at δ = 2e-6 (random scene 19, vertex 2), a false gap in
    a closed fan, and the line was judged tangent where it enters a solid.
    """
    q = directions.shape[0]
    blocked = np.zeros(q, dtype=np.bool_)
    degenerate = np.zeros(q, dtype=np.bool_)
    most = 0
    for i in range(q):
        most = max(most, hi_rows[i] - lo_rows[i])
    starts = np.empty(2 * most)
    lengths = np.empty(2 * most)
    # rays of the point's wedges: (first, end) of each wedge, rows 2k and 2k + 1
    rays = np.empty((2 * most, 3))
    e1 = np.empty(3)
    e2 = np.empty(3)
    snap2 = angle_tol * angle_tol
    for i in range(q):
        norm = np.sqrt(directions[i, 0] ** 2 + directions[i, 1] ** 2 + directions[i, 2] ** 2)
        dx, dy, dz = directions[i, 0] / norm, directions[i, 1] / norm, directions[i, 2] / norm
        # e1 = d × (the axis d is least aligned with), e2 = d × e1
        ax, ay, az = abs(dx), abs(dy), abs(dz)
        if ax <= ay and ax <= az:
            e1[0], e1[1], e1[2] = 0.0, dz, -dy
        elif ay <= az:
            e1[0], e1[1], e1[2] = -dz, 0.0, dx
        else:
            e1[0], e1[1], e1[2] = dy, -dx, 0.0
        en = np.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
        e1[0], e1[1], e1[2] = e1[0] / en, e1[1] / en, e1[2] / en
        e2[0], e2[1], e2[2] = dy * e1[2] - dz * e1[1], dz * e1[0] - dx * e1[2], dx * e1[1] - dy * e1[0]
        lo = lo_rows[i]
        nw = hi_rows[i] - lo
        # the rays, each replaced by the first earlier ray it coincides with
        for k in range(nw):
            nx, ny, nz = normal[lo + k, 0], normal[lo + k, 1], normal[lo + k, 2]
            a0, a1, a2 = first[lo + k, 0], first[lo + k, 1], first[lo + k, 2]
            cs, sn = np.cos(span[lo + k]), np.sin(span[lo + k])
            # n × a: the wedge's plane is spanned by a and n × a
            m0, m1, m2 = ny * a2 - nz * a1, nz * a0 - nx * a2, nx * a1 - ny * a0
            rays[2 * k, 0], rays[2 * k, 1], rays[2 * k, 2] = a0, a1, a2
            rays[2 * k + 1, 0], rays[2 * k + 1, 1], rays[2 * k + 1, 2] = cs * a0 + sn * m0, cs * a1 + sn * m1, cs * a2 + sn * m2
        for r in range(1, 2 * nw):
            if span[lo + r // 2] >= TWO_PI - 1e-12:
                continue
            for t in range(r):
                if t // 2 == r // 2 or span[lo + t // 2] >= TWO_PI - 1e-12:
                    continue
                g0, g1, g2 = rays[r, 0] - rays[t, 0], rays[r, 1] - rays[t, 1], rays[r, 2] - rays[t, 2]
                if g0 * g0 + g1 * g1 + g2 * g2 <= snap2:
                    rays[r, 0], rays[r, 1], rays[r, 2] = rays[t, 0], rays[t, 1], rays[t, 2]
                    break
        m = 0
        full = False
        for k in range(nw):
            nx, ny, nz = normal[lo + k, 0], normal[lo + k, 1], normal[lo + k, 2]
            a0, a1, a2 = rays[2 * k, 0], rays[2 * k, 1], rays[2 * k, 2]
            b0, b1, b2 = rays[2 * k + 1, 0], rays[2 * k + 1, 1], rays[2 * k + 1, 2]
            sp = span[lo + k]
            m0, m1, m2 = ny * a2 - nz * a1, nz * a0 - nx * a2, nx * a1 - ny * a0
            c = nx * dx + ny * dy + nz * dz
            whole = sp >= TWO_PI - 1e-12
            if not whole:
                # the line runs along one of the wedge's edges
                xa = (a1 * dz - a2 * dy) ** 2 + (a2 * dx - a0 * dz) ** 2 + (a0 * dy - a1 * dx) ** 2
                xb = (b1 * dz - b2 * dy) ** 2 + (b2 * dx - b0 * dz) ** 2 + (b0 * dy - b1 * dx) ** 2
                if np.sqrt(xa) <= angle_tol or np.sqrt(xb) <= angle_tol:
                    degenerate[i] = True
            if abs(c) <= angle_tol:
                # d lies in the face's plane: the line lies on the face if ±d is in the wedge
                dm = dx * m0 + dy * m1 + dz * m2
                da = dx * a0 + dy * a1 + dz * a2
                for sign in (1.0, -1.0):
                    ang = np.arctan2(sign * dm, sign * da) % TWO_PI
                    if whole or ang <= sp + angle_tol or ang >= TWO_PI - angle_tol:
                        degenerate[i] = True
                continue
            if whole:
                full = True
                continue
            ta = _angle_about(a0, a1, a2, e1, e2)
            tb = _angle_about(b0, b1, b2, e1, e2)
            # the projection along d keeps the wedge's orientation iff n · d > 0
            if c > 0:
                st, ln = ta % TWO_PI, (tb - ta) % TWO_PI
            else:
                st, ln = tb % TWO_PI, (ta - tb) % TWO_PI
            if sp > np.pi and ln <= np.pi:  # rounding at a reflex wedge
                ln = TWO_PI - ln
            # insertion by start (few wedges per point)
            j = m
            while j > 0 and starts[j - 1] > st:
                starts[j], lengths[j] = starts[j - 1], lengths[j - 1]
                j -= 1
            starts[j], lengths[j] = st, ln
            m += 1
        if full:
            blocked[i] = True
            continue
        if m == 0:
            continue
        # do the intervals (starts in [0, 2π)) cover the circle? Sweep [0, 2π) from 0, covered
        # at first as far as the intervals wrapping past 2π reach: sweeping from the smallest
        # start alone missed a circle closed by a wrapping interval that covers that start
        # (a T-vertex: two half-planes and a quarter inside one of them)
        reach = 0.0
        for j in range(m):
            reach = max(reach, starts[j] + lengths[j] - TWO_PI)
        for j in range(m):
            if starts[j] > reach + angle_tol:
                break
            reach = max(reach, starts[j] + lengths[j])
        blocked[i] = reach >= TWO_PI - angle_tol
    return blocked, degenerate


def tangent_in_wedges(wedges, directions, angle_tol=ANGLE_TOLERANCE):
    """Whether the line along each direction passes the surface given by its wedges.

    Parameters
    ----------
    wedges : Wedges or WedgeRanges
        The surface around each query point (:mod:`viscx.scene.neighbourhood`).
    directions : (q, 3) float

    Returns
    -------
    tangent : (q,) bool
        The surface does not separate the line's two rays at the point (faces
        the line lies on are left out of that decision).
    degenerate : (q,) bool
        The line lies on a face touching the point, or along an edge there.
    """
    directions = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    lo, hi = wedges.ranges()
    blocked, degenerate = _separation(
        lo, hi, np.ascontiguousarray(wedges.first), np.ascontiguousarray(wedges.normal), wedges.span,
        directions, angle_tol,
    )
    return ~blocked, degenerate
