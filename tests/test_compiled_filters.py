"""The compiled EKF loop (estim.estimators.ekf_compiled) against the numpy loop it stands in
for, and the compiled matrix exponential against the batched one and scipy's."""

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from estim.estimators import ekf_compiled
from estim.estimators.ekf import ExtendedKalmanFilter
from estim.estimators.kf import KalmanFilter
from estim.estimators.ukf import UnscentedKalmanFilter
from estim.models.diffamp_em import DiffAmpEbersMoll
from estim.models.diffamp_exp import DiffAmpExponential
from estim.models.mosfet_ekv import MosfetEKV
from estim.numerics import linalg, small_matrices

pytestmark = pytest.mark.skipif(not ekf_compiled.AVAILABLE, reason="numba is not installed")

ROOT = Path(__file__).resolve().parents[1]


def netlist_model():
    from estim.spice import model_class

    cls = model_class(ROOT / "circuits" / "mosfet_ekv.cir", "VIN", "v(d)",
                      name="netlist:test_compiled_filters")
    return cls(vin_bias=0.435)


MODELS = {
    "mosfet_ekv": lambda: MosfetEKV(V_IN=0.435, drain_current="ekv"),
    "mosfet_weak_saturation": lambda: MosfetEKV(V_IN=0.435, drain_current="weak_saturation"),
    "diffamp_em": DiffAmpEbersMoll,
    "diffamp_exp": DiffAmpExponential,
    "netlist": netlist_model,
}


def problem(model, runs=6, steps=60, dt=1e-4, sigma=0.05, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(steps + 1) * dt
    p = model.n_inputs
    bias = np.ones(p) if p == 2 else np.zeros(p)
    src = bias + 0.01 * np.sin(2 * np.pi * 1000 * t)[:, None] * np.array([1.0, -1.0][:p])
    u = model.source_to_input(src, dt)
    x0 = model.operating_point(u=u[0]) if p == 2 else model.operating_point()
    z = model.h(x0)[None, None, :] + sigma * rng.standard_normal((runs, steps, 1))
    return x0, z, u, dt


def both(ekf, model, z, u, dt, x0, monkeypatch):
    """The filter's estimate through the compiled loop, then through the numpy loop."""
    assert ekf.compiled_plan(model) is not None
    fast = ekf.run(model, z, u, dt, x0)
    with monkeypatch.context() as patch:
        patch.setattr(ExtendedKalmanFilter, "compiled_plan", lambda *args, **kwargs: None)
        slow = ekf.run(model, z, u, dt, x0)
    return fast, slow


def assert_same(fast, slow, rtol):
    np.testing.assert_array_equal(fast.broken, slow.broken)
    assert set(fast.diagnostics) == set(slow.diagnostics)
    for key in ("broken_step", "broken_state", "broken_cause"):     # why each run broke
        if key in slow.diagnostics:
            np.testing.assert_array_equal(fast.diagnostics[key], slow.diagnostics[key], key)
    for name in ("x_hat", "P", "S", "innovation", "y_hat"):
        a, b = getattr(fast, name), getattr(slow, name)
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=name)
        if np.isnan(b).all():
            continue
        scale = np.nanmax(np.abs(b))
        np.testing.assert_allclose(a, b, rtol=0, atol=rtol * scale, err_msg=name, equal_nan=True)


CASES = [(name, disc, sub) for name in MODELS
         for disc, sub in [("exponential", 1), ("exponential", 3), ("rosenbrock", 1),
                           ("euler", 800)]
         if not (name.startswith("diffamp") and disc == "exponential" and sub > 1)]
"""Every model and discretisation; substeps of the exponential on the MOSFET models (on the
differential pair, see the note below, two correct exponentials already differ by 3e-5 there)."""


@pytest.mark.parametrize("name, discretization, substeps", CASES)
def test_compiled_ekf_follows_the_numpy_loop(name, discretization, substeps, monkeypatch):
    """Every model with a kernel and an affine output, every discretisation the compiled
    loop takes: the estimates, covariances and innovations agree to rounding."""
    model = MODELS[name]()
    x0, z, u, dt = problem(model)
    n = model.n_states
    ekf = ExtendedKalmanFilter(Q=[1e-4] * n, R=0.01, P0=[1e-3] * n,
                               discretization=discretization, substeps=substeps)
    fast, slow = both(ekf, model, z, u, dt, x0, monkeypatch)
    stiff = name.startswith("diffamp") and discretization == "exponential"
    assert_same(fast, slow, 1e-6 if stiff else 1e-9)
    if name.startswith("diffamp") and discretization == "euler":
        assert fast.broken.all()      # ||T J|| ~ 2e9: forward Euler breaks at once, in both
    else:
        assert np.isfinite(fast.x_hat).all()


# The differential pair's parasitic capacitance gives ||T J|| ~ 2e9: the exponential
# is squared ~29 times, which multiplies the Pade step's rounding by ~5e8, so two correct
# exponentials differ in the 8th digit there (linalg.expm against scipy's: 3e-8). With substeps
# the next substep's drift is taken at that state and the filter magnifies it further: the numpy
# loop with scipy's exponential instead of linalg.expm moves x_hat by 3e-5.

def test_a_broken_run_is_broken_at_the_same_step_in_both_loops(monkeypatch):
    """A run whose estimate leaves the filter's bound is frozen from the same step in both
    loops, and the other runs go on."""
    model = MODELS["mosfet_ekv"]()
    x0, z, u, dt = problem(model, runs=4)
    z[1, 20:] += 50.0                          # one run's measurements jump far away
    ekf = ExtendedKalmanFilter(Q=[1e-4] * 4, R=0.01, P0=[1e-3] * 4, divergence_bound=5.0)
    fast, slow = both(ekf, model, z, u, dt, x0, monkeypatch)
    assert fast.broken.tolist() == [False, True, False, False]
    first = np.flatnonzero(np.isnan(fast.x_hat[1, :, 0]))[0]
    assert first == 20
    assert_same(fast, slow, 1e-9)
    why = fast.diagnostics
    assert why["broken_step"].tolist() == [-1, 20, -1, -1]
    assert why["broken_cause"][1] == "estimate beyond the bound"
    assert abs(fast.x_hat[1, 19, why["broken_state"][1]]) <= 5.0   # a state the bound stopped


def test_a_filter_that_overrides_cycle_keeps_the_numpy_loop():
    """A plugin (or the UKF) that changes the step is never replaced by the compiled EKF."""

    class Shifted(ExtendedKalmanFilter):
        def cycle(self, model, x, P, z, u, dt, Q, R):
            return super().cycle(model, x, P, z, u, dt, Q, R)

    class Unscented(UnscentedKalmanFilter):
        def cycle(self, model, x, P, z, u, dt, Q, R):
            return super().cycle(model, x, P, z, u, dt, Q, R)

    model = MODELS["mosfet_ekv"]()
    ekf = Shifted(Q=1e-4, R=0.01, P0=1e-3)
    assert ekf.compiled_plan(model) is None
    assert Unscented(Q=1e-4, R=0.01, P0=1e-3).compiled_plan(model) is None
    assert UnscentedKalmanFilter(Q=1e-4, R=0.01, P0=1e-3).compiled_plan(model) is not None
    assert ExtendedKalmanFilter(Q=1e-4, R=0.01, P0=1e-3,
                                discretization="radau").compiled_plan(model) is None


def kf_both(kf, z, u, monkeypatch):
    """The KF's estimate through the compiled loop, then through the numpy loop."""
    assert kf.compiled()
    fast = kf.run(None, z, u)
    with monkeypatch.context() as patch:
        patch.setattr(KalmanFilter, "compiled", lambda self: False)
        slow = kf.run(None, z, u)
    return fast, slow


def test_compiled_kf_follows_the_numpy_loop(monkeypatch):
    """A 3-state, 2-output, 2-input system with inputs that differ per run: both loops
    agree to rounding, and the estimate is the closed-form one-step KF of eqs A.1-A.7 at
    the first step."""
    rng = np.random.default_rng(11)
    A = np.array([[0.9, 0.1, 0.0], [-0.1, 0.9, 0.05], [0.0, 0.02, 0.7]])
    B = rng.normal(size=(3, 2))
    C = rng.normal(size=(2, 3))
    Q = np.diag([1e-3, 2e-3, 5e-4])
    R = np.array([[0.04, 0.01], [0.01, 0.09]])
    P0 = np.eye(3)
    z = rng.normal(size=(5, 200, 2))
    u = rng.normal(size=(5, 200, 2))
    kf = KalmanFilter(A=A.tolist(), B=B.tolist(), C=C.tolist(), Q=Q.tolist(), R=R.tolist(),
                      P0=P0.tolist(), x0=[0.1, -0.2, 0.3])
    fast, slow = kf_both(kf, z, u, monkeypatch)
    assert_same(fast, slow, 1e-12)
    assert not fast.broken.any()
    x = A @ [0.1, -0.2, 0.3] + B @ u[2, 0]
    P = A @ P0 @ A.T + Q
    K = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    np.testing.assert_allclose(fast.x_hat[2, 0], x + K @ (z[2, 0] - C @ x), rtol=1e-12)
    np.testing.assert_allclose(fast.P[2, 0], (np.eye(3) - K @ C) @ P, rtol=1e-10, atol=1e-14)


def test_a_kf_run_that_overflows_is_broken_from_the_same_step_in_both_loops(monkeypatch):
    """A very unstable A: the run whose measurement jumps to 1e300 at step 5 follows it, and
    its next prediction (1e10 times that) overflows; both loops mark it broken with NaN
    from that step on, and the other runs go on."""
    z = np.zeros((3, 40, 1))
    z[1, 5:] = 1e300
    kf = KalmanFilter(A=[[1e10]], B=[[0.0]], C=[[1.0]], Q=1.0, R=1.0, P0=1.0, x0=[0.0])
    fast, slow = kf_both(kf, z, np.zeros((40, 1)), monkeypatch)
    assert fast.broken.tolist() == [False, True, False]
    assert np.flatnonzero(np.isnan(fast.x_hat[1, :, 0]))[0] == 6
    assert np.isfinite(fast.x_hat[[0, 2]]).all()
    assert_same(fast, slow, 1e-12)


def test_kf_runs_share_one_covariance_and_blocks_of_runs_keep_each_run_its_own():
    """70 runs (the compiled loop's blocks of 32, and a last one of 6), then run 40
    overflowing at step 6: every run's estimate is the one it gets filtered alone, bit for
    bit; ``P`` and ``S`` are one read-only copy the runs share while no run breaks, and each
    run's own (NaN from its break on) when one does."""
    rng = np.random.default_rng(3)
    A = np.array([[1.2, 0.1], [-0.1, 0.9]])
    kf = KalmanFilter(A=A.tolist(), B=[[1.0], [0.5]], C=[[1.0, 0.0]], Q=[[1e-3, 0], [0, 1e-3]],
                      R=0.04, P0=1.0)
    z, u = rng.normal(size=(70, 30, 1)), rng.normal(size=(70, 30, 1))
    together = kf.run(None, z, u)
    assert not together.P.flags.writeable and together.P.strides[0] == 0
    for r in (0, 31, 32, 63, 64, 69):
        alone = kf.run(None, z[r:r + 1], u[r:r + 1])
        assert alone.x_hat.tobytes() == together.x_hat[r:r + 1].tobytes()
        assert alone.P.tobytes() == together.P[r:r + 1].tobytes()
    steep = KalmanFilter(A=[[1e10, 0.0], [0.0, 0.9]], B=[[0.0], [0.0]], C=[[1.0, 0.0]],
                         Q=[[1.0, 0], [0, 1.0]], R=1.0, P0=1.0)
    z[40, 5:] = 1e300                  # followed at step 5, its prediction at 6 overflows
    broken = steep.run(None, z, u)
    assert broken.broken.tolist() == [r == 40 for r in range(70)]
    assert np.isnan(broken.P[40, 6:]).all() and np.isfinite(broken.P[40, :6]).all()
    assert np.isfinite(broken.P[41]).all()
    assert broken.x_hat[41].tobytes() == steep.run(None, z[41:42], u[41:42]).x_hat.tobytes()


@pytest.mark.parametrize("scale", [1e-3, 1.0, 30.0, 1e4])
def test_compiled_expm_equals_the_batched_one_and_scipy(scale):
    """Matrices that need no squaring and ones that need many: the compiled exponential
    takes the same scaling as :func:`estim.numerics.linalg.expm`, so the two agree to rounding,
    and both agree with scipy."""
    rng = np.random.default_rng(7)
    work = np.empty((6, 5, 5))
    out = np.empty((5, 5))
    for _ in range(5):
        A = scale * (0.3 * rng.standard_normal((5, 5)) - 2 * np.eye(5))
        small_matrices.expm_into(A, out, work)
        ours = linalg.expm(A)
        ref = scipy.linalg.expm(A)
        size = np.abs(ref).max()
        np.testing.assert_allclose(out, ours, rtol=0, atol=1e-12 * size)
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-9 * size)


def test_compiled_expm_of_a_non_finite_matrix_is_nan():
    A = np.eye(3)
    A[1, 2] = np.inf
    out = np.zeros((3, 3))
    small_matrices.expm_into(A, out, np.empty((6, 3, 3)))
    assert np.all(np.isnan(out))


UKF_CASES = [(name, disc) for name in ("mosfet_ekv", "mosfet_weak_saturation", "netlist",
                                       "diffamp_em")
             for disc in ("exponential", "rosenbrock")]


@pytest.mark.parametrize("name, discretization", UKF_CASES)
def test_compiled_ukf_follows_the_numpy_loop(name, discretization, monkeypatch):
    """The UKF through its compiled loop and through the numpy one agree to rounding, with
    a small spread (alpha 1e-3, whose weights of -1e6 and 1.25e5 cancel: both loops' sums
    are rounded at 1e6 times the state) and with the default alpha = 1 (0.1 on the
    differential pair, as its configs give it: at 1 its sigma points leave the junctions'
    range, where exp(T J) has a norm of 1e47 and neither loop gives a usable prediction)."""
    model = MODELS[name]()
    x0, z, u, dt = problem(model)
    n = model.n_states
    pair = name.startswith("diffamp")
    for alpha in (1e-3, 0.1 if pair else 1.0):
        ukf = UnscentedKalmanFilter(Q=[1e-4] * n, R=0.01, P0=[1e-3] * n, alpha=alpha,
                                    discretization=discretization)
        assert ukf.compiled_plan(model) is not None
        fast = ukf.run(model, z, u, dt, x0)
        with monkeypatch.context() as patch:
            patch.setattr(UnscentedKalmanFilter, "compiled_plan", lambda *args: None)
            slow = ukf.run(model, z, u, dt, x0)
        assert_same(fast, slow, 1e-6 if pair or alpha < 0.1 else 1e-9)
        assert not fast.broken.any()


def test_the_compiled_square_root_falls_back_to_the_symmetric_root():
    """A positive definite P gets its Cholesky factor; a semidefinite one (a zero variance,
    a rank-one matrix) the symmetric root with its negative rounding clipped: L L^T = P."""
    from estim.estimators import ukf_compiled
    from estim.estimators.ukf import sqrt_psd

    rng = np.random.default_rng(2)
    M = rng.normal(size=(4, 4))
    v = rng.normal(size=4)
    for P in (M @ M.T + np.eye(4), np.diag([1.0, 0.0, 2.0, 3.0]), np.outer(v, v)):
        L = np.empty((4, 4))
        ukf_compiled.sqrt_psd(P, L)
        np.testing.assert_allclose(L @ L.T, P, atol=1e-12 * np.abs(P).max())
        ours = sqrt_psd(P[None])[0]
        np.testing.assert_allclose(L @ L.T, ours @ ours.T, atol=1e-12 * np.abs(P).max())
    L = np.empty((4, 4))
    ukf_compiled.sqrt_psd(M @ M.T + np.eye(4), L)
    np.testing.assert_allclose(L, np.linalg.cholesky(M @ M.T + np.eye(4)), rtol=1e-13)


def test_a_kf_makes_its_matrices_once_and_leaves_the_callers_arrays_alone(oscillator):
    """The matrices are made and the covariances checked once per filter (a run of one
    Monte Carlo run is otherwise mostly that), as read-only copies: the arrays given stay
    the caller's and writable; the sizes against a model are still checked at every run."""
    A = np.array([[0.9]])
    kf = KalmanFilter(A=A, B=[[0.0]], C=[[1.0]], Q=1e-3, R=0.1, P0=1.0)
    assert kf.matrices() is kf.matrices() and A.flags.writeable
    assert not kf.matrices()[0].flags.writeable and kf.matrices()[0] is not A
    kf.run(None, np.zeros((1, 5, 1)), np.zeros((5, 1)))
    for _ in range(2):
        with pytest.raises(ValueError, match="A: 1 rows, but the model"):
            kf.run(oscillator, np.zeros((1, 5, 1)), np.zeros((5, 1)), 0.1)
