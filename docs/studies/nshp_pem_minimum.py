"""Where the prediction-error minimum of each 2-D Kalman filter lies (issue 15, D69).

Run from the project folder: ``python docs/studies/nshp_pem_minimum.py`` (about 5 minutes).
On a stationary NSHP field (M = 1, phi = [0.6, 0.3, 0.5, -0.45], 8000 rows of 40 pixels,
unit driving noise, 5 dB additive noise, seed 11) it minimises over phi, by Nelder-Mead from
the truth, the mean squared innovation of

* the reduced filter of eqs 13a-e (``kalman2d.restore``: eq 13b drops the cross-covariance of
  the two past local states), the filter Table I's recursion adapts; and
* the exact filter of the same field (``kalman2d.restore_exact``: the wavefront state of the
  last N + 1 pixels with its full covariance).

and prints each minimiser with the mean squared innovation there and at the truth (the
first 20 rows left out). The rows are narrow so that the exact filter is cheap; the
adaptive recursion itself needs long rows (it restarts at every row), which is why
``adaptive_phi_bias.py`` uses a 40 x 8000 field.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from estim.images import kalman2d, nshp

PHI = np.array([0.6, 0.3, 0.5, -0.45])


def main() -> None:
    rng = np.random.default_rng(11)
    u = nshp.simulate(PHI, 1, rng.standard_normal((8000, 40)))
    u -= u.mean()
    sigma_v2 = u.var() / 10**0.5
    noisy = u + np.sqrt(sigma_v2) * rng.standard_normal(u.shape)

    def power(a: np.ndarray, kind: str) -> float:
        if kind == "exact":
            out = kalman2d.restore_exact(noisy, a, 1, 1.0, sigma_v2)
        else:
            A10, A01, _ = nshp.state_matrices(a, 1)
            out = kalman2d.restore(noisy, A10, A01, 1.0, sigma_v2, 1)
        return float(np.mean(out["innovation"][20:] ** 2))

    print("filter | minimiser of the mean squared innovation | there | at the true phi")
    for kind in ("reduced", "exact"):
        fit = minimize(power, PHI, args=(kind,), method="Nelder-Mead",
                       options={"xatol": 1e-4, "fatol": 1e-7, "maxiter": 600})
        print(kind, np.round(fit.x, 3), round(float(fit.fun), 4), round(power(PHI, kind), 4))


if __name__ == "__main__":
    main()
