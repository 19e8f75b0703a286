"""``estim``: run, reproduce, table, check, tune, validate, list.

Exit codes: 0 ok, 1 a check found differences, 2 a usage or config error, 3 a run failed,
130 interrupted.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import stat
import sys
import tempfile
import time
from pathlib import Path

import click
import estim
import matplotlib.pyplot as plt
import pandas as pd
import yaml
from estim import io, runner, tables
from estim.analyses import ANALYSES
from estim.analyses.base import ShardDone, execution
from estim.cli import project
from estim.cli.group import Group, fail
from estim.config import (
    MAX_WORK,
    OVERRIDE_KEY,
    apply_overrides,
    load_yaml,
    parse_data,
    parse_override,
    spec_hash,
)
from estim.errors import ConfigError, ReferenceJoinError, UsageError
from estim.io import read_manifest, read_table
from estim.schema import Experiment

MAX_CONFIG_BYTES = 1 << 20


def load(path: Path, overrides: dict | None = None, max_work: int = MAX_WORK,
         quick: bool = False) -> Experiment:
    """Read and validate one config file (a regular file of at most 1 MiB of UTF-8); with
    ``quick``, shrunk to its analysis' quick profile (``tiny``) and validated again."""
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(str(path), "", "not a regular file")
        if info.st_size > MAX_CONFIG_BYTES:
            raise ConfigError(str(path), "", f"larger than {MAX_CONFIG_BYTES // 1024} KiB")
        with path.open("rb") as fh:
            raw = fh.read(MAX_CONFIG_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(str(path), "", "no such file") from None
    except OSError as exc:
        raise ConfigError(str(path), "", f"cannot read ({exc.strerror or exc})") from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(str(path), "", f"larger than {MAX_CONFIG_BYTES // 1024} KiB")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(str(path), "", "not a UTF-8 text file") from None
    data = load_yaml(text, str(path))
    if overrides:
        data = apply_overrides(data, overrides, str(path))
    exp = parse_data(data, str(path), path.stem, 2**62 if quick else max_work)
    if quick:                          # the first cell of a sweep, shrunk: the grid's size is moot
        spec = copy.deepcopy(exp.spec)
        sweep = spec.pop("sweep", None)
        if sweep:
            spec = apply_overrides(spec, {k: v[0] for k, v in sweep.items()}, str(path))
        small = ANALYSES[exp.analysis].tiny(spec)
        exp = parse_data(small, f"{path} (--quick)", path.stem, max_work)
    return exp


def split_overrides(args) -> tuple[list[Path], dict]:
    """Config paths and ``key.path=value`` overrides, in any order on the command line; an
    argument that names an existing file is a path even if it holds '='."""
    paths, overrides = [], {}
    for arg in args:
        text_ = str(arg)
        key = text_.partition("=")[0]
        if "=" in text_ and not Path(text_).exists() and OVERRIDE_KEY.fullmatch(key.strip()):
            try:
                k, v = parse_override(text_)
            except UsageError as exc:
                fail(str(exc))
            overrides[k] = v
        elif "=" in text_ and not Path(text_).exists():
            fail(f"{text_!r}: expected a config file or key.path=value (list items by index)")
        else:
            paths.append(Path(text_))
    return paths, overrides


def load_all(paths, overrides: dict | None = None, max_work: int = MAX_WORK,
             quick: bool = False) -> list[Experiment]:
    try:
        exps = [load(Path(p), overrides, max_work, quick) for p in paths]
    except ConfigError as exc:
        fail(str(exc))
    names = [e.name for e in exps]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        fail(f"two configs share the name {dupes[0]!r}")
    return exps


def cell_store(exp: Experiment, out: Path) -> io.CellStore:
    """Where the finished cells of ``exp`` wait in ``out`` (keyed by config and source)."""
    key = hashlib.sha256((spec_hash(exp.spec) + io.code_fingerprint()).encode()).hexdigest()
    return io.CellStore(out / f".{exp.name}.cells-{key[:16]}")


def run_one(exp: Experiment, out: Path, jobs: int, quiet: bool,
            overrides: dict | None = None, on_done=None, executor=None,
            resume: bool = True, figure_format: str = "png") -> runner.Result:
    """Run ``exp`` and write ``out/<name>/`` as a unit: all old or all new (estim.io); the
    result's tables and the names of the figures written (each written and closed as its
    sweep cell finishes).

    Each finished work unit is kept in ``out/.<name>.cells-<hash>/`` (of the config and of
    estim's source) until the run
    is written, so a run stopped by a crash or Ctrl-C resumes with the cells it has (unless
    not ``resume``); ``executor`` runs the units elsewhere (estim.executors)."""
    start = time.perf_counter()
    total = runner.work_units(exp)
    store = cell_store(exp, out)
    if not resume:
        store.clear()
    written: dict[str, None] = {}
    with io.ResultFolder(out, exp.name) as folder, execution(executor, store):
        def write_figures(figures: dict) -> None:
            for name, fig in figures.items():
                io.write_figure(fig, folder.path / "figures" / f"{name}.{figure_format}")
                plt.close(fig)
                written[name] = None

        if quiet:
            result = runner.execute(exp, jobs, on_done, write_figures)
        elif not sys.stderr.isatty():
            click.echo(f"{exp.name}: {total} work units ...", err=True)
            result = runner.execute(exp, jobs, progress_lines(exp.name, total), write_figures)
        else:
            with click.progressbar(length=total, label=exp.name, file=sys.stderr) as bar:
                result = runner.execute(exp, jobs, lambda: bar.update(1), write_figures)
        for metric, df in result.tables.items():
            io.write_csv(df, folder.path / f"{metric}.csv")
        io.write_manifest(folder.path, exp.spec, spec_hash(exp.spec),
                          time.perf_counter() - start, command=" ".join(["estim", *sys.argv[1:]]),
                          overrides=overrides or {})
        folder.commit()
    if store.hits and not quiet:
        click.echo(f"{exp.name}: resumed with {store.hits} finished cell(s) of an earlier run",
                   err=True)
    store.clear()
    return runner.Result(tables=result.tables, figures=written)


def progress_lines(name: str, total: int, prefix: str = ""):
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


def report(exp: Experiment, out: Path, result: runner.Result, quiet: bool) -> None:
    """Where the results went, and the analysis' summary."""
    if quiet:
        return
    click.echo(f"{exp.name} -> {out / exp.name}")
    text = runner.summary(exp, result)
    if text:
        click.echo(text)


def config_differences(stored: dict, current: dict, path: str = "") -> list[str]:
    """Key paths where two resolved configs differ, with both values."""
    if isinstance(stored, dict) and isinstance(current, dict):
        out = []
        for key in sorted(set(stored) | set(current), key=str):
            sub = f"{path}.{key}" if path else str(key)
            out += config_differences(stored.get(key), current.get(key), sub)
        return out
    if stored != current:
        return [f"{path or '(config)'}: stored {stored!r}, config {current!r}"]
    return []


@click.group(cls=Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(estim.__version__, "-V", "--version", prog_name="estim")
def main() -> None:
    """Reproduce the result tables of Bansal (2019), state estimation in ODE/PDE models.

    Exit codes: 0 ok, 1 check found differences, 2 usage or config error, 3 a run failed,
    130 interrupted.
    """


_jobs = click.option("--jobs", type=click.IntRange(1, 256), default=1, show_default=True,
                     help="Worker processes over work units.")
_max_work = click.option("--max-work", type=click.IntRange(1), default=MAX_WORK,
                         show_default=True,
                         help="Refuse a config whose work (state-samples) exceeds this.")


def _out_folder(out: Path | None, exps: list[Experiment], overridden: bool,
                update_baseline: bool, quiet: bool) -> Path:
    """Where a run writes: the baseline ``results/`` only for the project's own configs run
    as they are (or with ``--update-baseline``); otherwise the scratch folder."""
    where = project.locate()
    own = all(where.is_own_config(Path(e.source)) for e in exps)
    if out is not None:
        if where.is_baseline(out) and (overridden or not own) and not update_baseline:
            why = "overrides its config" if overridden else "is not a config of configs/"
            raise UsageError(f"{out} holds the stored baseline and this run {why}; pass "
                             "--update-baseline to replace it, or choose another --out")
        return out
    if (overridden or not own) and not update_baseline:
        if not quiet:
            why = "overrides the config" if overridden else "uses a config outside configs/"
            click.echo(f"this run {why}: writing to {where.scratch}/, not the baseline "
                       f"{where.results}/ (--update-baseline to replace it)", err=True)
        return where.scratch
    return where.results


@main.command()
@click.argument("configs", nargs=-1, required=True)
@click.option("--out", type=click.Path(file_okay=False, path_type=Path),
              help="Folder for results [default: the project's results/ for a config of "
                   "configs/ run as it is, else its scratch/].")
@click.option("--runs", type=click.IntRange(1), help="Override monte_carlo.runs.")
@click.option("--seed", type=click.IntRange(0), help="Override monte_carlo.seed.")
@click.option("--update-baseline", is_flag=True,
              help="Allow an overridden run to write into the stored results/.")
@click.option("--quick", is_flag=True,
              help="A first look in seconds: each analysis' quick profile (one sweep point, "
                   "the first cell of a sweep: block, short records, 3 runs); never written "
                   "into results/.")
@_jobs
@_max_work
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
    """Run the experiment(s) of CONFIGS and write OUT/<config name>/.

    CONFIGS may mix config files and overrides KEY.PATH=VALUE (the value is YAML; list
    items by index), applied to every config before it is validated, e.g.
    ``estim run configs/mosfet_saturation.yaml simulation.rtol=1e-6 monte_carlo.runs=5``.
    An overridden run writes into scratch/ and its manifest records the overrides.
    """
    configs, given = split_overrides(configs)
    if not configs:
        fail("no config file given")
    overrides = {**given, **{k: v for k, v in (("monte_carlo.runs", runs),
                                                ("monte_carlo.seed", seed)) if v is not None}}
    if quick and update_baseline:
        fail("--quick never writes the baseline: drop --update-baseline")
    if scheduler and executor != "dask":
        fail("--scheduler needs --executor dask")
    exps = load_all(configs, overrides, max_work, quick)
    folder = _out_folder(out, exps, bool(overrides) or quick, update_baseline, quiet)
    io.ensure_writable(folder)
    if shard is not None:
        k, n = _parse_shard(shard)
        for exp in exps:
            store = cell_store(exp, folder)
            with execution(None, store, shard=(k, n)) as ctx:
                try:
                    runner.execute(exp, jobs)
                except ShardDone:
                    pass
            if not ctx.offsets:
                click.echo(f"{exp.name}: the {exp.analysis} analysis does not split into "
                           "work units, so no shard keeps any of it; 'estim merge' runs it "
                           "whole")
            else:
                click.echo(f"{exp.name}: shard {k}/{n}: {ctx.computed} cell(s) in "
                           f"{store.folder}; finish with 'estim merge'")
        return
    with _executor(executor, scheduler, jobs) as units:
        for exp in exps:
            report(exp, folder, run_one(exp, folder, jobs, quiet, overrides, executor=units,
                                        resume=not no_resume, figure_format=figure_format),
                   quiet)


def _parse_shard(text_: str) -> tuple[int, int]:
    k, sep, n = text_.partition("/")
    if not (sep and k.isdigit() and n.isdigit() and 1 <= int(k) <= int(n)):
        fail(f"--shard {text_!r}: expected K/N with 1 <= K <= N")
    return int(k), int(n)


@main.command()
@click.argument("configs", nargs=-1, required=True)
@click.option("--from", "sources", multiple=True, required=True,
              type=click.Path(file_okay=False, exists=True, path_type=Path),
              help="A folder the shards wrote into (repeat for several).")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path),
              help="Folder for results [default: as for run].")
@click.option("--runs", type=click.IntRange(1), help="As given to the shards' run.")
@click.option("--seed", type=click.IntRange(0), help="As given to the shards' run.")
@click.option("--quick", is_flag=True, help="As given to the shards' run.")
@_jobs
@_max_work
@click.option("--quiet", is_flag=True)
def merge(configs, sources, out, runs, seed, quick, jobs, max_work, quiet) -> None:
    """Gather the cells of 'estim run --shard K/N' runs from the --from folders and write
    the tables, computing any cell no shard made. CONFIGS, overrides, --runs and --seed as
    given to run: the cells are found by the config they were computed for."""
    configs, given = split_overrides(configs)
    overrides = {**given, **{k: v for k, v in (("monte_carlo.runs", runs),
                                                ("monte_carlo.seed", seed)) if v is not None}}
    exps = load_all(configs, overrides, max_work, quick)
    folder = _out_folder(out, exps, bool(overrides) or quick, False, quiet)
    io.ensure_writable(folder)
    for exp in exps:
        target = cell_store(exp, folder)
        copied = 0
        for source in sources:
            found = cell_store(exp, source).folder
            for cell in sorted(found.glob("cell-*.pkl")) if found.is_dir() else []:
                if found != target.folder:
                    target.folder.mkdir(parents=True, exist_ok=True)
                    io.atomic_write_bytes(target.folder / cell.name, cell.read_bytes())
                copied += 1
        if not copied:
            click.echo(f"{exp.name}: no cells of this config in the --from folder(s) (an analysis "
                       "that does not split, or shards run with another config, overrides, "
                       "--runs, --seed or estim version); computing it whole", err=True)
        elif not quiet:
            click.echo(f"{exp.name}: {copied} cell(s) from {len(sources)} folder(s)", err=True)
        report(exp, folder, run_one(exp, folder, jobs, quiet, overrides), quiet)


@contextlib.contextmanager
def _executor(kind: str, scheduler: str | None, jobs: int):
    """``None`` for this machine, or a Dask executor on ``scheduler`` (a local cluster of
    ``jobs`` single-threaded workers without one), closed afterwards."""
    if kind == "local":
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        fail("--executor dask needs Dask distributed: pip install 'estim[dask]'")
    from estim.executors import dask_executor

    cluster = None if scheduler else LocalCluster(n_workers=jobs, threads_per_worker=1,
                                                  processes=True, dashboard_address=None)
    try:
        client = Client(scheduler) if scheduler else Client(cluster)
    except OSError as exc:
        raise UsageError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
    try:
        yield dask_executor(client)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@main.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path),
              help="Folder for results [default: the project's results/].")
@_jobs
@_max_work
@click.option("--quiet", is_flag=True)
def reproduce(out, jobs, max_work, quiet) -> None:
    """Run every config of configs/ (the thesis tables on the default settings)."""
    where = project.locate()
    if not quiet:
        click.echo(where.describe(), err=True)
    exps = load_all(where.configs(), max_work=max_work)
    folder = out or where.results
    io.ensure_writable(folder)
    for exp in exps:
        report(exp, folder, run_one(exp, folder, jobs, quiet), quiet)


def _stored_tables(results: Path, metric: str):
    """``(folder, TableSpec, path)`` of every stored experiment that has ``metric``."""
    for manifest_path in sorted(results.glob("*/manifest.json")):
        folder = manifest_path.parent
        manifest = read_manifest(folder)
        if manifest is None or not isinstance(manifest.get("config"), dict):
            raise UsageError(f"{manifest_path}: not a readable estim manifest")
        analysis = ANALYSES.get(manifest["config"].get("analysis", "estimation"))
        spec = analysis.TABLES.get(metric) if analysis else None
        if spec is not None and (folder / spec.file).is_file():
            yield folder, spec, folder / spec.file


def _metrics_help() -> str:
    """The metrics of the registered analyses, for ``estim table --help``."""
    lines = ["\b", "Metrics (analyses that write them):"]
    for metric, specs in sorted(runner.table_specs().items()):
        title = next((s.title for s in specs.values() if s.title), "")
        lines.append(f"  {metric:<11} {title} [{', '.join(sorted(specs))}]")
    return "\n".join(lines)


@main.command(epilog=_metrics_help())
@click.argument("metric", type=click.Choice(sorted(runner.table_specs())))
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              help="Folder of stored results [default: the project's results/].")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "markdown", "latex"]),
              default="text", show_default=True)
@click.option("--thesis", "--paper", "--reference", "thesis", is_flag=True,
              help="Show the printed value (thesis or paper) and ours/printed beside ours.")
@click.option("--partial", is_flag=True,
              help="With --thesis: allow thesis rows that the results do not cover.")
def table(metric, results, fmt, thesis, partial) -> None:
    """Print the METRIC tables of every experiment found under RESULTS.

    csv gives one CSV over all experiments (an ``experiment`` column first); markdown and
    latex (booktabs, escaped) one table per experiment under its name; text wraps at 100
    columns.
    """
    results = results or project.locate().results
    shown = 0
    frames = []
    for folder, spec, path in _stored_tables(results, metric):
        df = tables.view(read_table(path, spec), spec)
        values = df.drop(columns=[*spec.keys, *tables.sweep_columns(df)], errors="ignore")
        if values.isna().all().all():
            continue
        shown += 1
        if thesis and spec.join and "table_id" in df:
            try:
                df = tables.with_reference(df, spec, allow_unmatched=partial)
            except ReferenceJoinError as exc:
                fail(f"{path}: {exc}")
        if fmt == "csv":
            frames.append(df.assign(experiment=folder.name)[["experiment", *df.columns]])
            continue
        ids = ", ".join(sorted({str(t) for t in df.get("table_id", []) if t}))
        note = f" (thesis Table {ids})" if ids else (
            " (no printed table to compare with)" if thesis else "")
        title = f"{folder.name}: {spec.title}" if spec.title else folder.name
        if fmt == "text":
            click.echo(f"== {title}" + note)
        elif fmt == "markdown":
            click.echo(f"### {title}{note}\n")
        else:
            click.echo(f"% {tables.latex_escape(title + note)}")
        click.echo(tables.render(df, fmt))
    if frames:
        click.echo(tables.render(pd.concat(frames, ignore_index=True), "csv"), nl=False)
    if not shown:
        fail(f"no {metric} values under {results}/ (run 'estim reproduce')")


@main.command()
@click.argument("configs", nargs=-1)
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              help="Folder of stored results [default: the project's results/].")
@_jobs
@_max_work
def check(configs, results, jobs, max_work) -> None:
    """Re-run CONFIGS (default: configs/*.yaml) as they are and compare every cell with the
    stored tables under each config's tolerances; the stored manifest must record the same
    config (runs, seed and every other value).

    Overrides KEY.PATH=VALUE among CONFIGS re-run the configs changed so (a solver, a
    tolerance) and compare their tables with the stored ones under the same tolerances; the
    stored config is then not required to match.
    """
    where = project.locate()
    configs, overrides = split_overrides(configs)
    exps = load_all(configs or where.configs(), overrides, max_work=max_work)
    if overrides:
        click.echo("check: with overrides " + ", ".join(f"{k}={v!r}" for k, v in
                                                       overrides.items())
                   + ": comparing tables only, not the stored config")
    results = results or where.results
    differing = 0
    with tempfile.TemporaryDirectory() as tmp:
        for exp in exps:
            differing += _check_one(exp, results / exp.name, Path(tmp), jobs,
                                    same_config=not overrides)
    if differing:
        click.echo(f"check: {differing} difference(s)")
        sys.exit(1)
    click.echo("check: all tables match")


def _check_one(exp: Experiment, stored_dir: Path, tmp: Path, jobs: int,
               same_config: bool = True) -> int:
    """Differences between the stored results of ``exp`` and a fresh run of it."""
    if not stored_dir.is_dir():
        click.echo(f"{exp.name}: no stored results in {stored_dir}")
        return 1
    manifest = read_manifest(stored_dir)
    if manifest is None:
        click.echo(f"{exp.name}: {stored_dir / 'manifest.json'} is missing or not JSON")
        return 1
    if same_config and manifest.get("config_sha256") != spec_hash(exp.spec):
        changes = config_differences(manifest.get("config"), exp.spec)
        shown = "; ".join(changes[:5]) + (f"; and {len(changes) - 5} more" if
                                          len(changes) > 5 else "")
        click.echo(f"{exp.name}: the stored results were made with another config than "
                   f"{exp.source}: {shown or 'config hash differs'}")
        return 1
    total = runner.work_units(exp)
    click.echo(f"{exp.name}: running {total} work units ...", err=True)
    start = time.perf_counter()
    result = run_one(exp, tmp, jobs, quiet=True, on_done=progress_lines(exp.name, total))
    click.echo(f"{exp.name}: ran in {time.perf_counter() - start:.0f} s", err=True)
    tol = exp.spec["check"]["tolerances"]
    skipped = sorted(c for c, t in tol.items() if t.get("skip"))
    for column in skipped:
        click.echo(f"{exp.name}: column {column} not compared ({tol[column]['skip']})")
    analysis = ANALYSES[exp.analysis]
    differing = 0
    for metric, new in result.tables.items():
        path = stored_dir / f"{metric}.csv"
        if not path.exists():
            click.echo(f"{exp.name}/{metric}.csv: missing from the stored results")
            differing += 1
            continue
        try:
            stored = read_table(path, analysis.TABLES.get(metric))
        except UsageError as exc:
            click.echo(f"{exp.name}/{metric}.csv: {exc}")
            differing += 1
            continue
        diffs = io.compare_tables(stored, read_table(tmp / exp.name / f"{metric}.csv"), tol)
        for d in diffs:
            click.echo(f"{exp.name}/{metric}.csv row {d['row']} {d['column']}: "
                       f"obtained {d['obtained']}, expected {d['expected']}, "
                       f"difference {d['difference']}")
        differing += len(diffs)
        spec = analysis.TABLES.get(metric)
        if spec is not None and spec.join:
            try:
                tables.with_reference(tables.view(stored, spec), spec, allow_unmatched=True)
            except ReferenceJoinError as exc:
                click.echo(f"{exp.name}/{metric}.csv: {exc}")
                differing += 1
        if not diffs:
            click.echo(f"{exp.name}/{metric}.csv: {len(new)} rows match")
    for name in sorted(result.figures):
        stored_as = [stored_dir / "figures" / f"{name}.{fmt}" for fmt in ("png", "svg", "pdf")]
        if not any(f.is_file() and f.stat().st_size > 0 for f in stored_as):
            click.echo(f"{exp.name}/figures/{name}.png: missing from the stored results")
            differing += 1
    return differing


@main.command()
@click.argument("config", type=click.Path(path_type=Path))
@click.option("--estimator", "label", required=True, help="Label of the filter to fit.")
@click.option("--as", "new_label", help="Label of the fitted entry [default: LABEL (fitted Q)].")
@click.option("--runs", type=click.IntRange(2, 10_000), default=10, show_default=True,
              help="Training runs per sweep point (drawn apart from the table's runs).")
@click.option("--fit-r", is_flag=True, help="Fit R too (reported as not identifiable when "
                                           "the data cannot tell Q from R).")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="Overlay file [default: fitted/<config name>.yaml beside the config].")
@_max_work
def tune(config, label, new_label, runs, fit_r, out, max_work) -> None:
    """Fit the Q (and R) of one estimator of CONFIG by maximum likelihood and write the
    fitted estimator entry to a YAML overlay."""
    exp = load_all([config], max_work=max_work)[0]
    analysis = ANALYSES[exp.analysis]
    if not hasattr(analysis, "tune"):
        fail(f"{config}: analysis {exp.analysis!r} has no estimators to tune")
    out = out or Path(config).parent / "fitted" / f"{exp.name}.yaml"
    start = time.perf_counter()
    entry, fit = analysis.tune(exp, label, runs, fit_r)
    entry["label"] = new_label or f"{label} (fitted {'Q, R' if fit_r else 'Q'})"
    lines = [
        f"# Written by: estim {' '.join(sys.argv[1:])}",
        f"# Maximum-likelihood noise covariances of {label!r} (core/tuning.py) on training",
        f"# draws of {runs} runs per sweep point, apart from the table's draws.",
        f"# Innovation log-likelihood: {fit.log_likelihood_start:.6g} at the config's values, "
        f"{fit.log_likelihood:.6g} fitted ({fit.evaluations} evaluations, "
        f"{time.perf_counter() - start:.0f} s).",
        f"# {fit.message}",
        f"# Q diagonal:    {[float(f'{v:.4g}') for v in fit.q]}",
        f"# standard error {[float(f'{v:.2g}') for v in fit.q_se]}",
    ]
    if fit_r:
        lines += [f"# R diagonal:    {[float(f'{v:.4g}') for v in fit.r]}",
                  f"# standard error {[float(f'{v:.2g}') for v in fit.r_se]}"]
    lines.append("# Add the entry below to the config's estimators to run it beside the others.")
    text = "\n".join(lines) + "\n" + yaml.safe_dump({"estimators": [entry]}, sort_keys=False)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        io.atomic_write_bytes(out, text.encode())
    except OSError as exc:
        raise UsageError(f"cannot write {out} ({exc.strerror or exc})") from None
    click.echo(text, nl=False)
    click.echo(f"-> {out}", err=True)


@main.command()
@click.argument("configs", nargs=-1, required=True)
@_max_work
def validate(configs, max_work) -> None:
    """Check CONFIGS without running them (overrides KEY.PATH=VALUE as for run)."""
    configs, overrides = split_overrides(configs)
    if not configs:
        fail("no config file given")
    for exp in load_all(configs, overrides, max_work=max_work):
        click.echo(f"{exp.source}: ok ({exp.name})")


@main.command(name="report")
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              help="Folder of stored results [default: the project's results/].")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default="report.html",
              show_default=True, help="The HTML file to write.")
def report_page(results, out) -> None:
    """Write one self-contained HTML page of the stored results: tables beside the printed
    values (failing claims in red), every figure, the deviations each config cites, seeds
    and versions."""
    from estim import report as html_report

    where = project.locate()
    results = results or where.results
    notes = where.root / "docs" / "deviations.md" if where.root else None
    entries = html_report.deviation_entries(notes.read_text()) if notes and notes.is_file() \
        else {}
    sections = []
    for manifest_path in sorted(results.glob("*/manifest.json")):
        folder = manifest_path.parent
        manifest = read_manifest(folder)
        if manifest is None or not isinstance(manifest.get("config"), dict):
            raise UsageError(f"{manifest_path}: not a readable estim manifest")
        config = manifest["config"]
        analysis = ANALYSES.get(config.get("analysis", "estimation"))
        section = html_report.Section(folder.name, str(config.get("title") or ""), manifest)
        for metric, spec in (analysis.TABLES.items() if analysis else []):
            path = folder / spec.file
            if not path.is_file():
                continue
            df = tables.view(read_table(path, spec), spec)
            if spec.join and "table_id" in df and df["table_id"].astype(str).str.len().any():
                try:
                    df = tables.with_reference(df, spec, allow_unmatched=True)
                except ReferenceJoinError:
                    pass
            section.tables.append((f"{metric}: {spec.title}", df))
        for figure in sorted((folder / "figures").glob("*")):
            if figure.suffix in (".png", ".svg", ".pdf"):
                section.figures.append((figure.name, figure.read_bytes()))
        source = where.config_dir / f"{folder.name}.yaml"
        text_ = source.read_text() if source.is_file() else ""
        section.deviations = [(d, entries[d]) for d in html_report.cited(text_) if d in entries]
        sections.append(section)
    if not sections:
        fail(f"no stored results under {results}/ (run 'estim reproduce')")
    page = html_report.page("estim: stored results", sections)
    io.atomic_write_bytes(out, page.encode("utf-8"))
    click.echo(f"report: {len(sections)} experiments -> {out}")


@main.command()
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              help="Folder of stored results [default: the project's results/].")
@click.option("--readme", type=click.Path(dir_okay=False, path_type=Path),
              help="Re-generate the summary blocks (<!-- summary: NAME --> ... "
                   "<!-- /summary -->) of this Markdown file in place.")
@click.option("--check", "check_only", is_flag=True,
              help="With --readme: write nothing; exit 1 naming the blocks that do not "
                   "match the stored tables.")
def summary(results, readme, check_only) -> None:
    """Print each stored experiment's claims (holds / fails / undecided out of its cells,
    with the range of the ratio) and the ranges of the quantities its analysis quotes."""
    from estim import summary as summaries

    results = results or project.locate().results
    if readme is None:
        found = summaries.everything(results, ANALYSES)
        if not found:
            fail(f"no stored results under {results}/ (run 'estim reproduce')")
        click.echo("\n\n".join("\n".join(lines) for lines in found.values()))
        return
    try:
        text = readme.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"{readme}: cannot read ({exc})") from None
    new, stale = summaries.refresh(text, results, ANALYSES)
    if check_only:
        if stale:
            click.echo(f"{readme}: stale summary blocks: {', '.join(stale)} (re-generate with "
                       f"'estim summary --readme {readme}')")
            sys.exit(1)
        click.echo(f"{readme}: every summary block matches {results}/")
        return
    if stale:
        io.atomic_write_bytes(readme, new.encode())
    click.echo(f"{readme}: {len(stale)} block(s) re-generated" + (
        f" ({', '.join(stale)})" if stale else ""))


@main.command(name="list")
def list_configs() -> None:
    """Show the configs and the thesis tables each reproduces."""
    where = project.locate()
    click.echo(where.describe(), err=True)
    for exp in load_all(where.configs()):
        click.echo(f"{exp.source:40s} {exp.name:24s} Tables {', '.join(exp.spec['reproduces'])}"
                   f"  {exp.spec['title']}")


if __name__ == "__main__":
    main()
