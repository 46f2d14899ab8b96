"""Shadows of a point light (Hoberock et al. §7.2, Fig. 8): lit polygons and shadow boundaries.

A point of a face is lit exactly when the light sees it, so the lit part of
each face is its visible part from the light (:mod:`viscx.queries.visibility`,
the light's V-cells projected onto the face); the shadow-boundary segments
are the traces on the face of the light's VE half-cells whose down blocker is
the face on one side and another face on the other (an occluder's edge casting
its shadow). Faces are two-sided: a face whose back is turned to the light is
lit on its back (``front`` says which side the light is on).
"""

import numpy as np

from viscx.queries.visibility import as_query, face_areas, view_from, view_summary


def shadow_result(scene, view, stored=False):
    """The shadows as a plain dict (the JSON schema of docs/queries.md).

    Parameters
    ----------
    scene : Scene
    view : PointView
        The light's view (:func:`viscx.queries.visibility.view_from`).

    Returns
    -------
    dict
        ``{"light": [x, y, z], "faces": [{"face", "group", "lit", "boundary", "front",
        "lit_area", "complete"}], "complete", "cells", "incomplete_cells", "open_chains"}``:
        per face (in face order) the lit loops, outer loops counter-clockwise seen from
        the face's front, holes clockwise, and the shadow-boundary segments.
    """
    p = view.point
    faces = []
    area = face_areas(view.faces).tolist()
    front = (scene.face_normal @ p > scene.face_offset).tolist()
    names = [scene.group_names[g] for g in scene.face_group.tolist()]
    for fv in view.faces:
        f = fv.face
        faces.append({
            "face": f,
            "group": names[f],
            "lit": [loop.tolist() for loop in fv.loops],
            "boundary": np.asarray(fv.boundary).tolist(),
            "front": front[f],
            "lit_area": area[f],
            "complete": fv.complete,
        })
    return {"light": p.tolist(), "faces": faces, **view_summary(view, stored)}


def shadows(source, light, faces=(), **scene_options):
    """Lit polygons and shadow boundaries of a point light, from a complex (in memory or a
    viscx file) or, scoped, from a scene file (only the light's V-cells are built).

    Parameters
    ----------
    source : viscx.pipeline.BuiltComplex, str or Path
        A complex, a viscx file, or a scene file (:func:`viscx.queries.visibility.as_query`).
    light : (3,) float64
    faces : sequence of int
        Face ids the caller will report; checked before any work (ViscxError when out of range).
    **scene_options
        ``weld``, ``epsilon``, ``relative_epsilon`` for a scene file.

    Returns
    -------
    scene : Scene
    view : PointView
    result : dict
        :func:`shadow_result`.
    """
    query = as_query(source, **scene_options)
    query.scene.face_ids(faces)
    view, stored = view_from(query, light)
    return query.scene, view, shadow_result(query.scene, view, stored)
