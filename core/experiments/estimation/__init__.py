"""Estimators against the actual circuit on noisy measurements (thesis Chapter 3).

For each sweep point (noise reading x noise level x input frequency, in thesis row order):

1. the source is the nominal waveform (the thesis' sine, or a pulse, step, piecewise-linear
   or recorded one: :mod:`estim.experiments.estimation.source`) plus white Gaussian noise at
   every sample after ``t_0`` (the "Gaussian noise at input source" of Tables 3.1-3.5), held
   over each sample interval as the model maps it;
2. the actual circuit is integrated with a stiff solver (:mod:`estim.numerics.simulate`; the batched
   Radau IIA by default, scipy's ``solve_ivp`` with ``simulation.solver: scipy``) from its DC
   operating point;
3. measurements are the actual output plus white measurement noise;
4. every estimator sees the measurements and the nominal input (or the noisy one, when
   ``noise.filters_see`` is ``noisy``, measured with ``noise.input_sensor_sigma`` of its
   own noise), fed to it as ``estimators[i].input_derivative`` says, and starts from the
   actual DC operating point;
5. every filter's health is judged (:mod:`estim.experiments.shared.health`): NEES against the actual
states,
   NIS, whiteness of the innovations, and divergence by the stated criterion;
6. RMSE (eq 3.42) is reported over the runs that did not diverge and over all runs
   (mean with its standard error, and median; a run the filter broke on counts as an
   infinite error), beside a "measurement" row, the raw measurement's own RMSE; residual
   statistics are over the runs that did not diverge.

Each sweep point draws from its own ``SeedSequence(seed, spawn_key=(point,))``, so any cell
can be re-run alone and comes out the same.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estim import reference
from estim.config import registry
from estim.config.builders import build_estimator, build_model, check_input_vector, operating_point
from estim.config.experiment import Experiment
from estim.errors import ConfigError, UsageError
from estim.estimators.base import GENERATOR_KEY, takes_generator
from estim.experiments.base import Quote, Result
from estim.experiments.estimation import actual as actual_circuit
from estim.experiments.estimation import figures as estimation_figures
from estim.experiments.estimation import parameters as estimated
from estim.experiments.estimation import source as waveforms
from estim.experiments.estimation.config import Config
from estim.experiments.estimation.points import SweepPoint, sampling, sweep
from estim.experiments.estimation.printing import printout as printout  # the protocol's printout
from estim.experiments.shared import claims, pipeline
from estim.numerics import signals
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")

SCHEMA: dict = Config.schema()

_ROW_KEYS = ("table_id", "s_no", "measurement", "noise_reading", "noise_param", "noise_sigma",
             "frequency_hz", "samples_per_period", "estimator")
_JOIN = (("s_no", ("s_no",)), ("estimator", ("estimator",)))

TABLES = {
    "rmse": TableSpec("rmse.csv", (*_ROW_KEYS, "regime"),
                      (*pipeline.RMSE_VALUES, "regime_fraction"),
                      reference=("rmse",), join=_JOIN, title="RMSE (eq 3.42)",
                      reference_ids=("3.1", "3.2", "3.5")),
    "health": TableSpec("health.csv", _ROW_KEYS,
                        (*pipeline.HEALTH_VALUES, "regressor_rank", "regressor_size",
                         "lambda_at_floor", "p_max_eig", *pipeline.BREAK_VALUES),
                        title="filter health: divergence, consistency, whiteness, excitation, "
                              "the first break",
                        text=pipeline.BREAK_VALUES[1:]),
    "residual": TableSpec("residual.csv", _ROW_KEYS,
                          ("residual_mean", "residual_mean_se", "residual_variance",
                           "residual_variance_se", "runs", "diverged"),
                          reference=("residual_mean", "residual_variance"), join=_JOIN,
                          title="residual (innovation) mean and variance, runs that did not "
                                "diverge",
                          reference_ids=("3.3", "3.4")),
    "states": TableSpec("states.csv", (*_ROW_KEYS, "state"), pipeline.STATE_VALUES,
                        title="RMSE of every state against the actual circuit's"),
    "outputs": TableSpec("outputs.csv", (*_ROW_KEYS, "output"), pipeline.OUTPUT_VALUES,
                         title="each measured quantity's RMSE and residual (where model.output "
                               "lists several)"),
    "parameters": TableSpec("parameters.csv", (*_ROW_KEYS, "parameter"), estimated.VALUES,
                            title="element values estimated as states: final estimates "
                                  "against the actual circuit's"),
    "claims": claims.TABLE,
}

QUOTES = (
    Quote("RMSE over all runs", "rmse", "rmse", by="estimator"),
    Quote("RMSE over the runs that did not diverge, in the cells where a run diverged", "rmse",
          "rmse_kept", by="estimator", where="diverged > 0"),
    Quote("fraction of actual samples in the named regime", "rmse", "regime_fraction",
          where="estimator == 'measurement'"),
    Quote("diverged runs", "health", "diverged", by="estimator", total="runs"),
    Quote("inconsistent runs (time-averaged NIS or NEES outside its 95 % band)", "health",
          "inconsistent", by="estimator", total="runs", where="inconsistent == inconsistent"),
    Quote("residual mean", "residual", "residual_mean", by="estimator"),
    Quote("mean final estimate of an element value estimated as a state", "parameters",
          "estimate", by="estimator"),
    Quote("runs whose final estimate of an element value is within 3 of its own standard "
          "deviations of the actual value", "parameters", "within_3_sigma", by="estimator",
          total="runs"),
)
"""What ``estim summary`` quotes of an estimation experiment (:mod:`estim.report.summary`)."""


@dataclass(frozen=True)
class Plan:
    """What an estimation experiment builds once: the actual circuit and, per estimator,
    its label, the estimator object and the model it filters with."""

    truth: object
    filters: tuple
    x0: object
    inputs: tuple = ()
    """Per estimator: its ``(input_derivative, derivative_bandwidth)``."""
    knots: object = None
    """The ``(t, w)`` knots of a ``pwl`` or ``file`` source (:mod:`.source`)."""
    parameters: tuple = ()
    """The values every filter estimates as states (:mod:`.parameters`)."""
    theta: object = None
    """Their actual values over the filters' first guesses."""


def prepare(config: Config, source: str) -> Plan:
    """Cross-checks beyond the schema; builds the models and estimators once."""
    model_cls = registry.MODELS[config.model.name]
    variant = config.model.variant
    inp, noise = config.input, config.noise
    if (inp.periods is None) == (inp.duration_s is None):
        raise ConfigError(source, "input.periods",
                          "give exactly one of input.periods and input.duration_s")
    for key in ("bias_v", "mix"):
        check_input_vector(getattr(inp, key), model_cls, source, f"input.{key}")
    knots = waveforms.check(inp, source)
    freqs = waveforms.frequencies(inp)
    if noise.pairs:
        if len(noise.input_levels) != len(freqs):
            raise ConfigError(source, "noise.pairs", "with pairs: true, noise.input_levels and "
                              "input.frequencies_hz must have the same length")
        cells = list(zip(noise.input_levels, freqs, strict=True))
        for i, cell in enumerate(cells):
            if cell in cells[:i]:
                raise ConfigError(source, f"input.frequencies_hz[{i}]",
                                  f"repeats the (noise level, frequency) pair {cell}")
    else:
        for key, values in (("noise.input_levels", noise.input_levels),
                            ("input.frequencies_hz", freqs)):
            for i, v in enumerate(values):
                if v in values[:i]:
                    raise ConfigError(source, f"{key}[{i}]", f"repeats {v!r}")
    if noise.input_sensor_sigma > 0 and noise.filters_see != "noisy":
        raise ConfigError(source, "noise.input_sensor_sigma", "applies only when the filters "
                          "see the noisy source (noise.filters_see: noisy)")
    truth = build_model(model_cls, variant, config.model.params, source, "model.params")
    held = (np.asarray(inp.bias_v, float)
            + waveforms.start(inp, knots) * np.asarray(inp.mix, float))
    x0 = operating_point(truth, held, source, "model.params")
    actual_circuit.check(config, truth, source)
    values = estimated.check(config, truth, source)
    sigma = noise.measurement_sigma
    if isinstance(sigma, list) and len(sigma) != truth.n_outputs:
        raise ConfigError(source, "noise.measurement_sigma", f"{len(sigma)} levels for "
                          f"{truth.n_outputs} measured quantities {list(truth.output_names)}")
    filters, labels = [], []
    for i, est in enumerate(config.estimators):
        path = f"estimators[{i}]"
        if est.label in labels:
            raise ConfigError(source, f"{path}.label", f"duplicate label {est.label!r}")
        if est.label == pipeline.MEASUREMENT:
            raise ConfigError(source, f"{path}.label", f"{pipeline.MEASUREMENT!r} is the label "
                              "of the raw-measurement baseline row; choose another")
        labels.append(est.label)
        model = build_model(model_cls, variant, {**config.model.params, **est.model_params},
                            source, f"{path}.model_params")
        estimator = build_estimator(registry.ESTIMATORS[est.type], est.settings, model,
                                    source, f"{path}.settings")
        est.settings.clear()      # the manifest records every default
        est.settings.update(estimator.to_spec())
        if values:
            estimator, model = estimated.augment(estimator, model, values, config.estimate,
                                                 source, path)
        filters.append((est.label, estimator, model))
        if est.input_derivative != "difference" and not model_cls.input_is_source_slope:
            raise ConfigError(source, f"{path}.input_derivative",
                              f"model {config.model.name}'s input is not the derivative of "
                              "its source; only 'difference' (the model's own mapping) applies")
        if ((est.input_derivative == "analytic" and inp.waveform != "sine")
                or (est.input_derivative == "kalman" and inp.waveform not in waveforms.PERIODIC)):
            raise ConfigError(source, f"{path}.input_derivative",
                              f"{est.input_derivative!r} needs a "
                              f"{'sine' if est.input_derivative == 'analytic' else 'periodic'} "
                              f"input, not {inp.waveform}; use 'difference'")
    regime = config.regime
    if regime is not None and regime not in truth.regimes:
        raise ConfigError(source, "regime", f"expected one of {list(truth.regimes)} for "
                          f"model {config.model.name}, got {regime!r}")
    if not any(table_id for _, table_id in config.tables.items()):
        raise ConfigError(source, "tables", "expected at least one of tables.rmse and "
                          "tables.residual")
    pipeline.check_claims(config.claims, labels, source)
    if config.claims and config.tables.rmse is None:
        raise ConfigError(source, "claims", "claims compare RMSEs: set tables.rmse")
    estimation_figures.check(config, source)
    dt = inp.sample_time_s
    if dt is not None and inp.waveform in waveforms.PERIODIC and dt * max(freqs) > 10:
        raise ConfigError(source, "input.sample_time_s",
                          f"{dt:g} s samples the highest input frequency "
                          f"{max(freqs):g} Hz fewer than once in ten periods")
    if dt is not None and inp.duration_s is not None and dt > inp.duration_s:
        raise ConfigError(source, "input.sample_time_s",
                          f"{dt:g} s is longer than the record (input.duration_s)")
    inputs = tuple((e.input_derivative, e.derivative_bandwidth)
                   for e in config.estimators)
    return Plan(truth=truth, filters=tuple(filters), x0=x0, inputs=inputs, knots=knots,
                parameters=values,
                theta=estimated.true_ratios(truth, values) if values else None)


def work_size(config: Config) -> int:
    """State-samples of the actual signal over every sweep point and figure batch."""
    n = len(registry.MODELS[config.model.name].state_names)
    inp, mc = config.input, config.monte_carlo
    per_freq = 0
    for f in waveforms.frequencies(inp):
        dt = inp.sample_time_s or 1.0 / (inp.samples_per_period * f)
        span = inp.duration_s if inp.duration_s is not None else (
            (inp.periods or 1) / f)
        per_freq += span / dt
    batches = len(config.noise.readings) * len(config.noise.input_levels)
    if config.noise.pairs:
        batches = len(config.noise.readings)
    batches *= len(config.noise.measurement)
    figures = 2 + len(config.figures.extra_noisy)
    return int(mc.runs * n * (per_freq * batches + figures * per_freq))


def tiny(config: Config) -> dict:
    """Seconds of work: one frequency, one noise level and reading, two periods (a waveform
    that does not repeat keeps its record), 3 runs."""
    inp, noise = config.input, config.noise
    out: dict = {}
    if inp.waveform in waveforms.PERIODIC:          # else one record, as the config has it
        out["input.frequencies_hz"] = inp.frequencies_hz[:1]
        if inp.periods is not None:
            out["input.periods"] = 2
        else:
            out["input.duration_s"] = 2.0 / inp.frequencies_hz[0]
    return {**out, "noise.input_levels": noise.input_levels[:1],
            "noise.readings": (noise.readings or ["sigma"])[:1],
            "noise.measurement": (noise.measurement or ["noisy"])[:1],
            "monte_carlo.runs": 3, "figures": {"names": config.figures.names}}


def work_units(exp: Experiment) -> int:
    return len(sweep(exp)) + 1


def simulate_point(exp: Experiment, frequency_hz: float, sigma: float, runs: int,
                   rng: np.random.Generator, measurement: str = "noisy") -> dict:
    """Actual trajectories and measurements for one frequency and input-noise level."""
    inp, noise = exp.config.input, exp.config.noise
    truth = exp.plan.truth
    dt, steps = sampling(exp, frequency_hz)
    t = np.arange(steps + 1) * dt
    mix, bias = np.asarray(inp.mix, float), np.asarray(inp.bias_v, float)
    clean = bias + waveforms.waveform(inp, exp.plan.knots, frequency_hz, t) * mix
    input_noise = sigma * rng.standard_normal((runs, steps + 1, 1)) * mix
    input_noise[:, 0] = 0.0    # the circuit starts at its operating point with v_in(t_0) known
    source = clean[None] + input_noise
    x0 = exp.plan.x0           # the DC point with the source held at its value at t_0
    states = actual_circuit.states(truth, x0, source, dt, exp.config.simulation)
    actual = truth.h(states)
    z = actual + np.asarray(noise.measurement_sigma) * rng.standard_normal(actual.shape)
    if measurement == "noise_free":
        z = actual.copy()
    seen = clean[None] if noise.filters_see == "nominal" else source
    if exp.plan.parameters:     # the filters' states: the circuit's, then the values
        states = np.concatenate([states, np.broadcast_to(
            exp.plan.theta, states.shape[:-1] + exp.plan.theta.shape)], axis=-1)
        x0 = np.concatenate([x0, np.ones(len(exp.plan.parameters))])
    if noise.input_sensor_sigma > 0:        # the filters measure the source imperfectly
        seen = seen + noise.input_sensor_sigma * rng.standard_normal(source.shape) * mix
        seen[:, 0] = source[:, 0]               # v_in(t_0) is known, as for the circuit
    return {"t": t[1:], "dt": dt, "x0": x0, "source": source, "clean": clean, "seen": seen,
            "frequency_hz": frequency_hz, "states": states, "actual": actual, "z": z,
            "u": truth.source_to_input(seen, dt)}


def estimate_point(exp: Experiment, data: dict, key: tuple) -> list:
    """Run every configured estimator on one simulated batch, drawn from the seed key
    ``key``; an estimator whose ``run`` takes ``rng`` gets a generator of its own from it
    (:func:`estim.estimators.base.takes_generator`)."""
    out = []
    for i, ((_, est, model), how) in enumerate(zip(exp.plan.filters, exp.plan.inputs,
                                                   strict=True)):
        extra = ({"rng": exp.config.monte_carlo.rng(*key, GENERATOR_KEY, i)}
                 if takes_generator(est) else {})
        u = waveforms.filter_input(exp.config.input, data, *how)
        out.append(est.run(model, data["z"], u, data["dt"], x0=data["x0"], **extra))
    return out


def run_point(exp: Experiment, point: SweepPoint, traces: bool = False) -> tuple[list, dict,
                                                                                  dict, dict]:
    """Table rows (the measurement baseline, then one per estimator) for one sweep point,
    the per-run losses for the claims, with ``traces`` the figure traces of its first run
    (the figures show the runs the table averages), and the rows of the tables only some
    configs have, by table: per state, per estimated value, per measured quantity."""
    mc = exp.config.monte_carlo
    rng = exp.config.monte_carlo.rng(point.index)
    data = simulate_point(exp, point.frequency_hz, point.sigma, mc.runs, rng,
                          point.measurement)
    estimates = estimate_point(exp, data, (point.index,))
    regime = exp.config.regime
    truth = exp.plan.truth
    fraction = float("nan") if regime is None else float(np.mean(truth.in_regime(
        regime, data["states"][..., :truth.n_states], data["source"][:, 1:])))
    common = {"measurement": point.measurement, "noise_reading": point.reading,
              "noise_param": point.level,
              "noise_sigma": point.sigma, "frequency_hz": point.frequency_hz,
              "samples_per_period": 1.0 / (point.frequency_hz * data["dt"]),
              "regime": regime or "", "regime_fraction": fraction}
    rows, losses, verdicts = pipeline.score(exp, data, exp.plan.filters, estimates, common)
    drawn = estimation_figures.traces(exp, data, estimates, verdicts) if traces else {}
    filters, names = exp.plan.filters, exp.plan.truth.output_names
    more = {"states": pipeline.state_rows(data, filters, estimates, verdicts, common),
            "parameters": (estimated.rows(filters, estimates, verdicts, exp.plan.theta, common)
                           if exp.plan.parameters else []),
            "outputs": (pipeline.output_rows(data, filters, estimates, verdicts, common, names)
                        if len(names) > 1 else [])}
    return rows, losses, drawn, more


def _run_point_args(args):
    return run_point(*args)


FIGURE_SEED_KEY = 2**31
"""Figure batches that are not a sweep point draw from ``spawn_key=(FIGURE_SEED_KEY, i)``: a
key space no sweep point reaches."""


def figure_cases(exp: Experiment) -> list[tuple[str, float, float, str]]:
    """``(key, frequency, noise level, reading)`` of every noisy figure batch: the figure's
    point and each ``figures.extra_noisy`` case."""
    fig = exp.config.figures
    f = fig.frequency_hz or waveforms.frequencies(exp.config.input)[0]
    level = fig.noise_level or exp.config.noise.input_levels[0]
    reading = fig.reading or exp.config.noise.readings[0]
    cases = [("noisy", f, level, reading)]
    cases += [(extra.name, f, extra.noise_level, extra.reading)
              for extra in fig.extra_noisy]
    return cases


def result_table(rows: list[dict], metric: str, table_id: str | None) -> pd.DataFrame:
    """The ``metric`` table from the sweep's rows, with thesis table id and row number."""
    df = pd.DataFrame(rows)
    for column in ("inconsistent", "first_break_step"):
        if column in df:
            df[column] = pd.array(df[column], dtype="Float64").astype("Int64")
    df.insert(0, "table_id", table_id if table_id and table_id != reference.OWN_TABLE else "")
    df.insert(1, "s_no", pipeline.thesis_row_numbers(df, table_id))
    return df[TABLES[metric].columns].reset_index(drop=True)


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
    rows = [row for part, *_ in done for row in part]
    known = {key: done[index][2] for index, keys in wanted.items() for key in keys}
    out = Result(tables={})
    filters_only = [row for row in rows if row["estimator"] != pipeline.MEASUREMENT]
    table_id = exp.config.tables.rmse or exp.config.tables.residual
    rmse = result_table(rows, "rmse", table_id)
    for metric, table_id_ in exp.config.tables.items():
        if table_id_ is not None:
            out.tables[metric] = (result_table(rows, metric, table_id_) if metric == "rmse"
                                  else result_table(filters_only, metric, table_id_))
    out.tables["health"] = result_table(filters_only, "health", table_id)
    for metric in ("states", "parameters", "outputs"):
        part = [row for *_, more in done for row in more[metric]]
        if part:
            out.tables[metric] = result_table(part, metric, table_id)
    out.tables["claims"] = pipeline.claims_table(exp.config, rmse,
                                                 [losses for _, losses, *_ in done],
                                        ("s_no", "measurement", "noise_reading", "noise_param",
                                         "frequency_hz"))
    out.figures = figures(exp, known)
    if on_done:
        on_done()
    return out


def figure_traces(exp: Experiment, known: dict) -> dict:
    """Traces of every figure: the noiseless run (one run, its own seed) and the noisy
    cases, taken from ``known`` (traces of sweep points) or simulated with their own seed."""
    mc = exp.config.monte_carlo
    cases = figure_cases(exp)
    f = cases[0][1]
    batches = [("noiseless", 0.0, 1)] + [
        (key, signals.noise_sigma(level, reading), mc.runs) for key, _, level, reading in cases]
    out = {}
    for i, (key, sigma, runs) in enumerate(batches):
        if key in known:
            out[key] = known[key]
            continue
        rng = exp.config.monte_carlo.rng(FIGURE_SEED_KEY, i)
        data = simulate_point(exp, f, sigma, runs, rng, exp.config.noise.measurement[0])
        estimates = estimate_point(exp, data, (FIGURE_SEED_KEY, i))
        verdicts = [pipeline.judge(exp, data, est, model)["diverged"]
                    for (_, _, model), est in zip(exp.plan.filters, estimates, strict=True)]
        out[key] = estimation_figures.traces(exp, data, estimates, verdicts)
    return out


def figures(exp: Experiment, known: dict) -> dict:
    """Every figure: the traces of :func:`figure_traces`, drawn by
    :func:`estim.experiments.estimation.figures.figures`; none with ``figures.kinds: []``
    and no extra figure (nothing simulated for them)."""
    if not exp.config.figures.kinds and not exp.config.figures.extra_noisy:
        return {}
    _, f, level, reading = figure_cases(exp)[0]
    return estimation_figures.figures(exp, figure_traces(exp, known), f, level, reading)


TUNE_SEED_KEY = 2**32
"""Training draws of ``estim tune`` use ``spawn_key=(TUNE_SEED_KEY, point)``: independent of
every table and figure batch."""


def training(exp: Experiment, label: str, runs: int) -> tuple[int, object, object, list]:
    """What ``estim tune`` fits (:func:`estim.experiments.shared.tuning.tune`): the index, estimator
    and model of the filter labelled ``label``, and training draws of ``runs`` runs at every sweep
    point (points with a noise-free measurement are left out when noisy ones exist: the likelihood
    assumes the measurement noise ``R`` describes)."""
    found = [(i, est, model) for i, (lab, est, model) in enumerate(exp.plan.filters)
             if lab == label]
    if not found:
        raise UsageError(f"{exp.name}: no estimator labelled {label!r}; expected one of "
                         f"{[lab for lab, _, _ in exp.plan.filters]}")
    index, est, model = found[0]
    batches = []
    points = sweep(exp)
    noisy = [p for p in points if p.measurement == "noisy"]
    for p in noisy or points:
        rng = exp.config.monte_carlo.rng(TUNE_SEED_KEY, p.index)
        batches.append({**simulate_point(exp, p.frequency_hz, p.sigma, runs, rng,
                                         p.measurement),
                        "generator_key": (TUNE_SEED_KEY, p.index, GENERATOR_KEY, index)})
    return index, est, model, batches
