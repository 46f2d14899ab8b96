"""Options shared by several commands, as decorators (one definition each)."""

import click


def output_option(help_text, required=True):
    """``-o/--output PATH``: where a command writes its result."""
    return click.option(
        "-o", "--output", "output", type=click.Path(dir_okay=False, writable=False), required=required, help=help_text
    )


epsilon_option = click.option(
    "--epsilon",
    type=float,
    default=None,
    metavar="EPS",
    help="Robustness epsilon (scene units): segments are trimmed by EPS at their ends and "
    "generators count as met within EPS (epsilon-visibility). "
    "Default: 1e-6 of the scene's bounding-box diagonal.",
)

relative_epsilon_option = click.option(
    "--relative-epsilon",
    type=float,
    default=None,
    metavar="R",
    help="The epsilon as a fraction of the bounding-box diagonal (instead of --epsilon).",
)


def quiet(ctx):
    """True when the user asked for ``viscx --quiet``."""
    root = ctx.find_root()
    return bool(root.obj and root.obj.get("quiet"))
