"""Estimators against the actual circuit on noisy measurements (thesis Chapter 3).

For each sweep point (noise reading x noise level x input frequency, in thesis row order):

1. the source is the nominal sine plus white Gaussian noise at every sample after ``t_0``
   (the "Gaussian noise at input source" of Tables 3.1-3.5), piecewise linear between
   samples;
2. the actual circuit is integrated with a stiff solver (:mod:`estim.simulate`; the batched
   Radau IIA by default, scipy's ``solve_ivp`` with ``simulation.solver: scipy``) from its DC
   operating point;
3. measurements are the actual output plus white measurement noise;
4. every estimator sees the measurements and the nominal input (or the noisy one, when
   ``noise.filters_see`` is ``noisy``, measured with ``noise.input_sensor_sigma`` of its
   own noise), fed to it as ``estimators[i].input_derivative`` says, and starts from the
   actual DC operating point;
5. every filter's health is judged (:mod:`estim.health`): NEES against the actual states,
   NIS, whiteness of the innovations, and divergence by the stated criterion;
6. RMSE (eq 3.42) is reported over the runs that did not diverge and over all runs
   (mean with its standard error, and median; a run the filter broke on counts as an
   infinite error), beside a "measurement" row, the raw measurement's own RMSE; residual
   statistics are over the runs that did not diverge.

Each sweep point draws from its own ``SeedSequence(seed, spawn_key=(point,))``, so any cell
can be re-run alone and comes out the same.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from estim import (
    claims,
    health,
    kalman_differentiator,
    metrics,
    plots,
    registry,
    signals,
    tables,
    tuning,
)
from estim.analyses.base import Result, TableSpec, map_tasks
from estim.errors import ConfigError, UsageError
from estim.estimators.base import as_matrix
from estim.schema import (
    MAX_VOLTS,
    REQUIRED,
    Experiment,
    boolean,
    build_estimator,
    build_model,
    check_input_vector,
    file_name,
    integer,
    list_of,
    mapping,
    model_block,
    number,
    operating_point,
    simulation_block,
    text,
    validate,
)
from estim.simulate import SOLVERS
from estim.summary import Quote

FIGURE_KINDS = ("noiseless", "noisy", "rmse", "residual")
DERIVATIVE_METHODS = {"difference", "analytic", "kalman"}
"""How a filter gets ``dv_in/dt`` for a model whose input is the source's slope (eq 3.26):
the difference of the samples it sees on each interval (the default), the nominal sine's
derivative at the interval's midpoint, or the Kalman differentiator of the samples it sees
(``derivative_bandwidth`` times the input frequency; :mod:`estim.kalman_differentiator`)."""
_READING = text({"sigma", "variance"})

SCHEMA: dict = {
    "model": model_block(registry.MODELS),
    "input": ({
        "waveform": (text({"sine"}), "sine"),
        "amplitude_v": (number(minimum=0.0, maximum=MAX_VOLTS), REQUIRED),
        "frequencies_hz": (list_of(number(minimum=1e-3, maximum=1e9)), REQUIRED),
        "samples_per_period": (integer(2, 10_000), 10),
        "sample_time_s": (number(minimum=1e-12, maximum=1e3), None),
        "periods": (integer(1, 100_000), None),
        "duration_s": (number(minimum=1e-9, maximum=1e4), None),
        "bias_v": (list_of(number(minimum=-MAX_VOLTS, maximum=MAX_VOLTS)), [0.0]),
        "mix": (list_of(number(minimum=-1e3, maximum=1e3)), [1.0]),
    }, REQUIRED),
    "noise": ({
        "input_levels": (list_of(number(positive=True, maximum=MAX_VOLTS)), REQUIRED),
        "readings": (list_of(_READING, unique=True), ["sigma"]),
        "measurement_sigma": (number(minimum=0.0, maximum=MAX_VOLTS), REQUIRED),
        "measurement": (list_of(text({"noisy", "noise_free"}), unique=True, max_length=2),
                        ["noisy"]),
        "filters_see": (text({"nominal", "noisy"}), "nominal"),
        "input_sensor_sigma": (number(minimum=0.0, maximum=MAX_VOLTS), 0.0),
        "pairs": (boolean, False),
    }, REQUIRED),
    "simulation": simulation_block(rtol=1e-6, atol=1e-7),
    "estimators": (list_of({
        "label": (text(max_length=60), REQUIRED),
        "type": (text(registry.ESTIMATORS), REQUIRED),
        "model_params": (mapping, {}),
        "settings": (mapping, {}),
        "input_derivative": (text(DERIVATIVE_METHODS), "difference"),
        "derivative_bandwidth": (number(minimum=0.1, maximum=1000.0), 3.0),
    }, max_length=20), REQUIRED),
    "monte_carlo": ({
        "runs": (integer(1, 1_000_000), REQUIRED),
        "seed": (integer(0, 2**63 - 1), REQUIRED),
    }, REQUIRED),
    "tables": ({
        "rmse": (text(), None),
        "residual": (text(), None),
    }, REQUIRED),
    "regime": (text(max_length=60), None),
    "health": ({
        "band": (number(minimum=0.5, maximum=0.9999), health.DEFAULTS["band"]),
        "whiteness_lag": (integer(1, 1000), health.DEFAULTS["lag"]),
        "whiteness_level": (number(minimum=1e-6, maximum=0.5), health.DEFAULTS["white_level"]),
        "consecutive": (integer(1, 1_000_000), health.DEFAULTS["consecutive"]),
        "growth": (number(minimum=1.5, maximum=1e6), health.DEFAULTS["growth"]),
    }, {}),
    "claims": (list_of({
        "better": (text(max_length=60), REQUIRED),
        "worse": (text(max_length=60), REQUIRED),
    }, nonempty=False, max_length=20), []),
    "figures": ({
        "frequency_hz": (number(minimum=1e-3, maximum=1e9), None),
        "noise_level": (number(positive=True, maximum=MAX_VOLTS), None),
        "reading": (_READING, None),
        "names": (mapping, {}),
        "extra_noisy": (list_of({
            "noise_level": (number(positive=True, maximum=MAX_VOLTS), REQUIRED),
            "reading": (_READING, "sigma"),
            "name": (file_name, REQUIRED),
        }, nonempty=False, max_length=20), []),
    }, {}),
}

_ROW_KEYS = ("table_id", "s_no", "measurement", "noise_reading", "noise_param", "noise_sigma",
             "frequency_hz", "samples_per_period", "estimator")
_JOIN = (("s_no", ("s_no",)), ("estimator", ("estimator",)))

MEASUREMENT = "measurement"
"""Label of the baseline row: the raw measurement taken as the estimate."""

RMSE_VALUES = ("rmse", "rmse_se", "rmse_median", "runs", "diverged", "rmse_kept",
               "rmse_kept_se")
"""RMSE over every run (the headline; a run whose estimate broke counts as an infinite
error), its standard error and median, the runs and how many diverged, and the RMSE over
the runs that did not diverge."""
HEALTH_VALUES = ("runs", "broken", "diverged", "inconsistent", "nees_mean", "nees_in_band",
                 "nis_mean", "nis_in_band", "white_fraction", "whiteness_lag")

TABLES = {
    "rmse": TableSpec("rmse.csv", (*_ROW_KEYS, "regime"), (*RMSE_VALUES, "regime_fraction"),
                      reference=("rmse",), join=_JOIN, title="RMSE (eq 3.42)",
                      reference_ids=("3.1", "3.2", "3.5")),
    "health": TableSpec("health.csv", _ROW_KEYS,
                        (*HEALTH_VALUES, "regressor_rank", "regressor_size", "lambda_at_floor",
                         "p_max_eig"),
                        title="filter health: divergence, consistency, whiteness, excitation"),
    "residual": TableSpec("residual.csv", _ROW_KEYS,
                          ("residual_mean", "residual_mean_se", "residual_variance",
                           "residual_variance_se", "runs", "diverged"),
                          reference=("residual_mean", "residual_variance"), join=_JOIN,
                          title="residual (innovation) mean and variance, runs that did not "
                                "diverge",
                          reference_ids=("3.3", "3.4")),
    "claims": claims.TABLE,
}

QUOTES = (
    Quote("RMSE over all runs", "rmse", "rmse", by="estimator"),
    Quote("RMSE over the runs that did not diverge", "rmse", "rmse_kept", by="estimator",
          where="diverged > 0"),
    Quote("fraction of actual samples in the named regime", "rmse", "regime_fraction",
          where="estimator == 'measurement'"),
    Quote("diverged runs", "health", "diverged", by="estimator", total="runs"),
    Quote("inconsistent runs (time-averaged NIS or NEES outside its 95 % band)", "health",
          "inconsistent", by="estimator", total="runs", where="inconsistent == inconsistent"),
    Quote("residual mean", "residual", "residual_mean", by="estimator"),
)
"""What ``estim summary`` quotes of an estimation experiment (:mod:`estim.summary`)."""


@dataclass(frozen=True)
class Plan:
    """What an estimation experiment builds once: the actual circuit and, per estimator,
    its label, the estimator object and the model it filters with."""

    truth: object
    filters: tuple
    x0: object
    inputs: tuple = ()
    """Per estimator: its ``(input_derivative, derivative_bandwidth)``."""


def prepare(spec: dict, source: str) -> Plan:
    """Cross-checks beyond the schema; builds the models and estimators once."""
    model_cls = registry.MODELS[spec["model"]["name"]]
    variant = spec["model"]["variant"]
    inp, noise = spec["input"], spec["noise"]
    if (inp["periods"] is None) == (inp["duration_s"] is None):
        raise ConfigError(source, "input.periods",
                          "give exactly one of input.periods and input.duration_s")
    for key in ("bias_v", "mix"):
        check_input_vector(inp[key], model_cls, source, f"input.{key}")
    if noise["pairs"]:
        if len(noise["input_levels"]) != len(inp["frequencies_hz"]):
            raise ConfigError(source, "noise.pairs", "with pairs: true, noise.input_levels and "
                              "input.frequencies_hz must have the same length")
        cells = list(zip(noise["input_levels"], inp["frequencies_hz"], strict=True))
        for i, cell in enumerate(cells):
            if cell in cells[:i]:
                raise ConfigError(source, f"input.frequencies_hz[{i}]",
                                  f"repeats the (noise level, frequency) pair {cell}")
    else:
        for key, values in (("noise.input_levels", noise["input_levels"]),
                            ("input.frequencies_hz", inp["frequencies_hz"])):
            for i, v in enumerate(values):
                if v in values[:i]:
                    raise ConfigError(source, f"{key}[{i}]", f"repeats {v!r}")
    if noise["input_sensor_sigma"] > 0 and noise["filters_see"] != "noisy":
        raise ConfigError(source, "noise.input_sensor_sigma", "applies only when the filters "
                          "see the noisy source (noise.filters_see: noisy)")
    truth = build_model(model_cls, variant, spec["model"]["params"], source, "model.params")
    x0 = operating_point(truth, inp["bias_v"], source, "model.params")
    filters, labels = [], []
    for i, est in enumerate(spec["estimators"]):
        path = f"estimators[{i}]"
        if est["label"] in labels:
            raise ConfigError(source, f"{path}.label", f"duplicate label {est['label']!r}")
        if est["label"] == MEASUREMENT:
            raise ConfigError(source, f"{path}.label", f"{MEASUREMENT!r} is the label of the "
                              "raw-measurement baseline row; choose another")
        labels.append(est["label"])
        model = build_model(model_cls, variant, {**spec["model"]["params"], **est["model_params"]},
                            source, f"{path}.model_params")
        estimator = build_estimator(registry.ESTIMATORS[est["type"]], est["settings"], model,
                                    source, f"{path}.settings")
        filters.append((est["label"], estimator, model))
        if est["input_derivative"] != "difference" and not model_cls.input_is_source_slope:
            raise ConfigError(source, f"{path}.input_derivative",
                              f"model {spec['model']['name']}'s input is not the derivative of "
                              "its source; only 'difference' (the model's own mapping) applies")
    regime = spec["regime"]
    if regime is not None and regime not in truth.regimes:
        raise ConfigError(source, "regime", f"expected one of {list(truth.regimes)} for "
                          f"model {spec['model']['name']}, got {regime!r}")
    if not any(spec["tables"].values()):
        raise ConfigError(source, "tables", "expected at least one of tables.rmse and "
                          "tables.residual")
    for i, claim in enumerate(spec["claims"]):
        for side in ("better", "worse"):
            if claim[side] not in labels:
                raise ConfigError(source, f"claims[{i}].{side}",
                                  f"expected an estimator label {labels}, got {claim[side]!r}")
        if spec["tables"]["rmse"] is None:
            raise ConfigError(source, "claims", "claims compare RMSEs: set tables.rmse")
    names = spec["figures"]["names"]
    for kind, name in names.items():
        if kind not in FIGURE_KINDS:
            raise ConfigError(source, f"figures.names.{kind}",
                              f"unknown figure kind; expected one of {list(FIGURE_KINDS)}")
        validate(name, file_name, source, f"figures.names.{kind}")
    used = {names.get(kind, kind): f"figures.names.{kind}" for kind in FIGURE_KINDS}
    if len(used) < len(FIGURE_KINDS):
        raise ConfigError(source, "figures.names", "two figure kinds share one file name")
    for i, extra in enumerate(spec["figures"]["extra_noisy"]):
        if extra["name"] in used:
            raise ConfigError(source, f"figures.extra_noisy[{i}].name",
                              f"{extra['name']!r} is already the file of {used[extra['name']]}")
        used[extra["name"]] = f"figures.extra_noisy[{i}].name"
    dt = inp["sample_time_s"]
    if dt is not None and dt * max(inp["frequencies_hz"]) > 10:
        raise ConfigError(source, "input.sample_time_s",
                          f"{dt:g} s samples the highest input frequency "
                          f"{max(inp['frequencies_hz']):g} Hz fewer than once in ten periods")
    inputs = tuple((e["input_derivative"], e["derivative_bandwidth"])
                   for e in spec["estimators"])
    return Plan(truth=truth, filters=tuple(filters), x0=x0, inputs=inputs)


def work_size(spec: dict) -> int:
    """State-samples of the actual signal over every sweep point and figure batch."""
    n = len(registry.MODELS[spec["model"]["name"]].state_names)
    inp, mc = spec["input"], spec["monte_carlo"]
    per_freq = 0
    for f in inp["frequencies_hz"]:
        dt = inp["sample_time_s"] or 1.0 / (inp["samples_per_period"] * f)
        span = inp["duration_s"] if inp["duration_s"] is not None else (
            (inp["periods"] or 1) / f)
        per_freq += span / dt
    batches = len(spec["noise"]["readings"]) * len(spec["noise"]["input_levels"])
    if spec["noise"]["pairs"]:
        batches = len(spec["noise"]["readings"])
    batches *= len(spec["noise"]["measurement"])
    figures = 2 + len(spec["figures"]["extra_noisy"])
    return int(mc["runs"] * n * (per_freq * batches + figures * per_freq))


def tiny(spec: dict) -> dict:
    """Seconds of work: one frequency, one noise level and reading, two periods, 3 runs."""
    spec["input"].update(frequencies_hz=spec["input"]["frequencies_hz"][:1])
    if spec["input"].get("periods") is not None:
        spec["input"]["periods"] = 2
    else:
        spec["input"]["duration_s"] = 2.0 / spec["input"]["frequencies_hz"][0]
    spec["noise"].update(input_levels=spec["noise"]["input_levels"][:1],
                         readings=(spec["noise"].get("readings") or ["sigma"])[:1],
                         measurement=(spec["noise"].get("measurement") or ["noisy"])[:1])
    spec["monte_carlo"]["runs"] = 3
    spec["figures"] = {"names": (spec.get("figures") or {}).get("names", {})}
    return spec


@dataclass(frozen=True)
class SweepPoint:
    index: int
    measurement: str
    reading: str
    level: float
    sigma: float
    frequency_hz: float


def sweep(exp: Experiment) -> list[SweepPoint]:
    """Sweep points in thesis row order: measurement reading, noise reading, noise level,
    then frequency (or the (level, frequency) pairs in the order given, with
    ``noise.pairs``). ``noise.measurement``: ``noisy``, the measured output plus white noise
    of ``measurement_sigma``; ``noise_free``, the actual output itself (the filters keep
    their ``R``)."""
    noise, inp = exp.spec["noise"], exp.spec["input"]
    if noise["pairs"]:
        cells = list(zip(noise["input_levels"], inp["frequencies_hz"], strict=True))
    else:
        cells = [(level, f) for level in noise["input_levels"] for f in inp["frequencies_hz"]]
    points = []
    for measurement in noise["measurement"]:
        for reading in noise["readings"]:
            for level, f in cells:
                points.append(SweepPoint(len(points), measurement, reading, float(level),
                                         signals.noise_sigma(level, reading), float(f)))
    return points


def work_units(exp: Experiment) -> int:
    return len(sweep(exp)) + 1


def sampling(exp: Experiment, frequency_hz: float) -> tuple[float, int]:
    """Sample time and number of samples after ``t_0`` for one input frequency."""
    inp = exp.spec["input"]
    dt = inp["sample_time_s"] or 1.0 / (inp["samples_per_period"] * frequency_hz)
    if inp["duration_s"] is not None:
        return dt, max(1, round(inp["duration_s"] / dt))
    return dt, max(1, round(inp["periods"] / (frequency_hz * dt)))


def simulate_point(exp: Experiment, frequency_hz: float, sigma: float, runs: int,
                   rng: np.random.Generator, measurement: str = "noisy") -> dict:
    """Actual trajectories and measurements for one frequency and input-noise level."""
    inp, noise = exp.spec["input"], exp.spec["noise"]
    truth = exp.plan.truth
    dt, steps = sampling(exp, frequency_hz)
    t = np.arange(steps + 1) * dt
    mix, bias = np.asarray(inp["mix"], float), np.asarray(inp["bias_v"], float)
    clean = bias + signals.sine(inp["amplitude_v"], frequency_hz, t) * mix
    input_noise = signals.gaussian(rng, sigma, (runs, steps + 1, 1)) * mix
    input_noise[:, 0] = 0.0    # the circuit starts at its operating point with v_in(t_0) known
    source = clean[None] + input_noise
    x0 = exp.plan.x0           # the DC point with the source held at its value at t_0
    sim = exp.spec["simulation"]
    states = SOLVERS[sim["solver"]](truth, x0, truth.source_to_input(source, dt), dt,
                                    rtol=sim["rtol"], atol=sim["atol"])
    actual = truth.h(states)
    z = actual + signals.gaussian(rng, noise["measurement_sigma"], actual.shape)
    if measurement == "noise_free":
        z = actual.copy()
    seen = clean[None] if noise["filters_see"] == "nominal" else source
    if noise["input_sensor_sigma"] > 0:        # the filters measure the source imperfectly
        seen = seen + signals.gaussian(rng, noise["input_sensor_sigma"], source.shape) * mix
        seen[:, 0] = source[:, 0]               # v_in(t_0) is known, as for the circuit
    return {"t": t[1:], "dt": dt, "x0": x0, "source": source, "clean": clean, "seen": seen,
            "frequency_hz": frequency_hz, "states": states, "actual": actual, "z": z,
            "u": truth.source_to_input(seen, dt)}


def filter_input(exp: Experiment, data: dict, method: str, bandwidth: float) -> np.ndarray:
    """The input a filter is given on each sample interval (:data:`DERIVATIVE_METHODS`)."""
    if method == "difference":
        return data["u"]
    inp, f, dt = exp.spec["input"], data["frequency_hz"], data["dt"]
    mix = np.asarray(inp["mix"], float)
    if method == "analytic":
        w = 2 * np.pi * f
        middle = data["t"] - dt / 2
        return (inp["amplitude_v"] * w * np.cos(w * middle))[None, :, None] * mix
    slopes = kalman_differentiator.with_bandwidth(data["seen"], dt, bandwidth * f)
    return 0.5 * (slopes[:, 1:] + slopes[:, :-1])


def estimate_point(exp: Experiment, data: dict) -> list:
    """Run every configured estimator on one simulated batch."""
    inputs = exp.plan.inputs or (("difference", 0.0),) * len(exp.plan.filters)
    return [est.run(model, data["z"], filter_input(exp, data, *how), data["dt"], x0=data["x0"])
            for (_, est, model), how in zip(exp.plan.filters, inputs, strict=True)]


def judge(exp: Experiment, data: dict, est, model) -> dict:
    """One estimator's health on one batch (:mod:`estim.health`): per run ``diverged`` (the
    estimate broke or ran away), ``broken`` and ``inconsistent`` (NIS or NEES outside its
    band; NaN-free only for filters with a noise model), and the batch summaries."""
    cfg = exp.spec["health"]
    nis = None if est.S is None else health.nis(est.innovation, est.S)
    nees = None
    if est.x_hat is not None and est.P is not None and est.x_hat.shape == data["states"].shape:
        nees = health.nees(data["states"], est.x_hat, est.P)
    out = {"diverged": health.diverged(est, data["actual"], model.output_range(),
                                       cfg["consecutive"], cfg["growth"]),
           "broken": np.asarray(est.broken, bool),
           "inconsistent": health.inconsistent(nis, est.innovation.shape[-1], nees,
                                               0 if est.x_hat is None else est.x_hat.shape[-1],
                                               cfg["band"])}
    nan = float("nan")
    out["nees_mean"] = out["nees_in_band"] = out["nis_mean"] = out["nis_in_band"] = nan
    if nees is not None:
        out["nees_mean"], out["nees_in_band"] = health.averaged_in_band(
            nees, est.x_hat.shape[-1], cfg["band"])
    if nis is not None:
        out["nis_mean"], out["nis_in_band"] = health.averaged_in_band(
            nis, est.innovation.shape[-1], cfg["band"])
    out["white_fraction"] = float(np.mean(health.white(
        est.innovation, cfg["whiteness_lag"], cfg["whiteness_level"])))
    out["whiteness_lag"] = health.effective_lag(est.innovation.shape[1], cfg["whiteness_lag"])
    for key in ("regressor_rank", "regressor_size", "lambda_at_floor", "p_max_eig"):
        values = np.asarray(est.diagnostics.get(key, []), float)
        finite = values[np.isfinite(values)]
        out[key] = float(np.median(finite)) if finite.size else nan
    return out


def rmse_columns(actual: np.ndarray, y_hat: np.ndarray, diverged: np.ndarray) -> tuple[dict,
                                                                                       np.ndarray]:
    """The RMSE columns (:data:`RMSE_VALUES`) of one estimator on one batch, and its per-run
    RMSE (a run whose estimate is not finite has an infinite error): the loss its claims
    compare."""
    with np.errstate(invalid="ignore", over="ignore"):
        per_run = metrics.rmse_per_run(actual, y_hat)
    per_run = np.where(np.isfinite(per_run), per_run, np.inf)
    if np.isinf(per_run).any():
        mean, se = float("inf"), float("nan")
    else:
        mean, se = metrics.mean_and_se(per_run)
    kept, kept_se = metrics.mean_and_se(per_run[~diverged])
    return {"rmse": mean, "rmse_se": se, "rmse_median": float(np.median(per_run)),
            "runs": int(per_run.size), "diverged": int(diverged.sum()), "rmse_kept": kept,
            "rmse_kept_se": kept_se}, per_run


def score(exp: Experiment, data: dict, filters: tuple, estimates: list, common: dict,
          measured: str = "") -> tuple[list[dict], dict, list]:
    """Rows of every table for one batch: the raw measurement's row, then one per filter
    (``filters``: ``(label, estimator, model, ...)``, with their ``estimates``), each with
    its RMSE, health and residual columns; the per-run losses of every row for the claims;
    and each filter's per-run divergence flags. ``measured`` names what the measurement row
    measures, when the table says."""
    raw = metrics.rmse_per_run(data["actual"], data["z"])
    none = np.zeros(raw.size, bool)
    columns, _ = rmse_columns(data["actual"], data["z"], none)
    rows = [{**common, **columns, "estimator": MEASUREMENT, "broken": 0,
             **({"measures": measured} if measured else {})}]
    losses = {MEASUREMENT: claims.Losses(raw)}
    verdicts = []
    for (label, _, model, *_), est in zip(filters, estimates, strict=True):
        verdict = judge(exp, data, est, model)
        diverged = verdict["diverged"]
        verdicts.append(diverged)
        columns, per_run = rmse_columns(data["actual"], est.y_hat, diverged)
        ok = ~diverged
        res_mean, res_var = metrics.residual_stats(est.innovation[ok])
        mean, mean_se = metrics.mean_and_se(res_mean)
        var, var_se = metrics.mean_and_se(res_var)
        flags = verdict["inconsistent"]
        rows.append({
            **common, **{k: v for k, v in verdict.items()
                         if k not in ("diverged", "broken", "inconsistent")},
            **columns, "estimator": label,
            "broken": int(verdict["broken"].sum()),
            "inconsistent": float("nan") if flags is None else int(flags.sum()),
            "residual_mean": mean, "residual_mean_se": mean_se,
            "residual_variance": var, "residual_variance_se": var_se,
        })
        losses[label] = claims.Losses(per_run, diverged)
    return rows, losses, verdicts


def run_point(exp: Experiment, point: SweepPoint, traces: bool = False) -> tuple[list, dict,
                                                                                  dict]:
    """Table rows (the measurement baseline, then one per estimator) for one sweep point,
    the per-run losses for the claims, and with ``traces`` the figure traces of its first
    run (the figures show the runs the table averages)."""
    mc = exp.spec["monte_carlo"]
    rng = np.random.default_rng(np.random.SeedSequence(mc["seed"], spawn_key=(point.index,)))
    data = simulate_point(exp, point.frequency_hz, point.sigma, mc["runs"], rng,
                          point.measurement)
    estimates = estimate_point(exp, data)
    regime = exp.spec["regime"]
    fraction = float("nan") if regime is None else float(np.mean(exp.plan.truth.in_regime(
        regime, data["states"], data["source"][:, 1:])))
    common = {"measurement": point.measurement, "noise_reading": point.reading,
              "noise_param": point.level,
              "noise_sigma": point.sigma, "frequency_hz": point.frequency_hz,
              "samples_per_period": 1.0 / (point.frequency_hz * data["dt"]),
              "regime": regime or "", "regime_fraction": fraction}
    rows, losses, verdicts = score(exp, data, exp.plan.filters, estimates, common)
    return rows, losses, (_traces(exp, data, estimates, verdicts) if traces else {})


def _traces(exp: Experiment, data: dict, estimates: list, diverged: list) -> dict:
    """What a figure draws of a batch: run 0's signals and every estimator's running RMSE
    over the runs that did not diverge."""
    labels = [label for label, _, _ in exp.plan.filters]
    pairs = list(zip(labels, estimates, strict=True))
    kept = dict(zip(labels, diverged, strict=True))
    return {
        "t": data["t"], "source": data["source"][0, 1:, 0], "clean": data["clean"][1:, 0],
        "actual": data["actual"][0, :, 0], "z": data["z"][0, :, 0],
        "y_hat": {lab: e.y_hat[0, :, 0] for lab, e in pairs},
        "innovation": {lab: e.innovation[0, :, 0] for lab, e in pairs},
        "running_rmse": {lab: metrics.running_rmse(data["actual"][~kept[lab]],
                                                   e.y_hat[~kept[lab]]) for lab, e in pairs},
    }


def _run_point_args(args):
    return run_point(*args)


FIGURE_SEED_KEY = 2**31
"""Figure batches that are not a sweep point draw from ``spawn_key=(FIGURE_SEED_KEY, i)``: a
key space no sweep point reaches."""


def figure_cases(exp: Experiment) -> list[tuple[str, float, float, str]]:
    """``(key, frequency, noise level, reading)`` of every noisy figure batch: the figure's
    point and each ``figures.extra_noisy`` case."""
    fig = exp.spec["figures"]
    f = fig["frequency_hz"] or exp.spec["input"]["frequencies_hz"][0]
    level = fig["noise_level"] or exp.spec["noise"]["input_levels"][0]
    reading = fig["reading"] or exp.spec["noise"]["readings"][0]
    cases = [("noisy", f, level, reading)]
    cases += [(extra["name"], f, extra["noise_level"], extra["reading"])
              for extra in fig["extra_noisy"]]
    return cases


def thesis_row_numbers(rows: pd.DataFrame, table_id: str | None) -> pd.Series:
    """The thesis row (``s_no``) of each of our rows: same noise number and frequency (none
    where ``table_id`` is a label of our own, not a thesis table)."""
    if table_id is None or not tables.has_reference_table(table_id):
        return pd.Series([pd.NA] * len(rows), dtype="Int64")
    ref = tables.reference_table(table_id).drop_duplicates("s_no")
    s_no = []
    for level, f in zip(rows["noise_param"], rows["frequency_hz"], strict=True):
        hit = ref[np.isclose(ref["noise_param_value"], level) & np.isclose(ref["frequency_hz"], f)]
        s_no.append(int(hit["s_no"].iloc[0]) if len(hit) else pd.NA)
    return pd.Series(s_no, dtype="Int64")


def result_table(rows: list[dict], metric: str, table_id: str | None) -> pd.DataFrame:
    """The ``metric`` table from the sweep's rows, with thesis table id and row number."""
    df = pd.DataFrame(rows)
    if "inconsistent" in df:
        df["inconsistent"] = pd.array(df["inconsistent"], dtype="Float64").astype("Int64")
    df.insert(0, "table_id", table_id if table_id and table_id != tables.OWN_TABLE else "")
    df.insert(1, "s_no", thesis_row_numbers(df, table_id))
    return df[TABLES[metric].columns].reset_index(drop=True)


def claim_pairs(spec: dict) -> list[tuple[str, str]]:
    """The claims an estimation table judges: the config's ``claims`` (the thesis' headline),
    then every filter against the raw measurement."""
    pairs = [(c["better"], c["worse"]) for c in spec["claims"]]
    pairs += [(e["label"], MEASUREMENT) for e in spec["estimators"]
              if (e["label"], MEASUREMENT) not in pairs]
    return pairs


def claims_table(spec: dict, rmse: pd.DataFrame, losses: list[dict],
                 keys: tuple[str, ...]) -> pd.DataFrame:
    """The claims of :func:`claim_pairs` judged by :mod:`estim.claims` in every cell; a cell
    is named by the ``keys`` of its rows in ``rmse`` (its first row per cell, in order)."""
    firsts = rmse[rmse["estimator"] == MEASUREMENT]
    cells = [(claims.cell(**{k: row[k] for k in keys}), cell_losses)
             for (_, row), cell_losses in zip(firsts.iterrows(), losses, strict=True)]
    return claims.table(cells, claim_pairs(spec), "RMSE")


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    """All sweep points (rows in thesis order whatever the number of jobs), the claims and
    the figures, drawn from the table's own batches where a figure shows a sweep point."""
    points = sweep(exp)
    wanted: dict[int, list[str]] = {}
    for key, f, level, reading in figure_cases(exp):
        match = next((p for p in points if p.measurement == points[0].measurement
                      and p.reading == reading and np.isclose(p.level, level)
                      and np.isclose(p.frequency_hz, f)), None)
        if match is not None:
            wanted.setdefault(match.index, []).append(key)
    tasks = [(exp, p, p.index in wanted) for p in points]
    done = map_tasks(_run_point_args, tasks, jobs, on_done)
    rows = [row for part, _, _ in done for row in part]
    known = {key: done[index][2] for index, keys in wanted.items() for key in keys}
    out = Result(tables={})
    filters_only = [row for row in rows if row["estimator"] != MEASUREMENT]
    table_id = exp.spec["tables"]["rmse"] or exp.spec["tables"]["residual"]
    rmse = result_table(rows, "rmse", table_id)
    for metric, table_id_ in exp.spec["tables"].items():
        if table_id_ is not None:
            out.tables[metric] = (result_table(rows, metric, table_id_) if metric == "rmse"
                                  else result_table(filters_only, metric, table_id_))
    out.tables["health"] = result_table(filters_only, "health", table_id)
    out.tables["claims"] = claims_table(exp.spec, rmse, [losses for _, losses, _ in done],
                                        ("s_no", "measurement", "noise_reading", "noise_param",
                                         "frequency_hz"))
    out.figures = figures(exp, known)
    if on_done:
        on_done()
    return out


def figure_traces(exp: Experiment, known: dict) -> dict:
    """Traces of every figure: the noiseless run (one run, its own seed) and the noisy
    cases, taken from ``known`` (traces of sweep points) or simulated with their own seed."""
    mc = exp.spec["monte_carlo"]
    cases = figure_cases(exp)
    f = cases[0][1]
    batches = [("noiseless", 0.0, 1)] + [
        (key, signals.noise_sigma(level, reading), mc["runs"]) for key, _, level, reading in cases]
    out = {}
    for i, (key, sigma, runs) in enumerate(batches):
        if key in known:
            out[key] = known[key]
            continue
        rng = np.random.default_rng(np.random.SeedSequence(mc["seed"],
                                                           spawn_key=(FIGURE_SEED_KEY, i)))
        data = simulate_point(exp, f, sigma, runs, rng, exp.spec["noise"]["measurement"][0])
        estimates = estimate_point(exp, data)
        verdicts = [judge(exp, data, est, model)["diverged"]
                    for (_, _, model), est in zip(exp.plan.filters, estimates, strict=True)]
        out[key] = _traces(exp, data, estimates, verdicts)
    return out


def figures(exp: Experiment, known: dict) -> dict:
    """Figs 3.2-3.7, 3.9-3.11: estimates without and with input noise, running RMSE and
    residuals, under the names of ``figures.names``."""
    data = figure_traces(exp, known)
    names = exp.spec["figures"]["names"]
    _, f, level, reading = figure_cases(exp)[0]
    what = exp.spec["title"] or exp.name
    period = 1.0 / f

    def noise(level: float, reading: str) -> str:
        return (f"input noise sigma = {level:g} V" if reading == "sigma"
                else f"input noise variance = {level:g} V^2")

    where = f"{f:g} Hz, {noise(level, reading)}"
    makers = {
        "noiseless": lambda: plots.estimates(data["noiseless"], f"{what}; {f:g} Hz, no input "
                                             "noise", period),
        "noisy": lambda: plots.estimates(data["noisy"], f"{what}; {where}", period),
        "rmse": lambda: plots.running_rmse(data["noisy"], f"RMSE over runs: {what}; {where}"),
        "residual": lambda: plots.residuals(data["noisy"], f"Residual (run 1): {what}; {where}"),
    }
    out = {names.get(kind, kind): makers[kind]() for kind in FIGURE_KINDS}
    for extra in exp.spec["figures"]["extra_noisy"]:
        title = f"{what}; {f:g} Hz, {noise(extra['noise_level'], extra['reading'])}"
        out[extra["name"]] = plots.estimates(data[extra["name"]], title, period)
    return out


def summary(result: Result) -> str:
    """RMSE by estimator (columns) and sweep point (rows)."""
    df = result.tables.get("rmse")
    if df is None:
        return ""
    view = df.pivot(index=["measurement", "noise_reading", "noise_param", "frequency_hz"],
                    columns="estimator", values="rmse")
    return view.to_string(float_format=lambda v: f"{v:.4g}")


TUNE_SEED_KEY = 2**32
"""Training draws of :func:`tune` use ``spawn_key=(TUNE_SEED_KEY, point)``: independent of
every table and figure batch."""


def tune(exp: Experiment, label: str, runs: int, fit_r: bool = False) -> tuple[dict, object]:
    """Maximum-likelihood ``Q`` (and ``R``) of estimator ``label`` (:mod:`estim.tuning`) on
    training draws of ``runs`` runs at every sweep point, pooled: one setting for the table,
    as the thesis uses one (points with a noise-free measurement are left out when noisy
    ones exist: the likelihood assumes the measurement noise ``R`` describes). Returns the
    estimator's config entry with the fitted diagonals and the :class:`estim.tuning.Fit`."""
    found = [(i, est, model) for i, (lab, est, model) in enumerate(exp.plan.filters)
             if lab == label]
    if not found:
        raise UsageError(f"{exp.name}: no estimator labelled {label!r}; expected one of "
                         f"{[lab for lab, _, _ in exp.plan.filters]}")
    index, est, model = found[0]
    if not (hasattr(est, "Q") and hasattr(est, "R")):
        raise UsageError(f"{exp.name}: {label!r} has no noise covariances to fit")
    mc = exp.spec["monte_carlo"]
    batches = []
    points = sweep(exp)
    noisy = [p for p in points if p.measurement == "noisy"]
    for p in noisy or points:
        rng = np.random.default_rng(np.random.SeedSequence(mc["seed"],
                                                           spawn_key=(TUNE_SEED_KEY, p.index)))
        batches.append(simulate_point(exp, p.frequency_hz, p.sigma, runs, rng, p.measurement))
    n, m = model.n_states, model.n_outputs
    q0 = np.diag(as_matrix(est.Q, n, "Q")).copy()
    r0 = np.diag(as_matrix(est.R, m, "R")).copy()
    q0[q0 <= 0] = 1e-12 * max(float(q0.max()), 1e-300)

    def evaluate(q, r):
        trial = copy.copy(est)
        trial.Q, trial.R = list(q), list(r)
        total = 0.0
        for data in batches:
            out = trial.run(model, data["z"], data["u"], data["dt"], x0=data["x0"])
            total += tuning.log_likelihood(out.innovation, out.S, R=as_matrix(r, m, "R"))
            if not np.isfinite(total):
                return -np.inf
        return total

    result = tuning.fit(evaluate, q0, r0, fit_r=fit_r)
    entry = copy.deepcopy(exp.spec["estimators"][index])
    entry["settings"]["Q"] = [float(f"{v:.6g}") for v in result.q]
    if fit_r:
        entry["settings"]["R"] = [float(f"{v:.6g}") for v in result.r]
    return entry, result
