"""Worker processes that leave Ctrl-C to their parent, and a pool stopped at once."""

from __future__ import annotations

import signal
from concurrent.futures import Executor


def ignore_interrupts() -> None:
    """Workers leave Ctrl-C to the parent, which stops them and reports once."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def stop(pool: Executor) -> None:
    """Stop ``pool`` now: its workers are terminated, which breaks the pool, and every unit
    it has not finished fails with ``BrokenProcessPool`` (waking whoever waits for it; units
    cancelled instead would not wake a waiter on Python 3.11, a run that hung in a test)."""
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()
    pool.shutdown(wait=False)
