"""How accurate the Chapter 3 "actual" signal is at the configs' solver tolerance.

Run from the project folder: ``python docs/studies/actual_signal_accuracy.py [--workers 2]``
(about 5 minutes on 2 cores).

For configs/mosfet_saturation.yaml, mosfet_conduction.yaml and mosfet_input_derivative.yaml
and every sweep point, the actual circuit is integrated as ``estimation.simulate_point``
does (the config's solver, ``simulation.rtol``/``atol``, the seeds of ``run_point``), and
again from the SAME noisy source with the batched Radau IIA at a tight tolerance (default
rtol 1e-10, atol 1e-13, as bench/bench_simulate.py makes its reference). The output (drain
voltage) error against the tight run is reported per point and per config: the largest
absolute error over all runs and samples, the largest per-run RMS error over the samples,
and the median per-run RMS error. The reference itself is checked on the worst point by an
even tighter run (rtol 1e-12, atol 1e-15).
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from estim.config import loading as config
from estim.config.experiment import Experiment
from estim.experiments import estimation
from estim.numerics.simulate import simulate

CONFIGS = ("mosfet_saturation", "mosfet_conduction", "mosfet_input_derivative")
TIGHTER = (1e-12, 1e-15)


def load(name: str) -> Experiment:
    path = Path("configs") / f"{name}.yaml"
    return config.parse(path.read_text(), str(path), name)


def point_label(point: estimation.SweepPoint) -> str:
    return (f"#{point.index} {point.reading} {point.level:g} (sigma {point.sigma:.3g} V), "
            f"{point.frequency_hz:g} Hz")


def actual_pair(name: str, index: int, rtol: float, atol: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """The actual output of one sweep point as the analysis makes it, and the same noisy
    source integrated at ``rtol``/``atol``: ``(runs, samples)`` each."""
    exp = load(name)
    point = estimation.sweep(exp)[index]
    mc = exp.spec["monte_carlo"]
    rng = np.random.default_rng(np.random.SeedSequence(mc["seed"], spawn_key=(point.index,)))
    data = estimation.simulate_point(exp, point.frequency_hz, point.sigma, mc["runs"], rng,
                                     point.measurement)
    truth = exp.plan.truth
    u = truth.source_to_input(data["source"], data["dt"])
    tight = truth.h(simulate(truth, exp.plan.x0, u, data["dt"], rtol=rtol, atol=atol))
    return data["actual"][..., 0], tight[..., 0]


def point_errors(name: str, index: int, rtol: float, atol: float) -> dict:
    """Per-run largest absolute and RMS output error of one sweep point."""
    start = time.perf_counter()
    actual, tight = actual_pair(name, index, rtol, atol)
    error = actual - tight
    return {"name": name, "index": index, "max_abs": np.max(np.abs(error), axis=1),
            "rms": np.sqrt(np.mean(error**2, axis=1)), "seconds": time.perf_counter() - start}


def reference_check(name: str, index: int, rtol: float, atol: float) -> float:
    """Largest output difference between the reference and a tighter run, one point."""
    _, reference = actual_pair(name, index, rtol, atol)
    _, tighter = actual_pair(name, index, *TIGHTER)
    return float(np.max(np.abs(reference - tighter)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rtol", type=float, default=1e-10, help="reference rtol")
    parser.add_argument("--atol", type=float, default=1e-13, help="reference atol")
    args = parser.parse_args()
    start = time.perf_counter()
    experiments = {name: load(name) for name in CONFIGS}
    tasks = [(name, p.index) for name, exp in experiments.items()
             for p in estimation.sweep(exp)]
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(point_errors, name, i, args.rtol, args.atol) for name, i in tasks]
        results = [f.result() for f in futures]
    print(f"output (drain voltage) error of the actual signal against the same noisy source "
          f"at rtol {args.rtol:g}, atol {args.atol:g}")
    worst_overall = (-1.0, "", 0)
    for name, exp in experiments.items():
        sim, runs = exp.spec["simulation"], exp.spec["monte_carlo"]["runs"]
        points = estimation.sweep(exp)
        mine = [r for r in results if r["name"] == name]
        print(f"\n{name}: solver {sim['solver']}, rtol {sim['rtol']:g}, atol {sim['atol']:g}; "
              f"{len(points)} points x {runs} runs")
        print(f"  {'point':<42} {'max |err| V':>12} {'max RMS V':>10} {'median RMS':>10}")
        for r in mine:
            print(f"  {point_label(points[r['index']]):<42} {r['max_abs'].max():12.2e} "
                  f"{r['rms'].max():10.2e} {np.median(r['rms']):10.2e}")
        by_abs = max(mine, key=lambda r: r["max_abs"].max())
        by_rms = max(mine, key=lambda r: r["rms"].max())
        rms = np.concatenate([r["rms"] for r in mine])
        print(f"  largest absolute error {by_abs['max_abs'].max():.2e} V "
              f"({point_label(points[by_abs['index']])}, run {by_abs['max_abs'].argmax()})")
        print(f"  largest per-run RMS error {by_rms['rms'].max():.2e} V "
              f"({point_label(points[by_rms['index']])}, run {by_rms['rms'].argmax()})")
        print(f"  median per-run RMS error {np.median(rms):.2e} V over {rms.size} runs; "
              f"95th percentile {np.percentile(rms, 95):.2e} V")
        if by_abs["max_abs"].max() > worst_overall[0]:
            worst_overall = (float(by_abs["max_abs"].max()), name, by_abs["index"])
    _, name, index = worst_overall
    check = reference_check(name, index, args.rtol, args.atol)
    print(f"\nreference check, {name} {point_label(estimation.sweep(experiments[name])[index])}:"
          f" rtol {args.rtol:g}/atol {args.atol:g} vs rtol {TIGHTER[0]:g}/atol {TIGHTER[1]:g}"
          f" differ by at most {check:.2e} V")
    print(f"wall time {time.perf_counter() - start:.0f} s ({args.workers} workers)")


if __name__ == "__main__":
    main()
