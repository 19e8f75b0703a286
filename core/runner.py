"""Experiment -> result tables and figures: one lookup, nothing analysis-specific."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import pandas as pd
from estim.analyses import ANALYSES
from estim.analyses.base import Result, ShardDone, sweep_cell
from estim.config import apply_overrides, parse_data
from estim.schema import Experiment
from estim.tables import SWEEP_PREFIX


def sweep_cells(exp: Experiment) -> list[tuple[dict, Experiment]]:
    """The experiments of a ``sweep:`` block, each with its values (the product of the lists
    in the order given, the last key fastest); ``[({}, exp)]`` without one. Every cell keeps
    the config's seed: the cells share their random numbers, so their differences are the
    swept values' own."""
    sweep = exp.spec.get("sweep")
    if not sweep:
        return [({}, exp)]
    base = {k: v for k, v in exp.spec.items() if k != "sweep"}
    keys = list(sweep)
    cells = []
    for combo in itertools.product(*(sweep[k] for k in keys)):
        values = dict(zip(keys, combo, strict=True))
        cells.append((values, parse_data(apply_overrides(base, values, exp.source), exp.source,
                                         exp.name, max_work=2**62)))
    return cells


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
    return Result(tables={m: pd.concat(parts, ignore_index=True) for m, parts in
                          tables.items()}, figures=figures)


def summary(exp: Experiment, result: Result) -> str:
    if exp.spec.get("sweep"):
        return "\n".join(f"{metric}: {len(df)} rows over {len(sweep_cells(exp))} sweep cells"
                         for metric, df in result.tables.items())
    return ANALYSES[exp.analysis].summary(result)


def table_specs() -> dict[str, dict]:
    """``{metric: {analysis: TableSpec}}`` over every registered analysis."""
    out: dict[str, dict] = {}
    for name, module in ANALYSES.items():
        for metric, spec in module.TABLES.items():
            out.setdefault(metric, {})[name] = spec
    return out
