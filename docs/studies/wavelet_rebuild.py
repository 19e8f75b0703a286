"""Why the wavelet method's rebuilt model diverges in many runs (Table 4.2, D54).

Run from the project folder: ``python docs/studies/wavelet_rebuild.py [frequency_hz]``. For
the 2/2 column of ``configs/kronecker_table_4_2.yaml`` at O.U. noise 0.001 (sigma reading)
and the given frequency (default 1000 Hz), 30 runs: the per-sample spectral radius of the
actual circuit's linearisation, each state's spread over the record against the 1 mV
measurement noise, and, for the states the method is given (all four, v_G and v_D, v_D only)
and for LMS and least squares, how many identified models have a linear part with spectral
radius above one and how many rebuilds leave the bound.
"""

from __future__ import annotations

import sys

import numpy as np
import yaml
from scipy import linalg

from estim.config.loading import parse_data
from estim.estimators.wavelet_lms import WaveletLMS, fundamental
from estim.experiments import kronecker as analysis
from estim.numerics import kronecker_form as kronecker


def main(frequency_hz: float) -> None:
    spec = yaml.safe_load(open("configs/kronecker_table_4_2.yaml"))
    spec["check"] = {}
    exp = parse_data(spec, "wavelet_rebuild", "wavelet_rebuild")
    column = exp.plan.columns[0]
    point = next(p for p in analysis.sweep(exp) if p.reading == "sigma"
                 and p.level == 0.001 and p.frequency_hz == frequency_hz)
    runs = exp.spec["monte_carlo"]["runs"]
    data = analysis.simulate_point(exp, column, point, runs)
    model, dt = column.truth, data["dt"]
    terms = kronecker.from_model(model, column.x0)
    rho = np.max(np.abs(np.linalg.eigvals(linalg.expm(dt * terms.A1))))
    print(f"{frequency_hz:g} Hz, T_s = {dt:.3g} s: actual circuit's per-sample spectral radius "
          f"{rho:.6f} (1 - {1 - rho:.2e})")
    spread = data["states"].std(axis=1).mean(axis=0)
    print("state spread over the record [V]:",
          ", ".join(f"{n} {s:.2g}" for n, s in zip(model.state_names, spread, strict=True)),
          f"(measurement noise {exp.spec['noise']['measurement_sigma']:g} V)")
    u = np.repeat(model.source_to_input(data["clean"][None], dt), runs, axis=0)
    for measures in (None, ["v_G", "v_D"], ["v_D"]):
        est = WaveletLMS(measures=measures, epochs=200)
        seen = est.measured_states(model)
        y0 = data["x0"][seen]
        fit = est.identify(data["measured"][..., seen], u, y0, dt, fundamental(u, dt))
        q = len(seen)
        for solver in ("lms", "least_squares"):
            theta = fit[solver]
            radius = np.abs(np.linalg.eigvals(np.eye(q) + theta[:, :, :q])).max(axis=1)
            _, broken = est.rebuild(theta, u, y0)
            names = " ".join(model.state_names[i] for i in seen)
            print(f"  sees {names:16s} {solver:13s}: spectral radius > 1 in "
                  f"{int((radius > 1).sum()):2d} of {runs}, median {np.median(radius):.4f}; "
                  f"rebuild left the bound in {int(broken.sum())}")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 1000.0)
