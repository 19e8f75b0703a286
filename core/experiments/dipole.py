"""The thesis' Chapter 5 experiment as printed: a Kalman filter and RLS per grid point for
the potentials of a Hertzian dipole, fields from the estimates (Tables 5.1-5.12).

Variant ``literal`` (eqs 5.42-5.47). On a grid of points ``(r, theta)`` in each zone:

1. per point and per potential ``q`` in ``A_r, A_theta, Phi`` the state ``[q, q']`` (eq
   5.42's ``[A, V, Phi, Psi]``, ``A`` with two components) follows ``F = [[1, T], [0, 1]]``
   driven by the analytic solution through ``Z_k`` (chosen so that the analytic potentials
   satisfy the recursion exactly) and by the source noise on the rates, ``T c^2 w``
   (``B^(3)``; the thesis puts the current noise on ``A``, docs/deviations.md);
2. ``A_r, A_theta, Phi`` are measured at every point with white noise ``sqrt(R_k)`` (eqs
   5.46-5.47);
3. the KF (Appendix A.1, the project's :class:`~estim.estimators.kf.KalmanFilter`) runs per
   point with the printed ``Q``, ``R``, ``P0`` from the analytic initial state; RLS (the
   project's :class:`~estim.estimators.rls.RecursiveLeastSquares`, fixed forgetting, its
   regressor the taps of ``cos(omega t)``: a sinusoid of the known frequency per point)
   smooths each measured potential, rates by a backward difference;
4. ``E = -grad Phi - V`` (eq 5.25) and ``H = curl A / mu0`` (eq 5.27) by finite differences
   on the ``(r, theta)`` grid; RMSE (eq 3.42) against the analytic field, for the real part
   (the experiment driven by ``Re{. e^{j omega t}}``), the imaginary part (a second,
   independent experiment driven by ``Im{.}``) and the magnitude ``|E|`` formed from the two.

Besides KF and RLS: ``measurement`` (fields from the raw measured potentials) and
``exact potentials`` (fields from the analytic potentials by the same finite differences:
the grid's own floor). Normalised units: ``c = mu0 = eps0 = 1``, period 1, wavelength 1,
``I0 dl = 1`` (``source``); the thesis gives none of ``N, Delta, dl, I0, omega``, the
distances or the units.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estim.config.builders import check_interval
from estim.config.experiment import Experiment
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
from estim.errors import ConfigError
from estim.estimators.base import as_matrix
from estim.estimators.kf import KalmanFilter
from estim.estimators.rls import RecursiveLeastSquares
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims
from estim.experiments.shared.blocks import MonteCarlo, Readings
from estim.fields.dipole import Dipole
from estim.numerics import metrics, signals
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")

COMPONENTS = ("E_r", "E_theta", "H_phi")
PARTS = ("imag", "real", "abs")
KF, RLS = "KF", "RLS"
TABLE_IDS = {(c, z, e): f"5.{1 + 3 * k + i}" for k, (z, e) in enumerate(
    (("near", KF), ("near", RLS), ("far", KF), ("far", RLS))) for i, c in enumerate(COMPONENTS)}
"""Thesis table of each (component, zone, estimator): 5.1-5.3 KF near, 5.4-5.6 RLS near,
5.7-5.9 KF far, 5.10-5.12 RLS far."""

@settings_class
class Source(Settings):
    """The Hertzian dipole's medium and frequency, in normalised units (D57)."""

    frequency: float = setting(1.0, number(positive=True, maximum=1e12), doc="frequency")
    c: float = setting(1.0, number(positive=True, maximum=1e12), doc="speed of light")
    mu0: float = setting(1.0, number(positive=True, maximum=1e6), doc="permeability")


@settings_class
class LiteralSource(Source):
    """The Hertzian dipole, in normalised units (D57)."""

    I0_dl: float = setting(1.0, number(positive=True, maximum=1e6), doc="current moment I0 dl")


@settings_class
class ZoneBlock(Settings):
    """A near or far zone in (r, theta)."""

    name: str = setting(REQUIRED, text({"near", "far"}), doc="near or far")
    r: list = setting(REQUIRED, list_of(number(positive=True, maximum=1e6), max_length=2),
                      doc="[low, high] radius")
    theta_deg: list = setting([30.0, 150.0], list_of(number(minimum=1.0, maximum=179.0),
                                                     max_length=2),
                              unit="deg", doc="[low, high] polar angle")


@settings_class
class LiteralZone(ZoneBlock):
    """A near or far zone: a grid of points in (r, theta)."""

    points_r: int = setting(5, integer(3, 200), doc="grid points in r")
    points_theta: int = setting(5, integer(3, 200), doc="grid points in theta")


@settings_class
class Time(Settings):
    """Sampling and record."""

    samples_per_period: int = setting(50, integer(8, 10_000), doc="samples per period")
    periods: int = setting(4, integer(1, 1000), doc="record length in periods")


@settings_class
class SourceNoise(Readings):
    """The thesis' noise at the source, as printed."""

    source_levels: list = setting(REQUIRED, list_of(number(positive=True, maximum=1e3)),
                                  doc="the printed source-noise numbers")


@settings_class
class Noise(SourceNoise):
    """Noise at the source (as printed) and on the measured potentials."""

    measurement_sigma: float = setting(0.1, number(minimum=MIN_NOISE, maximum=1e3),
                                       doc="white noise on every measured potential")


@settings_class
class KFSettings(Settings):
    """The per-point KF of eqs 5.42-5.47, its covariances as printed."""

    Q: list = setting([1e-4, 1e-3, 1e-4, 1e-2], list_of(number(minimum=0.0, maximum=1e6),
                                                       max_length=4),
                      doc="diag Q for [A, V, Phi, Psi] (eq 5.42)")
    R: float = setting(0.01, number(positive=True, maximum=1e6), doc="R per measured potential")
    P0: list = setting([1e-4] * 4, list_of(number(minimum=0.0, maximum=1e6), max_length=4),
                       doc="diag P0 for [A, V, Phi, Psi]")


@settings_class
class RLSSettings(Settings):
    """The per-point RLS baseline (a sinusoid of the known frequency)."""

    lambda0: float = setting(0.98, number(minimum=0.5, maximum=1.0), doc="fixed forgetting")
    delta: float = setting(100.0, number(positive=True, maximum=1e12), doc="P(0) = delta I")


@settings_class
class Config(Settings):
    """The thesis' Chapter 5 experiment as printed: a KF and RLS per grid point."""

    variant: str = setting("literal", text({"literal"}), doc="the experiment as printed")
    source: LiteralSource = block(LiteralSource, doc="the dipole")
    zones: tuple = blocks(LiteralZone, max_length=2, doc="the near and far zones")
    time: Time = block(Time, doc="sampling and record")
    noise: Noise = block(Noise, required=True, doc="source and measurement noise")
    kf: KFSettings = block(KFSettings, doc="the KF's covariances")
    rls: RLSSettings = block(RLSSettings, doc="the RLS baseline")
    monte_carlo: MonteCarlo = block(MonteCarlo, required=True, doc="runs and seed")


SCHEMA: dict = Config.schema()

_KEYS = ("table_id", "s_no", "zone", "noise_reading", "noise_param", "noise_sigma", "estimator",
         "field_component", "part")
TABLES = {
    "rmse": TableSpec("rmse.csv", _KEYS, ("rmse", "rmse_se", "runs", "field_rms"),
                      reference=("rmse",),
                      join=(("s_no", ("s_no",)), ("part", ("part",))),
                      title="RMSE of the fields (eq 3.42) against the analytic dipole",
                      reference_ids=tuple(TABLE_IDS.values())),
    "claims": claims.TABLE,
}
CLAIMS = ((KF, RLS), (KF, "measurement"), (RLS, "measurement"))
"""The thesis' headline (KF below RLS in every cell), and each filter against the fields
of the raw measured potentials."""
QUOTES = (Quote("relative RMSE (RMSE / field RMS)", "rmse", "rmse / field_rms",
                by="estimator"),)


@dataclass(frozen=True)
class Zone:
    name: str
    r: np.ndarray
    theta: np.ndarray


@dataclass(frozen=True)
class Plan:
    """The zones' grids and the dipole, built once."""

    zones: tuple
    dipole: Dipole


def prepare(config: Config, source: str) -> Plan:
    zones = []
    for i, z in enumerate(config.zones):
        for key in ("r", "theta_deg"):
            check_interval(getattr(z, key), source, f"zones[{i}].{key}")
        if z.name in [other.name for other in zones]:
            raise ConfigError(source, f"zones[{i}].name", f"repeats {z.name!r}")
        zones.append(Zone(z.name, np.linspace(*z.r, z.points_r),
                          np.radians(np.linspace(*z.theta_deg, z.points_theta))))
    s = config.source
    dipole = Dipole(I0=s.I0_dl, dl=1.0, omega=2 * np.pi * s.frequency, c=s.c,
                    mu0=s.mu0)
    for key in ("Q", "P0"):
        if len(getattr(config.kf, key)) != 4:
            raise ConfigError(source, f"kf.{key}", "expected 4 diagonal entries for "
                              "[A, V, Phi, Psi] (eq 5.42)")
    return Plan(tuple(zones), dipole)


@dataclass(frozen=True)
class Point:
    key: tuple[int, int, int]
    zone: int
    reading: str
    level: float
    sigma: float


def sweep(exp: Experiment) -> list[Point]:
    noise = exp.config.noise
    return [Point((z, r, i), z, reading, float(level), signals.noise_sigma(level, reading))
            for z in range(len(exp.plan.zones))
            for r, reading in enumerate(noise.readings)
            for i, level in enumerate(noise.source_levels)]


def work_units(exp: Experiment) -> int:
    return len(sweep(exp))


def work_size(config: Config) -> int:
    t = config.time
    points = sum(z.points_r * z.points_theta for z in config.zones)
    return int(config.monte_carlo.runs * points * 12 * t.samples_per_period
               * t.periods * len(config.noise.source_levels)
               * len(config.noise.readings or ["sigma", "variance"]))


def tiny(config: Config) -> dict:
    """Seconds of work: one noise level and reading, one zone, one period, 3 runs."""
    return {"noise.source_levels": config.noise.source_levels[:1],
            "noise.readings": (config.noise.readings or ["sigma"])[:1],
            "zones": [z.to_spec() for z in config.zones[:1]], "time.periods": 1,
            "monte_carlo.runs": 3}


POTENTIALS = ("A_r", "A_theta", "Phi")


def analytic(dipole: Dipole, zone: Zone, t: np.ndarray) -> dict[str, np.ndarray]:
    """Real and imaginary experiments of every potential, its rate and every field:
    ``(2, nr, ntheta, steps)``, parts in the order (imag, real)."""
    R, TH = np.meshgrid(zone.r, zone.theta, indexing="ij")
    phasors = dipole.phasors(R, TH)
    turn = np.exp(1j * dipole.omega * t)
    out = {}
    for name, F in phasors.items():
        signal = F[..., None] * turn
        rate = 1j * dipole.omega * signal
        out[name] = np.stack([signal.imag, signal.real])
        out[name + "_rate"] = np.stack([rate.imag, rate.real])
    return out


def fields(zone: Zone, mu0: float, A_r, A_theta, Phi, V_r, V_theta) -> dict[str, np.ndarray]:
    """E (eq 5.25) and H (eq 5.27) by finite differences on the ``(r, theta)`` grid (axes
    -3 and -2 of every array; time last)."""
    r = zone.r[:, None, None]
    dPhi_dr = np.gradient(Phi, zone.r, axis=-3)
    dPhi_dth = np.gradient(Phi, zone.theta, axis=-2)
    d_rAth_dr = np.gradient(r * A_theta, zone.r, axis=-3)
    dAr_dth = np.gradient(A_r, zone.theta, axis=-2)
    return {"E_r": -dPhi_dr - V_r, "E_theta": -dPhi_dth / r - V_theta,
            "H_phi": (d_rAth_dr - dAr_dth) / (mu0 * r)}


def kf_per_point(truth: dict, z: np.ndarray, dt: float, settings: KFSettings,
                 measured: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The per-point KF of eqs 5.45-5.47 on every series: ``z`` the measured potentials
    ``(series, steps, 3)``, ``truth`` the analytic potentials and rates ``(series, steps+1, 3)``
    each (the forcing ``Z_k`` and the initial state). Series where ``measured`` is False get
    no measurement: their estimate is the open loop. Returns potentials and rates,
    ``(series, steps, 3)`` each."""
    q, rate = truth["q"], truth["rate"]
    series, steps, _ = z.shape
    F1 = np.array([[1.0, dt], [0.0, 1.0]])
    F = np.kron(np.eye(3), F1)
    x_all = np.stack([q, rate], axis=-1).reshape(series, steps + 1, 6)
    Z = x_all[:, 1:] - x_all[:, :-1] @ F.T           # the analytic solution fits exactly
    Qd, P0d = settings.Q, settings.P0
    Q = np.diag([Qd[0], Qd[1], Qd[0], Qd[1], Qd[2], Qd[3]])
    P0 = np.diag([P0d[0], P0d[1], P0d[0], P0d[1], P0d[2], P0d[3]])
    C = np.kron(np.eye(3), [[1.0, 0.0]])
    kf = KalmanFilter(A=F, B=np.eye(6), C=C, Q=Q, R=as_matrix(settings.R, 3, "R"), P0=P0)
    measured = np.ones(series, bool) if measured is None else np.asarray(measured, bool)
    x_hat = np.empty((series, steps, 6))
    if measured.any():
        x_hat[measured] = kf.run(None, z[measured], Z[measured], dt,
                                 x0=x_all[measured, 0]).x_hat
    if (~measured).any():
        x = x_all[~measured, 0]
        for k in range(steps):
            x = x @ F.T + Z[~measured, k]
            x_hat[~measured, k] = x
    x_hat = x_hat.reshape(series, steps, 3, 2)
    return {"q": x_hat[..., 0], "rate": x_hat[..., 1]}


def sinusoid_rls(z: np.ndarray, t: np.ndarray, omega: float,
                 settings: RLSSettings) -> np.ndarray:
    """The thesis-style RLS baseline of Chapter 5 (its formulation is not printed): the
    project's RLS with fixed forgetting on each series of ``z (series, steps, m)``, its
    regressor two taps of ``cos(omega t)`` (``t`` the ``steps`` sample times) and a bias: a
    sinusoid of the known frequency and an offset. Returns the smoothed series."""
    rls = RecursiveLeastSquares(order=2, forgetting="fixed", lambda0=settings.lambda0,
                                delta=settings.delta)
    return rls.run(None, z, np.cos(omega * t)[:, None]).y_hat


def rls_per_point(z: np.ndarray, t: np.ndarray, omega: float, dt: float,
                  config: Config) -> dict[str, np.ndarray]:
    """:func:`sinusoid_rls` on each measured potential; rates by a backward difference."""
    smooth = sinusoid_rls(z, t[:-1], omega, config.rls)
    return {"q": smooth, "rate": _backward_rate(smooth, dt)}


def _backward_rate(q: np.ndarray, dt: float) -> np.ndarray:
    rate = np.empty_like(q)
    rate[:, 1:] = (q[:, 1:] - q[:, :-1]) / dt
    rate[:, 0] = rate[:, 1]
    return rate


def run_point(exp: Experiment, point: Point) -> tuple[list[dict], list]:
    """Rows of one zone, noise reading and level: every estimator, component and part; and
    per component and part its cell's per-run losses for the claims."""
    config, plan = exp.config, exp.plan
    zone, dipole = plan.zones[point.zone], plan.dipole
    runs = config.monte_carlo.runs
    dt = 1.0 / (config.source.frequency * config.time.samples_per_period)
    steps = config.time.samples_per_period * config.time.periods
    t = np.arange(steps + 1) * dt
    rng = exp.config.monte_carlo.rng(*point.key)
    exact = analytic(dipole, zone, t)
    nr, nth = zone.r.size, zone.theta.size
    shape = (runs, 2, nr, nth)
    # analytic potentials and rates as (series, steps+1, 3), series = runs x parts x points
    q = np.stack([np.broadcast_to(exact[p], shape + (steps + 1,)) for p in POTENTIALS], -1)
    rate = np.stack([np.broadcast_to(exact[p + "_rate"], shape + (steps + 1,))
                     for p in POTENTIALS], -1)
    q, rate = (a.reshape(-1, steps + 1, 3) for a in (q, rate))
    # the source noise enters the rates (T c^2 w, eq 5.42's B^(3)) and accumulates
    c2dt = config.source.c ** 2 * dt
    kick = c2dt * (point.sigma * rng.standard_normal((q.shape[0], steps, 3)))
    drift_rate = np.zeros_like(rate)
    drift_rate[:, 1:] = np.cumsum(kick, axis=1)
    drift_q = np.zeros_like(q)
    drift_q[:, 1:] = dt * np.cumsum(drift_rate[:, :-1], axis=1)
    actual_q = q + drift_q
    z = actual_q[:, 1:] + config.noise.measurement_sigma * rng.standard_normal(
        actual_q[:, 1:].shape)
    estimates = {
        KF: kf_per_point({"q": q, "rate": rate}, z, dt, config.kf),
        RLS: rls_per_point(z, t, dipole.omega, dt, config),
        "measurement": {"q": z, "rate": _backward_rate(z, dt)},
        "exact potentials": {"q": q[:, 1:], "rate": rate[:, 1:]},
    }
    truth_fields = {c: exact[c][..., 1:] for c in COMPONENTS}
    mu0 = config.source.mu0
    rows, losses = [], {}
    for label, est in estimates.items():
        grid = [a.reshape(runs, 2, nr, nth, steps, 3) for a in (est["q"], est["rate"])]
        pot, rt = grid
        got = fields(zone, mu0, pot[..., 0], pot[..., 1], pot[..., 2], rt[..., 0], rt[..., 1])
        for comp in COMPONENTS:
            want = truth_fields[comp]
            for part in PARTS:
                if part == "abs":
                    g, w = np.hypot(got[comp][:, 0], got[comp][:, 1]), np.hypot(want[0], want[1])
                else:
                    i = PARTS.index(part)
                    g, w = got[comp][:, i], want[i]
                err = (g - w).reshape(runs, -1)
                per_run = np.sqrt(np.mean(err**2, axis=1))
                mean, se = metrics.mean_and_se(per_run)
                losses.setdefault((comp, part), {})[label] = claims.Losses(per_run)
                table_id = TABLE_IDS.get((comp, zone.name, label), "")
                rows.append({"table_id": table_id, "zone": zone.name,
                             "noise_reading": point.reading, "noise_param": point.level,
                             "noise_sigma": point.sigma, "estimator": label,
                             "field_component": comp, "part": part, "rmse": mean,
                             "rmse_se": se, "runs": runs,
                             "field_rms": float(np.sqrt(np.mean(np.broadcast_to(w, g.shape[1:])
                                                                ** 2)))})
    where = {"zone": zone.name, "noise_reading": point.reading, "noise_param": point.level}
    return rows, [(claims.cell(**where, field_component=comp, part=part), cell_losses)
                  for (comp, part), cell_losses in losses.items()]


def _run_point_args(args):
    return run_point(*args)


def _s_no(levels: list[float], level: float) -> int:
    return levels.index(level) + 1


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    points = sweep(exp)
    done = map_tasks(_run_point_args, [(exp, p) for p in points], jobs, on_done)
    df = pd.DataFrame([row for part, _ in done for row in part])
    levels = [float(v) for v in exp.config.noise.source_levels]
    df.insert(1, "s_no", [_s_no(levels, v) for v in df["noise_param"]])
    df = df[TABLES["rmse"].columns].reset_index(drop=True)
    table = claims.table([c for _, cells in done for c in cells], CLAIMS, "RMSE")
    return Result(tables={"rmse": df, "claims": table})


def printout(result: Result) -> str:
    df = result.tables["rmse"]
    view = df[df["part"] == "abs"].pivot_table(
        index=["zone", "noise_reading", "noise_param", "field_component"],
        columns="estimator", values="rmse", sort=False)
    return view.to_string(float_format=lambda v: f"{v:.3g}")
