"""A polygon soup: what a scene file holds before any cleaning.

Every loader in :mod:`viscx.formats` returns a :class:`PolygonSoup`; the scene
builder (:func:`viscx.scene.build_scene`) turns it into a clean polygonal scene.
"""

from dataclasses import dataclass, field

import numpy as np


@dataclass
class PolygonSoup:
    """Polygons as a CSR list over a vertex array, with group and material labels.

    Attributes
    ----------
    vertices : (n, 3) float
        Vertex positions.
    polygon_offsets : (p + 1,) int
        Polygon ``i`` uses ``polygon_vertices[polygon_offsets[i]:polygon_offsets[i + 1]]``.
    polygon_vertices : (m,) int
        Vertex indices of all polygons, in order.
    polygon_group : (p,) int
        Index into ``group_names`` of each polygon (OBJ ``o``/``g``).
    group_names : list of str
        Group names in order of first appearance.
    polygon_material : (p,) int
        Index into ``material_names`` of each polygon, -1 for none.
    material_names : list of str
    material_kd : (k, 3) float
        Diffuse reflectance of each material.
    material_ke : (k, 3) float
        Emitted radiance of each material (zero for non-emitters).
    """

    vertices: np.ndarray
    polygon_offsets: np.ndarray
    polygon_vertices: np.ndarray
    polygon_group: np.ndarray
    group_names: list
    polygon_material: np.ndarray = None
    material_names: list = field(default_factory=list)
    material_kd: np.ndarray = None
    material_ke: np.ndarray = None

    def __post_init__(self):
        p = len(self.polygon_offsets) - 1
        if self.polygon_material is None:
            self.polygon_material = np.full(p, -1, dtype=np.int64)
        if self.material_kd is None:
            self.material_kd = np.zeros((len(self.material_names), 3))
        if self.material_ke is None:
            self.material_ke = np.zeros((len(self.material_names), 3))

    @property
    def n_polygons(self):
        return len(self.polygon_offsets) - 1
