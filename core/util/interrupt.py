"""Whether this process has been interrupted: the SIGINT and SIGTERM handler the console
script installs first (:mod:`estim.cli.launch`) records it here, where the commands and the
work-unit engine ask (standard library only, so the launcher can import it before anything
else). Both signals unwind the command as Ctrl-C does, so what it started (a worker pool, an
ngspice run, a result folder being written) is stopped or left whole on the way out.

The handler's ``KeyboardInterrupt`` can be lost: Python clears an error raised while its
import statement reads a lazily loaded module's ``__spec__`` (CPython 3.11's
``_PyModuleSpec_IsInitializing``), so a Ctrl-C that lands while such a module loads is
recorded here and raised nowhere. The places a run waits call :func:`raise_if_interrupted`
and raise it there (before they did, a shared ``estim reproduce`` interrupted while it
imported its analyses went on to its end)."""

from __future__ import annotations

import signal

INTERRUPTED = [False]
SIGNAL = [signal.SIGINT]
"""The signal that interrupted this process (its exit status is 128 plus its number)."""


ARMED = [False]
"""Whether the launcher's ``try`` that turns an interrupt into its one line has begun."""


def on_interrupt(signum, frame) -> None:
    """Record the signal; once :func:`arm` has run, unwind the command as Ctrl-C does (an
    interrupt before that is raised by :func:`arm`, inside the launcher's ``try``)."""
    INTERRUPTED[0] = True
    SIGNAL[0] = signum
    if ARMED[0]:
        raise KeyboardInterrupt


def arm() -> None:
    """From here on an interrupt unwinds the command; one that came before is raised now."""
    ARMED[0] = True
    if INTERRUPTED[0]:
        raise KeyboardInterrupt


def interrupted() -> bool:
    """Whether this process has received SIGINT or SIGTERM."""
    return INTERRUPTED[0]


def raise_if_interrupted() -> None:
    """Raise the ``KeyboardInterrupt`` of an interrupt this process has received since the
    launcher armed its handler (nothing when estim is used as a library, where no handler
    of estim's is installed)."""
    if INTERRUPTED[0] and ARMED[0]:
        raise KeyboardInterrupt


def exit_status() -> int:
    """The exit status of an interrupted run: 130 for SIGINT, 143 for SIGTERM."""
    return 128 + int(SIGNAL[0])


def interrupt_line() -> str:
    """The one line an interrupted run ends with."""
    return "error: interrupted" if exit_status() == 130 else "error: terminated"
