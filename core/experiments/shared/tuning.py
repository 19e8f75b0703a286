"""Maximum-likelihood noise covariances for a Kalman-type filter (issue 11, not in the thesis).

For a filter with a Gaussian noise model the innovations ``nu_k`` are, given the past,
``N(0, S_k)``; the log-likelihood of a batch of measurement records is

    log L = -1/2 sum_runs sum_k ( log det(2 pi S_k) + nu_k^T S_k^-1 nu_k )

(the prediction-error decomposition; Schweppe 1965). :func:`fit` maximises it over the
diagonal of ``Q`` (and optionally ``R``), each entry as ``exp(theta)`` so it stays positive,
with scipy's L-BFGS-B (forward-difference gradients on a step of 1e-4 in ``theta``: a
likelihood summed over 1e5 innovations carries rounding of ~1e-10 relative, which the
default 1e-8 step turns into gradient noise larger than the gradient). Where L-BFGS-B stops
without converging (a likelihood with runs that break is not smooth), Nelder-Mead continues
from its point with a simplex of one unit (a factor e) in each entry. Standard errors
come from the inverse of the finite-difference Hessian of ``-log L`` in ``theta`` (the
observed information), mapped by the delta method (``se(q) = q se(theta)``). When that
Hessian is not positive definite, or its condition
number exceeds :data:`IDENTIFIABLE_CONDITION`, or an entry's standard error exceeds the
entry itself, the fit is reported as not identifiable from these data, naming the entries:
an entry the likelihood does not depend on (a state the output never sees) has no standard
error and an arbitrary value.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estim.util import lazy

optimize = lazy.load("scipy.optimize")

IDENTIFIABLE_CONDITION = 1e8
"""Largest condition number of the observed information at which the fit is reported."""


LOST_STEP_NIS = 100.0
"""A step lost to a broken run scores as an innovation of this NIS (10 standard deviations
for one output) with ``S = R``: worse than any step a working filter plausibly has."""


def log_likelihood(innovation: np.ndarray, S: np.ndarray, R: np.ndarray | None = None) -> float:
    """Innovation log-likelihood of a batch ``(runs, steps, m)``.

    A step without a finite innovation (the run broke before it) makes the result ``-inf``;
    with ``R`` given it scores as :data:`LOST_STEP_NIS` instead, so that a fit started where
    some runs break can still climb towards settings that keep them.
    """
    m = innovation.shape[-1]
    with np.errstate(invalid="ignore"):
        sign, logdet = np.linalg.slogdet(np.where(np.isfinite(S), S, np.eye(m)))
    ok = (np.all(np.isfinite(innovation), axis=-1) & np.all(np.isfinite(S), axis=(-2, -1))
          & (sign > 0))
    if not ok.all() and R is None:
        return -np.inf
    quad = np.sum(innovation[ok] * np.linalg.solve(S[ok], innovation[ok][..., None])[..., 0],
                  axis=-1)
    total = -0.5 * np.sum(logdet[ok] + quad + m * np.log(2 * np.pi))
    lost = int(np.sum(~ok))
    if lost:
        total -= 0.5 * lost * (np.linalg.slogdet(np.atleast_2d(R))[1] + LOST_STEP_NIS * m
                               + m * np.log(2 * np.pi))
    return float(total)


@dataclass(frozen=True)
class Fit:
    """Result of :func:`fit`: fitted diagonals, their standard errors (NaN where not
    identifiable), log-likelihoods at the start and the optimum, and a verdict."""

    q: np.ndarray
    q_se: np.ndarray
    r: np.ndarray
    r_se: np.ndarray
    log_likelihood_start: float
    log_likelihood: float
    identifiable: bool
    message: str
    evaluations: int


def _hessian(fun: Callable[[np.ndarray], float], x: np.ndarray, step: float = 1e-2) -> np.ndarray:
    """Central second differences of ``fun`` at ``x``."""
    n = x.size
    H = np.empty((n, n))
    f0 = fun(x)
    for i in range(n):
        ei = np.zeros(n)
        ei[i] = step
        H[i, i] = (fun(x + ei) - 2 * f0 + fun(x - ei)) / step**2
        for j in range(i):
            ej = np.zeros(n)
            ej[j] = step
            H[i, j] = H[j, i] = (fun(x + ei + ej) - fun(x + ei - ej) - fun(x - ei + ej)
                                 + fun(x - ei - ej)) / (4 * step**2)
    return H


def fit(evaluate: Callable[[np.ndarray, np.ndarray], float], q0: np.ndarray, r0: np.ndarray,
        fit_r: bool = False, max_iterations: int = 200,
        progress: Callable[[int, float], None] | None = None) -> Fit:
    """Maximise ``evaluate(q_diag, r_diag)`` (a log-likelihood) over ``q`` (and ``r``).

    ``q0`` and ``r0`` are the starting diagonals; with ``fit_r`` false ``r`` stays ``r0``.
    ``progress(evaluations, best log-likelihood so far)`` is called after every evaluation.
    """
    q0, r0 = np.asarray(q0, float), np.asarray(r0, float)
    nq = q0.size
    count = [0]

    def split(theta):
        q = np.exp(theta[:nq])
        r = np.exp(theta[nq:]) if fit_r else r0
        return q, r

    best = [-np.inf]

    def nll(theta):
        count[0] += 1
        value = evaluate(*split(theta))
        if np.isfinite(value):
            best[0] = max(best[0], value)
        if progress is not None:
            progress(count[0], best[0])
        return 1e300 if not np.isfinite(value) else -value

    theta0 = np.log(np.concatenate([q0, r0]) if fit_r else q0)
    start = -nll(theta0)
    res = optimize.minimize(nll, theta0, method="L-BFGS-B",
                            bounds=[(t - 25.0, t + 25.0) for t in theta0],
                            options={"maxiter": max_iterations, "eps": 1e-4})
    if not res.success:
        steps = np.eye(theta0.size)
        simplex = np.vstack([res.x, res.x + steps])
        res = optimize.minimize(nll, res.x, method="Nelder-Mead",
                                options={"initial_simplex": simplex, "maxfev": 40 * theta0.size**2,
                                         "xatol": 1e-2, "fatol": 1e-1})
        res.message = f"L-BFGS-B stopped, Nelder-Mead from there: {res.message}"
    q, r = split(res.x)
    H = _hessian(nll, res.x)
    scale = float(np.max(np.abs(np.diag(H)), initial=0.0))
    flat = ~(np.diag(H) > 1e-8 * scale) if scale > 0 else np.ones(theta0.size, bool)
    se = np.full(theta0.size, np.nan)
    condition = np.inf
    if not flat.all():
        sub = H[np.ix_(~flat, ~flat)]
        eig = np.linalg.eigvalsh(sub)
        if eig[0] > 0:
            condition = eig[-1] / eig[0]
            se[~flat] = np.sqrt(np.diag(np.linalg.inv(sub))) * np.exp(res.x[~flat])
    names = [f"Q[{i}]" for i in range(nq)] + ([f"R[{i}]" for i in range(r0.size)]
                                              if fit_r else [])
    loose = [name for name, s_, v in zip(names, se, np.exp(res.x), strict=True)
             if not s_ < v]
    identifiable = not loose and condition < IDENTIFIABLE_CONDITION
    spread = [name for name, f, s_, v in zip(names, flat, se, np.exp(res.x), strict=True)
              if not f and np.isfinite(s_) and not s_ < v]
    if condition >= IDENTIFIABLE_CONDITION:
        se[:] = np.nan
        loose = names
    if identifiable:
        message = f"converged: {res.message}" if res.success else f"stopped: {res.message}"
    else:
        message = (f"not identifiable from these data: {', '.join(loose)} "
                   f"({'; '.join(_why(names, flat, spread, condition))}). The fitted values "
                   f"still raise the log-likelihood from {start:.6g} to {-res.fun:.6g}, so "
                   "they may well help the filter (run it beside the others to see), but the "
                   "data do not pin these entries down: another fit may land elsewhere")
    q_se = se[:nq]
    r_se = se[nq:] if fit_r else np.full(r0.size, np.nan)
    return Fit(q=q, q_se=q_se, r=np.asarray(r, float), r_se=r_se,
               log_likelihood_start=float(start), log_likelihood=float(-res.fun),
               identifiable=identifiable, message=message, evaluations=count[0])


def _why(names: list[str], flat: np.ndarray, spread: list[str], condition: float) -> list[str]:
    """The reasons :func:`fit` gives for entries it cannot pin down."""
    reasons = []
    if flat.any():
        reasons.append("the likelihood does not change with "
                       + ", ".join(n for n, f in zip(names, flat, strict=True) if f)
                       + " (a state the output never sees, or a noise swamped by another)")
    if spread:
        reasons.append(f"{', '.join(spread)}: standard error above the value")
    if not flat.all() and not np.isfinite(condition):
        reasons.append("the likelihood's curvature at the optimum is not positive definite "
                       "(no standard errors)")
    elif condition >= IDENTIFIABLE_CONDITION:
        reasons.append(f"the observed information's condition number is {condition:.2g}, "
                       f"above {IDENTIFIABLE_CONDITION:.0e}: some combination of the entries "
                       "leaves the likelihood flat (no standard errors)")
    return reasons


def check_tunable(exp, label: str) -> None:
    """What :func:`tune` cannot fit, as a ``UsageError`` before any work: a swept config (it
    would fit the config's own values, no cell of the sweep), a config whose filters carry
    element values as states (``estimate``: the fitted Q would not be the config's), and a
    full-matrix ``Q`` or ``R`` of ``label`` (the fit is of diagonals; the off-diagonal
    entries would be lost)."""
    from estim.errors import UsageError

    if exp.sweep:
        raise UsageError(f"{exp.source}: estim tune fits one config, and this one sweeps "
                         f"{', '.join(exp.sweep)}; tune one cell (its values as "
                         "overrides of a copy without the sweep block)")
    if getattr(exp.config, "estimate", ()):
        raise UsageError(f"{exp.source}: estim tune fits the Q of the circuit's states, and "
                         "this config's filters carry element values (estimate) as states "
                         "too; tune a copy without the estimate block")
    entry = next((e for e in getattr(exp.config, "estimators", ()) if e.label == label), None)
    for key in ("Q", "R"):
        given = (entry.settings if entry else {}).get(key, 0.0)
        if isinstance(given, dict):          # by state name: a diagonal
            continue
        M = np.asarray(given, dtype=float)
        if M.ndim == 2 and np.any(M - np.diag(np.diag(M))):
            raise UsageError(f"{exp.source}: estim tune fits diagonal covariances; the {key} "
                             f"of {label!r} is a full matrix (its off-diagonal entries would "
                             "be dropped)")


def tune(exp, training: Callable, label: str, runs: int, fit_r: bool = False,
         progress: Callable[[int, float], None] | None = None) -> tuple[dict, Fit]:
    """Maximum-likelihood ``Q`` (and ``R``) of the filter ``label`` of ``exp``, pooled over the
    training draws its analysis gives (``training(exp, label, runs)``, e.g.
    :func:`estim.experiments.estimation.training`): one setting for the table, as the thesis
    uses one. Returns the estimator's config entry with the fitted diagonals, and the
    :class:`Fit`. ``progress`` is :func:`fit`'s."""
    from estim.errors import UsageError
    from estim.estimators.base import as_matrix, takes_generator

    check_tunable(exp, label)
    index, est, model, batches = training(exp, label, runs)
    if not (hasattr(est, "Q") and hasattr(est, "R")):
        raise UsageError(f"{exp.name}: {label!r} has no noise covariances to fit")
    n, m = model.n_states, model.n_outputs
    labels = est.state_labels(model) if hasattr(est, "state_labels") else None
    q0 = np.diag(as_matrix(est.Q, n, "Q", labels)).copy()
    r0 = np.diag(as_matrix(est.R, m, "R")).copy()
    q0[q0 <= 0] = 1e-12 * max(float(q0.max()), 1e-300)

    def evaluate(q, r):
        trial = dataclasses.replace(est, Q=[float(v) for v in q], R=[float(v) for v in r])
        total = 0.0
        for data in batches:            # a filter's own draws repeat at every evaluation
            extra = ({"rng": exp.config.monte_carlo.rng(*data["generator_key"])}
                     if takes_generator(trial) else {})
            out = trial.run(model, data["z"], data["u"], data["dt"], x0=data["x0"], **extra)
            total += log_likelihood(out.innovation, out.S, R=as_matrix(r, m, "R"))
            if not np.isfinite(total):
                return -np.inf
        return total

    result = fit(evaluate, q0, r0, fit_r=fit_r, progress=progress)
    entry = exp.config.estimators[index].to_spec()
    entry["settings"]["Q"] = [float(f"{v:.6g}") for v in result.q]
    if fit_r:
        entry["settings"]["R"] = [float(f"{v:.6g}") for v in result.r]
    return entry, result


def overlay(entry: dict, result: Fit, label: str, runs: int, command: str, seconds: float,
            fit_r: bool) -> str:
    """The YAML overlay ``estim tune`` writes: the fit as comments (likelihoods, standard
    errors, identifiability), then the fitted estimator entry."""
    import yaml

    lines = [
        f"# Written by: {command}",
        f"# Maximum-likelihood noise covariances of {label!r} (estim tune) on training",
        f"# draws of {runs} runs per sweep point, apart from the table's draws.",
        f"# Innovation log-likelihood: {result.log_likelihood_start:.6g} at the config's "
        f"values, {result.log_likelihood:.6g} fitted ({result.evaluations} evaluations, "
        f"{seconds:.0f} s).",
        f"# {result.message}",
        f"# Q diagonal:    {[float(f'{v:.4g}') for v in result.q]}",
        f"# standard error {[float(f'{v:.2g}') for v in result.q_se]}",
    ]
    if fit_r:
        lines += [f"# R diagonal:    {[float(f'{v:.4g}') for v in result.r]}",
                  f"# standard error {[float(f'{v:.2g}') for v in result.r_se]}"]
    lines.append("# Add the entry below to the config's estimators to run it beside the others.")
    return "\n".join(lines) + "\n" + yaml.safe_dump({"estimators": [entry]}, sort_keys=False)
