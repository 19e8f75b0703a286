"""Input waveforms and noise."""

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


def gaussian(rng: np.random.Generator, sigma: float, shape: tuple[int, ...]) -> np.ndarray:
    """Zero-mean white Gaussian samples of standard deviation ``sigma``."""
    return sigma * rng.standard_normal(shape)
