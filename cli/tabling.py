"""``estim table``: stored tables printed from plain CSV reading (no pandas), loading only
the analyses of the experiments it prints."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import click

from estim.cli import arguments, project
from estim.cli.group import DeferredChoice, LazyEpilog, fail
from estim.config.registry import ANALYSES
from estim.errors import UsageError
from estim.report import tables


def _metrics() -> list[str]:
    from estim.engine import runner

    return sorted(runner.table_specs())


METRICS = DeferredChoice(_metrics)
"""The table metrics of the registered analyses, listed only for help, completion and an
unknown metric."""


@click.command(cls=LazyEpilog, epilog_from=arguments.metrics_help)
@click.argument("metric", type=METRICS)
@click.argument("experiments", nargs=-1)
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              help="Folder of stored results [default: the project's results/].")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "markdown", "latex"]),
              default="text", show_default=True)
@click.option("--thesis", "--paper", "--reference", "thesis", is_flag=True,
              help="Show the printed value (thesis or paper) and ours/printed beside ours; "
                   "experiments with no printed table are left out, named in one line.")
@click.option("--partial", is_flag=True,
              help="With --thesis: allow thesis rows that the results do not cover.")
@click.option("--width", type=click.IntRange(min=0), default=None,
              help="Text: fit each table to this many characters [default: the terminal's "
                   "width, 100 when not a terminal; 0: every column, wrapped].")
def table(metric, experiments, results, fmt, thesis, partial, width) -> None:
    """Print the METRIC tables of the EXPERIMENTS named (result folder names, e.g.
    mosfet_saturation), or of every experiment found under RESULTS.

    csv gives one CSV over all experiments (an "experiment" column first); markdown and
    latex (booktabs, escaped) one table per experiment under its name. text fits each table
    to the width: a column with one value in every row is said once above it, then come the
    keys, the printed value beside ours with the ratio, and as many other columns as fit; a
    note names the ones left out. RESULTS' experiment folders are its direct subfolders.
    """
    if partial and not thesis:
        fail("--partial applies only with --thesis")
    results = results or project.locate().results
    if width is None:
        width = (shutil.get_terminal_size((tables.TEXT_WIDTH, 24)).columns
                 if sys.stdout.isatty() else tables.TEXT_WIDTH)
    try:
        text_ = tables.stored(results, metric, fmt, thesis, partial, ANALYSES,
                              only=tuple(experiments), width=width)
    except UsageError:
        METRICS.check(metric)            # an unknown metric is told as such, not as missing
        raise
    click.echo(text_, nl=not text_.endswith("\n"))
