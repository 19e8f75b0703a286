"""Fraction of actual samples in a named regime over gate bias (docs/deviations.md D38).

Run from the project folder, e.g.::

    python docs/studies/regime_scan.py configs/mosfet_saturation.yaml \
        weak_inversion_saturation 1e5 0.25 0.3 0.35 0.435

(arguments: config, regime, R_D, then gate biases V_IN). Prints, per V_IN, the fraction at
each frequency (100 Hz, 1 kHz, 10 kHz) and input-noise sigma (0.1, 0.25, 0.316, 0.5 V), 10
runs each, and how many of those 12 cells fall below one half.
"""

from __future__ import annotations

import sys

import numpy as np
import yaml

from estim.config import loading as config
from estim.errors import ConfigError
from estim.experiments import estimation


def scan(path: str, regime: str, r_d: float, biases: list[float]) -> None:
    with open(path) as fh:
        base = yaml.safe_load(fh)
    base["estimators"] = [e for e in base["estimators"] if e["type"] == "rls"]
    base["figures"], base["claims"] = {}, []
    base.pop("check", None)
    for v_in in biases:
        data = yaml.safe_load(yaml.safe_dump(base))
        data["model"]["params"].update(V_IN=v_in, R_D=r_d)
        try:
            exp = config.parse_data(data, "scan", "scan")
        except ConfigError as exc:
            print(f"V_IN={v_in}: {exc}")
            continue
        out = []
        for f in (100.0, 1000.0, 10000.0):
            for sigma in (0.1, 0.25, 0.316, 0.5):
                batch = estimation.simulate_point(exp, f, sigma, 10, np.random.default_rng(0))
                inside = exp.plan.truth.in_regime(regime, batch["states"],
                                                  batch["source"][:, 1:])
                out.append(float(np.mean(inside)))
        below = sum(o < 0.5 for o in out)
        print(f"R_D={r_d:g} V_IN={v_in}: min {min(out):.2f} max {max(out):.2f} "
              f"below half: {below}/12  " + " ".join(f"{o:.2f}" for o in out))


if __name__ == "__main__":
    scan(sys.argv[1], sys.argv[2], float(sys.argv[3]), [float(v) for v in sys.argv[4:]])
