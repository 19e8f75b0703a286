"""A filter on the field itself: the dipole's potentials on a 3-D grid (thesis eqs 5.1-5.32
and the Remark, eqs 5.48-5.49) with sparse noisy measurements of E and H (eq 5.32), Tables
5.1-5.12 in the thesis' layout for this experiment.

Per scenario (the source the filter is told) and noise row:

* truth: the analytic field of the dipole (``estim.fields.dipole``) with the true current
  ``I0 = 1``; the thesis' "noise at the driving source" (2.5e-4, 5e-4 of the current) is
  three orders below the grid's own error and does not enter it (docs/deviations.md);
* sensors: a fixed random ``fraction`` of the grid points between ``sensor_r`` radii
  measure all six components of E and H every step, with white noise
  ``measurement_sigma``;
* ``plain simulation``: the leapfrog/Mur simulation (``estim.fields.fdtd``) driven by the
  nominal source, no data: the open loop, and with the true source the grid's floor;
* ``KF`` (the ensemble filter, ETKF of ``estim.fields.etkf``): ``members`` simulations whose
  complex source amplitude is part of the state (drawn around the nominal one, spread
  ``amplitude_spread``), spun up for ``spinup_periods``, then analysed at every step; the
  observation error variance is ``measurement_sigma^2 + model_error^2`` (the grid's own
  error in the measured fields, declared);
* ``RLS``: the thesis-style baseline: the project's RLS fits a sinusoid of the known
  frequency to each sensor's time series, and each field point takes its nearest sensor;
* ``measurement``: each field point takes its nearest sensor's raw reading.

RMSE (eq 3.42) of E_r, E_theta, H_phi over the zone's points and the recorded periods,
against the analytic field, per run; the experiment is driven by the real part of the
current; the ``imag`` experiment is the same one a quarter period later, and ``abs`` the
magnitude formed from the two (:func:`_errors`). Normalised units as in
:mod:`estim.experiments.dipole`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from estim.config.schema import REQUIRED, Experiment, check_interval, integer, list_of, number, text
from estim.config.settings import Settings, block, blocks, setting, settings_class
from estim.errors import ConfigError
from estim.experiments import dipole as literal
from estim.experiments.base import Quote, Result
from estim.experiments.dipole import COMPONENTS, TABLE_IDS, sinusoid_rls
from estim.experiments.shared import claims, plots
from estim.experiments.shared.blocks import MonteCarlo
from estim.fields import etkf, wave
from estim.fields.dipole import Dipole
from estim.numerics import metrics
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.memory import reuse_freed_memory
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")
spatial = lazy.load("scipy.spatial")
fdtd = lazy.load("estim.fields.fdtd")
grids = lazy.load("estim.fields.grid")
letkf = lazy.load("estim.fields.letkf")
model_error = lazy.load("estim.fields.model_error")

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
    measurement_sigma: float = setting(0.01, number(positive=True, maximum=1e3),
                                       doc="white noise on every measured component")
    seed: int = setting(5, integer(0, 2**63 - 1), doc="seed of the sensors' positions")


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


SCHEMA: dict = Config.schema()

_KEYS = ("table_id", "s_no", "scenario", "zone", "beta_r", "noise_reading", "noise_param",
         "estimator", "field_component", "part")
TABLES = {
    "rmse": TableSpec("rmse.csv", _KEYS, ("rmse", "rmse_se", "runs", "field_rms",
                                          "relative"),
                      reference=("rmse",), join=(("s_no", ("s_no",)), ("part", ("part",))),
                      title="RMSE of the fields against the analytic dipole (field filter)",
                      reference_ids=tuple(TABLE_IDS.values())),
    "claims": claims.TABLE,
    "health": TableSpec("health.csv", ("scenario", "noise_reading", "noise_param",
                                       "estimator", "step"),
                        ("time", "effective_rank_min", "effective_rank_max", "nis", "runs"),
                        title="the ensembles over time: effective rank of the forecast "
                              "(singular values above 1e-6 of the largest), NIS per reading"),
}
CLAIMS = ((KF, FIT), (KF, PLAIN), (KF, SOURCE_ONLY), (KF, RLS), (KF, "measurement"),
          (RLS, "measurement"))
"""The field filter against the best a source-only filter can do (the amplitude-only fit),
the plain simulation (the open loop: with the true source, the grid's floor), today's
source-only ETKF, the thesis' RLS baseline (its headline) and the raw nearest sensor; and RLS
against the raw sensor."""
QUOTES = (Quote("relative RMSE (RMSE / field RMS)", "rmse", "relative", by="estimator"),)


@dataclass(frozen=True)
class Plan:
    """The grid, the sensors (grid indices) and their rows of the operators, and each
    zone's grid points, built once."""

    grid: grids.Grid
    sensors: np.ndarray
    zones: dict
    sensor_ops: tuple
    beta_r: dict


def prepare(spec: dict, source: str) -> Plan:
    g = spec["grid"]
    if g["n"] % 2:
        raise ConfigError(source, "grid.n", "expected an even number (no grid point on the "
                          "source's centre, where the analytic field is infinite)")
    grid = grids.Grid(g["n"], g["length"] / g["n"])
    half = g["length"] / 2
    for i, z in enumerate(spec["zones"]):
        check_interval(z["r"], source, f"zones[{i}].r")
        check_interval(z["theta_deg"], source, f"zones[{i}].theta_deg")
        if z["r"][1] > half - grid.spacing:
            raise ConfigError(source, f"zones[{i}].r", f"reaches the box's faces at "
                              f"{half:g}: keep it below {half - grid.spacing:g}")
    check_interval(spec["sensors"]["r"], source, "sensors.r")
    names = [s["name"] for s in spec["scenarios"]]
    for i, s in enumerate(spec["scenarios"]):
        if len(s["nominal_amplitude"]) != 2:
            raise ConfigError(source, f"scenarios[{i}].nominal_amplitude",
                              "expected [magnitude, phase in degrees]")
        if s["name"] in names[:i]:
            raise ConfigError(source, f"scenarios[{i}].name", f"repeats {s['name']!r}")
    rng = np.random.default_rng(spec["sensors"]["seed"])
    lo, hi = spec["sensors"]["r"]
    candidates = np.flatnonzero((grid.r >= lo) & (grid.r <= hi))
    count = max(1, int(round(spec["sensors"]["fraction"] * grid.size)))
    if count > candidates.size:
        raise ConfigError(source, "sensors.fraction", f"asks for {count} sensors; only "
                          f"{candidates.size} grid points lie between the sensor radii")
    sensors = np.sort(rng.choice(candidates, count, replace=False))
    zones = {}
    for z in spec["zones"]:
        th = np.degrees(grid.theta)
        zones[z["name"]] = np.flatnonzero((grid.r >= z["r"][0]) & (grid.r <= z["r"][1])
                                          & (th >= z["theta_deg"][0])
                                          & (th <= z["theta_deg"][1]))
    if g["n"] % spec["filter"]["block"]:
        raise ConfigError(source, "filter.block", f"expected a divisor of grid.n = {g['n']}")
    wavelength = spec["source"]["c"] / spec["source"]["frequency"]
    beta_r = {z["name"]: "{:.2f}-{:.2f}".format(*(2 * np.pi * np.array(z["r"]) / wavelength))
              for z in spec["zones"]}
    return Plan(grid=grid, sensors=sensors, zones=zones,
                sensor_ops=sensor_operators(grid, sensors), beta_r=beta_r)


FIELD_COST_RATIO = 1000
"""``--max-work`` bounds cost in the currency of the other analyses, state-samples of the
stiff integrator. One grid-point update of the vectorised leapfrog costs far less: measured
on the development machine, 6.4e8 of them (one run of this config: 4 n^3 states x 51
members x 96 steps) took 21 s, where ``mosfet_saturation``'s 4.3e5 state-samples take about
20 s, a ratio near 1500. Grid-point updates are divided by this (rounded-down) ratio."""


def work_size(spec: dict) -> int:
    """Grid-point updates (``4 n^3`` per member and step; two ensembles, the field filter's
    and the source-only one, and three free runs: the plain simulation and the fit's basis)
    over every scenario, noise row and run, over :data:`FIELD_COST_RATIO`."""
    g, t = spec["grid"], spec["time"]
    per_period = round(g["n"] / (g["courant"] * g["length"]))
    steps = (t["spinup_periods"] + t["periods"]) * per_period
    points = len(spec["noise"]["source_levels"]) * len(spec["noise"].get("readings") or [1])
    updates = (4 * g["n"] ** 3 * (2 * spec["filter"]["members"] + 3) * steps * points
               * len(spec["scenarios"]) * spec["monte_carlo"]["runs"])
    return int(updates / FIELD_COST_RATIO)


def work_units(exp: Experiment) -> int:
    return len(_points(exp))


def tiny(spec: dict) -> dict:
    spec["grid"] = {**(spec.get("grid") or {}), "n": 12}
    spec["zones"] = [{"name": "far", "r": [0.9, 1.5]}]
    spec["sensors"] = {**(spec.get("sensors") or {}), "r": [0.2, 1.5], "fraction": 0.05}
    spec["scenarios"] = spec["scenarios"][:1]
    spec["noise"].update(source_levels=spec["noise"]["source_levels"][:1],
                         readings=(spec["noise"].get("readings") or ["sigma"])[:1])
    spec["filter"] = {**(spec.get("filter") or {}), "members": 5}
    spec["time"] = {"spinup_periods": 1, "periods": 1}
    spec["monte_carlo"]["runs"] = 1
    return spec


def _points(exp: Experiment) -> list[tuple]:
    noise = exp.spec["noise"]
    return [(s, r, i) for s in range(len(exp.spec["scenarios"]))
            for r in range(len(noise["readings"])) for i in range(len(noise["source_levels"]))]


def _amplitude(pair: list[float]) -> complex:
    return pair[0] * np.exp(1j * np.radians(pair[1]))


def _observe(grid: grids.Grid, states_before: np.ndarray, states_after: np.ndarray, dt: float,
             mu0: float, ops: tuple | None = None) -> dict[str, np.ndarray]:
    """Cartesian E and H at time t from ``states_before`` (levels t - dt, t) and
    ``states_after`` (t, t + dt): ``dA/dt`` by the centred difference. With ``ops`` (the
    sensor rows of the gradient and curl, :func:`sensor_operators`) only at the sensors."""
    A, Phi = states_after[:, 0, 0], states_after[:, 0, 1]
    dA = (states_after[:, 1, 0] - states_before[:, 0, 0]) / (2 * dt)
    if ops is None:
        return fdtd.fields_from(grid, A, Phi, dA, mu0)
    (grad_s, grad_points), (curl_z, curl_points), pick = ops
    E = -(grad_s @ Phi[:, grad_points].T).T.reshape(A.shape[0], 3, -1)
    E[:, 2] -= dA[:, pick]
    H = (curl_z @ A[:, curl_points].T).T.reshape(A.shape[0], 3, -1) / mu0
    return {"E": E, "H": H}


def _on_points_used(op) -> tuple:
    """A sparse operator cut to the grid points it reads, and those points: applied to the
    members' values at them, it sums the same products in the same order, without copying
    every member's whole field into a transposed array first (scipy does, for a strided
    right-hand side)."""
    op = op.tocsr()
    op.sort_indices()
    points = np.unique(op.indices)
    cut = op[:, points]
    cut.sort_indices()
    return cut, points


def sensor_operators(grid: grids.Grid, sensors: np.ndarray) -> tuple:
    """The rows of the gradient at the sensors, the columns of the curl that act on ``A_z``
    (the only component of ``A``) at the sensors' rows, each cut to the points it reads
    (:func:`_on_points_used`), and the sensors themselves."""
    rows = np.concatenate([sensors + k * grid.size for k in range(3)])
    grad_s = grid.grad[rows]
    curl_z = grid.curl[rows][:, 2 * grid.size:3 * grid.size]
    return _on_points_used(grad_s), _on_points_used(curl_z), sensors


@dataclass
class _Setup:
    """What one case's runs share: the simulation, its step, the record's length, the
    localisation and the observation variances."""

    sim: fdtd.Simulation
    dipole: Dipole
    dt: float
    per: int
    quarter: int
    spin: int
    record: int
    local: letkf.Localisation
    local_half_width: float
    amplitude_taper: np.ndarray
    amplitude_half_width: float
    source_distances: np.ndarray
    smoother: np.ndarray
    error_scale: np.ndarray
    R_field: np.ndarray
    R_source: np.ndarray


def _setup(spec: dict, plan: Plan) -> _Setup:
    grid, src = plan.grid, spec["source"]
    dipole = Dipole(I0=1.0, dl=grid.spacing, omega=2 * np.pi * src["frequency"], c=src["c"],
                    mu0=src["mu0"])
    dt = spec["grid"]["courant"] * grid.spacing / src["c"]
    per = int(round(1 / (src["frequency"] * dt)))
    dt = 1 / (src["frequency"] * per)                  # whole steps per period
    sim = fdtd.Simulation(grid, dipole, dt, dl=grid.spacing, width=spec["grid"]["source_width"],
                     boundary=spec["grid"]["boundary"])
    quarter = max(1, per // 4)
    f, so = spec["filter"], spec["source_only"]
    wavelength = src["c"] / src["frequency"]
    where = grid.xyz[plan.sensors]
    local = letkf.localisation(grid.n, grid.xyz, where, f["block"],
                               f["localisation"] * wavelength)
    sigma2 = spec["sensors"]["measurement_sigma"] ** 2
    shape = (plan.sensors.size, 6)
    distances = np.linalg.norm(where, axis=1)
    scale = np.full((2, grid.size), f["field_error"])
    if f["field_error_profile"] == "truncation":
        ph = dipole.phasors(grid.r, grid.theta)
        A_z = ph["A_r"] * np.cos(grid.theta) - ph["A_theta"] * np.sin(grid.theta)
        bins = np.arange(0.0, grid.r.max() + grid.spacing, grid.spacing)
        profile = model_error.truncation_profile(sim, (A_z, ph["Phi"]), bins)
        scale = np.clip(profile, f["field_error"], ERROR_CAP)
    amplitude_half_width = f["amplitude_localisation"] * wavelength
    return _Setup(sim=sim, dipole=dipole, dt=dt, per=per, quarter=quarter,
                  spin=spec["time"]["spinup_periods"] * per - quarter,
                  record=spec["time"]["periods"] * per + quarter, local=local,
                  local_half_width=f["localisation"] * wavelength,
                  amplitude_taper=letkf.gaspari_cohn(distances, amplitude_half_width),
                  amplitude_half_width=amplitude_half_width, source_distances=distances,
                  smoother=model_error.gaussian_smoother(grid.n, f["field_error_length"]),
                  error_scale=scale,
                  R_field=np.full(shape, sigma2 + f["representation_error"] ** 2),
                  R_source=np.full(shape, sigma2 + so["representation_error"] ** 2))


ERROR_CAP = 0.1
"""The truncation profile's per-step error is capped at 10 %: inside the source's own cells
the analytic potentials are not the grid's solution at all."""


def _levels(X: np.ndarray) -> np.ndarray:
    """Rows ``[A(t - dt), A(t), Phi(t), A(t + dt), Phi(t + dt)]`` -> leapfrog states
    ``(m, 2, 2, points)`` holding the levels (t, t + dt)."""
    return np.stack([X[:, 1:3], X[:, 3:5]], axis=1)


def _rows_of(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """The analysed state of one step: ``A(t - dt)`` from ``before``'s first level and the
    two levels of ``after`` (t, t + dt), ``(m, 5, points)``. ``dA/dt`` at ``t`` is formed
    from this one analysis (D60: before, the first step mixed an un-analysed ``A(t - dt)``
    with analysed levels)."""
    return np.concatenate([before[:, 0, 0][:, None], after[:, 0], after[:, 1]], axis=1)


def _fields_of(grid: grids.Grid, mean: np.ndarray, dt: float,
               mu0: float) -> dict[str, np.ndarray]:
    """E and H at ``t`` of an ensemble mean of the rows ``(5, points)`` (:func:`_rows_of`)."""
    return fdtd.fields_from(grid, mean[None, 1], mean[None, 2], (mean[None, 3] - mean[None, 0])
                       / (2 * dt), mu0)


def _sensor_rows(grid, before, after, dt, mu0, ops) -> np.ndarray:
    """Predicted readings ``(members, sensors, 6)``."""
    o = _observe(grid, before, after, dt, mu0, ops)
    return np.concatenate([o["E"], o["H"]], axis=1).transpose(0, 2, 1)


def _nis(Yp: np.ndarray, innovation: np.ndarray, R: np.ndarray) -> float:
    """Normalised innovation squared per reading, ``d^T S^-1 d / p`` with ``S = R + Yp^T Yp
    / (m - 1)`` (Woodbury: an ``m x m`` solve); 1 for a consistent filter."""
    m = Yp.shape[0]
    Z = Yp.reshape(m, -1)
    d, r = innovation.ravel(), R.ravel()
    Zr = Z / r
    inner = (m - 1) * np.eye(m) + Zr @ Z.T
    v = Zr @ d
    return float((d @ (d / r) - v @ np.linalg.solve(inner, v)) / d.size)


def field_analysis(su: _Setup, before: np.ndarray, after: np.ndarray, amps: np.ndarray,
                   y_rows: np.ndarray, Y: np.ndarray, inflation: float) -> tuple:
    """One analysis of the field filter: local ETKF transforms of the field (levels ``t - dt``
    to ``t + dt``, :func:`_rows_of`) from the sensors around each cube, and of the source
    amplitude from the sensors around the source. ``after`` (the forecast leapfrog state,
    C-ordered) is analysed in place; of ``A(t - dt)`` only the analysed mean is formed
    (nothing steps from it). Returns the analysed leapfrog state, the amplitudes, the
    analysed ensemble mean of the rows ``(5, points)`` and the forecast's effective rank
    and NIS."""
    Yp, dy = Y - Y.mean(axis=0), y_rows - Y.mean(axis=0)
    rank, nis = letkf.effective_rank(after[:, 0]), _nis(Yp, dy, su.R_field)
    W = letkf.transforms(Yp, dy, su.R_field, su.local.taper, inflation)
    means = letkf.analyse_levels(after, before[:, 0, 0], su.local, W)
    W0 = letkf.transforms(Yp, dy, su.R_field, su.amplitude_taper[None], inflation)[0]
    amps = amps.mean() + W0 @ (amps - amps.mean())
    return after, amps, means, rank, nis


def source_analysis(su: _Setup, before: np.ndarray, after: np.ndarray, amps: np.ndarray,
                    y_rows: np.ndarray, Y: np.ndarray, inflation: float) -> tuple:
    """One analysis of the source-only filter: one global ETKF of the field and the source
    amplitude together, R including the representation error (D60). Its definition, for
    any members; the cycle carries it by its amplitudes (:func:`source_analysis_on_basis`,
    tested equal to this)."""
    m = Y.shape[0]
    rows = _rows_of(before, after)
    rank = letkf.effective_rank(after[:, 0])
    nis = _nis(Y - Y.mean(axis=0), y_rows - Y.mean(axis=0), su.R_source)
    Xs = np.concatenate([rows.reshape(m, -1), amps.real[:, None], amps.imag[:, None]], axis=1)
    Xs = etkf.analysis(Xs, Y.reshape(m, -1), y_rows.ravel(), su.R_source.ravel(), inflation)
    rows = Xs[:, :-2].reshape(rows.shape)
    return _levels(rows), Xs[:, -2] + 1j * Xs[:, -1], rows, rank, nis


def source_analysis_on_basis(su: _Setup, amps: np.ndarray, basis_now: np.ndarray,
                             basis_readings: np.ndarray, basis_fields: dict,
                             y_rows: np.ndarray, inflation: float) -> tuple:
    """:func:`source_analysis` for an ensemble that differs only in the source amplitude.

    The leapfrog and its Mur faces are linear in the state and the source, and every
    member starts from rest, so member ``i`` is ``Re(a_i) B_1 + Im(a_i) B_2`` at every
    step, ``B_1``, ``B_2`` the runs driven by 1 and by j; an analysis replaces the members
    by affine combinations of themselves, and ``a_i`` by the same combination, so that stays
    true. The transform depends only on the predicted readings, which are the same
    combination of the basis runs' readings. So the filter is carried by its amplitudes
    (the ETKF analyses the members' coefficients on the basis in place of their fields):
    ``basis_now`` holds the basis runs' level ``t`` ``(2, fields, points)``, for the
    effective rank; ``basis_readings`` their predicted readings ``(2, sensors, 6)``;
    ``basis_fields`` their E and H at ``t`` (``(2, 3, points)`` each). Returns the analysed
    amplitudes, E and H of the analysed mean, the forecast's effective rank and NIS. Equal
    to :func:`source_analysis` on the stepped members to rounding (tested)."""
    coef = np.stack([amps.real, amps.imag], axis=1)                 # (m, 2)
    Y = np.einsum("mb,bsk->msk", coef, basis_readings)
    m = Y.shape[0]
    rank = letkf.effective_rank_on_basis(coef, basis_now)
    nis = _nis(Y - Y.mean(axis=0), y_rows - Y.mean(axis=0), su.R_source)
    coef = etkf.analysis(coef, Y.reshape(m, -1), y_rows.ravel(), su.R_source.ravel(),
                         inflation)
    a = coef.mean(axis=0)
    fields = {F: a[0] * basis_fields[F][:1] + a[1] * basis_fields[F][1:] for F in ("E", "H")}
    return coef[:, 0] + 1j * coef[:, 1], fields, rank, nis


def cycle(exp: Experiment, su: _Setup, nominal: complex, rng: np.random.Generator,
          euler: bool = False) -> dict:
    """One run: spin-up, then ``record`` steps of forecast, sensors and both filters'
    analyses. Returns the traces of every estimator's E and H at each step (``traces``),
    the times, the readings ``(steps, 2, 3, sensors)`` and the filters' health per step.

    BLAS runs on one thread here: a multi-threaded BLAS splits the ensemble-sized products
    and eigen-decompositions by its thread count, and the tables' last digits followed the
    machine's core count (measured: a run with OMP_NUM_THREADS unset and one with it at 1
    differed at 2e-12). With one thread they are the same whatever the machine or
    ``--jobs``, and the runs here were timed so."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _cycle(exp, su, nominal, rng, euler)


def _cycle(exp: Experiment, su: _Setup, nominal: complex, rng: np.random.Generator,
           euler: bool) -> dict:
    reuse_freed_memory()
    spec, plan = exp.spec, exp.plan
    grid = plan.grid
    sim, dipole, dt = su.sim, su.dipole, su.dt
    fcfg = spec["filter"]
    m, infl = fcfg["members"], fcfg["inflation"]
    sigma_obs = spec["sensors"]["measurement_sigma"]
    free_amps = np.array([nominal, 1.0, 1.0j])          # plain simulation, the fit's basis
    phasors = dipole.phasors(grid.r, grid.theta)
    omega_dt = dipole.omega * dt
    draws = rng.standard_normal(m) + 1j * rng.standard_normal(m)
    amps = nominal + fcfg["amplitude_spread"] * draws / np.sqrt(2)
    free = np.zeros((3, 2, 2, grid.size))
    t = 0.0
    for _ in range(su.spin):
        free = sim.step(free, t, free_amps)
        t += dt
    # the members are still the basis runs' combinations (see source_analysis_on_basis)
    field = (amps.real[:, None, None, None] * free[1] + amps.imag[:, None, None, None]
             * free[2])
    amp_field, amp_src = amps.copy(), amps.copy()
    run_euler = _EulerRun(sim, nominal) if euler else None
    if run_euler is not None:
        for k in range(su.spin):
            run_euler.step(k * dt)
    traces = {name: [] for name in (KF, SOURCE_ONLY, PLAIN, EULER)}
    basis_traces, basis_sensors, measured, times, health = [], [], [], [], []
    mu0, ops = dipole.mu0, plan.sensor_ops
    for step in range(su.record):
        free_next = sim.step(free, t, free_amps)
        field_next = sim.step(field, t, amp_field)
        jitter = model_error.smooth_noise(rng, 2 * m, grid.n, su.smoother)
        field_next = model_error.perturb(field_next, omega_dt, jitter[:m], jitter[m:],
                                         su.error_scale)
        truth = _analytic_cartesian(grid, phasors, np.exp(1j * dipole.omega * t), plan.sensors)
        y = truth + sigma_obs * rng.standard_normal(truth.shape)
        y_rows = y.reshape(6, -1).T                      # (sensors, 6)
        Y = _sensor_rows(grid, field, field_next, dt, mu0, ops)
        field, amp_field, means, rank_f, nis_f = field_analysis(su, field, field_next,
                                                                amp_field, y_rows, Y, infl)
        traces[KF].append(_fields_of(grid, means, dt, mu0))
        basis = _observe(grid, free[1:], free_next[1:], dt, mu0)
        basis_y = _sensor_rows(grid, free[1:], free_next[1:], dt, mu0, ops)
        amp_src, fields_s, rank_s, nis_s = source_analysis_on_basis(
            su, amp_src, free_next[1:, 0], basis_y, basis, y_rows, infl)
        traces[SOURCE_ONLY].append(fields_s)
        traces[PLAIN].append(_observe(grid, free[:1], free_next[:1], dt, mu0))
        basis_traces.append(basis)
        basis_sensors.append(basis_y)
        free = free_next
        if run_euler is not None:
            traces[EULER].append(run_euler.fields())
            run_euler.step(t)
        measured.append(y)
        times.append(t)
        health += [{"step": step, "time": t, "estimator": name, "effective_rank": rank,
                    "nis": nis} for name, rank, nis in ((KF, rank_f, nis_f),
                                                        (SOURCE_ONLY, rank_s, nis_s))]
        t += dt
    measured = np.stack(measured)
    traces[FIT] = _amplitude_fit(measured, basis_sensors, basis_traces)
    return {"traces": traces, "times": np.array(times), "measured": measured,
            "health": health, "phasors": phasors}


def run_point(exp: Experiment, key: tuple) -> tuple[list[dict], list, dict, list[dict]]:
    """Rows of one scenario and noise row over every run; for the first noise row of a
    scenario, the figure's slices from run 1 at the last recorded step; and the filters'
    health over time (effective rank, NIS)."""
    spec, plan = exp.spec, exp.plan
    grid, sensors = plan.grid, plan.sensors
    s_idx, r_idx, l_idx = key
    scenario = spec["scenarios"][s_idx]
    reading = spec["noise"]["readings"][r_idx]
    level = float(spec["noise"]["source_levels"][l_idx])
    su = _setup(spec, plan)
    nominal = _amplitude(scenario["nominal_amplitude"])
    per_run, health = {}, []
    for run in range(spec["monte_carlo"]["runs"]):
        rng = exp.config.monte_carlo.rng(*key, run)
        out = cycle(exp, su, nominal, rng, euler=run == 0)
        health += [{**h, "run": run} for h in out["health"]]
        smooth = _smoothed(out["measured"], out["times"], su.dipole.omega, spec["rls"])
        per_run[run] = _errors(exp, grid, out["phasors"], su.dipole, sensors, out["times"],
                               out["traces"], out["measured"], smooth, su.quarter)
        if run == 0 and r_idx == 0 and l_idx == 0:
            slices = _slices(grid, out["phasors"], su.dipole, out["times"], out["traces"])
    figure = {"scenario": scenario["name"], **slices} if r_idx == 0 and l_idx == 0 else {}
    rows, cells = _rows(exp, key, reading, level, per_run)
    return rows, cells, figure, _health_rows(exp, key, reading, level, health)


def _amplitude_fit(measured: np.ndarray, basis_sensors: list, basis_traces: list) -> list:
    """The amplitude-only fit: the one complex source amplitude ``a`` whose simulation best
    fits every reading of the record in least squares (the simulation is linear in ``Re a``
    and ``Im a``: two basis runs, driven by 1 and by j), then its fields. It sees the whole
    record at once (a smoother): the best any filter that corrects only the source can do."""
    G = np.stack(basis_sensors)                    # (steps, 2 basis, sensors, 6)
    y = measured.reshape(len(G), 6, -1).transpose(0, 2, 1)
    design = G.transpose(1, 0, 2, 3).reshape(2, -1).T
    coef = np.linalg.lstsq(design, y.ravel(), rcond=None)[0]
    return [{F: coef[0] * b[F][:1] + coef[1] * b[F][1:] for F in ("E", "H")}
            for b in basis_traces]


def _health_rows(exp, key, reading, level, health) -> list[dict]:
    """Per filter and recorded step: the effective rank of the forecast ensemble (singular
    values of the anomalies of ``A`` and ``Phi`` at ``t`` above 1e-6 of the largest; min and
    max over runs) and the NIS
    per reading (mean over runs)."""
    df = pd.DataFrame(health)
    out = []
    for (name, step), g in df.groupby(["estimator", "step"], sort=False):
        out.append({"scenario": exp.spec["scenarios"][key[0]]["name"],
                    "noise_reading": reading, "noise_param": level, "estimator": name,
                    "step": int(step), "time": float(g["time"].iloc[0]),
                    "effective_rank_min": int(g["effective_rank"].min()),
                    "effective_rank_max": int(g["effective_rank"].max()),
                    "nis": float(g["nis"].mean()), "runs": len(g)})
    return out


def _smoothed(measured: np.ndarray, times: np.ndarray, omega: float, rls: dict) -> np.ndarray:
    """The RLS baseline on every sensor's time series, shaped like ``measured``."""
    series = measured.reshape(len(times), -1).T[:, :, None]    # (sensors x 6, steps, 1)
    return sinusoid_rls(series, times, omega, rls)[..., 0].T.reshape(measured.shape)


def _slices(grid, phasors, dipole, times, traces) -> dict:
    """|E| and |H| in the plane through the source nearest y = 0 at the last recorded step:
    the analytic truth, the field filter's mean, the amplitude-only fit and the field
    filter's error; points within two cells of the source are left blank."""
    n = grid.n
    plane = np.flatnonzero(np.isclose(grid.xyz[:, 1], grid.axis[n // 2]))
    turn = np.exp(1j * dipole.omega * times[-1])
    truth = _analytic_cartesian(grid, phasors, turn, plane)
    kf = np.stack([traces[KF][-1]["E"][0][:, plane], traces[KF][-1]["H"][0][:, plane]])
    fit = np.stack([traces[FIT][-1]["E"][0][:, plane], traces[FIT][-1]["H"][0][:, plane]])
    blank = grid.r[plane] < 2 * grid.spacing
    out = {"labels": SLICE_LABELS}
    for i, field_name in enumerate(("E", "H")):
        for label, data in zip(SLICE_LABELS, (truth[i], kf[i], fit[i], kf[i] - truth[i]),
                               strict=True):
            mag = np.linalg.norm(data, axis=0)
            mag[blank] = np.nan
            out[f"{field_name}|{label}"] = mag.reshape(n, n)
    out["extent"] = [grid.axis[0], grid.axis[-1], grid.axis[0], grid.axis[-1]]
    out["time"] = float(times[-1])
    return out


class _EulerRun:
    """The plain simulation with the thesis' forward Euler (``F ~ I + T F`` for eq 5.20's
    system) on ``(u, u')`` for ``u = [A_z, Phi]``, nominal source, Mur faces not applied
    (Euler has no two-level boundary of that kind); it grows without bound and is reported
    as it comes out."""

    def __init__(self, sim: fdtd.Simulation, amplitude: complex) -> None:
        self.sim, self.amplitude = sim, np.array([amplitude])
        self.u = np.zeros((1, 2, sim.grid.size))
        self.v = np.zeros_like(self.u)

    def step(self, t: float) -> None:
        L = self.sim.grid.laplacian
        s = np.zeros_like(self.u)
        s[..., self.sim._support] = self.sim.source(t, self.amplitude)
        with np.errstate(all="ignore"):
            self.u, self.v = wave.step(self.u, self.v,
                                       lambda x: (L @ x.reshape(-1, x.shape[-1]).T).T.reshape(
                                           x.shape),
                                       self.sim.dipole.c, self.sim.dt, s_now=s,
                                       method="euler")

    def fields(self) -> dict:
        with np.errstate(all="ignore"):
            return fdtd.fields_from(self.sim.grid, self.u[:, 0], self.u[:, 1], self.v[:, 0],
                               self.sim.dipole.mu0)


def _analytic_cartesian(grid: grids.Grid, phasors: dict, turn: complex,
                        where: np.ndarray) -> np.ndarray:
    """Analytic E and H at ``where`` as ``(2, 3, points)`` Cartesian components."""
    th, ph = grid.theta[where], grid.phi[where]
    Er = (phasors["E_r"][where] * turn).real
    Et = (phasors["E_theta"][where] * turn).real
    Hp = (phasors["H_phi"][where] * turn).real
    st, ct, sp_, cp = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    E = np.stack([st * cp * Er + ct * cp * Et, st * sp_ * Er + ct * sp_ * Et, ct * Er - st * Et])
    H = np.stack([-sp_ * Hp, cp * Hp, np.zeros_like(Hp)])
    return np.stack([E, H])


def _errors(exp, grid, phasors, dipole, sensors, times, traces, measured, smooth,
            quarter: int) -> dict:
    """Per estimator, component, zone and part: (mean squared error, mean squared truth).

    The record starts a quarter period (``quarter`` steps) before the table's window.
    ``real``: the estimate against ``Re{F e^{j omega t}}`` over the window. ``imag``: the
    experiment driven by ``Im{I0 e^{j omega t}}`` is this one a quarter period later, so
    its estimate at ``t`` is this run's estimate at ``t - T/4``, against
    ``Im{F e^{j omega t}}``. ``abs``: the magnitude formed from the two, against ``|F|``."""
    out = {}
    tree = spatial.cKDTree(grid.xyz[sensors])
    for zone, where in exp.plan.zones.items():
        _, nearest = tree.query(grid.xyz[where])
        turn = np.exp(1j * dipole.omega * times)[:, None]
        want = {"E_r": (phasors["E_r"][where] * turn).real,
                "E_theta": (phasors["E_theta"][where] * turn).real,
                "H_phi": (phasors["H_phi"][where] * turn).real}
        est = {}
        for name in (KF, SOURCE_ONLY, FIT, PLAIN, EULER):
            if not traces[name]:
                continue
            E = np.stack([tr["E"][0] for tr in traces[name]])[..., where]
            H = np.stack([tr["H"][0] for tr in traces[name]])[..., where]
            Es, Hs = fdtd.spherical(grid, E, where), fdtd.spherical(grid, H, where)
            est[name] = {"E_r": Es["r"], "E_theta": Es["theta"], "H_phi": Hs["phi"]}
        for name, data in (("measurement", measured), (RLS, smooth)):
            E, H = data[:, 0][..., nearest], data[:, 1][..., nearest]
            Es, Hs = fdtd.spherical(grid, E, where), fdtd.spherical(grid, H, where)
            est[name] = {"E_r": Es["r"], "E_theta": Es["theta"], "H_phi": Hs["phi"]}
        q = quarter
        for name, comps in est.items():
            for comp in COMPONENTS:
                x, w = comps[comp], want[comp]
                with np.errstate(all="ignore"):
                    pairs = {"real": (x[q:], w[q:]), "imag": (x[:-q], w[:-q]),
                             "abs": (np.hypot(x[q:], x[:-q]), np.hypot(w[q:], w[:-q]))}
                for part, (got, truth) in pairs.items():
                    with np.errstate(all="ignore"):
                        mse = float(np.mean((got - truth) ** 2))
                    out[(name, zone, comp, part)] = (mse if np.isfinite(mse) else np.inf,
                                                     float(np.mean(truth**2)))
    return out


def _rows(exp, key, reading, level, per_run) -> tuple[list[dict], list]:
    """The rows of one scenario and noise row, and per zone, component and part the cell's
    per-run losses (RMSE) for the claims; an RMSE above :data:`DIVERGED_RATIO` times the
    field's RMS is a diverged run (reported ``inf``)."""
    spec = exp.spec
    scenario = spec["scenarios"][key[0]]["name"]
    s_no = key[2] + 1
    rows, losses = [], {}
    for cell in per_run[0]:
        name, zone, comp, part = cell
        present = [r for r in per_run if cell in per_run[r]]     # the Euler run: run 1 only
        mse = np.array([per_run[r][cell][0] for r in present])
        ref = float(np.mean([per_run[r][cell][1] for r in present]))
        values = np.sqrt(mse)
        broke = ~(values <= DIVERGED_RATIO * np.sqrt(ref))
        mean, se = metrics.mean_and_se(values) if len(values) > 1 else (float(values[0]),
                                                                        float("nan"))
        if broke.any():
            mean, se = float("inf"), float("nan")
        losses.setdefault((zone, comp, part), {})[name] = claims.Losses(values, broke)
        rows.append({"table_id": TABLE_IDS.get((comp, zone, name), ""), "s_no": s_no,
                     "scenario": scenario, "zone": zone, "beta_r": exp.plan.beta_r[zone],
                     "noise_reading": reading,
                     "noise_param": level, "estimator": name, "field_component": comp,
                     "part": part, "rmse": mean, "rmse_se": se, "runs": len(values),
                     "field_rms": np.sqrt(ref), "relative": mean / np.sqrt(ref)})
    cells = [(claims.cell(scenario=scenario, zone=zone, noise_reading=reading,
                          noise_param=level, field_component=comp, part=part), cell_losses)
             for (zone, comp, part), cell_losses in losses.items()]
    return rows, cells


def _run_point_args(args):
    return run_point(*args)


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    done = map_tasks(_run_point_args, [(exp, k) for k in _points(exp)], jobs, on_done)
    df = pd.DataFrame([row for part, _, _, _ in done for row in part])[TABLES["rmse"].columns]
    table = claims.table([c for _, cells, _, _ in done for c in cells], CLAIMS, "RMSE")
    health = pd.DataFrame([row for *_, part in done for row in part])[TABLES["health"].columns]
    figures = {}
    for _, _, fig, _ in done:
        if fig:
            name = "field_slices_" + "".join(ch if ch.isalnum() else "_"
                                             for ch in fig["scenario"]).strip("_")
            figures[name] = plots.field_slices(
                fig, f"{fig['scenario']}: |E| and |H| in the x-z plane through the source, "
                f"t = {fig['time']:.3g} periods (run 1)")
    figures["effective_rank"] = plots.ensemble_rank(health)
    return Result(tables={"rmse": df.reset_index(drop=True), "claims": table,
                          "health": health.reset_index(drop=True)}, figures=figures)


def summary(result: Result) -> str:
    df = result.tables["rmse"]
    view = df[df["part"] == "real"].pivot_table(
        index=["scenario", "noise_param", "zone", "field_component"], columns="estimator",
        values="relative", sort=False)
    return "relative RMSE (RMSE / field RMS)\n" + view.to_string(
        float_format=lambda v: f"{v:.3g}")

