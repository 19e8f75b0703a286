"""Perturbation analysis and distortion of the Chapter 2 circuits (Tables 2.1-2.4).

For each configured row (one per thesis row, in thesis order) the circuit is built with the
row's parameters, driven with the row's amplitude ``A`` and, for a check of the expansion,
with ``A/2``; :func:`core.perturbation.respond` gives the zeroth-order output ``y0``, the
first-order output ``y1`` and the full nonlinear output over one period of the periodic
steady state (a sine) or over the row's window after a step. The row of ``distortion.csv``:

``percent_distortion``  eq 2.43 as an RMS ratio, ``100 rms(y1) / rms(y0 + y1)``
``thd_percent``         total harmonic distortion of the full output (harmonics 2-10)
``gain_db``             fundamental of the full output over the source amplitude
``err_linear_rms``      ``rms(y_full - y0)``: the error of keeping the linear term only
``err_first_order_rms`` ``rms(y_full - y0 - y1)``: the error left after the first order
``order_linear``, ``order_first_order``  ``log2`` of each error's ratio between ``A`` and
                        ``A/2``: about 2 and 3 when the expansion works as it should
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from core import metrics, registry
from core.analyses import map_tasks
from core.config import Experiment
from core.perturbation import Response, respond


def rows(exp: Experiment) -> list[dict]:
    return exp.spec["rows"]


def build_model(exp: Experiment, row: dict):
    spec = exp.spec["model"]
    return registry.MODELS[spec["name"]](spec["variant"], **{**spec["params"], **row["params"]})


def source(exp: Experiment, row: dict, amplitudes: np.ndarray) -> tuple[np.ndarray, float]:
    """Sampled sources ``(len(amplitudes), steps + 1, p)`` of one row, and the sample time."""
    exc = exp.spec["excitation"]
    bias, mix = np.asarray(exc["bias_v"], float), np.asarray(exc["mix"], float)
    if exc["waveform"] == "sine":
        steps = exc["samples_per_period"]
        dt = 1.0 / (row["frequency_hz"] * steps)
        shape = np.sin(2 * np.pi * np.arange(steps + 1) / steps)
    else:
        steps = exc["samples"]
        dt = row["duration_s"] / steps
        shape = np.ones(steps + 1)
        shape[0] = 0.0
    wave = amplitudes[:, None, None] * shape[None, :, None] * mix
    return bias + wave, dt


def respond_row(exp: Experiment, row: dict) -> tuple[Response, np.ndarray]:
    """Responses at the row's amplitude and at half of it."""
    amplitudes = np.array([row["amplitude_v"], row["amplitude_v"] / 2])
    src, dt = source(exp, row, amplitudes)
    sim = exp.spec["simulation"]
    response = respond(build_model(exp, row), src, np.asarray(exp.spec["excitation"]["bias_v"]),
                       dt, periodic=exp.spec["excitation"]["waveform"] == "sine",
                       solver=sim["solver"], rtol=sim["rtol"], atol=sim["atol"])
    return response, amplitudes


def row_params(row: dict) -> str:
    return ", ".join(f"{k}={v:g}" for k, v in row["params"].items())


def run_row(exp: Experiment, row: dict) -> dict:
    """One row of ``distortion.csv``."""
    return _evaluate((exp, row))[0]


def summarize(exp: Experiment, row: dict, r: Response, amplitudes: np.ndarray) -> dict:
    """The ``distortion.csv`` row of the responses ``r`` at ``amplitudes`` (A, A/2)."""
    periodic = exp.spec["excitation"]["waveform"] == "sine"
    # one period of samples t_0..t_{N-1} (t_N repeats t_0); the whole window after a step
    window = slice(0, -1) if periodic else slice(1, None)
    y0, y1, y = r.y0[:, window], r.y1[:, window], r.y_full[:, window]
    err_lin = metrics.rms(y - y0)
    err_first = metrics.rms(y - y0 - y1)
    nan = float("nan")
    return {
        "s_no": row["s_no"], "amplitude_v": row["amplitude_v"],
        "frequency_hz": row["frequency_hz"] if periodic else nan,
        "row_params": row_params(row),
        "percent_distortion": float(metrics.percent_distortion(y0[0], y1[0])),
        "thd_percent": float(metrics.thd_percent(y[0])) if periodic else nan,
        "gain_db": float(metrics.gain_db(y[0], amplitudes[0])) if periodic else nan,
        "output_rms": float(metrics.rms(y[0])),
        "err_linear_rms": float(err_lin[0]), "err_first_order_rms": float(err_first[0]),
        "order_linear": float(np.log2(err_lin[0] / err_lin[1])),
        "order_first_order": float(np.log2(err_first[0] / err_first[1])),
        "shooting_iterations": r.shooting_iterations,
    }


def _evaluate(args: tuple[Experiment, dict]) -> tuple[dict, Response]:
    exp, row = args
    r, amplitudes = respond_row(exp, row)
    return summarize(exp, row, r, amplitudes), r


def run(exp: Experiment, jobs: int = 1,
        on_point: Callable[[], None] | None = None) -> list[tuple[dict, Response]]:
    """Every row's ``distortion.csv`` entry and responses, in thesis order whatever the number
    of jobs."""
    return map_tasks(_evaluate, [(exp, row) for row in rows(exp)], jobs, on_point)


def figure_data(exp: Experiment, responses: dict[int, Response]) -> dict:
    """Traces of the figure row (``figures.row``, default the first) from the rows'
    ``responses`` by ``s_no``: two periods of the steady state for a sine, the whole window
    after a step."""
    wanted = exp.spec["figures"]["row"]
    row = next((r for r in rows(exp) if r["s_no"] == wanted), rows(exp)[0])
    r = responses[row["s_no"]]
    src, _ = source(exp, row, np.array([row["amplitude_v"]]))
    mix = np.asarray(exp.spec["excitation"]["mix"], float)
    drive = (src[0] - np.asarray(exp.spec["excitation"]["bias_v"], float)) @ mix / (mix @ mix)
    traces = {"t": r.t, "input": drive, "y0": r.y0[0], "y1": r.y1[0], "y_full": r.y_full[0]}
    if exp.spec["excitation"]["waveform"] == "sine":
        period = r.t[-1]
        traces = {k: np.concatenate([v[:-1], v]) for k, v in traces.items() if k != "t"} | {
            "t": np.concatenate([r.t[:-1], r.t + period])}
    traces["row"] = row
    return traces
