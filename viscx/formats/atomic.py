"""Output files: never one of the inputs; regular files written atomically.

A regular file is written to a temporary file beside the target and renamed on
success: a build that fails or is interrupted (Ctrl-C, SIGTERM) leaves neither a
partial output nor its temporary file behind; the CLI turns SIGTERM into an
exception so that the clean-up below runs (see :func:`viscx.cli.main`). A process
killed outright (SIGKILL) cannot clean up: the next write to the same path removes
the temporaries whose writer is gone (the writer's pid is in the name).

A FIFO, a character device (a terminal, ``/dev/null``) or ``-`` (standard output)
is written directly: renaming a file onto it would replace it. An output that is
one of the files the command read (the same file, also through a symbolic or hard
link: same device and inode) is refused, so that no input is lost.
"""

import contextlib
import os
import re
import stat
from pathlib import Path

from viscx.errors import ViscxError

__all__ = ["atomic_path", "temporary_name", "received_signals", "register_input", "check_output", "clear_inputs",
           "release_input", "remove_stale_temporaries"]

#: Signals the CLI received (its handlers append here before raising). A handler's
#: exception is lost when it lands in a weakref callback or ``__del__`` (Python
#: prints "Exception ignored" and carries on), so the commit below checks this too.
received_signals = []

#: The files read so far: (st_dev, st_ino) -> the path as given (cleared by the CLI per command)
_inputs = {}


def register_input(path):
    """Remember that ``path`` is an input: no output may replace it."""
    with contextlib.suppress(OSError, ValueError):
        st = os.stat(path)
        if stat.S_ISREG(st.st_mode):
            _inputs.setdefault((st.st_dev, st.st_ino), str(path))


def clear_inputs():
    _inputs.clear()


def release_input(path):
    """Allow ``path`` to be written although it was read (an update in place, asked for)."""
    with contextlib.suppress(OSError, ValueError):
        st = os.stat(path)
        _inputs.pop((st.st_dev, st.st_ino), None)


def _same_as_input(path, inputs):
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return inputs.get((st.st_dev, st.st_ino))


def check_output(path, inputs=()):
    """ViscxError when ``path`` is one of ``inputs`` or of the registered inputs (the same
    file through any link). Commands call it before their work; :func:`atomic_path` again
    before it writes."""
    if path is None or str(path) == "-":
        return
    for extra in inputs:
        register_input(extra)
    same = _same_as_input(path, _inputs)
    if same is not None:
        alias = "" if os.path.abspath(same) == os.path.abspath(path) else f" (the same file as {same})"
        raise ViscxError(f"-o {path} is an input of this command{alias}; write the output to another file")


def is_stream(path):
    """True for ``-`` and for an existing FIFO, character device or socket (written directly)."""
    if str(path) == "-":
        return True
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return False
    return stat.S_ISFIFO(mode) or stat.S_ISCHR(mode) or stat.S_ISSOCK(mode)


def temporary_name(path):
    """The temporary file name used while ``path`` is written: hidden, same folder
    (so the final rename is atomic), unique per process."""
    path = Path(path)
    return path.with_name(f".{path.name}.tmp{os.getpid()}")


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return pid > 0  # another user's live process (or a name that is no pid: kept)
    return True


def remove_stale_temporaries(path):
    """Remove ``.NAME.tmpPID`` files beside ``path`` whose writer (process PID) is gone:
    what a writer killed by SIGKILL leaves. Returns the removed paths."""
    path = Path(path)
    pattern = re.compile(rf"\.{re.escape(path.name)}\.tmp([0-9]+)")
    removed = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(path.parent if str(path.parent) else "."):
            m = pattern.fullmatch(entry.name)
            if m and int(m.group(1)) != os.getpid() and not _pid_alive(int(m.group(1))) and entry.is_file(follow_symlinks=False):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(entry.path)
                    removed.append(Path(entry.path))
    return removed


@contextlib.contextmanager
def atomic_path(path, stream=True):
    """Yield a path to write; for a regular file a temporary one renamed to ``path`` on success.

    On any exception (including KeyboardInterrupt and SystemExit) the temporary
    file is removed and ``path`` is left as it was. ``-`` and existing FIFOs and
    character devices are yielded as they are (``-`` as ``/dev/stdout``) and written
    directly, unless ``stream`` is False (formats that need a seekable file: HDF5),
    then they are refused. A symbolic link is followed: its target is replaced.

    Raises
    ------
    ViscxError
        When ``path`` is one of the command's inputs (:func:`check_output`).

    Examples
    --------
    >>> with atomic_path("out.h5") as tmp:          # doctest: +SKIP
    ...     write_everything(tmp)
    """
    check_output(path)
    if is_stream(path):
        if not stream:
            raise ViscxError(f"-o {path}: this format needs a regular file (it is written with seeks), "
                             "not a pipe, a device or standard output")
        yield Path("/dev/stdout") if str(path) == "-" else Path(path)
        return
    path = Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)
    remove_stale_temporaries(path)
    tmp = temporary_name(path)
    try:
        yield tmp
        if received_signals:
            raise KeyboardInterrupt(f"signal {received_signals[0]}")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
