"""Atomic output files: write to a temporary file beside the target, rename on success.

A build that fails or is interrupted (Ctrl-C, SIGTERM) leaves neither a partial
output nor its temporary file behind; the CLI turns SIGTERM into an exception so
that the clean-up below runs (see :func:`viscx.cli.main`).
"""

import contextlib
import os
from pathlib import Path

__all__ = ["atomic_path", "temporary_name", "received_signals"]

#: Signals the CLI received (its handlers append here before raising). A handler's
#: exception is lost when it lands in a weakref callback or ``__del__`` (Python
#: prints "Exception ignored" and carries on), so the commit below checks this too.
received_signals = []


def temporary_name(path):
    """The temporary file name used while ``path`` is written: hidden, same folder
    (so the final rename is atomic), unique per process."""
    path = Path(path)
    return path.with_name(f".{path.name}.tmp{os.getpid()}")


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path to write; on success rename it to ``path``.

    On any exception (including KeyboardInterrupt and SystemExit) the temporary
    file is removed and ``path`` is left as it was.

    Examples
    --------
    >>> with atomic_path("out.h5") as tmp:          # doctest: +SKIP
    ...     write_everything(tmp)
    """
    path = Path(path)
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
