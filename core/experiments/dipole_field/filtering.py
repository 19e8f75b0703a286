"""The field filter's cycle (thesis eqs 5.20-5.32 and the Remark, eqs 5.48-5.49): the
sensors' operators, the ensemble set up once per case, and each step's forecast and
analyses (the field filter, the source-only one, the plain simulation, the printed Euler
run and the amplitude-only fit's basis)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from estim.config.experiment import Experiment
from estim.experiments.dipole_field.config import EULER, FIT, KF, PLAIN, SOURCE_ONLY, Config
from estim.experiments.dipole_field.scoring import EulerRun, amplitude_fit, analytic_cartesian
from estim.fields import etkf
from estim.fields.dipole import Dipole
from estim.util import lazy
from estim.util.memory import reuse_freed_memory

fdtd = lazy.load("estim.fields.fdtd")
grids = lazy.load("estim.fields.grid")
letkf = lazy.load("estim.fields.letkf")
model_error = lazy.load("estim.fields.model_error")


@dataclass(frozen=True)
class Layout:
    """The sensors of a run (grid indices) and their rows of the operators
    (:func:`sensor_operators`)."""

    sensors: np.ndarray
    ops: tuple


@dataclass(frozen=True)
class Plan:
    """The grid, each zone's grid points, the points sensors are drawn from and how many,
    built once; ``fixed``, the one layout of every run when ``sensors.seed`` is given."""

    grid: grids.Grid
    zones: dict
    beta_r: dict
    candidates: np.ndarray
    count: int
    fixed: Layout | None


def draw_layout(grid: grids.Grid, candidates: np.ndarray, count: int,
                rng: np.random.Generator) -> Layout:
    """``count`` sensors drawn without replacement from the grid points ``candidates``."""
    sensors = np.sort(rng.choice(candidates, count, replace=False))
    return Layout(sensors, sensor_operators(grid, sensors))


def layout(config: Config, plan: Plan, run: int) -> Layout:
    """The sensors of Monte Carlo run ``run``: drawn from the run's own generator (key
    ``(run,)`` of ``monte_carlo.seed``, shared by every scenario and noise row of the run,
    so their comparisons stay paired), or the one layout of ``sensors.seed`` when it is
    given. A claim about the filters is then judged over layouts, not on one."""
    if plan.fixed is not None:
        return plan.fixed
    return draw_layout(plan.grid, plan.candidates, plan.count, config.monte_carlo.rng(run))


def amplitude(pair: list[float]) -> complex:
    return pair[0] * np.exp(1j * np.radians(pair[1]))


def observe(grid: grids.Grid, states_before: np.ndarray, states_after: np.ndarray, dt: float,
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


def on_points_used(op) -> tuple:
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
    (:func:`on_points_used`), and the sensors themselves."""
    rows = np.concatenate([sensors + k * grid.size for k in range(3)])
    grad_s = grid.grad[rows]
    curl_z = grid.curl[rows][:, 2 * grid.size:3 * grid.size]
    return on_points_used(grad_s), on_points_used(curl_z), sensors


@dataclass
class Setup:
    """What one run's cycle needs: the simulation, its step, the record's length, the
    sensors, the localisation around them and the observation variances."""

    sim: fdtd.Simulation
    layout: Layout
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


def setup(config: Config, plan: Plan, sensors: Layout) -> Setup:
    grid, src = plan.grid, config.source
    dipole = Dipole(I0=1.0, dl=grid.spacing, omega=2 * np.pi * src.frequency, c=src.c,
                    mu0=src.mu0)
    dt = config.grid.courant * grid.spacing / src.c
    per = int(round(1 / (src.frequency * dt)))
    dt = 1 / (src.frequency * per)                  # whole steps per period
    sim = fdtd.Simulation(grid, dipole, dt, dl=grid.spacing, width=config.grid.source_width,
                     boundary=config.grid.boundary)
    quarter = max(1, per // 4)
    f, so = config.filter, config.source_only
    wavelength = src.c / src.frequency
    where = grid.xyz[sensors.sensors]
    local = letkf.localisation(grid.n, grid.xyz, where, f.block,
                               f.localisation * wavelength)
    sigma2 = config.sensors.measurement_sigma ** 2
    shape = (sensors.sensors.size, 6)
    distances = np.linalg.norm(where, axis=1)
    scale = np.full((2, grid.size), f.field_error)
    if f.field_error_profile == "truncation":
        ph = dipole.phasors(grid.r, grid.theta)
        A_z = ph["A_r"] * np.cos(grid.theta) - ph["A_theta"] * np.sin(grid.theta)
        bins = np.arange(0.0, grid.r.max() + grid.spacing, grid.spacing)
        profile = model_error.truncation_profile(sim, (A_z, ph["Phi"]), bins)
        scale = np.clip(profile, f.field_error, ERROR_CAP)
    amplitude_half_width = f.amplitude_localisation * wavelength
    return Setup(sim=sim, layout=sensors, dipole=dipole, dt=dt, per=per, quarter=quarter,
                  spin=config.time.spinup_periods * per - quarter,
                  record=config.time.periods * per + quarter, local=local,
                  local_half_width=f.localisation * wavelength,
                  amplitude_taper=letkf.gaspari_cohn(distances, amplitude_half_width),
                  amplitude_half_width=amplitude_half_width, source_distances=distances,
                  smoother=model_error.gaussian_smoother(grid.n, f.field_error_length),
                  error_scale=scale,
                  R_field=np.full(shape, sigma2 + f.representation_error ** 2),
                  R_source=np.full(shape, sigma2 + so.representation_error ** 2))


ERROR_CAP = 0.1
"""The truncation profile's per-step error is capped at 10 %: inside the source's own cells
the analytic potentials are not the grid's solution at all."""


def levels(X: np.ndarray) -> np.ndarray:
    """Rows ``[A(t - dt), A(t), Phi(t), A(t + dt), Phi(t + dt)]`` -> leapfrog states
    ``(m, 2, 2, points)`` holding the levels (t, t + dt)."""
    return np.stack([X[:, 1:3], X[:, 3:5]], axis=1)


def rows_of(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """The analysed state of one step: ``A(t - dt)`` from ``before``'s first level and the
    two levels of ``after`` (t, t + dt), ``(m, 5, points)``. ``dA/dt`` at ``t`` is formed
    from this one analysis (D60: before, the first step mixed an un-analysed ``A(t - dt)``
    with analysed levels)."""
    return np.concatenate([before[:, 0, 0][:, None], after[:, 0], after[:, 1]], axis=1)


def fields_of(grid: grids.Grid, mean: np.ndarray, dt: float,
               mu0: float) -> dict[str, np.ndarray]:
    """E and H at ``t`` of an ensemble mean of the rows ``(5, points)`` (:func:`rows_of`)."""
    return fdtd.fields_from(grid, mean[None, 1], mean[None, 2], (mean[None, 3] - mean[None, 0])
                       / (2 * dt), mu0)


def sensor_rows(grid, before, after, dt, mu0, ops) -> np.ndarray:
    """Predicted readings ``(members, sensors, 6)``."""
    o = observe(grid, before, after, dt, mu0, ops)
    return np.concatenate([o["E"], o["H"]], axis=1).transpose(0, 2, 1)


def nis_of(Yp: np.ndarray, innovation: np.ndarray, R: np.ndarray) -> float:
    """Normalised innovation squared per reading, ``d^T S^-1 d / p`` with ``S = R + Yp^T Yp
    / (m - 1)`` (Woodbury: an ``m x m`` solve); 1 for a consistent filter."""
    m = Yp.shape[0]
    Z = Yp.reshape(m, -1)
    d, r = innovation.ravel(), R.ravel()
    Zr = Z / r
    inner = (m - 1) * np.eye(m) + Zr @ Z.T
    v = Zr @ d
    return float((d @ (d / r) - v @ np.linalg.solve(inner, v)) / d.size)


def field_analysis(su: Setup, before: np.ndarray, after: np.ndarray, amps: np.ndarray,
                   y_rows: np.ndarray, Y: np.ndarray, inflation: float) -> tuple:
    """One analysis of the field filter: local ETKF transforms of the field (levels ``t - dt``
    to ``t + dt``, :func:`rows_of`) from the sensors around each cube, and of the source
    amplitude from the sensors around the source. ``after`` (the forecast leapfrog state,
    C-ordered) is analysed in place; of ``A(t - dt)`` only the analysed mean is formed
    (nothing steps from it). Returns the analysed leapfrog state, the amplitudes, the
    analysed ensemble mean of the rows ``(5, points)`` and the forecast's effective rank
    and NIS."""
    Yp, dy = Y - Y.mean(axis=0), y_rows - Y.mean(axis=0)
    rank, nis = letkf.effective_rank(after[:, 0]), nis_of(Yp, dy, su.R_field)
    W = letkf.transforms(Yp, dy, su.R_field, su.local.taper, inflation)
    means = letkf.analyse_levels(after, before[:, 0, 0], su.local, W)
    W0 = letkf.transforms(Yp, dy, su.R_field, su.amplitude_taper[None], inflation)[0]
    amps = amps.mean() + W0 @ (amps - amps.mean())
    return after, amps, means, rank, nis


def source_analysis(su: Setup, before: np.ndarray, after: np.ndarray, amps: np.ndarray,
                    y_rows: np.ndarray, Y: np.ndarray, inflation: float) -> tuple:
    """One analysis of the source-only filter: one global ETKF of the field and the source
    amplitude together, R including the representation error (D60). Its definition, for
    any members; the cycle carries it by its amplitudes (:func:`source_analysis_on_basis`,
    tested equal to this)."""
    m = Y.shape[0]
    rows = rows_of(before, after)
    rank = letkf.effective_rank(after[:, 0])
    nis = nis_of(Y - Y.mean(axis=0), y_rows - Y.mean(axis=0), su.R_source)
    Xs = np.concatenate([rows.reshape(m, -1), amps.real[:, None], amps.imag[:, None]], axis=1)
    Xs = etkf.analysis(Xs, Y.reshape(m, -1), y_rows.ravel(), su.R_source.ravel(), inflation)
    rows = Xs[:, :-2].reshape(rows.shape)
    return levels(rows), Xs[:, -2] + 1j * Xs[:, -1], rows, rank, nis


def source_analysis_on_basis(su: Setup, amps: np.ndarray, basis_now: np.ndarray,
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
    nis = nis_of(Y - Y.mean(axis=0), y_rows - Y.mean(axis=0), su.R_source)
    coef = etkf.analysis(coef, Y.reshape(m, -1), y_rows.ravel(), su.R_source.ravel(),
                         inflation)
    a = coef.mean(axis=0)
    fields = {F: a[0] * basis_fields[F][:1] + a[1] * basis_fields[F][1:] for F in ("E", "H")}
    return coef[:, 0] + 1j * coef[:, 1], fields, rank, nis


def cycle(exp: Experiment, su: Setup, nominal: complex, rng: np.random.Generator,
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
        return cycle_steps(exp, su, nominal, rng, euler)


def cycle_steps(exp: Experiment, su: Setup, nominal: complex, rng: np.random.Generator,
           euler: bool) -> dict:
    reuse_freed_memory()
    config, plan = exp.config, exp.plan
    grid = plan.grid
    sim, dipole, dt = su.sim, su.dipole, su.dt
    fcfg = config.filter
    m, infl = fcfg.members, fcfg.inflation
    sigma_obs = config.sensors.measurement_sigma
    free_amps = np.array([nominal, 1.0, 1.0j])          # plain simulation, the fit's basis
    phasors = dipole.phasors(grid.r, grid.theta)
    omega_dt = dipole.omega * dt
    draws = rng.standard_normal(m) + 1j * rng.standard_normal(m)
    amps = nominal + fcfg.amplitude_spread * draws / np.sqrt(2)
    free = np.zeros((3, 2, 2, grid.size))
    t = 0.0
    for _ in range(su.spin):
        free = sim.step(free, t, free_amps)
        t += dt
    # the members are still the basis runs' combinations (see source_analysis_on_basis)
    field = (amps.real[:, None, None, None] * free[1] + amps.imag[:, None, None, None]
             * free[2])
    amp_field, amp_src = amps.copy(), amps.copy()
    run_euler = EulerRun(sim, nominal) if euler else None
    if run_euler is not None:
        for k in range(su.spin):
            run_euler.step(k * dt)
    traces = {name: [] for name in (KF, SOURCE_ONLY, PLAIN, EULER)}
    basis_traces, basis_sensors, measured, times, health = [], [], [], [], []
    mu0, ops, sensors = dipole.mu0, su.layout.ops, su.layout.sensors
    for step in range(su.record):
        free_next = sim.step(free, t, free_amps)
        field_next = sim.step(field, t, amp_field)
        jitter = model_error.smooth_noise(rng, 2 * m, grid.n, su.smoother)
        field_next = model_error.perturb(field_next, omega_dt, jitter[:m], jitter[m:],
                                         su.error_scale)
        truth = analytic_cartesian(grid, phasors, np.exp(1j * dipole.omega * t), sensors)
        y = truth + sigma_obs * rng.standard_normal(truth.shape)
        y_rows = y.reshape(6, -1).T                      # (sensors, 6)
        Y = sensor_rows(grid, field, field_next, dt, mu0, ops)
        field, amp_field, means, rank_f, nis_f = field_analysis(su, field, field_next,
                                                                amp_field, y_rows, Y, infl)
        traces[KF].append(fields_of(grid, means, dt, mu0))
        basis = observe(grid, free[1:], free_next[1:], dt, mu0)
        basis_y = sensor_rows(grid, free[1:], free_next[1:], dt, mu0, ops)
        amp_src, fields_s, rank_s, nis_s = source_analysis_on_basis(
            su, amp_src, free_next[1:, 0], basis_y, basis, y_rows, infl)
        traces[SOURCE_ONLY].append(fields_s)
        traces[PLAIN].append(observe(grid, free[:1], free_next[:1], dt, mu0))
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
    traces[FIT] = amplitude_fit(measured, basis_sensors, basis_traces)
    return {"traces": traces, "times": np.array(times), "measured": measured,
            "health": health, "phasors": phasors}
