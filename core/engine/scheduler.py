"""Several configs at once on one pool of processes (``estim reproduce``, ``estim check``,
``estim run`` of several configs on this machine).

Each config's driver (its analysis' ``run``: the work units it hands to
:func:`estim.util.workunits.map_tasks`, then its tables and figures) runs in a thread of this
process, as many at once as the pool has processes, the longest config first; every work
unit of every config runs in one shared pool of ``jobs`` worker processes. So while one
config draws its figures or waits for its last unit, the pool works on the next config's
units, and a small config fills a core the big one leaves idle. Where a unit runs does not
change what it computes (each draws from its own seed), so the tables are those of
``--jobs 1``.

An analysis that times itself (``RUNS_ALONE = True``: :mod:`estim.experiments.burden`) runs
after every other config has finished, alone, so no other work shares its clock.
"""

from __future__ import annotations

import collections
import contextlib
import queue
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from estim.util.interrupt import raise_if_interrupted
from estim.util.processes import ignore_interrupts, stop

T = TypeVar("T")

_DONE = object()

POLL_S = 0.25
"""Seconds between two looks at :func:`estim.util.interrupt.raise_if_interrupted` while the
caller's thread waits for the drivers."""


@contextlib.contextmanager
def process_pool(jobs: int) -> Iterator[ProcessPoolExecutor]:
    """A pool of ``jobs`` worker processes, stopped on an error or Ctrl-C and shut down after
    its last unit otherwise. With the fork start method every worker is started before this
    returns, so no process is forked while the drivers' threads run (spawn and forkserver
    start workers on demand, from a clean process)."""
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=ignore_interrupts)
    try:
        pool.submit(int).result()
        raise_if_interrupted()
        yield pool
    except BaseException:
        stop(pool)
        raise
    pool.shutdown()


def run_each(items: Sequence[T], work: Callable[[T], Any], threads: int,
             alone: Callable[[T], bool] = lambda _item: False,
             on_error: Callable[[], None] | None = None) -> Iterator[tuple[T, Any]]:
    """``work(item)`` for every item, up to ``threads`` at once, started in the order given;
    yields ``(item, value)`` as each finishes. The items ``alone`` names run afterwards, one
    at a time, once the others have all finished.

    The first exception stops the start of further items, calls ``on_error`` (to cancel the
    work the running ones wait for), waits for the running ones to end, and is raised."""
    together = [item for item in items if not alone(item)]
    yield from _concurrently(together, work, threads, on_error)
    yield from _concurrently([item for item in items if alone(item)], work, 1, on_error)


def _concurrently(items: list, work: Callable, threads: int,
                  on_error: Callable[[], None] | None) -> Iterator[tuple[Any, Any]]:
    todo = collections.deque(items)
    lock = threading.Lock()
    failed = threading.Event()
    results: queue.Queue = queue.Queue()

    def driver() -> None:
        while not failed.is_set():
            with lock:
                if not todo:
                    break
                item = todo.popleft()
            try:
                results.put((item, work(item), None))
            except BaseException as exc:            # handed to the caller's thread
                failed.set()
                results.put((item, None, exc))
        results.put(_DONE)

    count = max(1, min(threads, len(items)))
    for _ in range(count if items else 0):
        threading.Thread(target=driver, daemon=True, name="estim-driver").start()
    running, first = count if items else 0, None
    while running:
        try:
            got = results.get(timeout=POLL_S)
        except queue.Empty:
            raise_if_interrupted()
            continue
        if got is _DONE:
            running -= 1
            continue
        item, value, exc = got
        if exc is None:
            if first is None:
                yield item, value
        elif first is None:
            first = exc
            if on_error is not None:
                on_error()
    if first is not None:
        raise first
