"""What makes the wavelet method's rebuilt model diverge in Table 4.2 (D54): slow poles, an
unconverged LMS, or the quadratic terms.

Run from the project folder: ``python docs/studies/wavelet_divergence_cause.py [epochs]``
(default 2000). Every cell of ``configs/kronecker_table_4_2.yaml`` (W/L column x noise
reading x level x frequency) is simulated with the analysis' own seeds
(:func:`estim.experiments.kronecker.simulate_point`), and its "LMS" and "LMS (least squares)"
estimators are run on the inputs :func:`estim.experiments.kronecker.run_point` gives them and
judged by :func:`estim.experiments.shared.pipeline.judge`; the per-cell divergence counts are
checked against the stored ``results/kronecker_table_4_2/health.csv``. Over all runs it counts:

* the runs where "LMS" diverges, and of those the runs whose identified linear part
  ``I + Theta[:, :q]`` has spectral radius above one;
* the runs that diverge when the same LMS fit is rebuilt with its quadratic coefficients
  (the ``c_i c_j`` columns of Theta) set to zero;
* the runs where the least-squares fit diverges, and of those the runs with radius above one;
* the runs that diverge when the LMS runs ``epochs`` passes instead of the config's.

The cells run in parallel over the machine's cores; the wall time is printed at the end.
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd

from estim.config import loading as config
from estim.estimators.base import Estimate, batch_input
from estim.estimators.wavelet_lms import WaveletLMS, fundamental
from estim.experiments import kronecker as analysis
from estim.experiments.shared import pipeline

CONFIG = "configs/kronecker_table_4_2.yaml"
STORED = "results/kronecker_table_4_2/health.csv"
LMS, LS = "LMS", "LMS (least squares)"
COUNTS = ("lms_div", "lms_div_rho", "lms_rho", "noquad_div", "noquad_div_rho", "noquad_only",
          "ls_div",
          "ls_div_rho", "ls_rho", "long_div", "long_div_rho", "long_rho", "long_fixed",
          "long_new", "mirror_mismatch")


def experiment():
    """The stored Table 4.2 config, parsed as ``estim reproduce`` parses it."""
    with open(CONFIG) as f:
        return config.parse(f.read(), CONFIG, "kronecker_table_4_2")


def radius(theta: np.ndarray) -> np.ndarray:
    """``(runs,)`` spectral radius of the identified linear part ``I + Theta[:, :, :q]``."""
    q = theta.shape[1]
    return np.abs(np.linalg.eigvals(np.eye(q) + theta[:, :, :q])).max(axis=1)


def without_quadratic(theta: np.ndarray) -> np.ndarray:
    """``theta`` with the columns of the ``c_i c_j (i <= j)`` regressors set to zero:
    ``phi = [c (q), c_i c_j (q(q+1)/2), u, 1]``
    (:func:`estim.estimators.wavelet_lms.regressors`)."""
    q = theta.shape[1]
    out = theta.copy()
    out[:, :, q:q + q * (q + 1) // 2] = 0.0
    return out


def diverged_rebuild(exp, data: dict, est: WaveletLMS, model, z: np.ndarray, u: np.ndarray,
                     y0: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``(runs,)`` divergence of the model ``theta`` rebuilt as ``WaveletLMS.run`` rebuilds
    it, judged as the analysis judges it."""
    states, broken = est.rebuild(theta, u, y0)
    out = est.measured_states(model).index(est.output_state(model))
    y_hat = states[..., out:out + 1]
    estimate = Estimate(y_hat=y_hat, innovation=z[..., out:out + 1] - y_hat, broken=broken)
    return pipeline.judge(exp, data, estimate, model)["diverged"]


def inputs(data: dict, model, seen: list[int]) -> tuple[np.ndarray, ...]:
    """What ``run_point`` gives a state-measuring estimator (``z`` and ``u``), and the
    batched input and DC point ``WaveletLMS.run`` identifies from (``u`` per run, ``y0``)."""
    z = data["measured"][..., seen]
    u = model.source_to_input(data["clean"][None], data["dt"])[0]
    return z, u, batch_input(u, z.shape[0]), np.asarray(data["x0"], float)[seen]


def cell(args: tuple) -> dict:
    """Counts over the runs of one column and sweep point."""
    exp, index, point, epochs = args
    column = exp.plan.columns[index]
    data = analysis.simulate_point(exp, column, point, exp.spec["monte_carlo"]["runs"])
    filters = {label: (est, model, seen) for label, est, model, seen in column.filters}
    flags, fits, given = {}, {}, {}
    for label in (LMS, LS):
        est, model, seen = filters[label]
        given[label] = z, u, ub, y0 = inputs(data, model, seen)
        flags[label] = pipeline.judge(exp, data, est.run(model, z, u, data["dt"],
                                                            x0=data["x0"]), model)["diverged"]
        fits[label] = est.identify(z, ub, y0, data["dt"], fundamental(ub, data["dt"]))
    est, model, _ = filters[LMS]
    z, _, ub, y0 = given[LMS]
    lms = fits[LMS]["lms"]
    mirror = diverged_rebuild(exp, data, est, model, z, ub, y0, lms)
    noquad = diverged_rebuild(exp, data, est, model, z, ub, y0, without_quadratic(lms))
    longer = WaveletLMS(**{**vars(est), "epochs": epochs})
    long_fit = longer.identify(z, ub, y0, data["dt"], fundamental(ub, data["dt"]))
    long_theta = long_fit["lms"]
    long_div = diverged_rebuild(exp, data, longer, model, z, ub, y0, long_theta)
    rho_lms, rho_ls, rho_long = (radius(lms), radius(fits[LS]["least_squares"]),
                                 radius(long_theta))
    lms_div, ls_div = flags[LMS], flags[LS]
    counts = {
        "lms_div": lms_div.sum(), "lms_div_rho": (lms_div & (rho_lms > 1)).sum(),
        "lms_rho": (rho_lms > 1).sum(),
        "noquad_div": noquad.sum(), "noquad_div_rho": (noquad & (rho_lms > 1)).sum(),
        "noquad_only": (noquad & ~lms_div).sum(),
        "ls_div": ls_div.sum(), "ls_div_rho": (ls_div & (rho_ls > 1)).sum(),
        "ls_rho": (rho_ls > 1).sum(),
        "long_div": long_div.sum(), "long_div_rho": (long_div & (rho_long > 1)).sum(),
        "long_rho": (rho_long > 1).sum(), "long_fixed": (lms_div & ~long_div).sum(),
        "long_new": (long_div & ~lms_div).sum(),
        "mirror_mismatch": (mirror != lms_div).sum(),
    }
    return {"noise_reading": point.reading, "noise_param": point.level,
            "frequency_hz": point.frequency_hz, "w_um": column.w_um, "l_um": column.l_um,
            "runs": lms_div.size, **{k: int(v) for k, v in counts.items()},
            "rho_lms": rho_lms, "rho_long": rho_long, "gap_lms": fits[LMS]["gap"],
            "gap_long": long_fit["gap"]}


def reproduction(df: pd.DataFrame) -> str:
    """How the per-cell divergence counts compare with the stored health table."""
    stored = pd.read_csv(STORED)
    keys = ["noise_reading", "noise_param", "frequency_hz", "w_um", "l_um"]
    lines = []
    for label, column in ((LMS, "lms_div"), (LS, "ls_div")):
        ref = stored[stored["estimator"] == label][[*keys, "diverged"]]
        both = df.merge(ref, on=keys, how="outer", validate="one_to_one")
        differ = int((both[column] != both["diverged"]).sum())
        lines.append(f"  {label:20s}: {int(df[column].sum()):4d} here, "
                     f"{int(ref['diverged'].sum()):4d} stored; {differ} of {len(both)} cells "
                     "differ")
    return "\n".join(lines)


def main(epochs: int) -> None:
    start = time.perf_counter()
    exp = experiment()
    tasks = [(exp, i, p, epochs) for i in range(len(exp.plan.columns))
             for p in analysis.sweep(exp)]
    with ProcessPoolExecutor(max_workers=min(len(tasks), os.cpu_count() or 1)) as pool:
        df = pd.DataFrame(list(pool.map(cell, tasks)))
    total = df[list(COUNTS)].sum()
    runs = int(df["runs"].sum())
    base = next(e["settings"] for e in exp.spec["estimators"] if e["label"] == LMS)
    print(f"Table 4.2, {len(df)} cells x {exp.spec['monte_carlo']['runs']} runs = {runs} runs; "
          f"'{LMS}': step {base['step']:g}, {base['epochs']} passes")
    print("reproduction of the stored divergence counts (health.csv):")
    print(reproduction(df))
    print(f"  mirrored rebuild of the LMS fit vs WaveletLMS.run: {total['mirror_mismatch']} "
          "runs differ")
    print()
    rows = [
        (f"LMS ({base['epochs']} passes)", total["lms_div"], total["lms_div_rho"],
         total["lms_rho"]),
        ("same LMS fit, quadratic terms zero", total["noquad_div"], total["noquad_div_rho"],
         total["lms_rho"]),
        ("least squares", total["ls_div"], total["ls_div_rho"], total["ls_rho"]),
        (f"LMS ({epochs} passes)", total["long_div"], total["long_div_rho"], total["long_rho"]),
    ]
    print(f"{'fit':38s} {'diverged':>9s} {'of those rho>1':>15s} {'all rho>1':>10s}")
    for name, div, div_rho, rho in rows:
        print(f"{name:38s} {div:9d} {div_rho:15d} {rho:10d}")
    print("(the zeroed fit keeps the LMS linear part: its rho column is the LMS fit's)")
    print()
    print(f"quadratic terms zero: diverge only without them {total['noquad_only']}, "
          f"still diverge {total['noquad_div'] - total['noquad_only']} of {total['lms_div']}")
    print(f"{epochs} passes: of the {total['lms_div']} diverged at {base['epochs']}, "
          f"{total['long_fixed']} no longer diverge; {total['long_new']} newly diverge")
    med = {key: np.median(np.concatenate(df[key].tolist()))
           for key in ("rho_lms", "rho_long", "gap_lms", "gap_long")}
    print(f"median over runs, {base['epochs']} / {epochs} passes: spectral radius of the LMS "
          f"fit {med['rho_lms']:.5f} / {med['rho_long']:.5f}; relative distance to the "
          f"least-squares fit |Theta_LMS - Theta_LS| / |Theta_LS| {med['gap_lms']:.3f} / "
          f"{med['gap_long']:.3f}")
    print()
    print("by frequency (all columns and noise settings):")
    by = df.groupby("frequency_hz")[["runs", "lms_div", "lms_div_rho", "noquad_div", "ls_div",
                                     "ls_div_rho", "long_div"]].sum()
    print(by.to_string())
    print()
    print("by W/L column:")
    by = df.groupby(["w_um", "l_um"], sort=False)[["runs", "lms_div", "lms_div_rho",
                                                   "noquad_div", "ls_div", "ls_div_rho",
                                                   "long_div"]].sum()
    print(by.to_string())
    print()
    print(f"wall time {time.perf_counter() - start:.0f} s on {os.cpu_count()} cores")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2000)
