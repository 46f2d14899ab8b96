"""An area light of a scene: faces, and the vertices and edges of their outline (the
generators whose families cast its discontinuity mesh, Hoberock et al. §7.5)."""

from dataclasses import dataclass

import numpy as np

from viscx.errors import ParameterError


@dataclass
class Light:
    """An area light: faces, outline vertices and edges.

    Attributes
    ----------
    faces : (k,) int64
    vertices : (a,) int64
        Vertex ids on the light's outline.
    edges : (b,) int64
        Edge ids of the outline (edges of one light face only).
    name : str
        ``group NAME`` or ``face I``.
    """

    faces: np.ndarray
    vertices: np.ndarray
    edges: np.ndarray
    name: str


def light_of(scene, face=None, group=None):
    """The :class:`Light` of one face or of the faces of a group (ViscxError when unknown)."""
    if (face is None) == (group is None):
        raise ParameterError("give exactly one of {light_face} and {light_group}")
    if face is not None:
        faces, name = scene.face_ids(face, "light_face"), f"face {face}"
    else:
        faces, name = scene.group_faces(group).astype(np.int64), f"group {group}"
    he = scene.half_edges
    in_light = np.zeros(scene.n_faces + 1, bool)
    in_light[faces] = True
    mine = in_light[he.face]
    other = np.where(he.opp >= 0, he.face[np.maximum(he.opp, 0)], -1)
    outline = mine & ~(in_light[other] & (he.opp >= 0))
    edges = np.unique(he.edge[outline])
    vertices = np.unique(scene.half_edges.edge_vertices[edges])
    return Light(faces, vertices.astype(np.int64), edges.astype(np.int64), name)
