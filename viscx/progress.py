"""Progress of long runs on stderr: tqdm bars on a terminal, log lines otherwise.

A run under CI, ``nohup`` or a pipe has no terminal to draw bars on, so there every
line says when it was written and how much memory the process has used::

    [   24.1 s, peak 1.02 GB] build: V1 started
    [   44.1 s, peak 1.35 GB] build: V1 still running (20 s in the stage)
    [   51.0 s, peak 1.38 GB] build: V1 done in 26.9 s

A stage (:class:`Stages`) logs its start and end, a bar inside it logs its count at
most every ``LOG_EVERY`` seconds, and a heartbeat thread writes a line when nothing
was written for ``HEARTBEAT`` seconds, so a long stage is never silent for longer
(unless one C call holds the interpreter's lock throughout: the line then comes when
it returns). A run's first ``QUIET_START`` seconds write nothing: a short command's
stderr holds its result or its one-line error only. ``quiet`` silences all of it.
"""

import atexit
import resource
import sys
import threading
import time

#: Seconds between two lines of a bar's count (non-terminal stderr).
LOG_EVERY = 10.0
#: A running stage writes a line when nothing was written for this many seconds.
HEARTBEAT = 20.0
#: Lines start once the run (the outermost :class:`Stages`, else the bar) is this old.
QUIET_START = 20.0

_LOCK = threading.RLock()
_last_line = [0.0]
# when the run started (the outermost Stages sets it), for the elapsed seconds and QUIET_START
_run_start = [None]


def peak_memory_gb():
    """The process's peak resident memory in GB (``ru_maxrss``: kilobytes on Linux,
    bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 1e9 if sys.platform == "darwin" else peak * 1024 / 1e9


def on_terminal():
    """Whether stderr is a terminal (bars) rather than a file or a pipe (log lines)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed stream
        return False


def log(message, start=None):
    """Write one progress line on stderr, stamped with the run's seconds and peak memory,
    once the run (started at ``start``, default the outermost Stages') is QUIET_START old."""
    with _LOCK:
        now = time.perf_counter()
        start = _run_start[0] if _run_start[0] is not None else (now if start is None else start)
        if now - start < QUIET_START:
            return
        sys.stderr.write(f"[{now - start:7.1f} s, peak {peak_memory_gb():.2f} GB] {message}\n")
        sys.stderr.flush()
        _last_line[0] = now


def quiet_for():
    """Seconds since the last progress line."""
    return time.perf_counter() - _last_line[0]


class LogBar:
    """tqdm's interface as used here (``update``, ``set_postfix_str``, ``close``, a
    context manager) written as log lines, at most one per ``LOG_EVERY`` seconds; none
    when ``silent``."""

    def __init__(self, total=None, desc=None, unit="it", silent=False):
        self.total, self.desc, self.unit, self.n, self.postfix = total, desc or "progress", unit, 0, ""
        self.start, self.silent = time.perf_counter(), silent

    def update(self, n=1):
        self.n += n
        if not self.silent and quiet_for() >= LOG_EVERY:
            of = f"/{self.total}" if self.total is not None else ""
            plural = "s" if self.unit.isalpha() and (self.total if self.total is not None else self.n) != 1 else ""
            log(f"{self.desc}: {self.n}{of} {self.unit}{plural}"
                + (f" ({self.postfix})" if self.postfix else ""), self.start)

    def set_postfix_str(self, s="", refresh=True):
        self.postfix = s

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def bar(total=None, desc=None, quiet=False, unit="it"):
    """A progress bar for a stage: tqdm on a terminal, :class:`LogBar` lines when stderr
    is not one, nothing when ``quiet`` (tqdm imported only for a bar it draws: 0.03 CPU s
    of a small command's start)."""
    if quiet or not on_terminal():
        return LogBar(total, desc, unit, silent=quiet)
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, leave=False, dynamic_ncols=True)


class Stages:
    """The named stages of a long run (a context manager): each :meth:`stage` is timed
    into ``timings``, shown on the run's bar (terminal) or logged at its start and end
    (otherwise), with a heartbeat line while it runs. ``current`` names the running
    stage (for a message when it fails).

    Parameters
    ----------
    names : list of str
        The stages, for the bar's total.
    desc : str
        The run's name (``build``).
    quiet : bool
    """

    def __init__(self, names, desc, quiet=False):
        self.desc, self.quiet, self.timings, self.current = desc, quiet, {}, None
        self.logging = not quiet and not on_terminal()
        self._bar = None if self.logging else bar(total=len(names), desc=desc, quiet=quiet, unit="stage")
        self._stage_start = None
        self._stop = threading.Event()
        self._beat = threading.Thread(target=self._heartbeat, daemon=True, name="viscx-heartbeat")

    def __enter__(self):
        self._outermost = _run_start[0] is None
        if self._outermost:
            _run_start[0] = time.perf_counter()
        if self.logging:
            self._beat.start()
        return self

    def __exit__(self, *exc):
        if self._outermost:
            _run_start[0] = None
        self._stop.set()
        if self._beat.is_alive():
            self._beat.join()
        if self._bar is not None:
            self._bar.close()

    def _heartbeat(self):
        while not self._stop.wait(min(1.0, HEARTBEAT / 4)):
            with _LOCK:
                name, start = self.current, self._stage_start
                if name is not None and quiet_for() >= HEARTBEAT:
                    log(f"{self.desc}: {name} still running ({time.perf_counter() - start:.0f} s in the stage)")

    def stage(self, name):
        """A context manager running stage ``name``."""
        return _Stage(self, name)


class _Stage:
    def __init__(self, stages, name):
        self.stages, self.name = stages, name

    def __enter__(self):
        s = self.stages
        with _LOCK:
            s.current, s._stage_start = self.name, time.perf_counter()
        if s._bar is not None:
            s._bar.set_postfix_str(self.name)
        if s.logging:
            log(f"{s.desc}: {self.name} started")
        return self

    def __exit__(self, kind, value, tb):
        s = self.stages
        if kind is not None:  # `current` keeps naming the stage that failed
            return False
        seconds = time.perf_counter() - s._stage_start
        s.timings[self.name] = seconds
        with _LOCK:
            s.current = None
        if s._bar is not None:
            s._bar.update()
        if s.logging:
            log(f"{s.desc}: {self.name} done in {seconds:.1f} s")
        return False


_compile = {"on": False, "installed": False, "bar": None}


def report_compilation(on=True):
    """Say so on stderr when numba compiles a kernel instead of loading it from its cache
    (``cache=True``): the first run after an install or a change of the source compiles
    about a hundred kernels, a minute of CPU. One notice line, then a count of the kernels
    compiled (a bar on a terminal, log lines otherwise). Nothing when every kernel comes
    from the cache. ``on=False`` turns it off (a command calls it at its end, so that
    other work in the process, such as tests, is not reported on)."""
    _compile["on"] = on
    if not on or _compile["installed"]:
        return
    from numba.core import event

    class Notice(event.Listener):
        def on_start(self, ev):
            if _compile["on"] and _compile["bar"] is None:
                sys.stderr.write("viscx: compiling numba kernels for their first use (once after an install; "
                                 "about a minute; `python -m viscx.warmup` does it ahead)\n")
                sys.stderr.flush()
                _compile["bar"] = bar(desc="compiling kernels", unit="kernel")

        def on_end(self, ev):  # viscx's kernels are counted, not numba's own helpers they compile
            kernel = getattr(ev.data.get("dispatcher"), "py_func", None)
            if _compile["on"] and _compile["bar"] is not None and getattr(kernel, "__module__", "").startswith("viscx"):
                _compile["bar"].set_postfix_str(kernel.__qualname__)
                _compile["bar"].update()

    _compile["installed"] = True
    event.register("numba:compile", Notice())
    atexit.register(lambda: _compile["bar"] is not None and _compile["bar"].close())
