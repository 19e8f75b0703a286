"""EKF on the Kronecker-product model vs LMS on the wavelet representation (thesis Chapter 4,
Tables 4.1-4.2, Figs 4.3-4.7).

For each W/L column x noise reading x noise level x input frequency (thesis row order
within a column):

1. the source is the nominal sine (``amplitude_v``) plus an Ornstein-Uhlenbeck process
   (eqs 4.8-4.9) with decay ``gamma`` and diffusion ``sigma`` read from the printed noise
   number, sampled exactly (:func:`estim.numerics.signals.ornstein_uhlenbeck`), piecewise linear
   between samples;
2. the actual circuit with the column's W/L (and, with ``area_scaled_caps``, capacitances
   scaled by W L over ``reference_area_um2``) is integrated by the stiff solver from its DC
   point; ``truth.params`` overrides the actual circuit only (Table 4.1's stand-in);
3. every state is measured with white noise of ``measurement_sigma`` (and an ADC of
   ``adc_bits`` over ``adc_range_v`` when set); each estimator gets the measurements it is
   said to see (the Kronecker EKF the output, eq 4.49; the wavelet method its ``measures``,
   eq 4.16) and the nominal input;
4. RMSE of the output (eq 4.60 on ``v_D``) over the runs that did not diverge and over all
   runs, the raw measurement as a baseline row, filter health
   (:mod:`estim.experiments.shared.health`), and the headline claim row by row.

The noise draws of a sweep point are shared by every W/L column (``spawn_key`` without the
column), so columns differ only by the circuit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from estim.config import registry
from estim.config.builders import build_estimator, build_model, check_interval, operating_point
from estim.config.experiment import Experiment
from estim.config.settings import (
    REQUIRED,
    Settings,
    block,
    blocks,
    boolean,
    file_name,
    integer,
    list_of,
    mapping,
    number,
    setting,
    settings_class,
    text,
)
from estim.errors import ConfigError
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, pipeline, plots
from estim.experiments.shared.blocks import (
    VOLTS,
    EstimatorEntry,
    FigurePoint,
    FilterTable,
    InputNoise,
    Sine,
    simulation,
)
from estim.numerics import signals
from estim.numerics.simulate import SOLVERS
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")

CAPACITANCES = ("C_S", "C_D", "C_B", "C_BS", "C_BD")
"""The device capacitances that scale with gate area under ``area_scaled_caps``."""

UM = number(positive=True, maximum=1e6)


@settings_class
class WL(Settings):
    """A W/L column of Table 4.2."""

    w_um: float = setting(REQUIRED, UM, unit="um", doc="gate width")
    l_um: float = setting(REQUIRED, UM, unit="um", doc="gate length")


@settings_class
class Geometry(Settings):
    """The W/L columns and whether the capacitances scale with the gate area."""

    columns: tuple = blocks(WL, max_length=20, doc="the table's W/L columns")
    area_scaled_caps: bool = setting(False, boolean,
                                     doc="scale the device capacitances with W L (D51)")
    reference_area_um2: float = setting(4.0, number(positive=True, maximum=1e12), unit="um^2",
                                        doc="the gate area at which the capacitances are as "
                                            "printed")


@settings_class
class Input(Sine):
    """The source: a sine plus an O.U. process (eqs 4.8-4.9)."""

    samples_per_period: int = setting(32, integer(4, 10_000), doc="samples per period")
    periods: int = setting(16, integer(1, 100_000), doc="record length in periods")


@settings_class
class Noise(InputNoise):
    """The O.U. input noise, the noise on every measured state, and an ADC."""

    gamma: float = setting(1.0, number(positive=True, maximum=1e12), unit="1/s",
                           doc="the O.U. process' decay (eq 4.8)")
    adc_bits: int | None = setting(None, integer(1, 32), doc="quantise the measurements with "
                                                             "an ADC of this many bits")
    adc_range_v: list = setting([0.0, 1.0], list_of(VOLTS, max_length=2), unit="V",
                                doc="the ADC's input range [low, high]")


@settings_class
class Truth(Settings):
    """What the actual circuit is (Table 4.1's stand-in changes it)."""

    data_source: str = setting("simulated", text(max_length=60),
                               doc="label of the actual data in the tables")
    params: dict = setting({}, mapping, doc="parameter overrides of the actual circuit only")


@settings_class
class FilterEntry(EstimatorEntry):
    """An estimator of Table 4.2, possibly on a model of its own."""

    model: str | None = setting(None, text(registry.MODELS),
                                doc="the estimator's own model (none: the config's)")


@settings_class
class Tables(Settings):
    """Which printed table the RMSE joins."""

    rmse: str | None = setting(None, text(), doc="thesis table of the RMSE (4.1, 4.2)")


@settings_class
class FigureName(WL):
    """The estimates figure of one W/L column."""

    name: str = setting(REQUIRED, file_name, doc="the figure's file name")


@settings_class
class Figures(FigurePoint):
    """The figures' sweep point and their columns."""

    names: tuple = blocks(FigureName, default=(), nonempty=False, max_length=20,
                          doc="one figure per named W/L column")


@settings_class
class Config(FilterTable):
    """A Chapter 4 experiment: the Kronecker EKF against the wavelet LMS."""

    geometry: Geometry = block(Geometry, required=True, doc="the W/L columns")
    input: Input = block(Input, required=True, doc="the source")
    noise: Noise = block(Noise, required=True, doc="input and measurement noise")
    truth: Truth = block(Truth, doc="the actual circuit's own overrides")
    simulation: Any = block(simulation(rtol=1e-6, atol=1e-9), doc="the actual circuit's solver")
    estimators: tuple = blocks(FilterEntry, max_length=20, doc="the estimators compared")
    tables: Tables = block(Tables, required=True, doc="the thesis table joined")
    figures: Figures = block(Figures, doc="the figures")


SCHEMA: dict = Config.schema()

_KEYS = ("table_id", "s_no", "data_source", "noise_reading", "noise_param", "noise_sigma",
         "frequency_hz", "w_um", "l_um", "area_scaled_caps", "estimator", "measures")
MEASUREMENT = pipeline.MEASUREMENT

TABLES = {
    "rmse": TableSpec("rmse.csv", _KEYS,
                      (*pipeline.RMSE_VALUES, "kept_fraction", "lms_ls_gap"),
                      reference=("rmse",),
                      join=(("s_no", ("s_no",)), ("estimator", ("estimator",)),
                            ("w_um", ("w_um",)), ("l_um", ("l_um",))),
                      optional_join=("w_um", "l_um"),
                      title="RMSE of the output (eqs 3.42, 4.60)",
                      reference_ids=("4.1", "4.2")),
    "health": TableSpec("health.csv", _KEYS[:-1], pipeline.HEALTH_VALUES,
                        title="filter health: divergence, consistency, whiteness"),
    "claims": claims.TABLE,
}
QUOTES = (
    Quote("RMSE over all runs", "rmse", "rmse", by="estimator"),
    Quote("RMSE over the runs that did not diverge, in the cells where a run diverged", "rmse",
          "rmse_kept", by="estimator", where="diverged > 0"),
    Quote("diverged runs", "health", "diverged", by="estimator", total="runs"),
    Quote("inconsistent runs (time-averaged NIS or NEES outside its 95 % band)", "health",
          "inconsistent", by="estimator", total="runs", where="inconsistent == inconsistent"),
)


@dataclass(frozen=True)
class Column:
    w_um: float
    l_um: float
    truth: object
    x0: np.ndarray
    filters: tuple      # (label, estimator, model, measured state indices or None)


def _geometry(config: Config, model_cls, column: dict) -> dict:
    """Parameter overrides a W/L column makes on a model that has them."""
    fields = set(model_cls.Params.__dataclass_fields__)
    out = {}
    if "W_L" in fields:
        out["W_L"] = column.w_um / column.l_um
    geometry = config.geometry
    if geometry.area_scaled_caps:
        factor = column.w_um * column.l_um / geometry.reference_area_um2
        for name in CAPACITANCES:
            if name in fields:
                out[name] = model_cls.Params.__dataclass_fields__[name].default * factor
    return out


@dataclass(frozen=True)
class Plan:
    """Every W/L column's actual circuit and estimators, built once."""

    columns: tuple[Column, ...]


def prepare(config: Config, source: str) -> Plan:
    """Builds the actual circuit and every estimator's model per W/L column."""
    if config.simulation.solver == "ngspice":
        raise ConfigError(source, "simulation.solver", "ngspice is the actual circuit of an "
                          "estimation config only; here: batched_radau or scipy")
    model_cls = registry.MODELS[config.model.name]
    variant = config.model.variant
    columns = config.geometry.columns
    given = [c.to_spec() for c in columns]
    for i, c in enumerate(given):
        if c in given[:i]:
            raise ConfigError(source, f"geometry.columns[{i}]", f"repeats {c}")
    for key in ("input.frequencies_hz", "noise.input_levels"):
        section, name = key.split(".")
        values = getattr(getattr(config, section), name)
        for i, v in enumerate(values):
            if v in values[:i]:
                raise ConfigError(source, f"{key}[{i}]", f"repeats {v!r}")
    check_interval(config.noise.adc_range_v, source, "noise.adc_range_v")
    labels = []
    for i, est in enumerate(config.estimators):
        if est.label in labels or est.label == MEASUREMENT:
            raise ConfigError(source, f"estimators[{i}].label",
                              f"duplicate or reserved label {est.label!r}")
        labels.append(est.label)
    pipeline.check_claims(config.claims, labels, source)
    for i, fig in enumerate(config.figures.names):
        if {"w_um": fig.w_um, "l_um": fig.l_um} not in given:
            raise ConfigError(source, f"figures.names[{i}]",
                              f"no geometry column W = {fig.w_um:g}, L = {fig.l_um:g} um")
    built = []
    for c in columns:
        geo = _geometry(config, model_cls, c)
        truth_params = {**config.model.params, **geo, **config.truth.params}
        truth = build_model(model_cls, variant, truth_params, source, "truth.params")
        x0 = operating_point(truth, [0.0] * truth.n_inputs, source, "model.params")
        filters = []
        for i, est in enumerate(config.estimators):
            path = f"estimators[{i}]"
            cls = registry.MODELS[est.model] if est.model else model_cls
            params = dict(est.model_params) if est.model else {
                **config.model.params, **est.model_params}
            params = {**_geometry(config, cls, c), **params}
            model = build_model(cls, None if est.model else variant, params, source,
                                f"{path}.model_params")
            estimator = build_estimator(registry.ESTIMATORS[est.type], est.settings,
                                        model, source, f"{path}.settings")
            est.settings.clear()      # the manifest records every default
            est.settings.update(estimator.to_spec())
            if model.n_outputs != truth.n_outputs:
                raise ConfigError(source, f"{path}.model", f"{model.name} has "
                                  f"{model.n_outputs} outputs, the circuit {truth.n_outputs}")
            seen = (estimator.measured_states(model)
                    if hasattr(estimator, "measured_states") else None)
            if seen is not None and model.n_states != truth.n_states:
                raise ConfigError(source, f"{path}.model", "an estimator that measures states "
                                  "needs a model with the circuit's states")
            filters.append((est.label, estimator, model, seen))
        built.append(Column(c.w_um, c.l_um, truth, x0, tuple(filters)))
    return Plan(tuple(built))


@dataclass(frozen=True)
class SweepPoint:
    key: tuple[int, int, int]
    reading: str
    level: float
    sigma: float
    frequency_hz: float


def sweep(exp: Experiment) -> list[SweepPoint]:
    noise, inp = exp.config.noise, exp.config.input
    return [SweepPoint((r, i, j), reading, float(level), signals.noise_sigma(level, reading),
                       float(f))
            for r, reading in enumerate(noise.readings)
            for i, level in enumerate(noise.input_levels)
            for j, f in enumerate(inp.frequencies_hz)]


def work_units(exp: Experiment) -> int:
    return len(sweep(exp)) * len(exp.plan.columns)


def work_size(config: Config) -> int:
    n = len(registry.MODELS[config.model.name].state_names)
    inp = config.input
    steps = inp.samples_per_period * inp.periods
    points = (len(config.noise.readings) * len(config.noise.input_levels)
              * len(inp.frequencies_hz))
    stages = config.model.params.get("stages", 1)
    stages = stages if isinstance(stages, int) else 1
    return int(config.monte_carlo.runs * n * stages * steps * points
               * len(config.geometry.columns))


def tiny(config: Config) -> dict:
    """Seconds of work: one frequency, noise level and reading, one geometry column, two
    periods, 3 runs, two LMS passes."""
    out = {"input.frequencies_hz": config.input.frequencies_hz[:1], "input.periods": 2,
           "noise.input_levels": config.noise.input_levels[:1],
           "noise.readings": (config.noise.readings or ["variance"])[:1],
           "geometry.columns": [c.to_spec() for c in config.geometry.columns[:1]],
           "monte_carlo.runs": 3, "figures": {}}
    for i, est in enumerate(config.estimators):
        if est.type == "wavelet_lms":
            out[f"estimators.{i}.settings.epochs"] = 2
    return out


def simulate_point(exp: Experiment, column: Column, point: SweepPoint, runs: int) -> dict:
    """Actual trajectories and measurements of every state for one column and point."""
    inp, noise = exp.config.input, exp.config.noise
    rng = exp.config.monte_carlo.rng(*point.key)
    f = point.frequency_hz
    dt = 1.0 / (inp.samples_per_period * f)
    steps = inp.samples_per_period * inp.periods
    t = np.arange(steps + 1) * dt
    clean = signals.sine(inp.amplitude_v, f, t)
    ou = signals.ornstein_uhlenbeck(rng, point.sigma, noise.gamma, dt, (runs, steps))
    source = clean[None] + ou[..., None]
    sim = exp.config.simulation
    truth = column.truth
    states = SOLVERS[sim.solver](truth, column.x0, truth.source_to_input(source, dt), dt,
                                    rtol=sim.rtol, atol=sim.atol)
    measured = states + noise.measurement_sigma * rng.standard_normal(states.shape)
    if noise.adc_bits is not None:
        lo, hi = noise.adc_range_v
        lsb = (hi - lo) / 2 ** noise.adc_bits
        codes = np.clip(np.round((measured - lo) / lsb), 0, 2 ** noise.adc_bits - 1)
        measured = lo + lsb * codes
    out = int(np.argmax(np.abs(np.asarray(truth.h_jacobian(column.x0)).reshape(-1))))
    return {"t": t[1:], "dt": dt, "x0": column.x0, "source": source, "clean": clean,
            "states": states, "actual": truth.h(states), "measured": measured,
            "z": measured[..., out:out + 1]}


def run_point(exp: Experiment, index: int, point: SweepPoint,
              traces: bool) -> tuple[list, dict, dict]:
    """Rows (measurement baseline, then each estimator) for one column and sweep point, the
    per-run losses for the claims, and with ``traces`` the figure's traces of run 1."""
    column = exp.plan.columns[index]
    data = simulate_point(exp, column, point, exp.config.monte_carlo.runs)
    common = {"data_source": exp.config.truth.data_source, "noise_reading": point.reading,
              "noise_param": point.level, "noise_sigma": point.sigma,
              "frequency_hz": point.frequency_hz, "w_um": column.w_um, "l_um": column.l_um,
              "area_scaled_caps": bool(exp.config.geometry.area_scaled_caps),
              "kept_fraction": float("nan"), "lms_ls_gap": float("nan")}
    out_name = column.truth.state_names[int(np.argmax(np.abs(np.asarray(
        column.truth.h_jacobian(column.x0)).reshape(-1))))]
    estimates = []
    for _, est, model, seen in column.filters:
        z = data["z"] if seen is None else data["measured"][..., seen]
        u = model.source_to_input(data["clean"][None], data["dt"])[0]
        estimates.append(est.run(model, z, u, data["dt"], x0=data["x0"]))
    rows, losses, _ = pipeline.score(exp, data, column.filters, estimates, common, out_name)
    for row, (_, _, model, seen), result in zip(rows[1:], column.filters, estimates,
                                                strict=True):
        row["measures"] = out_name if seen is None else " ".join(model.state_names[i]
                                                                 for i in seen)
        row.update({key: float(np.nanmedian(result.diagnostics[key]))
                    for key in ("kept_fraction", "lms_ls_gap") if key in result.diagnostics})
    trace = {}
    if traces:
        trace = {"t": data["t"], "source": data["source"][0, 1:, 0],
                 "clean": data["clean"][1:, 0], "actual": data["actual"][0, :, 0],
                 "z": data["z"][0, :, 0],
                 "y_hat": {lab: e.y_hat[0, :, 0]
                           for (lab, *_), e in zip(column.filters, estimates, strict=True)}}
    return rows, losses, trace


def _run_point_args(args):
    return run_point(*args)


def _figure_point(exp: Experiment, points: list[SweepPoint]) -> SweepPoint:
    fig = exp.config.figures
    f = fig.frequency_hz or exp.config.input.frequencies_hz[0]
    level = fig.noise_level or exp.config.noise.input_levels[0]
    reading = fig.reading or exp.config.noise.readings[0]
    hit = [p for p in points if p.reading == reading and np.isclose(p.level, level)
           and np.isclose(p.frequency_hz, f)]
    return hit[0] if hit else points[0]


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    points = sweep(exp)
    shown = _figure_point(exp, points)
    named = {(f.w_um, f.l_um): f.name for f in exp.config.figures.names}
    tasks = [(exp, i, p, p == shown and (c.w_um, c.l_um) in named)
             for i, c in enumerate(exp.plan.columns) for p in points]
    done = map_tasks(_run_point_args, tasks, jobs, on_done)
    rows = [row for part, _, _ in done for row in part]
    table_id = exp.config.tables.rmse
    df = pd.DataFrame(rows)
    df["inconsistent"] = pd.array(df["inconsistent"], dtype="Float64").astype("Int64")
    df.insert(0, "table_id", table_id or "")
    df.insert(1, "s_no", pipeline.thesis_row_numbers(df, table_id))
    out = Result(tables={"rmse": df[TABLES["rmse"].columns].reset_index(drop=True)})
    filters = df[df["estimator"] != MEASUREMENT]
    out.tables["health"] = filters[TABLES["health"].columns].reset_index(drop=True)
    out.tables["claims"] = pipeline.claims_table(
        exp.config, out.tables["rmse"], [losses for _, losses, _ in done],
        ("s_no", "noise_reading", "noise_param", "frequency_hz", "w_um", "l_um"))
    for (_, i, p, wanted), (_, _, trace) in zip(tasks, done, strict=True):
        if wanted:
            c = exp.plan.columns[i]
            title = (f"W = {c.w_um:g} µm, L = {c.l_um:g} µm, {p.frequency_hz:g} Hz, "
                     f"O.U. input noise {p.level:g} ({p.reading})")
            out.figures[named[(c.w_um, c.l_um)]] = plots.estimates_clipped(trace, title)
    return out


def printout(result: Result) -> str:
    df = result.tables["rmse"]
    view = df.pivot_table(index=["noise_reading", "noise_param", "frequency_hz"],
                          columns=["w_um", "l_um", "estimator"], values="rmse", sort=False)
    return view.to_string(float_format=lambda v: f"{v:.4g}")

