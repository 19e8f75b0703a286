"""What every analysis module provides, and what the runner, the CLI and ``estim check`` use.

An analysis is a module registered by one line in :data:`estim.analyses.ANALYSES`. It owns:

``SCHEMA``      its config keys beyond the common ones of :mod:`estim.config` (a schema of
                :mod:`estim.schema`; it may re-declare a common key, e.g. make ``model``
                required)
``TABLES``      ``{metric: TableSpec}``: every table it writes, its columns and the key that
                joins a row to the reference (thesis or paper) table
``Config``      its settings (:mod:`estim.settings`); ``SCHEMA = Config.schema()``
``prepare(spec, source) -> Plan``   cross-checks beyond the schema (raising ``ConfigError``
                with the key path) and the objects built once per experiment (models,
                estimators) as the analysis' own typed ``Plan``; stored as
                ``Experiment.plan``
``work_units(exp) -> int``          for progress reports
``work_size(spec) -> int``          state-samples the run computes, bounded by ``--max-work``
``run(exp, jobs, on_done) -> Result``  tables (one DataFrame per metric) and figures
``summary(result) -> str``          what ``estim run`` prints after a run
``tiny(spec) -> spec``              the experiment shrunk to seconds (contract tests)
``RUNS_ALONE``  optional, True for an analysis whose tables are timings: run with no other
                config's work beside it (:mod:`estim.scheduler`)
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

from estim import lazy
from estim.scheduler import ignore_interrupts, stop
from estim.tablespec import TableSpec

pd = lazy.load("pandas")

__all__ = ["TableSpec"]


@dataclass
class Result:
    tables: dict[str, pd.DataFrame]
    figures: dict[str, Any] = field(default_factory=dict)


@dataclass
class Execution:
    """How :func:`map_tasks` runs inside :func:`execution`: ``executor`` (``None``: this
    machine, ``jobs`` processes) is a callable ``executor(fn, tasks) -> iterator of (index,
    result)`` in any order (:func:`estim.executors.dask_executor`); ``store`` keeps finished
    cells, ``store.get(key) -> (found, value)`` and ``store.put(key, value)``
    (:class:`estim.io.CellStore`), keyed by the sweep cell, the map call's number within it
    and the task's index. ``offsets`` counts the tasks of each map call number over the
    sweep cells so far (empty: the analysis made no map call, so a shard cannot share it
    out); ``computed`` counts the cells computed here. ``pool`` is a process pool shared
    with other configs' drivers (:mod:`estim.scheduler`): the tasks go there, whatever
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
        futures = {ctx.pool.submit(fn, tasks[i]): i for i in pending}
        left = set(futures)
        try:
            while left:
                done, left = wait(left, timeout=1.0, return_when=FIRST_COMPLETED)
                for future in done:
                    finished(futures[future], future.result())
                if any(future.cancelled() for future in left):   # a cancel wakes no waiter
                    raise CancelledError("the shared pool was stopped")
        except BaseException:
            for future in futures:
                future.cancel()
            raise
    elif jobs > 1 and len(pending) > 1:
        pool = ProcessPoolExecutor(max_workers=min(jobs, len(pending)),
                                   initializer=ignore_interrupts)
        try:
            for i, value in zip(pending, pool.map(fn, [tasks[i] for i in pending]),
                                strict=True):
                finished(i, value)
        except BaseException:
            stop(pool)
            raise
        pool.shutdown()
    else:
        for i in pending:
            finished(i, fn(tasks[i]))
    if others:
        raise ShardDone
    return out
