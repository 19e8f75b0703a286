"""The settings of the field-filter experiment (:mod:`estim.experiments.dipole_field`) and the
names of its estimators."""

from __future__ import annotations

from estim.config.settings import (
    MIN_NOISE,
    REQUIRED,
    Settings,
    block,
    blocks,
    integer,
    list_of,
    number,
    setting,
    settings_class,
    text,
)
from estim.experiments import dipole as literal
from estim.experiments.shared.blocks import MonteCarlo

KF, RLS, PLAIN = "KF", "RLS", "plain simulation"


SOURCE_ONLY, FIT = "KF (source only)", "amplitude-only fit"


SLICE_LABELS = ("truth", KF, FIT, "KF error")


EULER = "plain simulation (Euler, eq 5.20)"


DIVERGED_RATIO = 1e3
"""An estimate whose RMSE exceeds this multiple of the field's RMS has diverged: its cell
reports ``inf`` (the printed Euler run reaches 1e22; the digits of a blown-up number carry
the rounding that seeded its growth and differ between machines)."""
"""The printed discretisation ``xi+ = (I + T F) xi``: forward Euler on (A, dA/dt), every
mode grows (:func:`estim.fields.wave.step`); run once per case to show it."""


@settings_class
class GridSettings(Settings):
    """The cubic grid and its boundary."""

    n: int = setting(32, integer(8, 96), doc="points per side (even)")
    length: float = setting(4.0, number(positive=True, maximum=1e3), doc="side, in wavelengths")
    courant: float = setting(0.5, number(positive=True, maximum=0.577),
                             doc="c T / Delta (leapfrog is stable to 0.577)")
    source_width: float = setting(0.7, number(positive=True, maximum=10.0),
                                  doc="width of the smooth source, in cells")
    boundary: str = setting("mur", text({"mur", "dirichlet"}),
                            doc="Mur's absorbing faces or a Dirichlet box")


@settings_class
class Scenario(Settings):
    """The source the filter is told."""

    name: str = setting(REQUIRED, text(max_length=40), doc="the scenario's name in the tables")
    nominal_amplitude: list = setting(REQUIRED, list_of(number(minimum=0.0, maximum=1e3),
                                                        max_length=2),
                                      doc="[magnitude, phase in degrees] of the told source")


@settings_class
class Sensors(Settings):
    """The sparse E/H sensors."""

    fraction: float = setting(0.02, number(positive=True, maximum=1.0),
                              doc="fraction of the grid's points that are sensors")
    r: list = setting([0.2, 1.9], list_of(number(positive=True, maximum=1e6), max_length=2),
                      doc="[low, high] radius the sensors are drawn from")
    measurement_sigma: float = setting(0.01, number(minimum=MIN_NOISE, maximum=1e3),
                                       doc="white noise on every measured component")
    seed: int | None = setting(None, integer(0, 2**63 - 1),
                               doc="absent: the sensors are drawn anew for each Monte Carlo "
                                   "run (from monte_carlo.seed); a seed: one layout, drawn "
                                   "from it, for every run")


@settings_class
class FilterSettings(Settings):
    """The field filter: a local ETKF on the field with model error (D60)."""

    members: int = setting(50, integer(3, 2000), doc="ensemble members")
    amplitude_spread: float = setting(0.3, number(positive=True, maximum=1e3),
                                      doc="spread of the members' source amplitudes")
    field_error: float = setting(0.003, number(minimum=0.0, maximum=0.5),
                                 doc="model error per step: std of the relative amplitude and "
                                     "of the phase (rad) of each member's local phasor")
    field_error_profile: str = setting("uniform", text({"truncation", "uniform"}),
                                       doc="truncation: per point and potential the larger "
                                           "of field_error and the leapfrog's own relative "
                                           "error per step in its radial shell; uniform: "
                                           "field_error everywhere")
    field_error_length: float = setting(3.0, number(positive=True, maximum=100.0),
                                        unit="cells",
                                        doc="Gaussian correlation length of the model error")
    localisation: float = setting(1.0, number(positive=True, maximum=100.0),
                                  unit="wavelengths",
                                  doc="Gaspari-Cohn half-width around each cube (zero from "
                                      "twice it)")
    amplitude_localisation: float = setting(0.5, number(positive=True, maximum=100.0),
                                            unit="wavelengths",
                                            doc="Gaspari-Cohn half-width around the source "
                                                "for the amplitude's analysis")
    block: int = setting(4, integer(1, 32), unit="cells",
                         doc="side of the cubes analysed together (divides grid.n)")
    representation_error: float = setting(0.0, number(minimum=0.0, maximum=1e3),
                                          doc="added to the sensor noise in R (in quadrature)")
    inflation: float = setting(1.0, number(minimum=1.0, maximum=2.0),
                               doc="multiplicative inflation of the forecast covariance")


@settings_class
class SourceOnly(Settings):
    """The source-only ETKF (the earlier field filter, kept as a variant): one global
    analysis whose ensemble differs only in the source amplitude."""

    representation_error: float = setting(0.02, number(minimum=0.0, maximum=1e3),
                                          doc="the grid's own error in a measured field, "
                                              "added to R in quadrature (D60)")


@settings_class
class Time(Settings):
    """Spin-up and record."""

    spinup_periods: int = setting(4, integer(1, 100), doc="periods before the first analysis")
    periods: int = setting(2, integer(1, 100), doc="recorded periods")


@settings_class
class Config(Settings):
    """A filter on the dipole's discretised field (D59-D61)."""

    grid: GridSettings = block(GridSettings, doc="the grid")
    source: literal.Source = block(literal.Source, doc="the dipole")
    scenarios: tuple = blocks(Scenario, max_length=10, doc="the sources the filter is told")
    zones: tuple = blocks(literal.ZoneBlock, max_length=2, doc="the near and far zones")
    sensors: Sensors = block(Sensors, doc="the sensors")
    filter: FilterSettings = block(FilterSettings, doc="the field filter (LETKF)")
    source_only: SourceOnly = block(SourceOnly, doc="the source-only ETKF")
    rls: literal.RLSSettings = block(literal.RLSSettings, doc="the per-sensor RLS baseline")
    time: Time = block(Time, doc="spin-up and record")
    noise: literal.SourceNoise = block(literal.SourceNoise, required=True,
                                       doc="the thesis' source-noise rows (kept for the "
                                           "layout, D59)")
    monte_carlo: MonteCarlo = block(MonteCarlo, required=True, doc="runs and seed")
