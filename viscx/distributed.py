"""A build's independent chunks run as dask tasks (``viscx build --scheduler``).

The V2 builders work in chunks that never meet (:mod:`viscx.skeleton.chunks`: V-cells
by ranges of vertices, EE-cells by chunks of squares). :class:`InProcess` runs them one
after the other in this process; :class:`Dask` sends each chunk to a worker of a
``dask.distributed`` cluster as one task, the scene sent once to every worker. Either
way the results come back in the chunks' order, one at a time, and the caller writes
each to the file before it takes the next (:class:`viscx.formats.hdf5.CellsAppender`):
no process holds a whole level, and the file is the same whatever runs the chunks.

dask is an optional dependency (``pip install 'viscx[dask]'``), imported only here and
only when a scheduler is asked for.
"""

import os
from dataclasses import replace

from viscx.cache import Cached
from viscx.errors import ParameterError, ViscxError

#: Chunks sent to the cluster ahead of the one the caller waits for, per worker: enough
#: to keep every worker busy while the client writes, few enough that the results
#: waiting for their turn stay small.
AHEAD = 2


class InProcess:
    """Chunks run one after the other in this process."""

    workers = 1

    def map(self, function, arguments, shared=()):
        """``function(*shared, *a)`` for each tuple ``a`` of ``arguments`` (an iterable,
        consumed one at a time), yielded in order."""
        for args in arguments:
            yield function(*shared, *args)

    def peaks(self):
        """Peak resident memory (GB) of each worker process: none."""
        return {}

    def close(self):
        pass


class Dask:
    """Chunks run as tasks of a dask.distributed cluster.

    Parameters
    ----------
    scheduler : str
        ``"local"``: a cluster of ``workers`` processes on this machine, started here
        and stopped by :meth:`close`; else the address of a running scheduler
        (``tcp://host:8786``), whose workers must import the same viscx.
    workers : int, optional
        Worker processes of the local cluster (default: the CPU count), one thread each
        (the builders' numpy and numba calls use the cores of their process).
    """

    def __init__(self, scheduler="local", workers=None):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise ParameterError("{scheduler} needs dask: pip install 'viscx[dask]' "
                                 "(dask and dask.distributed)") from None
        self.cluster = None
        if scheduler == "local":
            n = max(1, int(workers or os.cpu_count() or 1))
            # processes, not threads: each worker's memory is its own (and measured so); no
            # dashboard, and the scheduler's HTTP routes on a free port (on 8787, the
            # default, a second cluster on the machine warns "Port 8787 is already in use")
            self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                        scheduler_kwargs={"dashboard": False}, memory_limit=0, silence_logs=40)
            self.client = Client(self.cluster)
        else:
            if workers is not None:
                raise ParameterError("{workers} sizes a local cluster ({scheduler} local); a running scheduler has "
                                     "the workers started for it")
            try:
                self.client = Client(scheduler, timeout="30s")
            except (OSError, TimeoutError) as exc:
                raise ViscxError(f"cannot reach the dask scheduler at {scheduler}: {exc}") from None
        self.workers = max(1, len(self.client.scheduler_info().get("workers", {})))

    def map(self, function, arguments, shared=()):
        """``function(*shared, *a)`` for each tuple ``a`` of ``arguments``, each one task,
        yielded in order as they finish. ``shared`` is sent once to every worker; at most
        AHEAD tasks per worker are out at a time, so ``arguments`` (an iterable) is made
        and the results are held only that far ahead of the caller."""
        from collections import deque

        shared = [self.client.scatter(portable(v), broadcast=True, hash=False) for v in shared]
        ahead = AHEAD * self.workers
        pending = deque()
        arguments = iter(arguments)
        try:
            for args in arguments:
                pending.append(self.client.submit(function, *shared, *args, pure=False))
                if len(pending) >= ahead:
                    yield self._take(pending)
            while pending:
                yield self._take(pending)
        finally:
            for future in [*pending, *shared]:
                future.release()

    @staticmethod
    def _take(pending):
        future = pending.popleft()
        try:
            return future.result()
        finally:
            future.release()

    def peaks(self):
        """Peak resident memory (GB) of each worker process so far: {worker address: GB}."""
        from viscx.progress import peak_memory_gb

        return self.client.run(peak_memory_gb)

    def close(self):
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def portable(value):
    """``value`` to send to another process: a record without its cache, a scene without
    its ray tracer (each worker builds its own on first use)."""
    from viscx.scene import Scene

    if isinstance(value, Scene):
        return replace(value, _caster=None, _contacts=None)
    return replace(value) if isinstance(value, Cached) else value


def runner(scheduler=None, workers=None):
    """:class:`Dask` for a scheduler (``"local"`` or an address), else :class:`InProcess`."""
    if scheduler is None:
        if workers is not None:
            raise ParameterError("{workers} sizes the dask cluster of {scheduler} local; give {scheduler} too")
        return InProcess()
    return Dask(scheduler, workers)
