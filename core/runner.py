"""Experiment -> result tables and figures. One entry point for every analysis."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import pandas as pd

from core import plots, tables
from core.analyses import estimation, perturbation
from core.config import FIGURE_KINDS, Experiment


@dataclass
class Result:
    tables: dict[str, pd.DataFrame]
    figures: dict[str, object] = field(default_factory=dict)


def n_points(exp: Experiment) -> int:
    """Work units of the experiment, for progress bars."""
    if exp.spec["analysis"] == "perturbation":
        return len(perturbation.rows(exp)) + 1
    return len(estimation.sweep(exp)) + 1


def execute(exp: Experiment, runs: int | None = None, seed: int | None = None, jobs: int = 1,
            on_point: Callable[[], None] | None = None) -> Result:
    """Run ``exp``; ``runs`` and ``seed`` override the config's Monte Carlo settings."""
    if exp.spec["analysis"] == "perturbation":
        return _execute_perturbation(exp, jobs, on_point)
    mc = exp.spec["monte_carlo"]
    runs = mc["runs"] if runs is None else runs
    seed = mc["seed"] if seed is None else seed
    rows = estimation.run(exp, runs, seed, jobs, on_point)
    out = Result(tables={})
    for metric, table_id in exp.spec["tables"].items():
        if table_id is not None:
            out.tables[metric] = tables.result_table(rows, metric, table_id)
    if "rmse" in out.tables:
        labels = {e["label"] for e in exp.spec["estimators"]}
        if {"EKF", "RLS"} <= labels:
            out.tables["claims"] = tables.claims(out.tables["rmse"])
    data = estimation.figure_data(exp, seed, runs)
    names = exp.spec["figures"]["names"]
    reading = exp.spec["figures"]["reading"] or exp.spec["noise"]["readings"][0]
    where = f"{data['frequency_hz']:g} Hz, input noise {data['noise_level']:g} ({reading})"
    figure_makers = {
        "noiseless": lambda: plots.estimates(data["noiseless"], f"{exp.name}, noiseless input"),
        "noisy": lambda: plots.estimates(data["noisy"], f"{exp.name}, {where}"),
        "rmse": lambda: plots.running_rmse(data["noisy"], f"{exp.name}: RMSE, {where}"),
        "residual": lambda: plots.residuals(data["noisy"], f"{exp.name}: residual, {where}"),
    }
    for kind in FIGURE_KINDS:
        out.figures[names.get(kind, kind)] = figure_makers[kind]()
    for extra in exp.spec["figures"]["extra_noisy"]:
        title = (f"{exp.name}, {data['frequency_hz']:g} Hz, input noise "
                 f"{extra['noise_level']:g} ({extra['reading']})")
        out.figures[extra["name"]] = plots.estimates(data[extra["name"]], title)
    if on_point:
        on_point()
    return out


def _execute_perturbation(exp: Experiment, jobs: int,
                          on_point: Callable[[], None] | None) -> Result:
    """Chapter 2: the distortion table and the figure of one row (deterministic: no seed)."""
    results = perturbation.run(exp, jobs, on_point)
    rows = [summary for summary, _ in results]
    out = Result(tables={"distortion": tables.distortion_table(rows,
                                                               exp.spec["tables"]["distortion"])})
    data = perturbation.figure_data(exp, {s["s_no"]: r for s, r in results})
    row = data["row"]
    what = f"{row['amplitude_v']:g} V"
    if row["frequency_hz"] is not None:
        what += f", {row['frequency_hz']:g} Hz"
    if row["params"]:
        what += f"\n{perturbation.row_params(row)}"
    out.figures[exp.spec["figures"]["name"]] = plots.perturbation(data, f"{exp.name}, {what}")
    if on_point:
        on_point()
    return out
