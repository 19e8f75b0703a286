"""Whether this process has been interrupted: the SIGINT handler the console script installs
first (:mod:`estim.cli.launch`) records it here, where the commands ask (standard library
only, so the launcher can import it before anything else)."""

from __future__ import annotations

INTERRUPTED = [False]


def on_interrupt(signum, frame) -> None:
    INTERRUPTED[0] = True
    raise KeyboardInterrupt


def interrupted() -> bool:
    """Whether this process has received SIGINT."""
    return INTERRUPTED[0]
