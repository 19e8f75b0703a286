"""Experiment -> result tables and figures: one lookup, nothing analysis-specific."""

from __future__ import annotations

from collections.abc import Callable

from core.analyses import ANALYSES
from core.analyses.base import Result
from core.schema import Experiment


def work_units(exp: Experiment) -> int:
    """Work units of the experiment, for progress reports."""
    return ANALYSES[exp.analysis].work_units(exp)


def execute(exp: Experiment, jobs: int = 1,
            on_done: Callable[[], None] | None = None) -> Result:
    """Run ``exp`` (its Monte Carlo runs and seed are in its config)."""
    return ANALYSES[exp.analysis].run(exp, jobs, on_done)


def summary(exp: Experiment, result: Result) -> str:
    return ANALYSES[exp.analysis].summary(result)


def table_specs() -> dict[str, dict]:
    """``{metric: {analysis: TableSpec}}`` over every registered analysis."""
    out: dict[str, dict] = {}
    for name, module in ANALYSES.items():
        for metric, spec in module.TABLES.items():
            out.setdefault(metric, {})[name] = spec
    return out
