"""The normalised LMS passes of the wavelet method (:class:`estim.estimators.wavelet_lms.
WaveletLMS`, thesis Sec 4.2), compiled with numba.

Each run's passes are sequential (every coefficient updates ``Theta`` for the next), so the
batched numpy form paid numpy's call overhead about ten times per coefficient and pass: 31 of
the 53 s of ``kronecker_table_4_2`` with 5 runs (cProfile). Here each run is one compiled
loop. The arithmetic is the numpy form's, operation for operation, except that the two
inner products are summed in index order, where numpy's matrix product hands them to BLAS,
whose order (and fused multiply-adds) depends on the CPU and the BLAS build: the compiled
result is the same on every machine, and differs from numpy's by rounding (within 1e-12
relative of the numpy form, tests/test_kronecker.py).
"""

from __future__ import annotations

import numpy as np

from estim.numerics.kernels import jit


@jit
def _passes(theta, Ws, Wt, step, epochs):  # pragma: no cover - compiled
    runs, kept, d = Ws.shape
    q = Wt.shape[2]
    e = np.empty(q)
    for r in range(runs):
        th = theta[r]
        for _ in range(epochs):
            for k in range(kept):
                g = Ws[r, k]
                for i in range(q):
                    s = 0.0
                    for j in range(d):
                        s += th[i, j] * g[j]
                    e[i] = Wt[r, k, i] - s
                norm = 0.0
                for j in range(d):
                    norm += g[j] * g[j]
                c = step / (1e-12 + norm)
                for i in range(q):
                    for j in range(d):
                        th[i, j] = th[i, j] + e[i] * (c * g[j])


def lms_passes(Ws: np.ndarray, Wt: np.ndarray, step: float, epochs: int) -> np.ndarray:
    """``Theta (runs, q, d)`` after ``epochs`` normalised-LMS passes over the kept
    coefficients, from zero: for each coefficient ``k`` with regressor ``g = Ws[:, k]`` and
    target ``Wt[:, k]``, ``Theta += step (Wt_k - Theta g) g^T / (1e-12 + g^T g)``."""
    Ws = np.ascontiguousarray(Ws, float)
    Wt = np.ascontiguousarray(Wt, float)
    theta = np.zeros((Ws.shape[0], Wt.shape[2], Ws.shape[2]))
    _passes(theta, Ws, Wt, float(step), int(epochs))
    return theta
