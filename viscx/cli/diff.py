"""``viscx diff``: compare two viscx files; the exit status says whether they differ."""

import click

from viscx.tolerances import DEFAULT_ATOL, DEFAULT_RTOL


@click.command(short_help="Compare two viscx files level by level (exit 1 when they differ).")
@click.argument("file_a", metavar="A", type=click.Path(dir_okay=True))
@click.argument("file_b", metavar="B", type=click.Path(dir_okay=True))
@click.option(
    "--rtol",
    type=click.FloatRange(min=0),
    default=DEFAULT_RTOL,
    show_default=True,
    help="Relative tolerance for float values, relative to B.",
)
@click.option(
    "--atol",
    type=click.FloatRange(min=0),
    default=DEFAULT_ATOL,
    show_default=True,
    help="Absolute tolerance for float values (a floor for values that should be zero; "
    "use 0 for scenes in very small units). --rtol 0 --atol 0 compares exactly.",
)
@click.option(
    "--max-report", "max_report", type=click.IntRange(min=0), default=10, show_default=True, metavar="N",
    help="Show at most N differences (all are counted).",
)
@click.pass_context
def diff(ctx, file_a, file_b, rtol, atol, max_report):
    """Compare the viscx files A and B level by level: attributes (build
    options, levels), which groups and datasets exist, their shapes, dtype
    kinds and values. Integers, booleans and strings must be equal; floats must
    satisfy |a - b| <= atol + rtol * |b|. The timings under /provenance and the
    viscx version that wrote the file are ignored.

    Exit status: 0 equal, 1 different (the first differences are printed),
    2 when A or B is missing or not a viscx file. Typical CI use:

    \b
    viscx build scene.obj -o new.h5
    viscx diff new.h5 tests/golden/scene.h5 || exit 1
    viscx diff a.h5 b.h5 --rtol 0 --atol 0      # bit-for-bit values
    """
    from viscx.cli.options import quiet
    from viscx.formats.diff import diff_files

    result = diff_files(file_a, file_b, rtol=rtol, atol=atol, max_items=max_report)
    if not (result.equal and quiet(ctx)):
        for line in result.report():
            click.echo(line)
    ctx.exit(0 if result.equal else 1)
