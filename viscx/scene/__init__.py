"""The scene model: clean polygon faces, half-edges, generators, groups.

``load_scene(path)`` reads a file (OBJ by viscx, other formats by trimesh) and
``build_scene(soup)`` cleans it, in this order:

1. triangulate every input polygon (fan if convex, ear clipping otherwise);
2. weld vertices closer than the weld tolerance;
3. drop degenerate triangles (thinner than the tolerance) and duplicates;
4. merge adjacent coplanar triangles of one group into polygon faces;
5. trace each face's boundary loops and drop straight-through vertices;
6. build half-edges and the generator edges and vertices.

Every step is deterministic and keeps input order, so the same file always gives
the same ids. The triangles stay available for ray casting
(``triangle_face`` maps them to faces).
"""

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viscx.arrays import bounding_diagonal
from viscx.cache import Cached
from viscx.errors import ParameterError, ViscxError, literal
from viscx.geometry.polygon import triangulate_polygons
from viscx.scene.clean import crossing_polygons, degenerate_triangles, duplicate_triangles, weld_vertices
from viscx.scene.faces import drop_collinear_vertices, face_loops, merge_coplanar
from viscx.scene.halfedge import HalfEdges, build_half_edges
from viscx.scene.soup import PolygonSoup
from viscx.tolerances import DEFAULT_EPSILON, DEFAULT_WELD, MAX_RELATIVE_EPSILON

__all__ = ["Scene", "PolygonSoup", "load_scene", "build_scene", "DEFAULT_WELD", "DEFAULT_EPSILON"]



@dataclass
class Scene(Cached):
    """A clean polygonal scene. All arrays are numpy; ids are positions.

    Attributes
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int
        Triangulation of the faces (for ray casting).
    triangle_face : (t,) int
    face_loop_offsets : (f + 1,) int
    loop_offsets : (l + 1,) int
    loop_vertices : (m,) int
        Face boundaries (see :func:`viscx.scene.faces.face_loops`).
    face_normal : (f, 3) float
    face_offset : (f,) float
        Face plane ``face_normal · x = face_offset``.
    face_area : (f,) float
    face_group : (f,) int
        Index into ``group_names``.
    face_material : (f,) int
        Index into ``material_names``, -1 for none.
    group_names, material_names : list of str
    material_kd, material_ke : (k, 3) float
    half_edges : HalfEdges
    weld_tolerance : float
        Absolute weld tolerance that was used.
    epsilon : float
        Absolute robustness epsilon for everything built on this scene.
    source : str
        Where the scene came from (file path), for messages.
    sha256 : str
        SHA-256 of the source file's bytes ("" when built in memory).
    cache : dict
        Data derived from this scene alone, computed once on first use
        (:meth:`cached`): keyed by the name of the function computing it
        (``"face_planes"``, ``"edge_contacts"``, ``"pencil_planes"``, …). Not an
        argument: :func:`dataclasses.replace` gives the new scene an empty cache, so
        a scene with other vertices or another epsilon never sees stale data.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_face: np.ndarray
    face_loop_offsets: np.ndarray
    loop_offsets: np.ndarray
    loop_vertices: np.ndarray
    face_normal: np.ndarray
    face_offset: np.ndarray
    face_area: np.ndarray
    face_group: np.ndarray
    face_material: np.ndarray
    group_names: list
    material_names: list
    material_kd: np.ndarray
    material_ke: np.ndarray
    half_edges: HalfEdges
    weld_tolerance: float
    epsilon: float
    source: str = ""
    sha256: str = ""
    _caster: object = field(default=None, repr=False, compare=False)
    _contacts: object = field(default=None, repr=False, compare=False)
    cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def n_vertices(self):
        return len(self.vertices)

    @property
    def n_faces(self):
        return len(self.face_area)

    @property
    def bbox(self):
        """(2, 3) float: lower and upper corner of the bounding box (a copy of the cached
        corners: every first hit asks for the diagonal, and a min/max over the vertices
        of a large scene at each call cost more than the hits of a few rays)."""
        return self.cached("bbox", lambda s: np.stack([s.vertices.min(axis=0), s.vertices.max(axis=0)])).copy()

    @property
    def diagonal(self):
        """Length of the bounding-box diagonal."""
        lo, hi = self.bbox
        return float(np.linalg.norm(hi - lo))

    @property
    def generator_edges(self):
        """(g,) int: ids of the generator edges."""
        return np.flatnonzero(self.half_edges.edge_is_generator)

    @property
    def generator_vertices(self):
        """(g,) int: ids of the generator vertices."""
        return np.flatnonzero(self.half_edges.vertex_is_generator)

    def face_loops(self, face):
        """The loops of one face as a list of (k, 3) float arrays, outer loop first."""
        lo, hi = self.face_loop_offsets[face], self.face_loop_offsets[face + 1]
        return [self.vertices[self.loop_vertices[self.loop_offsets[j] : self.loop_offsets[j + 1]]] for j in range(lo, hi)]

    def group_faces(self, name):
        """(k,) int: the faces of the group called ``name``; ViscxError if there is none."""
        if name not in self.group_names:
            raise ViscxError(f"no group named {name!r} (groups: {', '.join(self.group_names)})")
        return np.flatnonzero(self.face_group == self.group_names.index(name))

    def face_ids(self, faces, param="faces"):
        """(k,) int64: the face ids ``faces`` (one int or a sequence); ParameterError
        naming ``param`` for one out of range."""
        ids = np.atleast_1d(np.asarray(faces, dtype=np.int64)).reshape(-1)
        bad = ids[(ids < 0) | (ids >= self.n_faces)]
        if len(bad):
            raise ParameterError(f"{{{param}}} {literal(bad[0])} is out of range (the scene has {self.n_faces} faces: "
                                 f"0 to {self.n_faces - 1})")
        return ids

    @property
    def ray_caster(self):
        """The :class:`viscx.raycast.RayCaster` of this scene (built on first use)."""
        if self._caster is None:
            from viscx.raycast import RayCaster

            self._caster = RayCaster(self.vertices, self.triangles, self.triangle_face, epsilon=self.epsilon)
        return self._caster

    def __getstate__(self):
        """Pickled without its ray tracer, which embree cannot pickle (built again on first
        use where it is read): a dask worker whose tasks cast rays sends its copy of the
        scene on to another worker that lacks it (the 3001-polygon city's V1 on 2 workers
        failed so, "Could not serialize object of type Scene")."""
        return {**self.__dict__, "_caster": None}

    @property
    def contacts(self):
        """The :class:`viscx.scene.neighbourhood.GeneratorContacts` of this scene (built on first use)."""
        if self._contacts is None:
            from viscx.scene.neighbourhood import generator_contacts

            self._contacts = generator_contacts(self)
        return self._contacts


def _relative(value, diagonal, name):
    if value is None:
        return None
    if not np.isfinite(value) or value < 0:
        raise ViscxError(f"{name} must be a finite non-negative number, got {value}")
    return float(value) * diagonal


def build_scene(soup, weld=DEFAULT_WELD, epsilon=None, relative_epsilon=None, source="", sha256=""):
    """Clean a :class:`PolygonSoup` into a :class:`Scene` (see module docstring).

    Parameters
    ----------
    soup : PolygonSoup
    weld : float
        Weld and coplanarity tolerance relative to the bounding-box diagonal.
    epsilon : float, optional
        Absolute robustness epsilon. Default: ``DEFAULT_EPSILON`` × diagonal.
    relative_epsilon : float, optional
        Epsilon relative to the diagonal (instead of ``epsilon``).
    source, sha256 : str
        Provenance, kept in the scene.

    Raises
    ------
    ViscxError
        When no non-degenerate face is left, or an option is out of range.
    """
    name = source or "scene"
    vertices = np.asarray(soup.vertices, dtype=np.float64)
    if soup.n_polygons == 0 or len(vertices) == 0:
        raise ViscxError(f"{name}: no faces")
    if not np.all(np.isfinite(vertices)):
        raise ViscxError(f"{name}: a vertex has a NaN or infinite coordinate")
    diagonal = bounding_diagonal(vertices[np.unique(soup.polygon_vertices)])
    if not np.isfinite(diagonal):
        raise ViscxError(f"{name}: coordinates too large (the bounding box overflows float64)")
    if diagonal == 0:
        raise ViscxError(f"{name}: all vertices coincide; no faces")
    if epsilon is not None and relative_epsilon is not None:
        raise ViscxError("give either epsilon or relative epsilon, not both")
    tolerance = _relative(weld, diagonal, "weld tolerance")
    if epsilon is not None:
        if not np.isfinite(epsilon) or epsilon <= 0:
            raise ViscxError(f"epsilon must be a finite positive number, got {epsilon}")
        eps = float(epsilon)
    else:
        eps = _relative(DEFAULT_EPSILON if relative_epsilon is None else relative_epsilon, diagonal, "relative epsilon")
        if eps <= 0:
            raise ViscxError("relative epsilon must be positive")
    if eps > MAX_RELATIVE_EPSILON * diagonal:
        raise ViscxError(f"epsilon {eps:g} is too large: at most {MAX_RELATIVE_EPSILON:g} of the scene's size "
                         f"(bounding-box diagonal {diagonal:g})")

    triangles, tri_polygon = triangulate_polygons(vertices, soup.polygon_offsets, soup.polygon_vertices)
    crossing = crossing_polygons(vertices, soup.polygon_offsets, soup.polygon_vertices, triangles, tri_polygon, tolerance)
    if crossing.any():
        raise ViscxError(f"{name}: face {int(np.argmax(crossing)) + 1} (in file order) intersects itself: its edges cross")
    vertices, remap = weld_vertices(vertices, tolerance)
    triangles = remap[triangles]
    keep = ~degenerate_triangles(vertices, triangles, tolerance)
    triangles, tri_polygon = triangles[keep], tri_polygon[keep]
    keep = ~duplicate_triangles(triangles)
    triangles, tri_polygon = triangles[keep], tri_polygon[keep]
    if len(triangles) == 0:
        raise ViscxError(f"{name}: every face is degenerate (zero area after welding)")
    # drop vertices no triangle uses, keeping order
    used = np.unique(triangles)
    new_id = np.full(len(vertices), -1, dtype=np.int64)
    new_id[used] = np.arange(len(used))
    vertices, triangles = vertices[used], new_id[triangles]

    tri_group = soup.polygon_group[tri_polygon]
    triangle_face, face_normal, face_offset, face_area = merge_coplanar(vertices, triangles, tri_group, tolerance)
    first = np.full(triangle_face.max() + 1, len(triangles), dtype=np.int64)
    np.minimum.at(first, triangle_face, np.arange(len(triangles)))
    face_group = tri_group[first]
    face_material = soup.polygon_material[tri_polygon[first]]

    flo, lo, lv = face_loops(vertices, triangles, triangle_face, face_normal)
    lo, lv = drop_collinear_vertices(vertices, lo, lv, tolerance)
    half_edges = build_half_edges(vertices, face_normal, flo, lo, lv, tolerance)
    return Scene(
        vertices=vertices,
        triangles=triangles,
        triangle_face=triangle_face,
        face_loop_offsets=flo,
        loop_offsets=lo,
        loop_vertices=lv,
        face_normal=face_normal,
        face_offset=face_offset,
        face_area=face_area,
        face_group=face_group.astype(np.int64),
        face_material=face_material.astype(np.int64),
        group_names=list(soup.group_names),
        material_names=list(soup.material_names),
        material_kd=np.asarray(soup.material_kd, dtype=np.float64).reshape(-1, 3),
        material_ke=np.asarray(soup.material_ke, dtype=np.float64).reshape(-1, 3),
        half_edges=half_edges,
        weld_tolerance=tolerance,
        epsilon=eps,
        source=source,
        sha256=sha256,
    )


def file_sha256(path):
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def load_scene(path, weld=DEFAULT_WELD, epsilon=None, relative_epsilon=None):
    """Load and clean a scene file (OBJ, PLY, or anything trimesh reads).

    Parameters
    ----------
    path : str or Path
    weld, epsilon, relative_epsilon
        See :func:`build_scene`.

    Returns
    -------
    Scene

    Examples
    --------
    >>> scene = load_scene("sample_scenes/cornell_box.obj")     # doctest: +SKIP
    >>> scene.n_faces, len(scene.generator_edges)                # doctest: +SKIP
    """
    from viscx.formats.trimesh_io import read_soup

    path = Path(path)
    soup = read_soup(path)
    return build_scene(soup, weld=weld, epsilon=epsilon, relative_epsilon=relative_epsilon, source=str(path), sha256=file_sha256(path))
