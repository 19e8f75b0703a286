"""Recursive least squares with a variable forgetting factor (thesis eqs 1.12-1.17).

RLS estimates the measured output as a linear function of a regressor built from the
known input: ``phi_k = [1, u_{k-1}, ..., u_{k-M}]`` in thesis indexing (the leading 1 when
``bias``; see :meth:`RecursiveLeastSquares.regressors` for array indexing), with the
noisy measurement ``z_k`` as the desired signal ``d_k`` (eq 1.12). Per step, batched:

    zeta_k   = d_k - phi_k^T W_{k-1}                       (1.13, a priori error)
    K_k      = P_{k-1} phi_k / (1 + phi_k^T P_{k-1} phi_k)      (1.14)
    W_k      = W_{k-1} + K_k zeta_k                         (1.15)
    lambda_k = 1 - (1 - phi_k^T K_k) |zeta_k|^2 / chi       (1.16), clipped to
               [lambda_min, 1]
    P_k      = (P_{k-1} - K_k phi_k^T P_{k-1}) / lambda_k   (1.17)

This is the variable-forgetting RLS of Fortescue, Kershenbaum and Ydstie (1981), the form
the thesis prints: the forgetting enters ``P`` after the update (1.17), so the gain's
denominator is ``1 + phi^T P phi`` as printed. Fixes to the printed form
(docs/thesis-notes.md, note 17): ``W_{k-1}`` in 1.13, ``M`` taps in both the weights and the
regressor, and ``lambda_k`` bounded to ``[lambda_min, 1]``. The regressor is the filter's
input ``u`` (for the MOSFET, the slope of the nominal source on each interval). The estimate
is the a posteriori output ``phi_k^T W_k``; the residual is ``zeta_k``.

Eq 1.16 computes every ``lambda_k`` from that step's error, so an initial forgetting factor
has no role in it: ``lambda0`` is the constant factor of ``forgetting: fixed``
(``lambda_k = lambda0``, exponentially weighted RLS) and is refused with
``forgetting: variable`` (earlier versions accepted it there and ignored it).

``p_max`` (not in the thesis; a variant) bounds the covariance: when ``trace P_k`` exceeds
it, ``P_k`` is scaled down to trace ``p_max``. Under a regressor that excites only some
directions, eq 1.17 divides the unexcited part of ``P`` by ``lambda_k < 1`` at every step
and it grows without bound.

Diagnostics (per run): ``regressor_rank``, the rank of the regressors once the tap line has
filled (rows ``k >= M``: the directions the input excites persistently) out of
``regressor_size``; ``lambda_at_floor``, the fraction of steps where eq 1.16 fell to
``lambda_min`` or below; ``p_max_eig``, the largest eigenvalue of ``P`` at the end.
"""

from __future__ import annotations

import numpy as np

from estim.config.settings import boolean, integer, number, setting, settings_class, text
from estim.errors import SettingError
from estim.estimators.base import Estimate, Estimator, batch_input


@settings_class
class RecursiveLeastSquares(Estimator, name="rls"):
    """RLS-VFF output estimator; see the module docstring for the recursion."""

    order: int = setting(10, integer(1, 200), doc="M, input taps in the regressor")
    chi: float = setting(1.0, number(positive=True, maximum=1e12), unit="output^2",
                         doc="eq 1.16's chi: the error power that sets the forgetting")
    forgetting: str = setting("variable", text({"variable", "fixed"}),
                              doc="variable: eq 1.16 per step; fixed: lambda_k = lambda0")
    lambda0: float | None = setting(None, number(positive=True, maximum=1.0),
                                    doc="the constant forgetting factor of forgetting: fixed")
    lambda_min: float = setting(0.9, number(positive=True, maximum=1.0),
                                doc="lower bound of eq 1.16's lambda_k")
    delta: float = setting(100.0, number(positive=True, maximum=1e12),
                           doc="P(0) = delta I")
    bias: bool = setting(True, boolean, doc="a constant 1 in the regressor")
    p_max: float | None = setting(None, number(positive=True, maximum=1e300),
                                  doc="bound on trace P (a variant; none: unbounded)")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.forgetting == "variable" and self.lambda0 is not None:
            raise ValueError("lambda0 is the constant factor of forgetting: fixed; with "
                             "forgetting: variable eq 1.16 computes every lambda_k from its "
                             "step's error and lambda0 would have no effect")
        if self.forgetting == "fixed" and self.lambda0 is None:
            raise SettingError("forgetting", "fixed needs lambda0")

    @classmethod
    def example(cls, model) -> RecursiveLeastSquares:
        return cls(order=3)

    def regressors(self, u: np.ndarray) -> np.ndarray:
        """``(runs, steps, q)`` regressors: row ``k`` is ``[1, u[k], u[k-1], ..., u[k-M+1]]``.

        ``u[k]`` is the input on the interval that ends at measurement ``z[k]`` (the thesis'
        ``u_{k-1}``); inputs before the first interval are zero.
        """
        runs, steps, p = u.shape
        padded = np.concatenate([np.zeros((runs, self.order - 1, p)), u], axis=1)
        taps = [padded[:, self.order - 1 - j: self.order - 1 - j + steps, :]
                for j in range(self.order)]
        phi = np.concatenate(taps, axis=-1)
        if self.bias:
            phi = np.concatenate([np.ones((runs, steps, 1)), phi], axis=-1)
        return phi

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float | None = None,
            x0: np.ndarray | None = None) -> Estimate:
        runs, steps, m = z.shape
        phi = self.regressors(batch_input(u, runs))
        q = phi.shape[-1]
        W = np.zeros((runs, q, m))
        P = np.broadcast_to(self.delta * np.eye(q), (runs, q, q)).copy()
        floor = np.zeros(runs)
        y_hat = np.empty((runs, steps, m))
        innovation = np.empty((runs, steps, m))
        for k in range(steps):
            ph = phi[:, k, :]
            zeta = z[:, k, :] - np.einsum("rq,rqm->rm", ph, W)
            Pph = np.einsum("rab,rb->ra", P, ph)
            denom = 1.0 + np.einsum("ra,ra->r", ph, Pph)
            K = Pph / denom[:, None]
            W = W + K[:, :, None] * zeta[:, None, :]
            if self.forgetting == "fixed":
                lam = np.full(runs, self.lambda0)
            else:
                gain = np.einsum("ra,ra->r", ph, K)
                raw = 1.0 - (1.0 - gain) * np.sum(zeta**2, axis=1) / self.chi
                lam = np.clip(raw, self.lambda_min, 1.0)
                floor += raw <= self.lambda_min
            P = (P - K[:, :, None] * Pph[:, None, :]) / lam[:, None, None]
            P = 0.5 * (P + np.swapaxes(P, -1, -2))
            if self.p_max is not None:
                trace = np.trace(P, axis1=-2, axis2=-1)
                P = P * np.minimum(1.0, self.p_max / trace)[:, None, None]
            y_hat[:, k] = np.einsum("rq,rqm->rm", ph, W)
            innovation[:, k] = zeta
        with np.errstate(all="ignore"):
            top = np.full(runs, np.nan)
            finite = np.all(np.isfinite(P), axis=(1, 2))
            top[finite] = np.linalg.eigvalsh(P[finite])[:, -1]
        diagnostics = {
            "regressor_rank": np.linalg.matrix_rank(phi[:, self.order:]).astype(float)
            if steps > self.order else np.full(runs, np.nan),
            "regressor_size": np.full(runs, float(q)),
            "lambda_at_floor": floor / steps,
            "p_max_eig": top,
        }
        return Estimate(y_hat=y_hat, innovation=innovation,
                        broken=~np.all(np.isfinite(y_hat), axis=(1, 2)),
                        diagnostics=diagnostics)
