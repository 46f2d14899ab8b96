"""The staged build: scene → nodes (V0) → arcs (V1) → V-cells and EE-cells (V2) → HDF5 file.

Builders are functions of in-memory data and never touch files; this module
chains them, times each stage and keeps the result as a :class:`BuiltComplex`,
which writes itself to a viscx file and reads one back (its levels on first use).
"""

import contextlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viscx.errors import ParameterError, ViscxError
from viscx.formats.hdf5 import (DEFAULT_COMPRESSION, ViscxFile, read_arcs, read_eecells, read_nodes, read_vcells,
                                 write_complex)
from viscx.progress import Stages, peak_memory_gb
from viscx.scene import DEFAULT_WELD, Scene, load_scene


def check_output(scene_path, output):
    """Refuse outputs that cannot be written or would replace the input scene file
    (``scene_path``; None or "" when there is none)."""
    output = Path(output)
    if not output.parent.resolve().is_dir():
        raise ViscxError(f"output folder does not exist: {output.parent}")
    scene_path = Path(scene_path) if scene_path else None
    if scene_path and output.exists() and scene_path.exists() and output.resolve() == scene_path.resolve():
        raise ViscxError(f"the output {output} is the input scene; write it to another file")
    if output.is_dir():
        raise ViscxError(f"the output {output} is a folder")


# The skeleton levels in build order: name, builder(scene, previous levels, quiet) and the
# writer that fills the level's HDF5 group. Level k needs the levels before it.
# A scoped build (:mod:`viscx.skeleton.scope`) passes its scope to V0 and V1 (it has no V2).
def _nodes(scene, built, quiet, scope=None):
    from viscx.skeleton.candidates import build_nodes

    return build_nodes(scene, quiet=quiet, scope=scope)


def _arcs(scene, built, quiet, scope=None):
    from viscx.skeleton.arcs import build_arcs

    return build_arcs(scene, built["V0"], quiet=quiet, scope=scope)


@dataclass
class TwoCells:
    """The V2 level: V-cells and EE-cells, with the seconds each took."""

    vcells: object
    eecells: object
    timings: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.vcells) + len(self.eecells)


def _two_cells(scene, built, quiet):
    from viscx.skeleton.eecells import build_eecells
    from viscx.skeleton.vcells import build_vcells

    t0 = time.perf_counter()
    vcells = build_vcells(scene, built["V1"], quiet=quiet)
    t1 = time.perf_counter()
    eecells = build_eecells(scene, built["V1"], quiet=quiet)
    return TwoCells(vcells, eecells, {"V2 V-cells": t1 - t0, "V2 EE-cells": time.perf_counter() - t1})


def stream_two_cells(scene, arcs, group, runner=None, timings=None, quiet=True):
    """Build V2 chunk by chunk into ``group`` (the file's ``V2``): the V-cells of ranges of
    vertices, then the EE-cells of chunks of squares (:mod:`viscx.skeleton.chunks`), each
    chunk written (:class:`viscx.formats.hdf5.CellsAppender`) before the next is taken, so
    that no more than a few chunks' cells are in memory; the content is
    :func:`_write_two_cells`'s of the whole level.

    Parameters
    ----------
    scene : Scene
    arcs : Arcs
        V1, or what V2 reads of it from the file (:func:`viscx.skeleton.chunks.stored_v2_arcs`:
        the V-cells' chunks then read their own rows, the EE-cells' a slice of arcs at a time).
    group : h5py.Group
    runner : viscx.distributed.InProcess or viscx.distributed.Dask, optional
        What runs the chunks (default: this process).
    timings : dict, optional
        Gets the seconds of the V-cells and of the EE-cells.
    quiet : bool
        No progress bars.

    Returns
    -------
    dict
        ``{"vcells": count, "eecells": count}``.
    """
    from viscx.distributed import InProcess
    from viscx.formats.hdf5 import CellsAppender
    from viscx.progress import bar
    from viscx.skeleton.chunks import eecell_parts, eecells_of_part, vcell_parts, vcells_of_part

    runner = runner or InProcess()
    timings = {} if timings is None else timings
    shared = (scene,)
    t0 = time.perf_counter()
    vcells = CellsAppender(group)
    with bar(desc="V-cells", quiet=quiet, unit="chunk") as progress:
        for cells in runner.map(vcells_of_part, vcell_parts(scene, arcs), shared):
            vcells.append(cells)
            progress.update()
    vcells.close()
    t1 = time.perf_counter()
    eecells = CellsAppender(group, ee=True)
    with bar(desc="EE-cells", quiet=quiet, unit="chunk") as progress:
        for cells, demoted in runner.map(eecells_of_part, eecell_parts(scene, arcs), shared):
            # the demoted loops of every chunk first, then the other chains (as build_eecells)
            n = len(cells.open_offsets) - 1
            eecells.append(cells, slice(0, demoted))
            eecells.hold_chains(cells, slice(demoted, n))
            progress.update()
    eecells.close()
    timings.update({"V2 V-cells": t1 - t0, "V2 EE-cells": time.perf_counter() - t1})
    return {"vcells": vcells.counts.get("cells", 0), "eecells": eecells.counts.get("cells", 0)}


def stream_arcs(scene, nodes, group, runner=None, quiet=True, step=None):
    """Build V1 chunk by chunk into ``group`` (the file's ``V1``): the families and planar
    events of the whole scene (:func:`viscx.skeleton.arcs.builder.arc_families`), then the
    arcs and half-cells of each chunk of families
    (:func:`viscx.skeleton.arcs.builder.arcs_of_families`), each written
    (:class:`viscx.formats.hdf5.ArcsAppender`) before the next is taken, then the XE
    arcs; the content is :func:`viscx.formats.hdf5.write_arcs`'s of the whole level.
    ``nodes`` are read only to find the families, by chunks of rows: the file's
    (:func:`viscx.formats.hdf5.stored_nodes`) are not read whole. ``step(name)``, when
    given, is a context manager around each of the two steps, ``"families"`` and
    ``"chunks of families"`` (``benchmarks/streamed_stages.py`` measures them). Other
    arguments as :func:`stream_two_cells`.

    Returns
    -------
    int
        The arcs written.
    """
    from viscx.distributed import InProcess
    from viscx.formats.hdf5 import ArcsAppender
    from viscx.memory import release_free_memory
    from viscx.progress import bar
    from viscx.skeleton.arcs import crossing_arcs
    from viscx.skeleton.arcs.builder import arc_families, arcs_of_families, family_parts

    runner = runner or InProcess()
    step = step or (lambda name: contextlib.nullcontext())
    with step("families"):
        planar, families = arc_families(scene, nodes, quiet=quiet)
        del nodes
    with step("chunks of families"):
        arcs = ArcsAppender(group)
        with bar(desc="arcs", quiet=quiet, unit="chunk") as progress:
            for part in runner.map(arcs_of_families, family_parts(families), (scene, families.plane_points)):
                arcs.append(*part)
                del part
                progress.update()
        del families
        release_free_memory()
        xe = crossing_arcs(scene)
        if xe is not None:  # after the VE arcs, as build_arcs
            arcs.append(xe)
        arcs.close(planar)
    return len(arcs)


def _write_two_cells(group, cells):
    from viscx.formats import hdf5

    hdf5.write_vcells(group, cells.vcells)
    hdf5.write_eecells(group, cells.eecells)


def _writer(level):
    from viscx.formats import hdf5

    return {"V0": hdf5.write_nodes, "V1": hdf5.write_arcs, "V2": _write_two_cells}[level]


def level_writers(built):
    """``{level name: writer(h5py.Group)}`` of the built levels, for
    :func:`viscx.formats.hdf5.write_complex`."""
    return {name: (lambda g, name=name: _writer(name)(g, built[name])) for name in built}


LEVELS = [("V0", _nodes), ("V1", _arcs), ("V2", _two_cells)]
NOUNS = {"V0": "nodes", "V1": "arcs", "V2": "V- and EE-cells"}
LONG_NOUNS = {**NOUNS, "V2": "V-cells and EE-cells"}
MAX_LEVEL = len(LEVELS) - 1


@dataclass
class BuiltComplex:
    """The visibility complex of a scene in memory: the scene, its built levels, the free
    points added as generators and the options it was built with. A complex opened from
    a viscx file (:func:`open_complex`) reads each level on first use. Data only: the
    queries are methods of :class:`viscx.api.Complex`.

    Attributes
    ----------
    scene : Scene
    built : dict
        ``{level name: built level}`` of the levels in memory: ``"V0"``
        (:class:`viscx.skeleton.nodes.Nodes`), ``"V1"`` (:class:`viscx.skeleton.arcs.Arcs`),
        ``"V2"`` (:class:`TwoCells`).
    points : (k, 3) float64
        Free points added as generator vertices ``n_vertices + i`` (empty when none).
    options : dict
        The build options, as ``viscx build`` stores them (the ``options`` attribute).
    timings : dict
        Seconds per build stage.
    path : Path or None
        The viscx file the levels not yet read come from.
    stored : list of str
        The levels of that file.
    """

    scene: object
    built: dict = field(default_factory=dict)
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    options: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    path: Path = None
    stored: list = field(default_factory=list)
    parts: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def levels(self):
        """The names of the levels it holds, in build order: list of str."""
        return [name for name, _ in LEVELS if name in self.built or name in self.stored]

    def level(self, name):
        """The built level ``name`` (``"V0"``, ``"V1"`` or ``"V2"``), read from the file on
        first use; ViscxError when the complex does not hold it."""
        if name not in self.built:
            if name == "V2":  # its two parts, each read on its own first use
                self.built[name] = TwoCells(self.vcells, self.eecells)
            else:
                self.built[name] = self._read(name, {"V0": read_nodes, "V1": read_arcs}[name])
        return self.built[name]

    def size(self, name):
        """The number of elements of level ``name`` (nodes, arcs, V- and EE-cells) without
        reading a level not in memory (its stored counts)."""
        if name in self.built:
            return len(self.built[name])
        with ViscxFile(self.path) as f:
            if name != "V2":
                return len(f.h5[name]["kind"])
            counts = json.loads(f.h5[name].attrs.get("counts", "{}"))
        return counts.get("cells", 0) + counts.get("ee_cells", 0)

    @property
    def nodes(self):
        """:class:`viscx.skeleton.nodes.Nodes`: V0."""
        return self.level("V0")

    @property
    def arcs(self):
        """:class:`viscx.skeleton.arcs.Arcs`: V1."""
        return self.level("V1")

    @property
    def vcells(self):
        """:class:`viscx.skeleton.vcells.VCells`: the V-cells of V2."""
        if "V2" in self.built:
            return self.built["V2"].vcells
        return self._read("V2", read_vcells, part="vcells")

    @property
    def eecells(self):
        """:class:`viscx.skeleton.eecells.EECells`: the EE-cells of V2."""
        if "V2" in self.built:
            return self.built["V2"].eecells
        return self._read("V2", read_eecells, part="eecells")

    def _read(self, name, reader, part=None):
        """``reader(group)`` of level ``name``'s group in the file, kept under ``part``."""
        if part in self.parts:
            return self.parts[part]
        if name not in self.stored:
            order = [level for level, _ in LEVELS]
            raise ParameterError(f"the complex has no {LONG_NOUNS[name]} ({name}); build it with "
                                 f"{{levels}} {order.index(name)} or more")
        with ViscxFile(self.path) as f:
            value = reader(f.h5[name])
        if part is not None:
            self.parts[part] = value
        return value

    def save(self, path, compression=DEFAULT_COMPRESSION):
        """Write the complex to a viscx file, atomically (a temporary file renamed when
        complete): the content ``viscx build`` writes for the same scene and options.

        Parameters
        ----------
        path : str or Path
        compression : str
            The HDF5 filter of the large datasets (:data:`viscx.formats.hdf5.COMPRESSIONS`).
        """
        from viscx.formats.atomic import release_input

        check_output(self.scene.source, path)
        built = {name: self.level(name) for name in self.levels}  # all read before the file is replaced
        release_input(path)  # asked for: may be a file read before (this complex's own, too)
        write_complex(path, self.scene, levels=level_writers(built), options=self.options, timings=self.timings,
                      points=self.points if len(self.points) else None, compression=compression)


def open_complex(path, need=None, hint=""):
    """The complex stored in a viscx file: the scene, points and options now, the levels
    on first use (:meth:`BuiltComplex.level`).

    Parameters
    ----------
    path : str or Path
    need : str, optional
        A level the caller needs (``"V2"``): ViscxError now when the file lacks it.
    hint : str
        Appended to that message (another way to get an answer).

    Raises ViscxError for a file that is not a valid viscx file.
    """
    with ViscxFile(path) as f:
        stored = [name for name in f.levels if name in f.h5 and name in dict(LEVELS)]
        cx = BuiltComplex(f.read_scene(), points=f.read_points(), options=f.options, timings=f.timings,
                          path=Path(path), stored=stored)
    return cx if need is None else require_level(cx, need, path, hint)


def require_level(cx, need, path, hint=""):
    """``cx`` (opened from the viscx file ``path`` by :func:`open_complex`) when it stores
    the level ``need``, else the ViscxError of :func:`open_complex` (``hint`` appended)."""
    if need not in cx.stored:
        raise ViscxError(f"{path} has no {LONG_NOUNS[need]} ({need}); build it with `viscx build` (all levels){hint}")
    return cx


def scene_of(source, epsilon=None, relative_epsilon=None, weld=None):
    """The :class:`Scene` of a scene file, a trimesh mesh or scene, or a Scene.

    Parameters
    ----------
    source : str, Path, trimesh.Trimesh, trimesh.Scene or Scene
    epsilon, relative_epsilon, weld
        See :func:`viscx.scene.build_scene` (``weld`` None: its default). A Scene keeps
        the ones it was built with: giving them is an error.
    """
    from viscx.scene import Scene, build_scene

    if isinstance(source, Scene):
        given = [name for name, v in (("epsilon", epsilon), ("relative_epsilon", relative_epsilon), ("weld", weld))
                 if v is not None]
        if given:
            raise ParameterError(f"a Scene keeps the epsilon and weld it was built with: {{{given[0]}}} "
                                 "applies to a scene file or a trimesh only")
        return source
    weld = DEFAULT_WELD if weld is None else weld
    if isinstance(source, (str, Path)):
        return load_scene(source, weld=weld, epsilon=epsilon, relative_epsilon=relative_epsilon)
    from viscx.formats.trimesh_io import soup_of_trimesh

    # a mesh read by trimesh.load keeps its file's name: its group is named as `viscx build` names it
    name = Path(str(getattr(getattr(source, "source", None), "file_name", None) or "mesh")).stem
    soup = soup_of_trimesh(source, name)
    return build_scene(soup, weld=weld, epsilon=epsilon, relative_epsilon=relative_epsilon)


#: The last level a scoped build holds (V0 and V1 of the light's families).
SCOPED_LEVEL = 1


def light_option(options):
    """The light a viscx file was scoped to, from its build options: ``{"light_face": I}``,
    ``{"light_group": NAME}``, or None for a full build."""
    light = options.get("light")
    return dict(light) if isinstance(light, dict) else None


def build_complex(source, epsilon=None, relative_epsilon=None, weld=None, levels=None, quiet=False,
                  points=None, output=None, compression=DEFAULT_COMPRESSION, light_face=None, light_group=None,
                  runner=None):
    """Build the visibility complex of a scene and, given ``output``, write it there.

    Parameters
    ----------
    source : str, Path, trimesh.Trimesh, trimesh.Scene or Scene
        A scene file (OBJ, PLY, or anything trimesh reads), a trimesh mesh or scene, or
        a cleaned scene (:func:`scene_of`).
    epsilon, relative_epsilon, weld
        See :func:`viscx.scene.build_scene` (``weld`` None: ``DEFAULT_WELD``).
    levels : int, optional
        The last skeleton level to build: -1 the scene only, 0 the nodes (V0),
        1 also the arcs (V1), 2 also the V-cells and EE-cells (V2). Default: every level
        the build can hold.
    quiet : bool
        No progress bars.
    points : (k, 3) float64, optional
        Free points (lights, viewpoints) added as generator vertices n, n + 1, …
        (:mod:`viscx.skeleton.points`); stored as ``/scene/points``.
    output : str or Path, optional
        The viscx file to write (:meth:`BuiltComplex.save`).
    compression : str
        The HDF5 filter of the large datasets (:data:`viscx.formats.hdf5.COMPRESSIONS`).
    light_face, light_group : int or str, optional
        A *scoped* build for one area light (a face, or the faces of a group): only the
        nodes and arcs of the families with one of the light's outline vertices or edges
        (:mod:`viscx.skeleton.scope`), what its discontinuity mesh and renders need; levels
        up to V1 (:data:`SCOPED_LEVEL`; more is refused). Stored as the option ``light``.
    runner : viscx.distributed.InProcess or viscx.distributed.Dask, optional
        What runs V1's and V2's chunks (:func:`viscx.distributed.runner`; default this
        process). With an ``output``, no ``points`` and no light, V1 and V2 are built
        chunk by chunk into the file (:func:`stream_arcs`, :func:`stream_two_cells`) and
        never held whole: the complex returned then reads them (and V0) from the file on
        first use. The file is the same either way.

    Returns
    -------
    BuiltComplex
    """
    scoped = light_face is not None or light_group is not None
    if levels is None:
        levels = SCOPED_LEVEL if scoped else MAX_LEVEL
    if not -1 <= levels <= MAX_LEVEL:
        raise ParameterError(f"{{levels}} must be between -1 (scene only) and {MAX_LEVEL}")
    if scoped:
        if levels > SCOPED_LEVEL:
            raise ParameterError(f"a build for one light ({{light_group}}/{{light_face}}) holds levels up to "
                                 f"{SCOPED_LEVEL} (V0 and V1 of the light's families); {{levels}} {levels} needs a full build")
        if points is not None and len(points):
            raise ParameterError("{points} and a light ({light_group}/{light_face}) cannot be combined: build one or "
                                 "the other")
    if output is not None and isinstance(source, (str, Path)):
        check_output(source, output)
    built = {}
    points = None if points is None else np.asarray(points, dtype=np.float64).reshape(-1, 3)
    has_points = points is not None and len(points) > 0
    # V1 and V2 built into the file chunk by chunk, after V0 is written
    stream = output is not None and levels >= 1 and not has_points and not scoped
    names = ["scene", *[name for name, _ in LEVELS[: levels + 1]], *(["points"] if has_points else []),
             *(["write"] if output is not None else [])]
    with Stages(names, "build", quiet=quiet) as stages:
        try:
            with stages.stage("scene"):
                scene = scene_of(source, weld=weld, epsilon=epsilon, relative_epsilon=relative_epsilon)
                scope = light_scope(scene, light_face, light_group) if scoped else None

            for name, builder in LEVELS[: 1 if stream else levels + 1]:
                with stages.stage(name):
                    built[name] = builder(scene, built, quiet, **({"scope": scope} if scoped else {}))
                stages.timings.update(getattr(built[name], "timings", {}))

            if has_points:
                from viscx.skeleton.points import add_points, build_points, check_points

                with stages.stage("points"):
                    check_points(scene, points)
                    if built:  # the points' nodes, arcs and cells, merged into the built levels
                        built.update(add_points(built, build_points(scene, points)))

            options = {"epsilon": scene.epsilon, "relative_epsilon": relative_epsilon,
                       "weld": DEFAULT_WELD if weld is None and not isinstance(source, Scene) else weld,
                       "levels": levels}
            if has_points:
                options["points"] = len(points)
            if scoped:
                options["light"] = {"light_face": int(light_face)} if light_face is not None else {"light_group": light_group}
            cx = BuiltComplex(scene, built, points if has_points else np.zeros((0, 3)), options, stages.timings)
            if stream:
                _write_streamed(cx, output, compression, stages, runner, quiet)
            elif output is not None:
                with stages.stage("write"):
                    cx.save(output, compression=compression)
        except MemoryError:
            raise ViscxError(out_of_memory(stages.current)) from None
    return cx


def _write_streamed(cx, output, compression, stages, runner, quiet):
    """Write ``cx`` (V0 built) to ``output``, V1 and V2 (up to its ``levels`` option) built
    into the file chunk by chunk (:func:`stream_arcs`, :func:`stream_two_cells`); ``cx``
    then reads them from the file."""
    from viscx.formats.atomic import release_input
    from viscx.formats.hdf5 import complex_writer, stored_nodes
    from viscx.memory import release_free_memory
    from viscx.skeleton.chunks import stored_v2_arcs

    check_output(cx.scene.source, output)
    release_input(output)  # as BuiltComplex.save
    names = [name for name, _ in LEVELS[: cx.options["levels"] + 1]]
    with complex_writer(output, cx.scene, names, cx.options, stages.timings, compression=compression) as f:
        with stages.stage("write"):
            for name, writer in level_writers(cx.built).items():
                writer(f.create_group(name, track_order=True))
        with stages.stage("V1"):
            # V1 reads the nodes back from the file chunk by chunk (and so does cx if asked)
            del cx.built["V0"]
            release_free_memory()
            stream_arcs(cx.scene, stored_nodes(f["V0"]), f.create_group("V1", track_order=True), runner, quiet)
        if "V2" in names:
            with stages.stage("V2"):
                # V2 reads a fifth of V1: read back from the file (only stream_two_cells holds it)
                stream_two_cells(cx.scene, stored_v2_arcs(f["V1"]), f.create_group("V2", track_order=True), runner,
                                 stages.timings, quiet)
    cx.path, cx.stored = Path(output), names


def light_scope(scene, light_face=None, light_group=None):
    """The :class:`viscx.skeleton.scope.Scope` of an area light's outline (its vertices and
    edges, :func:`viscx.scene.light.light_of`; ViscxError for an unknown face or group)."""
    from viscx.scene.light import light_of
    from viscx.skeleton.scope import Scope

    light = light_of(scene, light_face, light_group)
    return Scope.of(scene, light.vertices, light.edges)


def build_file(scene_path, output, epsilon=None, relative_epsilon=None, weld=DEFAULT_WELD, levels=MAX_LEVEL,
               quiet=False, points=None, compression=DEFAULT_COMPRESSION):
    """Build the visibility complex of a scene file and write it to ``output``
    (:func:`build_complex`).

    Returns
    -------
    scene : Scene
    built : dict
        ``{level name: built level}``.
    timings : dict
        Seconds per stage.
    """
    cx = build_complex(scene_path, epsilon=epsilon, relative_epsilon=relative_epsilon, weld=weld, levels=levels,
                       quiet=quiet, points=points, output=output, compression=compression)
    return cx.scene, cx.built, cx.timings


def out_of_memory(stage):
    """The one-line message for a build that ran out of memory in ``stage``."""
    order = [name for name, _ in LEVELS]
    fewer = f"build fewer levels (--levels {order.index(stage) - 1}), " if stage in order[1:] else ""
    return (f"out of memory in the {stage} stage (peak {peak_memory_gb():.1f} GB); "
            f"{fewer}build a smaller scene, or use a machine with more memory")
