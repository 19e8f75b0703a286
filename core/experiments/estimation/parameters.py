"""Element values as states (the config's ``estimate``, issue 47): every filter estimates
them with the circuit's states from a first guess, while the actual circuit keeps the
netlist's values (:mod:`estim.spice.parameter_states`). Here: the checks, each filter's
augmented model and covariances, and ``parameters.csv``, each value's final estimate against
the truth."""

from __future__ import annotations

import numpy as np

from estim.config.builders import build_estimator
from estim.errors import ConfigError
from estim.estimators.base import GaussianFilter, as_matrix
from estim.numerics import metrics
from estim.spice.netlist_model import NetlistModel
from estim.spice.parameter_states import Parameter, ParameterStates, split, value_of

VALUES = ("true", "start", "estimate", "estimate_se", "sigma", "error", "within_3_sigma",
          "runs", "diverged")
"""``parameters.csv``'s columns per filter and value: the truth (the actual circuit's value)
and the filters' first guess; over the runs that did not diverge, the mean of the final
estimates with its standard error, the mean of the filter's final standard deviation, the
mean estimate's error, and how many runs' final estimates are within three of their own
standard deviations of the truth; every run, and how many diverged."""


def check(config, truth, source: str) -> tuple[Parameter, ...]:
    """The config's ``estimate`` as :class:`Parameter` s, each naming a value of ``truth``'s
    netlist; a :class:`ConfigError` at the entry's key otherwise."""
    if not config.estimate:
        return ()
    if not isinstance(truth, NetlistModel):
        raise ConfigError(source, "estimate", f"model {config.model.name} is hand-written: "
                          "element values as states need a netlist model (model.netlist)")
    if truth.circuit.junctions:
        raise ConfigError(source, "estimate", f"{truth.circuit.junctions[0].name} is a "
                          "junction capacitance: element values as states take a constant "
                          "capacitance matrix")
    out, seen = [], {}
    for i, entry in enumerate(config.estimate):
        path = f"estimate[{i}]"
        try:
            value_of(truth, entry.name)
        except ValueError as err:
            raise ConfigError(source, f"{path}.name", str(err)) from None
        key = entry.name.lower()
        if key in seen:
            raise ConfigError(source, f"{path}.name", f"{entry.name!r} is already "
                              f"estimate[{seen[key]}]")
        seen[key] = i
        if entry.start == 0:
            raise ConfigError(source, f"{path}.start", "expected a first guess other than 0 "
                              "(the state is the value over it)")
        element, field = split(truth, entry.name)
        out.append(Parameter(entry.name, element, field, float(entry.start)))
    return tuple(out)


def true_ratios(truth, parameters: tuple[Parameter, ...]) -> np.ndarray:
    """Each value of the actual circuit over the filters' first guess (the states' truth)."""
    return np.array([value_of(truth, p.name) / p.start for p in parameters])


def augment(estimator, model, parameters: tuple[Parameter, ...], entries, source: str,
            path: str):
    """``(estimator, model)`` with the parameters as states: the model a
    :class:`ParameterStates`, the estimator's ``Q`` and ``P0`` (checked against the circuit's
    states first) with the values' entries ``(drift / start)^2`` and ``(sigma0 / start)^2``
    appended, and its ``x0`` with the first guesses (1)."""
    if not isinstance(estimator, GaussianFilter):
        raise ConfigError(source, f"{path}.type", f"{estimator.name!r} has no state "
                          "covariance to carry estimated values (estimate): use a filter of "
                          "the model (ekf, ukf, enkf, ...)")
    try:
        extended = ParameterStates(model, parameters)
    except ValueError as err:
        raise ConfigError(source, "estimate", str(err)) from None
    n, names = model.n_states, estimator.state_labels(model)
    blocks = []
    for key, spread in (("Q", [e.drift for e in entries]), ("P0", [e.sigma0 for e in entries])):
        M = np.zeros((n + len(parameters),) * 2)
        M[:n, :n] = as_matrix(getattr(estimator, key), n, key, names)
        M[n:, n:] = np.diag((np.array(spread) / extended.starts) ** 2)
        blocks.append(M.tolist())
    spec = {**estimator.to_spec(), "Q": blocks[0], "P0": blocks[1]}
    if estimator.x0 is not None:
        spec["x0"] = [*estimator.x0, *([1.0] * len(parameters))]
    return build_estimator(type(estimator), spec, extended, source, f"{path}.settings"), extended


def rows(filters: tuple, estimates: list, verdicts: list, theta: np.ndarray,
         common: dict) -> list[dict]:
    """``parameters.csv``'s rows (:data:`VALUES`) of one batch: per filter and value."""
    out = []
    for (label, _, model), est, diverged in zip(filters, estimates, verdicts, strict=True):
        if not isinstance(model, ParameterStates) or est.x_hat is None:
            continue
        n = model.base.n_states
        for j, p in enumerate(model.parameters):
            scale = abs(p.start)
            final = est.x_hat[:, -1, n + j] * p.start
            with np.errstate(invalid="ignore"):
                sd = np.sqrt(est.P[:, -1, n + j, n + j]) * scale
            kept = ~np.asarray(diverged, bool) & np.isfinite(final) & np.isfinite(sd)
            true = theta[j] * p.start
            mean, se = metrics.mean_and_se(final[kept])
            nan = float("nan")
            out.append({**common, "estimator": label, "parameter": p.name, "true": true,
                        "start": p.start, "estimate": mean, "estimate_se": se,
                        "sigma": float(np.mean(sd[kept])) if kept.any() else nan,
                        "error": mean - true,
                        "within_3_sigma": int(np.sum(np.abs(final[kept] - true)
                                                     <= 3 * sd[kept])),
                        "runs": int(final.size), "diverged": int(np.sum(diverged))})
    return out


def traces(filters: tuple, estimates: list, theta: np.ndarray) -> dict:
    """Run 0's estimate and standard deviation of each value by each filter, and the
    truth: what the ``parameters`` figure draws."""
    out: dict = {}
    for (label, _, model), est in zip(filters, estimates, strict=True):
        if not isinstance(model, ParameterStates) or est.x_hat is None:
            continue
        n = model.base.n_states
        for j, p in enumerate(model.parameters):
            unit = {"r": " [\u03a9]", "l": " [H]"}.get(p.element.rpartition(".")[2][:1], "")
            name = f"{p.name}{unit}" if p.field is None else p.name
            values = out.setdefault(name, {"true": theta[j] * p.start, "filters": {}})
            with np.errstate(invalid="ignore"):
                values["filters"][label] = (est.x_hat[0, :, n + j] * p.start,
                                            np.sqrt(est.P[0, :, n + j, n + j]) * abs(p.start))
    return out
