"""The compiled Radau integrator (estim.numerics.radau_compiled) against the numpy one it
replaces."""

import numpy as np
import pytest

from estim.models.cco import CrossCoupledOscillator
from estim.models.diffamp_em import DiffAmpEbersMoll
from estim.models.diffamp_exp import DiffAmpExponential
from estim.models.mosfet_ekv import MosfetEKV
from estim.numerics import kernels
from estim.numerics import radau_compiled as compiled
from estim.numerics.simulate import simulate

pytestmark = pytest.mark.skipif(not compiled.AVAILABLE, reason="numba is not installed")

MODELS = [
    (MosfetEKV, {"drain_current": "ekv"}),
    (MosfetEKV, {"drain_current": "weak_inversion", "V_IN": 0.47}),
    (MosfetEKV, {"drain_current": "weak_saturation", "V_IN": 0.435}),
    (DiffAmpEbersMoll, {}),
    (DiffAmpExponential, {}),
]


def batch(model, runs=4, steps=30, dt=1e-5, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(steps + 1) * dt
    bias = np.ones(model.n_inputs) if model.n_inputs == 2 else np.zeros(1)
    wave = 0.01 * np.sin(2 * np.pi * 1000 * t)[:, None] * np.array([1.0, -1.0][:model.n_inputs])
    src = bias + wave[None] + 0.02 * rng.standard_normal((runs, steps + 1, model.n_inputs))
    return model.source_to_input(src, dt), dt


@pytest.mark.parametrize("cls, params", MODELS, ids=lambda v: getattr(v, "__name__", str(v)))
def test_kernel_equals_the_models_drift_and_jacobian(cls, params):
    model = cls(**params)
    kind, P = model.kernel()
    rng = np.random.default_rng(1)
    x0 = model.operating_point()
    for _ in range(5):
        x = x0 + 0.05 * rng.standard_normal(model.n_states)
        u = rng.standard_normal(model.n_inputs) * 0.01 + (1.0 if model.n_inputs == 2 else 0.0)
        f, J = np.empty(model.n_states), np.empty((model.n_states, model.n_states))
        kernels.evaluate(kind, x, u, P, f, J)
        f_ref, J_ref = model.f_and_jacobian(x, u)
        np.testing.assert_allclose(f, f_ref, rtol=1e-12, atol=1e-12 * np.abs(f_ref).max())
        np.testing.assert_allclose(J, J_ref, rtol=1e-12, atol=1e-12 * np.abs(J_ref).max())


@pytest.mark.parametrize("cls, params", MODELS, ids=lambda v: getattr(v, "__name__", str(v)))
def test_compiled_integrator_follows_the_numpy_one(cls, params):
    """The same algorithm step for step: the trajectories agree to rounding."""
    model = cls(**params)
    u, dt = batch(model)
    x0 = model.operating_point(u=u[0, 0]) if model.n_inputs == 2 else model.operating_point()
    fast = simulate(model, x0, u, dt, rtol=1e-6, atol=1e-8, engine="compiled")
    slow = simulate(model, x0, u, dt, rtol=1e-6, atol=1e-8, engine="numpy")
    scale = np.abs(slow).max()
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-11 * scale)


def test_models_without_a_kernel_keep_the_numpy_path():
    model = CrossCoupledOscillator()
    assert model.kernel() is None
    with pytest.raises(ValueError, match="no compiled kernel"):
        simulate(model, model.operating_point(), np.full((1, 2, 1), 5.0), 1e-7,
                 engine="compiled")
    out = simulate(model, model.operating_point(), np.full((1, 2, 1), 5.0), 1e-7)
    assert np.all(np.isfinite(out))


def test_step_underflow_is_reported_not_hidden():
    model = MosfetEKV(drain_current="ekv")
    u = np.full((2, 3, 1), 0.0)
    u[1, 1] = np.nan                 # a run whose input is not a number cannot be integrated
    x0 = model.operating_point()
    out = simulate(model, x0, u, 1e-5, on_failure="nan")
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1, 1:]))


def test_expanded_system_kernel_equals_its_drift():
    """The stacked zeroth/first-order system of the Chapter 2 expansion (integrated where the
    exact propagation is too stiff) has a compiled kernel too."""
    from estim.numerics.expansion import ExpandedSystem, expand

    model = DiffAmpExponential(variant="thesis_printed")
    u_op = np.array([1.0, 1.0])
    system = ExpandedSystem(expand(model, model.operating_point(u=u_op), u_op), model.name)
    kind, P = system.kernel()
    rng = np.random.default_rng(2)
    for _ in range(3):
        x, u = 1e-3 * rng.standard_normal(8), 1e-3 * rng.standard_normal(2)
        f, J = np.empty(8), np.empty((8, 8))
        kernels.evaluate(kind, x, u, P, f, J)
        f_ref, J_ref = system.f_and_jacobian(x, u)
        np.testing.assert_allclose(f, f_ref, rtol=1e-12, atol=1e-12 * np.abs(f_ref).max())
        np.testing.assert_allclose(J, J_ref, rtol=1e-12, atol=1e-12 * np.abs(J_ref).max())


def test_a_read_only_input_reuses_the_integrator_compiled_for_a_writable_one():
    """numba compiles a function anew for every array type it meets, and a read-only array
    is a type of its own; ``compiled.integrate`` hands it writable arrays, so a read-only
    input (the perturbation analysis' source) costs no second compile of the integrator,
    and gives the same states."""
    model = MosfetEKV(drain_current="ekv")
    u, dt = batch(model, runs=2, steps=5)
    x0 = model.operating_point()
    kind, P = model.kernel()
    writable = compiled.integrate(kind, P, x0[None].repeat(2, 0), u, dt, 1e-6, 1e-8, 1e-12,
                                  20, 10_000, False)
    before = list(compiled.integrate_runs.signatures)
    frozen = u.copy()
    frozen.setflags(write=False)
    read_only = compiled.integrate(kind, P, x0[None].repeat(2, 0), frozen, dt, 1e-6, 1e-8,
                                   1e-12, 20, 10_000, False)
    assert list(compiled.integrate_runs.signatures) == before
    np.testing.assert_array_equal(read_only[0], writable[0])
