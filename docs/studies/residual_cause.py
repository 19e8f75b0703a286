"""Why the EKF's residual mean is large in Tables 3.3/3.4 (issue 11): re-measure the causes.

Run from the project folder: ``python docs/studies/residual_cause.py [V_IN ...]``. For the
saturation config at each gate bias, at thesis row 2 (input noise sigma 0.25 V, 1 kHz):
the true drain's mean with and without the input noise, the EKF's predicted drain (mean and
fraction of steps below ground), and the EKF's RMSE when it is given the true (noisy) input.
"""

from __future__ import annotations

import sys

import numpy as np
import yaml

from estim.config import loading as config
from estim.experiments import estimation
from estim.numerics import metrics


def experiment(v_in: float, filters_see: str):
    data = yaml.safe_load(open("configs/mosfet_saturation.yaml"))
    data["model"]["params"]["V_IN"] = v_in
    data["estimators"] = [e for e in data["estimators"] if e["label"] == "EKF"]
    data["claims"], data["figures"] = [], {}
    data.pop("check", None)
    data["noise"]["filters_see"] = filters_see
    return config.parse_data(data, "residual_cause", "residual_cause")


def main(biases: list[float]) -> None:
    for v_in in biases:
        out = {}
        for see in ("nominal", "noisy"):
            exp = experiment(v_in, see)
            for sigma in (0.0, 0.25):
                rng = np.random.default_rng(np.random.SeedSequence(2019, spawn_key=(1,)))
                data = estimation.simulate_point(exp, 1000.0, sigma, 30, rng)
                est = estimation.estimate_point(exp, data)[0]
                prior = data["z"] - est.innovation
                out[see, sigma] = dict(
                    true_mean=float(np.mean(data["actual"])),
                    prior_mean=float(np.nanmean(prior)),
                    prior_negative=float(np.nanmean(prior < 0)),
                    prior_above=float(np.nanmean(prior > exp.plan.truth.params.V_DD)),
                    residual_mean=float(np.nanmean(est.innovation)),
                    rmse=float(np.nanmean(metrics.rmse_per_run(data["actual"], est.y_hat))))
        a, b, c = out["nominal", 0.25], out["nominal", 0.0], out["noisy", 0.25]
        print(f"V_IN = {v_in} V (row 2: sigma 0.25 V, 1 kHz, 30 runs)")
        print(f"  true drain mean: {a['true_mean']:.4f} V with input noise, "
              f"{b['true_mean']:.4f} V without (shift {a['true_mean'] - b['true_mean']:+.4f})")
        print(f"  EKF predicted drain: mean {a['prior_mean']:.4f} V, below ground in "
              f"{100 * a['prior_negative']:.0f} % of steps, above V_DD in "
              f"{100 * a['prior_above']:.0f} %; residual mean "
              f"{a['residual_mean']:.4f} V; RMSE {a['rmse']:.4f} V")
        print(f"  EKF given the true noisy input: residual mean {c['residual_mean']:.4f} V, "
              f"RMSE {c['rmse']:.4f} V; predicted drain below ground in "
              f"{100 * c['prior_negative']:.0f} %, above V_DD in {100 * c['prior_above']:.0f} %")


if __name__ == "__main__":
    main([float(v) for v in sys.argv[1:]] or [0.35, 0.435])
