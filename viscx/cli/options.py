"""Options shared by several commands, as decorators (one definition each)."""

import functools

import click

from viscx.tolerances import DEFAULT_WELD

#: the names commands give their input files' arguments
INPUT_ARGUMENTS = ("file", "scene_file", "file_a", "file_b")


#: ``FILE``: the viscx file (or, for the scoped point queries, the scene file) a command reads.
file_argument = click.argument("file", metavar="FILE", type=click.Path(dir_okay=True))


def positive(ctx, param, value):
    """Click callback: ``value`` (None, or a number) must be finite and positive."""
    if value is not None and not (0 < value < float("inf")):
        raise click.BadParameter(f"{value} must be a positive number", ctx, param)
    return value


def at_least(low):
    """Click callback: an integer ``value`` (or None) of at least ``low``."""

    def check(ctx, param, value):
        if value is not None and value < low:
            raise click.BadParameter(f"{value} must be at least {low}", ctx, param)
        return value

    return check


def output_option(help_text, required=True):
    """``-o/--output PATH``: where a command writes its result."""
    return click.option(
        "-o", "--output", "output", type=click.Path(dir_okay=False, writable=False), required=required, help=help_text
    )


def option_names(command):
    """``{parameter name: its longest option}`` of a click command (``light_face`` ->
    ``--light-face``): how the command spells the library's parameters."""
    return {p.name: max(p.opts, key=len) for p in command.params if isinstance(p, click.Option)}


def guard_outputs(command):
    """Make ``command`` (and a group's subcommands) refuse, before it runs, an ``output``
    that is one of its input files, also through a link
    (:func:`viscx.formats.atomic.check_output`; the writers check again when they write),
    and name in the library's messages about a parameter its option
    (:class:`viscx.errors.ParameterError`). The CLI applies it to every command it loads."""
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            guard_outputs(sub)
        return command
    callback = command.callback
    if callback is None or getattr(callback, "guarded", False):
        return command

    @functools.wraps(callback)
    def checked(*args, **kwargs):
        from viscx.formats.atomic import check_output

        from viscx.errors import ParameterError

        check_output(kwargs.get("output"), [kwargs[name] for name in INPUT_ARGUMENTS if kwargs.get(name)])
        try:
            return callback(*args, **kwargs)
        except ParameterError as exc:
            raise exc.renamed(option_names(command)) from None

    checked.guarded = True
    command.callback = checked
    return command


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


weld_option = click.option(
    "--weld",
    type=float,
    default=None,
    metavar="W",
    help="Vertices closer than this fraction of the bounding-box diagonal are welded; "
    f"faces within it of a common plane are merged. Default: {DEFAULT_WELD:g}.",
)


def scene_options(command):
    """``--epsilon``, ``--relative-epsilon``, ``--weld``: how a scene file is cleaned, for the
    queries that take a scene file as well as a viscx file (a scoped query)."""
    for option in (weld_option, relative_epsilon_option, epsilon_option):
        command = option(command)
    return command


def quiet(ctx):
    """True when the user asked for ``viscx --quiet``."""
    root = ctx.find_root()
    return bool(root.obj and root.obj.get("quiet"))


class PointType(click.ParamType):
    """``X,Y,Z``: three finite numbers separated by commas (a point in scene units)."""

    name = "X,Y,Z"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        parts = str(value).split(",")
        try:
            point = tuple(float(p) for p in parts)
        except ValueError:
            point = ()
        if len(point) != 3 or not all(abs(x) < float("inf") for x in point):
            self.fail(f"{value!r} is not a point X,Y,Z (three finite numbers separated by commas)", param, ctx)
        return point


POINT = PointType()


def point_option(*names, help_text, multiple=False, required=True):
    """A point option (``--from``, ``--light``, ``--point``) given as ``X,Y,Z``."""
    return click.option(*names, type=POINT, multiple=multiple, required=required and not multiple, metavar="X,Y,Z",
                        help=help_text)


format_option = click.option(
    "--format",
    "fmt",
    type=click.Choice(["json", "msgpack"]),
    default=None,
    help="Output format. Default: from the output's extension (.msgpack/.mpk, .ply where the "
    "query writes geometry), else JSON.",
)


def light_options(command):
    """``--light-face I`` / ``--light-group NAME``: an area light (exactly one is needed;
    :func:`viscx.scene.light.light_of` says so in one line otherwise)."""
    command = click.option("--light-group", "light_group", default=None, metavar="NAME",
                           help="The light is the faces of group NAME.")(command)
    return click.option("--light-face", "light_face", type=int, default=None, metavar="I",
                        help="The light is face I.")(command)
