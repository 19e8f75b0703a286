"""The optimum differentiator from Kalman theory on the double integrator (the paper in
``shared/seeds/001_01b49ce744343ce9.txt``, which prints no numbers): the derivative error
variance in closed form, from the continuous Riccati equation, from the discrete one, and
measured by Monte Carlo on the discrete filter (:mod:`estim.estimators.kalman_differentiator`); and
the differentiator's frequency response against the ideal ``s``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estim.config.experiment import Experiment
from estim.config.settings import (
    REQUIRED,
    Settings,
    block,
    blocks,
    file_name,
    number,
    setting,
    settings_class,
)
from estim.errors import ConfigError
from estim.estimators import kalman_differentiator as kd
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, plots
from estim.experiments.shared.blocks import MonteCarlo
from estim.numerics import metrics
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")
linalg = lazy.load("scipy.linalg")


@settings_class
class Case(Settings):
    """One double integrator: process and measurement noise, sample time."""

    q: float = setting(REQUIRED, number(positive=True, maximum=1e12),
                       doc="process noise intensity")
    r: float = setting(REQUIRED, number(positive=True, maximum=1e12),
                       doc="measurement noise intensity")
    dt: float = setting(REQUIRED, number(positive=True, maximum=10.0), unit="s",
                        doc="sample time")


@settings_class
class Figures(Settings):
    """The frequency-response figure."""

    name: str = setting("frequency_response", file_name, doc="the figure's file name")
    max_hz: float = setting(20.0, number(positive=True, maximum=1e6), unit="Hz",
                            doc="the highest frequency drawn")


@settings_class
class Config(Settings):
    """The optimum differentiator from Kalman theory on the double integrator."""

    cases: tuple = blocks(Case, max_length=20, doc="the cases")
    record_s: float = setting(5.0, number(positive=True, maximum=1e4), unit="s",
                              doc="Monte Carlo record length")
    settle_s: float = setting(1.0, number(minimum=0.0, maximum=1e4), unit="s",
                              doc="left out at the start of the record (the filter settling)")
    monte_carlo: MonteCarlo = block(MonteCarlo, required=True, doc="runs and seed")
    figures: Figures = block(Figures, doc="the figure")


SCHEMA: dict = Config.schema()

TABLES = {
    "derivative": TableSpec("derivative.csv", ("q", "r", "dt"),
                            ("w0", "p22_closed_form", "p22_riccati", "p22_discrete",
                             "p22_monte_carlo", "p22_monte_carlo_se", "runs"),
                            title="derivative error variance P22: closed form, Riccati, "
                                  "discrete, Monte Carlo"),
    "claims": claims.TABLE,
}
KALMAN, DIFFERENCE = "Kalman differentiator", "difference of the measurements"
CLAIMS = ((KALMAN, DIFFERENCE),)
"""The differentiator against the raw measurement's own derivative (its first difference),
on the per-run mean squared derivative error after ``settle_s``."""
QUOTES = (
    Quote("P22 closed form", "derivative", "p22_closed_form", by="r"),
    Quote("P22 discrete Riccati", "derivative", "p22_discrete", by="r"),
    Quote("P22 Monte Carlo", "derivative", "p22_monte_carlo", by="r"),
    Quote("P22 Monte Carlo standard error", "derivative", "p22_monte_carlo_se", by="r"),
)

F = np.array([[0.0, 1.0], [0.0, 0.0]])
H = np.array([[1.0], [0.0]])


@dataclass(frozen=True)
class Plan:
    """The typed config: this analysis builds nothing else before its work units."""

    config: Config


def prepare(config: Config, source: str) -> Plan:
    for i, case in enumerate(config.cases):
        if int(round(config.settle_s / case.dt)) >= int(round(config.record_s / case.dt)):
            raise ConfigError(source, "settle_s", f"expected less than record_s "
                              f"({config.record_s:g} s): the error is averaged over the "
                              f"samples after settle_s, and cases[{i}] (dt {case.dt:g} s) "
                              "would have none")
    return Plan(config)


def work_units(exp: Experiment) -> int:
    return len(exp.config.cases)


def work_size(config: Config) -> int:
    return int(sum(2 * config.record_s / c.dt for c in config.cases)
               * config.monte_carlo.runs / 100)


def tiny(config: Config) -> dict:
    """Seconds of work: one case, 5 runs of half a second."""
    return {"cases": [c.to_spec() for c in config.cases[:1]], "monte_carlo.runs": 5,
            "record_s": 0.5, "settle_s": 0.1}


def run_case(exp: Experiment, index: int) -> tuple[tuple, dict]:
    """One case's claims cell and its ``derivative.csv`` row."""
    config = exp.config
    case = config.cases[index]
    q, r, dt = case.q, case.r, case.dt
    G = np.array([[0.0], [np.sqrt(q)]])
    closed = kd.double_integrator(q, r)
    P, _ = kd.steady_state(F, G, H, r)
    Phi, Qd = kd.discretize(F, G, dt)
    Pd = linalg.solve_discrete_are(Phi.T, H, Qd, np.array([[r / dt]]))
    S = H.T @ Pd @ H + r / dt
    P_post = Pd - Pd @ H @ np.linalg.inv(S) @ H.T @ Pd
    runs = config.monte_carlo.runs
    steps = int(round(config.record_s / dt))
    rng = exp.config.monte_carlo.rng(index)
    L = np.linalg.cholesky(Qd)
    noise = rng.standard_normal((runs, steps, 2)) @ L.T
    x = np.zeros((runs, 2))
    xs = np.empty((runs, steps, 2))
    for k in range(steps):
        x = x @ Phi.T + noise[:, k]
        xs[:, k] = x
    z = xs[..., :1] + np.sqrt(r / dt) * rng.standard_normal((runs, steps, 1))
    out = kd.differentiate(z, F, G, H, r, dt)
    start = int(round(config.settle_s / dt))
    per_run = np.mean((out["derivative"][:, start:, 0] - xs[:, start:, 1]) ** 2, axis=1)
    raw = np.diff(z[..., 0], axis=1, prepend=0.0) / dt
    raw_per_run = np.mean((raw[:, start:] - xs[:, start:, 1]) ** 2, axis=1)
    mean, se = metrics.mean_and_se(per_run)
    losses = (claims.cell(q=q, r=r, dt=dt), {KALMAN: claims.Losses(per_run),
                                             DIFFERENCE: claims.Losses(raw_per_run)})
    return losses, {"q": q, "r": r, "dt": dt, "w0": closed["w0"], "p22_closed_form": closed["P22"],
            "p22_riccati": float(P[1, 1]), "p22_discrete": float(P_post[1, 1]),
            "p22_monte_carlo": mean, "p22_monte_carlo_se": se, "runs": runs}


def _run_case_args(args):
    return run_case(*args)


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    done = map_tasks(_run_case_args, [(exp, i) for i in range(len(exp.config.cases))],
                     jobs, on_done)
    rows = [row for _, row in done]
    f = np.linspace(0.05, exp.config.figures.max_hz, 400)
    curves = {}
    for case in exp.config.cases:
        G = np.array([[0.0], [np.sqrt(case.q)]])
        _, K = kd.steady_state(F, G, H, case.r)
        curves[f"q = {case.q:g}, r = {case.r:g}"] = kd.frequency_response(F, H, K, f)
    figure = plots.differentiator_response(f, curves)
    return Result(tables={"derivative": pd.DataFrame(rows)[TABLES["derivative"].columns],
                          "claims": claims.table([c for c, _ in done], CLAIMS,
                                                 "mean squared derivative error")},
                  figures={exp.config.figures.name: figure})


def printout(result: Result) -> str:
    return result.tables["derivative"].to_string(index=False, float_format=lambda v: f"{v:.4g}")
