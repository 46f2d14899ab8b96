"""The ``viscx`` command: a thin click layer over the library.

One module per command (``viscx/cli/<command>.py``), shared options in
:mod:`viscx.cli.options`. Commands load lazily so ``viscx --help`` stays fast.

Exit status: 0 success, 1 a difference found (``viscx diff``) or an internal
error, 2 bad input or usage (one line on stderr, never a traceback),
130 interrupted, 143 terminated.
"""

import importlib
import os
import signal
import sys

import click

from viscx import __version__
from viscx.errors import ViscxError

# name -> "module:attribute", in the order `viscx --help` lists them.
COMMANDS = {
    "build": "viscx.cli.build:build",
    "info": "viscx.cli.info:info",
}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def __init__(self, *args, lazy_commands=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy_commands = dict(lazy_commands or {})

    def list_commands(self, ctx):
        return list(self.lazy_commands) + sorted(self.commands)

    def get_command(self, ctx, name):
        if name in self.lazy_commands:
            module, attr = self.lazy_commands[name].split(":")
            return getattr(importlib.import_module(module), attr)
        return super().get_command(ctx, name)


@click.group(cls=LazyGroup, lazy_commands=COMMANDS, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="viscx")
@click.option("-q", "--quiet", is_flag=True, help="No progress bars and no chatter; results and errors only.")
@click.pass_context
def cli(ctx, quiet):
    """Build the visibility complex of a polygonal scene and query it.

    \b
    viscx build sample_scenes/cornell_box.obj -o cornell.h5
    viscx info cornell.h5
    """
    ctx.ensure_object(dict)
    ctx.obj["quiet"] = quiet


class Terminated(BaseException):
    """Raised in the main thread on SIGTERM so that clean-up (temporary files) runs."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _fail(message, code):
    click.echo(f"viscx: {message}", err=True)
    return code


def main(argv=None):
    """Entry point of the ``viscx`` console script; returns via ``sys.exit``."""
    signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        cli.main(args=argv, prog_name="viscx", standalone_mode=False)
        code = 0
    except click.exceptions.Exit as exc:
        code = exc.exit_code
    except click.UsageError as exc:
        where = f" (see 'viscx {exc.ctx.command_path.split(' ', 1)[1]} --help')" if exc.ctx and " " in exc.ctx.command_path else " (see 'viscx --help')"
        code = _fail(f"error: {exc.format_message()}{where}", 2)
    except click.ClickException as exc:
        code = _fail(f"error: {exc.format_message()}", exc.exit_code or 2)
    except ViscxError as exc:
        code = _fail(f"error: {exc}", exc.exit_code)
    except (KeyboardInterrupt, click.Abort):
        code = _fail("interrupted", 130)
    except Terminated:
        code = _fail("terminated", 143)
    except OSError as exc:
        name = f": {exc.filename}" if exc.filename else ""
        code = _fail(f"error: {exc.strerror or exc}{name}", 2)
    except Exception as exc:  # a bug in viscx: say so in one line unless asked for more
        if os.environ.get("VISCX_DEBUG"):
            raise
        code = _fail(f"internal error: {type(exc).__name__}: {exc} (set VISCX_DEBUG=1 for a traceback)", 1)
    sys.exit(code)
