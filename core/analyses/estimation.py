"""Estimators against the actual circuit on noisy measurements (thesis Chapter 3).

For each sweep point (noise reading x noise level x input frequency, in thesis row order):

1. the source is the nominal sine plus white Gaussian noise at every sample after ``t_0``
   (the "Gaussian noise at input source" of Tables 3.1-3.5), piecewise linear between
   samples;
2. the actual circuit is integrated with a stiff solver (:mod:`core.simulate`; the batched
   Radau IIA by default, scipy's ``solve_ivp`` with ``simulation.solver: scipy``) from its DC
   operating point;
3. measurements are the actual output plus white measurement noise;
4. every estimator sees the measurements and the nominal input (or the noisy one, when
   ``noise.filters_see`` is ``noisy``) and starts from the actual DC operating point;
5. RMSE (eq 3.42) and residual statistics are taken over runs that did not diverge.

Each sweep point draws from its own ``SeedSequence(seed, spawn_key=(point,))``, so any cell
can be re-run alone and comes out the same.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from core import metrics, registry, signals
from core.analyses import map_tasks
from core.config import Experiment
from core.simulate import SOLVERS


@dataclass(frozen=True)
class SweepPoint:
    index: int
    reading: str
    level: float
    sigma: float
    frequency_hz: float


def sweep(exp: Experiment) -> list[SweepPoint]:
    """Sweep points in thesis row order: reading, then noise level, then frequency (or the
    (level, frequency) pairs in the order given, with ``noise.pairs``)."""
    noise, inp = exp.spec["noise"], exp.spec["input"]
    if noise["pairs"]:
        cells = list(zip(noise["input_levels"], inp["frequencies_hz"], strict=True))
    else:
        cells = [(level, f) for level in noise["input_levels"] for f in inp["frequencies_hz"]]
    points = []
    for reading in noise["readings"]:
        for level, f in cells:
            points.append(SweepPoint(len(points), reading, float(level),
                                     signals.noise_sigma(level, reading), float(f)))
    return points


def sampling(exp: Experiment, frequency_hz: float) -> tuple[float, int]:
    """Sample time and number of samples after ``t_0`` for one input frequency."""
    inp = exp.spec["input"]
    dt = inp["sample_time_s"] or 1.0 / (inp["samples_per_period"] * frequency_hz)
    if inp["duration_s"] is not None:
        return dt, max(1, round(inp["duration_s"] / dt))
    return dt, max(1, round(inp["periods"] / (frequency_hz * dt)))


def _models(exp: Experiment):
    spec = exp.spec["model"]
    cls = registry.MODELS[spec["name"]]
    truth = cls(spec["variant"], **spec["params"])
    filter_models = [cls(spec["variant"], **{**spec["params"], **e["model_params"]})
                     for e in exp.spec["estimators"]]
    return truth, filter_models


def simulate_point(exp: Experiment, frequency_hz: float, sigma: float, runs: int,
                   rng: np.random.Generator) -> dict:
    """Actual trajectories and measurements for one frequency and input-noise level."""
    inp, noise = exp.spec["input"], exp.spec["noise"]
    truth, _ = _models(exp)
    dt, steps = sampling(exp, frequency_hz)
    t = np.arange(steps + 1) * dt
    mix, bias = np.asarray(inp["mix"], float), np.asarray(inp["bias_v"], float)
    clean = bias + signals.sine(inp["amplitude_v"], frequency_hz, t) * mix
    input_noise = signals.gaussian(rng, sigma, (runs, steps + 1, 1)) * mix
    input_noise[:, 0] = 0.0    # the circuit starts at its operating point with v_in(t_0) known
    source = clean[None] + input_noise
    rest = truth.source_to_input(np.repeat(clean[None, :1], 2, axis=1), dt)[0, 0]
    x0 = truth.operating_point(u=rest)
    sim = exp.spec["simulation"]
    states = SOLVERS[sim["solver"]](truth, x0, truth.source_to_input(source, dt), dt,
                                    rtol=sim["rtol"], atol=sim["atol"])
    actual = truth.h(states)
    z = actual + signals.gaussian(rng, noise["measurement_sigma"], actual.shape)
    seen = clean[None] if noise["filters_see"] == "nominal" else source
    return {"t": t[1:], "dt": dt, "x0": x0, "source": source, "clean": clean,
            "actual": actual, "z": z, "u": truth.source_to_input(seen, dt)}


def estimate_point(exp: Experiment, data: dict) -> list:
    """Run every configured estimator on one simulated batch."""
    _, filter_models = _models(exp)
    out = []
    for est_spec, model in zip(exp.spec["estimators"], filter_models, strict=True):
        est = registry.ESTIMATORS[est_spec["type"]](**est_spec["settings"])
        out.append(est.run(model, data["z"], data["u"], data["dt"], x0=data["x0"]))
    return out


def run_point(exp: Experiment, point: SweepPoint, runs: int, seed: int) -> list[dict]:
    """Table rows (one per estimator) for one sweep point."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(point.index,)))
    data = simulate_point(exp, point.frequency_hz, point.sigma, runs, rng)
    rows = []
    for est_spec, est in zip(exp.spec["estimators"], estimate_point(exp, data), strict=True):
        ok = ~est.diverged
        rmse, rmse_se = metrics.mean_and_se(
            metrics.rmse_per_run(data["actual"][ok], est.y_hat[ok]))
        res_mean, res_var = metrics.residual_stats(est.innovation[ok])
        mean, mean_se = metrics.mean_and_se(res_mean)
        var, var_se = metrics.mean_and_se(res_var)
        rows.append({
            "noise_reading": point.reading, "noise_param": point.level,
            "noise_sigma": point.sigma, "frequency_hz": point.frequency_hz,
            "samples_per_period": 1.0 / (point.frequency_hz * data["dt"]),
            "estimator": est_spec["label"], "rmse": rmse, "rmse_se": rmse_se,
            "residual_mean": mean, "residual_mean_se": mean_se,
            "residual_variance": var, "residual_variance_se": var_se,
            "runs": int(ok.sum()), "diverged": int((~ok).sum()),
        })
    return rows


def _run_point_args(args):
    return run_point(*args)


def run(exp: Experiment, runs: int, seed: int, jobs: int = 1,
        on_point: Callable[[], None] | None = None) -> list[dict]:
    """All sweep points; rows in thesis order whatever the number of jobs."""
    tasks = [(exp, p, runs, seed) for p in sweep(exp)]
    return [row for rows in map_tasks(_run_point_args, tasks, jobs, on_point) for row in rows]


def figure_data(exp: Experiment, seed: int, runs: int) -> dict:
    """Traces for the figures: a noiseless run, a noisy batch at the figure's point, and one
    batch for each ``figures.extra_noisy`` case (keyed by its figure name)."""
    fig = exp.spec["figures"]
    f = fig["frequency_hz"] or exp.spec["input"]["frequencies_hz"][0]
    level = fig["noise_level"] or exp.spec["noise"]["input_levels"][0]
    sigma = signals.noise_sigma(level, fig["reading"] or exp.spec["noise"]["readings"][0])
    labels = [e["label"] for e in exp.spec["estimators"]]
    out = {"frequency_hz": f, "noise_level": level, "labels": labels}
    cases = [("noiseless", 0.0, 1), ("noisy", sigma, runs)]
    cases += [(extra["name"], signals.noise_sigma(extra["noise_level"], extra["reading"]), runs)
              for extra in fig["extra_noisy"]]
    for i, (key, s, n) in enumerate(cases):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(10_000 + i,)))
        data = simulate_point(exp, f, s, n, rng)
        ests = estimate_point(exp, data)
        out[key] = {
            "t": data["t"], "source": data["source"][0, 1:, 0], "clean": data["clean"][1:, 0],
            "actual": data["actual"][0, :, 0], "z": data["z"][0, :, 0],
            "y_hat": {lab: e.y_hat[0, :, 0] for lab, e in zip(labels, ests, strict=True)},
            "innovation": {lab: e.innovation[0, :, 0] for lab, e in zip(labels, ests, strict=True)},
            "running_rmse": {lab: metrics.running_rmse(data["actual"][~e.diverged],
                                                       e.y_hat[~e.diverged])
                             for lab, e in zip(labels, ests, strict=True)},
        }
    return out
