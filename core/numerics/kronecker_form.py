"""The Kronecker-product (quadratic) form of a circuit, thesis eq 4.15, built from any model.

About an expansion point ``(x*, u*)`` with deviations ``d = x - x*``, ``w = u - u*``,

    dx/dt = f0 + A1 d + A2 (d (x) d) + B w + A5 (d (x) w) + Auu (w (x) w)        (4.15)

with ``A1 = df/dx``, ``A2 = 1/2 H_xx`` reshaped ``n x n^2`` (so ``(d (x) d)[n i + j] =
d_i d_j``, eq 4.40), ``B = df/du`` and ``A5 = H_xu`` reshaped ``n x n p``: the second-order
expansion the Chapter 2 engine already computes (:func:`estim.numerics.expansion.expand`), nothing
typed in by hand. The thesis' ``A3 u1 + A4 u2`` is ``B w`` plus the constant ``f0`` here;
its noise terms ``A6 dbeta + A7 (x (x) dbeta)`` belong to the filter's ``Q``.

Its Jacobian is ``A1 + A2 (I (x) d + d (x) I) + A5 (I (x) w)``; the thesis' eq 4.37-4.38 keep
only ``A1`` (docs/deviations.md).

:func:`discretize` gives the discrete form of eq 4.36,
``d_k = F1 d_{k-1} + F2 (d (x) d) + G w + c``, either as printed (forward Euler,
``F1 = I + T A1``, ``F2 = T A2``) or by the exponential integrator (``F1 = e^{T A1}``,
``F2 = Gamma A2`` with ``Gamma = int_0^T e^{A1 s} ds``), which keeps the same Kronecker
structure and is stable for the stiff circuit, where Euler is not.

:func:`printed_terms` gives the matrices exactly as eqs 4.15 and 4.38-4.44 print them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.numerics.expansion import expand
from estim.util import lazy

linalg = lazy.load("scipy.linalg")


@dataclass(frozen=True)
class KroneckerTerms:
    """Continuous Kronecker form of a model about ``(x_op, u_op)``: shapes ``A1 (n, n)``,
    ``A2 (n, n^2)``, ``B (n, p)``, ``A5 (n, n p)``, ``Auu (n, p^2)``, ``f0 (n,)``."""

    x_op: np.ndarray
    u_op: np.ndarray
    f0: np.ndarray
    A1: np.ndarray
    A2: np.ndarray
    B: np.ndarray
    A5: np.ndarray
    Auu: np.ndarray

    @property
    def n(self) -> int:
        return self.A1.shape[0]

    @property
    def p(self) -> int:
        return self.B.shape[1]

    def drift(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Right-hand side of eq 4.15 (noise-free), batched over leading axes."""
        d = np.asarray(x, float) - self.x_op
        w = np.asarray(u, float) - self.u_op
        dd = (d[..., :, None] * d[..., None, :]).reshape(d.shape[:-1] + (-1,))
        dw = (d[..., :, None] * w[..., None, :]).reshape(d.shape[:-1] + (-1,))
        ww = (w[..., :, None] * w[..., None, :]).reshape(w.shape[:-1] + (-1,))
        return (self.f0 + d @ self.A1.T + dd @ self.A2.T + w @ self.B.T + dw @ self.A5.T
                + ww @ self.Auu.T)

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``A1 + A2 (I (x) d + d (x) I) + A5 (I (x) w)``, batched."""
        d = np.asarray(x, float) - self.x_op
        w = np.asarray(u, float) - self.u_op
        n, p = self.n, self.p
        T = self.A2.reshape(n, n, n)
        quad = np.einsum("iab,...b->...ia", T + T.swapaxes(1, 2), d)
        mixed = np.einsum("iac,...c->...ia", self.A5.reshape(n, n, p), w)
        return self.A1 + quad + mixed

    def linear_only(self) -> KroneckerTerms:
        """The same form with every quadratic term dropped (``A2 = A5 = Auu = 0``)."""
        return KroneckerTerms(self.x_op, self.u_op, self.f0, self.A1, np.zeros_like(self.A2),
                              self.B, np.zeros_like(self.A5), np.zeros_like(self.Auu))


def from_model(model, x_op: np.ndarray, u_op: np.ndarray | None = None) -> KroneckerTerms:
    """The Kronecker form of ``model`` about ``(x_op, u_op)`` from its Jacobians and Hessian."""
    n, p = model.n_states, model.n_inputs
    u_op = np.zeros(p) if u_op is None else np.asarray(u_op, float)
    e = expand(model, x_op, u_op)
    H = e.H.copy()
    if model.input_affine:
        H[:, n:, :] = 0.0
        H[:, :, n:] = 0.0
    A2 = 0.5 * H[:, :n, :n].reshape(n, n * n)
    A5 = H[:, :n, n:].reshape(n, n * p)
    Auu = 0.5 * H[:, n:, n:].reshape(n, p * p)
    f0 = np.asarray(model.f(e.x_op, u_op), float)
    return KroneckerTerms(e.x_op, u_op, f0, e.A, A2, e.B, A5, Auu)


DISCRETIZATIONS = ("exponential", "euler")


@dataclass(frozen=True)
class DiscreteKronecker:
    """Eq 4.36 in deviations: ``d_k = F1 d + F2 (d (x) d) + G w + F5 (d (x) w) + Guu (w (x) w)
    + c`` for one sample interval."""

    terms: KroneckerTerms
    F1: np.ndarray
    F2: np.ndarray
    G: np.ndarray
    F5: np.ndarray
    Guu: np.ndarray
    c: np.ndarray


def discretize(terms: KroneckerTerms, dt: float, method: str = "exponential") -> DiscreteKronecker:
    """``euler``: ``F1 = I + T A1`` and ``T`` times the rest (eqs 4.38-4.45, as printed);
    ``exponential``: ``F1 = e^{T A1}`` and ``Gamma = int_0^T e^{A1 s} ds`` times the rest
    (exact for the linear part, the nonlinear terms held over the interval)."""
    if method not in DISCRETIZATIONS:
        raise ValueError(f"discretization {method!r}; expected one of {list(DISCRETIZATIONS)}")
    n = terms.n
    if method == "euler":
        F1, Gamma = np.eye(n) + dt * terms.A1, dt * np.eye(n)
    else:
        aug = np.zeros((2 * n, 2 * n))
        aug[:n, :n], aug[:n, n:] = dt * terms.A1, dt * np.eye(n)
        E = linalg.expm(aug)
        F1, Gamma = E[:n, :n], E[:n, n:]
    return DiscreteKronecker(terms, F1, Gamma @ terms.A2, Gamma @ terms.B, Gamma @ terms.A5,
                             Gamma @ terms.Auu, Gamma @ terms.f0)


PRINTED_ORDER = ("v_G", "v_B", "v_S", "v_D")
"""The state order eq 4.15 states; :func:`printed_terms` follows it."""


def printed_s(C_S: float, C_D: float, C_B: float, C_BS: float, C_BD: float, I_0: float,
              W_L: float, U_T: float, V_T0: float, eta: float) -> dict[str, float]:
    """The coefficients ``s_1 .. s_8`` exactly as printed under eq 4.14."""
    den_a = C_BD * C_S * (-C_S - C_BS) + C_S * C_BS * (-C_D - C_BD)
    den_b = C_S * C_BD * (-C_S - C_BS) + C_S * C_BS * (-C_D - C_BD)
    sum_ = C_S + C_D + C_B
    s1 = C_D * (C_S + C_BS) * (C_S * C_BS + C_S * C_BD) / (C_S * C_BS * den_a) - 1 / C_BS
    s2 = (C_D * (C_S + C_BS) * (-C_S * C_D * C_BS - C_S * C_BD * (C_S + C_BS))
          / (C_S * C_BS * den_b) - C_S / C_BS + sum_ * (C_S + C_BS) / (C_S * C_BS)
          + C_D * (C_S + C_BS) * (-C_BD * sum_ * (C_S + C_BS)) / (C_S * C_BS * den_b))
    s3 = C_D * (C_BS + C_BD) / (C_S * C_BD * (C_S + C_BS) + C_S * C_BS * (C_S + C_BD))
    s4 = (C_D / C_S * (C_S * C_D * C_BS - C_S**2 * C_BD + C_BD * (C_S + C_BS) * sum_)
          / (C_D * C_BD * (C_S + C_BS) + C_S * C_BS * (C_D + C_BD)) + sum_ / C_S)
    den_5 = C_D * C_BD * (-C_S - C_BS) + C_S * C_BS * (-C_D - C_BD)
    s5 = C_D * (C_BS + C_BD) / den_5
    s6 = (-C_S * C_D * C_BS + C_S**2 * C_BD + C_BD * (-C_S - C_BS) * sum_) / den_5
    r = V_T0 / (eta * U_T)
    k = I_0 / U_T * W_L
    s7 = k * (1 - r + r**2 / 2 - r**3 / 6)
    s8 = k * (1 / (eta * U_T) - V_T0 / (eta**2 * U_T**2) + V_T0**2 / (2 * eta**3 * U_T**3))
    return {"s1": s1, "s2": s2, "s3": s3, "s4": s4, "s5": s5, "s6": s6, "s7": s7, "s8": s8}


def printed_matrices(s: dict[str, float], R_in: float, C_GX: float, U_T: float,
                     gamma: float) -> dict[str, np.ndarray]:
    """``A1``, ``A2``, ``A3``, ``A4`` of eq 4.15 as printed, columns in the printed order
    ``[v_G, v_B, v_S, v_D]`` (the column of ``x (x) x`` for ``x_i x_j`` is ``4 i + j``)."""
    a = 1.0 / (R_in * C_GX)
    rows = (None, s["s1"], s["s3"], s["s5"])
    drive = np.array([1.0, s["s2"], s["s4"], s["s6"]])
    A1 = np.zeros((4, 4))
    A2 = np.zeros((4, 16))
    A1[:, 0] = -a * drive
    for i, si in enumerate(rows):
        if si is None:
            continue
        q7, q8 = si * s["s7"], si * s["s8"]
        A1[i, 1], A1[i, 2] = q7, -q7
        for col, value in ((1, q8), (2, -q8), (5, -q7 / (2 * U_T)), (6, -q7 / (2 * U_T)),
                           (7, q7 / U_T), (9, q7 / (2 * U_T)), (10, q7 / (2 * U_T)),
                           (11, -q7 / U_T), (13, -q8), (14, q8)):
            A2[i, col] = value
    return {"A1": A1, "A2": A2, "A3": -gamma * drive, "A4": a * drive}
