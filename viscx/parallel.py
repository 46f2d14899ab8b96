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


def map_chunks(function, chunks, workers=None, progress=None):
    """``[function(c) for c in chunks]``, run on ``workers`` threads.

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
        out = function(chunk)
        if progress is not None:
            with lock:
                progress(chunk)
        return out

    workers = default_workers(workers)
    if workers == 1 or len(chunks) <= 1:
        return [run(c) for c in chunks]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(run, chunks))
