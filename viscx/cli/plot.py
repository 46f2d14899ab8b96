"""``viscx plot``: pictures of a viscx file (needs the ``plot`` extra: matplotlib)."""

import click

from viscx.cli.options import output_option
from viscx.errors import ViscxError


@click.group(context_settings={"help_option_names": ["-h", "--help"]}, short_help="Draw parts of a viscx file.")
def plot():
    """Pictures of the complex stored in a viscx file (needs matplotlib: pip install 'viscx[plot]').

    \b
    viscx plot vcells cornell.h5 --vertex 3 -o v3.png
    """


@plot.command(short_help="Draw the V-cells of one vertex on its direction sphere.")
@click.argument("file", metavar="FILE", type=click.Path(dir_okay=True))
@click.option("--vertex", "vertex", type=int, required=True, metavar="N", help="The generator vertex whose V-cells to draw.")
@output_option("The image to write (.png, .svg or .pdf).")
@click.option("--size", type=click.IntRange(16, 4000), default=300, show_default=True,
              help="Pixels per hemisphere side.")
def vcells(file, vertex, output, size):
    """Draw the V-cells of vertex N of FILE on its direction sphere: the two hemispheres
    (+y from above, -y from below) in equal-area projection, one colour per cell,
    listed with their blocker pair (up → down) and solid angle.

    \b
    viscx build sample_scenes/tetrahedra.obj -o tetra.h5
    viscx plot vcells tetra.h5 --vertex 0 -o tetra_v0.png
    """
    from viscx.formats.hdf5 import ViscxFile, read_arcs, read_vcells
    from viscx.render.vcells import plot_vcells

    with ViscxFile(file) as f:
        if "V2" not in f.levels or "V2" not in f.h5:
            raise ViscxError(f"{file} has no V-cells (V2); build it with `viscx build --levels 2`")
        scene = f.read_scene()
        arcs = read_arcs(f.h5["V1"])
        cells = read_vcells(f.h5["V2"])
    if not 0 <= vertex < scene.n_vertices or not scene.half_edges.vertex_is_generator[vertex]:
        raise ViscxError(f"--vertex {vertex} is not a generator vertex of {file} "
                         f"(it has {scene.n_vertices} vertices, {len(scene.generator_vertices)} generators)")
    result = plot_vcells(scene, arcs, cells, vertex, output, size=size)
    note = f", {result['unlocated']:.1%} of the sphere in no cell (loops V1 could not close)" if result["unlocated"] else ""
    click.echo(f"{result['cells']} V-cells of vertex {vertex} -> {output}{note}")
