"""Config blocks that several analyses share, each declared once (:mod:`estim.config.settings`).

An analysis declares its config as a :class:`~estim.config.settings.Settings` dataclass whose fields
use these blocks (``monte_carlo: MonteCarlo = block(MonteCarlo, required=True)``) and its own.
"""

from __future__ import annotations

import re

import numpy as np

from estim.config import registry
from estim.config.settings import (
    MAX_VOLTS,
    MIN_NOISE,
    REQUIRED,
    Settings,
    block,
    blocks,
    integer,
    list_of,
    mapping,
    number,
    setting,
    settings_class,
    text,
)
from estim.experiments.shared import health

READING = text({"sigma", "variance"})
"""How a printed noise number reads: a standard deviation or a variance (notes.md (a))."""


@settings_class
class MonteCarlo(Settings):
    """Monte Carlo runs per table cell and the seed every cell's draws derive from."""

    runs: int = setting(REQUIRED, integer(1, 1_000_000), doc="Monte Carlo runs per cell")
    seed: int = setting(REQUIRED, integer(0, 2**63 - 1),
                        doc="root of every cell's SeedSequence (same seed, same tables)")

    def rng(self, *key: int) -> np.random.Generator:
        """The random generator of the work unit ``key`` (a sweep point, a run, ...): its own
        ``SeedSequence(seed, spawn_key=key)``, so a unit draws the same numbers wherever and
        whenever it runs."""
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=key))


_SIMULATIONS: dict[tuple[float, float], type] = {}


def simulation(rtol: float, atol: float) -> type:
    """The ``simulation`` block (the stiff solver of the "actual" signal) with an analysis'
    default tolerances: one class per pair, named ``Simulation_<rtol>_<atol>`` in this module
    (its ``__getattr__`` builds it again by that name, so a config holding one crosses to a
    worker process)."""
    from estim.numerics.simulate import SOLVERS

    key = (float(rtol), float(atol))
    if key in _SIMULATIONS:
        return _SIMULATIONS[key]
    default_rtol, default_atol = key

    @settings_class
    class Simulation(Settings):
        """The stiff solver of the actual signal."""

        solver: str = setting("batched_radau", text((*SOLVERS, "ngspice")),
                              doc="batched_radau: estim's batched Radau IIA; scipy: solve_ivp; "
                                  "ngspice: ngspice's transient analysis of the netlist (an "
                                  "estimation config's actual circuit only, D78)")
        rtol: float = setting(default_rtol, number(minimum=1e-12, below=0.1),
                              doc="relative tolerance of the solver")
        atol: float = setting(default_atol, number(minimum=1e-15, maximum=1.0), unit="state",
                              doc="absolute tolerance of the solver")

    Simulation.__qualname__ = Simulation.__name__ = f"Simulation_{key[0]!r}_{key[1]!r}"
    _SIMULATIONS[key] = Simulation
    return Simulation


def __getattr__(name: str) -> type:
    """``Simulation_<rtol>_<atol>``: the class :func:`simulation` makes (for pickle)."""
    m = re.fullmatch(r"Simulation_([^_]+)_([^_]+)", name)
    if m is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return simulation(float(m.group(1)), float(m.group(2)))


def _quantities(v):
    ok = isinstance(v, list) and v and len(v) <= 1000 and all(
        isinstance(i, str) and 0 < len(i) <= 200 for i in v)
    return None if ok else "a list of v(node), v(node,node) or i(inductor)"


def _outputs(v):
    ok = (isinstance(v, str) and 0 < len(v) <= 200) or (
        isinstance(v, list) and 0 < len(v) <= 8 and all(
            isinstance(i, str) and 0 < len(i) <= 200 for i in v))
    return None if ok else "a measured quantity or a list of at most 8"


def _source_names(v):
    ok = isinstance(v, str) and v or (isinstance(v, list) and v and all(
        isinstance(i, str) and i for i in v))
    return None if ok else "a source name or a list of them"


@settings_class
class Model(Settings):
    """A registered model, its variant and its parameter overrides."""

    name: str = setting(REQUIRED, text(registry.MODELS), doc="a registered model")
    variant: str | None = setting(None, text(), doc="one of the model's variants; none: its "
                                                    "first (the completed circuit)")
    params: dict = setting({}, mapping, doc="parameter overrides (estim settings MODEL "
                                            "lists them; for a netlist its .param values)")
    netlist: str | None = setting(None, text(), doc="a SPICE netlist file instead of a "
                                                    "registered model (beside the config, in "
                                                    "a folder above it, or circuits/NAME "
                                                    "installed with estim); name is then "
                                                    "netlist:<file stem>")
    input: list | str | None = setting(None, _source_names, doc="with netlist: the voltage "
                                                                  "source(s) the model input "
                                                                  "drives")
    output: str | list | None = setting(None, _outputs,
                                        doc="with netlist: v(node), v(node,node), i(inductor, "
                                            "resistor, diode or voltage source), ic/ib/ie(bjt) "
                                            "or id(mosfet), or a list of them (measured "
                                            "together)")
    hold: str | None = setting(None, text({"mean", "start", "end"}),
                               doc="with netlist: the source over an interval held at the "
                                   "mean of its two end samples (default, as the "
                                   "hand-written amplifiers), its first (zero-order hold) or "
                                   "its last (as cco)")
    thesis_states: list | None = setting(None, _quantities,
                                         doc="with netlist: the states the filters' Q and P0 "
                                             "are written in (noise_units: thesis), one per "
                                             "netlist state, each v(node), v(node,node) or "
                                             "i(inductor); default: the netlist's own states "
                                             "(D77)")


@settings_class
class Health(Settings):
    """How filter health is judged (:mod:`estim.experiments.shared.health`, docs/claims.md)."""

    band: float = setting(health.DEFAULTS["band"], number(minimum=0.5, maximum=0.9999),
                          doc="two-sided probability of the NEES/NIS band")
    whiteness_lag: int = setting(health.DEFAULTS["lag"], integer(1, 1000),
                                 doc="Ljung-Box lag (at most a quarter of the record)")
    whiteness_level: float = setting(health.DEFAULTS["white_level"],
                                     number(minimum=1e-6, maximum=0.5),
                                     doc="Ljung-Box test size")
    consecutive: int = setting(health.DEFAULTS["consecutive"], integer(1, 1_000_000),
                               doc="steps in a row outside the physical range that make a run "
                                   "diverged")
    growth: float = setting(health.DEFAULTS["growth"], number(minimum=1.5, maximum=1e6),
                            doc="last-quarter over second-quarter RMS error of a runaway run")


@settings_class
class Claim(Settings):
    """One claim of the config: ``better``'s loss below ``worse``'s (docs/claims.md)."""

    better: str = setting(REQUIRED, text(max_length=60), doc="an estimator label")
    worse: str = setting(REQUIRED, text(max_length=60), doc="an estimator label")


@settings_class
class EstimatorEntry(Settings):
    """One estimator of an estimation table: its label, type and settings."""

    label: str = setting(REQUIRED, text(max_length=60), doc="the row's name in the tables")
    type: str = setting(REQUIRED, text(registry.ESTIMATORS), doc="a registered estimator")
    model_params: dict = setting({}, mapping,
                                 doc="overrides of the model's parameters for this filter's "
                                     "own model")
    settings: dict = setting({}, mapping, doc="the estimator's settings (estim settings "
                                              "TYPE lists them)")


VOLTS = number(minimum=-MAX_VOLTS, maximum=MAX_VOLTS)
"""A voltage within the bound of every config (:data:`estim.config.settings.MAX_VOLTS`)."""


@settings_class
class Sine(Settings):
    """A sine source: its amplitude and the table's frequencies."""

    amplitude_v: float = setting(REQUIRED, number(minimum=0.0, maximum=MAX_VOLTS), unit="V",
                                 doc="peak amplitude of the sine")
    frequencies_hz: list = setting(REQUIRED, list_of(number(minimum=1e-3, maximum=1e9)),
                                   unit="Hz", doc="the table's input frequencies")


@settings_class
class Readings(Settings):
    """How the printed noise numbers read."""

    readings: list = setting(["sigma"], list_of(READING, unique=True),
                             doc="read each printed level as a standard deviation, a "
                                 "variance, or both (notes.md (a))")


@settings_class
class InputNoise(Readings):
    """Noise at the input source, as printed, and on the measurement."""

    input_levels: list = setting(REQUIRED, list_of(number(positive=True, maximum=MAX_VOLTS)),
                                 unit="V or V^2", doc="the printed noise numbers, one block of "
                                                      "table rows each")
    measurement_sigma: float = setting(REQUIRED, number(minimum=MIN_NOISE, maximum=MAX_VOLTS),
                                       unit="V", doc="white noise on each measured value")


@settings_class
class SourceLevels(Settings):
    """Where a source enters the model: its DC level and its weight in each model input."""

    bias_v: list = setting([0.0], list_of(VOLTS), unit="V",
                           doc="DC level of each model input")
    mix: list = setting([1.0], list_of(number(minimum=-1e3, maximum=1e3)),
                        doc="the source's weight in each model input (0.5, -0.5: "
                            "differential)")


@settings_class
class FigurePoint(Settings):
    """The sweep point the figures show."""

    frequency_hz: float | None = setting(None, number(minimum=1e-3, maximum=1e9), unit="Hz",
                                         doc="the figures' frequency; none: the first")
    noise_level: float | None = setting(None, number(positive=True, maximum=MAX_VOLTS),
                                        unit="V or V^2", doc="none: the first level")
    reading: str | None = setting(None, READING, doc="none: the first reading")


@settings_class
class FilterTable(Settings):
    """What every table of estimators against an actual circuit shares (Chapters 3 and 4)."""

    model: Model = block(Model, required=True, doc="the actual circuit")
    monte_carlo: MonteCarlo = block(MonteCarlo, required=True, doc="runs and seed")
    health: Health = block(Health, doc="how filter health is judged")
    claims: tuple = blocks(Claim, default=(), nonempty=False, max_length=20,
                           doc="the table's headline claims (each filter is also judged "
                               "against the raw measurement)")
