"""The console script ``estim``: Ctrl-C at any moment, even while Python is still importing
the commands, ends in one line and exit 130.

This module imports nothing but the standard library before it has installed its SIGINT
handler; the handler records the interrupt, so that an error it causes further down (a
worker pool broken by the same Ctrl-C) is still reported as an interruption.
"""

from __future__ import annotations

import os
import signal
import sys

from estim.cli.interrupt import interrupted, on_interrupt


def main() -> None:
    """Run the commands with click's standalone mode off: click's own handling would turn a
    Ctrl-C that lands in its argument parsing, before any command runs, into "Aborted!" and
    exit 1; here every interrupt is exit 130, and click's other outcomes are mapped as
    standalone mode maps them (its usage errors exit 2, a closed output pipe exits 1)."""
    signal.signal(signal.SIGINT, on_interrupt)
    for name in ("stdout", "stderr"):       # a closed stream, or one that cannot spell a name
        stream = getattr(sys, name)
        if stream is None:
            setattr(sys, name, open(os.devnull, "w"))       # noqa: SIM115 - lives as long as sys
        elif hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="replace")
    try:
        import click

        from estim.cli.entry import main as commands

        try:
            code = commands(standalone_mode=False)
        except click.Abort:
            if not interrupted():
                sys.stderr.write("error: aborted\n")
                sys.exit(1)
            raise KeyboardInterrupt from None
        except click.ClickException as exc:
            exc.show()
            sys.exit(exc.exit_code)
        except BrokenPipeError:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            sys.exit(1)
        if interrupted():       # an interrupt some library's bare except swallowed
            raise KeyboardInterrupt
        sys.exit(code if isinstance(code, int) else 0)
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted\n")
        sys.exit(130)
