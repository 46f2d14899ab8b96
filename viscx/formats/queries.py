"""Query outputs: JSON (people), msgpack (programs) and PLY (the lit/unlit split of a
scene, for MeshLab). Schemas in docs/queries.md.
"""

import json
import sys
from pathlib import Path

import msgpack
import numpy as np

from viscx.errors import ParameterError, ViscxError, literal
from viscx.formats.atomic import atomic_path
from viscx.geometry.polygon import ear_clip, plane_basis, signed_area_2d

FORMATS = ("json", "msgpack", "ply")


def output_format(output, fmt, geometry=False):
    """The format to write: ``fmt`` when given, else from the output's extension
    (.msgpack/.mpk, .ply when ``geometry``), else JSON. Raises ViscxError for a
    combination the query cannot write."""
    ext = Path(output).suffix.lower() if output else ""
    guess = {".msgpack": "msgpack", ".mpk": "msgpack", ".ply": "ply"}.get(ext, "json")
    chosen = fmt or guess
    if guess == "ply" and fmt and fmt != "ply":
        raise ParameterError(f"{{fmt}} {literal(fmt)} does not write {literal(output)}; use a .json or .msgpack name")
    if chosen == "ply" and not geometry:
        raise ViscxError("this query writes JSON or msgpack, not PLY")
    return chosen


def write_result(result, output=None, fmt="json"):
    """Write a query's dict as JSON or msgpack to ``output`` (atomically) or to stdout."""
    if fmt == "msgpack":
        data = msgpack.packb(result, use_bin_type=True)
    else:
        data = (json.dumps(result, separators=(",", ":")) + "\n").encode()
    if output is None or str(output) == "-":
        sys.stdout.buffer.write(data)
        sys.stdout.flush()
        return
    with atomic_path(output) as tmp:
        Path(tmp).write_bytes(data)


# --------------------------------------------------------------------------------------
# PLY: the scene split along the shadow boundaries


def bridge_holes(outer, holes):
    """One weakly simple polygon (a keyhole) from an outer loop and its holes.

    Parameters
    ----------
    outer : (k, 2) float64
        Counter-clockwise.
    holes : list of (m, 2) float64
        Clockwise.

    Returns
    -------
    (q, 2) float64
        Counter-clockwise; each hole joined by a bridge from its rightmost vertex to
        an outer vertex the bridge reaches without crossing an edge.
    """
    ring = np.asarray(outer, dtype=np.float64)
    for hole in sorted((np.asarray(h, dtype=np.float64) for h in holes), key=lambda h: -h[:, 0].max()):
        i = int(np.argmax(hole[:, 0]))
        h = hole[i]
        edges = [ring, *[np.asarray(x) for x in holes]]
        a = np.concatenate([e for e in edges])
        b = np.concatenate([np.roll(e, -1, axis=0) for e in edges])
        best = None
        for j in np.argsort(np.linalg.norm(ring - h, axis=1)):
            if not _crosses_any(h, ring[j], a, b):
                best = int(j)
                break
        if best is None:
            best = int(np.argmin(np.linalg.norm(ring - h, axis=1)))
        hole_walk = np.roll(hole, -i, axis=0)
        ring = np.concatenate([ring[: best + 1], hole_walk, hole_walk[:1], ring[best:]])
    return ring


def _crosses_any(p, q, a, b):
    """Whether segment p-q properly crosses any segment a_i-b_i (shared ends do not count)."""
    def orient(x, y, z):
        return (y[..., 0] - x[..., 0]) * (z[..., 1] - x[..., 1]) - (y[..., 1] - x[..., 1]) * (z[..., 0] - x[..., 0])

    d1, d2 = orient(p, q, a), orient(p, q, b)
    d3, d4 = orient(a, b, p), orient(a, b, q)
    return bool(np.any((d1 * d2 < 0) & (d3 * d4 < 0)))


def _clip(poly, a, b, left):
    """The part of a convex polygon on the left (or right) of the line a → b."""
    if len(poly) == 0:
        return poly
    s = (b[0] - a[0]) * (poly[:, 1] - a[1]) - (b[1] - a[1]) * (poly[:, 0] - a[0])
    s = s if left else -s
    out = []
    for k in range(len(poly)):
        c, d = poly[k], poly[(k + 1) % len(poly)]
        sc, sd = s[k], s[(k + 1) % len(poly)]
        if sc >= 0:
            out.append(c)
        if (sc >= 0) != (sd >= 0):
            out.append(c + (sc / (sc - sd)) * (d - c))
    return np.asarray(out).reshape(-1, 2)


def subtract_triangles(pieces, triangles, tiny):
    """Convex pieces minus triangles (all counter-clockwise, 2-D): convex pieces.

    Parameters
    ----------
    pieces : list of (k, 2) float64
    triangles : (t, 3, 2) float64
    tiny : float
        Pieces of smaller area are dropped.
    """
    for tri in triangles:
        lo, hi = tri.min(axis=0), tri.max(axis=0)
        out = []
        for piece in pieces:
            if np.any(piece.min(axis=0) >= hi) or np.any(piece.max(axis=0) <= lo):
                out.append(piece)
                continue
            rest = piece
            for k in range(3):
                a, b = tri[k], tri[(k + 1) % 3]
                outside = _clip(rest, a, b, left=False)
                if len(outside) >= 3 and signed_area_2d(outside) > tiny:
                    out.append(outside)
                rest = _clip(rest, a, b, left=True)
                if len(rest) < 3:
                    break
        pieces = out
    return pieces


def split_faces(scene, view):
    """Triangles of the scene split along the lit polygons of a view.

    Returns
    -------
    triangles : (t, 3, 3) float64
    face : (t,) int64
    lit : (t,) bool
    """
    tris, faces, lit = [], [], []
    tiny = 1e-12 * scene.diagonal ** 2
    for fv in view.faces:
        f = fv.face
        n = scene.face_normal[f]
        u, v = plane_basis(n)
        origin = n * scene.face_offset[f]
        to2 = lambda x: np.stack([x @ u, x @ v], axis=-1)  # noqa: E731
        to3 = lambda q: origin + q[..., :1] * u + q[..., 1:] * v  # noqa: E731
        lit2 = []
        for outer, holes in fv.polygons:
            ring = bridge_holes(to2(outer), [to2(h) for h in holes])
            for t in ear_clip(ring):
                tri = ring[t]
                if signed_area_2d(tri) > tiny:
                    lit2.append(tri)
        lit2 = np.asarray(lit2).reshape(-1, 3, 2)
        base = scene.vertices[scene.triangles[scene.triangle_face == f]]
        pieces = []
        for tri in to2(base):
            if signed_area_2d(tri) < 0:
                tri = tri[::-1]
            pieces.append(tri)
        pieces = subtract_triangles(pieces, lit2, tiny)
        for tri in lit2:
            tris.append(to3(tri))
            faces.append(f)
            lit.append(True)
        for piece in pieces:
            for k in range(1, len(piece) - 1):
                tris.append(to3(piece[[0, k, k + 1]]))
                faces.append(f)
                lit.append(False)
    return np.asarray(tris).reshape(-1, 3, 3), np.asarray(faces, np.int64), np.asarray(lit, bool)


#: Face colours in the PLY: lit, unlit.
LIT_RGB = (255, 236, 170)
UNLIT_RGB = (60, 60, 80)


def write_triangle_ply(path, triangles, properties, rgb, comments):
    """Binary little-endian PLY of separate triangles (three vertices each), written
    atomically, with per-triangle properties and colours (MeshLab shows them).

    Parameters
    ----------
    path : str or Path
    triangles : (t, 3, 3) float
    properties : list of (name, PLY numpy type code "<i4" or "u1", (t,) array)
    rgb : (t, 3) uint8
    comments : list of str
    """
    t = len(triangles)
    vertex = np.asarray(triangles, dtype="<f8").reshape(-1, 3)
    ply_type = {"<i4": "int", "u1": "uchar"}
    fdt = np.dtype([("n", "u1"), ("v", "<i4", 3)] + [(name, code) for name, code, _ in properties]
                   + [("red", "u1"), ("green", "u1"), ("blue", "u1")])
    rows = np.zeros(t, fdt)
    rows["n"] = 3
    rows["v"] = np.arange(3 * t).reshape(-1, 3)
    for name, _, values in properties:
        rows[name] = values
    if t:
        rows["red"], rows["green"], rows["blue"] = np.asarray(rgb, dtype=np.uint8).reshape(-1, 3).T
    header = (
        "ply\nformat binary_little_endian 1.0\n" + "".join(f"comment {c}\n" for c in comments)
        + f"element vertex {3 * t}\nproperty double x\nproperty double y\nproperty double z\n"
        + f"element face {t}\nproperty list uchar int vertex_indices\n"
        + "".join(f"property {ply_type[code]} {name}\n" for name, code, _ in properties)
        + "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as out:
            out.write(header.encode())
            out.write(vertex.tobytes())
            out.write(rows.tobytes())


def write_shadow_ply(path, scene, view):
    """Binary PLY of the scene split along the shadow boundaries: per triangle its face
    id (``face``), ``lit`` (0/1) and a colour (MeshLab shows per-face colours).

    Parameters
    ----------
    path : str or Path
    scene : Scene
    view : PointView
        The light's view.

    Returns
    -------
    dict
        Counts: triangles, lit triangles.
    """
    tris, face, lit = split_faces(scene, view)
    # the triangles' own normal follows the face's (the 2-D work is counter-clockwise about it)
    write_triangle_ply(path, tris, [("face", "<i4", face), ("lit", "u1", lit)],
                       np.where(lit[:, None], LIT_RGB, UNLIT_RGB),
                       ["viscx shadows: lit 1 where the light sees the triangle",
                        "light " + " ".join(repr(float(x)) for x in view.point)])
    return {"triangles": len(tris), "lit_triangles": int(lit.sum())}


# --------------------------------------------------------------------------------------
# PLY: receivers split into the regions of a discontinuity mesh


def region_triangles(mesh):
    """Triangles of every region of a :class:`viscx.queries.discontinuities.DiscontinuityMesh`.

    Returns
    -------
    triangles : (t, 3, 3) float64
        Counter-clockwise about their receiver's normal.
    face : (t,) int64
    region : (t,) int64
        Region index within its face (the ``regions`` list of the JSON).
    """
    tris, faces, regions = [], [], []
    for r in mesh.receivers:
        for j, g in enumerate(r.regions):
            ring = bridge_holes(g.outer, g.holes)
            for t in ear_clip(ring):
                tri = ring[t]
                if signed_area_2d(tri) > 0:
                    tris.append(r.to3(tri))
                    faces.append(r.face)
                    regions.append(j)
    return np.asarray(tris).reshape(-1, 3, 3), np.asarray(faces, np.int64), np.asarray(regions, np.int64)


def _region_rgb(face, region):
    """A deterministic colour per (face, region): (t, 3) uint8."""
    h = (face.astype(np.uint64) * np.uint64(2654435761) + region.astype(np.uint64) * np.uint64(40503) + np.uint64(12345))
    h = (h ^ (h >> np.uint64(13))) * np.uint64(1274126177)
    rgb = np.stack([(h >> np.uint64(s)) & np.uint64(255) for s in (0, 8, 16)], axis=1)
    return (64 + rgb.astype(np.int64) * 3 // 4).astype(np.uint8)


def write_regions_ply(path, mesh):
    """Binary PLY of the receivers split into the discontinuity mesh's regions: per
    triangle its face id (``face``), region index (``region``) and a colour per region.

    Returns
    -------
    dict
        Counts: triangles, regions.
    """
    tris, face, region = region_triangles(mesh)
    write_triangle_ply(path, tris, [("face", "<i4", face), ("region", "<i4", region)], _region_rgb(face, region),
                       ["viscx discontinuities: receivers split into regions", f"light {mesh.light.name}"])
    return {"triangles": len(tris), "regions": sum(len(r.regions) for r in mesh.receivers)}
