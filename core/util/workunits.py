"""The work-unit engine every analysis maps its tasks with (:func:`map_tasks`): in this
process, in ``jobs`` worker processes, on a shared pool or an executor set by the runner
(:func:`execution`), each finished unit kept in a cell store and a resumed run taking the
stored ones back. It knows nothing of analyses: the runner (:mod:`estim.engine.runner`) sets
the execution, the analyses call :func:`map_tasks`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import (
    FIRST_COMPLETED,
    CancelledError,
    Executor,
    ProcessPoolExecutor,
    wait,
)
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any

from estim.util.interrupt import raise_if_interrupted
from estim.util.processes import ignore_interrupts, stop


@dataclass
class Execution:
    """How :func:`map_tasks` runs inside :func:`execution`: ``executor`` (``None``: this
    machine, ``jobs`` processes) is a callable ``executor(fn, tasks) -> iterator of (index,
    result)`` in any order (:func:`estim.engine.executors.dask_executor`); ``store`` keeps finished
    cells, ``store.get(key) -> (found, value)`` and ``store.put(key, value)``
    (:class:`estim.engine.cells.CellStore`), keyed by the sweep cell, the map call's number within
    it and the task's index. ``offsets`` counts the tasks of each map call number over the
    sweep cells so far (empty: the analysis made no map call, so a shard cannot share it
    out); ``computed`` counts the cells computed here. ``pool`` is a process pool shared
    with other configs' drivers (:mod:`estim.engine.scheduler`): the tasks go there, whatever
    ``jobs`` says."""

    executor: Callable | None = None
    store: Any = None
    pool: Executor | None = None
    calls: int = 0
    shard: tuple[int, int] | None = None
    cell: int = 0
    offsets: dict = field(default_factory=dict)
    computed: int = 0


class ShardDone(Exception):
    """A shard (``--shard K/N``) has stored its cells of a map call whose other cells it
    does not have; the run stops there and ``estim merge`` finishes it (the cells it
    computed are counted in :attr:`Execution.computed`)."""


_EXECUTION: ContextVar[Execution | None] = ContextVar("estim_execution", default=None)


@contextmanager
def execution(executor: Callable | None = None, store: Any = None,
              shard: tuple[int, int] | None = None,
              pool: Executor | None = None) -> Iterator[Execution]:
    """Run the analyses called inside on ``executor`` (or on the shared ``pool``), saving
    each finished cell in ``store`` and taking the ones it already has from it (a resumed
    run); with ``shard = (k, n)`` compute only the cells whose number, counted over the
    sweep cells of a swept run, is ``k - 1`` modulo ``n`` (:class:`ShardDone`)."""
    token = _EXECUTION.set(Execution(executor, store, shard=shard, pool=pool))
    try:
        yield _EXECUTION.get()
    finally:
        _EXECUTION.reset(token)


@contextmanager
def sweep_cell(n: int) -> Iterator[None]:
    """Key the map calls made inside by sweep cell ``n`` (their numbers restart at 0), so a
    cell's stored work units are found again whatever the other cells did or did not do."""
    ctx = _EXECUTION.get()
    if ctx is None:
        yield
        return
    saved = ctx.cell, ctx.calls
    ctx.cell, ctx.calls = n, 0
    try:
        yield
    finally:
        ctx.cell, ctx.calls = saved


def map_tasks(fn: Callable[[Any], Any], tasks: Iterable, jobs: int = 1,
              on_done: Callable[[], None] | None = None) -> list:
    """``[fn(t) for t in tasks]``, in ``jobs`` processes when more than one (or on the
    executor of :func:`execution`); results keep the order of ``tasks`` and ``on_done`` is
    called once per finished task. Every task is a cell of its own, seeded by its own key,
    so where it runs does not change its result."""
    tasks = list(tasks)
    ctx = _EXECUTION.get()
    key: tuple[int, ...] = (0,)
    offset = 0
    if ctx is not None:
        key = (ctx.cell, ctx.calls) if ctx.cell else (ctx.calls,)
        offset = ctx.offsets.get(ctx.calls, 0)         # tasks of this call in earlier cells
        ctx.offsets[ctx.calls] = offset + len(tasks)
        ctx.calls += 1
    store = ctx.store if ctx is not None else None
    out: list = [None] * len(tasks)
    pending = []
    for i in range(len(tasks)):
        found, value = store.get((*key, i)) if store is not None else (False, None)
        if found:
            out[i] = value
            if on_done:
                on_done()
        else:
            pending.append(i)

    def finished(i: int, value: Any) -> None:
        out[i] = value
        if ctx is not None:
            ctx.computed += 1
        if store is not None:
            store.put((*key, i), value)
        if on_done:
            on_done()

    shard = ctx.shard if ctx is not None else None
    if shard is not None and pending:
        k, n = shard
        mine = [i for i in pending if (offset + i) % n == k - 1]
        others = [i for i in pending if (offset + i) % n != k - 1]
        pending = mine
    else:
        others = []
    if ctx is not None and ctx.executor is not None and pending:
        for i, value in ctx.executor(fn, {i: tasks[i] for i in pending}):
            finished(i, value)
    elif ctx is not None and ctx.pool is not None and pending:
        _on_pool(ctx.pool, fn, tasks, pending, finished)
    elif jobs > 1 and len(pending) > 1:
        pool = ProcessPoolExecutor(max_workers=min(jobs, len(pending)),
                                   initializer=ignore_interrupts)
        try:
            _on_pool(pool, fn, tasks, pending, finished)
        except BaseException:
            stop(pool)
            raise
        pool.shutdown()
    else:
        for i in pending:
            raise_if_interrupted()
            finished(i, fn(tasks[i]))
    if others:
        raise ShardDone
    return out


def _on_pool(pool: Executor, fn: Callable[[Any], Any], tasks: list, pending: list[int],
             finished: Callable[[int, Any], None]) -> None:
    """``finished(i, fn(tasks[i]))`` for every ``i`` of ``pending``, the calls on ``pool``,
    in the order they finish. The wait looks up every second for an interrupt Python may have
    swallowed (:func:`estim.util.interrupt.raise_if_interrupted`) and for units cancelled by a
    stopped shared pool (a cancel wakes no waiter); on any error the units not started are
    cancelled."""
    futures = {pool.submit(fn, tasks[i]): i for i in pending}
    left = set(futures)
    try:
        while left:
            done, left = wait(left, timeout=1.0, return_when=FIRST_COMPLETED)
            for future in done:
                finished(futures[future], future.result())
            raise_if_interrupted()
            if any(future.cancelled() for future in left):
                raise CancelledError("the shared pool was stopped")
    except BaseException:
        for future in futures:
            future.cancel()
        raise
