"""The staged build: scene → nodes (V0) → arcs (V1) → V-cells and EE-cells (V2) → HDF5 file.

Builders are functions of in-memory data and never touch files; this module
chains them, times each stage and hands everything to the writer.
"""

import time
from dataclasses import dataclass, field
from pathlib import Path

from viscx.errors import ViscxError
from viscx.formats.hdf5 import DEFAULT_COMPRESSION, write_complex
from viscx.progress import Stages, peak_memory_gb
from viscx.scene import DEFAULT_WELD, load_scene


def check_output(scene_path, output):
    """Refuse outputs that cannot be written or would replace the input."""
    output, scene_path = Path(output), Path(scene_path)
    if not output.parent.resolve().is_dir():
        raise ViscxError(f"output folder does not exist: {output.parent}")
    if output.exists() and scene_path.exists() and output.resolve() == scene_path.resolve():
        raise ViscxError(f"the output {output} is the input scene; choose another -o")
    if output.is_dir():
        raise ViscxError(f"the output {output} is a folder")


# The skeleton levels in build order: name, builder(scene, previous levels, quiet) and the
# writer that fills the level's HDF5 group. Level k needs the levels before it.
def _nodes(scene, built, quiet):
    from viscx.skeleton.candidates import build_nodes

    return build_nodes(scene, quiet=quiet)


def _arcs(scene, built, quiet):
    from viscx.skeleton.arcs import build_arcs

    return build_arcs(scene, built["V0"], quiet=quiet)


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
MAX_LEVEL = len(LEVELS) - 1


def build_file(scene_path, output, epsilon=None, relative_epsilon=None, weld=DEFAULT_WELD, levels=MAX_LEVEL,
               quiet=False, points=None, compression=DEFAULT_COMPRESSION):
    """Build the visibility complex of a scene file and write it to ``output``.

    Parameters
    ----------
    scene_path, output : str or Path
    epsilon, relative_epsilon, weld
        See :func:`viscx.scene.build_scene`.
    levels : int
        The last skeleton level to build: -1 the scene only, 0 the nodes (V0),
        1 also the arcs (V1), 2 also the V-cells and EE-cells (V2).
    quiet : bool
        No progress bars.
    points : (k, 3) float64, optional
        Free points (lights, viewpoints) added as generator vertices n, n + 1, …
        (:mod:`viscx.skeleton.points`); stored as ``/scene/points``.
    compression : str
        The HDF5 filter of the large datasets (:data:`viscx.formats.hdf5.COMPRESSIONS`).

    Returns
    -------
    scene : Scene
    built : dict
        ``{level name: built level}``.
    timings : dict
        Seconds per stage.
    """
    if not -1 <= levels <= MAX_LEVEL:
        raise ViscxError(f"--levels must be between -1 (scene only) and {MAX_LEVEL}")
    check_output(scene_path, output)
    built = {}
    has_points = points is not None and len(points) > 0
    names = ["scene", *[name for name, _ in LEVELS[: levels + 1]], *(["points"] if has_points else []), "write"]
    with Stages(names, "build", quiet=quiet) as stages:
        try:
            with stages.stage("scene"):
                scene = load_scene(scene_path, weld=weld, epsilon=epsilon, relative_epsilon=relative_epsilon)

            for name, builder in LEVELS[: levels + 1]:
                with stages.stage(name):
                    built[name] = builder(scene, built, quiet)
                stages.timings.update(getattr(built[name], "timings", {}))

            if has_points:
                from viscx.skeleton.points import add_points, build_points, check_points

                with stages.stage("points"):
                    check_points(scene, points)
                    if built:  # the points' nodes, arcs and cells, merged into the built levels
                        built.update(add_points(built, build_points(scene, points)))

            with stages.stage("write"):
                options = {"epsilon": scene.epsilon, "relative_epsilon": relative_epsilon, "weld": weld,
                           "levels": levels}
                if has_points:
                    options["points"] = len(points)
                write_complex(output, scene, levels=level_writers(built), options=options, timings=stages.timings,
                              points=points if has_points else None, compression=compression)
        except MemoryError:
            raise ViscxError(out_of_memory(stages.current)) from None
    return scene, built, stages.timings


def out_of_memory(stage):
    """The one-line message for a build that ran out of memory in ``stage``."""
    order = [name for name, _ in LEVELS]
    fewer = f"build fewer levels (--levels {order.index(stage) - 1}), " if stage in order[1:] else ""
    return (f"out of memory in the {stage} stage (peak {peak_memory_gb():.1f} GB); "
            f"{fewer}build a smaller scene, or use a machine with more memory")
