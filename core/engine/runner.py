"""Experiment -> result tables and figures: one lookup, nothing analysis-specific."""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from concurrent.futures import Executor
from pathlib import Path

from estim import store
from estim.config.experiment import Experiment
from estim.config.loading import sweep_cells
from estim.config.registry import ANALYSES
from estim.engine import cells
from estim.errors import UsageError
from estim.experiments.base import Result
from estim.experiments.shared import claims
from estim.reference import SWEEP_PREFIX
from estim.util import lazy
from estim.util.workunits import ShardDone, execution, sweep_cell

pd = lazy.load("pandas")


def work_units(exp: Experiment) -> int:
    """Work units of the experiment, for progress reports."""
    return sum(ANALYSES[e.analysis].work_units(e) for _, e in sweep_cells(exp))


def execute(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None,
            on_figures: Callable[[dict], None] | None = None) -> Result:
    """Run ``exp`` (its Monte Carlo runs and seed are in its config). A swept experiment
    runs each cell and stacks its tables under a leading column ``sweep:<key path>`` per
    swept key; figures are named ``<figure>_sweep<n>`` (n from 1, in the grid's order).

    Under a shard (``--shard K/N``) every sweep cell computes its share before
    :class:`ShardDone` is raised. With ``on_figures`` each cell's figures are handed
    to it as they are drawn (to be written and closed) instead of kept in the result, so a
    long sweep holds one cell's figures at a time."""
    cells = sweep_cells(exp)
    if len(cells) == 1 and not cells[0][0]:
        result = ANALYSES[exp.analysis].run(exp, jobs, on_done)
        if "claims" in result.tables and exp.claim_margin:
            result.tables["claims"] = claims.with_margin(result.tables["claims"],
                                                         exp.claim_margin)
        if on_figures is None:
            return result
        on_figures(result.figures)
        return Result(tables=result.tables)
    tables: dict[str, list] = {}
    figures = {}
    incomplete = False
    for n, (values, cell) in enumerate(cells, start=1):
        try:
            with sweep_cell(n):
                result = ANALYSES[cell.analysis].run(cell, jobs, on_done)
        except ShardDone:
            incomplete = True
            continue
        for metric, df in result.tables.items():
            df = df.copy()
            for i, (key, value) in enumerate(values.items()):
                df.insert(i, SWEEP_PREFIX + key, [value] * len(df))
            tables.setdefault(metric, []).append(df)
        drawn = {f"{name}_sweep{n}": fig for name, fig in result.figures.items()}
        if on_figures is None:
            figures.update(drawn)
        else:
            on_figures(drawn)
    if incomplete:
        raise ShardDone
    stacked = {m: pd.concat(parts, ignore_index=True) for m, parts in tables.items()}
    if "claims" in stacked:             # a claim's family is its cells over the whole sweep
        stacked["claims"] = claims.with_margin(claims.families(stacked["claims"]),
                                               exp.claim_margin)
    return Result(tables=stacked, figures=figures)


def printout(exp: Experiment, result: Result) -> str:
    if exp.sweep:
        return "\n".join(f"{metric}: {len(df)} rows over {len(sweep_cells(exp))} sweep cells"
                         for metric, df in result.tables.items())
    return ANALYSES[exp.analysis].printout(result)


def table_specs() -> dict[str, dict]:
    """``{metric: {analysis: TableSpec}}`` over every registered analysis."""
    out: dict[str, dict] = {}
    for name, module in ANALYSES.items():
        for metric, spec in module.TABLES.items():
            out.setdefault(metric, {})[name] = spec
    return out


def cell_store(exp: Experiment, out: Path) -> cells.CellStore:
    """Where the finished cells of ``exp`` wait in ``out`` (keyed by config and source)."""
    config, source = store.spec_hash(exp.spec), cells.code_fingerprint()
    key = hashlib.sha256((config + source).encode()).hexdigest()
    return cells.CellStore(Path(out) / f".{exp.name}.cells-{key[:16]}",
                           {"config": config, "source": source})


def run_to_folder(exp: Experiment, out: Path, jobs: int = 1,
                  on_done: Callable[[], None] | None = None, executor: Callable | None = None,
                  resume: bool = True, figure_format: str = "png", command: str = "",
                  overrides: dict | None = None,
                  on_start: Callable[[], None] | None = None,
                  pool: Executor | None = None) -> tuple[Result, int]:
    """Run ``exp`` and write ``out/<name>/`` as a unit, all old or all new (:mod:`estim.store`):
    its tables as CSV, its figures (each written and closed as its sweep cell finishes) and
    ``manifest.json``. Returns the result (its tables, and the names of the figures written)
    and how many finished cells of an earlier run it resumed with.

    Each finished work unit is kept in ``out/.<name>.cells-<hash>/`` (of the config and of
    estim's source) until the run is written, so a run stopped by a crash or Ctrl-C resumes
    with the cells it has (unless not ``resume``); ``executor`` runs the units elsewhere
    (:mod:`estim.engine.executors`) or on a process ``pool`` shared with other configs
    (:mod:`estim.engine.scheduler`); ``on_start`` is called once the folder is open (its space and
    lock checked), ``on_done`` once per finished work unit."""
    start = time.perf_counter()
    done = cell_store(exp, out)
    if not resume:
        done.clear()
    written: dict[str, None] = {}
    machine = machine_outputs(exp)
    with store.ResultFolder(Path(out), exp.name) as folder, execution(executor, done,
                                                                    pool=pool):
        def write_figures(figures: dict) -> None:
            for name, fig in figures.items():
                path = store.figure_path(folder.path, name, figure_format, machine)
                path.parent.mkdir(parents=True, exist_ok=True)
                store.write_figure(fig, path)
                written[name] = None

        if on_start is not None:
            on_start()
        result = execute(exp, jobs, on_done, write_figures)
        store.write_tables_and_manifest(folder.path, result.tables, exp.spec,
                                     time.perf_counter() - start, command=command,
                                     overrides=overrides, models=exp.models,
                                     machine=machine)
        folder.commit()
    resumed = done.hits
    done.clear()
    return Result(tables=result.tables, figures=written), resumed


def machine_outputs(exp: Experiment) -> tuple[str, ...]:
    """The tables and figures of ``exp``'s analysis that measure the machine (its
    ``MACHINE``), written under ``machine/`` and never compared."""
    return tuple(getattr(ANALYSES[exp.analysis], "MACHINE", ()))


WALL_TIMES = "wall_times.csv"
"""Beside the result folders: each config's wall time on the machine that made the stored
results (``bench/record_wall_times.py`` writes it from their run records), for a checkout
that has no run records of its own yet (a fresh clone)."""


def recorded_seconds(folder: Path) -> float:
    """How long the config of result ``folder`` took: the wall time its run record
    (``run.json``) gives, else the one :data:`WALL_TIMES` beside it gives, else infinity:
    the longest-first order of :mod:`estim.engine.scheduler`, which starts a config it
    knows nothing of early, and the progress' weights."""
    seconds = store.read_run_record(folder).get("wall_time_s")
    if seconds is None:
        seconds = _reference_seconds(Path(folder).parent).get(Path(folder).name)
    return float(seconds) if isinstance(seconds, int | float) and seconds >= 0 else float("inf")


def run_shard(exp: Experiment, out: Path, k: int, n: int, jobs: int = 1) -> tuple[int, bool]:
    """Compute shard ``k`` of ``n`` of ``exp``'s work units (``K, K+N, ...``, counted over
    its sweep cells) into its cell store in ``out``, for :func:`gather_cells` and a later run
    to finish. Returns the cells computed, and whether the analysis splits into work units at
    all (one that does not is left to the merge, whole)."""
    done = cell_store(exp, out)
    with execution(None, done, shard=(k, n)) as ctx:
        try:
            execute(exp, jobs)
        except ShardDone:
            pass
    return ctx.computed, bool(ctx.offsets)


def gather_cells(exp: Experiment, out: Path, sources: list[Path]) -> tuple[int, list[str]]:
    """Copy the cells shards of ``exp`` left in ``sources`` into its cell store in ``out``:
    the number of cells taken, and every other file of the shards' cell folders, named with
    why it was refused (not a regular file, not a cell, a cell of another config or estim:
    :meth:`estim.engine.cells.CellStore.read`; nothing in it is run)."""
    target = cell_store(exp, out)
    found_cells, refused = 0, []
    for source in sources:
        found = cell_store(exp, source).folder
        for cell in sorted(found.iterdir()) if found.is_dir() else []:
            try:
                if not cell.name.startswith("cell-") or cell.suffix != cells.SUFFIX:
                    raise cells.CellError("not a cell file's name")
                target.read(cell)
            except cells.CellError as exc:
                refused.append(f"{cell} ({exc})")
                continue
            if found != target.folder:
                target.folder.mkdir(parents=True, exist_ok=True)
                store.atomic_write_bytes(target.folder / cell.name, cell.read_bytes())
            found_cells += 1
    return found_cells, refused


def _reference_seconds(results: Path) -> dict[str, float]:
    """``{config name: seconds}`` of :data:`WALL_TIMES` in ``results`` (empty when there is
    none or it cannot be read)."""
    path = results / WALL_TIMES
    if not path.is_file():
        return {}
    try:
        df = store.read_table(path)
        return {str(k): float(v) for k, v in zip(df["name"], df["wall_time_s"], strict=True)}
    except (UsageError, KeyError, ValueError):
        return {}
