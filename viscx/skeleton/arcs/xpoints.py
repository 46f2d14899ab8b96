"""The crossing points X of X-junctions as pseudo-vertices (the scene the XE families are
judged on).
"""

import numpy as np

from viscx.skeleton.arcs.pencils import pencil_planes
from viscx.skeleton.generators import edge_crossings, edge_junctions
from viscx.skeleton.nodes import BLOCK_EDGE, BLOCK_VERTEX, face_planes


def crossing_scene(scene):
    """The scene with the crossing points X of its X-junctions (:func:`edge_crossings`)
    appended as generator vertices n, n + 1, … (n its vertex count), so that the VE
    machinery judges the lines through them; tangency at X from the faces touching it,
    found geometrically like a vertex's. Cached on the scene.

    Returns
    -------
    xs : Scene
        Shares the faces, half-edges (but ``vertex_is_generator``) and the ray caster.
    first : int
        Id of the first crossing point (n).
    """
    return scene.cached("crossing_scene", _crossing_scene)


def _crossing_scene(scene):
    import dataclasses

    from viscx.scene.neighbourhood import Wedges, surface_wedges

    cr = edge_crossings(scene)
    he = dataclasses.replace(scene.half_edges, vertex_is_generator=np.concatenate(
        [scene.half_edges.vertex_is_generator, np.ones(len(cr), bool)]))
    xs = dataclasses.replace(scene, vertices=np.concatenate([scene.vertices, cr.point]), half_edges=he)
    xs._caster = scene.ray_caster  # X lies on the scene's faces: nothing to add
    c, w = scene.contacts, surface_wedges(scene, cr.point)
    v = c.vertex
    xs._contacts = dataclasses.replace(c, vertex=Wedges(
        np.concatenate([v.offsets, v.offsets[-1] + w.offsets[1:]]), np.concatenate([v.face, w.face]),
        np.concatenate([v.first, w.first]), np.concatenate([v.normal, w.normal]), np.concatenate([v.span, w.span])))
    xs.cache["edge_contacts"] = edge_junctions(scene), cr
    # the scene's pencils: X points are not foreign vertices touching a face
    xs.cache["pencil_planes"], xs.cache["face_planes"] = pencil_planes(scene), face_planes(scene)
    return xs, scene.n_vertices


def blocked_at_crossings(kinds, ids, row, xe, cr, state=None):
    """Where an XE line is blocked at its crossing point (judged as the pseudo-vertex of
    :func:`crossing_scene`), name the blocker as the edge a (kind BLOCK_EDGE): X is no
    vertex of the scene. ``kinds``, ``ids`` (m, 2) are changed in place (or ``state``'s
    columns 1-4 when given); ``row`` is each line's crossing, used where ``xe``."""
    at_x = xe[:, None] & (kinds == BLOCK_VERTEX)
    kinds[at_x] = BLOCK_EDGE
    ids[at_x] = np.broadcast_to(cr.edges[np.where(xe, row, 0), 0][:, None], ids.shape)[at_x]
    if state is not None:
        state[:, [1, 3]], state[:, [2, 4]] = kinds, ids
