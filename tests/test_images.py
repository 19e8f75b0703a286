"""The 2-D sister papers: the NSHP image model, its identification and the 2-D Kalman filter."""

import numpy as np
import pytest

from estim.images import kalman2d, nshp, wavefront

A_TRUE = np.array([0.6, 0.3, 0.5, -0.45])        # M = 1: (0,1), (1,-1), (1,0), (1,1)


def noisy_field(seed: int, shape: tuple[int, int], sigma_v2: float = 4.0):
    """A field of ``A_TRUE`` (unit driving noise) and it with white noise of ``sigma_v2``."""
    rng = np.random.default_rng(seed)
    u = nshp.simulate(A_TRUE, 1, rng.standard_normal(shape))
    return u, u + np.sqrt(sigma_v2) * rng.standard_normal(u.shape), sigma_v2


@pytest.mark.parametrize("M", [1, 2, 3])
def test_eq_1_and_the_state_space_form_give_the_same_field(M):
    rng = np.random.default_rng(M)
    a = 0.05 * rng.standard_normal(2 * M * M + 2 * M)
    e = rng.standard_normal((15, 4 * M + 7))
    field = nshp.simulate(a, M, e)
    np.testing.assert_allclose(nshp.simulate_state_space(a, M, e), field, atol=1e-12)
    assert np.abs(field).max() > 0.5


def test_the_printed_block_8b_is_wrong_for_every_block_but_the_second():
    """Eq 8b puts a_{2,-M} in every block i = 2..M; the model needs a_{i,-M}: block i of
    A01's first row holds exactly the coefficient of u(m - i, n + M)."""
    M = 3
    a = np.arange(1, 2 * M * M + 2 * M + 1, dtype=float)
    _, A01, _ = nshp.state_matrices(a, M)
    coeff = dict(zip(nshp.window(M), a, strict=True))
    for i in range(2, M + 1):
        column = (M + 1) + (i - 2) * (2 * M + 1) + M
        assert A01[0, column] == coeff[(i, -M)]
    assert coeff[(3, -M)] != coeff[(2, -M)]          # so the printed a_{2,-M} is wrong at i = 3


def test_noise_corrected_yule_walker_recovers_a_synthetic_field():
    rng = np.random.default_rng(11)
    u = nshp.simulate(A_TRUE, 1, rng.standard_normal((300, 300)))
    u -= u.mean()
    sigma_v2 = u.var() / 10**0.5                     # 5 dB
    noisy = u + np.sqrt(sigma_v2) * rng.standard_normal(u.shape)
    a, sigma_e2 = nshp.yule_walker(noisy, 1, sigma_v2)
    assert np.max(np.abs(a - A_TRUE)) < 0.05, a
    assert sigma_e2 == pytest.approx(1.0, rel=0.15)


def test_the_filter_with_the_true_model_restores_a_synthetic_field_to_its_error_variance():
    """With the model that made the field, the filter halves the noise's mean square error
    away from the image's edges."""
    u, noisy, sigma_v2 = noisy_field(5, (200, 200))
    A10, A01, _ = nshp.state_matrices(A_TRUE, 1)
    out = kalman2d.restore(noisy, A10, A01, 1.0, sigma_v2, 1)
    inner = (slice(20, None), slice(20, -20))
    mse = np.mean((out["image"] - u)[inner] ** 2)
    assert mse < 0.5 * sigma_v2
    assert np.all(np.isfinite(out["P_norm"])) and np.all(out["K_norm"] > 0)
    z, s = out["innovation"][inner], out["innovation_variance"][inner]
    assert np.mean(z**2 / s) == pytest.approx(1.0, abs=0.05)      # NIS of a consistent filter
    assert abs(np.corrcoef(z[:, 1:].ravel(), z[:, :-1].ravel())[0, 1]) < 0.1


def test_non_adaptive_filter_improves_camera_at_5_db():
    from skimage import data

    img = data.camera().astype(float)[:128, :128]
    u = img - img.mean()
    sigma_v2 = u.var() / 10**0.5
    noisy = u + np.sqrt(sigma_v2) * np.random.default_rng(0).standard_normal(u.shape)
    a, sigma_e2 = nshp.yule_walker(noisy, 1, sigma_v2)
    A10, A01, _ = nshp.state_matrices(a, 1)
    out = kalman2d.restore(noisy, A10, A01, sigma_e2, sigma_v2, 1)["image"]
    assert np.mean((out - u) ** 2) < 0.5 * np.mean((noisy - u) ** 2)


def test_adaptive_identification_moves_to_the_truth_and_matches_the_known_model_filter():
    """Started at half the true parameters on a long stationary field, Table I's recursion
    (full gradient; paper settings H(0) = I, lambda(0) = 0.95) comes within 0.15 of them and
    its filter's SNR is within 0.3 dB of the filter that knows them, on this field (seed
    11). Neither holds with margin everywhere: over seeds 11-15 the distance is 0.054-0.118
    and the SNR loss 0.10-0.45 dB (D69). It does not come within 0.05: the recursion
    minimises the prediction error of the reduced filter of eq 13b, whose minimum is 0.12
    from the truth (docs/studies/nshp_pem_minimum.py; the exact filter's is within 0.005,
    and Table I through it stays within 0.05: next test)."""
    rng = np.random.default_rng(11)
    u = nshp.simulate(A_TRUE, 1, rng.standard_normal((40, 8000)))
    u -= u.mean()
    sigma_v2 = u.var() / 10**0.5
    noisy = u + np.sqrt(sigma_v2) * rng.standard_normal(u.shape)

    def snr(est):
        return 10 * np.log10(u.var() / np.mean((u - est) ** 2))

    A10, A01, _ = nshp.state_matrices(A_TRUE, 1)
    known = snr(kalman2d.restore(noisy, A10, A01, 1.0, sigma_v2, 1)["image"])
    settings = {"H0": 1.0, "lambda0": 0.95, "v0": 1.0, "mu_u": 0.0, "gradient": "full"}
    out = kalman2d.restore_adaptive(noisy, 0.5 * A_TRUE, 1.0, sigma_v2, 1, settings,
                                    trace_row=30)
    start = np.abs(0.5 * A_TRUE - A_TRUE).max()
    assert np.abs(out["trace"][4000:] - A_TRUE).max() < min(0.15, start / 2)
    assert abs(snr(out["image"]) - known) < 0.3


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_table_i_through_the_exact_filter_identifies_phi_within_0_05(seed):
    """The issue's line: on a stationary synthetic field the identified phi stays within
    0.05 of the truth (here over the second half of the pixels, from a start at phi / 2)
    and the adaptive filter's SNR is within 0.3 dB of the filter that knows phi. It holds
    for Table I's recursion when its filter keeps the cross-covariance (the exact
    wavefront filter); through eq 13b's reduced filter it cannot (previous test, D69)."""
    rng = np.random.default_rng(seed)
    u = nshp.simulate(A_TRUE, 1, rng.standard_normal((3000, 20)))
    u -= u.mean()
    sigma_v2 = u.var() / 10**0.5
    noisy = u + np.sqrt(sigma_v2) * rng.standard_normal(u.shape)
    out = wavefront.restore_adaptive_exact(noisy, 0.5 * A_TRUE, 1, 1.0, sigma_v2,
                                          {"H0": 1.0, "lambda0": 0.95, "v0": 1.0})
    half = out["trace"][out["trace"].shape[0] // 2:]
    assert np.abs(half - A_TRUE).max() < 0.05
    known = wavefront.restore_exact(noisy, A_TRUE, 1, 1.0, sigma_v2)["image"]

    def snr(est):
        return 10 * np.log10(u.var() / np.mean((u - est) ** 2))

    assert abs(snr(out["image"]) - snr(known)) < 0.3
    held = wavefront.restore_adaptive_exact(noisy, A_TRUE, 1, 1.0, sigma_v2,
                                           {"H0": 1.0, "lambda0": 0.95, "v0": 1e-300})
    np.testing.assert_allclose(held["image"], known, atol=1e-12)


def test_table_i_sensitivities_are_the_derivatives_of_the_restored_image():
    """With phi held (v(0) ~ 0), the recursion's Sigma_a (eqs 21a, 22a with kappa of 22b)
    is d(restored pixel)/dphi of the non-adaptive filter, by central differences, at every
    pixel; leaving out kappa and the row above's Sigma_a is not."""
    rng = np.random.default_rng(2)
    noisy = nshp.simulate(A_TRUE, 1, rng.standard_normal((12, 30))) + 1.5 * rng.standard_normal(
        (12, 30))
    held = {"H0": 1.0, "lambda0": 0.95, "v0": 1e-300, "mu_u": 0.0}

    def restored(a):
        A10, A01, _ = nshp.state_matrices(a, 1)
        return kalman2d.restore(noisy, A10, A01, 1.0, 2.25, 1, boundary_variance=2.0)["image"]

    h = 1e-6
    fd = np.stack([(restored(A_TRUE + h * e) - restored(A_TRUE - h * e)) / (2 * h)
                   for e in np.eye(4)], axis=-1)
    for gradient, close in (("full", True), ("approximate", False)):
        out = kalman2d.restore_adaptive(noisy, A_TRUE, 1.0, 2.25, 1,
                                        {**held, "gradient": gradient}, boundary_variance=2.0)
        np.testing.assert_array_equal(out["image"], restored(A_TRUE))
        assert (np.abs(out["sensitivity"] - fd).max() < 1e-7) == close


def test_vector_yule_walker_recovers_a_vector_ar_1():
    from estim.images import strip

    rng = np.random.default_rng(4)
    W = 4
    phi = 0.5 * np.eye(W) + 0.1 * rng.standard_normal((W, W))
    L = np.linalg.cholesky(0.5 * np.eye(W) + 0.3 * np.ones((W, W)))
    Z = np.zeros((W, 40_000))
    for k in range(1, Z.shape[1]):
        Z[:, k] = phi.T @ Z[:, k - 1] + L @ rng.standard_normal(W)
    est, Q, _ = strip.yule_walker(Z, 1)
    assert np.abs(est[0] - phi).max() < 0.02
    assert np.abs(Q - L @ L.T).max() < 0.02


def test_eqs_36_equal_a_standard_kalman_filter_on_the_synchronised_model():
    """The composite model of eq 22 with a blur state, filtered by eqs 36a-f, gives the same
    image estimates as an ordinary Kalman filter on [x1(k); x2(k)], the synchronised model
    the paper says would not give "true filtered" estimates."""
    from estim.images import strip

    rng = np.random.default_rng(8)
    W, P, n2 = 3, 2, 2
    phi = 0.3 * rng.standard_normal((P, W, W))
    A1, B1, C1 = strip.companion(phi)
    Q = np.eye(W) + 0.2 * np.ones((W, W))
    A2 = 0.4 * rng.standard_normal((n2, n2))
    B2, C2, D2 = (rng.standard_normal(s) for s in ((n2, W), (W, n2), (W, W)))
    sigma_v2, steps = 0.5, 40
    n1 = A1.shape[0]
    Y = rng.standard_normal((steps, W))
    P0 = np.eye(n1 + n2)
    ours = strip.filter_36(Y, A1, B1, C1, Q, A2, B2, C2, D2, sigma_v2, P0)
    # synchronised: w(k) = [x1(k); x2(k)], w(k) = F w(k-1) + G U(k), Y(k) = Cbar w(k) + V(k)
    F = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1, A2]])
    GQG = np.zeros((n1 + n2, n1 + n2))
    GQG[:n1, :n1] = B1 @ Q @ B1.T
    Cbar = np.hstack([D2 @ C1, C2])
    # the same prior: eqs 36 start from [x1(-1); x2(0)] ~ (0, P0); here w(-1) = [x1(-1);
    # x2(-1)] with x2(0) = A2 x2(-1) + B2 C1 x1(-1), so w(-1)'s prior is chosen to give P0
    M = np.block([[np.eye(n1), np.zeros((n1, n2))], [B2 @ C1, A2]])
    P = np.linalg.solve(M, np.linalg.solve(M, P0).T).T
    w = np.zeros(n1 + n2)
    expected = []
    for k in range(steps):
        w, P = F @ w, F @ P @ F.T + GQG
        S = Cbar @ P @ Cbar.T + sigma_v2 * np.eye(W)
        K = P @ Cbar.T @ np.linalg.inv(S)
        w, P = w + K @ (Y[k] - Cbar @ w), P - K @ S @ K.T
        expected.append(C1 @ w[:n1])
    np.testing.assert_allclose(ours, np.array(expected), atol=1e-10)


def test_strip_filter_with_noise_taken_off_improves_camera_at_5_db():
    from skimage import data

    from estim.images import strip

    img = data.camera().astype(float)[:128, :256]
    u = img - img.mean()
    sigma_v2 = u.var() / 10**0.5
    noisy = u + np.sqrt(sigma_v2) * np.random.default_rng(0).standard_normal(u.shape)
    out = strip.restore(noisy, 8, 1, sigma_v2)
    assert out["unstable_strips"] == 0
    assert np.mean((out["image"] - u) ** 2) < 0.5 * np.mean((noisy - u) ** 2)


def test_online_identification_is_the_batch_solution_of_the_columns_so_far():
    """Eq 15's recursion of the covariances is exact: the model used at the last column is
    the batch vector Yule-Walker solution of all the columns before it."""
    from estim.images import strip

    rng = np.random.default_rng(2)
    Z = rng.standard_normal((3, 4, 60)).cumsum(axis=-1) * 0.1 + rng.standard_normal((3, 4, 60))
    phi, Q, rho0 = strip.online_models(Z, 2, 0.3, True, 1e-3)
    ref = strip.yule_walker(Z[..., :59], 2, 0.3, True, 1e-3)
    for ours, batch in zip((phi[:, -1], Q[:, -1], rho0[:, -1]), ref, strict=True):
        np.testing.assert_allclose(ours, batch, rtol=1e-9, atol=1e-12)


def test_eq_17_is_only_first_order():
    """Eq 17 is the first-order Neumann term, not the (exact) inversion lemma: its error
    falls as the square of the update, quartering when the update halves."""
    from estim.images import strip

    rng = np.random.default_rng(6)
    A = rng.standard_normal((6, 6))
    T = A @ A.T + 6 * np.eye(6)
    dT = rng.standard_normal((6, 6))
    dT = 0.05 * (dT + dT.T)
    errors = [np.abs(strip.neumann_inverse(T, T + h * dT, np.linalg.inv(T))
                     - np.linalg.inv(T + h * dT)).max() for h in (1.0, 0.5)]
    assert errors[0] > 1e-8
    assert 3.5 < errors[0] / errors[1] < 4.5


@pytest.mark.parametrize("M", [1, 2])
def test_the_exact_filter_is_the_conditional_mean_of_the_field(M):
    """``restore_exact`` gives E[u(k) | y(1..k)] computed from the field's joint Gaussian law
    (u = L e, pixel by pixel in raster order) to rounding."""
    rows, cols = 5, 6
    rng = np.random.default_rng(M)
    a = A_TRUE if M == 1 else 0.05 * rng.standard_normal(2 * M * M + 2 * M)
    n = rows * cols
    L = np.column_stack([nshp.simulate(a, M, np.eye(n)[k].reshape(rows, cols)).ravel()
                         for k in range(n)])
    sigma_e2, sigma_v2 = 1.3, 0.7
    Cu = sigma_e2 * L @ L.T
    y = (nshp.simulate(a, M, np.sqrt(sigma_e2) * rng.standard_normal((rows, cols)))
         + np.sqrt(sigma_v2) * rng.standard_normal((rows, cols))).ravel()
    ref = [Cu[k, :k + 1] @ np.linalg.solve(Cu[:k + 1, :k + 1] + sigma_v2 * np.eye(k + 1),
                                           y[:k + 1]) for k in range(n)]
    out = wavefront.restore_exact(y.reshape(rows, cols), a, M, sigma_e2, sigma_v2)
    np.testing.assert_allclose(out["image"].ravel(), ref, atol=1e-12)


def test_the_reduced_filter_of_eq_13b_predicts_worse_than_the_exact_filter():
    """Eq 13b's dropped cross-covariance costs prediction power: on a stationary field the
    exact filter's innovations are smaller, and its estimate closer to the field."""
    u, noisy, sigma_v2 = noisy_field(4, (400, 30))
    A10, A01, _ = nshp.state_matrices(A_TRUE, 1)
    reduced = kalman2d.restore(noisy, A10, A01, 1.0, sigma_v2, 1)
    exact = wavefront.restore_exact(noisy, A_TRUE, 1, 1.0, sigma_v2)
    rows = slice(20, None)
    assert np.mean(exact["innovation"][rows] ** 2) < 0.99 * np.mean(
        reduced["innovation"][rows] ** 2)
    assert np.mean((exact["image"] - u)[rows] ** 2) < np.mean((reduced["image"] - u)[rows] ** 2)


# ----- docs/deviations.md D69-D70: the numbers quoted, against results/image_kalman ----------

def _image_table():
    from pathlib import Path

    import pandas as pd

    root = Path(__file__).resolve().parents[1]
    doc = (root / "docs" / "deviations" / "papers.md").read_text()
    snr = pd.read_csv(root / "results" / "image_kalman" / "snr.csv")
    return doc, snr.set_index(["image", "estimator"])


def _rounds_to(value: float, quoted: str) -> bool:
    digits = len(quoted.split(".")[1]) if "." in quoted else 0
    return abs(value - float(quoted)) <= 0.5 * 10 ** -digits + 1e-12


def test_d69_table_is_the_stored_table():
    """D69's table: SNR (and SSIM where given) of every stored column, by image."""
    doc, snr = _image_table()
    d69 = doc[doc.index("**D69."):doc.index("**D70.")]
    assert "mean of 10 runs" in d69
    assert set(snr["runs"]) == {10}
    stored = ("NSHP Kalman", "NSHP Kalman, adaptive", None, "Wiener, noise given",
              "Wiener, noise estimated", "wavelet (BayesShrink)")
    rows = [r for r in d69.splitlines() if r.strip().startswith(("| camera", "| moon",
                                                                 "| brick"))]
    assert len(rows) == 3
    for row in rows:
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        for estimator, cell in zip(stored, cells[1:], strict=True):
            if estimator is None:
                continue
            parts = [p.replace("dB", "").replace("SSIM", "").split("±")[0].strip()
                     for p in cell.split(",")]
            value = snr.loc[(cells[0], estimator)]
            assert _rounds_to(value["snr_db"], parts[0]), (row, estimator)
            if len(parts) > 1:
                assert _rounds_to(value["ssim"], parts[1]), (row, estimator)


def test_d70_strip_results_are_the_stored_ones():
    doc, snr = _image_table()
    d70 = doc[doc.index("- Results (5 dB, 10 runs)"):]
    d70 = d70[:d70.index("`unstable_strips`")]
    quoted = {"strip Kalman": ("13.3", "12.4", "12.0"),
              "strip Kalman, online model (eq 15)": ("12.7", "11.6", "11.3"),
              "strip Kalman, model from clean image": ("13.8", "12.8", "12.3")}
    text = " ".join(d70.split())
    assert "camera 13.3 dB (SSIM 0.45), moon 12.4, brick 12.0" in text
    assert "on line 12.7, 11.6, 11.3; from the clean image 13.8, 12.8, 12.3" in text
    for estimator, values in quoted.items():
        for image, text in zip(("camera", "moon", "brick"), values, strict=True):
            assert _rounds_to(snr.loc[(image, estimator), "snr_db"], text), (estimator, image)
    assert _rounds_to(snr.loc[("camera", "strip Kalman"), "ssim"], "0.45")
    assert _rounds_to(snr.loc[("brick", "strip Kalman"), "ssim"], "0.81")
