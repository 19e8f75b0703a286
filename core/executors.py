"""Where the work units of a run go besides this machine's processes: Dask distributed
(``pip install 'estim[dask]'``). An executor is a callable ``executor(fn, tasks) -> iterator
of (index, result)`` for ``tasks = {index: task}``, yielding in completion order
(:func:`estim.analyses.base.execution`).

Each work unit draws from its own ``SeedSequence`` key, so a cell computes the same on any
worker: a Dask run writes the same tables, byte for byte, as ``--jobs 1``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any


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
