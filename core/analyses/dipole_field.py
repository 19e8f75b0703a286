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
:mod:`estim.analyses.dipole`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from estim import claims, metrics, plots
from estim.analyses import dipole as literal
from estim.analyses.base import Result, TableSpec, map_tasks
from estim.analyses.dipole import COMPONENTS, TABLE_IDS, sinusoid_rls
from estim.blocks import MonteCarlo
from estim.errors import ConfigError
from estim.fields import etkf, wave
from estim.fields.dipole import Dipole
from estim.fields.fdtd import Grid, Simulation, fields_from, spherical
from estim.schema import REQUIRED, Experiment, check_interval, integer, list_of, number, text
from estim.settings import Settings, block, blocks, setting, settings_class
from estim.summary import Quote

KF, RLS, PLAIN = "KF", "RLS", "plain simulation"
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
    """The ensemble filter."""

    members: int = setting(50, integer(3, 2000), doc="ensemble members")
    amplitude_spread: float = setting(0.3, number(positive=True, maximum=1e3),
                                      doc="spread of the members' source amplitudes")
    model_error: float = setting(0.02, number(minimum=0.0, maximum=1e3),
                                 doc="the grid's own error in a measured field, added to R")
    inflation: float = setting(1.0, number(minimum=1.0, maximum=2.0),
                               doc="multiplicative inflation of the forecast covariance")


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
    filter: FilterSettings = block(FilterSettings, doc="the ensemble filter")
    rls: literal.RLSSettings = block(literal.RLSSettings, doc="the per-sensor RLS baseline")
    time: Time = block(Time, doc="spin-up and record")
    noise: literal.SourceNoise = block(literal.SourceNoise, required=True,
                                       doc="the thesis' source-noise rows (kept for the "
                                           "layout, D59)")
    monte_carlo: MonteCarlo = block(MonteCarlo, required=True, doc="runs and seed")


SCHEMA: dict = Config.schema()

_KEYS = ("table_id", "s_no", "scenario", "zone", "noise_reading", "noise_param", "estimator",
         "field_component", "part")
TABLES = {
    "rmse": TableSpec("rmse.csv", _KEYS, ("rmse", "rmse_se", "runs", "field_rms",
                                          "relative"),
                      reference=("rmse",), join=(("s_no", ("s_no",)), ("part", ("part",))),
                      title="RMSE of the fields against the analytic dipole (field filter)",
                      reference_ids=tuple(TABLE_IDS.values())),
    "claims": claims.TABLE,
}
CLAIMS = ((KF, RLS), (KF, PLAIN), (KF, "measurement"), (RLS, "measurement"))
"""The thesis' headline (the filter below RLS), the filter against the plain simulation
(the open loop: with the true source, the grid's floor) and each filter against the raw
nearest sensor."""
QUOTES = (Quote("relative RMSE (RMSE / field RMS)", "rmse", "relative", by="estimator"),)


@dataclass(frozen=True)
class Plan:
    """The grid, the sensors (grid indices) and their rows of the operators, and each
    zone's grid points, built once."""

    grid: Grid
    sensors: np.ndarray
    zones: dict
    sensor_ops: tuple


def prepare(spec: dict, source: str) -> Plan:
    g = spec["grid"]
    if g["n"] % 2:
        raise ConfigError(source, "grid.n", "expected an even number (no grid point on the "
                          "source's centre, where the analytic field is infinite)")
    grid = Grid(g["n"], g["length"] / g["n"])
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
    return Plan(grid=grid, sensors=sensors, zones=zones,
                sensor_ops=sensor_operators(grid, sensors))


FIELD_COST_RATIO = 1000
"""``--max-work`` bounds cost in the currency of the other analyses, state-samples of the
stiff integrator. One grid-point update of the vectorised leapfrog costs far less: measured
on the development machine, 6.4e8 of them (one run of this config: 4 n^3 states x 51
members x 96 steps) took 21 s, where ``mosfet_saturation``'s 4.3e5 state-samples take about
20 s, a ratio near 1500. Grid-point updates are divided by this (rounded-down) ratio."""


def work_size(spec: dict) -> int:
    """Grid-point updates (``4 n^3`` per member and step, the plain simulation counted as a
    member) over every scenario, noise row and run, over :data:`FIELD_COST_RATIO`."""
    g, t = spec["grid"], spec["time"]
    per_period = round(g["n"] / (g["courant"] * g["length"]))
    steps = (t["spinup_periods"] + t["periods"]) * per_period
    points = len(spec["noise"]["source_levels"]) * len(spec["noise"].get("readings") or [1])
    updates = (4 * g["n"] ** 3 * (spec["filter"]["members"] + 1) * steps * points
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


def _observe(grid: Grid, states_before: np.ndarray, states_after: np.ndarray, dt: float,
             mu0: float, ops: tuple | None = None) -> dict[str, np.ndarray]:
    """Cartesian E and H at time t from ``states_before`` (levels t - dt, t) and
    ``states_after`` (t, t + dt): ``dA/dt`` by the centred difference. With ``ops`` (the
    sensor rows of the gradient and curl, :func:`sensor_operators`) only at the sensors."""
    A, Phi = states_after[:, 0, 0], states_after[:, 0, 1]
    dA = (states_after[:, 1, 0] - states_before[:, 0, 0]) / (2 * dt)
    if ops is None:
        return fields_from(grid, A, Phi, dA, mu0)
    grad_s, curl_z, pick = ops
    E = -(grad_s @ Phi.T).T.reshape(A.shape[0], 3, -1)
    E[:, 2] -= dA[:, pick]
    H = (curl_z @ A.T).T.reshape(A.shape[0], 3, -1) / mu0
    return {"E": E, "H": H}


def sensor_operators(grid: Grid, sensors: np.ndarray) -> tuple:
    """The rows of the gradient at the sensors, the columns of the curl that act on ``A_z``
    (the only component of ``A``) at the sensors' rows, and the sensors themselves."""
    rows = np.concatenate([sensors + k * grid.size for k in range(3)])
    grad_s = grid.grad[rows]
    curl_z = grid.curl[rows][:, 2 * grid.size:3 * grid.size]
    return grad_s.tocsr(), curl_z.tocsr(), sensors


def run_point(exp: Experiment, key: tuple) -> tuple[list[dict], list, dict]:
    """Rows of one scenario and noise row over every run; and, for the first noise row of a
    scenario, the figure's slices from run 1 at the last recorded step."""
    spec, plan = exp.spec, exp.plan
    grid, sensors = plan.grid, plan.sensors
    s_idx, r_idx, l_idx = key
    scenario = spec["scenarios"][s_idx]
    reading = spec["noise"]["readings"][r_idx]
    level = float(spec["noise"]["source_levels"][l_idx])
    src = spec["source"]
    dipole = Dipole(I0=1.0, dl=grid.spacing, omega=2 * np.pi * src["frequency"], c=src["c"],
                    mu0=src["mu0"])
    dt = spec["grid"]["courant"] * grid.spacing / src["c"]
    per = int(round(1 / (src["frequency"] * dt)))
    dt = 1 / (src["frequency"] * per)                  # whole steps per period
    sim = Simulation(grid, dipole, dt, dl=grid.spacing, width=spec["grid"]["source_width"],
                     boundary=spec["grid"]["boundary"])
    quarter = max(1, per // 4)
    spin = spec["time"]["spinup_periods"] * per - quarter
    record = spec["time"]["periods"] * per + quarter
    fcfg = spec["filter"]
    m = fcfg["members"]
    sigma_obs = spec["sensors"]["measurement_sigma"]
    R = np.full(6 * sensors.size, sigma_obs**2 + fcfg["model_error"] ** 2)
    nominal = _amplitude(scenario["nominal_amplitude"])
    phasors = dipole.phasors(grid.r, grid.theta)
    runs = spec["monte_carlo"]["runs"]
    per_run = {}
    for run in range(runs):
        rng = np.random.default_rng(np.random.SeedSequence(spec["monte_carlo"]["seed"],
                                                           spawn_key=(*key, run)))
        spread = fcfg["amplitude_spread"]
        draws = rng.standard_normal(m) + 1j * rng.standard_normal(m)
        amps = nominal + spread * draws / np.sqrt(2)
        ens = np.zeros((m, 2, 2, grid.size))
        plain = np.zeros((1, 2, 2, grid.size))
        t = 0.0
        for _ in range(spin):
            ens = sim.step(ens, t, amps)
            plain = sim.step(plain, t, np.array([nominal]))
            t += dt
        euler = _EulerRun(sim, nominal) if run == 0 else None
        if euler is not None:
            for k in range(spin):
                euler.step(k * dt)
        traces = {name: [] for name in (KF, PLAIN, EULER, "measured")}
        times = []
        for _ in range(record):
            ens_next = sim.step(ens, t, amps)
            plain_next = sim.step(plain, t, np.array([nominal]))
            t_obs = t                                   # the level ens_next[:, 0] is at t
            turn = np.exp(1j * dipole.omega * t_obs)
            truth_cart = _analytic_cartesian(grid, phasors, turn, sensors)
            y = truth_cart.ravel() + sigma_obs * rng.standard_normal(truth_cart.size)
            obs = _observe(grid, ens, ens_next, dt, dipole.mu0, plan.sensor_ops)
            Y = np.concatenate([obs["E"], obs["H"]], axis=1).reshape(m, -1)
            X = np.concatenate([ens_next.reshape(m, -1), amps.real[:, None],
                                amps.imag[:, None]], axis=1)
            Xa = etkf.analysis(X, Y, y, R, fcfg["inflation"])
            amps = Xa[:, -2] + 1j * Xa[:, -1]
            analysed = Xa[:, :-2].reshape(ens_next.shape)
            mean_now = analysed.mean(axis=0, keepdims=True)
            traces[KF].append(_observe(grid, ens.mean(axis=0, keepdims=True), mean_now, dt,
                                       dipole.mu0))
            traces[PLAIN].append(_observe(grid, plain, plain_next, dt, dipole.mu0))
            if euler is not None:
                traces[EULER].append(euler.fields())
                euler.step(t)
            traces["measured"].append(y.reshape(2, 3, -1))
            times.append(t_obs)
            ens, plain = analysed, plain_next
            t += dt
        times = np.array(times)
        measured = np.stack(traces["measured"])                # (steps, 2, 3, sensors)
        smooth = _smoothed(measured, times, dipole.omega, spec["rls"])
        per_run[run] = _errors(exp, grid, phasors, dipole, sensors, times, traces, measured,
                               smooth, quarter)
        if run == 0 and r_idx == 0 and l_idx == 0:
            slices = _slices(grid, phasors, dipole, sensors, times, traces, smooth[-1])
    figure = {"scenario": scenario["name"], **slices} if r_idx == 0 and l_idx == 0 else {}
    rows, cells = _rows(exp, key, reading, level, per_run)
    return rows, cells, figure


def _smoothed(measured: np.ndarray, times: np.ndarray, omega: float, rls: dict) -> np.ndarray:
    """The RLS baseline on every sensor's time series, shaped like ``measured``."""
    series = measured.reshape(len(times), -1).T[:, :, None]    # (sensors x 6, steps, 1)
    return sinusoid_rls(series, times, omega, rls)[..., 0].T.reshape(measured.shape)


def _slices(grid, phasors, dipole, sensors, times, traces, smooth_last) -> dict:
    """|E| and |H| in the plane through the source nearest y = 0 at the last recorded step:
    the analytic truth, the filter's mean, the RLS baseline (nearest sensor) and the
    filter's error; points within two cells of the source are left blank."""
    n = grid.n
    plane = np.flatnonzero(np.isclose(grid.xyz[:, 1], grid.axis[n // 2]))
    turn = np.exp(1j * dipole.omega * times[-1])
    truth = _analytic_cartesian(grid, phasors, turn, plane)
    kf = np.stack([traces[KF][-1]["E"][0][:, plane], traces[KF][-1]["H"][0][:, plane]])
    _, nearest = cKDTree(grid.xyz[sensors]).query(grid.xyz[plane])
    rls = smooth_last[..., nearest]
    blank = grid.r[plane] < 2 * grid.spacing
    out = {}
    for i, field_name in enumerate(("E", "H")):
        for label, data in (("truth", truth[i]), (KF, kf[i]), (RLS, rls[i]),
                            ("KF error", kf[i] - truth[i])):
            mag = np.linalg.norm(data, axis=0)
            mag[blank] = np.nan
            out[f"{field_name}|{label}"] = mag.reshape(n, n)
    out["extent"] = [grid.axis[0], grid.axis[-1], grid.axis[0], grid.axis[-1]]
    out["time"] = float(times[-1])
    return out


class _EulerRun:
    """The plain simulation with the thesis' forward Euler (eq 5.20) on ``(u, u')`` for
    ``u = [A_z, Phi]``, nominal source, Mur faces not applied (Euler has no two-level
    boundary of that kind); it grows without bound and is reported as it comes out."""

    def __init__(self, sim: Simulation, amplitude: complex) -> None:
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
            return fields_from(self.sim.grid, self.u[:, 0], self.u[:, 1], self.v[:, 0],
                               self.sim.dipole.mu0)


def _analytic_cartesian(grid: Grid, phasors: dict, turn: complex,
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
    tree = cKDTree(grid.xyz[sensors])
    for zone, where in exp.plan.zones.items():
        _, nearest = tree.query(grid.xyz[where])
        turn = np.exp(1j * dipole.omega * times)[:, None]
        want = {"E_r": (phasors["E_r"][where] * turn).real,
                "E_theta": (phasors["E_theta"][where] * turn).real,
                "H_phi": (phasors["H_phi"][where] * turn).real}
        est = {}
        for name in (KF, PLAIN, EULER):
            if not traces[name]:
                continue
            E = np.stack([tr["E"][0] for tr in traces[name]])[..., where]
            H = np.stack([tr["H"][0] for tr in traces[name]])[..., where]
            Es, Hs = spherical(grid, E, where), spherical(grid, H, where)
            est[name] = {"E_r": Es["r"], "E_theta": Es["theta"], "H_phi": Hs["phi"]}
        for name, data in (("measurement", measured), (RLS, smooth)):
            E, H = data[:, 0][..., nearest], data[:, 1][..., nearest]
            Es, Hs = spherical(grid, E, where), spherical(grid, H, where)
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
                     "scenario": scenario, "zone": zone, "noise_reading": reading,
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
    df = pd.DataFrame([row for part, _, _ in done for row in part])[TABLES["rmse"].columns]
    table = claims.table([c for _, cells, _ in done for c in cells], CLAIMS, "RMSE")
    figures = {}
    for _, _, fig in done:
        if fig:
            name = "field_slices_" + "".join(ch if ch.isalnum() else "_"
                                             for ch in fig["scenario"]).strip("_")
            figures[name] = plots.field_slices(
                fig, f"{fig['scenario']}: |E| and |H| in the x-z plane through the source, "
                f"t = {fig['time']:.3g} periods (run 1)")
    return Result(tables={"rmse": df.reset_index(drop=True), "claims": table},
                  figures=figures)


def summary(result: Result) -> str:
    df = result.tables["rmse"]
    view = df[df["part"] == "real"].pivot_table(
        index=["scenario", "noise_param", "zone", "field_component"], columns="estimator",
        values="relative", sort=False)
    return "relative RMSE (RMSE / field RMS)\n" + view.to_string(
        float_format=lambda v: f"{v:.3g}")

