"""The visibility polyhedron of a point (Hoberock et al. §7.1) from the point's V-cells.

From a point p, the ray along a direction d first meets the face ``down(d)``:
the V-cells of p whose down blocker is face f together are the directions in
which p sees f, and their central projection through p onto f's plane is the
part of f visible from p. Their union is bounded by the boundary elements
(VE half-cells (p, e) on p's direction sphere) whose two sides have different
down blockers; elements between two cells with the same down (only the up
blocker behind p changes) are inside the union and cancel. The remaining
elements are chained again (FormLoops grouped by down face, Hoberock et al. §5.3),
classified outer / hole by their turning sums and grouped by crossing parity,
exactly as V2 does for one cell (:mod:`viscx.skeleton.vcells`).

Projection: an element is a great-circle arc, the directions from p to a
stretch of edge e; the plane through p holding it meets f's plane in a line,
so its image on f is the segment between the images of its ends, which are
where the segments of the VE family end on f (their VV/VEE nodes). Nothing
is clipped: where p sees f, the boundary is made of the VE half-cells of f's
own edges and of the edges that hide parts of f, so the loops lie in f. A
boundary element whose edge is not an edge of f is where another object cuts
f's visible part: a shadow boundary when p is a light (Hoberock et al. §7.2, Fig. 8).

Open chains (cells V1 could not close, docs/skeleton.md "V-cells") are
reported per face (``complete`` false) and their elements kept as boundary
segments; such a face's polygons miss the region the chain bounds.
"""

from dataclasses import dataclass, field

from pathlib import Path

import numpy as np

from viscx.arrays import expand_ranges


@dataclass
class FaceView:
    """What a point sees of one face.

    Attributes
    ----------
    face : int
    polygons : list of (outer, holes)
        ``outer`` : (k, 3) float64, counter-clockwise seen from the face's front
        (its normal); ``holes`` : list of (k, 3) float64, clockwise.
    boundary : (b, 2, 3) float64
        Segments of the visible part's boundary cast by other objects (traces of
        VE half-cells of edges not on this face): the shadow boundaries.
    complete : bool
        Every boundary element of the face closed into a loop.
    """

    face: int
    polygons: list = field(default_factory=list)
    boundary: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    complete: bool = True

    @property
    def loops(self):
        """Every loop, outer loops and their holes in order: list of (k, 3) float64."""
        return [loop for outer, holes in self.polygons for loop in (outer, *holes)]

    def area(self):
        """Area of the visible part (outer loops minus holes), float: the loops are
        oriented about one normal, so their Newell vectors add up to twice it."""
        loops = self.loops
        return 0.5 * float(np.linalg.norm(sum(_newell(loop) for loop in loops))) if loops else 0.0


def _newell(points):
    p = np.asarray(points, dtype=np.float64)
    return np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)


def face_areas(faces):
    """:meth:`FaceView.area` of every face at once (the same sums, in one pass).

    Parameters
    ----------
    faces : list of FaceView

    Returns
    -------
    (f,) float64
    """
    loops = [fv.loops for fv in faces]
    count = np.array([len(x) for x in loops], dtype=np.int64)
    rings = [loop for x in loops for loop in x]
    out = np.zeros(len(faces))
    if not rings:
        return out
    size = np.array([len(r) for r in rings], dtype=np.int64)
    pts = np.concatenate(rings).reshape(-1, 3).astype(np.float64)
    at = np.cumsum(size) - size
    nxt = np.arange(1, len(pts) + 1)
    nxt[np.cumsum(size) - 1] = at  # np.roll(ring, -1) of every ring
    newell = np.add.reduceat(np.cross(pts, pts[nxt]), at)
    some = np.flatnonzero(count)
    out[some] = 0.5 * np.linalg.norm(np.add.reduceat(newell, (np.cumsum(count) - count)[some]), axis=1)
    return out


@dataclass
class PointView:
    """The visibility polyhedron of a point: per face, the part it sees.

    Attributes
    ----------
    point : (3,) float64
    faces : list of FaceView
        One per face of the scene, in face order (empty polygons where nothing is seen).
    cells : int
        V-cells of the point.
    incomplete_cells : int
        Of those, cells whose vertex has loops that did not close (``VCells.complete`` false).
    open_chains : int
        Chains of the visible parts' boundaries that did not close.
    """

    point: np.ndarray
    faces: list
    cells: int
    incomplete_cells: int
    open_chains: int

    @property
    def complete(self):
        return self.incomplete_cells == 0 and self.open_chains == 0


def point_view(scene, arcs, vcells, vertex, point):
    """The visible part of every face from a point, from the point's V-cells.

    Parameters
    ----------
    scene : Scene
        The scene the half-cells refer to (with the point appended when the
        point is a free point: :func:`viscx.skeleton.points.with_points`).
    arcs : Arcs
    vcells : VCells
    vertex : int
        The point's generator vertex id.
    point : (3,) float64

    Returns
    -------
    PointView
    """
    # the skeleton's modules here, not at the top: opening a file for a form-factor matrix
    # (:func:`open_query`) needs none of them (nor embree)
    from viscx.skeleton.loops import cells_of_loops
    from viscx.skeleton.nodes import BLOCK_FACE
    from viscx.skeleton.vcells import inside_loops, reference_points, sphere_loops, sphere_turning_sums, stored_elements

    p = np.asarray(point, dtype=np.float64)
    n_faces = len(scene.face_area)
    mine = np.flatnonzero(vcells.vertex == vertex)
    ochains = np.flatnonzero(vcells.open_vertex == vertex)
    # every boundary element of the point's cells and open chains, with its cell's down face
    lo = vcells.element_offsets[vcells.loop_offsets[mine]]
    hi = vcells.element_offsets[vcells.loop_offsets[mine + 1]]
    cell_of, rows = expand_ranges(lo, hi - lo)
    cell_down = np.where(vcells.down_kind[mine] == BLOCK_FACE, vcells.down[mine], -1)
    lo = vcells.open_offsets[ochains]
    chain_of, orows = expand_ranges(lo, vcells.open_offsets[ochains + 1] - lo)
    chain_down = np.where(vcells.open_down_kind[ochains] == BLOCK_FACE, vcells.open_down[ochains], -1)
    signed = np.concatenate([vcells.element[rows], vcells.open_element[orows]]).astype(np.int64)
    anti = np.concatenate([vcells.antipodal[rows], vcells.open_antipodal[orows]]).astype(bool)
    down = np.concatenate([cell_down[cell_of], chain_down[chain_of]]).astype(np.int64)
    faces = [FaceView(face=f) for f in range(n_faces)]
    if not len(signed):
        return PointView(p, faces, len(mine), int(np.count_nonzero(~vcells.complete[mine])), 0)
    # an element and its mirror (the other side of the same image) between two cells seeing
    # the same face lie inside that face's visible part: drop both
    code = (np.abs(signed) - 1) * 4 + anti * 2 + (signed < 0)
    mirror = code ^ 1
    order = np.argsort(code)
    at = np.clip(np.searchsorted(code[order], mirror), 0, len(code) - 1)
    has_mirror = code[order][at] == mirror
    same = has_mirror & (down[order][at] == down)
    keep = (down >= 0) & ~same
    signed, anti, down = signed[keep], anti[keep], down[keep]
    el = stored_elements(scene, arcs, signed, anti)
    walk_order, loop_offsets, chain_offsets = sphere_loops(scene, el, down)
    walk = el.take(walk_order)
    walk_down = down[walk_order]
    n_loops = len(loop_offsets) - 1
    turning = sphere_turning_sums(walk, loop_offsets)
    ref = reference_points(walk, loop_offsets)
    loop_face = walk_down[loop_offsets[:-1]]
    cell = cells_of_loops(walk, loop_offsets, loop_face, ref, inside_loops) if n_loops else np.zeros(0, np.int64)

    # which edges bound which face (a boundary along f's own edge is f's outline, not a shadow)
    he = scene.half_edges
    edge_of = arcs.half_cells.edge[np.abs(walk.signed) - 1]
    n_edges = len(he.edge_vertices)
    own = np.unique(he.face.astype(np.int64) * n_edges + he.edge)
    key = walk_down * n_edges + edge_of
    shadow = own[np.clip(np.searchsorted(own, key), 0, len(own) - 1)] != key

    # every element's start and end on its down face's plane (central projection through p)
    normal, offset = scene.face_normal, scene.face_offset
    nf = normal[walk_down]
    height = offset[walk_down] - nf @ p
    start = p + (height / np.einsum("ij,ij->i", walk.start, nf))[:, None] * walk.start
    end = p + (height / np.einsum("ij,ij->i", walk.end, nf))[:, None] * walk.end

    # loops by cell, the outer loop (largest turning sum) first; cells by (face, cell)
    by_cell = np.lexsort([np.arange(n_loops), -turning, cell])
    first = np.r_[True, cell[by_cell][1:] != cell[by_cell][:-1]] if n_loops else np.zeros(0, bool)
    outer_face = loop_face[by_cell][first]
    group = np.cumsum(first) - 1
    loops = by_cell[np.lexsort([np.arange(n_loops), cell[by_cell], outer_face[group]])]
    rank0 = np.r_[True, cell[loops][1:] != cell[loops][:-1]] if n_loops else np.zeros(0, bool)
    # outer loops counter-clockwise about the face's normal, holes clockwise: the sign of
    # each ring's Newell vector along the normal (twice its signed area in the face's plane)
    is_outer = np.zeros(n_loops, bool)
    is_outer[loops[rank0]] = True
    length = np.diff(loop_offsets)
    li, k = expand_ranges(loop_offsets[:-1], length)
    nxt = k + 1
    nxt[np.cumsum(length) - 1] = loop_offsets[:-1]  # each ring's last point closes on its first
    at = np.cumsum(length) - length
    newell = np.add.reduceat(np.cross(start[k], start[nxt]), at) if n_loops else np.zeros((0, 3))
    flip = (np.einsum("ij,ij->i", newell, normal[loop_face]) < 0) == is_outer
    heads = np.flatnonzero(rank0)
    for a, b in zip(heads.tolist(), np.r_[heads[1:], n_loops].tolist()):
        rings = [start[loop_offsets[m]:loop_offsets[m + 1]][::-1 if flip[m] else 1] for m in loops[a:b].tolist()]
        faces[int(loop_face[loops[a]])].polygons.append((rings[0], rings[1:]))
    # shadow boundaries and open chains
    k = np.flatnonzero(shadow)
    k = k[np.argsort(walk_down[k], kind="stable")]
    segs = np.stack([start[k], end[k]], axis=1)
    f, first_k = np.unique(walk_down[k], return_index=True)
    for i, fi in enumerate(f.tolist()):
        faces[fi].boundary = segs[first_k[i]:first_k[i + 1] if i + 1 < len(f) else len(k)]
    for fi in walk_down[chain_offsets[:-1]].tolist():
        faces[fi].complete = False
    return PointView(p, faces, len(mine), int(np.count_nonzero(~vcells.complete[mine])), len(chain_offsets) - 1)


# --------------------------------------------------------------------------------------
# from a complex (in memory or a file)


def open_query(path, **scene_options):
    """The complex a point query reads: a viscx file's (which must hold V-cells, V2), or
    the scene of a scene file (OBJ, PLY, …) alone for a *scoped* query that builds only
    the point's V-cells (:func:`view_from`), with the same definitions as the full build.

    Parameters
    ----------
    path : str or Path
    **scene_options
        ``weld``, ``epsilon``, ``relative_epsilon`` for a scene file (see
        :func:`viscx.scene.build_scene`); a viscx file keeps the ones it was built with.

    Returns
    -------
    viscx.pipeline.BuiltComplex

    Raises ViscxError (one line, exit status 2) for a viscx file without V2, or with
    scene options.
    """
    import h5py

    from viscx.errors import ParameterError, literal
    from viscx.pipeline import BuiltComplex, open_complex, scene_of

    given = {k: v for k, v in scene_options.items() if v is not None}
    if not (Path(path).is_file() and h5py.is_hdf5(path)):
        return BuiltComplex(scene_of(path, **given))
    if given:
        names = ", ".join("{" + k + "}" for k in sorted(given))
        raise ParameterError(f"{literal(path)} is a viscx file, built with its own scene options: {names} apply to "
                             "scene files only")
    return open_complex(path, need="V2", hint=", or query the scene file itself")


def as_query(source, **scene_options):
    """``source`` when it is a complex (:class:`viscx.pipeline.BuiltComplex`), else the
    complex of the file it names (:func:`open_query`)."""
    from viscx.pipeline import BuiltComplex

    return source if isinstance(source, BuiltComplex) else open_query(source, **scene_options)


def QueryScene(path, scene, points):  # noqa: N802 -- the name older callers construct
    """The complex of viscx file ``path`` whose scene and points were read already."""
    from viscx.pipeline import BuiltComplex

    return BuiltComplex(scene, points=np.asarray(points, dtype=np.float64).reshape(-1, 3), path=Path(path),
                        stored=["V0", "V1", "V2"])


def view_from(query, point):
    """The visibility polyhedron of a point: from the complex's V-cells when the point is
    one of its free points (``viscx build --point``, within the epsilon) and it holds V2,
    else computed on demand (:func:`viscx.skeleton.points.point_vcells`, nothing stored).

    Parameters
    ----------
    query : viscx.pipeline.BuiltComplex
    point : (3,) float64

    Returns
    -------
    view : PointView
    stored : bool
        Whether the complex's V-cells were used.
    """
    from viscx.skeleton.points import check_points, point_vcells, with_points

    scene = query.scene
    p = np.asarray(point, dtype=np.float64).reshape(3)
    check_points(scene, p[None])
    if len(query.points) and "V2" in query.levels:
        dist = np.linalg.norm(query.points - p, axis=1)
        k = int(np.argmin(dist))
        if dist[k] <= scene.epsilon:
            ext = with_points(scene, query.points)
            return point_view(ext, query.arcs, query.vcells, scene.n_vertices + k, query.points[k]), True
    pc = point_vcells(scene, p)
    return point_view(pc.scene, pc.arcs, pc.vcells, int(pc.point_ids[0]), p), False


def visible_result(scene, view, stored=False):
    """The visibility polyhedron as a plain dict (the JSON schema of docs/queries.md)."""
    faces = []
    area = face_areas(view.faces)
    for fv in view.faces:
        faces.append({
            "face": fv.face,
            "group": scene.group_names[scene.face_group[fv.face]],
            "polygons": [{"outer": outer.tolist(), "holes": [h.tolist() for h in holes]} for outer, holes in fv.polygons],
            "area": float(area[fv.face]),
            "complete": fv.complete,
        })
    return {"from": view.point.tolist(), "faces": faces, **view_summary(view, stored)}


def view_summary(view, stored):
    """The fields every point query reports about the point's cells."""
    return {
        "complete": bool(view.complete),
        "cells": view.cells,
        "incomplete_cells": view.incomplete_cells,
        "open_chains": view.open_chains,
        "source": "file" if stored else "on demand",
    }
