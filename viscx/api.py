"""The library in a notebook: build or open a visibility complex and query it in memory.

    >>> import viscx
    >>> cx = viscx.build("sample_scenes/cornell_box.obj")        # doctest: +SKIP
    >>> view = cx.shadows([278, 540, 280])                        # doctest: +SKIP
    >>> cx.save("cornell.h5")                                     # doctest: +SKIP

:func:`build` and :func:`open` return a :class:`Complex`; its methods are the queries
of the ``viscx`` command, which calls the same functions (the CLI only parses options
and writes files). Errors are :class:`viscx.errors.ViscxError` with a one-line
message naming the parameters as spelled here.
"""

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viscx.errors import ParameterError
from viscx.pipeline import MAX_LEVEL, BuiltComplex, build_complex, open_complex

__all__ = ["Complex", "FormFactor", "build", "open", "form_factor", "form_factor_matrix", "render_light"]

SIDES = {"front": 1, "back": -1}


@dataclass
class FormFactor:
    """A form factor and how it was computed.

    Attributes
    ----------
    F : float
        The form factor (a fraction of the energy leaving the source).
    error : float
        Its absolute error estimate (0.0 for the exact point-to-face form factor).
    record : dict
        Every field ``viscx formfactor`` writes (the JSON schema of docs/queries.md):
        the per-side or per-face parts, the tolerance, the seconds it took.
    """

    F: float
    error: float
    record: dict = field(default_factory=dict, repr=False)


class Complex(BuiltComplex):
    """The visibility complex of a scene, in memory (see :class:`viscx.pipeline.BuiltComplex`
    for its data: ``scene``, ``levels``, ``nodes``, ``arcs``, ``vcells``, ``eecells``,
    ``points``, ``options``), with its queries as methods. A complex from :func:`open`
    reads each level from its file on first use.
    """

    def __repr__(self):
        name = Path(self.scene.source).name if self.scene.source else "a scene in memory"
        points = f", {len(self.points)} points" if len(self.points) else ""
        return f"<viscx.Complex of {name}: {self.scene.n_faces} faces, levels {self.levels}{points}>"

    @classmethod
    def of(cls, built):
        """The :class:`Complex` holding what ``built`` (a BuiltComplex) holds (no copy)."""
        cx = cls(built.scene, built.built, built.points, built.options, built.timings, built.path, built.stored)
        cx.parts.update(built.parts)
        return cx

    def visible(self, point):
        """The visibility polyhedron of a point (Hoberock et al. §7.1): per face, the part
        the point sees, from the point's V-cells (the complex's when the point is one of
        its free points, else computed on demand).

        Parameters
        ----------
        point : (3,) float
            In scene units, outside every solid.

        Returns
        -------
        viscx.queries.visibility.PointView
            ``faces[f].polygons``: list of ``(outer (k, 3) float64, holes [(k, 3) float64])``,
            outer counter-clockwise seen from the face's front; ``faces[f].area()``.
        """
        from viscx.queries.visibility import view_from

        return view_from(self, point)[0]

    def shadows(self, light):
        """The lit polygons and shadow boundaries of a point light (Hoberock et al. §7.2):
        the light's view, a face lit where the light sees it.

        Parameters
        ----------
        light : (3,) float

        Returns
        -------
        viscx.queries.visibility.PointView
            ``faces[f].loops``: the lit loops, list of (k, 3) float64;
            ``faces[f].boundary``: (b, 2, 3) float64 shadow-boundary segments;
            ``faces[f].area()``: the lit area.
        """
        from viscx.queries.shadows import shadows

        return shadows(self, light)[1]

    def formfactor(self, to_face=None, to_group=None, point=None, normal=None, from_face=None, from_group=None,
                   from_side="front", tol=None, quiet=True):
        """A form factor (:func:`form_factor`): from a differential area (``point``,
        ``normal``; exact), or from a side of a face or a group (``from_face`` /
        ``from_group``, ``from_side``; error estimate below ``tol``) to a face or a group
        (``to_face`` / ``to_group``, both sides); a progress bar unless ``quiet``. Returns
        :class:`FormFactor`."""
        return form_factor(self, to_face=to_face, to_group=to_group, point=point, normal=normal, from_face=from_face,
                           from_group=from_group, from_side=from_side, tol=tol, quiet=quiet)

    def formfactor_matrix(self, tol=None, quiet=True):
        """Every pair of face sides, sparse, with the sky term (:func:`form_factor_matrix`).
        Returns :class:`viscx.queries.formfactor.Matrix`."""
        return form_factor_matrix(self, tol=tol, quiet=quiet)

    def discontinuities(self, light_face=None, light_group=None, faces=()):
        """The discontinuity mesh of an area light (Hoberock et al. §7.5), from V1's arcs.

        Parameters
        ----------
        light_face : int, optional
        light_group : str, optional
            The light: one face or the faces of a group (exactly one of the two).
        faces : sequence of int
            Receivers to subdivide (default: every face not in the light).

        Returns
        -------
        viscx.queries.discontinuities.DiscontinuityMesh
            ``receivers[k].regions``: the regions of each receiver (2-D loops in its
            ``frame``; ``receivers[k].to3`` maps them to 3-D); ``points`` (p, 3) float64
            and ``offsets`` (m + 1,) int64: the traced events as polylines.
        """
        from viscx.queries.discontinuities import light_mesh

        return light_mesh(self, light_face, light_group, faces)

    def render(self, eye, look_at, up=(0.0, 1.0, 0.0), fov=39.3, size=(512, 512), light_face=None, light_group=None,
               radiance=None, samples=None, reference=None, seed=0, regions=False):
        """The direct illumination from an area light seen by a pinhole camera
        (:func:`render_light`).

        Parameters
        ----------
        eye, look_at, up : (3,) float
        fov : float
            Vertical field of view, degrees.
        size : (int, int)
            Width and height in pixels.
        light_face, light_group
            The light (exactly one), as in :meth:`discontinuities`.
        radiance : (3,) float, optional
            The light's emitted radiance (default: its material's Ke).
        samples : int, optional
            Sparse reconstruction from this many samples.
        reference : int, optional
            Monte Carlo with this many light samples per pixel instead.
        seed : int
        regions : bool
            Label the pixels by the regions of the light's discontinuity mesh (made from
            V1; the sparse reconstruction always is).

        Returns
        -------
        viscx.render.image.Render
            ``radiance``: (h, w, 3) float64 linear radiance; ``label``: (h, w) int64 the
            pixels' (face, side, region) (region -1 without the mesh).
        """
        return render_light(self, eye, look_at, up, fov, size, light_face=light_face, light_group=light_group,
                            radiance=radiance, samples=samples, reference=reference, seed=seed, regions=regions)


def build(scene, levels=MAX_LEVEL, epsilon=None, relative_epsilon=None, weld=None, points=None, quiet=True):
    """Build the visibility complex of a scene, in memory.

    Parameters
    ----------
    scene : str, Path, trimesh.Trimesh, trimesh.Scene or viscx.scene.Scene
        A scene file (OBJ, PLY, or anything trimesh reads), a trimesh mesh or scene, or a
        cleaned scene (:func:`viscx.load_scene`; it keeps its own epsilon and weld).
    levels : int
        The last level to build: -1 the scene only, 0 the nodes (V0), 1 also the arcs
        (V1), 2 also the V-cells and EE-cells (V2, the default).
    epsilon, relative_epsilon, weld : float, optional
        See :func:`viscx.scene.build_scene`.
    points : (k, 3) float, optional
        Free points (lights, viewpoints) built as generators, as ``viscx build --point``.
    quiet : bool
        No progress bars.

    Returns
    -------
    Complex
        ``save`` writes what ``viscx build`` writes for the same scene and options.
    """
    return Complex.of(build_complex(scene, epsilon=epsilon, relative_epsilon=relative_epsilon, weld=weld,
                                    levels=levels, quiet=quiet, points=points))


def open(path):  # noqa: A001 -- viscx.open, as a notebook reads
    """The complex stored in a viscx file (written by ``viscx build`` or
    :meth:`Complex.save`); its levels are read on first use.

    Returns
    -------
    Complex
    """
    return Complex.of(open_complex(path))


def _side(from_side):
    if from_side not in SIDES:
        raise ParameterError("{from_side} must be front or back, not " + repr(from_side).replace("{", "{{"))
    return SIDES[from_side]


def form_factor(query, to_face=None, to_group=None, point=None, normal=None, from_face=None, from_group=None,
                from_side="front", tol=None, quiet=True):
    """A form factor from a complex (Hoberock et al. §7.4; method in docs/queries.md).

    Three forms, by the source given:

    - ``point`` and ``normal``: a differential area; exact (its V-cells and Lambert's formula);
    - ``from_face`` and ``to_face``: one side of face i to face j (both of its sides),
      occlusion-exact integrand, adaptive quadrature to ``tol``;
    - ``from_group`` or ``from_face``, ``to_group`` or ``to_face`` (a group on either
      side): area-weighted over the emitting faces.

    Parameters
    ----------
    query : viscx.pipeline.BuiltComplex
    to_face : int, optional
    to_group : str, optional
        The receiver (exactly one).
    point, normal : (3,) float, optional
    from_face : int, optional
    from_group : str, optional
        The source (exactly one of ``point``, ``from_face``, ``from_group``).
    from_side : str
        ``"front"`` (the side of the face normal) or ``"back"``.
    tol : float, optional
        Target on each polygon pair's absolute error estimate (default
        :data:`viscx.queries.formfactor.DEFAULT_TOL`).
    quiet : bool
        No progress bar (the faces' and groups' cubatures).

    Returns
    -------
    FormFactor
    """
    from viscx.queries import formfactor as ff

    scene = query.scene
    if sum(x is not None for x in (point, from_face, from_group)) != 1:
        raise ParameterError("give exactly one source: {point} (with {normal}), {from_face} or {from_group}")
    if (to_face is None) == (to_group is None):
        raise ParameterError("give exactly one receiver: {to_face} or {to_group}")
    if (point is None) != (normal is None):
        raise ParameterError("{point} needs {normal} (and {normal} needs {point})")
    if tol is not None and not tol > 0:
        raise ParameterError("{tol} must be positive")
    target = {"to_face": int(to_face)} if to_face is not None else {"to_group": to_group}
    faces = scene.face_ids(to_face, "to_face") if to_face is not None else scene.group_faces(to_group)
    t0 = time.perf_counter()
    if point is not None:
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(n)) and np.any(n != 0)):
            raise ParameterError("{normal} must be a non-zero vector")
        r = ff.point_to_faces(query, point, n, [int(f) for f in faces])
        return FormFactor(r["F"], 0.0, {"F": r.pop("F"), **target, **r})
    side = _side(from_side)
    tol = tol or ff.DEFAULT_TOL
    if from_face is not None:
        sources, source = scene.face_ids(from_face, "from_face"), {"from_face": int(from_face)}
    else:
        sources, source = scene.group_faces(from_group), {"from_group": from_group}
    if from_face is not None and to_face is not None:
        if from_face == to_face:
            raise ParameterError("{from_face} and {to_face} are the same face (a planar face does not see itself)")
        r = ff.face_to_face(scene, int(from_face), int(to_face), side_i=side, tol=tol, quiet=quiet)
        record = {"F": r["F"], "error": r["error"], **source, "from_side": from_side, **target, "sides": r["sides"],
                  "tol_reached": r["tol_reached"]}
    else:
        r = ff.group_to_group(scene, [int(f) for f in sources], [int(f) for f in faces], side_i=side, tol=tol,
                              quiet=quiet)
        record = {"F": r["F"], "error": r["error"], **source, "from_side": from_side, **target, "pairs": r["pairs"],
                  "tol_reached": r["tol_reached"]}
    record["tol"] = tol
    record["seconds"] = round(time.perf_counter() - t0, 4)
    return FormFactor(record["F"], record["error"], record)


def form_factor_matrix(query, tol=None, quiet=True, gap_search=True):
    """F between every pair of face sides (sparse) with every side's sky term
    (:func:`viscx.queries.formfactor.form_factor_matrix`).

    Parameters
    ----------
    query : viscx.pipeline.BuiltComplex
    tol : float, optional
        Target on each entry's error estimate (default :data:`viscx.queries.formfactor.MATRIX_TOL`).
    quiet : bool
        No progress bar.
    gap_search : bool
        Rows on three levels look for receivers seen through gaps between their nodes
        (:func:`viscx.queries.formfactor.row_gaps`, the default; without, such an entry
        says 0 with a small estimate; at 1e-4 1.05 times the rows' CPU on office(300),
        1.155 on office(1000)).

    Returns
    -------
    viscx.queries.formfactor.Matrix
    """
    from viscx.queries import formfactor as ff

    if tol is not None and not tol > 0:
        raise ParameterError("{tol} must be positive")
    return ff.form_factor_matrix(query.scene, tol=tol or ff.MATRIX_TOL, quiet=quiet, gap_search=gap_search)


def render_light(query, eye, look_at, up=(0.0, 1.0, 0.0), fov=39.3, size=(512, 512), light_face=None,
                 light_group=None, radiance=None, samples=None, reference=None, seed=0, progress=None, regions=False):
    """Render the direct illumination from an area light (:func:`viscx.render.image.render`).
    The light's discontinuity mesh (:func:`viscx.queries.discontinuities.light_mesh`, from
    the complex's V1) is made only for the sparse reconstruction (``samples``) and for
    ``regions``: the exact image and the Monte Carlo reference need the scene only.

    Parameters
    ----------
    query : viscx.pipeline.BuiltComplex
    eye, look_at, up, fov, size, light_face, light_group, radiance, samples, reference, seed, regions
        See :meth:`Complex.render`.
    progress : callable, optional
        Called with the pixels done (Monte Carlo only).

    Returns
    -------
    viscx.render.image.Render
    """
    from viscx.queries.discontinuities import light_mesh
    from viscx.render.camera import Camera
    from viscx.render.image import render
    from viscx.scene.light import light_of

    if samples is not None and reference is not None:
        raise ParameterError("give {samples} or {reference}, not both")
    if samples is not None and samples < 0:
        raise ParameterError(f"{{samples}} {int(samples)} must be at least 0")
    if reference is not None and reference < 1:
        raise ParameterError(f"{{reference}} {int(reference)} must be at least 1")
    camera = Camera(eye, look_at, up, fov, int(size[0]), int(size[1]))
    if samples is not None or regions:
        mesh, light = light_mesh(query, light_face, light_group), None
    else:
        mesh, light = None, light_of(query.scene, light_face, light_group)
    return render(query.scene, mesh, camera, radiance=radiance, samples=samples, reference=reference, seed=seed,
                  progress=progress, light=light)

