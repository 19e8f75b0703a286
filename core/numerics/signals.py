"""Input waveforms, the reading of printed noise levels, and coloured noise (white noise is
``sigma * rng.standard_normal(shape)`` where it is drawn)."""

from __future__ import annotations

import numpy as np


def sine(amplitude: float, frequency_hz: float, t: np.ndarray) -> np.ndarray:
    """``amplitude * sin(2 pi f t)`` as a ``(len(t), 1)`` column."""
    return (amplitude * np.sin(2 * np.pi * frequency_hz * t))[:, None]


def noise_sigma(level: float, reading: str) -> float:
    """The standard deviation meant by a printed noise number read as ``sigma`` or ``variance``.

    The thesis' tables say sigma where its figure captions say variance (notes.md (a)).
    """
    if reading == "sigma":
        return float(level)
    if reading == "variance":
        return float(np.sqrt(level))
    raise ValueError(f"reading {reading!r}; expected 'sigma' or 'variance'")


def ornstein_uhlenbeck(rng: np.random.Generator, sigma: float, gamma: float, dt: float,
                       shape: tuple[int, int]) -> np.ndarray:
    """Exact samples of ``dv = -gamma v dt + sigma dbeta`` (thesis eqs 4.8-4.9) at ``t_k = k dt``
    from ``v(0) = 0``, shape ``(runs, steps + 1)`` for ``shape = (runs, steps)``.

    Each step is ``v_{k+1} = a v_k + s xi_k`` with ``a = e^{-gamma dt}`` and
    ``s = sigma sqrt((1 - a^2) / (2 gamma))``: the transition of the process itself, with no
    discretisation error at any ``dt`` (unlike Euler-Maruyama). One noise source drives the
    input; its effect on every node follows from the circuit.
    """
    from scipy import signal as sps

    a = float(np.exp(-gamma * dt))
    s = sigma * float(np.sqrt(-np.expm1(-2 * gamma * dt) / (2 * gamma)))
    xi = rng.standard_normal(shape)
    out = np.zeros((shape[0], shape[1] + 1))
    out[:, 1:] = sps.lfilter([s], [1.0, -a], xi, axis=1)
    return out
