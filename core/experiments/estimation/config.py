"""The config of an estimation experiment (Chapter 3), each setting declared once
(:mod:`estim.config.settings`): ``SCHEMA`` of :mod:`estim.experiments.estimation` is
``Config.schema()``."""

from __future__ import annotations

from typing import Any

from estim.config.settings import (
    MAX_VOLTS,
    MIN_NOISE,
    REQUIRED,
    Settings,
    block,
    blocks,
    boolean,
    file_name,
    integer,
    list_of,
    mapping,
    number,
    setting,
    settings_class,
    text,
)
from estim.experiments.shared.blocks import (
    READING,
    EstimatorEntry,
    FigurePoint,
    FilterTable,
    InputNoise,
    Sine,
    SourceLevels,
    simulation,
)

WAVEFORMS = ("sine", "pulse", "step", "pwl", "file")
"""The source waveforms (:func:`estim.experiments.estimation.source.waveform`)."""

DERIVATIVE_METHODS = {"difference", "analytic", "kalman"}
"""How a filter gets ``dv_in/dt`` for a model whose input is the source's slope (eq 3.26):
the difference of the samples it sees on each interval (the default), the nominal sine's
derivative at the interval's midpoint, or the Kalman differentiator of the samples it sees
(``derivative_bandwidth`` times the input frequency;
:mod:`estim.estimators.kalman_differentiator`)."""


@settings_class
class Input(SourceLevels, Sine):
    """The source: a waveform (a sine by default), sampled, with a DC level per model input
    (:mod:`estim.experiments.estimation.source`)."""

    waveform: str = setting("sine", text(set(WAVEFORMS)),
                            doc="the source's waveform: sine, pulse (both repeat at each of "
                                "frequencies_hz), step, pwl (points) or file (a CSV)")
    amplitude_v: float | None = setting(None, number(minimum=-MAX_VOLTS, maximum=MAX_VOLTS),
                                        unit="V", doc="peak of the sine, height of the pulse "
                                                      "or step (below 0: it falls; not for "
                                                      "pwl or file)")
    frequencies_hz: list | None = setting(None, list_of(number(minimum=1e-3, maximum=1e9)),
                                          unit="Hz", doc="the table's input frequencies (sine "
                                                         "and pulse only: the others have one, "
                                                         "1 / duration_s)")
    delay_s: float = setting(0.0, number(minimum=0.0, maximum=1e4), unit="s",
                             doc="pulse and step: the time the source first rises")
    duty: float = setting(0.5, number(positive=True, below=1.0),
                          doc="pulse: the fraction of each period it is high")
    points: list | None = setting(None, list_of(list_of(number(minimum=-1e4, maximum=1e4),
                                                        max_length=2), max_length=100_000),
                                  unit="s, V", doc="pwl: [time, volts] knots, linear between, "
                                                   "held after the last")
    file: str | None = setting(None, text(max_length=1000),
                               doc="file: a CSV (header, then time in s and volts), relative "
                                   "to the config's folder (or a folder above it); linear "
                                   "between its rows")
    samples_per_period: int = setting(10, integer(2, 10_000),
                                      doc="samples per period of each frequency")
    sample_time_s: float | None = setting(None, number(minimum=1e-12, maximum=1e3), unit="s",
                                          doc="one sample time for every frequency instead "
                                              "(Table 3.5's T_s)")
    periods: int | None = setting(None, integer(1, 100_000),
                                  doc="record length in periods (give this or duration_s)")
    duration_s: float | None = setting(None, number(minimum=1e-9, maximum=1e4), unit="s",
                                       doc="record length (give this or periods)")


_SIGMA = number(minimum=MIN_NOISE, maximum=MAX_VOLTS)


def _one_or_each(v):
    """One noise level, or a list of them (one per measured quantity)."""
    if isinstance(v, list):
        ok = 0 < len(v) <= 8 and not any(_SIGMA(i) for i in v)
        return None if ok else "a list of at most 8 noise levels (positive numbers)"
    return _SIGMA(v)


@settings_class
class Noise(InputNoise):
    """Noise at the input source (as the thesis prints it) and on the measured output."""

    measurement_sigma: float | list = setting(REQUIRED, _one_or_each, unit="V (A for a current)",
                                              doc="white noise on each measured value: one "
                                                  "level, or one per output (model.output a "
                                                  "list)")

    measurement: list = setting(["noisy"], list_of(text({"noisy", "noise_free"}), unique=True,
                                                   max_length=2),
                                doc="noisy: output plus measurement noise; noise_free: the "
                                    "output itself (the filters keep their R)")
    filters_see: str = setting("nominal", text({"nominal", "noisy"}),
                               doc="the source the filters are given: the nominal sine or the "
                                   "noisy source")
    input_sensor_sigma: float = setting(0.0, number(minimum=0.0, maximum=MAX_VOLTS), unit="V",
                                        doc="noise of the filters' own sensor of the source "
                                            "(filters_see: noisy)")
    pairs: bool = setting(False, boolean,
                          doc="pair input_levels with frequencies_hz one to one (Table 3.5)")


@settings_class
class FilterEntry(EstimatorEntry):
    """An estimator of a Chapter 3 table, and how it gets dv_in/dt."""

    input_derivative: str = setting("difference", text(DERIVATIVE_METHODS),
                                    doc="how the filter gets dv_in/dt (eq 3.26)")
    derivative_bandwidth: float = setting(3.0, number(minimum=0.1, maximum=1000.0),
                                          doc="the Kalman differentiator's bandwidth, in "
                                              "input frequencies")


@settings_class
class Tables(Settings):
    """Which printed table each result table joins (a thesis table id, or ours)."""

    rmse: str | None = setting(None, text(), doc="thesis table of the RMSE (3.1, 3.2, 3.5)")
    residual: str | None = setting(None, text(), doc="thesis table of the residual (3.3, 3.4)")


@settings_class
class ExtraNoisy(Settings):
    """One more noisy-estimates figure at another noise level."""

    noise_level: float = setting(REQUIRED, number(positive=True, maximum=MAX_VOLTS),
                                 unit="V or V^2", doc="the printed noise number")
    reading: str = setting("sigma", READING, doc="sigma or variance")
    name: str = setting(REQUIRED, file_name, doc="the figure's file name")


FIGURE_KINDS = ("noiseless", "noisy", "rmse", "residual", "parameters")
"""The figures an estimation experiment draws (Figs 3.2-3.7, 3.9-3.11; ``parameters``, each
estimated value against the truth, where ``estimate`` names any)."""


@settings_class
class Estimated(Settings):
    """An element value the filters estimate as a state, a random walk from their first
    guess (:mod:`estim.spice.parameter_states`); the actual circuit keeps the netlist's
    value."""

    name: str = setting(REQUIRED, text(max_length=60),
                        doc="R1 or L1 (a resistor's or an inductor's value) or D1.is (a "
                            "diode's, BJT's or MOSFET's .model parameter)")
    start: float = setting(REQUIRED, number(), unit="its unit",
                           doc="the filters' first guess (not 0)")
    sigma0: float = setting(REQUIRED, number(positive=True), unit="its unit",
                            doc="standard deviation of the first guess (P0's entry)")
    drift: float = setting(0.0, number(minimum=0.0), unit="its unit",
                           doc="standard deviation of its random walk per sample interval "
                               "(Q's entry); 0: a constant")


@settings_class
class Figures(FigurePoint):
    """The figures' sweep point, kinds and file names."""

    kinds: list = setting(list(FIGURE_KINDS), list_of(text(FIGURE_KINDS), nonempty=False,
                                                      unique=True),
                          doc="the figure kinds drawn (noiseless, noisy, rmse, residual, "
                              "parameters: where estimate names any); []: none, the tables "
                              "alone")
    names: dict = setting({}, mapping, doc="file name of each figure kind (noiseless, noisy, "
                                           "rmse, residual)")
    extra_noisy: tuple = blocks(ExtraNoisy, default=(), nonempty=False, max_length=20,
                                doc="more noisy-estimates figures")


@settings_class
class Config(FilterTable):
    """An estimation experiment (Chapter 3): the circuit, its noisy source, the estimators."""

    input: Input = block(Input, required=True, doc="the source")
    noise: Noise = block(Noise, required=True, doc="input and measurement noise")
    simulation: Any = block(simulation(rtol=1e-6, atol=1e-7), doc="the actual circuit's solver")
    estimators: tuple = blocks(FilterEntry, max_length=20, doc="the estimators compared")
    tables: Tables = block(Tables, required=True, doc="the thesis tables joined")
    regime: str | None = setting(None, text(max_length=60),
                                 doc="the operating regime the table names (rmse.csv gives the "
                                     "fraction of samples in it)")
    figures: Figures = block(Figures, doc="the figures")
    estimate: tuple = blocks(Estimated, default=(), nonempty=False, max_length=20,
                             doc="element values estimated as states by every filter (a "
                                 "netlist model's)")


