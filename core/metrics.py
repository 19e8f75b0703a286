"""Error metrics over a Monte Carlo batch."""

from __future__ import annotations

import numpy as np


def rmse_per_run(actual: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """Eq 3.42 for each run: ``sqrt(mean_k |e_k|^2)``, ``e_k = actual - estimate``.

    ``actual`` and ``estimate`` have shape ``(runs, steps, m)``; the mean runs over steps
    and outputs (eq 4.60 for vectors).
    """
    return np.sqrt(np.mean((actual - estimate) ** 2, axis=(1, 2)))


def mean_and_se(values: np.ndarray) -> tuple[float, float]:
    """Mean over runs and its standard error (NaN for the error with fewer than two runs)."""
    values = np.asarray(values, float)
    if values.size == 0:
        return float("nan"), float("nan")
    se = float(np.std(values, ddof=1) / np.sqrt(values.size)) if values.size > 1 else float("nan")
    return float(np.mean(values)), se


def residual_stats(innovation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-run time mean and time variance of the residual ``(runs, steps, m)``.

    The thesis never defines "residual" (Tables 3.3, 3.4); here it is the prior residual
    (innovation, eq 3.84) ``z_k - y_hat_{k|k-1}``: the measurement minus the estimator's
    prediction of it before seeing it.
    """
    return np.mean(innovation, axis=(1, 2)), np.var(innovation, axis=(1, 2))


def running_rmse(actual: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """RMSE across runs at each step, ``(steps,)``: the curve of thesis Fig 3.6."""
    if actual.shape[0] == 0:
        return np.full(actual.shape[1], np.nan)
    return np.sqrt(np.mean((actual - estimate) ** 2, axis=(0, 2)))
