"""``viscx formfactor``: exact and occlusion-exact form factors from a viscx file, one
subcommand per form (``point``, ``faces``, ``groups``, ``matrix``; schemas in
docs/queries.md). The old one-command style (``viscx formfactor FILE --matrix``) still
works: :class:`FormfactorGroup` rewrites it to its subcommand with a deprecation note."""

import click

from viscx.cli.options import POINT, file_argument, format_option, positive, quiet

#: The options of the old one-command style that name its form, in the order they decide it.
OLD_FORMS = [("matrix", ("--matrix",)), ("point", ("--point", "--normal")),
             ("groups", ("--from-group", "--to-group")), ("faces", ("--from-face", "--to-face"))]


def old_form(args):
    """``(subcommand, the option that names it, its arguments)`` of an old-style call's
    options, or None when no option names a form."""
    words = [a.split("=", 1)[0] for a in args if a.startswith("--")]
    for name, flags in OLD_FORMS:
        found = [w for w in words if w in flags]
        if found:
            return name, found[0], [a for a in args if a != "--matrix"]
    return None


class FormfactorGroup(click.Group):
    """The subcommands, and the old style ``viscx formfactor FILE --OPTION ...`` (the file
    first) rewritten to ``viscx formfactor FORM FILE ...`` with a one-line note on stderr."""

    def parse_args(self, ctx, args):
        if args and args[0] not in self.commands and not args[0].startswith("-"):
            found = old_form(args[1:])
            if found is None:
                forms = ",".join(self.commands)
                raise click.UsageError(f"say which form factor: viscx formfactor {{{forms}}} FILE ...", ctx)
            name, flag, rest = found
            click.echo(f"viscx: note: 'viscx formfactor FILE {flag} ...' is deprecated; use "
                       f"'viscx formfactor {name} FILE ...'", err=True)
            args = [name, args[0], *rest]
        return super().parse_args(ctx, args)


@click.group(cls=FormfactorGroup, context_settings={"help_option_names": ["-h", "--help"]},
             short_help="Form factors: point to face, face to face, groups, the matrix.")
def formfactor():
    """Form factors between parts of the scene in FILE (built by `viscx build`, with V2).
    Faces are two-sided: a form factor leaves one side of a face (--from-side) and
    arrives on both sides of the receivers.

    \b
    viscx formfactor point cornell.h5 --point 278,1,280 --normal 0,1,0 --to-face 15
    viscx formfactor faces cornell.h5 --from-face 0 --to-face 15
    viscx formfactor groups cornell.h5 --from-group floor --to-group light
    viscx formfactor matrix two.h5 -o F.h5
    """


def tol_option(default):
    return click.option("--tol", type=float, default=None, metavar="T", callback=positive,
                        help=f"Target on the absolute error estimate of each polygon-to-polygon form factor (default "
                             f"{default:g}); the output reports the estimate reached.")


from_side_option = click.option(
    "--from-side", "from_side", type=click.Choice(["front", "back"]), default="front", show_default=True,
    help="Side of the emitting face(s): front is the side of the face normal.")
result_output_option = click.option("-o", "--output", "output", type=click.Path(dir_okay=False), default=None,
                                    help="Where to write: .json or .msgpack (default: standard output).")


def _write(ctx, file, fmt, output, **form):
    """Compute one form factor (:func:`viscx.api.form_factor`) and write its record."""
    from viscx.api import form_factor
    from viscx.formats.queries import output_format, write_result
    from viscx.queries.visibility import open_query

    fmt = output_format(output, fmt)
    record = form_factor(open_query(file), **form, quiet=quiet(ctx)).record
    write_result(record, output, fmt)
    if not record.get("complete", True) and not quiet(ctx):
        click.echo("viscx: warning: some of the point's V-cells are incomplete; see docs/queries.md", err=True)
    if record.get("tol_reached") is False and not quiet(ctx):
        from viscx.queries.formfactor import MAX_CELLS

        click.echo(f"viscx: warning: a pair's error estimate is above --tol {record['tol']:g}: its refinement "
                   f"stopped at {MAX_CELLS:,} triangles ('error' says how far it got)", err=True)


@formfactor.command(short_help="Exact F from a differential area to a face or a group.")
@file_argument
@click.option("--point", "point", type=POINT, required=True, metavar="X,Y,Z", help="The differential area's position.")
@click.option("--normal", "normal", type=POINT, required=True, metavar="NX,NY,NZ", help="Its normal (any length).")
@click.option("--to-face", "to_face", type=int, default=None, metavar="J", help="Receiving face J.")
@click.option("--to-group", "to_group", default=None, metavar="NAME", help="Receiving group (its faces summed).")
@result_output_option
@format_option
@click.pass_context
def point(ctx, file, point, normal, to_face, to_group, output, fmt):
    """F from a differential area at X,Y,Z with normal N to face J or to the faces of a
    group, exact: Lambert's formula over the part of each face the point sees, from its
    V-cells (the file's for a point built with `viscx build --point`, else computed),
    Hoberock et al. §7.4.

    \b
    viscx formfactor point cornell.h5 --point 278,1,280 --normal 0,1,0 --to-face 15
    viscx formfactor point cornell.h5 --point 278,1,280 --normal 0,1,0 --to-group light -o F.json
    """
    _write(ctx, file, fmt, output, point=point, normal=normal, to_face=to_face, to_group=to_group)


@formfactor.command(short_help="F from one side of a face to a face, with an error estimate.")
@file_argument
@click.option("--from-face", "from_face", type=int, required=True, metavar="I", help="Emitting face I.")
@from_side_option
@click.option("--to-face", "to_face", type=int, required=True, metavar="J",
              help="Receiving face J (both of its sides).")
@tol_option(1e-6)
@result_output_option
@format_option
@click.pass_context
def faces(ctx, file, from_face, from_side, to_face, tol, output, fmt):
    """F from one side of face I to face J: the unoccluded double contour integral less
    what the occluders hide, by adaptive cubature of an exact integrand (the visible part
    of J from each point), refined until the error estimate is within --tol. The output
    reports that estimate ("error", per side of J and summed): an estimate of |F − exact
    F|, made to lie above it (checked against finer computations and Monte Carlo), not a
    proven bound; docs/queries.md says how it is made.

    \b
    viscx formfactor faces cornell.h5 --from-face 0 --to-face 15
    viscx formfactor faces cornell.h5 --from-face 15 --from-side front --to-face 0 --tol 1e-5
    """
    _write(ctx, file, fmt, output, from_face=from_face, from_side=from_side, to_face=to_face, tol=tol)


@formfactor.command(short_help="F between groups (area-weighted over the emitting faces).")
@file_argument
@click.option("--from-group", "from_group", default=None, metavar="NAME", help="Emitting group.")
@from_side_option
@click.option("--to-group", "to_group", default=None, metavar="NAME", help="Receiving group.")
# a face on one side, as the old style allowed (`--from-face 0 --to-group light`)
@click.option("--from-face", "from_face", type=int, default=None, hidden=True)
@click.option("--to-face", "to_face", type=int, default=None, hidden=True)
@tol_option(1e-6)
@result_output_option
@format_option
@click.pass_context
def groups(ctx, file, from_group, from_side, to_group, from_face, to_face, tol, output, fmt):
    """F from one side of the faces of group A to the faces of group B,
    Σ_i A_i Σ_j F_ij / Σ_i A_i (a face in both does not see itself). As in the
    matrix, each face pair is computed once, from its face of smaller area, and
    the other direction derived by reciprocity (A_i F_ij = A_j F_ji), its error
    estimate scaled alike: a floor to a desk is computed from the desk's faces,
    each to --tol times A_floor / A_face (within --tol once scaled).

    \b
    viscx formfactor groups cornell.h5 --from-group floor --to-group light
    viscx formfactor groups cornell.h5 --from-group light --to-group tall_block -o F.msgpack
    """
    _write(ctx, file, fmt, output, from_group=from_group, from_face=from_face, from_side=from_side, to_group=to_group,
           to_face=to_face, tol=tol)


@formfactor.command(short_help="Every pair of face sides, sparse, with the sky term.")
@file_argument
@tol_option(1e-6)
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False), required=True,
              help="Where to write the matrix: .h5 (sparse CSR, docs/format.md), .npz (arrays and the group table) "
                   "or .csv (the group-to-group table).")
@click.option("--format", "fmt", type=click.Choice(["json", "msgpack"]), default="json", show_default=True,
              help="Format of the summary on standard output.")
@click.option("--gap-search/--no-gap-search", "gap_search", default=True, show_default=True,
              help="Rows integrated on three levels (their receivers' kink lines too many to cut along) look for "
                   "receivers seen through gaps between their nodes; without it such an entry is reported as hidden "
                   "with a small estimate that is not honest (docs/queries.md, \"The matrix\"). It costs 5–16 % of "
                   "the time on furnished rooms (a 300-polygon office 7 %, a 1,000-polygon one 16 %).")
@click.pass_context
def matrix(ctx, file, tol, output, fmt, gap_search):
    """The form factors between every pair of face sides (sparse CSR) and every side's
    sky term; reciprocity and row sums are reported on standard output (JSON).

    \b
    viscx build sample_scenes/two_triangles.obj -o two.h5
    viscx formfactor matrix two.h5 -o F.h5
    viscx formfactor matrix two.h5 --tol 1e-7 -o F.csv
    viscx formfactor matrix office.h5 --tol 1e-4 --no-gap-search -o F.h5
    """
    import numpy as np

    from viscx.api import form_factor_matrix
    from viscx.formats.formfactors import write_export, write_matrix
    from viscx.formats.queries import write_result
    from viscx.queries.formfactor import estimates_above
    from viscx.queries.visibility import open_query

    q = open_query(file)
    m = form_factor_matrix(q, tol=tol, quiet=quiet(ctx), gap_search=gap_search)
    plain = str(output).lower().endswith((".npz", ".csv"))
    summary = (write_export if plain else write_matrix)(output, m, q.scene)
    write_result({"matrix": str(output), **summary}, None, fmt)
    above = estimates_above(np.concatenate([m.error, m.sky_error]), m.tol)
    if above and not quiet(ctx):
        click.echo(f"viscx: warning: {above} of the matrix's error estimates are above --tol {m.tol:g} (the largest "
                   f"{summary['max_error_estimate']:.2g}): a row stopped at its cap of triangles, or an entry is a "
                   f"closed room's row sum, whose estimate is the sum of the row's", err=True)
