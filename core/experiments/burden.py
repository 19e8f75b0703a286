"""Computational burden of the Kronecker EKF and the wavelet method (thesis Tables 4.3, 4.4).

For chains of 1, 2, 4, ... MOSFET stages (``n_x = 4, 8, 16, ...``; the Darlington pair is two)
three numbers stand beside each printed row:

``printed``   the thesis' formula evaluated at ``n_x``, ``d`` (outputs) and ``p`` (inputs);
``counted``   the multiplications our code performs per step, read off its code path
              (:mod:`estim.numerics.opcount`), for the same equation;
``ours_formula``  the closed form of what the code does (a test checks it equals the count);
              in Table 4.4's rows ``N`` is the block length, ``q`` the measured states,
              ``D = q + q(q+1)/2 + p + 1`` the regressors, ``K`` the kept wavelet
              coefficients, ``C`` the detail coefficients of every level, ``taps`` the
              wavelet's filter length.

``slopes.csv`` holds the log-log slopes of the counts against ``n_x``. ``timing.csv`` holds
the measured wall time per step (median of ``repeats``, in this process) of one run, and per
run of ``batch_runs`` runs filtered together (the way the tables run: there the per-step
interpreter overhead is shared), with its slopes in ``timing_slopes.csv`` and the figure
``burden_timing``: they measure the machine (:data:`MACHINE`), so they are written under
``machine/``, untracked, and ``estim check`` compares the counts only.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from estim import reference
from estim.config import registry
from estim.config.builders import build_estimator, build_model
from estim.config.experiment import Experiment
from estim.config.settings import (
    REQUIRED,
    Settings,
    block,
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
from estim.estimators.kronecker_ekf import KroneckerEKF
from estim.estimators.wavelet_lms import WaveletLMS
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, plots
from estim.experiments.shared.blocks import Model as ModelBlock
from estim.numerics import opcount
from estim.reference.tablespec import TableSpec
from estim.util import lazy

pd = lazy.load("pandas")
pywt = lazy.load("pywt")


@settings_class
class Timing(Settings):
    """How the wall time per step is measured (this machine's; check skips it)."""

    steps: int = setting(200, integer(10, 100_000), doc="EKF steps timed")
    repeats: int = setting(5, integer(1, 100), doc="repeats (the median is kept)")
    block_samples: int = setting(512, integer(64, 1_000_000),
                                 doc="samples of the wavelet method's block")
    sample_time_s: float = setting(3.125e-5, number(positive=True, maximum=1.0), unit="s",
                                   doc="sample time")
    fundamental_hz: float = setting(1000.0, number(positive=True, maximum=1e9), unit="Hz",
                                    doc="the input's fundamental")
    batch_runs: int = setting(256, integer(2, 100_000),
                              doc="runs filtered together in the second timing")


@settings_class
class Tables(Settings):
    """The thesis tables joined."""

    burden_ekf: str = setting("4.3", text(), doc="the EKF's table")
    burden_wt: str = setting("4.4", text(), doc="the wavelet method's table")


@settings_class
class Figures(Settings):
    """The figure."""

    name: str = setting("fig_burden", file_name, doc="the figure's file name")


@settings_class
class Config(Settings):
    """Tables 4.3-4.4: multiplications per step, printed, as written and counted."""

    model: Any = block(ModelBlock, required=True, doc="a chain of stages (mosfet_darlington)")
    stages: list = setting([1, 2, 4, 8], list_of(integer(1, 64), max_length=8, unique=True),
                           doc="chain lengths (n_x = 4 per stage)")
    ekf: dict = setting(REQUIRED, mapping, doc="the Kronecker EKF's settings")
    wavelet: dict = setting(REQUIRED, mapping, doc="the wavelet method's settings")
    timing: Timing = block(Timing, doc="the wall-time measurement")
    claim_passes: int = setting(200, integer(1, 1_000_000),
                                doc="LMS passes the burden claim counts (Table 4.2's LMS "
                                    "runs 200); the cross-over table gives every count")
    tables: Tables = block(Tables, doc="the thesis tables joined")
    figures: Figures = block(Figures, doc="the figure")


SCHEMA: dict = Config.schema()

_KEYS = ("table_id", "row_order", "row_label_printed", "n_x", "d", "p",
         "multiplications_printed", "ours_formula")
TABLES = {
    "burden_ekf": TableSpec("burden_ekf.csv", (*_KEYS, "as_written_formula"),
                            ("printed", "as_written", "counted", "ours_value"),
                            join=(("row_order", ("row_order",)),),
                            title="EKF multiplications per step: printed formula, counted, ours",
                            reference_ids=("4.3",)),
    "burden_wt": TableSpec("burden_wt.csv", _KEYS,
                           ("printed", "counted", "ours_value", "kept_coefficients"),
                           join=(("row_order", ("row_order",)),),
                           title="wavelet method multiplications: printed formula, counted",
                           reference_ids=("4.4",)),
    "timing": TableSpec("timing.csv", ("estimator", "n_x"),
                        ("seconds_per_step", "counted_per_step"),
                        title="measured wall time per step (this machine)"),
    "slopes": TableSpec("slopes.csv", ("estimator", "quantity"), ("slope",),
                        title="log-log slope of the counted multiplications against n_x"),
    "timing_slopes": TableSpec("timing_slopes.csv", ("estimator", "quantity"), ("slope",),
                               title="log-log slope of the wall time against n_x (this "
                                     "machine)"),
    "crossover": TableSpec("crossover.csv", ("n_x",),
                           ("ekf_per_sample", "lms_fixed_per_sample", "lms_per_pass_per_sample",
                            "crossover_passes", "claim_passes", "lms_at_claim_passes"),
                           title="wavelet LMS multiplications per sample against its passes: "
                                 "fixed (regressors, transform) + passes x one pass; the "
                                 "passes at which it equals the Kronecker EKF's"),
    "claims": claims.TABLE,
}
EKF, WAVELET = "Kronecker EKF", "wavelet LMS"
"""The thesis' comparison of the two burdens (Tables 4.3-4.4: the EKF O(n_x^3), the wavelet
method O(n_x^5)): multiplications per sample, counted on our code (the EKF per step, the
wavelet method per sample of a block, its transform included), the LMS at the config's
``claim_passes`` passes (the claim names them). Deterministic: exact."""


def wavelet_label(passes: int) -> str:
    """The wavelet method's name in the claim, with the LMS passes it counts."""
    return f"{WAVELET} ({passes} passes)"
QUOTES = (
    Quote("Table 4.3, printed / as written (1: the printed count is exact)", "burden_ekf",
          "printed / as_written", by="row_label_printed", where="as_written == as_written"),
    Quote("Table 4.3, printed / counted on our code", "burden_ekf", "printed / counted",
          by="row_label_printed", where="printed == printed"),
    Quote("Table 4.4, printed / counted on our code", "burden_wt", "printed / counted",
          by="row_label_printed", where="printed == printed"),
    Quote("LMS passes at which the wavelet method costs the Kronecker EKF's multiplications "
          "per sample (n_x = 4 to 32)", "crossover", "crossover_passes"),
)

AS_WRITTEN = {
    # thesis row -> multiplications of the equation as the thesis writes it
    1: "n_x**3 + 2*n_x**2 + n_x*p",          # eq 4.36's F1 x + F2 (x (x) x) + B u
    2: "4*n_x**3",                           # F P F^T + L Q L^T with a general n x n L
    3: "2*n_x**2*d + 2*n_x*d**2",            # P H^T formed twice, M = I, inverse not counted
    4: "2*n_x*d",                            # H x and K nu
    5: "n_x**3 + n_x**2*d",                  # (I - K H) P, the plain form A.16 prints
    6: "6*n_x**3 + 3*n_x**2*d + 2*n_x*d**2 + 2*n_x**2 + n_x*p + 2*n_x*d",   # rows 1-5
    7: "n_x**3 + 2*n_x**2 + n_x*p",          # eq 4.15 itself
}
"""Table 4.3 read literally (docs/deviations.md D55): each row's equation counted in the
form the thesis writes it, so that a printed count can be called exact or off."""

EKF_ROWS = {
    # thesis row -> (our opcount labels, closed form of what the code does)
    1: (("A.12",), "n_x**3 + 2*n_x**2 + n_x*p"),
    2: (("A.13",), "2*n_x**3"),
    3: (("A.14",), "n_x**2*d + 2*n_x*d**2 + ceil(d**3/3)"),
    4: (("A.15",), "2*n_x*d"),
    5: (("A.16",), "2*n_x**3 + 2*n_x**2*d + n_x*d**2"),
    6: (("total",), "6*n_x**3 + 3*n_x**2*d + 3*n_x*d**2 + 2*n_x**2 + n_x*p + 2*n_x*d"
                    " + ceil(d**3/3)"),
    7: (("A.12",), "n_x**3 + 2*n_x**2 + n_x*p"),
}
JACOBIAN_ROW = (8, "quadratic Jacobian (not printed)", ("jacobian",), "n_x**3")


def evaluate(expr: str, n_x: int, d: int, p: int, **extra: float) -> float:
    """A multiplication-count expression at ``n_x, d, p`` (Python syntax, ``ceil`` allowed)."""
    names = {"n_x": n_x, "d": d, "p": p, "ceil": math.ceil, **extra}
    return float(eval(expr, {"__builtins__": {}}, names))  # noqa: S307 - own and shipped text


def dwt_coefficients(samples: int, wavelet: str) -> int:
    """Detail coefficients ``wavedec`` (mode ``periodization``) computes over every level:
    ``C = sum_j ceil(N / 2^j)``; each costs ``2 taps`` multiplications (two filters)."""
    level = max(1, pywt.dwt_max_level(samples, pywt.Wavelet(wavelet).dec_len))
    return sum(math.ceil(samples / 2**j) for j in range(1, level + 1))


@dataclass(frozen=True)
class Plan:
    """What the burden analysis builds once: the chain of each length, and the two
    estimators whose multiplications it counts."""

    models: dict
    ekf: KroneckerEKF
    wavelet: WaveletLMS


def prepare(config: Config, source: str) -> Plan:
    model_cls = registry.MODELS[config.model.name]
    if "stages" not in model_cls.Params.__dataclass_fields__:
        raise ConfigError(source, "model.name", f"{model_cls.name} has no 'stages' parameter: "
                          "the burden is measured on chains of stages (mosfet_darlington)")
    models = {}
    for i, k in enumerate(config.stages):
        models[k] = build_model(model_cls, config.model.variant,
                                {**config.model.params, "stages": k}, source,
                                f"stages[{i}]")
    first = models[config.stages[0]]
    ekf = build_estimator(KroneckerEKF, config.ekf, first, source, "ekf")
    wavelet = build_estimator(WaveletLMS, config.wavelet, first, source, "wavelet")
    for given, built in ((config.ekf, ekf), (config.wavelet, wavelet)):
        given.clear()                   # every default, in the resolved config's own mapping
        given.update(built.to_spec())
    if wavelet.measures is not None:
        raise ConfigError(source, "wavelet.measures", "the burden is counted with every state "
                          "measured (eq 4.16, H = I); leave measures unset")
    for metric, table_id in config.tables.items():
        if not reference.has_reference_table(table_id):
            raise ConfigError(source, f"tables.{metric}", f"no reference table {table_id!r}")
    return Plan(models, ekf, wavelet)


def work_units(exp: Experiment) -> int:
    return len(exp.config.stages)


def work_size(config: Config) -> int:
    t = config.timing
    return int(sum(4 * k * (t.steps + t.block_samples) * t.repeats
                   for k in config.stages))


def tiny(config: Config) -> dict:
    """Seconds of work: two chains, ten steps, one repeat."""
    return {"stages": config.stages[:2], "timing.steps": 10, "timing.repeats": 1,
            "timing.block_samples": 64}


def _measure_ekf(est: KroneckerEKF, model, steps: int, repeats: int, dt: float,
                 batch: int):
    n = model.n_states
    D = est.discrete(model, dt)
    H = np.asarray(model.h_jacobian(D.terms.x_op), float)
    Q, R = 1e-8 * np.eye(n), 1e-6 * np.eye(H.shape[0])
    x = D.terms.x_op[None].copy()
    P = 1e-8 * np.eye(n)[None]
    z = np.zeros((1, H.shape[0]))
    u = np.zeros((1, model.n_inputs))
    with opcount.counting(runs=1) as tally:
        est.cycle(D, H, x, P, z, u, Q, R)
    rng = np.random.default_rng(0)
    us = np.zeros((steps, model.n_inputs))
    out = []
    for runs in (1, batch):
        zs = D.terms.x_op[-1] + 1e-3 * rng.standard_normal((runs, steps, H.shape[0]))
        seconds = []
        for _ in range(repeats):
            start = time.perf_counter()
            est.run(model, zs, us, dt, x0=D.terms.x_op)
            seconds.append((time.perf_counter() - start) / (steps * runs))
        out.append(float(np.median(seconds)))
    return tally, out[0], out[1]


def _measure_wavelet(est: WaveletLMS, model, samples: int, repeats: int, dt: float, f: float):
    n = model.n_states
    rng = np.random.default_rng(0)
    t = np.arange(samples) * dt
    y = 1e-3 * rng.standard_normal((1, samples, n)) + np.sin(2 * np.pi * f * t)[None, :, None]
    u = np.cos(2 * np.pi * f * t)[None, :, None].repeat(model.n_inputs, axis=2)
    with opcount.counting(runs=1) as tally:
        fit = est.identify(y, u, np.zeros(n), dt, f)
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        est.identify(y, u, np.zeros(n), dt, f)
        seconds.append((time.perf_counter() - start) / samples)
    return tally, round(fit["kept_fraction"] * samples), float(np.median(seconds))


TIMING_FIGURE = "burden_timing"
"""The figure of the wall times (the counts' figure is named by ``figures.name``)."""

MACHINE = ("timing", "timing_slopes", TIMING_FIGURE)
"""What measures the machine: written under ``machine/`` (untracked), never compared."""

RUNS_ALONE = True
"""Its tables are timings: ``estim reproduce``, ``estim check`` and ``estim run`` of several
configs run it after every other config, with no other work on the machine's cores
(:mod:`estim.engine.scheduler`)."""


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    """Counts and timings, one chain length after another in this process (timings are
    ratios within one process; parallel jobs would disturb them)."""
    config, plan = exp.config, exp.plan
    t = config.timing
    ref_ekf = reference.reference_table(config.tables.burden_ekf)
    ref_wt = reference.reference_table(config.tables.burden_wt)
    ekf_rows, wt_rows, timing, crossover_rows = [], [], [], []
    for k in config.stages:
        model = plan.models[k]
        n, d, p = model.n_states, model.n_outputs, model.n_inputs
        tally, sec, sec_batch = _measure_ekf(plan.ekf, model, t.steps, t.repeats,
                                             t.sample_time_s, t.batch_runs)
        common = {"n_x": n, "d": d, "p": p}
        for _, row in ref_ekf.iterrows():
            labels, ours = EKF_ROWS[int(row["row_order"])]
            ekf_rows.append({"table_id": config.tables.burden_ekf,
                             "row_order": int(row["row_order"]),
                             "row_label_printed": row["row_label_printed"], **common,
                             "multiplications_printed": row["multiplications_printed"],
                             "printed": evaluate(row["multiplications_expr"], n, d, p),
                             "as_written_formula": AS_WRITTEN[int(row["row_order"])],
                             "as_written": evaluate(AS_WRITTEN[int(row["row_order"])], n, d,
                                                    p),
                             "counted": sum(tally.get(lab, 0.0) for lab in labels),
                             "ours_formula": ours, "ours_value": evaluate(ours, n, d, p)})
        order, label, labels, ours = JACOBIAN_ROW
        ekf_rows.append({"table_id": config.tables.burden_ekf, "row_order": order,
                         "row_label_printed": label, **common, "multiplications_printed": "-",
                         "printed": float("nan"), "as_written_formula": "-",
                         "as_written": float("nan"), "counted": tally.get("jacobian", 0.0),
                         "ours_formula": ours, "ours_value": evaluate(ours, n, d, p)})
        wt_tally, kept, wt_sec = _measure_wavelet(plan.wavelet, model, t.block_samples,
                                                  t.repeats, t.sample_time_s,
                                                  t.fundamental_hz)
        epochs = plan.wavelet.epochs
        ours_wt = {1: ("regressors", "N*q*(q+1)/2"),
                   2: ("LMS", "epochs*K*(2*q*D + 2*D)")}
        size = {"N": t.block_samples, "q": n, "D": n + n * (n + 1) // 2 + p + 1, "K": kept,
                "epochs": epochs, "taps": pywt.Wavelet(plan.wavelet.wavelet).dec_len,
                "C": dwt_coefficients(t.block_samples, plan.wavelet.wavelet)}
        for _, row in ref_wt.iterrows():
            label, ours = ours_wt[int(row["row_order"])]
            wt_rows.append({"table_id": config.tables.burden_wt,
                            "row_order": int(row["row_order"]),
                            "row_label_printed": row["row_label_printed"], **common,
                            "multiplications_printed": row["multiplications_printed"],
                            "printed": evaluate(row["multiplications_expr"], n, d, p),
                            "counted": wt_tally.get(label, 0.0), "ours_formula": ours,
                            "ours_value": evaluate(ours, n, d, p, **size),
                            "kept_coefficients": kept})
        wt_rows.append({"table_id": config.tables.burden_wt, "row_order": 3,
                        "row_label_printed": "wavelet transform (not printed)", **common,
                        "multiplications_printed": "-", "printed": float("nan"),
                        "counted": wt_tally.get("wavelet transform", 0.0),
                        "ours_formula": "2*taps*C*(q + D)",
                        "ours_value": evaluate("2*taps*C*(q + D)", n, d, p, **size),
                        "kept_coefficients": kept})
        timing.append({"estimator": "Kronecker EKF", "n_x": n, "seconds_per_step": sec,
                       "counted_per_step": tally["total"]})
        timing.append({"estimator": f"Kronecker EKF, {t.batch_runs} runs batched (per run)",
                       "n_x": n, "seconds_per_step": sec_batch,
                       "counted_per_step": tally["total"]})
        timing.append({"estimator": "wavelet LMS (per sample of a block)", "n_x": n,
                       "seconds_per_step": wt_sec,
                       "counted_per_step": wt_tally["total"] / t.block_samples})
        per_pass = wt_tally.get("LMS", 0.0) / epochs / t.block_samples
        fixed = wt_tally["total"] / t.block_samples - epochs * per_pass
        crossover_rows.append({
            "n_x": n, "ekf_per_sample": float(tally["total"]), "lms_fixed_per_sample": fixed,
            "lms_per_pass_per_sample": per_pass,
            "crossover_passes": (tally["total"] - fixed) / per_pass if per_pass else np.inf,
            "claim_passes": config.claim_passes,
            "lms_at_claim_passes": fixed + config.claim_passes * per_pass})
        if on_done:
            on_done()
    out = Result(tables={
        "burden_ekf": pd.DataFrame(ekf_rows)[TABLES["burden_ekf"].columns],
        "burden_wt": pd.DataFrame(wt_rows)[TABLES["burden_wt"].columns],
        "timing": pd.DataFrame(timing)[TABLES["timing"].columns],
    })
    out.tables["slopes"] = slopes(out.tables["timing"], "counted")
    out.tables["timing_slopes"] = slopes(out.tables["timing"], "seconds")
    out.tables["crossover"] = pd.DataFrame(crossover_rows)[TABLES["crossover"].columns]
    wavelet = wavelet_label(config.claim_passes)
    cells = [(claims.cell(n_x=int(row["n_x"])),
              {EKF: claims.Losses([float(row["ekf_per_sample"])]),
               wavelet: claims.Losses([float(row["lms_at_claim_passes"])])})
             for _, row in out.tables["crossover"].iterrows()]
    out.tables["claims"] = claims.table(cells, ((EKF, wavelet),), "multiplications per sample",
                                         exact=True)
    out.figures[config.figures.name] = plots.burden(out.tables["timing"],
                                                        out.tables["slopes"])
    out.figures[TIMING_FIGURE] = plots.burden_timing(out.tables["timing"],
                                                     out.tables["timing_slopes"])
    return out


def slopes(timing: pd.DataFrame, quantity: str) -> pd.DataFrame:
    """Least-squares slope of ``log`` counts (``quantity`` ``"counted"``) or ``log`` seconds
    (``"seconds"``) per step against ``log n_x``."""
    column = {"counted": "counted_per_step", "seconds": "seconds_per_step"}[quantity]
    rows = []
    for est, part in timing.groupby("estimator", sort=False):
        if len(part) < 2:
            continue
        logn = np.log(part["n_x"].to_numpy(float))
        slope = float(np.polyfit(logn, np.log(part[column].to_numpy(float)), 1)[0])
        rows.append({"estimator": est, "quantity": quantity, "slope": slope})
    return pd.DataFrame(rows, columns=TABLES["slopes"].columns)


def printout(result: Result) -> str:
    ekf = result.tables["burden_ekf"]
    view = ekf.pivot_table(index=["row_order", "row_label_printed"], columns="n_x",
                           values=["printed", "counted"], sort=False)
    return (view.to_string(float_format=lambda v: f"{v:.4g}") + "\n\n"
            + result.tables["slopes"].to_string(index=False, float_format=lambda v: f"{v:.3g}")
            + "\n\nwall time per step on this machine, log-log slopes:\n"
            + result.tables["timing_slopes"].to_string(index=False,
                                                       float_format=lambda v: f"{v:.3g}"))
