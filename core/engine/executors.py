"""Where the work units of a run go besides this machine's processes: Dask distributed
(``pip install 'estim[dask]'``). An executor is a callable ``executor(fn, tasks) -> iterator
of (index, result)`` for ``tasks = {index: task}``, yielding in completion order
(:func:`estim.util.workunits.execution`).

Each work unit draws from its own ``SeedSequence`` key, so a cell computes the same on any
worker: a Dask run writes the same tables, byte for byte, as ``--jobs 1``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

from estim.errors import UsageError


def dask_executor(client: Any) -> Callable[[Callable, dict], Iterator[tuple[int, Any]]]:
    """An executor over a ``distributed.Client`` (a scheduler address, a LocalCluster, or a
    dask-jobqueue cluster such as ``SLURMCluster``)."""
    from distributed import as_completed

    def run(fn: Callable, tasks: dict) -> Iterator[tuple[int, Any]]:
        futures = {client.submit(fn, task, pure=False): i for i, task in tasks.items()}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        except BaseException:
            client.cancel(list(futures))
            raise
    return run


@contextlib.contextmanager
def executor(kind: str, scheduler: str | None, jobs: int) -> Iterator[Callable | None]:
    """``None`` for this machine (``kind`` ``local``), or a Dask executor on ``scheduler`` (a
    local cluster of ``jobs`` single-threaded workers without one), closed afterwards. A
    missing Dask or an unreachable or malformed scheduler address is a ``UsageError``."""
    if kind == "local":
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise UsageError("--executor dask needs Dask distributed: pip install "
                         "'estim[dask]'") from None
    cluster = None if scheduler else LocalCluster(n_workers=jobs, threads_per_worker=1,
                                                  processes=True, dashboard_address=None)
    try:
        client = Client(scheduler) if scheduler else Client(cluster)
    except (OSError, ValueError, TypeError) as exc:
        if cluster is not None:
            cluster.close()
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        raise UsageError(f"cannot reach the Dask scheduler {scheduler}: {first}") from None
    try:
        yield dask_executor(client)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
