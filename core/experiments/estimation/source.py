"""The source an estimation experiment drives its circuit with: the nominal waveform on the
sample times, before the input noise (:func:`estim.experiments.estimation.simulate_point`).

Every waveform is a deviation ``w(t)`` from the DC level: the source is
``bias_v + w(t) * mix``. A sine and a pulse repeat at each of the table's frequencies; a
step, a piecewise-linear source (``pwl``) and a source read from a CSV file (``file``) do
not, so their table has one frequency, ``1 / duration_s`` (the record's own), and their
sample time is ``sample_time_s``. The circuit starts at its DC point with the source held at
``bias_v + w(0) * mix``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from estim.errors import ConfigError
from estim.estimators import kalman_differentiator
from estim.experiments.shared import records
from estim.numerics import signals

PERIODIC = ("sine", "pulse")
"""Waveforms that repeat at the table's frequencies (``input.frequencies_hz``)."""

EDGE = 1e-9
"""A sample time within this fraction of a period (or of ``delay_s``) of an edge is on the
edge's far side, whichever way the product ``k * dt`` rounded."""

HEIGHT = ("sine", "pulse", "step")
"""Waveforms whose size is ``input.amplitude_v``."""


def frequencies(inp) -> list[float]:
    """The table's input frequencies: ``frequencies_hz`` for a periodic waveform, else the
    record's own ``1 / duration_s``."""
    if inp.waveform in PERIODIC:
        return [float(f) for f in inp.frequencies_hz or ()]
    return [1.0 / float(inp.duration_s)]


def label(inp, frequency_hz: float) -> str:
    """How a figure title names the source: its frequency, or the waveform."""
    if inp.waveform == "sine":
        return f"{frequency_hz:g} Hz"
    if inp.waveform == "pulse":
        return f"{frequency_hz:g} Hz pulse"
    if inp.waveform == "file":
        return f"input from {Path(inp.file).name}"
    return {"step": "step input", "pwl": "piecewise-linear input"}[inp.waveform]


def check(inp, source: str) -> np.ndarray | None:
    """The waveform's settings against each other, one :class:`ConfigError` at the first
    problem; returns the ``(t, w)`` knots of a ``pwl`` or ``file`` source (``None`` for the
    others)."""
    def error(key: str, what: str) -> ConfigError:
        return ConfigError(source, f"input.{key}", what)

    kind = inp.waveform
    if kind in PERIODIC and inp.frequencies_hz is None:
        raise error("frequencies_hz", f"required for waveform {kind}")
    if kind not in PERIODIC:
        if inp.frequencies_hz is not None:
            raise error("frequencies_hz", f"a {kind} input does not repeat: leave it out (the "
                        "table's frequency is 1 / duration_s)")
        for key in ("sample_time_s", "duration_s"):
            if getattr(inp, key) is None:
                raise error(key, f"required for waveform {kind} (it has no period)")
    if kind in HEIGHT and inp.amplitude_v is None:
        raise error("amplitude_v", f"required for waveform {kind}")
    if kind not in HEIGHT and inp.amplitude_v is not None:
        raise error("amplitude_v", f"a {kind} input gives its own values; leave it out")
    if (kind == "pwl") != (inp.points is not None):
        raise error("points", "required for waveform pwl" if kind == "pwl"
                    else f"only for waveform pwl, not {kind}")
    if (kind == "file") != (inp.file is not None):
        raise error("file", "required for waveform file" if kind == "file"
                    else f"only for waveform file, not {kind}")
    if kind == "pwl":
        knots = np.array(inp.points, float)
        if knots.ndim != 2 or knots.shape[1] != 2:
            raise error("points", "expected a list of [time in s, volts] pairs")
        return _knots(knots, "input.points", source)
    if kind == "file":
        return _knots(read_file(inp.file, source), f"{inp.file} (input.file)", source)
    return None


def _knots(knots: np.ndarray, where: str, source: str) -> np.ndarray:
    if len(knots) < 1 or not np.all(np.isfinite(knots)):
        raise ConfigError(source, where.split(" ")[-1].strip("()"),
                          f"{where}: expected finite times and volts")
    if np.any(np.diff(knots[:, 0]) < 0) or knots[0, 0] < 0:
        raise ConfigError(source, where.split(" ")[-1].strip("()"),
                          f"{where}: times must start at 0 s or later and not decrease")
    return knots


def read_file(name: str, source: str) -> np.ndarray:
    """The ``(t, w)`` rows of a CSV file with a header and two columns (time in s, the
    source's deviation from its DC level in V), found beside the config
    (:func:`estim.experiments.shared.records.read_rows`)."""
    path, _, body = records.read_rows(name, source, "input.file")
    try:
        knots = np.array([[float(row[0]), float(row[1])] for row in body])
    except (ValueError, IndexError):
        raise ConfigError(source, "input.file", f"{path}: expected a header line, then rows "
                          "of two numbers (time in s, volts)") from None
    return knots.reshape(-1, 2)


def waveform(inp, knots: np.ndarray | None, frequency_hz: float, t: np.ndarray) -> np.ndarray:
    """``w(t)`` as a ``(len(t), 1)`` column (the source is ``bias_v + w * mix``).

    sine: ``A sin(2 pi f t)``; pulse: 0 until ``delay_s``, then ``A`` for ``duty`` of each
    period ``1 / f`` and 0 for the rest (SPICE's PULSE with zero edges: on the sample times
    an edge takes one sample interval, as every source here is held over its interval);
    step: 0 up to ``delay_s``, ``A`` after; pwl and file: linear between the knots, held
    before the first and after the last."""
    kind = inp.waveform
    if kind == "sine":
        return signals.sine(inp.amplitude_v, frequency_hz, t)
    begun = t > inp.delay_s * (1 + EDGE)
    if kind == "pulse":
        cycles = (t - inp.delay_s) * frequency_hz
        phase = cycles - np.floor(cycles + EDGE)
        return (inp.amplitude_v * (begun & (phase < inp.duty)).astype(float))[:, None]
    if kind == "step":
        return (inp.amplitude_v * begun.astype(float))[:, None]
    return np.interp(t, knots[:, 0], knots[:, 1])[:, None]


def start(inp, knots: np.ndarray | None) -> float:
    """``w(0)``: the source's deviation from ``bias_v`` where the circuit starts."""
    return float(waveform(inp, knots, frequencies(inp)[0], np.zeros(1))[0, 0])


def filter_input(inp, data: dict, method: str, bandwidth: float) -> np.ndarray:
    """The input a filter is given on each sample interval of a batch ``data`` (the config's
    ``input`` block ``inp``; ``method`` one of
    :data:`estim.experiments.estimation.config.DERIVATIVE_METHODS`): the model's own mapping
    of the samples it sees, the nominal sine's slope at each interval's midpoint, or the
    Kalman differentiator's (``bandwidth`` times the input frequency)."""
    if method == "difference":
        return data["u"]
    f, dt = data["frequency_hz"], data["dt"]
    mix = np.asarray(inp.mix, float)
    if method == "analytic":
        w = 2 * np.pi * f
        middle = data["t"] - dt / 2
        return (inp.amplitude_v * w * np.cos(w * middle))[None, :, None] * mix
    slopes = kalman_differentiator.with_bandwidth(data["seen"], dt, bandwidth * f)
    return 0.5 * (slopes[:, 1:] + slopes[:, :-1])
