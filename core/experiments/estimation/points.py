"""The sweep points of an estimation experiment, in thesis row order, and each frequency's
sampling (:mod:`estim.experiments.estimation`)."""

from __future__ import annotations

from dataclasses import dataclass

from estim.config.experiment import Experiment
from estim.experiments.estimation import source as waveforms
from estim.numerics import signals


@dataclass(frozen=True)
class SweepPoint:
    index: int
    measurement: str
    reading: str
    level: float
    sigma: float
    frequency_hz: float


def sweep(exp: Experiment) -> list[SweepPoint]:
    """Sweep points in thesis row order: measurement reading, noise reading, noise level,
    then frequency (or the (level, frequency) pairs in the order given, with
    ``noise.pairs``). ``noise.measurement``: ``noisy``, the measured output plus white noise
    of ``measurement_sigma``; ``noise_free``, the actual output itself (the filters keep
    their ``R``)."""
    noise, inp = exp.config.noise, exp.config.input
    freqs = waveforms.frequencies(inp)
    if noise.pairs:
        cells = list(zip(noise.input_levels, freqs, strict=True))
    else:
        cells = [(level, f) for level in noise.input_levels for f in freqs]
    points = []
    for measurement in noise.measurement:
        for reading in noise.readings:
            for level, f in cells:
                points.append(SweepPoint(len(points), measurement, reading, float(level),
                                         signals.noise_sigma(level, reading), float(f)))
    return points


def sampling(exp: Experiment, frequency_hz: float) -> tuple[float, int]:
    """Sample time and number of samples after ``t_0`` for one input frequency."""
    inp = exp.config.input
    dt = inp.sample_time_s or 1.0 / (inp.samples_per_period * frequency_hz)
    if inp.duration_s is not None:
        return dt, max(1, round(inp.duration_s / dt))
    return dt, max(1, round(inp.periods / (frequency_hz * dt)))
