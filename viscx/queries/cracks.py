"""Cracks: free segments that pass between two faces touching face to face.

Two blocks standing against each other (faces of one plane P with opposite normals whose
areas overlap) leave a crack of zero width between them. A segment lying in P through
the overlap grazes both faces, each from its outer side, and is free for the complex
(grazing is free, docs/skeleton.md): it is the limit of the free segments inside either
block. A receiver point on such a segment sees the light through the crack only: a set
of lines of measure zero, so nothing changes in the visible part of the light across the
trace of its family (the receiver regions on both sides are covered by the blocks). The
discontinuity mesh drops those traces (docs/queries.md, "Cracks").

Everything is decided exactly in P's 2-D coordinates: the overlap of a triangle of one
face with a triangle of the other is the intersection of their six half-planes, shrunk by
epsilon (a segment along the overlap's outline, the blocks' common edge, is no crack).
"""

from dataclasses import dataclass

import numpy as np

from viscx.geometry.polygon import plane_basis
from viscx.skeleton.nodes import coplanar_partners, face_planes
from viscx.tolerances import GRAZE_COSINE


@dataclass
class ContactPieces:
    """Overlaps of the triangles of two faces touching face to face.

    Attributes
    ----------
    plane : (k,) int
        :func:`viscx.skeleton.nodes.face_planes` id of each piece's plane.
    normal : (k, 3) float
        The plane's unit normal (of the lower face id), ``normal · x = offset`` on it.
    offset : (k,) float
    frame : (k, 3, 3) float
        Origin, u and v of the plane's 2-D coordinates.
    half_planes : (k, 6, 3) float
        (a, b, c) per triangle edge, (a, b) its outward unit normal: (x, y) lies in both
        triangles where a x + b y <= c for all six.
    """

    plane: np.ndarray
    normal: np.ndarray
    offset: np.ndarray
    frame: np.ndarray
    half_planes: np.ndarray


def contact_pieces(scene):
    """The :class:`ContactPieces` of a scene: every pair of triangles of two coplanar faces
    with opposite normals whose bounding boxes meet (cached on the scene)."""
    return scene.cached("contact_pieces", _contact_pieces)


def _contact_pieces(scene):
    off, partner, _, _ = coplanar_partners(scene)
    f = np.repeat(np.arange(scene.n_faces), np.diff(off))
    facing = np.einsum("ij,ij->i", scene.face_normal[f], scene.face_normal[partner]) < 0
    f, g = f[facing], partner[facing]
    # the triangles of each face (CSR), then every triangle pair of each contact
    order = np.argsort(scene.triangle_face, kind="stable")
    start = np.searchsorted(scene.triangle_face[order], np.arange(scene.n_faces + 1))
    count_f, count_g = start[f + 1] - start[f], start[g + 1] - start[g]
    pair = np.repeat(np.arange(len(f)), count_f * count_g)
    k = np.arange(len(pair)) - np.repeat(np.cumsum(count_f * count_g) - count_f * count_g, count_f * count_g)
    tf = order[start[f[pair]] + k // count_g[pair]]
    tg = order[start[g[pair]] + k % count_g[pair]]
    lower = scene.triangle_face[tg]
    normal, offset = scene.face_normal[lower], scene.face_offset[lower]
    frame = np.empty((len(tg), 3, 3))
    frame[:, 0] = scene.vertices[scene.triangles[tg, 0]]
    for i in range(len(tg)):  # a basis per piece; pieces are per contact, not per query
        frame[i, 1], frame[i, 2] = plane_basis(normal[i])
    half = np.empty((len(tg), 6, 3))
    for first, tri in ((0, tf), (3, tg)):
        c = scene.vertices[scene.triangles[tri]] - frame[:, None, 0]
        xy = np.stack([np.einsum("kij,kj->ki", c, frame[:, 1]), np.einsum("kij,kj->ki", c, frame[:, 2])], axis=2)
        a, b = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
        turn = np.sign(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])  # either winding
        for i in range(3):
            e = xy[:, (i + 1) % 3] - xy[:, i]
            out = turn[:, None] * np.stack([e[:, 1], -e[:, 0]], axis=1)
            out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)
            half[:, first + i, :2] = out
            half[:, first + i, 2] = np.einsum("ki,ki->k", out, xy[:, i])
    return ContactPieces(face_planes(scene)[lower], normal, offset, frame, half)


#: Segments × pieces judged at once by :func:`through_cracks`.
CRACK_CHUNK = 1 << 18


def through_cracks(scene, starts, ends):
    """Whether each segment, trimmed by epsilon at both ends, passes through a crack: it lies
    in the plane of a contact (within the weld tolerance and GRAZE_COSINE, as grazing is
    judged) and enters the interior of one of its pieces shrunk by epsilon.

    The segment x(s) = P + s (Q - P) is clipped by each piece's six half-planes
    (Cyrus-Beck): a·x(s) <= c - eps is s (a·d) <= c - eps - a·P, an interval of s.

    Parameters
    ----------
    starts, ends : (n, 3) float

    Returns
    -------
    (n,) bool
    """
    starts = np.asarray(starts, dtype=np.float64).reshape(-1, 3)
    vec = np.asarray(ends, dtype=np.float64).reshape(-1, 3) - starts
    length = np.linalg.norm(vec, axis=1)
    crack = np.zeros(len(starts), dtype=bool)
    pieces = contact_pieces(scene)
    eps = scene.epsilon
    long = length > 2 * eps
    for q in np.unique(pieces.plane):
        mine = np.flatnonzero(pieces.plane == q)
        n, off = pieces.normal[mine[0]], pieces.offset[mine[0]]
        with np.errstate(divide="ignore", invalid="ignore"):
            cosine = np.abs(vec @ n) / length
        rows = np.flatnonzero(long & (cosine <= GRAZE_COSINE) & (np.abs(starts @ n - off) <= scene.weld_tolerance))
        fr, hp = pieces.frame[mine], pieces.half_planes[mine]
        for lo in range(0, len(rows), max(1, CRACK_CHUNK // len(mine))):
            r = rows[lo:lo + max(1, CRACK_CHUNK // len(mine))]
            rel = starts[r][:, None, :] - fr[None, :, 0]
            p2 = np.stack([np.einsum("rpi,pi->rp", rel, fr[:, 1]), np.einsum("rpi,pi->rp", rel, fr[:, 2])], axis=2)
            d2 = np.stack([vec[r] @ fr[:, 1].T, vec[r] @ fr[:, 2].T], axis=2)
            num = hp[None, :, :, 2] - eps - np.einsum("pmi,rpi->rpm", hp[..., :2], p2)
            den = np.einsum("pmi,rpi->rpm", hp[..., :2], d2)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = num / den
            enter = np.maximum(np.max(np.where(den < 0, ratio, -np.inf), axis=2), (eps / length[r])[:, None])
            leave = np.minimum(np.min(np.where(den > 0, ratio, np.inf), axis=2), (1 - eps / length[r])[:, None])
            never = np.any((den == 0) & (num < 0), axis=2)
            crack[r] |= np.any(~never & (enter < leave), axis=1)
    return crack
