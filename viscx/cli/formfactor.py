"""``viscx formfactor``: exact and occlusion-exact form factors from a viscx file
(schemas in docs/queries.md)."""

import click

from viscx.cli.options import POINT, format_option, quiet


@click.command(short_help="Form factors: point to face, face to face, groups, the matrix.")
@click.argument("file", metavar="FILE", type=click.Path(dir_okay=True))
@click.option("--point", "point", type=POINT, default=None, metavar="X,Y,Z", help="A differential area at X,Y,Z (needs --normal).")
@click.option("--normal", "normal", type=POINT, default=None, metavar="NX,NY,NZ", help="Its normal (any length).")
@click.option("--from-face", "from_face", type=int, default=None, metavar="I", help="Emitting face I.")
@click.option("--from-side", "from_side", type=click.Choice(["front", "back"]), default="front", show_default=True,
              help="Side of the emitting face(s): front is the side of the face normal.")
@click.option("--to-face", "to_face", type=int, default=None, metavar="J", help="Receiving face J (both of its sides).")
@click.option("--from-group", "from_group", default=None, metavar="NAME", help="Emitting group (area-weighted).")
@click.option("--to-group", "to_group", default=None, metavar="NAME", help="Receiving group.")
@click.option("--matrix", is_flag=True, help="Every pair of face sides, sparse, written to -o F.h5.")
@click.option("--tol", type=float, default=None, metavar="T",
              help="Target on the absolute error estimate of each polygon-to-polygon form factor (default 1e-6); the output reports the estimate reached.")
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False), default=None,
              help="Where to write: the matrix (--matrix) as .h5, .npz (arrays and the group table) or .csv (the "
                   "group table), else .json or .msgpack (default: standard output).")
@format_option
@click.pass_context
def formfactor(ctx, file, point, normal, from_face, from_side, to_face, from_group, to_group, matrix, tol, output, fmt):
    """Form factors between parts of the scene in FILE (built by `viscx build`, with V2).

    \b
    Point to face (exact: Lambert's formula over the part of J the point sees, from
    its V-cells, Hoberock et al. §7.4):
      viscx formfactor cornell.h5 --point 278,1,280 --normal 0,1,0 --to-face 15
    Face to face (occlusion-exact integrand, adaptive quadrature, error estimate):
      viscx formfactor cornell.h5 --from-face 0 --to-face 15
    Groups (area-weighted over the emitting faces):
      viscx formfactor cornell.h5 --from-group floor --to-group light
    The matrix of every pair of face sides (sparse CSR, reciprocity and row sums reported;
    -o F.npz or F.csv for plain exports with the group-to-group table):
      viscx formfactor cornell.h5 --matrix -o F.h5

    Output: JSON {"F": value, ...} on standard output (or -o), msgpack with --format msgpack.
    """
    from viscx.api import form_factor, form_factor_matrix
    from viscx.formats.queries import output_format, write_result
    from viscx.queries.visibility import open_query

    point_mode = point is not None or normal is not None
    source_given = from_face is not None or from_group is not None
    target_given = to_face is not None or to_group is not None
    if sum([point_mode, source_given, bool(matrix)]) != 1:
        raise click.UsageError("give exactly one of --point/--normal, --from-face/--from-group, --matrix")
    if matrix and (target_given or output is None):
        raise click.UsageError("--matrix takes no --to-face/--to-group and needs -o F.h5")
    if matrix:
        fmt = fmt or "json"
    else:
        fmt = output_format(output, fmt)

    q = open_query(file)
    if matrix:
        from viscx.formats.formfactors import write_export, write_matrix

        m = form_factor_matrix(q, tol=tol, quiet=quiet(ctx))
        plain = str(output).lower().endswith((".npz", ".csv"))
        summary = (write_export if plain else write_matrix)(output, m, q.scene)
        write_result({"matrix": str(output), **summary}, None, fmt)
        return
    result = form_factor(q, to_face=to_face, to_group=to_group, point=point, normal=normal, from_face=from_face,
                         from_group=from_group, from_side=from_side, tol=tol).record
    write_result(result, output, fmt)
    if point_mode and not result["complete"] and not quiet(ctx):
        click.echo("viscx: warning: some of the point's V-cells are incomplete; see docs/queries.md", err=True)
