"""Worker processes that leave Ctrl-C to their parent, and a pool stopped at once."""

from __future__ import annotations

import signal
from concurrent.futures import Executor


def ignore_interrupts() -> None:
    """Workers leave Ctrl-C to the parent, which stops them and reports once; SIGTERM, by
    which the parent stops them, ends them at once (a forked worker would otherwise inherit
    the parent's handler, :mod:`estim.util.interrupt`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def stop(pool: Executor, join_s: float = 10.0) -> None:
    """Stop ``pool`` now: its workers are terminated, which breaks the pool, and every unit
    it has not finished fails with ``BrokenProcessPool`` (waking whoever waits for it; units
    cancelled instead would not wake a waiter on Python 3.11, a run that hung in a test).

    The pool's manager thread is then given up to ``join_s`` seconds to notice and close its
    wake-up pipe. Left running, it can close that pipe while the interpreter's exit hook
    writes to it (CPython 3.11 takes no lock there), which prints an ``OSError`` traceback
    after "error: interrupted"; CI caught it once in 757 tests."""
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False)
    if manager is not None:
        manager.join(timeout=join_s)
