"""What the commands print besides their results: progress while work units finish, and the
summary after a run."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from pathlib import Path
from typing import TypeVar

import click

from estim.config.experiment import Experiment
from estim.config.registry import ANALYSES
from estim.engine import runner, scheduler
from estim.experiments.base import Result
from estim.util import lazy

T = TypeVar("T")


def progress_lines(name: str, total: int, prefix: str = "") -> Callable[[], None]:
    """Without a terminal (CI, cluster logs): one line per finished work unit with the
    elapsed time and an estimate of the time left."""
    start, done = time.perf_counter(), [0]

    def on_done() -> None:
        done[0] += 1
        elapsed = time.perf_counter() - start
        left = elapsed / done[0] * (total - done[0]) if done[0] < total else 0.0
        click.echo(f"{prefix}{name}: {min(done[0], total)}/{total} done, {elapsed:.0f} s "
                   f"elapsed, about {left:.0f} s left", err=True)
    return on_done


class Progress:
    """The progress of a run: nothing when quiet, a bar on a terminal, one line per finished
    work unit otherwise. :meth:`start` once the run's folder is open (a run refused before
    any work prints none of it), :meth:`done` per finished unit, :meth:`close` at the end."""

    def __init__(self, exp: Experiment, quiet: bool, bar: bool = True) -> None:
        self.exp, self.quiet, self.bar = exp, quiet, bar
        self._bar = None
        self._line: Callable[[], None] | None = None

    def start(self) -> None:
        if self.quiet:
            return
        total = runner.work_units(self.exp)
        if self.bar and sys.stderr.isatty():
            self._bar = click.progressbar(length=total, label=self.exp.name, file=sys.stderr)
            self._bar.__enter__()
        else:
            click.echo(f"{self.exp.name}: {total} work units ...", err=True)
            self._line = progress_lines(self.exp.name, total)

    def done(self) -> None:
        if self._bar is not None:
            self._bar.update(1)
        elif self._line is not None:
            self._line()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.__exit__(None, None, None)
            self._bar = None


def run_and_report(exp: Experiment, folder: Path, jobs: int, quiet: bool,
                   overrides: dict | None = None, executor=None, resume: bool = True,
                   figure_format: str = "png") -> None:
    """:func:`estim.engine.runner.run_to_folder` with progress, then where the results went and the
    analysis' summary (unless quiet)."""
    shown = Progress(exp, quiet)
    try:
        result, resumed = runner.run_to_folder(
            exp, folder, jobs, on_done=shown.done, executor=executor, resume=resume,
            figure_format=figure_format, command=_command(), overrides=overrides,
            on_start=shown.start)
    finally:
        shown.close()
    report(exp, folder, result, resumed, quiet)


def _command() -> str:
    return " ".join(["estim", *sys.argv[1:]])


def report(exp: Experiment, folder: Path, result: Result, resumed: int, quiet: bool) -> None:
    """Where a run's results went and its analysis' summary (nothing when quiet)."""
    if quiet:
        return
    if resumed:
        click.echo(f"{exp.name}: resumed with {resumed} finished cell(s) of an earlier run",
                   err=True)
    click.echo(f"{exp.name} -> {folder / exp.name}")
    text = runner.printout(exp, result)
    if text:
        click.echo(text)


def longest_first(exps: list[Experiment], recorded: Path) -> list[Experiment]:
    """``exps`` by the wall time each one's manifest in ``recorded`` records, longest first
    (one without a manifest first of all)."""
    return sorted(exps, key=lambda e: -runner.recorded_seconds(recorded / e.name))


def runs_alone(exp: Experiment) -> bool:
    return bool(getattr(ANALYSES[exp.analysis], "RUNS_ALONE", False))


def on_shared_pool(exps: list[Experiment], jobs: int, recorded: Path,
                   work: Callable[[Experiment, Executor], T]) -> Iterator[tuple[Experiment, T]]:
    """``work(exp, pool)`` for every config of ``exps``, up to ``jobs`` at once, their work
    units on one pool of ``jobs`` processes (:mod:`estim.engine.scheduler`), longest first by the
    manifests in ``recorded``; yields ``(exp, value)`` as each finishes. Every lazily
    registered module is imported first (:func:`estim.util.lazy.import_all_now`)."""
    lazy.import_all_now()
    with scheduler.process_pool(jobs) as pool:
        yield from scheduler.run_each(longest_first(exps, recorded),
                                      lambda exp: work(exp, pool), jobs, alone=runs_alone,
                                      on_error=lambda: scheduler.stop(pool))


def run_together(exps: list[Experiment], folder: Path, jobs: int, quiet: bool,
                 recorded: Path, overrides: dict | None = None, resume: bool = True,
                 figure_format: str = "png") -> None:
    """Every config of ``exps`` run :func:`on_shared_pool`; each one's summary is printed as
    it finishes, its progress one line per finished work unit."""
    def work(exp: Experiment, pool: Executor) -> tuple[Result, int]:
        shown = Progress(exp, quiet, bar=False)
        return runner.run_to_folder(exp, folder, jobs, on_done=shown.done, resume=resume,
                                    figure_format=figure_format, command=_command(),
                                    overrides=overrides, on_start=shown.start, pool=pool)

    for exp, (result, resumed) in on_shared_pool(exps, jobs, recorded, work):
        report(exp, folder, result, resumed, quiet)
