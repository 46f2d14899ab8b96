"""Flatland scenes: convex objects (circles, polygons, segments) that are disjoint or touch, plus the blue sky.

Every object is stored the same way, as a *rounded convex polygon*: support points
``v_0 .. v_{m-1}`` (counter-clockwise) and a radius ``r``.  A circle is one support point
(its centre) with ``r > 0``; a polygon is its corners with ``r = 0``; a segment is a two-corner polygon (its two sides are the two
"edges" p0 → p1 and p1 → p0, so its perimeter counts both sides: 2 × its length).  The support function
of object k in the direction e(φ) = (cos φ, sin φ) is then

    h_k(φ) = max_x x·e(φ) = v_j·e(φ) + r,    j = the support point active at φ,

and corner j of a polygon is active for φ between the outward normal angles of its two
incident edges.  Everything in the 2-D complex (tangency curves, bitangents, dual areas,
contact arc lengths) is a closed-form function of (v_j, r) on those φ pieces.

The blue sky is not stored: it is object id ``-1`` (``SKY``) wherever an object id is
expected.

Loaders: :func:`load_json`, :func:`load_svg`, :func:`load_dxf`, and :func:`load_scene`
which dispatches on the file suffix.  Bad input raises :class:`viscx.errors.ViscxError`.
"""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viscx.errors import ViscxError

SKY = -1
CIRCLE, POLYGON, SEGMENT = 0, 1, 2
# the gap that opens every contact (Scene.opened), relative to the scene diagonal: far above the
# 1e-9 line tolerance of the complex, far below any feature of a real layout (the build
# tries complex.OPEN_RELS in turn)
OPEN_REL = 1e-6
# two objects closer than this (× the scene diagonal) touch (check_disjoint): 4 × the line
# tolerance of the complex (complex.TOL_U, complex.JOIN), so that objects that touch one
# degenerate line within the tolerance on its two sides, overlapping along it, are a
# contact (opened by a gap γ), never two entries of one line at one point
CONTACT_TOL = 4e-9
TWO_PI = 2.0 * math.pi


@dataclass
class Scene:
    """A flatland scene.

    Attributes
    ----------
    kind : (n,) int8
        ``CIRCLE`` (0), ``POLYGON`` (1) or ``SEGMENT`` (2, two corners, two-sided).
    vert_start : (n + 1,) int64
        CSR offsets into ``verts``: object k owns ``verts[vert_start[k]:vert_start[k+1]]``.
    verts : (V, 2) float64
        Support points, counter-clockwise per object (a circle has one: its centre).
    radius : (n,) float64
        Rounding radius (circle radius; 0 for polygons).
    emission, reflectance : (n,) float64
        Emitted radiosity E and reflectance ρ ∈ [0, 1).
    names : list of str
        One name per object (used in error messages and plots).
    """

    kind: np.ndarray
    vert_start: np.ndarray
    verts: np.ndarray
    radius: np.ndarray
    emission: np.ndarray
    reflectance: np.ndarray
    names: list = field(default_factory=list)

    @property
    def n(self) -> int:
        return int(self.kind.shape[0])

    # -- derived, cached quantities -------------------------------------------------------
    def pieces(self):
        """Support-function pieces (see :func:`support_pieces`), cached."""
        if not hasattr(self, "_pieces"):
            self._pieces = support_pieces(self.vert_start, self.verts, self.radius)
        return self._pieces

    def object_hashes(self) -> np.ndarray:
        """(n,) uint64: a digest of each object's geometry (support points and radius), cached."""
        if not hasattr(self, "_hashes"):
            self._hashes = np.array([_geometry_hash(self.verts[self.vert_start[k]:self.vert_start[k + 1]],
                                                    self.radius[k]) for k in range(self.n)], np.uint64)
        return self._hashes

    def name_hashes(self) -> np.ndarray:
        """(n,) uint64: a digest of each object's name (stable when others move, appear or
        vanish), cached."""
        if not hasattr(self, "_name_hashes"):
            self._name_hashes = np.array([_text_hash(x) for x in self.names], np.uint64).reshape(-1)
        return self._name_hashes

    def perimeters(self) -> np.ndarray:
        """(n,) float64: boundary length L_k (= measure of the lines meeting O_k)."""
        return self.pieces()[3]

    def bounding_boxes(self) -> np.ndarray:
        """(n, 4) float64: xmin, ymin, xmax, ymax per object (cached; do not modify)."""
        if not hasattr(self, "_bboxes"):
            s = self.vert_start[:-1]
            r = self.radius[:, None]
            self._bboxes = np.concatenate([np.minimum.reduceat(self.verts, s, axis=0) - r,
                                           np.maximum.reduceat(self.verts, s, axis=0) + r], axis=1)
        return self._bboxes

    def object_polygon(self, k, samples=128) -> np.ndarray:
        """(m, 2) float64: the boundary of object k as a closed-ready polygon (circles sampled)."""
        v = self.verts[self.vert_start[k] : self.vert_start[k + 1]]
        if self.kind[k] == CIRCLE:
            a = np.linspace(0.0, TWO_PI, samples, endpoint=False)
            return v[0] + self.radius[k] * np.stack([np.cos(a), np.sin(a)], axis=1)
        return v.copy()

    def moved(self, k, dx, dy) -> "Scene":
        """A copy of the scene with object k translated by (dx, dy) (no overlap check);
        caches carried over (:meth:`replaced`), so a move costs O(size of k), not O(n)."""
        s, e = int(self.vert_start[k]), int(self.vert_start[k + 1])
        return self.replaced(k, self.verts[s:e] + (dx, dy), self.radius[k])

    def replaced(self, k, verts_k, radius_k) -> "Scene":
        """A copy with object k's support points (same count) and radius replaced.

        The cached support pieces, digests and bounding boxes are carried over with object
        k's entries alone recomputed (from its new corners, as a fresh scene would)."""
        s, e = int(self.vert_start[k]), int(self.vert_start[k + 1])
        verts, radius = self.verts.copy(), self.radius.copy()
        verts[s:e] = verts_k
        radius[k] = radius_k
        out = Scene(self.kind.copy(), self.vert_start.copy(), verts, radius,
                    self.emission.copy(), self.reflectance.copy(), list(self.names))
        if hasattr(self, "_pieces"):
            mine = support_pieces(np.array([0, e - s]), verts[s:e], radius[k:k + 1])
            pieces = [x.copy() for x in self._pieces]
            for whole, part in zip(pieces[:3], mine[:3]):
                whole[s:e] = part
            pieces[3][k] = mine[3][0]
            out._pieces = tuple(pieces)
        if hasattr(self, "_hashes"):
            out._hashes = self._hashes.copy()
            out._hashes[k] = _geometry_hash(verts[s:e], radius[k])
        if hasattr(self, "_name_hashes"):
            out._name_hashes = self._name_hashes
        if hasattr(self, "_bboxes"):
            bb = self._bboxes.copy()
            bb[k] = np.concatenate([verts[s:e].min(axis=0) - radius[k], verts[s:e].max(axis=0) + radius[k]])
            out._bboxes = bb
        return out

    def selected(self, keep) -> "Scene":
        """A copy holding the objects ``keep`` (ascending indices) alone, in that order,
        caches carried over per object (an object's cached entries depend on it alone)."""
        keep = np.asarray(keep, np.int64)
        size = np.diff(self.vert_start)[keep]
        vs = np.zeros(keep.size + 1, np.int64)
        np.cumsum(size, out=vs[1:])
        vi = np.repeat(self.vert_start[keep] - vs[:-1], size) + np.arange(vs[-1])
        out = Scene(self.kind[keep], vs, self.verts[vi], self.radius[keep], self.emission[keep],
                    self.reflectance[keep], [self.names[k] for k in keep])
        if hasattr(self, "_pieces"):
            out._pieces = tuple(x[vi] for x in self._pieces[:3]) + (self._pieces[3][keep],)
        if hasattr(self, "_hashes"):
            out._hashes = self._hashes[keep]
        if hasattr(self, "_name_hashes"):
            out._name_hashes = self._name_hashes[keep]
        if hasattr(self, "_bboxes"):
            out._bboxes = self._bboxes[keep]
        return out

    def joined(self, other: "Scene") -> "Scene":
        """A scene of this scene's objects followed by ``other``'s (caches carried over
        when both have them; contacts not checked)."""
        out = Scene(np.concatenate([self.kind, other.kind]),
                    np.concatenate([self.vert_start, other.vert_start[1:] + self.vert_start[-1]]),
                    np.concatenate([self.verts, other.verts]), np.concatenate([self.radius, other.radius]),
                    np.concatenate([self.emission, other.emission]),
                    np.concatenate([self.reflectance, other.reflectance]), list(self.names) + list(other.names))
        if hasattr(self, "_hashes"):
            out._hashes = np.concatenate([self._hashes, other.object_hashes()])
        if hasattr(self, "_name_hashes"):
            out._name_hashes = np.concatenate([self._name_hashes, other.name_hashes()])
        if hasattr(self, "_bboxes"):
            out._bboxes = np.concatenate([self._bboxes, other.bounding_boxes()])
        if hasattr(self, "_pieces"):
            out._pieces = tuple(np.concatenate([a, b]) for a, b in zip(self._pieces, other.pieces()))
        return out

    def contacts(self) -> np.ndarray:
        """(c, 2) int64: the pairs of objects that touch (i < j), cached
        (:func:`check_disjoint`; raises on an overlap)."""
        if not hasattr(self, "_contacts"):
            self._contacts = check_disjoint(self)
        return self._contacts

    def opened(self, rel=OPEN_REL) -> "Scene":
        """A copy in which every object that touches another is eroded by a small γ
        (``rel`` × the scene diagonal, at most a quarter of the object's width), so that
        every contact opens into a gap: the closing gap whose limit defines touching
        objects (docs/flatland.md).  Support points keep their indices and the edges
        their directions (a polygon's edges move inward by γ, corner j by
        γ (ν_{j−1} + ν_j) / (1 + ν_{j−1}·ν_j), ν the outward unit normals; a segment
        loses γ at each end; a circle's radius γ), so a support point of the opened
        scene names the same corner of the scene.  Convex sets shrunk into their
        interiors are disjoint when the originals only touched."""
        diag = self.diagonal()
        verts, radius = self.verts.copy(), self.radius.copy()
        for k in np.unique(self.contacts()):
            s, e = self.vert_start[k], self.vert_start[k + 1]
            verts[s:e], radius[k] = self.eroded(k, rel * diag)
        out = Scene(self.kind.copy(), self.vert_start.copy(), verts, radius, self.emission.copy(),
                    self.reflectance.copy(), list(self.names))
        left = check_disjoint(out, eps=0.01 * rel * diag)
        if left.size:
            raise_along(self, *left[0])
        return out

    def diagonal(self) -> float:
        """The diagonal of the scene's bounding box."""
        bb = self.bounding_boxes()
        return math.hypot(bb[:, 2].max() - bb[:, 0].min(), bb[:, 3].max() - bb[:, 1].min())

    def eroded(self, k, gap):
        """Object k shrunk by ``gap`` (at most a quarter of its width): (support points
        (m, 2), radius), as :meth:`opened` erodes it (it depends on the object and the gap
        alone)."""
        s, e = self.vert_start[k], self.vert_start[k + 1]
        v = self.verts[s:e]
        if self.kind[k] == CIRCLE:
            return v.copy(), self.radius[k] - min(gap, 0.25 * self.radius[k])
        edge = np.roll(v, -1, axis=0) - v
        length = np.hypot(edge[:, 0], edge[:, 1])
        if self.kind[k] == SEGMENT:
            g = min(gap, 0.1 * length[0])
            t = edge[0] / length[0]
            return v + np.array([g, -g])[:, None] * t, self.radius[k]
        nu = np.stack([edge[:, 1], -edge[:, 0]], 1) / length[:, None]
        width = min(np.max((v - v[j]) @ nu[j] * -1.0) for j in range(e - s))
        g = min(gap, 0.25 * width)
        prev = np.roll(nu, 1, axis=0)
        shift = (prev + nu) / (1.0 + np.einsum("ij,ij->i", prev, nu))[:, None]
        # a short edge between two sharp corners vanishes when eroded too far: keep
        # every edge's direction (halve γ until it does)
        while np.any(np.einsum("ij,ij->i", np.roll(v - g * shift, -1, axis=0) - (v - g * shift), edge) <= 0.0):
            g *= 0.5
        return v - g * shift, self.radius[k]

    def perturbed(self, rel=1e-7) -> "Scene":
        """A copy with every object rotated about its centre and translated by tiny,
        deterministic amounts (``rel`` × the scene diagonal; angles from the golden-ratio
        sequence), which breaks collinear edges of different objects (a degeneracy the
        complex does not resolve symbolically).  Form factors change by O(rel)."""
        bb = self.bounding_boxes()
        diag = math.hypot(bb[:, 2].max() - bb[:, 0].min(), bb[:, 3].max() - bb[:, 1].min())
        verts = self.verts.copy()
        g = (math.sqrt(5.0) - 1.0) / 2.0
        for k in range(self.n):
            s, e = self.vert_start[k], self.vert_start[k + 1]
            v = verts[s:e]
            c = v.mean(axis=0)
            size = max(np.ptp(v, axis=0).max() + 2 * self.radius[k], 1e-300)
            a = rel * diag / size * (((k + 1) * g) % 1.0 - 0.5) * 2.0
            ca, sa = math.cos(a), math.sin(a)
            d = v - c
            t = rel * diag * np.array([((k + 1) * g * g) % 1.0 - 0.5, ((k + 1) * g * g * g) % 1.0 - 0.5])
            verts[s:e] = c + t + np.stack([ca * d[:, 0] - sa * d[:, 1], sa * d[:, 0] + ca * d[:, 1]], axis=1)
        out = Scene(self.kind.copy(), self.vert_start.copy(), verts, self.radius.copy(), self.emission.copy(),
                    self.reflectance.copy(), list(self.names))
        check_disjoint(out)
        return out

    def to_json(self) -> dict:
        """The scene as the JSON document :func:`load_json` reads."""
        objs = []
        for k in range(self.n):
            v = self.verts[self.vert_start[k] : self.vert_start[k + 1]]
            o = {"name": self.names[k], "emission": float(self.emission[k]), "reflectance": float(self.reflectance[k])}
            if self.kind[k] == CIRCLE:
                o.update(type="circle", center=[float(v[0, 0]), float(v[0, 1])], radius=float(self.radius[k]))
            else:
                o.update(type="segment" if self.kind[k] == SEGMENT else "polygon", points=v.tolist())
            objs.append(o)
        return {"objects": objs}


def raise_along(scene, a, b):
    """The error of two objects that still meet once opened: they lie along each other."""
    raise ViscxError(f"objects {scene.names[a]!r} and {scene.names[b]!r} lie along each other (two segments "
                     "on one line, or a segment inside a polygon's edge twice): they overlap")


def _text_hash(text):
    """uint64 digest of a string."""
    import hashlib

    return np.frombuffer(hashlib.blake2b(text.encode("utf-8", "surrogatepass"), digest_size=8).digest(), np.uint64)[0]


def _geometry_hash(v, r):
    """uint64 digest of one object's support points and radius."""
    import hashlib

    h = hashlib.blake2b(digest_size=8)
    h.update(np.ascontiguousarray(v).tobytes())
    h.update(np.float64(r).tobytes())
    return np.frombuffer(h.digest(), np.uint64)[0]


def support_pieces(vert_start, verts, radius):
    """Angular pieces of every object's support function.

    Support point j of object k is active for φ in [A_j, A_{j+1}) (unwrapped, A_{j+1} =
    A_j + exterior angle at corner j, the pieces of one object span exactly 2π).  With
    them: ``cumG[j] = ∫_{A_0}^{A_j} h dφ`` and ``cumS[j]`` = boundary length from the
    contact point at A_0 to corner j.  A circle has one piece [0, 2π).

    Returns
    -------
    A, cumG, cumS : (V,) float64 ; perimeter : (n,) float64
    """
    V = verts.shape[0]
    n = vert_start.shape[0] - 1
    size = np.diff(vert_start)
    start = vert_start[:-1]
    # all objects at once (numpy over vertices; the running sums by position within each
    # object, so every object's values are what it gets alone: a moved object's pieces are
    # recomputed by itself, bit-identical)
    owner = np.repeat(np.arange(n), size)
    j = np.arange(V) - start[owner]
    nxt = np.where(j + 1 < size[owner], np.arange(V) + 1, start[owner])
    prv = np.where(j > 0, np.arange(V) - 1, start[owner] + size[owner] - 1)
    edge = verts[nxt] - verts                                   # edge j: v_j -> v_{j+1}
    alpha = np.arctan2(-edge[:, 0], edge[:, 1])                 # outward normal angle (dy, -dx)
    # corner j is active between the normals of edges j-1 and j
    ext = np.mod(alpha - alpha[prv], TWO_PI)                    # exterior angle at corner j
    a0 = np.mod(alpha[start + size - 1], TWO_PI)                # start of piece 0
    elen = np.hypot(edge[:, 0], edge[:, 1])
    A, cumG, cumS = np.zeros(V), np.zeros(V), np.zeros(V)
    perimeter = np.zeros(n)
    poly = size > 1
    for i in range(1, int(size.max()) if V else 0):             # Σ of the exterior angles before corner i
        at = start[size > i] + i
        A[at] = A[at - 1] + ext[at - 1]
    A += a0[owner]
    # ∫ v_j·e(φ) dφ = v_j·(sin φ, −cos φ) between the piece ends
    b = A + ext
    piece = verts[:, 0] * (np.sin(b) - np.sin(A)) - verts[:, 1] * (np.cos(b) - np.cos(A))
    for i in range(1, int(size.max()) if V else 0):
        at = start[size > i] + i
        cumG[at] = cumG[at - 1] + piece[at - 1]
        cumS[at] = cumS[at - 1] + elen[at - 1]                  # corner j after edges 0..j-1
    perimeter[poly] = [elen[a:b].sum() for a, b in zip(start[poly], (start + size)[poly])]
    perimeter[~poly] = TWO_PI * radius[~poly]
    A[~poly[owner]] = 0.0
    cumG[~poly[owner]] = 0.0
    return A, cumG, cumS, perimeter


# ----------------------------------------------------------------------------- building
def make_scene(objects) -> Scene:
    """Build and validate a :class:`Scene` from a list of object dicts.

    Each dict has ``type`` ("circle" with ``center``, ``radius``; "polygon" with
    ``points``; "segment" with two ``points``: a two-sided panel or wall), optional ``name``, ``emission`` (E ≥ 0, default 0) and ``reflectance``
    (0 ≤ ρ < 1, default 0.5).  Polygons are made counter-clockwise; a non-convex polygon,
    a degenerate object or two overlapping objects raise ViscxError naming them.
    """
    if not isinstance(objects, (list, tuple)) or len(objects) == 0:
        raise ViscxError("flatland scene has no objects")
    kinds, starts, verts, radius, E, rho, names = [], [0], [], [], [], [], []
    for o, name in _pieces_of(objects):
        t = o.get("type")
        try:
            if t == "circle":
                c = np.asarray(o["center"], dtype=float).reshape(2)
                r = float(o["radius"])
                if not (np.all(np.isfinite(c)) and math.isfinite(r) and r > 0):
                    raise ViscxError(f"object {name!r}: a circle needs a finite centre and a radius > 0")
                kinds.append(CIRCLE)
                verts.append(c[None, :])
                radius.append(r)
            elif t == "polygon":
                p = np.asarray(o["points"], dtype=float)
                if p.ndim != 2 or p.shape[1] != 2 or not np.all(np.isfinite(p)):
                    raise ViscxError(f"object {name!r}: 'points' must be a list of finite [x, y] pairs")
                kinds.append(POLYGON)
                verts.append(_convex_ccw(p, name))
                radius.append(0.0)
            elif t in ("segment", "polyline"):
                kinds.append(SEGMENT)
                verts.append(_segment(o["points"], name))
                radius.append(0.0)
            else:
                raise ViscxError(f"object {name!r}: unknown type {t!r} (expected 'circle', 'polygon' or 'segment')")
            e = float(o.get("emission", 0.0))
            r_ = float(o.get("reflectance", 0.5))
        except (KeyError, TypeError, ValueError) as exc:
            raise ViscxError(f"object {name!r}: bad or missing field ({exc})") from None
        if not (math.isfinite(e) and e >= 0):
            raise ViscxError(f"object {name!r}: emission must be finite and >= 0")
        if not (0.0 <= r_ < 1.0):
            raise ViscxError(f"object {name!r}: reflectance must be in [0, 1)")
        starts.append(starts[-1] + len(verts[-1]))
        E.append(e)
        rho.append(r_)
        names.append(name)
    if len(set(names)) != len(names):
        dup = sorted({x for x in names if names.count(x) > 1})[0]
        raise ViscxError(f"two objects are named {dup!r}; names must be unique")
    scene = Scene(np.array(kinds, dtype=np.int8), np.array(starts, dtype=np.int64), np.concatenate(verts),
                  np.array(radius), np.array(E), np.array(rho), names)
    scene._contacts = check_disjoint(scene)
    return scene


def _pieces_of(objects):
    """(object dict, name) of every object, an open polyline of m > 1 segments
    split into its m pieces (segments named ``name[0]`` .. ``name[m-1]``, touching at the
    shared corners: point contacts, docs/flatland.md)."""
    for i, o in enumerate(objects):
        if not isinstance(o, dict):
            raise ViscxError(f"object {i} is not a JSON object")
        name = str(o.get("name", f"object{i}"))
        pts = o.get("points") if o.get("type") in ("segment", "polyline") else None
        if isinstance(pts, (list, tuple)) and len(pts) > 2:
            for j in range(len(pts) - 1):
                yield dict(o, type="segment", points=[pts[j], pts[j + 1]]), f"{name}[{j}]"
        else:
            yield o, name


def _off_line(p):
    """How far (twice an area) the corners ``p`` (k, 2) stray from the line of the first two."""
    d = p[1] - p[0]
    return float(np.abs(d[0] * (p[:, 1] - p[0, 1]) - d[1] * (p[:, 0] - p[0, 0])).max())


def _segment(points, name):
    """(2, 2) float64 ends of a segment object, or ViscxError (open polylines of several
    segments are split into pieces before, :func:`_pieces_of`)."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or not np.all(np.isfinite(p)):
        raise ViscxError(f"object {name!r}: 'points' must be a list of finite [x, y] pairs")
    if len(p) != 2:
        raise ViscxError(f"object {name!r}: a segment or polyline needs at least 2 points")
    if np.all(p[0] == p[1]):
        raise ViscxError(f"object {name!r}: the two ends of a segment coincide")
    return p


def _convex_ccw(p, name, eps=1e-12):
    """(m, 2) float64 counter-clockwise corners of a strictly convex polygon, or ViscxError.

    Repeated closing points and collinear corners are dropped (a flat corner is not a
    corner of the support function)."""
    if len(p) > 1 and np.allclose(p[0], p[-1]):
        p = p[:-1]
    # drop consecutive duplicates
    keep = np.ones(len(p), bool)
    keep[1:] = np.any(np.abs(np.diff(p, axis=0)) > 0, axis=1)
    p = p[keep]
    scale = max(np.ptp(p, axis=0).max() if len(p) else 0.0, 1e-300)
    area2 = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]) if len(p) >= 3 else 0.0
    if len(p) < 3 or abs(area2) <= eps * scale * scale:
        # zero signed area from corners off one line: the outline crosses itself (a bow tie)
        if len(p) >= 4 and _off_line(p) > eps * scale * scale:
            raise ViscxError(f"object {name!r} is not convex (self-intersecting outline)")
        raise ViscxError(f"object {name!r}: a polygon needs at least 3 non-collinear points")
    if area2 < 0:
        p = p[::-1]
    # cross product at each corner: > 0 convex, ~0 flat (dropped), < 0 reflex (rejected)
    a, b = p - np.roll(p, 1, axis=0), np.roll(p, -1, axis=0) - p
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    tol = eps * scale * scale
    if np.any(cross < -tol):
        raise ViscxError(f"object {name!r} is not convex (reflex corner at {p[np.argmin(cross)].tolist()})")
    p = p[cross > tol]
    # a convex polygon turns exactly once around
    e = np.roll(p, -1, axis=0) - p
    ang = np.arctan2(e[:, 1], e[:, 0])
    turn = np.mod(np.diff(np.concatenate([ang, ang[:1]])), TWO_PI).sum()
    if abs(turn - TWO_PI) > 1e-6:
        raise ViscxError(f"object {name!r} is not convex (self-intersecting outline)")
    return p


def _sat_eps(scene, eps):
    return CONTACT_TOL * max(scene.diagonal(), 1e-300) if eps is None else eps


def check_disjoint(scene: Scene, eps=None) -> np.ndarray:
    """Raise ViscxError naming the first two objects that overlap; return the pairs that
    touch, (c, 2) int64 (i < j, ascending).

    Separating-axis test: two convex objects are disjoint iff some direction separates
    them; for circle/rounded polygons the candidate axes are the polygons' edge normals
    and the directions between support points (exact for circles and polygons).  The
    largest gap over the axes is > eps for disjoint objects, within ±eps for touching
    ones (a point or an edge in common, interiors disjoint), < −eps for overlapping
    ones.  Touching objects are the limit of a closing gap (docs/flatland.md)."""
    bb = scene.bounding_boxes()
    eps = _sat_eps(scene, eps)
    touch = []
    # broad phase: overlapping bounding boxes
    order = np.argsort(bb[:, 0], kind="stable")
    for ii, i in enumerate(order):
        for j in order[ii + 1:]:
            if bb[j, 0] > bb[i, 2] + eps:
                break
            if bb[j, 1] > bb[i, 3] + eps or bb[i, 1] > bb[j, 3] + eps:
                continue
            _pair_contact(scene, int(i), int(j), eps, touch)
    return np.array(sorted(touch), np.int64).reshape(-1, 2)


def check_object_disjoint(scene: Scene, k: int, eps=None) -> np.ndarray:
    """:func:`check_disjoint` for the pairs of object k alone (the others are known
    disjoint or touching): raises on an overlap, returns k's touching pairs (c, 2)."""
    bb = scene.bounding_boxes()
    eps = _sat_eps(scene, eps)
    near = np.nonzero((bb[:, 0] <= bb[k, 2] + eps) & (bb[k, 0] <= bb[:, 2] + eps)
                      & (bb[:, 1] <= bb[k, 3] + eps) & (bb[k, 1] <= bb[:, 3] + eps))[0]
    touch = []
    for j in near:
        if j != k:
            _pair_contact(scene, int(k), int(j), eps, touch)
    return np.array(sorted(touch), np.int64).reshape(-1, 2)


def _pair_contact(scene, i, j, eps, touch):
    """Append (min, max) to ``touch`` if objects i, j touch; raise if they overlap."""
    gap = _separation(scene, i, j)
    if gap > eps:
        return
    a, b = sorted((i, j))
    if gap < -eps:
        raise ViscxError(f"objects {scene.names[a]!r} and {scene.names[b]!r} overlap; "
                         "flatland objects must not overlap (they may touch)")
    touch.append((a, b))


def _separation(scene, i, j):
    """The largest gap between objects i and j over the separating-axis candidates."""
    vi = scene.verts[scene.vert_start[i]:scene.vert_start[i + 1]]
    vj = scene.verts[scene.vert_start[j]:scene.vert_start[j + 1]]
    ri, rj = scene.radius[i], scene.radius[j]
    axes = []
    for v in (vi, vj):
        if len(v) > 1:
            e = np.roll(v, -1, axis=0) - v
            axes.append(np.stack([e[:, 1], -e[:, 0]], axis=1))
    d = (vj[None, :, :] - vi[:, None, :]).reshape(-1, 2)
    axes.append(d)
    ax = np.concatenate(axes)
    nrm = np.hypot(ax[:, 0], ax[:, 1])
    ax = ax[nrm > 0] / nrm[nrm > 0, None]
    if ax.shape[0] == 0:  # two circles with one centre: no axis separates them
        return -(ri + rj)
    pi = vi @ ax.T
    pj = vj @ ax.T
    gap1 = pj.min(axis=0) - rj - (pi.max(axis=0) + ri)
    gap2 = pi.min(axis=0) - ri - (pj.max(axis=0) + rj)
    return float(np.max(np.maximum(gap1, gap2)))


# ----------------------------------------------------------------------------- loaders
def load_scene(path) -> Scene:
    """Load a flatland scene from ``.json``, ``.svg`` or ``.dxf`` (by suffix)."""
    path = Path(path)
    if not path.is_file():
        raise ViscxError(f"no such scene file: {path}")
    suffix = path.suffix.lower()
    loaders = {".json": load_json, ".svg": load_svg, ".dxf": load_dxf}
    if suffix in loaders:
        try:
            return loaders[suffix](path)
        except ViscxError as exc:  # the one line names the file
            if str(path) in str(exc):
                raise
            raise ViscxError(f"{path}: {exc}") from None
    raise ViscxError(f"{path}: unknown flatland scene type {suffix!r} (expected .json, .svg or .dxf)")


def load_json(path) -> Scene:
    """JSON: ``{"objects": [{"type": "circle", "center": [x, y], "radius": r, "emission": E,
    "reflectance": ρ, "name": ...}, {"type": "polygon", "points": [[x, y], ...], ...},
    {"type": "segment", "points": [[x0, y0], [x1, y1]], ...}]}``."""
    from viscx.formats.validate import load_json as load_bounded

    try:
        doc = load_bounded(Path(path).read_text(), f"{path}: the JSON scene")  # nesting bounded
    except (OSError, UnicodeDecodeError) as exc:
        raise ViscxError(f"{path}: not a readable JSON file ({exc})") from None
    if not isinstance(doc, dict) or "objects" not in doc:
        raise ViscxError(f"{path}: a flatland JSON scene needs an 'objects' list")
    return make_scene(doc["objects"])


_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _floats(text):
    return [float(x) for x in re.findall(_NUM, text or "")]


def _svg_material(el, name):
    out = {}
    for key, attr in (("emission", "emission"), ("reflectance", "reflectance")):
        val = el.get(attr, el.get(f"data-{attr}"))
        if val is not None:
            try:
                out[key] = float(val)
            except ValueError:
                raise ViscxError(f"SVG element {name!r}: {attr}={val!r} is not a number") from None
    return out


def _path_points(d, name):
    """Points of an SVG path made of straight segments only (M/L/H/V/Z, absolute or relative)."""
    tokens = re.findall(r"[A-Za-z]|" + _NUM, d or "")
    pts, cur, start, cmd, i, closed = [], np.zeros(2), None, None, 0, False
    while i < len(tokens):
        t = tokens[i]
        if t.isalpha():
            cmd = t
            i += 1
            if cmd in "Zz":
                closed = True
                if start is not None:
                    cur = start.copy()
            elif cmd not in "MmLlHhVv":
                raise ViscxError(f"SVG path {name!r}: curved or unsupported path command {cmd!r} "
                                 "(only straight segments M, L, H, V, Z)")
            continue
        if cmd is None:
            raise ViscxError(f"SVG path {name!r}: path data must start with a command")
        if closed and cmd not in "Mm":
            raise ViscxError(f"SVG path {name!r}: one closed outline per path")
        rel = cmd.islower()
        if cmd in "MmLl":
            x, y = float(tokens[i]), float(tokens[i + 1])
            i += 2
            cur = cur + (x, y) if rel else np.array([x, y])
            if cmd in "Mm":
                if pts:
                    raise ViscxError(f"SVG path {name!r}: one outline per path (several 'M' found)")
                start = cur.copy()
                cmd = "l" if rel else "L"
        elif cmd in "Hh":
            x = float(tokens[i]); i += 1
            cur = np.array([cur[0] + x if rel else x, cur[1]])
        else:
            y = float(tokens[i]); i += 1
            cur = np.array([cur[0], cur[1] + y if rel else y])
        pts.append(cur.copy())
    return np.array(pts), closed


def load_svg(path) -> Scene:
    """SVG: ``circle``, ``rect``, ``polygon`` and ``path`` (straight segments, closed) become
    objects, and ``line``, two-point ``polyline`` and open two-point ``path`` segments; ``emission``/``reflectance`` (or ``data-emission``/``data-reflectance``)
    attributes set the material; ``id`` names the object.  Ellipses, curved paths and
    transforms are rejected with a clear error."""
    try:
        root = ET.parse(str(path)).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ViscxError(f"{path}: not a readable SVG file ({exc})") from None
    objs = []
    for el in root.iter():
        tag = el.tag.rsplit("}", 1)[-1]
        name = el.get("id") or f"{tag}{len(objs)}"
        if el.get("transform"):  # on a shape or on a group (<g>) holding shapes
            raise ViscxError(f"SVG element {name!r}: transforms are not supported; apply them first")
        if tag == "ellipse":
            raise ViscxError(f"SVG element {name!r}: ellipses are not supported (use a circle or a polygon)")
        try:
            if tag == "circle":
                o = {"type": "circle", "center": [float(el.get("cx", 0)), float(el.get("cy", 0))],
                     "radius": float(el.get("r"))}
            elif tag == "rect":
                x, y = float(el.get("x", 0)), float(el.get("y", 0))
                w, h = float(el.get("width")), float(el.get("height"))
                if el.get("rx") or el.get("ry"):
                    raise ViscxError(f"SVG rect {name!r}: rounded corners are curves and are not supported")
                o = {"type": "polygon", "points": [[x, y], [x + w, y], [x + w, y + h], [x, y + h]]}
            elif tag == "polygon":
                f = _floats(el.get("points"))
                if len(f) % 2:
                    raise ViscxError(f"SVG polygon {name!r}: odd number of coordinates")
                o = {"type": "polygon", "points": np.array(f).reshape(-1, 2).tolist()}
            elif tag == "path":
                pts, closed = _path_points(el.get("d"), name)
                o = {"type": "polygon" if closed else "segment", "points": pts.tolist()}
            elif tag == "line":
                o = {"type": "segment", "points": [[float(el.get("x1", 0)), float(el.get("y1", 0))],
                                                   [float(el.get("x2", 0)), float(el.get("y2", 0))]]}
            elif tag == "polyline":
                f = _floats(el.get("points"))
                if len(f) % 2:
                    raise ViscxError(f"SVG polyline {name!r}: odd number of coordinates")
                o = {"type": "segment", "points": np.array(f).reshape(-1, 2).tolist()}
            else:
                continue
        except (TypeError, ValueError, IndexError):
            raise ViscxError(f"SVG element {name!r}: missing or malformed geometry attributes") from None
        o["name"] = name
        o.update(_svg_material(el, name))
        objs.append(o)
    if not objs:
        raise ViscxError(f"{path}: no circle, rect, polygon, path or line elements found")
    return make_scene(objs)


def load_dxf(path, emission=0.0, reflectance=0.5) -> Scene:
    """DXF 2-D plans via trimesh's path loader: every closed outline (trimesh traces
    connected lines and polylines into closed paths; curves come discretised) must be
    convex and becomes a polygon object named ``outline<i>``; an entity in no closed
    outline (a LINE, a two-point open polyline) becomes a segment.  Materials: E = 0, ρ = 0.5."""
    try:
        import trimesh
        p = trimesh.load_path(str(path))
    except Exception as exc:  # trimesh raises many kinds on bad files
        raise ViscxError(f"{path}: not a readable DXF file ({type(exc).__name__}: {exc})") from None
    objs = []
    try:
        loops = list(p.discrete)
        # entities in no closed path (LINEs, open polylines): segments
        loops += [p.entities[e].discrete(p.vertices) for e in p.dangling]
    except Exception as exc:  # trimesh's path graph code raises various kinds
        raise ViscxError(f"{path}: DXF outlines could not be traced ({type(exc).__name__}: {exc})") from None
    for i, pts in enumerate(loops):
        pts = np.asarray(pts, dtype=float)[:, :2]
        closed = len(pts) >= 4 and np.allclose(pts[0], pts[-1])
        objs.append({"type": "polygon" if closed else "segment", "points": (pts[:-1] if closed else pts).tolist(),
                     "name": f"outline{i}", "emission": emission, "reflectance": reflectance})
    if not objs:
        raise ViscxError(f"{path}: no outlines found in the DXF")
    return make_scene(objs)
