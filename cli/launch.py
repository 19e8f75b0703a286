"""The console script ``estim``: Ctrl-C at any moment, even while Python is still importing
the commands, ends in one line and exit 130.

This module imports nothing but the standard library before it has installed its SIGINT
handler; the handler records the interrupt, so that an error it causes further down (a
worker pool broken by the same Ctrl-C) is still reported as an interruption.
"""

from __future__ import annotations

import signal
import sys

INTERRUPTED = [False]


def _on_interrupt(signum, frame) -> None:
    INTERRUPTED[0] = True
    raise KeyboardInterrupt


def interrupted() -> bool:
    """Whether this process has received SIGINT."""
    return INTERRUPTED[0]


def main() -> None:
    signal.signal(signal.SIGINT, _on_interrupt)
    try:
        from estim.cli.entry import main as commands

        commands()
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted\n")
        sys.exit(130)
