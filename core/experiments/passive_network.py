"""The passive-network estimator (eq 22) against the classical one (eq 19) and a discrete
Kalman filter on ``x = A e^{-t} + N`` (the paper in ``shared/seeds/004_...``, Figs 4-7),
for each reading of what the paper leaves open (the sign of eq 22's coupling, ``u``, the
initial values, whether ``z`` or ``x`` is fed, whether the record starts at ``t = 0`` or one
sample later): mean and maximum absolute error over the record, averaged over Monte Carlo
runs, beside the raw record itself (``measurement``), and the paper's claims "eq 22 beats
eq 19" and "eq 22 beats the Kalman filter", each estimator against the raw record, judged
by :mod:`estim.experiments.shared.claims` on the per-run mean absolute errors."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estim.config.experiment import Experiment
from estim.config.settings import (
    MIN_NOISE,
    REQUIRED,
    Settings,
    block,
    blocks,
    file_name,
    integer,
    number,
    setting,
    settings_class,
    text,
)
from estim.estimators import passive_network as pn
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, plots
from estim.experiments.shared.blocks import MonteCarlo
from estim.numerics import metrics
from estim.reference.tablespec import TableSpec
from estim.util import lazy

pd = lazy.load("pandas")


@settings_class
class Signal(Settings):
    """``x = A e^-t + N`` (eqs 25-26)."""

    A: float = setting(REQUIRED, number(minimum=-1e6, maximum=1e6), doc="amplitude")
    sigma: float = setting(REQUIRED, number(minimum=MIN_NOISE, maximum=1e6),
                           doc="standard deviation of N")


@settings_class
class Reading(Settings):
    """One reading of what the paper leaves open (D65)."""

    name: str = setting(REQUIRED, text(max_length=40), doc="the reading's name in the tables")
    coupling: str = setting("printed", text({"printed", "flipped"}),
                            doc="the sign of eq 22's coupling: as printed or flipped")
    u: float = setting(6.0, number(minimum=0.0, maximum=1e6),
                       doc="the source u of eqs 19 and 22 (6 as printed; 1 = q)")
    x0: float = setting(1.0, number(minimum=-1e6, maximum=1e6), doc="initial estimate")
    V0: float = setting(2.0, number(minimum=-1e6, maximum=1e6), doc="initial gain V")
    feed: str = setting("x", text({"z", "x"}),
                        doc="what is fed in: the record x or the model's measurement z = x/2")
    start: str = setting("one_sample", text({"zero", "one_sample"}),
                         doc="the record's first sample at t = 0 or one sample later")


@settings_class
class Figure(Settings):
    """The paper's figures of one signal: the record and the errors."""

    A: float = setting(REQUIRED, number(), doc="the signal's A")
    signal: str | None = setting(None, file_name, doc="file name of the record's figure")
    errors: str | None = setting(None, file_name, doc="file name of the errors' figure")


@settings_class
class Config(Settings):
    """The passive-network estimator (eq 22) against eq 19 and a Kalman filter."""

    signals: tuple = blocks(Signal, max_length=20, doc="the signals")
    readings: tuple = blocks(Reading, max_length=40, doc="the readings")
    sample_time: float = setting(0.01, number(positive=True, maximum=1.0), unit="s",
                                 doc="forward Euler step and sample time")
    samples: int = setting(500, integer(10, 1_000_000), doc="points of the record")
    kalman_p0: float = setting(1.0, number(positive=True, maximum=1e12),
                               doc="the Kalman filter's initial variance")
    monte_carlo: MonteCarlo = block(MonteCarlo, required=True, doc="runs and seed")
    figures: tuple = blocks(Figure, default=({"A": 1.0, "signal": "fig_4", "errors": "fig_5"},
                                             {"A": 100.0, "signal": "fig_6",
                                              "errors": "fig_7"}),
                            nonempty=False, max_length=20, doc="the paper's Figs 4-7")


SCHEMA: dict = Config.schema()

ESTIMATORS = ("eq 19", "eq 22", "Kalman filter")
MEASUREMENT = "measurement"
"""The raw record ``x = A e^-t + N`` taken as the estimate."""
CLAIMS = (("eq 22", "eq 19"), ("eq 22", "Kalman filter"), ("eq 19", MEASUREMENT),
          ("eq 22", MEASUREMENT), ("Kalman filter", MEASUREMENT))
"""The paper's claims (eq 22 better than eq 19 for A > 1, and than the Kalman filter) and
each estimator against the raw record."""
QUOTES = (
    Quote("mean |error| at A = 1, over the readings", "errors", "mean_abs_error",
          by="estimator", where="A == 1"),
    Quote("mean |error| at A = 100, over the readings", "errors", "mean_abs_error",
          by="estimator", where="A == 100"),
)
TABLES = {
    "errors": TableSpec("errors.csv", ("reading", "A", "sigma", "estimator"),
                        ("mean_abs_error", "mean_abs_error_se", "max_abs_error",
                         "max_abs_error_se", "runs", "diverged"),
                        title="absolute estimation error over the record"),
    "claims": claims.TABLE,
}


@dataclass(frozen=True)
class Plan:
    """The typed config: this analysis builds nothing else before its work units."""

    config: Config


def prepare(config: Config, source: str) -> Plan:
    from estim.errors import ConfigError

    names = [r.name for r in config.readings]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise ConfigError(source, f"readings[{i}].name", f"repeats {name!r}")
    amplitudes = [sig.A for sig in config.signals]
    files: list[str] = []
    for i, fig in enumerate(config.figures):
        if fig.A not in amplitudes:
            raise ConfigError(source, f"figures[{i}].A", f"expected the A of a signal "
                              f"{amplitudes}, got {fig.A!r}")
        for kind in ("signal", "errors"):
            if getattr(fig, kind) is None:
                continue
            if getattr(fig, kind) in files:
                raise ConfigError(source, f"figures[{i}].{kind}", f"repeats {getattr(fig, kind)!r}")
            files.append(getattr(fig, kind))
    return Plan(config)


def work_units(exp: Experiment) -> int:
    return 1


def work_size(config: Config) -> int:
    return (config.monte_carlo.runs * config.samples * len(config.signals)
            * len(config.readings) * 3)


def tiny(config: Config) -> dict:
    """Seconds of work: 3 runs."""
    return {"monte_carlo.runs": 3}


def _estimates(config: Config, reading: dict, signal: np.ndarray, dt: float) -> dict:
    z = signal / 2 if reading.feed == "z" else signal
    sign = -1 if reading.coupling == "printed" else 1
    return {
        "eq 19": pn.estimator(z, dt, reading.u, reading.x0, reading.V0, "eq19"),
        "eq 22": pn.estimator(z, dt, reading.u, reading.x0, reading.V0, "eq22", sign),
        "Kalman filter": pn.kalman(signal / 2, dt, reading.x0, config.kalman_p0),
    }


def times(config: Config, reading: dict) -> np.ndarray:
    """Sample times of the record: ``T, 2T, ..., N T`` (``start: one_sample``, the default)
    or ``0, T, ..., (N - 1) T`` (``start: zero``); the paper says only "the first 500 points
    with a sampling time of 0.01"."""
    first = 1 if reading.start == "one_sample" else 0
    return config.sample_time * np.arange(first, config.samples + first)


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    config = exp.config
    dt, steps, runs = config.sample_time, config.samples, config.monte_carlo.runs
    rows, cells, figure_data = [], [], {}
    for s_idx, sig in enumerate(config.signals):
        rng = exp.config.monte_carlo.rng(s_idx)
        noise = sig.sigma * rng.standard_normal((runs, steps))
        for reading in config.readings:
            t = times(config, reading)
            clean = sig.A * np.exp(-t)
            noisy = clean + noise
            est = {**_estimates(config, reading, noisy, dt), MEASUREMENT: noisy}
            losses = {}
            for name, values in est.items():
                with np.errstate(invalid="ignore", over="ignore"):
                    err = np.abs(values - clean)
                mean_err = np.where(np.isfinite(err).all(axis=1), err.mean(axis=1), np.inf)
                max_err = np.where(np.isfinite(err).all(axis=1), err.max(axis=1), np.inf)
                losses[name] = claims.Losses(mean_err)
                with np.errstate(invalid="ignore"):     # a diverged run is inf: SE nan
                    m, m_se = metrics.mean_and_se(mean_err)
                    x, x_se = metrics.mean_and_se(max_err)
                rows.append({"reading": reading.name, "A": sig.A, "sigma": sig.sigma,
                             "estimator": name, "mean_abs_error": m, "mean_abs_error_se": m_se,
                             "max_abs_error": x, "max_abs_error_se": x_se, "runs": runs,
                             "diverged": int(np.isinf(mean_err).sum())})
            cells.append((claims.cell(reading=reading.name, A=float(sig.A),
                                      sigma=float(sig.sigma)), losses))
            if reading is config.readings[0]:
                figure_data[sig.A] = {"t": t, "clean": clean, "noisy": noisy[0],
                                         "sigma": sig.sigma, "errors": {}}
            if reading.start == config.readings[0].start:    # one time axis a figure
                figure_data[sig.A]["errors"][reading.name] = {
                    n: np.abs(v[0] - clean) for n, v in est.items() if n != MEASUREMENT}
    df = pd.DataFrame(rows)[TABLES["errors"].columns]
    table = claims.table(cells, CLAIMS, "mean |error|")
    figures = {}
    for fig in config.figures:
        data = figure_data[fig.A]
        if fig.signal is not None:
            figures[fig.signal] = plots.noisy_signal(
                data["t"], data["clean"], data["noisy"],
                rf"$x = A e^{{-t}} + N$, $A$ = {fig.A:g}, $\sigma$ = {data['sigma']:g} (run 1)")
        if fig.errors is not None:
            figures[fig.errors] = plots.absolute_errors(data["t"], data["errors"],
                                                           f"$A$ = {fig.A:g}")
    if on_done:
        on_done()
    return Result(tables={"errors": df, "claims": table}, figures=figures)


def printout(result: Result) -> str:
    df = result.tables["errors"]
    view = df.pivot_table(index=["reading", "A", "sigma"], columns="estimator",
                          values="mean_abs_error", sort=False)
    return view.to_string(float_format=lambda v: f"{v:.4g}")
