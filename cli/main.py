"""``estim``: the commands, and nothing else (the library does the work: :mod:`estim`).

Exit codes: 0 ok, 1 a check found differences, 2 a usage or config error, 3 a run failed,
130 interrupted, 143 terminated.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import click

import estim
from estim import store
from estim.cli import arguments, listing, project, results, tabling, validating
from estim.cli.group import Group, debug_option, fail
from estim.cli.options import NamedPath, jobs_option, max_work_option
from estim.cli.output import (
    Overall,
    on_shared_pool,
    run_and_report,
    run_together,
    say_if_compiling,
    tune_progress,
)
from estim.config import loading as config
from estim.config.registry import ANALYSES
from estim.engine import check as checking
from estim.engine import runner
from estim.engine.executors import executor as executor_for
from estim.errors import UsageError
from estim.experiments.shared import tuning


@click.group(cls=Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(estim.__version__, "-V", "--version", prog_name="estim")
@debug_option
def main(debug: bool) -> None:
    """Reproduce the result tables of Bansal (2019), state estimation in ODE/PDE models.

    Exit codes: 0 ok, 1 check found differences, 2 usage or config error, 3 a run failed,
    130 interrupted, 143 terminated.
    """


@main.command()
@click.argument("configs", nargs=-1, required=True)
@click.option("--out", type=NamedPath(file_okay=False, path_type=Path),
              help="Folder for results [default: the project's results/ for a config of "
                   "configs/ run as it is, else its scratch/].")
@click.option("--runs", type=click.IntRange(1), help="Override monte_carlo.runs.")
@click.option("--seed", type=click.IntRange(0), help="Override monte_carlo.seed.")
@click.option("--update-baseline", is_flag=True,
              help="Allow an overridden run to write into the stored results/.")
@click.option("--quick", is_flag=True,
              help="A first look in seconds: each analysis' quick profile (the first cell of "
                   "a sweep, mostly one point or row of it, short records, one to five "
                   "runs); never written into results/.")
@jobs_option
@max_work_option
@click.option("--executor", type=click.Choice(["local", "dask"]), default="local",
              show_default=True, help="Where work units run: this machine (--jobs processes) "
                                      "or a Dask cluster (pip install 'estim[dask]').")
@click.option("--scheduler", metavar="ADDRESS",
              help="With --executor dask: the scheduler (tcp://host:8786) [default: a local "
                   "cluster of --jobs workers].")
@click.option("--no-resume", is_flag=True,
              help="Recompute every cell, even those an interrupted run left.")
@click.option("--figure-format", type=click.Choice(["png", "pdf", "svg"]), default="png",
              show_default=True, help="Figures as PNG, or as vector PDF/SVG for a paper.")
@click.option("--shard", metavar="K/N",
              help="Compute only work units K, K+N, ... (1 <= K <= N) and keep them for "
                   "'estim merge' (array jobs without a scheduler).")
@click.option("--quiet", is_flag=True, help="No progress and no summary.")
def run(configs, out, runs, seed, update_baseline, quick, jobs, max_work, executor, scheduler,
        no_resume, figure_format, shard, quiet) -> None:
    """Run the experiment(s) of CONFIGS and write OUT/NAME/ for each config NAME.

    A folder holds its tables (CSV; claims.csv judges the claims), manifest.json (what the
    tables depend on), run.json (command, commit, wall time, host; git ignores it) and,
    where the config draws any, figures/ (machine/, git-ignored, holds what measures the
    machine).

    CONFIGS may mix config files and overrides KEY.PATH=VALUE (the value is YAML; list
    items by index), applied to every config before it is validated, e.g.
    "estim run configs/mosfet_saturation.yaml simulation.rtol=1e-6 monte_carlo.runs=5".
    An overridden run writes into scratch/ and its manifest records the overrides.
    Every setting a config may give: "estim settings".
    """
    paths, given = arguments.split_arguments(configs)
    if not paths:
        fail("no config file given")
    overrides = arguments.overrides(given, runs, seed)
    if quick and update_baseline:
        fail("--quick never writes the baseline: drop --update-baseline")
    if scheduler and executor != "dask":
        fail("--scheduler needs --executor dask")
    say_if_compiling(quiet)
    exps = config.load_files(paths, overrides, max_work, quick)
    folder, note = project.locate().output_folder(out, [e.source for e in exps],
                                                  bool(overrides), update_baseline, quick)
    if note and not quiet:
        click.echo(note, err=True)
    store.ensure_writable(folder)
    if shard is not None:
        k, n = arguments.shard(shard)
        store.ensure_free(folder)                   # the cells are written as they finish
        for exp in exps:
            computed, splits = runner.run_shard(exp, folder, k, n, jobs)
            if not splits:
                click.echo(f"{exp.name}: the {exp.analysis} analysis does not split into "
                           "work units, so no shard keeps any of it; 'estim merge' runs it "
                           "whole")
            else:
                click.echo(f"{exp.name}: shard {k}/{n}: {computed} cell(s) in "
                           f"{runner.cell_store(exp, folder).folder}; finish with 'estim merge'")
        return
    if executor == "local" and jobs > 1 and len(exps) > 1:
        run_together(exps, folder, jobs, quiet, folder, overrides, resume=not no_resume,
                     figure_format=figure_format, verb="run")
        return
    with executor_for(executor, scheduler, jobs) as units:
        for exp in exps:
            run_and_report(exp, folder, jobs, quiet, overrides, executor=units,
                           resume=not no_resume, figure_format=figure_format)


@main.command()
@click.argument("configs", nargs=-1, required=True)
@click.option("--from", "sources", multiple=True, required=True,
              type=click.Path(file_okay=False, exists=True, path_type=Path),
              help="A folder the shards wrote into (repeat for several).")
@click.option("--out", type=NamedPath(file_okay=False, path_type=Path),
              help="Folder for results [default: as for run].")
@click.option("--runs", type=click.IntRange(1), help="As given to the shards' run.")
@click.option("--seed", type=click.IntRange(0), help="As given to the shards' run.")
@click.option("--quick", is_flag=True, help="As given to the shards' run.")
@jobs_option
@max_work_option
@click.option("--quiet", is_flag=True)
def merge(configs, sources, out, runs, seed, quick, jobs, max_work, quiet) -> None:
    """Gather the cells of 'estim run --shard K/N' runs from the --from folders and write
    the tables, computing any cell no shard made. CONFIGS, overrides, --runs and --seed as
    given to run: the cells are found by the config they were computed for."""
    paths, given = arguments.split_arguments(configs)
    if not paths:
        fail("no config file given (merge takes the config the shards ran)")
    overrides = arguments.overrides(given, runs, seed)
    say_if_compiling(quiet)
    exps = config.load_files(paths, overrides, max_work, quick)
    folder, note = project.locate().output_folder(out, [e.source for e in exps],
                                                  bool(overrides), False, quick,
                                                  can_update=False)
    if note and not quiet:
        click.echo(note, err=True)
    store.ensure_writable(folder)
    for exp in exps:
        found, refused = runner.gather_cells(exp, folder, list(sources))
        if refused:
            click.echo(f"{exp.name}: refused {len(refused)} file(s) of the shards' cell folders, "
                       f"never loaded: {'; '.join(refused[:5])}"
                       + (f"; and {len(refused) - 5} more" if len(refused) > 5 else ""), err=True)
        if not found:
            click.echo(f"{exp.name}: no cells of this config in the --from folder(s) (an analysis "
                       "that does not split, or shards run with another config, overrides, "
                       "--runs, --seed, --quick or estim version); computing it whole", err=True)
        elif not quiet:
            click.echo(f"{exp.name}: {found} cell(s) from {len(sources)} folder(s)", err=True)
        run_and_report(exp, folder, jobs, quiet, overrides)


@main.command()
@click.option("--out", type=NamedPath(file_okay=False, path_type=Path),
              help="Folder for results [default: the project's results/].")
@jobs_option
@max_work_option
@click.option("--all", "everything", is_flag=True,
              help="Also configs/studies/ (Chapter 5's field filter against grid, sensors "
                   "and members) and configs/netlist/ (circuits from SPICE netlists).")
@click.option("--quiet", is_flag=True)
def reproduce(out, jobs, max_work, everything, quiet) -> None:
    """Run every config of configs/ (the thesis tables on the default settings)."""
    where = project.locate()
    folder = out or where.results
    if not quiet:
        click.echo(where.describe(folder), err=True)
    say_if_compiling(quiet)
    exps = config.load_files(where.configs(everything), max_work=max_work)
    store.ensure_writable(folder)
    if jobs > 1 and len(exps) > 1:
        run_together(exps, folder, jobs, quiet, where.results, verb="reproduce")
        return
    for exp in exps:
        run_and_report(exp, folder, jobs, quiet)


@main.command()
@click.argument("configs", nargs=-1)
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              help="Folder of stored results [default: the project's results/].")
@jobs_option
@max_work_option
@click.option("--all", "everything", is_flag=True,
              help="Also configs/studies/ and configs/netlist/ when no CONFIGS are named.")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON object at the end: per config its differences and the "
                   "lines the text would print (the exit code is the same).")
def check(configs, results, jobs, max_work, everything, as_json) -> None:
    """Re-run CONFIGS (default: configs/*.yaml) as they are and compare every cell with the
    stored tables under each config's tolerances; the stored manifest must record the same
    config (runs, seed and every other value).

    Overrides KEY.PATH=VALUE among CONFIGS re-run the configs changed so (a solver, a
    tolerance) and compare their tables with the stored ones under the same tolerances; the
    stored config is then not required to match.
    """
    where = project.locate()
    paths, overrides = arguments.split_arguments(configs)
    exps = config.load_files(paths or where.configs(everything), overrides, max_work=max_work)
    if overrides and not as_json:
        click.echo("check: with overrides " + ", ".join(f"{k}={v!r}" for k, v in
                                                       overrides.items())
                   + ": comparing tables only, not the stored config")
    results = results or where.results
    differing = 0
    report: list[dict] = []
    overall = Overall(exps, results, as_json, "check")
    overall.start()
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as tmp:
        def one(exp, say, pool=None) -> int:
            return checking.check(exp, results / exp.name, Path(tmp), jobs, say,
                                  same_config=not overrides,
                                  on_done=lambda: overall.unit_done(exp),
                                  note=lambda text_: click.echo(text_, err=True), pool=pool)

        if jobs > 1 and len(exps) > 1:
            def said_of(exp, pool) -> tuple[int, list[str]]:
                said: list[str] = []                # printed whole once the config is done
                return one(exp, said.append, pool), said

            try:
                for exp, (found, said) in on_shared_pool(exps, jobs, results, said_of):
                    for line in [] if as_json else said:
                        overall.echo(line)
                    report.append({"config": exp.name, "differences": found, "lines": said})
                    differing += found
            finally:
                overall.close(finished=False)
        else:
            try:
                for exp in exps:
                    said = []

                    def say(line: str, said: list = said) -> None:
                        said.append(line)
                        if not as_json:
                            overall.echo(line)

                    found = one(exp, say)
                    report.append({"config": exp.name, "differences": found, "lines": said})
                    differing += found
            finally:
                overall.close(finished=False)
    if as_json:
        import json

        click.echo(json.dumps({"differences": differing, "overrides": overrides,
                               "configs": report}, indent=1, default=str))
        sys.exit(1 if differing else 0)
    if differing:
        click.echo(f"check: {differing} difference(s)")
        sys.exit(1)
    click.echo("check: all tables match")


@main.command()
@click.argument("config", type=click.Path(path_type=Path))
@click.option("--estimator", "label", required=True, help="Label of the filter to fit.")
@click.option("--as", "new_label", help="Label of the fitted entry [default: LABEL (fitted Q)].")
@click.option("--runs", type=click.IntRange(2, 10_000), default=10, show_default=True,
              help="Training runs per sweep point (drawn apart from the table's runs).")
@click.option("--fit-r", is_flag=True, help="Fit R too (reported as not identifiable when "
                                           "the data cannot tell Q from R).")
@click.option("--out", type=NamedPath(dir_okay=False, path_type=Path),
              help="Overlay file [default: fitted/NAME.yaml beside the config NAME].")
@max_work_option
def tune(config, label, new_label, runs, fit_r, out, max_work) -> None:
    """Fit the Q (and R) of one estimator of CONFIG by maximum likelihood and write the
    fitted estimator entry to a YAML overlay."""
    exp = estim.config.loading.load_files([config], max_work=max_work)[0]
    analysis = ANALYSES[exp.analysis]
    if not hasattr(analysis, "training"):
        fail(f"{config}: estim tune fits the estimators of an estimation config (Chapter 3's "
             f"analysis); this config's analysis is {exp.analysis!r}")
    tuning.check_tunable(exp, label)                      # before any training draw
    labels = [e["label"] for e in exp.spec["estimators"]]
    if new_label is not None and (not 0 < len(new_label.strip()) <= 60 or new_label in labels):
        fail(f"--as {new_label[:60]!r}: expected a new label of 1 to 60 characters, not one of "
             f"{labels}")
    out = out or Path(config).parent / "fitted" / f"{exp.name}.yaml"
    store.output_file(out, "--out")                 # a path the system takes, not a folder
    store.ensure_writable(out.parent)                       # before the fit, not after it
    start = time.perf_counter()
    entry, fit = tuning.tune(exp, analysis.training, label, runs, fit_r,
                             progress=tune_progress(start))
    entry["label"] = new_label or f"{label} (fitted {'Q, R' if fit_r else 'Q'})"
    text_ = tuning.overlay(entry, fit, label, runs, " ".join(["estim", *sys.argv[1:]]),
                           time.perf_counter() - start, fit_r)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        store.atomic_write_bytes(out, text_.encode())
    except OSError as exc:
        raise UsageError(f"cannot write {out} ({exc.strerror or exc})") from None
    click.echo(text_, nl=False)
    click.echo(f"-> {out}", err=True)


@main.command()
@click.argument("config", type=click.Path(path_type=Path))
@click.option("--ngspice", "executable", help="The ngspice executable [default: ngspice on "
              "PATH].")
@click.option("--reltol", type=click.FloatRange(1e-14, 1e-3), default=1e-7, show_default=True,
              help="ngspice's relative tolerance to start at; a case with a difference above "
                   "its bar is run again at 10x and 100x tighter, then with a 10x "
                   "smaller largest step, then 1000x tighter.")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "markdown"]),
              default="text", show_default=True)
def spice(config, executable, reltol, fmt) -> None:
    """Simulate CONFIG's netlist circuit in estim and in ngspice on the config's own input and
    report the largest relative differences (DC point, every state and the output over the
    run, AC gain), each against its bar: holds, undecided (above it while ngspice's own last
    two answers differ by more) or fails; exit 1 if any fails."""
    from estim.engine import ngspice_check as compare
    from estim.spice.ngspice import NgspiceError

    if executable is not None and not executable.strip():
        fail("--ngspice: an empty name; leave the option out for ngspice on PATH")
    if not reltol == reltol:                  # NaN passes click's range; ngspice refuses it
        fail("--reltol: expected a number from 1e-14 to 1e-3, got nan")

    exp = estim.config.loading.load_files([config])[0]
    try:
        table_ = compare.compare(exp, executable, reltol=reltol)
    except NgspiceError as exc:
        fail(str(exc))
    shown = table_.assign(difference=table_["difference"].map("{:.2e}".format),
                          reltol=table_["reltol"].map("{:.0e}".format),
                          own_scale=table_["own_scale"].map("{:.2e}".format),
                          ngspice_spread=table_["ngspice_spread"].map("{:.1e}".format),
                          bar=table_["bar"].map("{:.1e}".format)).drop(columns="holds")
    if fmt == "csv":
        click.echo(table_.to_csv(index=False), nl=False)
    elif fmt == "markdown":
        click.echo(shown.to_markdown(index=False))
    else:
        click.echo(shown.to_string(index=False))
    counts = table_["verdict"].value_counts()
    failing, undecided = int(counts.get("fails", 0)), int(counts.get("undecided", 0))
    if undecided:
        click.echo(f"{exp.name}: {undecided} of {len(table_)} differences above their bars "
                   "undecided: ngspice's own last two answers differ by more than the bar",
                   err=True)
    if failing:
        click.echo(f"error: {exp.name}: {failing} of {len(table_)} differences from ngspice "
                   "above their bars", err=True)
        sys.exit(1)
    if not undecided:
        click.echo(f"{exp.name}: all {len(table_)} differences from ngspice within their "
                   "bars", err=True)


for _command in (tabling.table, validating.validate, results.report_page, results.summary,
                 results.settings, listing.list_configs):
    main.add_command(_command)


if __name__ == "__main__":            # as the console script: launch's signals and errors
    from estim.cli.launch import main as launch

    launch()
