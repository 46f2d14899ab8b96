"""The staged build: scene → (later: nodes → arcs → V/EE cells) → HDF5 file.

Builders are functions of in-memory data and never touch files; this module
chains them, times each stage and hands everything to the writer.
"""

import time
from pathlib import Path

from viscx.errors import ViscxError
from viscx.formats.hdf5 import write_complex
from viscx.progress import bar
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


def build_file(scene_path, output, epsilon=None, relative_epsilon=None, weld=DEFAULT_WELD, quiet=False):
    """Build the visibility complex of a scene file and write it to ``output``.

    Parameters
    ----------
    scene_path, output : str or Path
    epsilon, relative_epsilon, weld
        See :func:`viscx.scene.build_scene`.
    quiet : bool
        No progress bars.

    Returns
    -------
    scene : Scene
    timings : dict
        Seconds per stage.
    """
    check_output(scene_path, output)
    timings = {}
    stages = ["scene", "write"]
    with bar(total=len(stages), desc="build", quiet=quiet, unit="stage") as progress:
        t0 = time.perf_counter()
        progress.set_postfix_str("scene")
        scene = load_scene(scene_path, weld=weld, epsilon=epsilon, relative_epsilon=relative_epsilon)
        timings["scene"] = time.perf_counter() - t0
        progress.update()

        t0 = time.perf_counter()
        progress.set_postfix_str("write")
        options = {"epsilon": scene.epsilon, "relative_epsilon": relative_epsilon, "weld": weld}
        write_complex(output, scene, options=options, timings=timings)
        timings["write"] = time.perf_counter() - t0
        progress.update()
    return scene, timings
