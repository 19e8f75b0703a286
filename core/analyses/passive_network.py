"""The passive-network estimator (eq 22) against the classical one (eq 19) and a discrete
Kalman filter on ``x = A e^{-t} + N`` (the paper in ``shared/seeds/004_...``, Figs 4-7),
for each reading of what the paper leaves open (the sign of eq 22's coupling, ``u``, the
initial values, whether ``z`` or ``x`` is fed): mean and maximum absolute error over the
record, averaged over Monte Carlo runs, and the claim "eq 22 beats eq 19 at A = 100"."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from core import metrics, plots
from core import passive_network as pn
from core.analyses.base import Result, TableSpec
from core.schema import REQUIRED, Experiment, file_name, integer, list_of, number, text

SCHEMA: dict = {
    "signals": (list_of({
        "A": (number(minimum=-1e6, maximum=1e6), REQUIRED),
        "sigma": (number(minimum=0.0, maximum=1e6), REQUIRED),
    }, max_length=20), REQUIRED),
    "readings": (list_of({
        "name": (text(max_length=40), REQUIRED),
        "coupling": (text({"printed", "flipped"}), "printed"),
        "u": (number(minimum=0.0, maximum=1e6), 6.0),
        "x0": (number(minimum=-1e6, maximum=1e6), 1.0),
        "V0": (number(minimum=-1e6, maximum=1e6), 2.0),
        "feed": (text({"z", "x"}), "x"),
    }, max_length=20), REQUIRED),
    "sample_time": (number(positive=True, maximum=1.0), 0.01),
    "samples": (integer(10, 1_000_000), 500),
    "kalman_p0": (number(positive=True, maximum=1e12), 1.0),
    "monte_carlo": ({
        "runs": (integer(2, 100_000), REQUIRED),
        "seed": (integer(0, 2**63 - 1), REQUIRED),
    }, REQUIRED),
    "figures": (list_of({
        "A": (number(), REQUIRED),
        "signal": (file_name, None),
        "errors": (file_name, None),
    }, nonempty=False, max_length=20), [{"A": 1.0, "signal": "fig_4", "errors": "fig_5"},
                                        {"A": 100.0, "signal": "fig_6", "errors": "fig_7"}]),
}

ESTIMATORS = ("eq 19", "eq 22", "Kalman filter")
TABLES = {
    "errors": TableSpec("errors.csv", ("reading", "A", "sigma", "estimator"),
                        ("mean_abs_error", "mean_abs_error_se", "max_abs_error",
                         "max_abs_error_se", "runs"),
                        title="absolute estimation error over the record"),
    "claims": TableSpec("claims.csv", ("claim", "reading", "A", "sigma"),
                        ("eq19_mean_abs_error", "eq22_mean_abs_error", "ratio", "holds"),
                        title="eq 22 beats eq 19 (the paper's claim for A > 1)"),
}


def prepare(spec: dict, source: str) -> None:
    from core.errors import ConfigError

    names = [r["name"] for r in spec["readings"]]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise ConfigError(source, f"readings[{i}].name", f"repeats {name!r}")
    amplitudes = [sig["A"] for sig in spec["signals"]]
    files: list[str] = []
    for i, fig in enumerate(spec["figures"]):
        if fig["A"] not in amplitudes:
            raise ConfigError(source, f"figures[{i}].A", f"expected the A of a signal "
                              f"{amplitudes}, got {fig['A']!r}")
        for kind in ("signal", "errors"):
            if fig[kind] is None:
                continue
            if fig[kind] in files:
                raise ConfigError(source, f"figures[{i}].{kind}", f"repeats {fig[kind]!r}")
            files.append(fig[kind])


def work_units(exp: Experiment) -> int:
    return 1


def work_size(spec: dict) -> int:
    return (spec["monte_carlo"]["runs"] * spec["samples"] * len(spec["signals"])
            * len(spec["readings"]) * 3)


def tiny(spec: dict) -> dict:
    spec["monte_carlo"]["runs"] = 3
    return spec


def _estimates(spec: dict, reading: dict, signal: np.ndarray, dt: float) -> dict:
    z = signal / 2 if reading["feed"] == "z" else signal
    sign = -1 if reading["coupling"] == "printed" else 1
    return {
        "eq 19": pn.estimator(z, dt, reading["u"], reading["x0"], reading["V0"], "eq19"),
        "eq 22": pn.estimator(z, dt, reading["u"], reading["x0"], reading["V0"], "eq22", sign),
        "Kalman filter": pn.kalman(signal / 2, dt, reading["x0"], spec["kalman_p0"]),
    }


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    spec = exp.spec
    dt, steps, runs = spec["sample_time"], spec["samples"], spec["monte_carlo"]["runs"]
    t = dt * np.arange(1, steps + 1)
    rows, figure_data = [], {}
    for s_idx, sig in enumerate(spec["signals"]):
        rng = np.random.default_rng(np.random.SeedSequence(spec["monte_carlo"]["seed"],
                                                           spawn_key=(s_idx,)))
        clean = sig["A"] * np.exp(-t)
        noisy = clean + sig["sigma"] * rng.standard_normal((runs, steps))
        for reading in spec["readings"]:
            est = _estimates(spec, reading, noisy, dt)
            for name, values in est.items():
                with np.errstate(invalid="ignore", over="ignore"):
                    err = np.abs(values - clean)
                mean_err = np.where(np.isfinite(err).all(axis=1), err.mean(axis=1), np.inf)
                max_err = np.where(np.isfinite(err).all(axis=1), err.max(axis=1), np.inf)
                with np.errstate(invalid="ignore"):     # a diverged run is inf: SE nan
                    m, m_se = metrics.mean_and_se(mean_err)
                    x, x_se = metrics.mean_and_se(max_err)
                rows.append({"reading": reading["name"], "A": sig["A"], "sigma": sig["sigma"],
                             "estimator": name, "mean_abs_error": m, "mean_abs_error_se": m_se,
                             "max_abs_error": x, "max_abs_error_se": x_se, "runs": runs})
            errors = {n: np.abs(v[0] - clean) for n, v in est.items()}
            figure_data.setdefault(sig["A"], {"clean": clean, "noisy": noisy[0],
                                              "sigma": sig["sigma"], "errors": {}})
            figure_data[sig["A"]]["errors"][reading["name"]] = errors
    df = pd.DataFrame(rows)[TABLES["errors"].columns]
    a = df[df["estimator"] == "eq 19"].set_index(["reading", "A", "sigma"])["mean_abs_error"]
    b = df[df["estimator"] == "eq 22"].set_index(["reading", "A", "sigma"])["mean_abs_error"]
    claims = pd.DataFrame({"eq19_mean_abs_error": a, "eq22_mean_abs_error": b}).reset_index()
    claims["ratio"] = claims["eq22_mean_abs_error"] / claims["eq19_mean_abs_error"]
    claims["holds"] = claims["eq22_mean_abs_error"] < claims["eq19_mean_abs_error"]
    claims.insert(0, "claim", "eq 22 mean |error| < eq 19 mean |error|")
    figures = {}
    for fig in spec["figures"]:
        data = figure_data[fig["A"]]
        if fig["signal"] is not None:
            figures[fig["signal"]] = plots.noisy_signal(
                t, data["clean"], data["noisy"],
                f"x = A e^-t + N, A = {fig['A']:g}, sigma = {data['sigma']:g} (run 1)")
        if fig["errors"] is not None:
            figures[fig["errors"]] = plots.absolute_errors(t, data["errors"], f"A = {fig['A']:g}")
    if on_done:
        on_done()
    return Result(tables={"errors": df, "claims": claims[TABLES["claims"].columns]},
                  figures=figures)


def summary(result: Result) -> str:
    df = result.tables["errors"]
    view = df.pivot_table(index=["reading", "A", "sigma"], columns="estimator",
                          values="mean_abs_error", sort=False)
    return view.to_string(float_format=lambda v: f"{v:.4g}")
