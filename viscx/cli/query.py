"""``viscx query``: questions to a built complex (schemas in docs/queries.md)."""

import click

from viscx.cli.options import (file_argument, format_option, light_options, output_option, point_option, quiet,
                               scene_options)


@click.group(context_settings={"help_option_names": ["-h", "--help"]}, short_help="Query a viscx file (visibility, shadows, discontinuities).")
def query():
    """Questions to the complex stored in a viscx file. Each reads the file (the scene and,
    for a point stored by `viscx build --point`, its V-cells; any other point's V-cells
    are computed on demand) and never rebuilds the whole complex. `visible` and `shadows`
    also take a scene file (OBJ, PLY, …): a scoped query that builds the point's V-cells
    only, the same cells the full build would have; `discontinuities` likewise builds
    the nodes and arcs of the light's families only.

    \b
    viscx query visible cornell.h5 --from 278,273,-800
    viscx query shadows sample_scenes/cornell_box.obj --light 278,540,280 -o shadows.ply
    viscx query shadows cornell.h5 --light 278,540,280 -o shadows.ply
    viscx query discontinuities cornell.h5 --light-group light -o mesh.json
    """


face_option = click.option("--face", "faces", type=int, multiple=True, metavar="N",
                           help="Report only face N (repeatable). Default: every face.")


def _only(result, faces):
    """Keep the faces asked for (checked by the query)."""
    if faces:
        result["faces"] = [result["faces"][f] for f in sorted(set(faces))]
    return result


def _warn(ctx, result):
    if not result["complete"] and not quiet(ctx):
        faces = [f["face"] for f in result["faces"] if not f["complete"]]
        click.echo(
            f"viscx: warning: {result['incomplete_cells']} of the point's {result['cells']} V-cells are incomplete "
            f"and {result['open_chains']} boundary chains did not close"
            + (f" (faces {', '.join(map(str, faces))})" if faces else "") + "; see docs/queries.md",
            err=True,
        )


@query.command(short_help="The visible part of every face from a point.")
@file_argument
@point_option("--from", "viewpoint", help_text="The viewpoint, in scene units.")
@output_option("Where to write (.json or .msgpack). Default: standard output.", required=False)
@format_option
@face_option
@scene_options
@click.pass_context
def visible(ctx, file, viewpoint, output, fmt, faces, epsilon, relative_epsilon, weld):
    """The visibility polyhedron of a point (Hoberock et al. §7.1): for every face, the part
    seen from X,Y,Z as polygons with holes (3-D loops), from the point's V-cells.

    \b
    viscx build sample_scenes/cornell_box.obj -o cornell.h5
    viscx query visible cornell.h5 --from 278,273,-800 -o view.json
    viscx query visible cornell.h5 --from 278,273,-800 --format msgpack -o view.msgpack
    viscx query visible sample_scenes/cornell_box.obj --from 278,273,-800 -o view.json

    FILE is a viscx file or a scene file (then only the point's V-cells are built, with
    --epsilon/--relative-epsilon/--weld as `viscx build` would use them).
    """
    from viscx.formats.queries import output_format, write_result
    from viscx.queries.visibility import open_query, view_from, visible_result

    fmt = output_format(output, fmt)
    q = open_query(file, epsilon=epsilon, relative_epsilon=relative_epsilon, weld=weld)
    q.scene.face_ids(faces)
    view, stored = view_from(q, viewpoint)
    result = _only(visible_result(q.scene, view, stored), faces)
    write_result(result, output, fmt)
    _warn(ctx, result)


@query.command(short_help="Lit polygons and shadow boundaries of a point light.")
@file_argument
@point_option("--light", "light", help_text="The point light, in scene units.")
@output_option("Where to write: .json, .msgpack, or .ply (the scene split along the shadow "
               "boundaries, a lit flag per face). Default: JSON on standard output.", required=False)
@format_option
@face_option
@scene_options
@click.pass_context
def shadows(ctx, file, light, output, fmt, faces, epsilon, relative_epsilon, weld):
    """For every face, the polygons lit by a point light at X,Y,Z (outer loops
    counter-clockwise seen from the face's front, holes clockwise) and the
    shadow-boundary segments (Hoberock et al. §7.2).

    \b
    viscx build sample_scenes/cornell_box.obj --point 278,540,280 -o cornell.h5
    viscx query shadows cornell.h5 --light 278,540,280 -o shadows.json
    viscx query shadows cornell.h5 --light 278,540,280 -o shadows.ply
    viscx query shadows sample_scenes/cornell_box.obj --light 278,540,280 -o shadows.ply

    FILE is a viscx file or a scene file (then only the light's V-cells are built, with
    --epsilon/--relative-epsilon/--weld as `viscx build` would use them).
    """
    from viscx.formats.queries import output_format, write_result, write_shadow_ply
    from viscx.queries.shadows import shadows as compute

    fmt = output_format(output, fmt, geometry=True)
    scene, view, result = compute(file, light, faces=faces, epsilon=epsilon, relative_epsilon=relative_epsilon, weld=weld)
    result = _only(result, faces)
    if fmt == "ply":
        counts = write_shadow_ply(output, scene, view)
        if not quiet(ctx):
            click.echo(f"{output}: {counts['triangles']} triangles, {counts['lit_triangles']} lit", err=True)
    else:
        write_result(result, output, fmt)
    _warn(ctx, result)


@query.command(short_help="The discontinuity mesh of an area light on every receiver.")
@file_argument
@light_options
@output_option("Where to write: .json, .msgpack, or .ply (the receivers split into the "
               "regions, a region id and colour per triangle). Default: JSON on standard output.", required=False)
@format_option
@face_option
@scene_options
@click.pass_context
def discontinuities(ctx, file, light_face, light_group, output, fmt, faces, epsilon, relative_epsilon, weld):
    """The discontinuity mesh cast by an area light (Hoberock et al. §7.5): on every receiver
    face, the traces of the VE and EEE events involving the light's vertices and edges
    (segments; EEE traces are conic arcs written as polylines), the receiver-plane events
    and the line where the light's plane crosses the face (the light emits from its
    front only), and the regions they cut the face into (outer loop counter-clockwise seen from the face's front, holes
    clockwise). Reads V1's arcs from the file; nothing is rebuilt.

    \b
    viscx build sample_scenes/cornell_box.obj -o cornell.h5
    viscx query discontinuities cornell.h5 --light-group light -o mesh.json
    viscx query discontinuities cornell.h5 --light-face 15 -o mesh.ply
    viscx query discontinuities sample_scenes/cornell_box.obj --light-group light -o mesh.json

    FILE is a viscx file (a full build, or one built for this light with `viscx build
    --light-group`) or a scene file: then only the nodes and arcs of the light's families
    are built (the full build's), with --epsilon/--relative-epsilon/--weld as `viscx build`
    would use them.
    """
    from viscx.formats.queries import output_format, write_regions_ply, write_result
    from viscx.queries.discontinuities import light_plane_count, mesh_result, open_discontinuities

    fmt = output_format(output, fmt, geometry=True)
    scene, mesh = open_discontinuities(file, light_face=light_face, light_group=light_group, faces=faces,
                                       epsilon=epsilon, relative_epsilon=relative_epsilon, weld=weld)
    planes = light_plane_count(scene, mesh.light)
    if planes > 1 and not quiet(ctx):
        click.echo(f"viscx: warning: the light's faces lie in {planes} planes; the mesh is exact for a planar light "
                   "only (docs/queries.md, \"What the mesh leaves out\" (3))", err=True)
    if fmt == "ply":
        counts = write_regions_ply(output, mesh)
        if not quiet(ctx):
            click.echo(f"{output}: {counts['triangles']} triangles, {counts['regions']} regions", err=True)
    else:
        write_result(mesh_result(scene, mesh), output, fmt)
