"""What every ``estim`` command shares and that must load fast: the group that turns a
failure into one line and an exit code, and ``fail``."""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable, Iterable

import click

from estim.errors import ConfigError, Notice, UsageError

MAX_LINE = 400
"""Longest error line printed: a value quoted from the user's input is cut in the middle."""
MAX_LINES = 12
"""Most error lines printed for one failure (one per problem of a config)."""


def bounded(line: str) -> str:
    """``line`` cut to :data:`MAX_LINE` characters, keeping its start and its end."""
    if len(line) <= MAX_LINE:
        return line
    cut = len(line) - (MAX_LINE - 100)
    return f"{line[:MAX_LINE - 180]} ...[{cut} characters]... {line[-80:]}"


DEBUG_ENV = "ESTIM_DEBUG"
"""Set to 1 for what ``--debug`` does."""


def debug_option(f: Callable) -> Callable:
    """``--debug``: an unexpected error shows its traceback and writes it to a log."""
    return click.option("--debug", is_flag=True, envvar=DEBUG_ENV,
                        help="On an unexpected error (not a config or usage mistake), print "
                             "the traceback and write it to a log file "
                             f"(also: {DEBUG_ENV}=1).")(f)


def debug_log() -> str:
    """Where ``--debug`` writes the traceback: ``estim-debug.log`` in the temporary folder."""
    import tempfile

    return os.path.join(tempfile.gettempdir(), "estim-debug.log")


def report_unexpected(exc: BaseException, debug: bool) -> None:
    """One line naming the error; with ``debug`` its traceback too, also written to
    :func:`debug_log`."""
    first = (str(exc).strip().splitlines() or [""])[0]
    line = f"{type(exc).__name__}: {first}"
    if not debug:
        click.echo(f"error: {bounded(line)} (estim --debug shows the traceback)", err=True)
        return
    import traceback

    text = "".join(traceback.format_exception(exc))
    click.echo(text.rstrip(), err=True)
    try:
        with open(debug_log(), "w", encoding="utf-8") as log:
            log.write(f"estim {' '.join(sys.argv[1:])}\n{text}")
        where = f"; traceback written to {debug_log()}"
    except OSError:
        where = ""
    click.echo(f"error: {bounded(line)}{where}", err=True)


def fail(message: str) -> None:
    lines = str(message).splitlines() or [""]
    for line in lines[:MAX_LINES]:
        click.echo(f"error: {bounded(line)}", err=True)
    if len(lines) > MAX_LINES:
        click.echo(f"error: ... and {len(lines) - MAX_LINES} more problems", err=True)
    sys.exit(2)


class Group(click.Group):
    """Turns a failure inside a command into one line: exit 2 for a usage error, 3 for a run
    that failed after starting (1 means drift)."""

    def invoke(self, ctx):
        warnings.simplefilter("ignore", RuntimeWarning)     # errors are reported, one line
        shown = warnings.showwarning

        def notice(message, category, *args, **kwargs):
            if issubclass(category, Notice):
                click.echo(f"notice: {bounded(str(message))}", err=True)
            else:
                shown(message, category, *args, **kwargs)
        warnings.showwarning = notice
        try:
            return super().invoke(ctx)
        except (KeyboardInterrupt, click.Abort):
            from estim.util.interrupt import exit_status, interrupt_line

            click.echo(interrupt_line(), err=True)
            sys.exit(exit_status())
        except (click.exceptions.Exit, click.ClickException, SystemExit, BrokenPipeError):
            raise                   # a closed output pipe (estim table | head): exit 1, quiet
        except (UsageError, ConfigError) as exc:
            fail(str(exc))
        except OSError as exc:
            where = f" ({exc.filename})" if exc.filename else ""
            click.echo(f"error: {bounded(f'{exc.strerror or exc}{where}')}", err=True)
            sys.exit(3)
        except Exception as exc:  # noqa: BLE001 - last line of defence, reported
            from estim.util.interrupt import interrupted

            if interrupted():                       # e.g. a worker pool the Ctrl-C broke
                from estim.util.interrupt import exit_status, interrupt_line

                click.echo(interrupt_line(), err=True)
                sys.exit(exit_status())
            debug = bool(ctx.params.get("debug")) or os.environ.get(DEBUG_ENV, "") not in (
                "", "0")
            report_unexpected(exc, debug)
            sys.exit(3)


class LazyChoice(click.Choice):
    """A ``click.Choice`` whose choices are listed at first use (a command line naming the
    command, its help), not when the CLI module is imported: listing the table metrics
    imports every analysis, which the other commands do not need."""

    def __init__(self, choices: Callable[[], Iterable[str]], case_sensitive: bool = True):
        self._source = choices
        self._listed: tuple[str, ...] | None = None
        self.case_sensitive = case_sensitive

    @property
    def choices(self) -> tuple[str, ...]:  # type: ignore[override]
        if self._listed is None:
            self._listed = tuple(self._source())
        return self._listed


class DeferredChoice(LazyChoice):
    """A :class:`LazyChoice` that takes any value when the command line is parsed; the
    command calls :meth:`check` only when the value finds nothing, so a valid value never
    lists the choices (listing the table metrics imports every analysis)."""

    def convert(self, value, param, ctx):
        return value

    def check(self, value: str) -> None:
        """A click usage error, as a ``Choice`` gives, unless ``value`` is a choice."""
        ctx = click.get_current_context()
        param = next(p for p in ctx.command.params if p.type is self)
        click.Choice.convert(self, value, param, ctx)


class LazyEpilog(click.Command):
    """A command whose help epilog is made when its help is shown (``epilog_from``)."""

    def __init__(self, *args, epilog_from: Callable[[], str], **kwargs):
        super().__init__(*args, **kwargs)
        self._epilog_from = epilog_from

    def format_epilog(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        if self.epilog is None:
            self.epilog = self._epilog_from()
        super().format_epilog(ctx, formatter)
