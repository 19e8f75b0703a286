"""Chapter 4: the Kronecker-product model, its EKF, the wavelet LMS, the O.U. input."""

import copy

import numpy as np
import pytest
import yaml

from estim.config.loading import parse_data, quick_data
from estim.estimators.kf import KalmanFilter
from estim.estimators.kronecker_ekf import KroneckerEKF
from estim.estimators.wavelet_lms import WaveletLMS, regressors
from estim.experiments import kronecker as analysis
from estim.models.mosfet_darlington import MosfetDarlington
from estim.models.mosfet_ekv import MosfetEKV
from estim.models.mosfet_printed import MosfetPrinted
from estim.numerics import kronecker_form as kronecker
from estim.numerics import opcount, signals

CIRCUIT = {"W_L": 1.0, "R_D": 1e9, "V_IN": 0.5}


def test_kronecker_model_error_is_third_order_and_linear_second_order():
    m = MosfetEKV("completed", **CIRCUIT)
    x = m.operating_point()
    terms = kronecker.from_model(m, x)
    direction = np.array([1.0, 0.3, -0.2, 0.7])
    errors = []
    for a in (0.02, 0.01, 0.005):
        xd = x + a * direction
        full = m.f(xd, [0.0])
        errors.append((np.linalg.norm(full - terms.drift(xd, [0.0])),
                       np.linalg.norm(full - terms.linear_only().drift(xd, [0.0]))))
    errors = np.array(errors)
    orders = np.log2(errors[:-1] / errors[1:])
    assert np.all(np.abs(orders[:, 0] - 3.0) < 0.2), orders
    assert np.all(np.abs(orders[:, 1] - 2.0) < 0.3), orders


@pytest.mark.parametrize("name", ["cco", "mosfet_darlington"])
def test_kronecker_form_of_other_registered_models_is_third_order(name):
    from estim.config import registry

    m = registry.MODELS[name]()
    x, u = m.operating_point(), np.zeros(m.n_inputs)
    terms = kronecker.from_model(m, x, u)
    direction = np.random.default_rng(0).standard_normal(m.n_states)
    errors = [np.linalg.norm(m.f(x + a * direction, u) - terms.drift(x + a * direction, u))
              for a in (4e-3, 2e-3, 1e-3)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - 3.0) < 0.2), orders


def test_kronecker_jacobian_is_the_derivative_of_the_drift():
    m = MosfetEKV("completed", **CIRCUIT)
    terms = kronecker.from_model(m, m.operating_point())
    x = terms.x_op + np.array([0.01, -0.004, 0.002, 0.02])
    u = np.array([3.0])
    h = 1e-7
    numeric = np.stack([(terms.drift(x + h * e, u) - terms.drift(x - h * e, u)) / (2 * h)
                        for e in np.eye(4)], axis=-1)
    assert np.allclose(terms.jacobian(x, u), numeric, rtol=1e-6, atol=1e-6 * np.abs(numeric).max())


def _eq_4_11_to_4_13(s, x, U_T):
    """The quadratic drift of eqs 4.11-4.13 as printed (the v_in, V_IN and noise terms
    left out; the linear term without the extra (I_0/U_T)(W/L), which A1 does not carry)."""
    vG, vB, vS, vD = x
    out = []
    for si in (s["s1"], s["s3"], s["s5"]):
        q7, q8 = si * s["s7"], si * s["s8"]
        out.append(q7 * (vD - vS) - q7 / U_T * vS * vB + q7 / U_T * vD * vB
                   + q7 / (2 * U_T) * (-vD * vS + vS * vD) + q8 * (vG * vD - vG * vS)
                   + q8 * (vB * vS - vB * vD) + q7 / (2 * U_T) * (vS**2 - vD**2))
    return np.array(out)


def test_printed_matrices_match_eqs_4_11_to_4_13_only_with_columns_G_D_S_B():
    m = MosfetPrinted()
    rng = np.random.default_rng(0)
    hits = {}
    for name, order in {"as printed [G,B,S,D]": (0, 1, 2, 3), "[G,D,S,B]": (0, 3, 2, 1)}.items():
        worst = 0.0
        for _ in range(5):
            v = rng.uniform(-0.05, 0.05, 4)          # named values v_G, v_B, v_S, v_D
            x = v[list(order)]                       # the vector in the column order tried
            xx = np.kron(x, x)
            printed = (m.A1 @ x + m.A2 @ xx)[1:] - m.A1[1:, 0] * x[0]   # v_G drive dropped
            wanted = _eq_4_11_to_4_13(m.s, v, m.params.U_T)
            worst = max(worst, np.max(np.abs(printed - wanted)) / np.max(np.abs(wanted)))
        hits[name] = worst
    assert hits["[G,D,S,B]"] < 1e-12
    assert hits["as printed [G,B,S,D]"] > 1e-2


def test_printed_model_is_unstable():
    for w_l in (0.5, 1.0, 5.0):
        m = MosfetPrinted(W_L=w_l)
        lam = np.max(np.linalg.eigvals(m.A1).real)
        assert lam > 0
        assert lam == pytest.approx(m.s["s7"] * (m.s["s1"] - m.s["s3"]), rel=1e-9)


def test_kronecker_ekf_without_quadratic_terms_is_the_kf(oscillator):
    dt = 0.05
    Ad, Bd = oscillator.discrete(dt)
    rng = np.random.default_rng(1)
    z = rng.normal(size=(4, 60, 1))
    u = rng.normal(size=(60, 1))
    common = {"Q": [0.01, 0.02], "R": 0.1, "P0": [1.0, 1.0]}
    ours = KroneckerEKF(**common, order=1).run(oscillator, z, u, dt, x0=np.array([0.3, -0.1]))
    kf = KalmanFilter(A=Ad, B=Bd, C=[[1.0, 0.0]], x0=[0.3, -0.1], **common).run(None, z, u)
    assert np.max(np.abs(ours.x_hat - kf.x_hat)) < 1e-12
    assert np.max(np.abs(ours.P - kf.P)) < 1e-12


def test_ou_input_autocorrelation_is_exponential():
    gamma, dt = 20.0, 0.01
    v = signals.ornstein_uhlenbeck(np.random.default_rng(2), 0.5, gamma, dt, (4000, 400))
    tail = v[:, 200:]                                     # 40 time constants in: stationary
    assert np.var(tail) == pytest.approx(0.25 / (2 * gamma), rel=0.02)
    for lag in (1, 3, 6):
        a, b = tail[:, :-lag].ravel(), tail[:, lag:].ravel()
        rho = np.corrcoef(a, b)[0, 1]
        expected = np.exp(-gamma * lag * dt)
        se = (1 - expected**2) / np.sqrt(tail.shape[0])   # one independent pair per run
        assert abs(rho - expected) < 3 * se


def _synthetic(runs=2, steps=1024):
    dt = 1e-3
    t = np.arange(steps) * dt
    u = (np.sin(2 * np.pi * 7 * t) + 0.5 * np.sin(2 * np.pi * 23 * t + 1))[None, :, None]
    u = np.repeat(u, runs, axis=0)
    theta = np.array([[-0.05, 0.02, 0.01, 0.0, -0.02, 0.05, 0.0],
                      [0.03, -0.08, 0.0, 0.02, 0.01, 0.0, 0.0]])
    x = np.zeros((runs, 2))
    y = []
    for k in range(steps):
        x = x + (theta @ regressors(x, u[:, k])[..., None])[..., 0]
        y.append(x)
    return np.stack(y, 1), u, theta, dt


def test_least_squares_recovers_theta_and_lms_ends_near_it():
    y, u, theta, dt = _synthetic()
    fit = WaveletLMS(band_factor=1e6, epochs=100, step=1.0).identify(y, u, np.zeros(2), dt, 7.0)
    assert np.max(np.abs(fit["least_squares"] - theta)) < 1e-6
    assert np.all(fit["gap"] < 0.01)
    assert np.max(np.abs(fit["lms"] - theta)) < 0.01 * np.max(np.abs(theta))


def _numpy_lms(Ws, Wt, step, epochs):
    """The batched numpy form of the LMS passes (before they were compiled)."""
    theta = np.zeros((Ws.shape[0], Wt.shape[2], Ws.shape[2]))
    for _ in range(epochs):
        for k in range(Ws.shape[1]):
            g = Ws[:, k, :]
            e = Wt[:, k, :] - (theta @ g[..., None])[..., 0]
            norm = 1e-12 + (g[:, None, :] @ g[..., None])[:, 0, 0]
            theta = theta + e[:, :, None] * ((step / norm[:, None]) * g)[:, None, :]
    return theta


@pytest.mark.parametrize("q", [1, 4])
def test_compiled_lms_passes_are_the_numpy_form_to_rounding_and_count_alike(q):
    from estim.estimators.wavelet_lms_compiled import lms_passes

    rng = np.random.default_rng(q)
    d = q + q * (q + 1) // 2 + 2
    Ws, Wt = rng.standard_normal((7, 30, d)), rng.standard_normal((7, 30, q))
    ours, ref = lms_passes(Ws, Wt, 0.5, 20), _numpy_lms(Ws, Wt, 0.5, 20)
    assert np.allclose(ours, ref, rtol=1e-12, atol=1e-14 * np.max(np.abs(ref)))
    assert not np.array_equal(lms_passes(Ws, Wt, 0.5, 19), ours)   # every pass is made
    y, u, _, dt = _synthetic()
    est = WaveletLMS(band_factor=1e6, epochs=3, step=1.0)
    with opcount.counting(runs=y.shape[0]) as tally:
        fit = est.identify(y, u, np.zeros(2), dt, 7.0)
    kept, d2 = round(fit["kept_fraction"] * y.shape[1]), 2 + 3 + u.shape[-1] + 1
    assert tally["LMS"] == 3 * kept * (2 * 2 * d2 + 2 * d2)     # 2 q d + 2 d per coefficient


@pytest.mark.parametrize("step", [2.0, 5.0])
def test_lms_step_above_the_stability_bound_is_refused(step):
    with pytest.raises(ValueError, match="stability bound"):
        WaveletLMS(step=step)


def test_darlington_with_one_stage_is_the_chapter_3_circuit():
    one = MosfetDarlington(stages=1)
    ref = MosfetEKV("completed", **{**CIRCUIT, "R_D": one.params.R_D})
    x = ref.operating_point() + np.array([0.01, 0.002, -0.001, 0.03])
    assert np.allclose(one.f(x, [0.7]), ref.f(x, [0.7]), rtol=1e-12, atol=0)
    assert np.allclose(one.jacobian(x, [0.7]), ref.jacobian(x, [0.7]), rtol=1e-12, atol=0)
    pair = MosfetDarlington()
    assert pair.n_states == 8
    x8 = pair.operating_point()
    assert np.max(np.linalg.eigvals(pair.jacobian(x8, [0.0])).real) < 0


def test_counted_multiplications_grow_as_the_code_does():
    counts = []
    for stages in (1, 2):
        m = MosfetDarlington(stages=stages)
        est = KroneckerEKF(Q=1e-8, R=1e-6, P0=1e-8)
        n = m.n_states
        D = est.discrete(m, 1e-5)
        H = m.h_jacobian(D.terms.x_op)
        x = np.broadcast_to(D.terms.x_op, (3, n)).copy()
        P = np.broadcast_to(1e-8 * np.eye(n), (3, n, n)).copy()
        with opcount.counting(runs=3) as tally:
            est.cycle(D, H, x, P, np.zeros((3, 1)), np.zeros((3, 1)), 1e-8 * np.eye(n),
                      1e-6 * np.eye(1))
        counts.append(tally)
        # A.13: F P F^T is two n x n x n products; the quadratic Jacobian one contraction
        # with the symmetrised F2 (n^3; A2 (I (x) d) + A2 (d (x) I) apart would be 2 n^3)
        assert tally["A.13"] == 2 * n**3
        assert tally["jacobian"] == n**3
    assert counts[1]["total"] > 6 * counts[0]["total"]


def _tiny_table(columns, area):
    spec = yaml.safe_load(open("configs/kronecker_table_4_2.yaml"))
    spec = quick_data(parse_data(copy.deepcopy(spec), "t.yaml", "t", plan=False))
    spec["geometry"]["columns"] = columns
    spec["geometry"]["area_scaled_caps"] = area
    spec["estimators"] = spec["estimators"][:2]
    exp = parse_data(spec, "t.yaml", "t")
    return analysis.run(exp).tables["rmse"]


def test_without_area_scaled_caps_equal_w_over_l_gives_equal_columns():
    cols = [{"w_um": 2, "l_um": 2}, {"w_um": 20, "l_um": 20}]
    df = _tiny_table(cols, False)
    a, b = df[df["w_um"] == 2], df[df["w_um"] == 20]
    assert np.array_equal(a["rmse"].to_numpy(), b["rmse"].to_numpy())
    scaled = _tiny_table(cols, True)
    a, b = scaled[scaled["w_um"] == 2], scaled[scaled["w_um"] == 20]
    assert not np.allclose(a["rmse"].to_numpy(), b["rmse"].to_numpy(), rtol=1e-6)


def test_burden_counts_equal_the_closed_forms_of_what_the_code_does():
    from estim.experiments import burden

    spec = yaml.safe_load(open("configs/kronecker_burden.yaml"))
    spec = quick_data(parse_data(copy.deepcopy(spec), "t.yaml", "t", plan=False))
    result = burden.run(parse_data(spec, "b.yaml", "b"))
    for name in ("burden_ekf", "burden_wt"):
        df = result.tables[name]
        assert (df["counted"] > 0).all()
        assert np.array_equal(df["counted"].to_numpy(), df["ours_value"].to_numpy()), name
    ekf = result.tables["burden_ekf"]
    at4 = ekf[ekf["n_x"] == 4].set_index("row_order")
    # the thesis' A.12 omits the n^3 of F2 (x (x) x): 36 printed, 100 done
    assert at4.loc[1, "printed"] == 36 and at4.loc[1, "counted"] == 100
    slopes = result.tables["slopes"].set_index(["estimator", "quantity"])["slope"]
    assert 2.5 < slopes[("Kronecker EKF", "counted")] < 3.0


def test_the_stored_burden_counts_say_what_the_deviations_say():
    """docs/deviations.md's counted slopes on Tables 4.3/4.4 (2.90 and 1.91) against the
    stored slopes.csv. Its wall-time slopes are measurements of a quiet machine, quoted as
    such and not tested: a fresh `estim reproduce` rewrites them before the tests run, and
    a busy machine moves them (the LMS's went to 3.1 with CI on the other core)."""
    import pandas as pd

    text = " ".join(open("docs/deviations/chapter-4.md").read().split())
    assert "none are quoted here" in text and "against the counted 2.90" in text
    slopes = pd.read_csv("results/kronecker_burden/slopes.csv").set_index(
        ["estimator", "quantity"])["slope"]
    one, lms = "Kronecker EKF", "wavelet LMS (per sample of a block)"
    assert f"{slopes[(one, 'counted')]:.2f}" == "2.90"
    assert f"{slopes[(lms, 'counted')]:.2f}" == "1.91"


def test_claim_passes_refuses_a_wrong_value_naming_key_and_file(tmp_path):
    """The burden config's claim_passes (the LMS passes its claim counts) is a whole number
    of at least 1; anything else is one line naming the file and the key."""
    from click.testing import CliRunner

    from estim.cli.main import main

    spec = yaml.safe_load(open("configs/kronecker_burden.yaml"))
    for bad in (0, "many", 2.5):
        spec["claim_passes"] = bad
        path = tmp_path / "burden.yaml"
        path.write_text(yaml.safe_dump(spec))
        out = CliRunner().invoke(main, ["validate", str(path)])
        assert out.exit_code == 2, out.output
        assert str(path) in out.output and "claim_passes" in out.output, out.output
