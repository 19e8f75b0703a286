"""Chapter 5: sparse field operators and time steppers."""

import numpy as np
import pandas as pd
import pytest
import yaml

from estim.fields import operators as ops


def _grid(n, length=1.0):
    spacing = length / (n + 1)
    x = spacing * np.arange(1, n + 1)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    return spacing, X, Y, Z


def test_laplacian_converges_at_second_order():
    errors = []
    for n in (15, 31, 63):
        h, X, Y, Z = _grid(n)
        u = np.sin(np.pi * X) * np.sin(2 * np.pi * Y) * np.sin(np.pi * Z)
        exact = -(np.pi**2) * (1 + 4 + 1) * u
        got = ops.laplacian(n, h) @ u.ravel()
        errors.append(np.max(np.abs(got - exact.ravel())))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - 2.0) < 0.1), orders


def test_div_curl_and_curl_grad_vanish():
    n, h = 9, 0.1
    rng = np.random.default_rng(0)
    vector, scalar = rng.standard_normal(3 * n**3), rng.standard_normal(n**3)
    scale = 1 / (2 * h) ** 2        # two centred differences; the random values are O(1)
    assert np.max(np.abs(ops.divergence(n, h) @ (ops.curl(n, h) @ vector))) < 1e-12 * scale
    assert np.max(np.abs(ops.curl(n, h) @ (ops.gradient(n, h) @ scalar))) < 1e-12 * scale


def _highest_mode(n):
    """The Dirichlet eigenvector of the 7-point Laplacian with the largest |eigenvalue|."""
    h, X, Y, Z = _grid(n)
    k = n * np.pi
    return h, (np.sin(k * X) * np.sin(k * Y) * np.sin(k * Z)).ravel()


def _growth(method, courant, n=12):
    """Spectral radius of one step on the highest mode: the 2 x 2 map the stepper applies
    to (mode amplitude, its rate), read off the real stepper."""
    from estim.fields import wave

    h, mode = _highest_mode(n)
    L = ops.laplacian(n, h)
    dt = courant * h
    columns = []
    for u, v in ((mode, 0 * mode), (0 * mode, mode)):
        u1, v1 = wave.step(u, v, L.dot, 1.0, dt, method=method)
        columns.append([u1 @ mode / (mode @ mode), v1 @ mode / (mode @ mode)])
    return float(np.max(np.abs(np.linalg.eigvals(np.array(columns).T))))


def test_leapfrog_is_stable_below_the_courant_limit_and_not_above():
    assert _growth("leapfrog", 0.57) <= 1 + 1e-12
    assert _growth("leapfrog", 0.60) > 1.001


@pytest.mark.parametrize("courant", [0.05, 0.3, 0.57])
def test_forward_euler_grows_at_every_step_size(courant):
    assert _growth("euler", courant) > 1.0


def test_dipole_fields_follow_from_its_potentials():
    from estim.fields.dipole import Dipole

    d = Dipole()
    r, th, h = np.array([0.11, 0.4, 2.3]), np.array([0.7, 1.2, 2.0]), 1e-6
    f = d.phasors(r, th)
    dr = {k: (d.phasors(r + h, th)[k] - d.phasors(r - h, th)[k]) / (2 * h) for k in f}
    dth = {k: (d.phasors(r, th + h)[k] - d.phasors(r, th - h)[k]) / (2 * h) for k in f}
    jw = 1j * d.omega
    E_r = -dr["Phi"] - jw * f["A_r"]
    E_th = -dth["Phi"] / r - jw * f["A_theta"]
    H_phi = ((f["A_theta"] + r * dr["A_theta"]) - dth["A_r"]) / (r * d.mu0)
    for got, want in ((E_r, f["E_r"]), (E_th, f["E_theta"]), (H_phi, f["H_phi"])):
        np.testing.assert_allclose(got, want, rtol=1e-6)
    far = d.phasors(np.array([200.0]), np.array([np.pi / 2]))
    assert abs(far["E_theta"][0]) / abs(far["H_phi"][0]) == pytest.approx(d.eta, rel=1e-4)


def _literal_batch(series=4, steps=60, seed=0):
    from estim.fields.dipole import Dipole

    d = Dipole()
    dt = 1 / 50
    t = np.arange(steps + 1) * dt
    r = np.linspace(0.5, 0.8, series)
    f = d.phasors(r, np.full(series, 1.0))
    turn = np.exp(1j * d.omega * t)
    q = np.stack([(f[p][:, None] * turn).real for p in ("A_r", "A_theta", "Phi")], -1)
    rate = np.stack([(1j * d.omega * f[p][:, None] * turn).real
                     for p in ("A_r", "A_theta", "Phi")], -1)
    z = q[:, 1:] + 0.1 * np.random.default_rng(seed).standard_normal(q[:, 1:].shape)
    from estim.experiments.dipole import KFSettings

    kf = KFSettings(Q=[1e-4, 1e-3, 1e-4, 1e-2], R=0.01, P0=[1e-4] * 4)
    return {"q": q, "rate": rate}, z, dt, kf


def test_literal_unmeasured_points_are_the_open_loop():
    from estim.experiments.dipole import kf_per_point

    truth, z, dt, spec = _literal_batch()
    measured = np.array([True, False, True, False])
    out = kf_per_point(truth, z, dt, spec, measured=measured)
    # the open loop with the analytic forcing reproduces the analytic potentials
    np.testing.assert_allclose(out["q"][~measured], truth["q"][~measured, 1:], atol=1e-12)
    np.testing.assert_allclose(out["rate"][~measured], truth["rate"][~measured, 1:],
                               atol=1e-12)
    assert np.max(np.abs(out["q"][measured] - truth["q"][measured, 1:])) > 1e-4


def test_literal_kf_smooths_the_measured_potentials():
    from estim.experiments.dipole import kf_per_point

    truth, z, dt, spec = _literal_batch(series=8, steps=200)
    out = kf_per_point(truth, z, dt, spec)
    raw = np.sqrt(np.mean((z - truth["q"][:, 1:]) ** 2))
    filtered = np.sqrt(np.mean((out["q"] - truth["q"][:, 1:]) ** 2))
    assert filtered < 0.5 * raw


def _plain_floor(n, boundary="mur", length=4.0, periods=5):
    """Relative RMS error of the plain simulation's E against the analytic dipole over its
    last period, in a near shell (0.25-0.45 wavelengths) and a far one (1.2-1.8)."""
    from estim.fields.dipole import Dipole
    from estim.fields.fdtd import Grid, Simulation, fields_from, spherical

    g = Grid(n, length / n)
    d = Dipole(dl=g.spacing)
    dt = 0.5 * g.spacing / d.c
    sim = Simulation(g, d, dt, dl=g.spacing, width=0.7, boundary=boundary)
    state = np.zeros((1, 2, 2, g.size))
    per = int(round(1 / dt))
    ph = d.phasors(g.r, g.theta)
    shells = {"near": (0.25, 0.45), "far": (1.2, 1.8)}
    acc = {k: [0.0, 0.0] for k in shells}
    t = 0.0
    for k in range(periods * per):
        new = sim.step(state, t, np.array([1.0]))
        if k >= (periods - 1) * per:
            f = fields_from(g, state[:, 1, 0], state[:, 1, 1],
                            (new[:, 1, 0] - state[:, 0, 0]) / (2 * dt), d.mu0)
            E = spherical(g, f["E"])
            turn = np.exp(1j * d.omega * t)
            for name, (r1, r2) in shells.items():
                m = (g.r >= r1) & (g.r <= r2) & (np.abs(np.cos(g.theta)) < np.cos(np.pi / 6))
                want_r, want_t = (ph["E_r"][m] * turn).real, (ph["E_theta"][m] * turn).real
                acc[name][0] += np.sum((E["r"][0, m] - want_r) ** 2
                                       + (E["theta"][0, m] - want_t) ** 2)
                acc[name][1] += np.sum(want_r**2 + want_t**2)
        state, t = new, t + dt
    return {k: np.sqrt(a / b) for k, (a, b) in acc.items()}


def test_plain_simulation_error_shrinks_with_the_grid_and_mur_beats_a_dirichlet_box():
    coarse, fine = _plain_floor(16), _plain_floor(32)
    for zone in ("near", "far"):
        assert fine[zone] < 0.6 * coarse[zone], (coarse, fine)
    assert _plain_floor(32, "dirichlet")["far"] > 3 * fine["far"]


def test_etkf_equals_the_kalman_filter_on_a_linear_model_with_an_exact_ensemble():
    from estim.fields import etkf

    rng = np.random.default_rng(7)
    n, p, m = 12, 5, 6                       # rank of P0: m - 1 = 5 directions
    F = np.eye(n) + 0.05 * rng.standard_normal((n, n))
    H = rng.standard_normal((p, n))
    R = np.full(p, 0.3)
    B = rng.standard_normal((n, m - 1))
    # an ensemble with exactly the mean x0 and the covariance B B^T
    Z = rng.standard_normal((m, m - 1))
    Z -= Z.mean(axis=0)
    U, _, Vt = np.linalg.svd(Z, full_matrices=False)
    Z = U @ Vt * np.sqrt(m - 1)              # Z^T Z = (m - 1) I, columns of zero mean
    x0 = rng.standard_normal(n)
    E = x0 + Z @ B.T
    x, P = x0.copy(), B @ B.T
    for _ in range(5):
        E, x, P = E @ F.T, F @ x, F @ P @ F.T
        y = H @ x + rng.standard_normal(p)
        E = etkf.analysis(E, E @ H.T, y, R)
        S = H @ P @ H.T + np.diag(R)
        K = P @ H.T @ np.linalg.inv(S)
        x, P = x + K @ (y - H @ x), (np.eye(n) - K @ H) @ P
    np.testing.assert_allclose(E.mean(axis=0), x, atol=1e-9)
    np.testing.assert_allclose(np.cov(E.T), P, atol=1e-9)


def test_with_the_wrong_source_the_field_filter_cuts_the_open_loop_error():
    from estim.config.loading import parse_data
    from estim.experiments import dipole_field

    spec = yaml.safe_load(open("configs/dipole_field.yaml"))
    spec.pop("check", None)
    spec.update(grid={"n": 20, "length": 3.0}, time={"spinup_periods": 3, "periods": 1},
                zones=[{"name": "near", "r": [0.3, 0.55]}, {"name": "far", "r": [0.9, 1.3]}],
                scenarios=[{"name": "wrong source", "nominal_amplitude": [0.7, 20.0]}])
    spec["sensors"].update(r=[0.3, 1.3], fraction=0.05)
    spec["filter"]["members"] = 20
    spec["noise"]["source_levels"] = [0.00025]
    spec["monte_carlo"]["runs"] = 1
    rows, _, figure, _ = dipole_field.run_point(parse_data(spec, "t.yaml", "t"), (0, 0, 0))
    rows = pd.DataFrame(rows)
    assert {"E|truth", "H|KF error"} <= set(figure)
    rel = rows.pivot_table(index=["zone", "field_component"], columns="estimator",
                           values="relative")
    for comp in ("E_theta", "H_phi"):
        for zone in ("near", "far"):
            assert rel.loc[(zone, comp), "KF"] < 0.5 * rel.loc[(zone, comp), "plain simulation"]


@pytest.mark.slow
def test_field_etkf_equals_a_dense_kalman_filter_on_an_8_cube():
    """The ensemble filter's plumbing on the real field model (N = 8, 2050 states): the
    members differ only in their source amplitude, so the covariance has rank 2 and the
    ensemble represents it exactly; a dense KF on the same linear model, started from the
    ensemble's mean and covariance, must give the same analysis mean."""
    from estim.experiments.dipole_field.filtering import observe, sensor_operators
    from estim.fields import etkf
    from estim.fields.dipole import Dipole
    from estim.fields.fdtd import Grid, Simulation

    g = Grid(8, 0.25)
    d = Dipole(dl=g.spacing)
    dt = 0.5 * g.spacing
    sim = Simulation(g, d, dt, dl=g.spacing, width=0.7)
    rng = np.random.default_rng(3)
    sensors = np.sort(rng.choice(g.size, 12, replace=False))
    ops = sensor_operators(g, sensors)
    m = 6
    amps = 0.8 + 0.3 * (rng.standard_normal(m) + 1j * rng.standard_normal(m))
    ens = np.zeros((m, 2, 2, g.size))
    size = ens[0].size

    def vec(states, a):                  # members -> rows [field state, Re a, Im a]
        return np.concatenate([states.reshape(len(a), -1), a.real[:, None], a.imag[:, None]],
                              axis=1)

    def step_rows(X, t):                 # the linear one-step map applied to rows
        a = X[:, -2] + 1j * X[:, -1]
        return vec(sim.step(X[:, :-2].reshape(-1, 2, 2, g.size), t, a), a)

    def observe_rows(X_before, X_after):
        before = X_before[:, :-2].reshape(-1, 2, 2, g.size)
        after = X_after[:, :-2].reshape(-1, 2, 2, g.size)
        o = observe(g, before, after, dt, d.mu0, ops)
        return np.concatenate([o["E"], o["H"]], axis=1).reshape(len(X_before), -1)

    X = vec(ens, amps)
    x = X.mean(axis=0)
    P = np.cov(X.T)
    eye = np.eye(size + 2)
    R = np.full(6 * sensors.size, 1e-4)
    t = 0.0
    for k in range(12):
        X_next = step_rows(X, t)
        F = step_rows(eye, t).T                                # column j: image of e_j
        x_next = F @ x
        if k >= 8:                                             # analyses on the last 4 steps
            H1 = observe_rows(eye, np.zeros_like(eye)).T        # the part from x
            H2 = observe_rows(np.zeros_like(eye), eye).T        # the part from x_next
            y = H1 @ x + H2 @ x_next + 0.01 * rng.standard_normal(H1.shape[0])
            X_next = etkf.analysis(X_next, observe_rows(X, X_next), y, R)
            # dense KF on the joint [x, x_next]: y = H1 x + H2 x_next + noise
            C_next_y = F @ P @ H1.T + F @ P @ F.T @ H2.T
            S = (H1 @ P @ H1.T + H1 @ P @ F.T @ H2.T + H2 @ F @ P @ H1.T
                 + H2 @ F @ P @ F.T @ H2.T + np.diag(R))
            K = C_next_y @ np.linalg.inv(S)
            P_next = F @ P @ F.T - K @ C_next_y.T
            x_next = x_next + K @ (y - H1 @ x - H2 @ x_next)
        else:
            P_next = F @ P @ F.T
        X, x, P = X_next, x_next, 0.5 * (P_next + P_next.T)
        t += dt
    scale = np.max(np.abs(x))
    np.testing.assert_allclose(X.mean(axis=0), x, atol=1e-8 * scale)
