"""Independent chunks of numpy and numba work on threads.

The heavy calls (numpy on large arrays, numba kernels compiled ``nogil``) release
the GIL, so threads overlap them without copying the scene into other processes.
Results come back in the chunks' order: the output does not depend on the number
of threads.
"""

import os
import threading
from concurrent.futures import ThreadPoolExecutor


def default_workers(workers=None):
    """``workers``, or the machine's CPU count."""
    return max(1, int(workers or os.cpu_count() or 1))


_worker = threading.local()


def in_pool():
    """Whether the calling thread is one of the threads of a :func:`map_chunks` running
    on several: they keep the cores busy, so numba kernels it calls need no threads of
    their own."""
    return getattr(_worker, "pooled", False)


def row_chunks(n, size):
    """Consecutive slices covering ``range(n)``, ``size`` rows each (the last one shorter)."""
    return [slice(lo, min(lo + size, n)) for lo in range(0, n, size)]


def map_chunks(function, chunks, workers=None, progress=None):
    """``[function(c) for c in chunks]``, run on ``workers`` threads.

    Called from inside a chunk (nested), it runs in the calling thread: the outer
    call already keeps the threads busy.

    Parameters
    ----------
    function : callable
    chunks : list
    workers : int, optional
        Default: the CPU count. 1 runs in the calling thread.
    progress : callable, optional
        Called with each chunk once it is done (e.g. a progress bar's update), under a lock.
    """
    lock = threading.Lock()

    def run(chunk):
        outer = getattr(_worker, "busy", False)
        _worker.busy = True
        try:
            out = function(chunk)
        finally:
            _worker.busy = outer
        if progress is not None:
            with lock:
                progress(chunk)
        return out

    workers = default_workers(workers)
    if workers == 1 or len(chunks) <= 1 or getattr(_worker, "busy", False):
        return [run(c) for c in chunks]

    def run_pooled(chunk):
        _worker.pooled = True
        return run(chunk)

    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(run_pooled, chunks))
