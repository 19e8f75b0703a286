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


def kernels_cached() -> bool:
    """Whether numba has compiled estim's kernels before (an index file ``*.nbi`` in the
    package's ``__pycache__`` folders, or under ``NUMBA_CACHE_DIR`` when it is set)."""
    import os

    import estim

    where = os.environ.get("NUMBA_CACHE_DIR") or os.path.dirname(estim.__file__)
    return any(Path(where).rglob("*.nbi"))


COMPILING = ("first run: numba compiles estim's kernels as they are first used (about a "
             "minute of CPU time on 2 cores, cached for later runs)")
"""What a run says when no compiled kernel is cached yet (a fresh install)."""


def say_if_compiling(quiet: bool) -> None:
    """:data:`COMPILING` on standard error when no kernel is cached yet; called before the
    configs are loaded (building a config's models may compile some)."""
    if not quiet and not kernels_cached():
        click.echo(COMPILING, err=True)


def tune_progress(start: float, every: float = 5.0) -> Callable[[int, float], None]:
    """``estim tune``'s progress: one line on standard error at most every ``every`` seconds
    with the likelihood evaluations so far and the best log-likelihood (a fit takes minutes,
    each evaluation a run of the filter over every training draw)."""
    last = [start]

    def report(evaluations: int, best: float) -> None:
        now = time.perf_counter()
        if now - last[0] >= every:
            last[0] = now
            click.echo(f"tune: {evaluations} likelihood evaluations, best log-likelihood "
                       f"{best:.6g}, {now - start:.0f} s", err=True)
    return report


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

    def __init__(self, exp: Experiment, quiet: bool) -> None:
        self.exp, self.quiet = exp, quiet
        self._bar = None
        self._line: Callable[[], None] | None = None

    def start(self) -> None:
        if self.quiet:
            return
        total = runner.work_units(self.exp)
        if sys.stderr.isatty():
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
    registered module is imported first (:func:`estim.util.lazy.import_all_now`), and the
    matplotlib modules the figures import inside their functions: two driver threads
    importing matplotlib.ticker at once could see it half-imported (``ImportError: cannot
    import name 'NullFormatter' from partially initialized module``, measured on a cold
    numba cache by bench/bench_first_run.py)."""
    lazy.import_all_now()
    import matplotlib.colors
    import matplotlib.figure
    import matplotlib.ticker  # noqa: F401
    with scheduler.process_pool(jobs) as pool:
        yield from scheduler.run_each(longest_first(exps, recorded),
                                      lambda exp: work(exp, pool), jobs, alone=runs_alone,
                                      on_error=lambda: scheduler.stop(pool))


def markdown(text: str, terminal: bool | None = None) -> None:
    """Print Markdown: rendered by rich on a terminal (bold, bullets, ruled tables), as it is
    when piped or redirected, so that ``estim summary > file.md`` is still Markdown.
    ``terminal`` overrides the check of standard output (None: ask it)."""
    import os

    if terminal is None:
        terminal = sys.stdout.isatty() and os.environ.get("TERM") != "dumb"
    if not terminal:
        click.echo(text, nl=not text.endswith("\n"))
        return
    from rich.console import Console
    from rich.markdown import Markdown

    Console(file=sys.stdout, force_terminal=True).print(Markdown(text))


def _duration(seconds: float) -> str:
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    minutes, rest = divmod(round(seconds), 60)
    return f"{minutes} min {rest} s" if minutes < 60 else f"{minutes // 60} h {minutes % 60} min"


class Overall:
    """The progress of several configs run together: one bar over all of them on a terminal
    (rich), else a line per finished config and at most one every :attr:`EVERY` seconds in
    between; then a closing summary. The time left is estimated from the wall time each
    config's stored manifest records (a work unit weighs its config's time over its units),
    not from counts of units whose cost differs a thousandfold between configs."""

    EVERY = 30.0
    """Seconds between progress lines without a terminal."""

    def __init__(self, exps: list[Experiment], recorded: Path, quiet: bool, verb: str) -> None:
        self.quiet, self.verb, self.count = quiet, verb, len(exps)
        self.units = {e.name: max(1, runner.work_units(e)) for e in exps}
        known = [runner.recorded_seconds(recorded / e.name) for e in exps]
        finite = sorted(t for t in known if t != float("inf"))
        guess = finite[len(finite) // 2] if finite else 10.0
        self.seconds = {e.name: (t if t != float("inf") else guess) or 0.1
                        for e, t in zip(exps, known, strict=True)}
        self.total = sum(self.seconds.values())
        self.done_weight, self.finished = 0.0, 0
        self.counts = {v: 0 for v in ("holds", "fails", "undecided")}
        self.start_time = time.perf_counter()
        self._last_line = self.start_time
        self._bar = None

    def start(self) -> None:
        if self.quiet:
            return
        click.echo(f"{self.verb}: {self.count} configs, {sum(self.units.values())} work "
                   "units ...", err=True)
        if sys.stderr.isatty():
            from rich.progress import (
                BarColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._bar = Progress(
                TextColumn("{task.description}"), BarColumn(),
                TextColumn("{task.percentage:>3.0f}% of the work ["), TimeElapsedColumn(),
                TextColumn("elapsed,"), TimeRemainingColumn(), TextColumn("left]"),
                transient=True, redirect_stdout=sys.stdout.isatty(), redirect_stderr=True)
            self._task = self._bar.add_task(self.verb, total=self.total)
            self._bar.start()

    def _left(self) -> str:
        elapsed = time.perf_counter() - self.start_time
        if self.done_weight <= 0:
            return "time left unknown yet"
        left = elapsed * (self.total - self.done_weight) / self.done_weight
        return f"about {_duration(left)} left"

    def unit_done(self, exp: Experiment) -> None:
        weight = self.seconds[exp.name] / self.units[exp.name]
        self.done_weight = min(self.total, self.done_weight + weight)
        if self.quiet:
            return
        if self._bar is not None:
            self._bar.update(self._task, advance=weight)
            return
        now = time.perf_counter()
        if now - self._last_line >= self.EVERY:
            self._last_line = now
            click.echo(f"{self.verb}: {100 * self.done_weight / self.total:.0f} % of the work, "
                       f"{_duration(now - self.start_time)} elapsed, {self._left()}", err=True)

    def config_done(self, exp: Experiment, folder: Path, result: Result, resumed: int,
                    seconds: float) -> None:
        """One line per finished config: where it went, its time and its claims."""
        self.finished += 1
        table = result.tables.get("claims")
        said = ""
        if table is not None and "verdict_family" in table:
            found = table["verdict_family"].astype(str).value_counts()
            part = {v: int(found.get(v, 0)) for v in self.counts}
            for v, n in part.items():
                self.counts[v] += n
            said = (f"; claims holds {part['holds']}, fails {part['fails']}, undecided "
                    f"{part['undecided']}")
        if self.quiet:
            return
        if resumed:
            self._say(f"{exp.name}: resumed with {resumed} finished cell(s) of an earlier run")
        line = (f"{exp.name} -> {folder / exp.name} ({_duration(seconds)}{said}) "
                f"[{self.finished}/{self.count}]")
        click.echo(line)

    def echo(self, text: str) -> None:
        """A result line on standard output (above the bar when both are one terminal: the
        bar redirects what is printed there)."""
        click.echo(text)

    def _say(self, text: str) -> None:
        click.echo(text, err=True)

    def close(self, finished: bool = True) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None
        if self.quiet or not finished:
            return
        c = self.counts
        click.echo(f"{self.verb}: {self.finished} configs in "
                   f"{_duration(time.perf_counter() - self.start_time)}; claims (after Holm's "
                   f"correction) holds {c['holds']}, fails {c['fails']}, undecided "
                   f"{c['undecided']}.\nNext: 'estim summary' (the verdicts by claim), "
                   "'estim table METRIC EXPERIMENT --thesis' (a table beside the printed one), "
                   "'estim report' (one page, report.html).")


def run_together(exps: list[Experiment], folder: Path, jobs: int, quiet: bool,
                 recorded: Path, overrides: dict | None = None, resume: bool = True,
                 figure_format: str = "png", verb: str = "run") -> None:
    """Every config of ``exps`` run :func:`on_shared_pool`: one overall progress
    (:class:`Overall`), one line per finished config (no tables: ``estim table`` prints
    them) and a closing summary."""
    overall = Overall(exps, recorded, quiet, verb)
    began: dict[str, float] = {}

    def work(exp: Experiment, pool: Executor) -> tuple[Result, int]:
        def on_start() -> None:
            began[exp.name] = time.perf_counter()

        return runner.run_to_folder(exp, folder, jobs, on_done=lambda: overall.unit_done(exp),
                                    resume=resume, figure_format=figure_format,
                                    command=_command(), overrides=overrides,
                                    on_start=on_start, pool=pool)

    overall.start()
    finished = False
    try:
        for exp, (result, resumed) in on_shared_pool(exps, jobs, recorded, work):
            overall.config_done(exp, folder, result, resumed,
                                time.perf_counter() - began.get(exp.name, overall.start_time))
        finished = True
    finally:
        overall.close(finished)
