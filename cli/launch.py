"""The console script ``estim``: Ctrl-C at any moment, even while Python is still importing
the commands, ends in one line and exit 130 (SIGTERM: exit 143).

This module imports nothing but the standard library before it has installed its SIGINT
handler; the handler records the interrupt, so that an error it causes further down (a
worker pool broken by the same Ctrl-C) is still reported as an interruption.
"""

from __future__ import annotations

import os
import signal
import sys

from estim.util.interrupt import arm, exit_status, interrupt_line, interrupted, on_interrupt


def _quiet_hooks() -> None:
    """Errors outside the command's own thread in one line, or none: a Ctrl-C that lands in
    the interpreter's exit (joining a worker pool's thread) or an ``OSError`` of a
    background thread on a full disk (which the command itself meets and reports) would
    otherwise print a traceback after the command's one line. ``ESTIM_DEBUG=1`` keeps
    Python's own hooks."""
    import threading

    if os.environ.get("ESTIM_DEBUG", "") not in ("", "0"):
        return

    def unraisable(info) -> None:
        if isinstance(info.exc_value, KeyboardInterrupt):
            return                      # the interrupt's own line is written, or will be
        sys.stderr.write(f"error: {type(info.exc_value).__name__}: "
                         f"{str(info.exc_value)[:200]} (ignored while exiting)\n")

    def in_thread(args) -> None:
        if isinstance(args.exc_value, (KeyboardInterrupt, OSError)):
            return                      # the command reports the same interrupt or disk
        sys.stderr.write(f"error: {args.exc_type.__name__}: {str(args.exc_value)[:200]} "
                         "(in a background thread; estim --debug shows the traceback)\n")

    sys.unraisablehook = unraisable
    threading.excepthook = in_thread


def _late_interrupt(signum, frame) -> None:
    """A Ctrl-C or SIGTERM after the command has returned (while the interpreter exits):
    its one line and exit status, at once."""
    try:
        sys.stdout.flush()
    except Exception:  # noqa: BLE001, S110 - a closed pipe: nothing left to flush
        pass
    os.write(2, b"error: interrupted\n" if signum == signal.SIGINT else b"error: terminated\n")
    os._exit(128 + int(signum))


def main() -> None:
    """Run the commands with click's standalone mode off: click's own handling would turn a
    Ctrl-C that lands in its argument parsing, before any command runs, into "Aborted!" and
    exit 1; here every interrupt is exit 130, and click's other outcomes are mapped as
    standalone mode maps them (its usage errors exit 2, a closed output pipe exits 1)."""
    signal.signal(signal.SIGINT, on_interrupt)
    signal.signal(signal.SIGTERM, on_interrupt)
    try:
        _run_commands()
    finally:
        signal.signal(signal.SIGINT, _late_interrupt)
        signal.signal(signal.SIGTERM, _late_interrupt)


def _run_commands() -> None:
    """The commands, with every outcome mapped to its one line and exit status."""
    for name in ("stdout", "stderr"):       # a closed stream, or one that cannot spell a name
        stream = getattr(sys, name)
        if stream is None:
            setattr(sys, name, open(os.devnull, "w"))       # noqa: SIM115 - lives as long as sys
        elif hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="replace")
    _quiet_hooks()
    try:
        arm()                   # an interrupt since the handler was installed lands here
        import click

        from estim.cli.entry import main as commands

        try:
            code = commands(standalone_mode=False)
        except click.Abort:
            if not interrupted():
                sys.stderr.write("error: aborted\n")
                sys.exit(1)
            raise KeyboardInterrupt from None
        except click.UsageError as exc:          # one line, as every other error
            path = " ".join(["estim", *(exc.ctx.command_path.split()[1:] if exc.ctx
                                        is not None else [])])    # however Python was started
            sys.stderr.write(f"error: {exc.format_message()} (see '{path} --help')\n")
            sys.exit(exc.exit_code)
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
        sys.stderr.write(interrupt_line() + "\n")
        sys.exit(exit_status())
