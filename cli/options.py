"""Options and argument types the commands share."""

from __future__ import annotations

import os

import click

from estim.config.loading import MAX_WORK


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity), the default of ``--jobs``."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                              # no affinity on this platform
        return os.cpu_count() or 1


class NamedPath(click.Path):
    """A path that must be named: ``--out ''`` is refused (as a path it would mean the
    current folder, which the user did not name)."""

    def convert(self, value, param, ctx):
        if isinstance(value, str) and not value.strip():
            self.fail("expected a path, got an empty string", param, ctx)
        return super().convert(value, param, ctx)


jobs_option = click.option("--jobs", type=click.IntRange(1, 256), default=usable_cores,
                     show_default="the usable cores",
                     help="Worker processes over work units (for one config never more than "
                          "its work units; reproduce, check and a run of several configs on "
                          "this machine share one pool of them, the longest config first).")


max_work_option = click.option("--max-work", type=click.IntRange(1), default=MAX_WORK,
                         show_default=True,
                         help="Refuse a config whose work (state-samples) exceeds this.")
