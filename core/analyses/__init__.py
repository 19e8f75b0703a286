"""Analyses: experiment -> table rows. Shared here: running independent work units."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from typing import Any


def map_tasks(fn: Callable[[Any], Any], tasks: Iterable, jobs: int = 1,
              on_done: Callable[[], None] | None = None) -> list:
    """``[fn(t) for t in tasks]``, in ``jobs`` processes when more than one; results keep the
    order of ``tasks`` and ``on_done`` is called once per finished task."""
    tasks = list(tasks)
    out = []
    if jobs > 1 and len(tasks) > 1:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            results = pool.map(fn, tasks)
            for result in results:
                out.append(result)
                if on_done:
                    on_done()
    else:
        for task in tasks:
            out.append(fn(task))
            if on_done:
                on_done()
    return out
