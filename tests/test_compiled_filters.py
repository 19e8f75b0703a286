"""The compiled EKF loop (estim.estimators.ekf_compiled) against the numpy loop it stands in
for, and the compiled matrix exponential against the batched one and scipy's."""

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from estim.estimators import ekf_compiled
from estim.estimators.ekf import ExtendedKalmanFilter
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


def test_a_filter_that_overrides_cycle_keeps_the_numpy_loop():
    """A plugin (or the UKF) that changes the step is never replaced by the compiled EKF."""

    class Shifted(ExtendedKalmanFilter):
        def cycle(self, model, x, P, z, u, dt, Q, R):
            return super().cycle(model, x, P, z, u, dt, Q, R)

    model = MODELS["mosfet_ekv"]()
    ekf = Shifted(Q=1e-4, R=0.01, P0=1e-3)
    assert ekf.compiled_plan(model) is None
    assert ExtendedKalmanFilter(Q=1e-4, R=0.01, P0=1e-3,
                                discretization="radau").compiled_plan(model) is None


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
