"""``viscx build``: build the visibility complex of a scene file."""

import time
from pathlib import Path

import click

from viscx.cli.options import epsilon_option, light_options, output_option, point_option, quiet, relative_epsilon_option
from viscx.formats.compression import COMPRESSIONS, DEFAULT_COMPRESSION
from viscx.tolerances import DEFAULT_WELD


@click.command(short_help="Build the visibility complex of a scene into an HDF5 file.")
@click.argument("scene_file", metavar="SCENE", type=click.Path(dir_okay=True))
@output_option("Output HDF5 file. Default: SCENE's name with .h5, in the current folder.", required=False)
@epsilon_option
@relative_epsilon_option
@click.option(
    "--weld",
    type=float,
    default=DEFAULT_WELD,
    show_default=True,
    help="Vertices closer than this fraction of the bounding-box diagonal are welded; "
    "faces within it of a common plane are merged.",
)
@click.option(
    "--levels",
    type=click.IntRange(-1, None),
    default=None,
    metavar="N",
    help="The last level to build: -1 the scene only, 0 the nodes (V0), 1 also the arcs (V1), "
    "2 also the V-cells and EE-cells (V2). Default: every level.",
)
@click.option(
    "--compression",
    type=click.Choice(list(COMPRESSIONS)),
    default=DEFAULT_COMPRESSION,
    show_default=True,
    help="Coder of the large datasets: gzip (level 1, about 3x smaller, read by any HDF5 library), "
    "lzf (a little faster, 2.4x, h5py only) or none.",
)
@point_option("--point", "points", multiple=True,
              help_text="Add a free point (e.g. a light) as a generator: its nodes, VE arcs and V-cells are "
              "built like a vertex's. Repeatable.")
@light_options
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Build V1's and V2's chunks as tasks of a dask cluster (needs `pip install 'viscx[dask]'`): `local` "
              "starts one on this machine, else the address of a running dask scheduler (tcp://host:8786). "
              "The file is the same as without it.")
@click.option("--workers", type=click.IntRange(1, None), default=None, metavar="N",
              help="Worker processes of --scheduler local. Default: the CPU count.")
@click.pass_context
def build(ctx, scene_file, output, epsilon, relative_epsilon, weld, levels, compression, points, light_face, light_group,
          scheduler, workers):
    """Load SCENE (OBJ, PLY, or any mesh trimesh reads), clean it into polygon
    faces with a half-edge structure and generators, and write the result.

    \b
    viscx build sample_scenes/cornell_box.obj -o cornell.h5
    viscx build scene.ply --relative-epsilon 1e-5 -o scene.h5
    viscx build sample_scenes/tetrahedra.obj --levels 0 -o nodes_only.h5
    viscx build sample_scenes/cornell_box.obj --point 278,540,280 -o cornell_light.h5
    viscx build sample_scenes/cornell_box.obj --light-group light -o cornell_mesh.h5

    With --light-group NAME (or --light-face I) the build is scoped to that area light:
    only the nodes (V0) and arcs (V1) of the families with one of its outline vertices or
    edges, what `viscx query discontinuities` and `viscx render` need for that light
    (docs/format.md, "Builds for one light").

    The output is written to a temporary file and renamed when complete, so a
    failed or interrupted build leaves nothing behind.
    """
    from viscx.errors import ViscxError
    from viscx.formats.atomic import check_output, is_stream
    from viscx.distributed import runner
    from viscx.pipeline import NOUNS, build_complex

    output = Path(output) if output else Path(Path(scene_file).stem + ".h5")
    check_output(output, [scene_file])  # also the default name
    if is_stream(output):
        raise ViscxError(f"-o {output}: an HDF5 file needs a regular file (it is written with seeks), "
                         "not a pipe, a device or standard output")
    start = time.perf_counter()
    run = runner(scheduler, workers)
    try:
        cx = build_complex(
            scene_file, epsilon=epsilon, relative_epsilon=relative_epsilon, weld=weld,
            levels=levels, quiet=quiet(ctx), points=list(points) or None,
            output=output, compression=compression, light_face=light_face, light_group=light_group, runner=run,
        )
        peaks = run.peaks()
    finally:
        run.close()
    scene = cx.scene
    if not quiet(ctx):
        total = time.perf_counter() - start  # the stages' timings nest (V2 holds its V- and EE-cells)
        counts = "".join(f", {cx.size(name)} {NOUNS[name]}" for name in cx.levels)
        if peaks:
            click.echo(f"dask: {len(peaks)} workers, peak memory "
                       + ", ".join(f"{gb:.2f}" for _, gb in sorted(peaks.items())) + " GB")
        click.echo(
            f"{output}: {scene.n_faces} faces, {len(scene.generator_edges)} generator edges, "
            f"{len(scene.generator_vertices)} generator vertices{counts}"
            + (f", {len(points)} points" if points else "") + f" ({total:.2f} s)"
        )
