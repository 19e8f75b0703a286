"""Re-measure the audit's Chapter 3 figures that the stored tables do not show (issue 11, D39, D41).

Run from the project folder: ``python docs/studies/audit_checks.py``. Each check draws its own
batches (seed 2019, 30 runs) and prints one line:

* conduction: diverged runs of the thesis-Q EKF per row with ``Q_gate`` lowered to 2.5e-4,
  and with the continuous-discrete (``radau``) predictor, against the stored setting;
* RLS on the saturation stage: the largest eigenvalue of ``P`` and the fraction of steps at
  ``lambda_min`` after 200, 800 and 2000 samples (the record-length dependence);
* the amplifier's row 2 (sigma 0.01, 1 kHz): ``Q`` fitted by maximum likelihood on that row
  alone, and the EKF's RMSE with it; and an empirical causal Wiener bound: the best causal
  FIR filter of the measurements (40 taps and a constant, fitted by least squares on 300
  training runs) applied to the table's draws;
* conduction: the spread (standard deviation over samples and runs) of the true drain per row.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import yaml

from estim.config import loading as config
from estim.experiments import estimation
from estim.experiments.shared import health, tuning
from estim.numerics import metrics


def load(name: str, labels: tuple[str, ...], **changes) -> object:
    with open(f"configs/{name}.yaml") as fh:
        data = yaml.safe_load(fh)
    data["estimators"] = [e for e in data["estimators"] if e["label"] in labels]
    data["claims"], data["figures"] = [], {}
    data.pop("check", None)
    for path, value in changes.items():
        node = data
        *parents, last = path.split(".")
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node[key]
        node[last] = value
    return config.parse_data(data, name, name)


def batch(exp, point, runs=30):
    rng = np.random.default_rng(np.random.SeedSequence(2019, spawn_key=(point.index,)))
    return estimation.simulate_point(exp, point.frequency_hz, point.sigma, runs, rng,
                                      point.measurement)


def diverged_per_row(exp) -> list[int]:
    out = []
    for point in estimation.sweep(exp):
        data = batch(exp, point)
        (_, est, model), = exp.plan.filters
        result = est.run(model, data["z"], data["u"], data["dt"], x0=data["x0"])
        cfg = exp.spec["health"]                        # the tables' criterion (D37)
        out.append(int(health.diverged(result, data["actual"], model.output_range(),
                                       cfg["consecutive"], cfg["growth"]).sum()))
    return out


def conduction() -> None:
    q = [0.0025, 0.002, 0.002, 0.002]
    cases = {
        "stored": {},
        "Q_gate 2.5e-4": {"estimators.0.settings.Q": [2.5e-4, *q[1:]]},
        "radau predictor": {"estimators.0.settings.discretization": "radau"},
    }
    for name, changes in cases.items():
        counts = diverged_per_row(load("mosfet_conduction", ("EKF",), **changes))
        print(f"conduction EKF, {name}: diverged runs per row {counts} (total {sum(counts)})")


def rls_record_length() -> None:
    point = estimation.sweep(load("mosfet_saturation", ("RLS",)))[1]
    for periods in (20, 80, 200):
        longer = load("mosfet_saturation", ("RLS",), **{"input.periods": periods})
        data = batch(longer, point)
        (_, est, model), = longer.plan.filters
        out = est.run(model, data["z"], data["u"], data["dt"])
        d = out.diagnostics
        rmse = np.mean(metrics.rmse_per_run(data["actual"], out.y_hat))
        print(f"RLS, saturation row 2, {periods * 10} samples: largest eigenvalue of P "
              f"{np.median(d['p_max_eig']):.3g}, lambda at floor "
              f"{100 * np.median(d['lambda_at_floor']):.0f} %, rank "
              f"{np.median(d['regressor_rank']):.0f} of {np.median(d['regressor_size']):.0f}, "
              f"RMSE {rmse:.3f} V")


def amplifier_row_2() -> None:
    exp = load("diffamp_ekf", ("EKF",), **{"noise.measurement": ["noisy"]})
    point = estimation.sweep(exp)[1]
    (_, est, model), = exp.plan.filters
    train_rng = np.random.default_rng(np.random.SeedSequence(
        2019, spawn_key=(estimation.TUNE_SEED_KEY, point.index)))
    train = estimation.simulate_point(exp, point.frequency_hz, point.sigma, 30, train_rng)

    def evaluate(q, r):
        trial = dataclasses.replace(est, Q=list(q))
        out = trial.run(model, train["z"], train["u"], train["dt"], x0=train["x0"])
        return tuning.log_likelihood(out.innovation, out.S)

    fit = tuning.fit(evaluate, np.full(4, 0.01), np.array([0.1]))
    wiener_train = estimation.simulate_point(exp, point.frequency_hz, point.sigma, 300,
                                             np.random.default_rng(np.random.SeedSequence(
                                                 2019, spawn_key=(2**33, point.index))))
    test = batch(exp, point)
    for label, q in (("thesis Q", [0.01] * 4), ("Q fitted on row 2", list(fit.q))):
        trial = dataclasses.replace(est, Q=q)
        out = trial.run(model, test["z"], test["u"], test["dt"], x0=test["x0"])
        rmse = np.mean(metrics.rmse_per_run(test["actual"], out.y_hat))
        shown = ", ".join(f"{v:.3g}" for v in q)
        print(f"amplifier row 2, EKF with {label} [{shown}]: RMSE {rmse:.3f} V")
    taps = 40
    X, y = fir_design(wiener_train["z"][..., 0], taps), wiener_train["actual"][..., 0]
    w = np.linalg.lstsq(X.reshape(-1, X.shape[-1]), y.reshape(-1), rcond=None)[0]
    estimate = fir_design(test["z"][..., 0], taps) @ w
    rmse = np.mean(np.sqrt(np.mean((estimate - test["actual"][..., 0]) ** 2, axis=1)))
    print(f"amplifier row 2, causal Wiener FIR ({taps} taps) of the measurements: RMSE "
          f"{rmse:.3f} V; raw measurement "
          f"{np.mean(metrics.rmse_per_run(test['actual'], test['z'])):.3f} V")


def fir_design(z: np.ndarray, taps: int) -> np.ndarray:
    """``(runs, steps, taps + 1)``: ``[1, z_k, z_{k-1}, ..., z_{k-taps+1}]`` (zeros before
    the record)."""
    runs, steps = z.shape
    padded = np.concatenate([np.zeros((runs, taps - 1)), z], axis=1)
    lagged = [padded[:, taps - 1 - j: taps - 1 - j + steps] for j in range(taps)]
    return np.stack([np.ones((runs, steps)), *lagged], axis=-1)


def conduction_drain_spread() -> None:
    exp = load("mosfet_conduction", ("RLS",))
    spread = [float(np.std(batch(exp, point)["actual"])) for point in estimation.sweep(exp)]
    print("conduction, true drain spread per row (V): "
          + " ".join(f"{s:.3f}" for s in spread))


if __name__ == "__main__":
    conduction()
    rls_record_length()
    amplifier_row_2()
    conduction_drain_spread()
