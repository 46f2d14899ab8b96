"""``viscx plot``: pictures of a viscx file (needs the ``plot`` extra: matplotlib)."""

import click

from viscx.cli.options import output_option
from viscx.errors import ViscxError


@click.group(context_settings={"help_option_names": ["-h", "--help"]}, short_help="Draw parts of a viscx file.")
def plot():
    """Pictures of the complex stored in a viscx file (needs matplotlib: pip install 'viscx[plot]').

    \b
    viscx plot vcells cornell.h5 --vertex 3 -o v3.png
    viscx plot eecell cornell.h5 --edges 4 17 -o e4_17.png
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
    from viscx.plot.vcell_sphere import plot_vcells
    from viscx.skeleton.points import with_points

    with ViscxFile(file) as f:
        if "V2" not in f.levels or "V2" not in f.h5:
            raise ViscxError(f"{file} has no V-cells (V2); build it with `viscx build --levels 2`")
        scene = f.read_scene()
        points = f.read_points()
        arcs = read_arcs(f.h5["V1"])
        cells = read_vcells(f.h5["V2"])
    if len(points):  # the free points of `viscx build --point` are generator vertices n, n + 1, …
        scene = with_points(scene, points)
    if not 0 <= vertex < scene.n_vertices or not scene.half_edges.vertex_is_generator[vertex]:
        raise ViscxError(f"--vertex {vertex} is not a generator vertex of {file} "
                         f"(it has {scene.n_vertices} vertices, {len(scene.generator_vertices)} generators)")
    result = plot_vcells(scene, arcs, cells, vertex, output, size=size)
    note = f", {result['unlocated']:.1%} of the sphere in no cell (loops V1 could not close)" if result["unlocated"] else ""
    click.echo(f"{result['cells']} V-cells of vertex {vertex} -> {output}{note}")


@plot.command(short_help="Draw the EE-cells of an edge pair in its square.")
@click.argument("file", metavar="FILE", type=click.Path(dir_okay=True))
@click.option("--edges", "edges", type=int, nargs=2, required=True, metavar="A B",
              help="The two generator edges (either order; x1 runs along the smaller id).")
@output_option("The image to write (.png, .svg or .pdf).")
@click.option("--size", type=click.IntRange(16, 4000), default=300, show_default=True,
              help="Pixels per side of the square.")
def eecell(file, edges, output, size):
    """Draw the EE-cells of the edge pair A, B of FILE in its square [0, 1]² (Hoberock et al.
    Fig. 7): point (x1, x2) is the line through the two edges' points x1 and x2, one
    colour per cell, the boundary arcs with their direction, each cell listed with its
    blocker pair (back → front) and area.

    \b
    viscx build sample_scenes/tetrahedra.obj -o tetra.h5
    viscx plot eecell tetra.h5 --edges 2 7 -o tetra_2_7.png
    """
    import numpy as np  # here, not at the top: `viscx --help` lists this command without numpy

    from viscx.formats.hdf5 import ViscxFile, read_arcs, read_eecells
    from viscx.plot.eecell_square import plot_eecells
    from viscx.skeleton.eecells import skew_pairs

    with ViscxFile(file) as f:
        if "V2" not in f.levels or "V2" not in f.h5:
            raise ViscxError(f"{file} has no EE-cells (V2); build it with `viscx build --levels 2`")
        scene = f.read_scene()
        arcs = read_arcs(f.h5["V1"])
        cells = read_eecells(f.h5["V2"])
    e1, e2 = sorted(edges)
    n_edges = len(scene.half_edges.edge_vertices)
    for e in (e1, e2):
        if not 0 <= e < n_edges or not scene.half_edges.edge_is_generator[e]:
            raise ViscxError(f"--edges: {e} is not a generator edge of {file} "
                             f"(it has {n_edges} edges, {len(scene.generator_edges)} generators)")
    if e1 == e2 or not skew_pairs(scene, [e1], [e2])[0]:
        raise ViscxError(f"--edges {e1} {e2}: the two edges share a vertex or a plane, so they have no square of EE-cells")
    known = np.any((cells.edge1 == e1) & (cells.edge2 == e2)) or np.any((cells.open_edge1 == e1) & (cells.open_edge2 == e2))
    if not known:
        raise ViscxError(f"--edges {e1} {e2}: no EE-cells (no free segment joins the two edges, or V1 has no arc bounding them)")
    result = plot_eecells(scene, arcs, cells, e1, e2, output, size=size)
    note = f", {result['conflict']:.1%} of the square in several cells" if result["conflict"] else ""
    click.echo(f"{result['cells']} EE-cells of edges {e1} and {e2} -> {output} "
               f"({result['hidden']:.1%} in no cell){note}")
