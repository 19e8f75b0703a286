"""How far the Chapter 2 distortion tables are from what a true sine input gives.

Run from the project folder: ``python docs/studies/staircase_vs_sine.py`` (about 6.5 minutes on
two cores; ``--jobs 1`` for one).

The perturbation analysis samples its sine source at ``excitation.samples_per_period`` = 128
points a period, and each model turns the samples into its input on each interval
(``source_to_input``): the amplifiers (``diffamp_exp``, ``diffamp_em``) hold the mean of an
interval's two end samples over it (a staircase), the EKV MOSFET is driven by the slope of
the piecewise-linear source. So ``percent_distortion``, ``thd_percent`` and ``gain_db`` in
``results/<name>/distortion.csv`` belong to a staircase or a piecewise-linear input, not to a
sine. This study re-runs the analysis' own computation (``perturbation.respond_row`` and
``summarize``) at N = 128, 256, ... samples a period and extrapolates to N -> infinity (the
true sine; the metrics are taken from the N output samples of whole periods, exact for the
ten harmonics used, so only the input changes with N).

How:

* N = 128 with the config's own solver tolerances must give back the stored table (printed:
  the largest relative difference of the three columns).
* The sequence in N is computed with the solver tolerance tightened to rtol 1e-11, atol 1e-13
  (at the configs' 1e-8 the integrator's error, ~1e-5 of the THD at N >= 4096, blurs the
  convergence orders); the N = 128 point of that sequence differs from the stored value by
  the solver error only (printed).
* The limit is a Richardson extrapolation in h = 1/N over the finest levels, with the error
  terms seen in the differences between successive levels (printed as observed orders,
  log2 of the ratio of successive differences, at the two finest pairs):
  staircase (amplifiers): h, h^2, h^3 on N = 128 .. 4096. THD converges as h^2; gain and
  percent distortion also have a term in h, largest in the 100 Hz rows (presumably the held
  input's half-interval lag, seen by the fast part of the circuit but not by the slow
  0.26 s state, which integrates the input). The printed EM amplifier shows h^2 only.
  piecewise linear (MOSFET): h^2, h^3, h^4 on N = 128 .. 131072. Order 2 is reached only
  once N f is well above the circuit's fast poles (0.23 us): from N ~ 512 at 10 kHz, but
  N ~ 1e4 at 100 Hz. N above the schema's 10000 is set on the parsed experiment's spec
  (the models, built at parse time, do not depend on N).
  The uncertainty printed is the change of the limit when the last error term is dropped
  (one level fewer).

Printed per config: every row's stored value, extrapolated limit and change (limit - stored;
relative for THD and percent distortion, in dB for gain), then the largest change.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from concurrent.futures import ProcessPoolExecutor
from functools import cache
from pathlib import Path

import numpy as np
import pandas as pd

from estim.config import loading as config
from estim.config.experiment import Experiment
from estim.config.settings import checked
from estim.experiments import perturbation

COLUMNS = ("percent_distortion", "thd_percent", "gain_db")
SHORT = {"percent_distortion": "PD", "thd_percent": "THD", "gain_db": "gain"}
STORED_N = 128
TIGHT = {"simulation.rtol": 1.0e-11, "simulation.atol": 1.0e-13}
STAIRCASE = (tuple(STORED_N * 2**k for k in range(6)), (1, 2, 3))
PIECEWISE_LINEAR = (tuple(STORED_N * 2**k for k in range(11)), (2, 3, 4))
CONFIGS: dict[str, tuple[tuple[int, ...], tuple[int, ...]]] = {
    "diffamp_distortion": STAIRCASE,
    "diffamp_em_distortion": STAIRCASE,
    "diffamp_printed_distortion": STAIRCASE,
    "diffamp_em_printed_distortion": STAIRCASE,
    "mosfet_distortion": PIECEWISE_LINEAR,
}
"""Config -> (samples per period, exponents of h = 1/N in the Richardson extrapolation)."""


@cache
def experiment(name: str, tight: bool) -> Experiment:
    """The config as the analysis parses it, with the tight solver tolerances if asked."""
    source = f"configs/{name}.yaml"
    data = config.load_yaml(Path(source).read_text(), source)
    if tight:
        data = config.apply_overrides(data, TIGHT, source)
    return config.parse_data(data, source, name)


def with_samples(exp: Experiment, n: int) -> Experiment:
    """``exp`` at ``n`` samples a period (also above the schema's limit of 10000)."""
    with checked():                     # the schema's limit is the study's to pass
        excitation = dataclasses.replace(exp.config.excitation, samples_per_period=n)
    return dataclasses.replace(exp, config=dataclasses.replace(exp.config,
                                                              excitation=excitation))


def evaluate(task: tuple[str, bool, int, int]) -> tuple[tuple[str, bool, int, int], dict]:
    """The three columns of one row at ``n`` samples a period."""
    name, tight, n, s_no = task
    exp = with_samples(experiment(name, tight), n)
    row = next(r for r in exp.config.rows if r.s_no == s_no)
    response, amplitudes = perturbation.respond_row(exp, row)
    summary = perturbation.summarize(exp, row, response, amplitudes)
    return task, {c: summary[c] for c in COLUMNS}


def richardson(levels: tuple[int, ...], values: np.ndarray,
               exponents: tuple[int, ...]) -> float:
    """Limit h -> 0 of ``values`` at h = 1/N (``levels``): the exact fit of
    ``c0 + sum_p c_p h^p`` over the finest ``len(exponents) + 1`` levels."""
    k = len(exponents) + 1
    h = STORED_N / np.asarray(levels[-k:], float)
    basis = np.column_stack([np.ones(k)] + [h**p for p in exponents])
    return float(np.linalg.solve(basis, values[-k:])[0])


def observed_orders(values: np.ndarray) -> np.ndarray:
    """log2 of the ratio of successive differences (levels doubling)."""
    d = np.diff(values)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log2(np.abs(d[:-1] / d[1:]))


def change(column: str, new: float, old: float) -> float:
    """``new - old``: relative for the percentages, in dB for the gain."""
    return new - old if column == "gain_db" else new / old - 1.0


def report(name: str, got: dict, stored: pd.DataFrame) -> None:
    levels, exponents = CONFIGS[name]
    rows = [int(s) for s in stored["s_no"]]
    repro = max(abs(got[name, False, STORED_N, s][c] / stored.loc[s, c] - 1.0)
                for s in rows for c in COLUMNS)
    solver = max(abs(change(c, got[name, True, STORED_N, s][c], stored.loc[s, c]))
                 for s in rows for c in COLUMNS)
    kind = "staircase" if exponents[0] == 1 else "piecewise linear"
    print(f"\n{name}  ({kind} input; N = {levels[0]}..{levels[-1]}, Richardson in h^"
          f"{', h^'.join(map(str, exponents))})")
    print(f"  N = {STORED_N} at the config's tolerances vs distortion.csv: max rel diff "
          f"{repro:.1e};  tight solver vs stored at N = {STORED_N}: {solver:.1e}")
    print("  s_no  f (Hz)   A (V) | PD stored   limit       rel chg  | THD stored  limit"
          "       rel chg  | gain stored (dB)  chg (dB)")
    worst = {c: 0.0 for c in COLUMNS}
    spread = {c: 0.0 for c in COLUMNS}
    orders: dict[str, list[float]] = {c: [] for c in COLUMNS}
    for s in rows:
        line = (f"  {s:4d} {stored.loc[s, 'frequency_hz']:7g} "
                f"{stored.loc[s, 'amplitude_v']:7g} |")
        for c in COLUMNS:
            values = np.array([got[name, True, n, s][c] for n in levels])
            limit = richardson(levels, values, exponents)
            lower = richardson(levels[:-1], values[:-1], exponents[:-1])
            delta = change(c, limit, stored.loc[s, c])
            spread[c] = max(spread[c], abs(change(c, limit, lower)))
            if abs(delta) > abs(worst[c]):
                worst[c] = delta
            orders[c].extend(observed_orders(values)[-2:])
            if c == "gain_db":
                line += f" {stored.loc[s, c]:16.8f}  {delta:+.2e}"
            else:
                line += f" {stored.loc[s, c]:.5e} {limit:.5e} {delta:+.2e} |"
        print(line)
    print("  largest change (limit - stored): "
          f"PD {worst['percent_distortion']:+.2e} rel, THD {worst['thd_percent']:+.2e} rel, "
          f"gain {worst['gain_db']:+.2e} dB")
    print("  extrapolation uncertainty (max): "
          f"PD {spread['percent_distortion']:.0e} rel, THD {spread['thd_percent']:.0e} rel, "
          f"gain {spread['gain_db']:.0e} dB")
    print("  observed orders, two finest pairs (min..max over rows): " + ", ".join(
        f"{SHORT[c]} {np.nanmin(orders[c]):.2f}..{np.nanmax(orders[c]):.2f}" for c in COLUMNS))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    args = parser.parse_args()
    start = time.perf_counter()
    stored = {name: pd.read_csv(f"results/{name}/distortion.csv").set_index("s_no", drop=False)
              for name in CONFIGS}
    tasks = []
    for name, (levels, _) in CONFIGS.items():
        for s_no in stored[name]["s_no"]:
            tasks.append((name, False, STORED_N, int(s_no)))
            tasks.extend((name, True, n, int(s_no)) for n in levels)
    # the largest N first so that the two workers finish together
    tasks.sort(key=lambda t: -t[2] * (1 if t[0].startswith("mosfet") else 32))
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        got = dict(pool.map(evaluate, tasks))
    print("Staircase / piecewise-linear source (as stored, N = 128) against a true sine "
          "(N -> infinity)")
    for name in CONFIGS:
        report(name, got, stored[name])
    print(f"\n{len(tasks)} responses in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
