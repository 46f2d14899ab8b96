"""The ``viscx`` command: a thin click layer over the library.

One module per command (``viscx/cli/<command>.py``), shared options in
:mod:`viscx.cli.options`. Commands load lazily so ``viscx --help`` stays fast.

Exit status: 0 success, 1 a difference found (``viscx diff``) or an internal
error, 2 bad input or usage (one line on stderr, never a traceback),
130 interrupted, 143 terminated.
"""

import functools
import importlib
import os
import signal
import sys
import threading
import warnings

import click

from viscx import __version__
from viscx.errors import ViscxError
from viscx.formats.atomic import clear_inputs, received_signals

# One BLAS thread for a command unless the user chose otherwise (read when numpy is first
# imported: by the commands, after this). viscx's BLAS calls are small products (points times a
# direction, `points @ u`), which gain nothing from threads; OpenBLAS's threads spin while they
# wait for the next one: `viscx render --samples 500` of the Cornell box (256 x 256) took
# 3.4-10.8 CPU s with them and 1.9 without (shared machine), and they take a busy machine's
# cores from other work. Its dense algebra is batches of 3 x 4 SVDs, one thread each anyway.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# Idle OpenMP threads (numba's threading layer, for its parallel kernels) sleep instead of
# spinning until the next kernel (read when the layer starts, on the first parallel kernel).
# A build calls such kernels tens of thousands of times between numpy steps; the spinning
# threads only burn CPU, on a busy machine taken from the threads doing the work. The results
# do not depend on it (tests/conftest.py sets it for the suite too).
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# numpy asks for transparent huge pages on its large arrays (madvise); where the kernel's
# THP defrag is "madvise", a fault there may compact memory synchronously, in the build's
# system time (office(600): 15.6 -> 8.1 system CPU s; docs/skeleton.md "Furnished
# buildings"). Read when numpy loads; the results do not depend on it.
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

# name -> "module:attribute", in the order `viscx --help` lists them.
COMMANDS = {
    "build": "viscx.cli.build:build",
    "info": "viscx.cli.info:info",
    "diff": "viscx.cli.diff:diff",
    "plot": "viscx.cli.plot:plot",
    "query": "viscx.cli.query:query",
    "formfactor": "viscx.cli.formfactor:formfactor",
    "render": "viscx.cli.render:render",
    "flatland": "viscx.cli.flatland:flatland",
}

HELP_OPTIONS = ["-h", "--help"]


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def __init__(self, *args, lazy_commands=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy_commands = dict(lazy_commands or {})

    def list_commands(self, ctx):
        return list(self.lazy_commands) + sorted(self.commands)

    def parse_args(self, ctx, args):
        ctx.meta["viscx.help"] = bool(set(args) & set(HELP_OPTIONS))  # a command's --help: nothing runs
        return super().parse_args(ctx, args)

    def get_command(self, ctx, name):
        if name in self.lazy_commands:
            from viscx.cli.options import guard_outputs

            module, attr = self.lazy_commands[name].split(":")
            return guard_outputs(getattr(importlib.import_module(module), attr))
        return super().get_command(ctx, name)


@click.group(cls=LazyGroup, lazy_commands=COMMANDS, context_settings={"help_option_names": HELP_OPTIONS})
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
    # a command that may compile numba kernels: say so when it does (not for its --help, which
    # then needs no numba import: 0.8 -> 0.1 CPU s)
    if ctx.invoked_subcommand is not None and not ctx.meta["viscx.help"]:
        from viscx.memory import keep_freed_memory
        from viscx.progress import report_compilation

        keep_freed_memory()
        skip_numbas_blas_probe()
        load_cached_kernels_without_registries()
        lock_kernel_cache_files()
        report_compilation(not quiet)
        ctx.call_on_close(lambda: report_compilation(False))


def skip_numbas_blas_probe():
    """Import numba's array functions (``numba.np.arraymath``) without the probe it runs
    when imported: ``_HAVE_BLAS = _check_blas()``, which imports ``scipy.linalg`` (~0.16 CPU
    s, half of numba's start-up; the whole Cornell matrix at ``--tol 1e-4`` is ~2) only to
    learn whether BLAS is there. scipy is a dependency of viscx, so the answer is yes, which
    is what the module records without the probe; the probe's function is put back at once,
    so a kernel that does use BLAS (``np.dot``) still imports scipy and checks it when it
    compiles. numba loads the module on the first kernel a command calls (its registries),
    so doing it here costs nothing more (~0.05 CPU s on a command that calls none). Nothing
    is done where the module is already loaded or numba's layout is not the one expected."""
    if "numba.np.arraymath" in sys.modules:
        return
    import numba.np.linalg as linalg

    probe = getattr(linalg, "ensure_blas", None)
    if probe is None:
        return
    linalg.ensure_blas = lambda: None
    try:
        import numba.np.arraymath as arraymath
    finally:
        linalg.ensure_blas = probe
    if getattr(arraymath, "ensure_blas", None) is not probe:  # the name it imported, put back too
        arraymath.ensure_blas = probe


def lock_kernel_cache_files():
    """Make numba's cache files of a kernel change one process at a time. numba's
    ``IndexDataCacheFile.save`` reads the kernel's index, names a data file after the
    entries it holds, writes the index, then the data: two processes compiling two
    signatures of one kernel at once (a cold cache: the first commands after a plain
    ``pip install``, or their worker processes) both name theirs ``.1``, the index keeps
    one signature and the data file the other's machine code, and the next process to
    load that signature calls the wrong code and crashes (numba issues #4807 and #10128;
    seen here: a segfault in ``point_views`` after two workers of a group query compiled
    it). A load between a save's index and its data reads the data file's previous
    content just as well. So each save holds an exclusive ``flock`` on a lock file beside
    the index, and each load a shared one. Nothing is done where numba's methods are not
    the ones expected, nor without ``fcntl`` (Windows)."""
    try:
        import fcntl
    except ImportError:
        return
    from numba.core import caching

    cache_file = caching.IndexDataCacheFile
    expected = {"save": "_save_index", "load": "_load_index"}
    methods = {name: getattr(cache_file, name, None) for name in expected}
    if any(getattr(m, "viscx", False) or need not in getattr(getattr(m, "__code__", None), "co_names", ())
           for m, need in zip(methods.values(), expected.values())):
        return

    def locked(method, mode):
        @functools.wraps(method)
        def run(self, *args):
            try:
                handle = open(self._index_path + ".lock", "a")
            except OSError:  # a read-only cache directory: nothing to race with
                return method(self, *args)
            with handle:
                fcntl.flock(handle, mode)  # released when the handle closes
                return method(self, *args)

        run.viscx = True
        return run

    cache_file.save = locked(methods["save"], fcntl.LOCK_EX)
    cache_file.load = locked(methods["load"], fcntl.LOCK_SH)


def load_cached_kernels_without_registries():
    """Load numba kernels from numba's cache without first refreshing its target and typing
    contexts. numba's ``Cache.load_overload`` calls ``target_context.refresh()`` before it
    loads a kernel: on a process's first kernel that imports and installs every registry of
    typing templates and lowering implementations (~0.2 CPU s; the Cornell matrix at
    ``--tol 1e-4`` is ~2), which compiling needs and loading machine code does not. What a
    loaded kernel does need is numba's runtime (NRT: its allocator's symbols for the
    JIT), so that is initialised instead (``rtsys.initialize``, what ``refresh`` does
    first). A kernel not in the cache is compiled as before: numba's compiler refreshes
    the contexts itself. Nothing is done where numba's ``load_overload`` is not the one
    expected (its code must name ``refresh`` and ``_load_overload``)."""
    from numba.core import caching

    cache = caching.Cache
    original = cache.load_overload
    names = getattr(getattr(original, "__code__", None), "co_names", ())
    if getattr(original, "viscx", False) or "refresh" not in names or "_load_overload" not in names:
        return
    from numba.core.runtime import rtsys

    def load_overload(self, sig, target_context):
        rtsys.initialize(target_context)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)

    load_overload.viscx = True
    cache.load_overload = load_overload


class Terminated(BaseException):
    """Raised in the main thread on SIGTERM so that clean-up (temporary files) runs."""


def _on_signal(signum, frame):
    received_signals.append(signum)
    if _numba_busy():
        _defer(signum)
    elif _in_numba(frame):
        _deliver_again(signum)
    else:
        raise _exception(signum)


def _exception(signum):
    return Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def _numba_busy():
    """Whether this thread holds numba's compiler lock: it is compiling a kernel or loading
    one from its cache. An exception raised in there can leave a kernel half loaded, and
    the process then crashes when it calls the kernel, not at the signal (seen under load:
    SIGINT while the scene stage's kernels loaded, a segfault in a kernel after SIGTERM)."""
    lock = sys.modules.get("numba.core.compiler_lock")  # not imported: no kernel yet
    return lock is not None and lock.global_compiler_lock.is_locked()


#: numba's and llvmlite's Python code, by file
_NUMBA_FILES = tuple(os.sep + name + os.sep for name in ("numba", "llvmlite"))


def _in_numba(frame):
    """Whether the signal's handler interrupted numba's (or llvmlite's) own Python code: a
    kernel call runs some (type dispatch, finalizers of its objects during the call's
    allocations), and an exception raised there can leave the call half done: a kernel that
    returns a tuple of arrays then hands back a tuple with an empty slot, and the caller's
    unpacking crashes (segfault in ``face_loops``' call of ``_cycles`` after SIGTERM, 3 of
    170 interrupted builds, seen in a core dump: the returned tuple's first item NULL)."""
    while frame is not None:
        # the whole stack: an exception raised here unwinds through every frame below; and a
        # handler interrupted while it arranged the delivery (a loaded machine runs the 5 ms
        # timer before ``Timer.start`` returns) would raise through the numba frame it left
        code = frame.f_code
        if code is _on_signal.__code__ or (code.co_filename.endswith(".py") and any(
                name in code.co_filename for name in _NUMBA_FILES)):
            return True
        frame = frame.f_back
    return False


def _deliver_again(signum):
    """Send ``signum`` to this process again in 5 ms (while viscx's handler is still the
    signal's): its exception is then raised outside numba's code."""
    def again():
        if signal.getsignal(signum) is _on_signal:
            os.kill(os.getpid(), signum)

    timer = threading.Timer(0.005, again)
    timer.daemon = True
    timer.start()


#: signals received while numba held its compiler lock, raised when it lets go of it;
#: and the listener that does so, registered with numba once
_deferred = []
_release_listener = []


def _defer(signum):
    """Raise ``signum``'s exception when numba releases its compiler lock (the release
    announces the end of a ``numba:compiler_lock`` event): the kernel is then whole."""
    from numba.core import event

    class Release(event.Listener):
        def on_start(self, ev):
            pass

        def on_end(self, ev):
            if _deferred and not _numba_busy():  # the outermost release (the lock is re-entrant)
                signum = _deferred[0]
                _deferred.clear()
                raise _exception(signum)

    if not _release_listener:
        _release_listener.append(Release())
        event.register("numba:compiler_lock", _release_listener[0])
    _deferred.append(signum)


def _unraisable(info):
    """Keep quiet about a signal's exception swallowed in a weakref callback or
    ``__del__``: ``received_signals`` still stops the commit and sets the exit status."""
    if not isinstance(info.exc_value, (KeyboardInterrupt, Terminated)):
        sys.__unraisablehook__(info)


def _fail(message, code):
    click.echo(f"viscx: {message}", err=True)
    return code


def main(argv=None):
    """Entry point of the ``viscx`` console script; returns via ``sys.exit``.

    While it runs, SIGTERM and SIGINT become exceptions (so that a command's clean-up runs),
    a signal's exception swallowed in a ``__del__`` is not reported, and RuntimeWarnings are
    ignored; all three are restored on the way out, so that a process that calls it (a
    notebook, a test through click's runner) keeps its own. Signal handlers can only be set
    from the main thread: elsewhere the command runs with the caller's.
    """
    received_signals.clear()
    _deferred.clear()
    clear_inputs()
    handlers = {}
    if threading.current_thread() is threading.main_thread():
        handlers = {signum: signal.signal(signum, _on_signal) for signum in (signal.SIGTERM, signal.SIGINT)}
    unraisablehook, sys.unraisablehook = sys.unraisablehook, _unraisable
    try:
        with warnings.catch_warnings():
            # numeric warnings are not messages for a person: errors are reported as such
            warnings.simplefilter("ignore", RuntimeWarning)
            code = _run(argv)
    finally:
        sys.unraisablehook = unraisablehook
        for signum, handler in handlers.items():
            if handler is not None:  # None: set outside Python, cannot be set back from it
                signal.signal(signum, handler)
    sys.exit(code)


def _run(argv):
    """Run the command line ``argv``; its exit status (reporting an error on stderr)."""
    try:
        # without standalone mode click returns ctx.exit()'s code instead of raising
        returned = cli.main(args=argv, prog_name="viscx", standalone_mode=False)
        code = returned if isinstance(returned, int) else 0
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
        code = 130
    except Terminated:
        code = 143
    except OSError as exc:
        name = f": {exc.filename}" if exc.filename else ""
        code = _fail(f"error: {exc.strerror or exc}{name}", 2)
    except Exception as exc:  # a bug in viscx: say so in one line unless asked for more
        if os.environ.get("VISCX_DEBUG"):
            raise
        # a signal's exception raised inside a C extension (h5py) can come out as another
        # exception: then it is the interruption, reported below, not a bug
        code = 1 if received_signals else _fail(
            f"internal error: {type(exc).__name__}: {exc} (set VISCX_DEBUG=1 for a traceback)", 1)
    if received_signals:  # also when the signal's exception was swallowed on the way
        code = 143 if received_signals[0] == signal.SIGTERM else 130
    if code in (130, 143):
        _fail("terminated" if code == 143 else "interrupted", code)
    return code
