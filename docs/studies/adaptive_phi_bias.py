"""Where Table I's recursion settles on stationary synthetic NSHP fields (issue 15, D69).

Run from the project folder: ``python docs/studies/adaptive_phi_bias.py`` (about 2 minutes).
Fields: M = 1, 40 x 8000 pixels, unit driving noise, 5 dB additive noise. The recursion
starts at phi / 2 with the paper's settings (H(0) = I, lambda(0) = 0.95, v(0) = 1), with
Table I's full gradient (kappa and the row above's Sigma_a) and with the approximate one,
and its trace along row 30 is summarised after pixel 4000.

Part 1, four fields from strongly to weakly correlated (seed 11): the trace's mean and its
largest distance from the truth, and the reduced filter's mean squared innovation with phi
fixed at the truth and at the full recursion's mean (the recursion settles where the
reduced filter of eq 13b predicts best, not at the true phi).

Part 2, the strongly correlated field with seeds 11-15: the largest distance from the truth
and the SNR lost against the filter that knows phi, for each gradient.
"""

from __future__ import annotations

import numpy as np

from estim.images import kalman2d, nshp

FIELDS = ([0.6, 0.3, 0.5, -0.45], [0.5, 0.2, 0.3, -0.2], [0.4, 0.1, 0.3, -0.15],
          [0.3, 0.1, 0.2, -0.1])
GRADIENTS = ("full", "approximate")


def field(phi: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    rng = np.random.default_rng(seed)
    u = nshp.simulate(phi, 1, rng.standard_normal((40, 8000)))
    u -= u.mean()
    sigma_v2 = u.var() / 10**0.5
    return u, u + np.sqrt(sigma_v2) * rng.standard_normal(u.shape), sigma_v2


def adapt(noisy: np.ndarray, phi: np.ndarray, sigma_v2: float, gradient: str) -> dict:
    settings = {"H0": 1.0, "lambda0": 0.95, "v0": 1.0, "mu_u": 0.0, "gradient": gradient}
    return kalman2d.restore_adaptive(noisy, 0.5 * phi, 1.0, sigma_v2, 1, settings,
                                     trace_row=30)


def known(noisy: np.ndarray, a: np.ndarray, sigma_v2: float) -> dict:
    A10, A01, _ = nshp.state_matrices(a, 1)
    return kalman2d.restore(noisy, A10, A01, 1.0, sigma_v2, 1)


def snr(u: np.ndarray, estimate: np.ndarray) -> float:
    return float(10 * np.log10(u.var() / np.mean((u - estimate) ** 2)))


def main() -> None:
    print("part 1: true phi | gradient | mean after 4000 | max |phi - true| "
          "| innovation power at true phi, at the full recursion's mean")
    for phi in map(np.array, FIELDS):
        u, noisy, sigma_v2 = field(phi, 11)
        means = {}
        for gradient in GRADIENTS:
            trace = adapt(noisy, phi, sigma_v2, gradient)["trace"][4000:]
            means[gradient] = trace.mean(axis=0)
            print(np.round(phi, 3), gradient, np.round(means[gradient], 3),
                  round(float(np.abs(trace - phi).max()), 3))
        power = [float(np.mean(known(noisy, a, sigma_v2)["innovation"][:, 20:] ** 2))
                 for a in (phi, means["full"])]
        print("   innovation power:", *(round(p, 4) for p in power))
    print("part 2: seed | gradient | max |phi - true| | SNR lost against known phi (dB)")
    phi = np.array(FIELDS[0])
    for seed in range(11, 16):
        u, noisy, sigma_v2 = field(phi, seed)
        reference = snr(u, known(noisy, phi, sigma_v2)["image"])
        for gradient in GRADIENTS:
            out = adapt(noisy, phi, sigma_v2, gradient)
            print(seed, gradient, round(float(np.abs(out["trace"][4000:] - phi).max()), 3),
                  round(reference - snr(u, out["image"]), 3))


if __name__ == "__main__":
    main()
