"""Free points (lights, viewpoints) as extra generators of the complex.

A free point p lies on no face: the surface never separates the two rays of a
line through p, so every line through p is tangent (passing) there, and every
V-cell of p has its antipodal twin. Otherwise p is a generator vertex with no
incident edges or faces, and its cells are built by the vertex machinery:

* **Ids.** Point k of a scene with n vertices is generator vertex n + k
  (:func:`with_points` appends the points to the vertex array and marks them as
  generator vertices; faces, edges and the ray caster are the scene's).
* **Nodes (V0).** VV (u, p) for every generator vertex u and VEE (p, e1, e2)
  for the pairs of generator edges met by one line through p, judged by
  :func:`viscx.skeleton.nodes.validate_candidates` like every node. Points are
  not occluders: two points see each other along no family of either, so no
  VV (p, q) is built (it would bound no cell).
* **Arcs (V1).** The VE families (p, e) for every generator edge e (a vertex's
  families come from its nodes; for a point every edge is seeded, so an arc
  whose events were all dropped as degenerate is still found), cut at the
  point's nodes and sampled by the arc builder's own stages.
* **V-cells (V2).** :func:`viscx.skeleton.vcells.build_vcells` on those half-cells.

:func:`point_vcells` does this for one point without any file (the queries);
:func:`add_points` merges the points' levels into a built complex
(``viscx build --point``): point nodes are sorted into V0 (arc ends renumbered),
point arcs and cells follow the scene's, whose ids do not change.
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

from viscx.errors import ViscxError
from viscx.skeleton.arcs.events import event_parameters
from viscx.skeleton.arcs.halfcells import build_half_cells
from viscx.skeleton.arcs.kinds import END_ENDPOINT, END_NODE, END_TRANSITION, VE, Arcs, HalfCells
from viscx.skeleton.arcs.stages import arcs_on_intervals, family_intervals, sorted_arcs
from viscx.skeleton.nodes import Nodes, validate_candidates
from viscx.skeleton.generators import edge_crossings
from viscx.skeleton.point_nodes import point_node_incidences, point_nodes
from viscx.tolerances import PARAMETER_SLACK


def with_points(scene, points):
    """The scene with free points appended as generator vertices n, n + 1, ….

    Parameters
    ----------
    scene : Scene
    points : (k, 3) float64

    Returns
    -------
    Scene
        Shares the faces, half-edges (but ``vertex_is_generator``) and the ray
        caster of ``scene``.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    he = dataclasses.replace(
        scene.half_edges,
        vertex_is_generator=np.concatenate([scene.half_edges.vertex_is_generator, np.ones(len(points), bool)]),
    )
    ext = dataclasses.replace(scene, vertices=np.concatenate([scene.vertices, points]), half_edges=he)
    ext._caster = scene.ray_caster  # the points are not in it: they block nothing
    ext._contacts = scene.contacts.with_free_points(len(points))  # they touch no face (check_points)
    return ext


def check_points(scene, points):
    """Refuse points that cannot be generators: non-finite, on a face (within the weld
    tolerance), or inside a solid (:func:`inside_solid`). Raises ViscxError."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    for p in points:
        where = f"({p[0]:g}, {p[1]:g}, {p[2]:g})"
        if not np.all(np.isfinite(p)):
            raise ViscxError(f"point {where} has a NaN or infinite coordinate")
    if len(points) == 0:
        return
    owner, tri = scene.ray_caster.exact.triangles_near(points, max(scene.weld_tolerance, scene.epsilon))
    if len(owner):
        p = points[owner[0]]
        raise ViscxError(f"point ({p[0]:g}, {p[1]:g}, {p[2]:g}) lies on face {int(scene.triangle_face[tri[0]])}")
    inside = inside_solid(scene, points)
    if inside.any():
        p = points[np.argmax(inside)]
        raise ViscxError(f"point ({p[0]:g}, {p[1]:g}, {p[2]:g}) is inside a solid (enclosed, seeing mostly the back of faces)")


def _fibonacci_sphere(n):
    """(n, 3) float64: nearly uniform unit directions."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z * z)
    phi = k * np.pi * (3 - np.sqrt(5))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


#: Directions cast by :func:`inside_solid`.
SOLID_PROBES = 256


def inside_solid(scene, points):
    """Whether each point is enclosed by a solid: no probe ray escapes to the sky and more
    than half of them meet the back of a face (faces are two-sided, so the normals are the
    only hint: solids are modelled facing outwards, rooms facing inwards).

    Parameters
    ----------
    points : (k, 3) float64

    Returns
    -------
    (k,) bool
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = _fibonacci_sphere(SOLID_PROBES)
    o = np.repeat(points, len(d), axis=0)
    dd = np.tile(d, (len(points), 1))
    face, _ = scene.ray_caster.first_hit(o, dd, tmin=scene.epsilon)
    face = face.reshape(len(points), -1)
    back = np.einsum("kij,kij->ki", scene.face_normal[np.maximum(face, 0)], dd.reshape(len(points), -1, 3)) > 0
    return (face >= 0).all(axis=1) & (np.count_nonzero(back, axis=1) > len(d) // 2)


# --------------------------------------------------------------------------------------
# V1: the point's VE arcs and half-cells (its nodes: :mod:`viscx.skeleton.point_nodes`)


def point_arcs(scene, point_ids, nodes):
    """The VE arcs (p, e) and half-cells of free points, by the stages of
    :func:`viscx.skeleton.arcs.build_arcs` (events, intervals, samples, half-cells).

    Parameters
    ----------
    scene : Scene
        With the points appended.
    point_ids : (k,) int
    nodes : Nodes
        The points' nodes (:func:`point_nodes`); ``end_node`` ids refer to them.

    Returns
    -------
    Arcs
        VE arcs only, sorted like :class:`viscx.skeleton.arcs.Arcs`; ``planar`` is empty.
    """
    point_ids = np.asarray(point_ids, dtype=np.int64)
    ge = scene.generator_edges
    # every family (p, e); events: the nodes on it (VEE (p, e1, e2) on (p, e1) and (p, e2);
    # VV (u, p) on (p, e) for every generator edge e at u)
    families = np.stack([np.repeat(point_ids, len(ge)), np.tile(ge, len(point_ids)), np.full(len(ge) * len(point_ids), -1)], axis=1)
    ev = scene.half_edges.edge_vertices
    inc, rows = point_node_incidences(scene, nodes)
    key = families[:, 0] * (len(ev) + 1) + families[:, 1]
    fam_of = np.searchsorted(key, inc[:, 0] * (len(ev) + 1) + inc[:, 1])
    fkind = np.full(len(families), VE)
    ev_s = event_parameters(scene, fkind[fam_of], families[fam_of], nodes, rows)
    nf = len(families)
    fam_of = np.concatenate([fam_of, np.arange(nf), np.arange(nf)])
    ev_s = np.concatenate([ev_s, np.zeros(nf), np.ones(nf)])
    ev_kind = np.concatenate([np.full(len(rows), END_NODE), np.full(2 * nf, END_ENDPOINT)])
    ev_index = np.concatenate([rows, np.full(2 * nf, -1)])
    # two edges crossing inside (an X-junction) give the VEE event V0 drops (its two edge
    # points coincide): cut both families exactly at the crossing, as a transition
    x_fam, x_s = _crossing_events(scene, point_ids, ge)
    fam_of = np.concatenate([fam_of, x_fam])
    ev_s = np.concatenate([ev_s, x_s])
    ev_kind = np.concatenate([ev_kind, np.full(len(x_fam), END_TRANSITION)])
    ev_index = np.concatenate([ev_index, np.full(len(x_fam), -1)])
    ev_s = np.nan_to_num(ev_s, nan=-1.0)
    inside = (ev_s >= -PARAMETER_SLACK) & (ev_s <= 1 + PARAMETER_SLACK)
    ev_s = np.clip(ev_s, 0.0, 1.0)
    intervals = family_intervals(scene, fkind, families, fam_of[inside], ev_s[inside], ev_kind[inside], ev_index[inside])
    built = arcs_on_intervals(scene, fkind, families, *intervals)
    built = sorted_arcs(built)
    half_cells = build_half_cells(scene, built)  # from the samples' side pairs
    del built["sides"]
    return Arcs(**built, planar=validate_candidates(scene, np.zeros(0, np.int8), np.zeros((0, 4), np.int64),
                                                     np.zeros((0, 3)), np.zeros((0, 3))), half_cells=half_cells)


def _crossing_events(scene, point_ids, ge):
    """Where the families (p, e) of each point pass the crossing of e with another generator
    edge (the scene's X-junctions, :func:`viscx.skeleton.generators.edge_crossings`: every
    line through p and X meets both edges).

    Returns
    -------
    family : (k,) int
        Row of the families (point-major, then ``ge`` order).
    s : (k,) float
        Parameter of the crossing on e.
    """
    cr = edge_crossings(scene)
    rows = np.searchsorted(ge, cr.edges)  # (k, 2) rows of both edges' families
    base = np.repeat(np.arange(len(point_ids)) * len(ge), 2 * len(cr.edges))
    return base + np.tile(rows.ravel(), len(point_ids)), np.tile(cr.s.ravel(), len(point_ids))


# --------------------------------------------------------------------------------------
# V2 and the on-demand entry point


@dataclass
class PointComplex:
    """The part of the complex generated by free points.

    Attributes
    ----------
    scene : Scene
        The scene with the points appended (:func:`with_points`): element geometry
        of the point's half-cells needs their positions.
    point_ids : (k,) int64
        Generator vertex ids of the points (n, n + 1, … for a scene of n vertices).
    nodes : Nodes
    arcs : Arcs
    vcells : VCells
    """

    scene: object
    point_ids: np.ndarray
    nodes: Nodes
    arcs: Arcs
    vcells: object


def build_points(scene, points, quiet=True):
    """Nodes, arcs and V-cells of free points (file-free: nothing is read or written).

    Parameters
    ----------
    scene : Scene
        The mesh scene (without points).
    points : (k, 3) float64

    Returns
    -------
    PointComplex
    """
    from viscx.skeleton.vcells import build_vcells

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    check_points(scene, points)
    ext = with_points(scene, points)
    ids = scene.n_vertices + np.arange(len(points))
    nodes = point_nodes(ext, ids)
    arcs = point_arcs(ext, ids, nodes)
    vcells = build_vcells(ext, arcs, quiet=quiet, vertices=ids)
    return PointComplex(ext, ids, nodes, arcs, vcells)


def point_vcells(scene, point, epsilon=None):
    """The V-cells of one free point, computed on demand (queries naming a point that is
    not in the file).

    Parameters
    ----------
    scene : Scene
    point : (3,) float64
    epsilon : float, optional
        Robustness epsilon (scene units); default the scene's.

    Returns
    -------
    PointComplex
        ``vcells`` holds the point's cells (vertex ``scene.n_vertices``).
    """
    if epsilon is not None and epsilon != scene.epsilon:
        scene = dataclasses.replace(scene, epsilon=float(epsilon), _caster=None)
    return build_points(scene, np.asarray(point, dtype=np.float64).reshape(1, 3))


# --------------------------------------------------------------------------------------
# merging into a built complex (viscx build --point)


def _node_order(nodes):
    """Permutation putting nodes in canonical order (the key of ``sort_nodes``)."""
    keys = [nodes.direction[:, 2], nodes.direction[:, 1], nodes.direction[:, 0]]
    keys += [nodes.generators[:, k] for k in (3, 2, 1, 0)] + [nodes.kind]
    return np.lexsort(keys)


def _concat(cls, a, b, **override):
    # the record's arguments only (not a declared cache)
    return cls(**{f.name: override[f.name] if f.name in override else np.concatenate([getattr(a, f.name), getattr(b, f.name)])
                  for f in dataclasses.fields(cls) if f.init})


def add_points(built, pc):
    """Merge the points' levels into a built complex (same scene, points appended).

    Parameters
    ----------
    built : dict
        ``{"V0": Nodes, "V1": Arcs, "V2": VCells}`` of the mesh scene (any prefix of the levels).
    pc : PointComplex

    Returns
    -------
    dict
        The merged levels: V0 in canonical order (the scene's arcs' node ends renumbered),
        V1 and V2 with the points' rows after the scene's (their vertex ids are larger).
    """
    from viscx.skeleton.vcells import VCells

    out = {}
    if "V0" not in built:
        return out
    n0 = len(built["V0"])
    merged = _concat(Nodes, built["V0"], pc.nodes)
    order = _node_order(merged)
    new_id = np.empty(len(order), np.int64)
    new_id[order] = np.arange(len(order))
    out["V0"] = Nodes(**{name: getattr(merged, name)[order] for name in Nodes.__dataclass_fields__})
    if "V1" not in built:
        return out
    a, b = built["V1"], pc.arcs
    na = len(a)

    def renumber(ids, types, shift):
        return np.where(types == END_NODE, new_id[np.maximum(ids, 0) + shift], ids)

    end_node = np.concatenate([renumber(a.end_node, a.end_type, 0), renumber(b.end_node, b.end_type, n0)])
    ha, hb = a.half_cells, b.half_cells
    half = _concat(
        HalfCells, ha, hb,
        arc=np.concatenate([ha.arc, hb.arc + na]),
        start=np.concatenate([renumber(ha.start, ha.start_type, 0), renumber(hb.start, hb.start_type, n0)]),
        end=np.concatenate([renumber(ha.end, ha.end_type, 0), renumber(hb.end, hb.end_type, n0)]),
    )
    out["V1"] = _concat(Arcs, a, b, end_node=end_node, planar=a.planar, half_cells=half)
    if "V2" not in built:
        return out
    # V2 holds the V-cells and the EE-cells (viscx.pipeline.TwoCells); the points' arcs come
    # after the scene's, so the EE-cells' arc ids stay valid and only the V-cells grow
    two = built["V2"]
    c, d = two.vcells, pc.vcells
    nh, nc = len(ha), len(c)

    def shift_elements(el):
        return np.sign(el) * (np.abs(el) + nh)

    out["V2"] = dataclasses.replace(two, vcells=_concat(
        VCells, c, d,
        twin=np.concatenate([c.twin, np.where(d.twin >= 0, d.twin + nc, -1)]),
        loop_offsets=np.concatenate([c.loop_offsets, d.loop_offsets[1:] + c.loop_offsets[-1]]),
        element_offsets=np.concatenate([c.element_offsets, d.element_offsets[1:] + c.element_offsets[-1]]),
        element=np.concatenate([c.element, shift_elements(d.element)]),
        open_offsets=np.concatenate([c.open_offsets, d.open_offsets[1:] + c.open_offsets[-1]]),
        open_element=np.concatenate([c.open_element, shift_elements(d.open_element)]),
    ))
    return out
