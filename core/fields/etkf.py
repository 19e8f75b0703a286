"""Ensemble transform Kalman filter analysis (Hunt, Kostelich and Szunyogh 2007, the ETKF
of Bishop et al. 2001 in its symmetric square-root form), for fields too large for a dense
covariance. Conventions as in DAPPER: the ensemble ``E`` has one member per row.

For a forecast ensemble ``E (m, n)`` with mean ``x`` and anomalies ``A = E - x``, predicted
observations ``Y (m, p)`` with mean ``y_f`` and anomalies ``Yp``, an observation ``y`` with
diagonal error variances ``R``:

    Pt^-1 = (m - 1) / infl I + Yp R^-1 Yp^T          (m x m)
    w     = Pt Yp R^-1 (y - y_f)
    T     = [(m - 1) Pt]^{1/2}                       (symmetric square root)
    E_a   = x + (w + T) A                            (row i: x + sum_j (w_j + T_ij) A_j)

For a linear model and observation, an ensemble whose mean and sample covariance equal the
KF's, and no model noise, the analysis mean and covariance equal the KF's exactly
(``tests/test_fields.py`` checks it against a dense KF).
"""

from __future__ import annotations

import numpy as np


def analysis(E: np.ndarray, Y: np.ndarray, y: np.ndarray, R: np.ndarray,
             inflation: float = 1.0) -> np.ndarray:
    """The analysis ensemble ``(m, n)``; ``R`` the diagonal observation variances ``(p,)``."""
    m = E.shape[0]
    x = E.mean(axis=0)
    A = E - x
    yf = Y.mean(axis=0)
    Yp = Y - yf
    C = Yp / R                                   # (m, p): Yp R^-1
    s, V = np.linalg.eigh((m - 1) / inflation * np.eye(m) + C @ Yp.T)
    Pt = (V / s) @ V.T
    w = Pt @ (C @ (y - yf))
    T = (V * np.sqrt((m - 1) / s)) @ V.T
    out = (w[None, :] + T) @ A
    out += x
    return out
