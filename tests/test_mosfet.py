import numpy as np
import pytest

from estim.models.mosfet_ekv import DRAIN_CURRENT_LAWS, MosfetEKV
from estim.numerics.simulate import simulate, simulate_scipy


@pytest.mark.parametrize("law", DRAIN_CURRENT_LAWS)
def test_jacobian_matches_finite_differences(law):
    model = MosfetEKV(drain_current=law)
    x = np.array([[0.43, 0.01, 0.005, 0.4], [0.46, 0.02, 0.01, 0.05]])
    u = np.array([[3.0], [-1.0]])
    eps = 1e-7
    numeric = np.stack([(model.f(x + eps * e, u) - model.f(x - eps * e, u)) / (2 * eps)
                        for e in np.eye(4)], axis=-1)
    J = model.jacobian(x, u)
    assert np.max(np.abs(J - numeric)) <= 1e-6 * np.max(np.abs(J))
    f2, J2 = model.f_and_jacobian(x, u)
    np.testing.assert_array_equal(J2, J)
    np.testing.assert_array_equal(f2, model.f(x, u))


def test_weak_inversion_law_is_eq_3_6():
    m = MosfetEKV(drain_current="weak_inversion", eta=1.3)
    p = m.params
    x = np.array([0.42, 0.02, 0.01, 0.05])
    vG, vB, vS, vD = x
    expected = p.I_0 * p.W_L * np.exp((vG - vB - p.V_T0) / (p.eta * p.U_T)) * (
        np.exp(-(vS - vB) / p.U_T) - np.exp(-(vD - vB) / p.U_T))
    assert m.drain_current(x)[0] == pytest.approx(expected, rel=1e-12)


def test_ekv_law_tends_to_weak_inversion_below_threshold():
    gaps = []
    for vG in (0.3, 0.2, 0.1):
        x = np.array([vG, 0.0, 0.0, 0.2])
        ekv = MosfetEKV(drain_current="ekv").drain_current(x)[0]
        weak = MosfetEKV(drain_current="weak_inversion").drain_current(x)[0]
        gaps.append(abs(ekv / weak - 1))
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] < 1e-3


def test_literal_circuit_drain_is_the_input_high_passed():
    """circuit-facts.md: no DC path; v_D follows v_G = the input high-passed by R_in C_GX."""
    model = MosfetEKV("thesis_literal")
    f, amp, dt, steps = 1000.0, 0.01, 1e-5, 300
    t = np.arange(steps + 1) * dt
    source = (amp * np.sin(2 * np.pi * f * t))[None, :, None]
    states = simulate(model, np.zeros(4), model.source_to_input(source, dt), dt)
    vD = states[0, 100:, 3]
    tau = model.params.R_in * model.params.C_GX
    assert np.ptp(vD) / 2 == pytest.approx(tau * 2 * np.pi * f * amp, rel=0.01)
    assert np.ptp(vD) / 2 == pytest.approx(1.885e-6, rel=0.01)
    np.testing.assert_allclose(states[0, :, :3], states[0, :, 3:4].repeat(3, 1), atol=1e-12)
    assert np.abs(model.drain_current(states[0])[0]).max() < 1e-15


@pytest.mark.parametrize("V_IN, mode", [(0.35, "saturation"), (0.435, "saturation"),
                                        (0.47, "conduction")])
def test_completed_circuit_works_in_weak_inversion_in_the_stated_mode(V_IN, mode):
    model = MosfetEKV(V_IN=V_IN)
    p = model.params
    vG, vB, vS, vD = model.operating_point()
    current = model.drain_current(np.array([vG, vB, vS, vD]))[0]
    assert current / (p.I_0 * p.W_L) < 0.1          # inversion coefficient: weak inversion
    assert vG - vB < p.V_T0
    if mode == "saturation":
        assert vD - vS > 4 * p.U_T
    else:
        assert vD - vS < 2 * p.U_T
    assert current == pytest.approx((p.V_DD - vD) / p.R_D, rel=1e-9)


def test_completed_saturation_stage_amplifies():
    model = MosfetEKV(V_IN=0.435)
    f, amp, dt, steps = 1000.0, 0.001, 1e-5, 400
    t = np.arange(steps + 1) * dt
    source = (amp * np.sin(2 * np.pi * f * t))[None, :, None]
    x0 = model.operating_point()
    vD = simulate(model, x0, model.source_to_input(source, dt), dt)[0, 200:, 3]
    assert np.ptp(vD) / 2 / amp > 5


@pytest.mark.slow
def test_simulator_matches_solve_ivp_radau():
    model = MosfetEKV(V_IN=0.435)
    x0 = model.operating_point()
    dt, steps = 1e-4, 40
    rng = np.random.default_rng(0)
    t = np.arange(steps + 1) * dt
    source = 0.01 * np.sin(2 * np.pi * 1000 * t)[None, :, None] + 0.25 * rng.normal(
        size=(2, steps + 1, 1))
    u = model.source_to_input(source, dt)
    reference = simulate_scipy(model, x0, u, dt, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(simulate(model, x0, u, dt, rtol=1e-8, atol=1e-9), reference,
                               atol=1e-6)
    np.testing.assert_allclose(simulate(model, x0, u, dt, rtol=1e-5, atol=1e-6), reference,
                               atol=1e-4)


def _input_derivative_experiment(**noise):
    import yaml

    from estim.config.loading import parse_data

    spec = yaml.safe_load(open("configs/mosfet_input_derivative.yaml"))
    spec["input"].update(frequencies_hz=[1000], periods=3)
    spec["noise"].update(input_levels=[0.001], **noise)
    spec["monte_carlo"]["runs"] = 4
    return parse_data(spec, "t.yaml", "t")


def test_filter_inputs_the_difference_the_analytic_derivative_and_the_kalman_one():
    """Eq 3.26's dv_in/dt three ways. On the nominal sine, the difference over an interval is
    the midpoint derivative times sinc(w dt / 2), exactly. The circuit's own input is the
    difference of the noisy source, which the filters get when they see it without sensor
    noise. With sensor noise far above the source's own, the Kalman differentiator is
    nearer to the circuit's input than the difference is."""
    from estim.experiments import estimation
    from estim.experiments.estimation.source import filter_input

    exp = _input_derivative_experiment(filters_see="nominal", input_sensor_sigma=0.0)
    data = estimation.simulate_point(exp, 1000.0, 0.001, 4, np.random.default_rng(1))
    x = 2 * np.pi * 1000.0 * data["dt"] / 2
    analytic = filter_input(exp.config.input, data, "analytic", 0.0)
    np.testing.assert_allclose(data["u"][0], analytic[0] * np.sin(x) / x, rtol=1e-9, atol=1e-9)

    exp = _input_derivative_experiment(input_sensor_sigma=0.0)
    data = estimation.simulate_point(exp, 1000.0, 0.001, 4, np.random.default_rng(1))
    circuit = exp.plan.truth.source_to_input(data["source"], data["dt"])
    np.testing.assert_array_equal(filter_input(exp.config.input, data, "difference", 0.0),
                                  circuit)

    exp = _input_derivative_experiment(input_sensor_sigma=0.05)
    data = estimation.simulate_point(exp, 1000.0, 0.001, 4, np.random.default_rng(1))
    circuit = exp.plan.truth.source_to_input(data["source"], data["dt"])
    errors = {how: np.sqrt(np.mean((filter_input(exp.config.input, data, how, 2.0)
                                    - circuit)[:, 10:] ** 2)) for how in ("difference", "kalman")}
    assert errors["kalman"] < 0.5 * errors["difference"], errors


def test_regimes_use_the_conventional_ekv_boundaries():
    """Weak inversion is i_f < 0.1 and saturation v_DS >= U_T (2 sqrt(i_f) + 4): a point at
    i_f = 0.3 (v_P > v_S would have called it weak before, the test read i_f < 0.48) is not
    weak; at i_f = 0.05 it is, saturated only past the EKV saturation voltage."""
    m = MosfetEKV()
    p = m.params

    def state(i_f, v_ds):
        # ln(1 + e^(a/2)) = sqrt(i_f), a = (v_P - v_S)/U_T; bulk at 0, v_S = 0.1
        a = 2 * np.log(np.expm1(np.sqrt(i_f)))
        v_s = 0.1
        v_g = p.eta * (v_s + a * p.U_T) + p.V_T0
        return np.array([v_g, 0.0, v_s, v_s + v_ds])

    assert not m.in_regime("weak_inversion", state(0.3, 0.5), None)
    assert m.in_regime("weak_inversion", state(0.05, 0.5), None)
    v_sat = p.U_T * (2 * np.sqrt(0.05) + 4)
    assert m.in_regime("weak_inversion_saturation", state(0.05, v_sat * 1.01), None)
    assert m.in_regime("weak_inversion_conduction", state(0.05, v_sat * 0.99), None)
