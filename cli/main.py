"""``estim``: run, reproduce, table, check, validate, list.

Exit codes: 0 ok, 1 a check found differences, 2 a usage or config error.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import click
import matplotlib.pyplot as plt
import pandas as pd

import core
from core import io, runner, tables
from core.config import ConfigError, Experiment, parse

CONFIG_DIR = Path("configs")
RESULTS_DIR = Path("results")


def fail(message: str) -> None:
    click.echo(f"error: {message}", err=True)
    sys.exit(2)


def load(path: Path) -> Experiment:
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ConfigError(str(path), "", "no such file") from None
    except OSError as exc:
        raise ConfigError(str(path), "", f"cannot read ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(str(path), "", "not a UTF-8 text file") from None
    return parse(text, str(path), path.stem)


def load_all(paths) -> list[Experiment]:
    try:
        exps = [load(Path(p)) for p in paths]
    except ConfigError as exc:
        fail(str(exc))
    names = [e.name for e in exps]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        fail(f"two configs share the name {dupes[0]!r}")
    return exps


def default_configs() -> list[Path]:
    paths = sorted(CONFIG_DIR.glob("*.yaml"))
    if not paths:
        fail(f"no configs found in {CONFIG_DIR}/ (run from the project folder)")
    return paths


def run_one(exp: Experiment, out: Path, runs: int | None, seed: int | None, jobs: int,
            quiet: bool) -> runner.Result:
    start = time.perf_counter()
    total = runner.n_points(exp)
    if quiet or not sys.stderr.isatty():
        if not quiet:
            click.echo(f"{exp.name}: {total} work units ...", err=True)
        result = runner.execute(exp, runs, seed, jobs)
    else:
        with click.progressbar(length=total, label=exp.name, file=sys.stderr) as bar:
            result = runner.execute(exp, runs, seed, jobs, on_point=lambda: bar.update(1))
    folder = out / exp.name
    for metric, df in result.tables.items():
        io.write_csv(df, folder / f"{metric}.csv")
    for name, fig in result.figures.items():
        io.write_figure(fig, folder / "figures" / f"{name}.png")
        plt.close(fig)
    produced = {f"{metric}.csv" for metric in result.tables}
    produced |= {f"figures/{name}.png" for name in result.figures}
    io.remove_stale(folder, produced)
    mc = exp.spec.get("monte_carlo", {"seed": None, "runs": None})
    io.write_manifest(folder, exp.spec, mc["seed"] if seed is None else seed,
                      mc["runs"] if runs is None else runs, time.perf_counter() - start)
    return result


def stored_settings(folder: Path) -> tuple[int | None, int | None]:
    """Seed and runs recorded in a stored manifest (None: use the config's)."""
    try:
        manifest = json.loads((folder / "manifest.json").read_text())
        return int(manifest["seed"]), int(manifest["runs"])
    except (OSError, ValueError, KeyError, TypeError):
        return None, None


def read_table(path: Path) -> pd.DataFrame:
    """A stored result table, with an empty ``table_id`` kept as an empty string."""
    df = pd.read_csv(path, dtype={"table_id": str}, keep_default_na=False,
                     na_values=["", "NaN", "nan", "<NA>"])
    if "table_id" in df:
        df["table_id"] = df["table_id"].fillna("")
    return df


def report(exp: Experiment, out: Path, result: runner.Result, quiet: bool) -> None:
    """Where the results went, and the RMSE by estimator or the distortion by row."""
    if quiet:
        return
    click.echo(f"{exp.name} -> {out / exp.name}")
    df = result.tables.get("rmse")
    if df is not None:
        view = df.pivot(index=["noise_reading", "noise_param", "frequency_hz"],
                        columns="estimator", values="rmse")
        click.echo(view.to_string(float_format=lambda v: f"{v:.4g}"))
    df = result.tables.get("distortion")
    if df is not None:
        columns = ["s_no", "amplitude_v", "frequency_hz", "percent_distortion", "thd_percent",
                   "gain_db", "err_linear_rms", "err_first_order_rms"]
        click.echo(df[columns].to_string(index=False, float_format=lambda v: f"{v:.4g}",
                                         na_rep="--"))


class Group(click.Group):
    """Turns a failure inside a command into one line and exit code 3 (1 means drift)."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except (click.exceptions.Exit, click.ClickException, click.Abort, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001 - last line of defence, reported
            click.echo(f"error: {type(exc).__name__}: {exc}", err=True)
            sys.exit(3)


@click.group(cls=Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(core.__version__, prog_name="estim")
def main() -> None:
    """Reproduce the result tables of Bansal (2019), state estimation in ODE/PDE models.

    Exit codes: 0 ok, 1 check found differences, 2 usage or config error, 3 a run failed.
    """


_out = click.option("--out", type=click.Path(file_okay=False, path_type=Path),
                    default=RESULTS_DIR, show_default=True, help="Folder for results.")
_jobs = click.option("--jobs", type=click.IntRange(1), default=1, show_default=True,
                     help="Worker processes over sweep points.")


@main.command()
@click.argument("configs", nargs=-1, required=True, type=click.Path(path_type=Path))
@_out
@click.option("--runs", type=click.IntRange(1), help="Override the Monte Carlo runs.")
@click.option("--seed", type=click.IntRange(0), help="Override the seed.")
@_jobs
@click.option("--quiet", is_flag=True, help="No progress and no summary.")
def run(configs, out, runs, seed, jobs, quiet) -> None:
    """Run the experiment(s) of CONFIGS and write OUT/<config name>/."""
    for exp in load_all(configs):
        report(exp, out, run_one(exp, out, runs, seed, jobs, quiet), quiet)


@main.command()
@_out
@_jobs
@click.option("--quiet", is_flag=True)
def reproduce(out, jobs, quiet) -> None:
    """Run every config in configs/ (the thesis tables on the default settings)."""
    for exp in load_all(default_configs()):
        report(exp, out, run_one(exp, out, None, None, jobs, quiet), quiet)


@main.command()
@click.argument("metric", type=click.Choice(sorted(tables.METRICS)))
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              default=RESULTS_DIR, show_default=True)
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "markdown", "latex"]),
              default="text", show_default=True)
@click.option("--thesis", is_flag=True, help="Show the thesis value and ours/thesis beside ours.")
def table(metric, results, fmt, thesis) -> None:
    """Print the METRIC tables of every experiment found under RESULTS."""
    files = sorted(results.glob(f"*/{tables.METRICS[metric]['file']}"))
    if not files:
        fail(f"no {tables.METRICS[metric]['file']} under {results}/ (run 'estim reproduce')")
    shown = 0
    for path in files:
        df = tables.view(read_table(path), metric)
        if df.drop(columns=tables.METRICS[metric]["keys"]).isna().all().all():
            continue
        shown += 1
        if thesis:
            df = tables.with_thesis(df, metric)
        if fmt == "text":
            click.echo(f"== {path.parent.name} (thesis Table {df['table_id'].iloc[0]})")
        click.echo(tables.render(df, fmt))
    if not shown:
        fail(f"no {metric} values under {results}/ (all empty)")


@main.command()
@click.argument("configs", nargs=-1, type=click.Path(path_type=Path))
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              default=RESULTS_DIR, show_default=True)
@_jobs
def check(configs, results, jobs) -> None:
    """Re-run CONFIGS (default: configs/*.yaml) and compare every cell with RESULTS."""
    exps = load_all(configs or default_configs())
    differing = 0
    with tempfile.TemporaryDirectory() as tmp:
        for exp in exps:
            stored_dir = results / exp.name
            if not stored_dir.is_dir():
                click.echo(f"{exp.name}: no stored results in {stored_dir}")
                differing += 1
                continue
            seed, runs = stored_settings(stored_dir)
            result = run_one(exp, Path(tmp), runs, seed, jobs, quiet=True)
            tol = exp.spec["check"]["tolerances"]
            for metric, new in result.tables.items():
                path = stored_dir / f"{metric}.csv"
                if not path.exists():
                    click.echo(f"{exp.name}/{metric}.csv: missing from the stored results")
                    differing += 1
                    continue
                stored = read_table(path)
                fresh = read_table(Path(tmp) / exp.name / f"{metric}.csv")
                diffs = io.compare_tables(stored, fresh, tol)
                for d in diffs:
                    click.echo(f"{exp.name}/{metric}.csv row {d['row']} {d['column']}: "
                               f"obtained {d['obtained']}, expected {d['expected']}, "
                               f"difference {d['difference']}")
                differing += len(diffs)
                if not diffs:
                    click.echo(f"{exp.name}/{metric}.csv: {len(new)} rows match")
    if differing:
        click.echo(f"check: {differing} difference(s)")
        sys.exit(1)
    click.echo("check: all tables match")


@main.command()
@click.argument("configs", nargs=-1, required=True, type=click.Path(path_type=Path))
def validate(configs) -> None:
    """Check CONFIGS without running them."""
    for exp in load_all(configs):
        click.echo(f"{exp.source}: ok ({exp.name})")


@main.command(name="list")
def list_configs() -> None:
    """Show the configs and the thesis tables each reproduces."""
    for exp in load_all(default_configs()):
        click.echo(f"{exp.source:40s} {exp.name:24s} Tables {', '.join(exp.spec['reproduces'])}"
                   f"  {exp.spec['title']}")


if __name__ == "__main__":
    main()
