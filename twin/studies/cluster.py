"""The Dask cluster a study runs on: a ``LocalCluster`` (one single-threaded process worker per core, on
loopback, no dashboard) or an existing scheduler (``dask scheduler`` + ``dask worker`` processes).

Example
-------
>>> with study_client(workers=2) as (client, n):   # doctest: +SKIP
...     client.submit(sum, [1, 2]).result()
3
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import dask
from distributed import WorkerPlugin

log = logging.getLogger(__name__)

#: dask's nannies start workers with MALLOC_TRIM_THRESHOLD_=65536: glibc then hands every freed block above 64 KB
#: back to the OS and maps it again, which for a run's many 100 x 100 matrices cost the reduced campaign on a
#: LocalCluster(2) 17.6 s of system time instead of 5.1 s, and 72 s of wall time instead of 60 s (issue 21); our
#: LocalCluster leaves glibc's default
NO_MALLOC_TRIM = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"

#: how long to wait for an existing scheduler to answer and to have at least one worker (s)
CONNECT_TIMEOUT_S = 30.0


class ClusterError(RuntimeError):
    """The cluster cannot be started or reached; the message says what to check."""


class QuietCaseLogs(WorkerPlugin):
    """Worker plugin of a study's own LocalCluster: the cases' ``twin`` warnings go into their records
    (``warnings``, ``warning_messages``) instead of the terminal, where they would bury the progress bar."""

    name = "furnace-twin-quiet-case-logs"

    def setup(self, worker: Any) -> None:
        logging.getLogger("twin").addHandler(logging.NullHandler())  # no fallback print to stderr


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def _connect(scheduler: str) -> Any:
    """A ``distributed.Client`` of the scheduler at ``scheduler``, or :class:`ClusterError` within
    :data:`CONNECT_TIMEOUT_S`."""
    from distributed import Client

    try:
        return Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except OSError as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None


def check_scheduler(scheduler: str) -> None:
    """:class:`ClusterError` unless the scheduler at ``scheduler`` answers: asked before anything slow (a
    missing radiation table's trace) so that a wrong address is said at once."""
    _connect(scheduler).close()


@contextmanager
def study_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[tuple[Any, int]]:
    """A ``distributed.Client`` and its number of workers; the LocalCluster (if any) ends with the block."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        client = _connect(scheduler)
        try:
            try:
                client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
            except TimeoutError:
                raise ClusterError(f"the Dask scheduler at {scheduler} has no workers "
                                   f"(start some: dask worker {scheduler} --nthreads 1)") from None
            n = len(client.scheduler_info(n_workers=-1)["workers"])
            log.info("study on the Dask scheduler %s with %d workers", scheduler, n)
            yield client, n
        finally:
            client.close()
        return
    n = workers or default_workers()
    try:
        with dask.config.set({NO_MALLOC_TRIM: None}):
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address=None, silence_logs=logging.WARNING)
    except (RuntimeError, OSError) as exc:  # a worker process that cannot start (memory, a script without a
        # `if __name__ == "__main__":` guard under spawn, ...)
        raise ClusterError(f"cannot start a LocalCluster of {n} process workers: {exc}") from exc
    try:
        client = Client(cluster)
        try:
            client.register_plugin(QuietCaseLogs())
            log.info("study on a LocalCluster with %d process workers", n)
            yield client, n
        finally:
            client.close()
    finally:
        cluster.close()

