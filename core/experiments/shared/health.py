"""Filter health over a Monte Carlo batch: divergence, consistency and whiteness.

Two different things, kept apart (docs/claims.md):

* A run *diverged* (:func:`diverged`) when its estimate broke: the filter's numbers became
  non-finite (``Estimate.broken``), the output estimate stayed outside the model's physical
  range for ``consecutive`` steps, or the error ran away (:func:`runaway`: the RMS error of
  the last quarter of the record is more than ``growth`` times that of the second quarter
  and larger than the actual output's own RMS swing). A diverged run counts as a loss for
  its filter in every claim; the RMSE over all runs stays the headline, with the RMSE over
  the runs that did not diverge beside it.
* A filter is *consistent* when its errors match the covariances it reports (Bar-Shalom,
  Li and Kirubarajan 2001, sec 5.4): NEES ``e_k^T P_k^-1 e_k`` (``e_k = x_k - x_hat_k``,
  needs the true state) is chi-square with ``n`` degrees of freedom, NIS
  ``nu_k^T S_k^-1 nu_k`` (the innovation of eq 3.84) with ``m``. A run is *inconsistent*
  (:func:`inconsistent`) when its time-averaged NIS (or NEES) lies outside the two-sided
  ``band`` of ``chi-square(K m) / K`` over its ``K`` steps. Inconsistency is a health
  column: it never drops a run and never decides a claim.

Averaged over ``N`` runs at one step, ``N`` times the average is chi-square with ``N n``
(``N m``) degrees of freedom; :func:`averaged_in_band` gives the fraction of steps whose
run-average falls in the band. The innovations of a consistent filter are also white:
:func:`ljung_box` tests each run's innovations.
"""

from __future__ import annotations

import numpy as np

from estim.estimators.base import Estimate
from estim.util import lazy

special = lazy.load("scipy.special")

DEFAULTS = {
    "band": 0.95,            # two-sided probability of the NEES/NIS band
    "lag": 10,               # Ljung-Box lag
    "white_level": 0.05,     # Ljung-Box test size
    "consecutive": 5,        # steps in a row outside the physical range that make a run diverged
    "growth": 10.0,          # last-quarter over second-quarter RMS error of a runaway run
}


def _quadratic(e: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``e^T M^-1 e`` over leading axes; NaN where ``e`` or ``M`` is not finite or ``M`` is
    singular."""
    out = np.full(e.shape[:-1], np.nan)
    ok = np.all(np.isfinite(e), axis=-1) & np.all(np.isfinite(M), axis=(-2, -1))
    if ok.any():
        with np.errstate(all="ignore"):
            try:
                sol = np.linalg.solve(M[ok], e[ok][..., None])[..., 0]
            except np.linalg.LinAlgError:
                sol = np.stack([np.linalg.lstsq(a, b, rcond=None)[0]
                                for a, b in zip(M[ok], e[ok], strict=True)])
        out[ok] = np.sum(e[ok] * sol, axis=-1)
    return out


def nees(x_true: np.ndarray, x_hat: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared, ``(runs, steps)``."""
    return _quadratic(x_true - x_hat, P)


def nis(innovation: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Normalised innovation squared, ``(runs, steps)``."""
    return _quadratic(innovation, S)


def band(dof: int, runs: int, probability: float = DEFAULTS["band"]) -> tuple[float, float]:
    """Two-sided ``probability`` band of the average of ``runs`` chi-square(``dof``) values."""
    tail = (1.0 - probability) / 2.0
    k = dof * runs
    return float(chi2_ppf(tail, k) / runs), float(chi2_ppf(1.0 - tail, k) / runs)


def chi2_ppf(p: float, dof: int) -> float:
    """Quantile ``p`` of chi-square(``dof``): ``2 gammaincinv(dof/2, p)``, the computation
    of ``scipy.stats.chi2.ppf`` (tested equal), without importing scipy.stats (0.3 s)."""
    return float(2 * special.gammaincinv(dof / 2, p))


def chi2_sf(x: np.ndarray, dof: int) -> np.ndarray:
    """Survival function of chi-square(``dof``) at ``x``: ``chdtrc``, the computation of
    ``scipy.stats.chi2.sf`` (tested equal; 1 left of the support, as there)."""
    x = np.asarray(x, float)
    return special.chdtrc(dof, np.where(x < 0, 0.0, x))


def averaged_in_band(values: np.ndarray, dof: int,
                     probability: float = DEFAULTS["band"]) -> tuple[float, float]:
    """Mean of ``values (runs, steps)`` and the fraction of steps whose average over the runs
    lies in :func:`band`. Runs with a non-finite value anywhere are left out (they broke and
    are counted as diverged); NaN for both when no run is left."""
    keep = np.all(np.isfinite(values), axis=1)
    if not keep.any():
        return float("nan"), float("nan")
    avg = np.mean(values[keep], axis=0)
    lo, hi = band(dof, int(keep.sum()), probability)
    return float(np.mean(avg)), float(np.mean((avg >= lo) & (avg <= hi)))


def effective_lag(steps: int, lag: int = DEFAULTS["lag"]) -> int:
    """The Ljung-Box lag used on a record of ``steps``: ``lag``, at most a quarter of it."""
    return max(1, min(lag, steps // 4))


def ljung_box(x: np.ndarray, lag: int = DEFAULTS["lag"]) -> np.ndarray:
    """Ljung-Box p-values of each run of ``x (runs, steps)`` at ``lag`` (Ljung and Box 1978):
    ``Q = N (N+2) sum_h r_h^2 / (N-h)``, chi-square(``lag``) for a white sequence. NaN for a
    run with a non-finite value or no variance."""
    x = np.asarray(x, float)
    runs, steps = x.shape
    out = np.full(runs, np.nan)
    ok = np.all(np.isfinite(x), axis=1)
    if not ok.any() or not 1 <= lag < steps:
        return out
    d = x[ok] - x[ok].mean(axis=1, keepdims=True)
    denom = np.sum(d * d, axis=1)
    good = denom > 0
    h = np.arange(1, lag + 1)
    r = np.stack([np.sum(d[:, j:] * d[:, :-j], axis=1) for j in h], axis=1)
    with np.errstate(all="ignore"):
        r = r / denom[:, None]
        q = steps * (steps + 2) * np.sum(r**2 / (steps - h), axis=1)
    p = chi2_sf(q, lag)
    p[~good] = np.nan
    out[ok] = p
    return out


def white(innovation: np.ndarray, lag: int = DEFAULTS["lag"],
          level: float = DEFAULTS["white_level"]) -> np.ndarray:
    """``(runs,)`` whether each run's innovations ``(runs, steps, m)`` pass the Ljung-Box test
    at ``level`` (every output, each at ``level / m``). A broken run does not pass."""
    m = innovation.shape[-1]
    lag = effective_lag(innovation.shape[1], lag)
    passed = np.ones(innovation.shape[0], bool)
    for j in range(m):
        p = ljung_box(innovation[..., j], lag)
        passed &= np.nan_to_num(p, nan=-1.0) > level / m
    return passed


def _runs_of(flags: np.ndarray, consecutive: int) -> np.ndarray:
    """``(runs,)`` whether ``flags (runs, steps)`` holds on ``consecutive`` steps in a row."""
    if consecutive > flags.shape[1]:
        return np.zeros(flags.shape[0], bool)
    window = np.lib.stride_tricks.sliding_window_view(np.asarray(flags, bool), consecutive,
                                                      axis=1)
    return np.any(np.all(window, axis=-1), axis=1)


def runaway(error: np.ndarray, scale: np.ndarray | float = 0.0,
            growth: float = DEFAULTS["growth"]) -> np.ndarray:
    """``(runs,)`` runs whose error ``(runs, steps, m)`` grows without bound: the RMS error
    over the last quarter of the record exceeds ``growth`` times the RMS error over the
    second quarter and exceeds ``scale`` (per run or one number: the size below which an
    error is no runaway, e.g. the actual signal's own swing). Records shorter than 8 steps
    are never runaways. A run with a non-finite error is left to the ``broken`` flag."""
    error = np.asarray(error, float)
    runs, steps = error.shape[:2]
    if steps < 8:
        return np.zeros(runs, bool)
    q = steps // 4
    with np.errstate(invalid="ignore", over="ignore"):
        second = np.sqrt(np.mean(error[:, q:2 * q] ** 2, axis=(1, 2)))
        last = np.sqrt(np.mean(error[:, steps - q:] ** 2, axis=(1, 2)))
        out = (last > growth * second) & (last > np.asarray(scale, float))
    return np.where(np.isfinite(last) & np.isfinite(second), out, False)


def diverged(est: Estimate, actual: np.ndarray | None = None,
             output_range: tuple[float, float] | None = None,
             consecutive: int = DEFAULTS["consecutive"],
             growth: float = DEFAULTS["growth"]) -> np.ndarray:
    """``(runs,)`` runs that diverged by the criterion of the module docstring.

    ``actual`` is the true output ``(runs, steps, m)`` (``None``: no runaway test);
    ``output_range`` the model's physical range of the measured output (``None``: none).
    """
    out = np.asarray(est.broken, bool).copy()
    if output_range is not None:
        lo, hi = output_range
        with np.errstate(invalid="ignore"):
            outside = np.any((est.y_hat < lo) | (est.y_hat > hi), axis=-1)
        out |= _runs_of(outside, consecutive)
    if actual is not None:               # each measured quantity against its own swing
        actual = np.asarray(actual, float)
        for j in range(actual.shape[-1]):
            one = actual[..., j:j + 1]
            swing = np.sqrt(np.mean((one - one.mean(axis=1, keepdims=True)) ** 2,
                                    axis=(1, 2)))
            out |= runaway(est.y_hat[..., j:j + 1] - one, swing, growth)
    return out


def run_average_outside(values: np.ndarray, dof: int,
                        probability: float = DEFAULTS["band"]) -> np.ndarray:
    """``(runs,)`` whether each run's time average of ``values (runs, steps)`` (chi-square
    with ``dof`` per step) lies outside the two-sided ``probability`` band of
    ``chi-square(steps dof) / steps``. False for a run with a non-finite value (broken:
    counted as diverged, not as inconsistent)."""
    values = np.asarray(values, float)
    ok = np.all(np.isfinite(values), axis=1)
    out = np.zeros(values.shape[0], bool)
    if not ok.any():
        return out
    lo, hi = band(dof, values.shape[1], probability)
    avg = values[ok].mean(axis=1)
    out[ok] = (avg < lo) | (avg > hi)
    return out


def inconsistent(nis_values: np.ndarray | None, m: int, nees_values: np.ndarray | None = None,
                 n: int = 0, probability: float = DEFAULTS["band"]) -> np.ndarray | None:
    """``(runs,)`` runs whose time-averaged NIS (``m`` outputs) or NEES (``n`` states) lies
    outside its band (:func:`run_average_outside`); ``None`` for a filter with neither."""
    out = None
    for values, dof in ((nis_values, m), (nees_values, n)):
        if values is not None:
            flags = run_average_outside(values, dof, probability)
            out = flags if out is None else out | flags
    return out
