"""What every ``estim`` command shares and that must load fast: the group that turns a
failure into one line and an exit code, and ``fail``."""

from __future__ import annotations

import sys
import warnings

import click

from estim.errors import ConfigError, UsageError


def fail(message: str) -> None:
    for line in str(message).splitlines() or [""]:
        click.echo(f"error: {line}", err=True)
    sys.exit(2)


class Group(click.Group):
    """Turns a failure inside a command into one line: exit 2 for a usage error, 3 for a run
    that failed after starting (1 means drift)."""

    def invoke(self, ctx):
        warnings.simplefilter("ignore", RuntimeWarning)     # errors are reported, one line
        try:
            return super().invoke(ctx)
        except (KeyboardInterrupt, click.Abort):
            click.echo("error: interrupted", err=True)
            sys.exit(130)
        except (click.exceptions.Exit, click.ClickException, SystemExit):
            raise
        except (UsageError, ConfigError) as exc:
            fail(str(exc))
        except OSError as exc:
            where = f" ({exc.filename})" if exc.filename else ""
            click.echo(f"error: {exc.strerror or exc}{where}", err=True)
            sys.exit(3)
        except Exception as exc:  # noqa: BLE001 - last line of defence, reported
            first = (str(exc).strip().splitlines() or [""])[0]
            click.echo(f"error: {type(exc).__name__}: {first}", err=True)
            sys.exit(3)
