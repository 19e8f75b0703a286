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


def rms(y: np.ndarray, axis: int = -1) -> np.ndarray:
    """Root mean square along ``axis``."""
    return np.sqrt(np.mean(np.square(y), axis=axis))


def percent_distortion(y0: np.ndarray, y1: np.ndarray, axis: int = -1) -> np.ndarray:
    """Eq 2.43 reduced to one number: ``100 rms(y1) / rms(y0 + y1)``.

    Eq 2.43 is the ratio ``(v_0 - v_0^(0)) / v_0`` at each instant, with ``v_0`` the linear
    plus first-order output; it has poles at the zero crossings of ``v_0``, so it is reduced
    here to the ratio of root-mean-square values over the analysis window (whole periods of
    the steady state for a periodic input), with outputs taken as deviations from the DC
    operating point (docs/deviations.md).
    """
    return 100.0 * rms(y1, axis) / rms(y0 + y1, axis)


def harmonics(y: np.ndarray, count: int = 10) -> np.ndarray:
    """Amplitudes of harmonics 0..count of ``y (..., N)`` sampled over exactly one period
    (``count < N/2``: the Nyquist bin is not a harmonic amplitude)."""
    n = y.shape[-1]
    if not count < n / 2:
        raise ValueError(f"harmonics up to {count} need more than {2 * count} samples, got {n}")
    spectrum = np.abs(np.fft.rfft(y, axis=-1)) / n
    spectrum[..., 1:] *= 2.0
    return spectrum[..., :count + 1]


def thd_percent(y: np.ndarray, count: int = 10) -> np.ndarray:
    """Total harmonic distortion ``100 sqrt(sum_{k=2..count} A_k^2) / A_1`` of ``y (..., N)``
    sampled over exactly one period (harmonics above the Nyquist index are not counted)."""
    a = harmonics(y, min(count, (y.shape[-1] - 1) // 2))
    return 100.0 * np.sqrt(np.sum(a[..., 2:] ** 2, axis=-1)) / a[..., 1]


def gain_db(y: np.ndarray, amplitude: float) -> np.ndarray:
    """``20 log10`` of the fundamental of ``y`` (one period) over the input ``amplitude``."""
    return 20.0 * np.log10(harmonics(y, 1)[..., 1] / amplitude)
