"""The Chapter 4 MOSFET exactly as eq 4.15 prints it (Kronecker form, s-coefficients).

States in the printed order ``[v_G, v_B, v_S, v_D]``, input ``u = v_in`` (the source
itself: eq 4.15's ``A3 u1``, held over each sample interval), the gate bias ``V_IN`` as the
constant input ``u2`` (``A4``), output ``v_D`` (eq 4.49, ``H = [0 0 0 1]``). The drift is the
quadratic polynomial ``A1 x + A2 (x (x) x) + A3 v_in + A4 V_IN`` with the matrices of
:func:`estim.numerics.kronecker_form.printed_matrices`; its Jacobian and Hessian are exact.

This model carries the printed errors on purpose (docs/deviations.md D44-D47): its columns
of ``A1``/``A2`` agree with eqs 4.11-4.13 only in the order ``[v_G, v_D, v_S, v_B]``, and
its linear part has a positive eigenvalue, so it is unstable. It exists so that a table can
show what the printed model does; the project's circuit is :mod:`estim.models.mosfet_ekv`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.config.settings import setting
from estim.models.base import Model, check_params
from estim.models.mosfet_ekv import DeviceParams
from estim.numerics.kronecker_form import printed_matrices, printed_s


@dataclass(frozen=True)
class PrintedParams(DeviceParams):
    """The shared device values (:class:`estim.models.mosfet_ekv.DeviceParams`) with
    Chapter 4's printed ``W/L`` and ``C_GX``, and the O.U. input's decay rate."""

    W_L: float = setting(1.0, unit="-", doc="aspect ratio W/L")
    C_GX: float = setting(1.0e-11, unit="F", doc="input coupling capacitor (as printed, l. 2325)")
    gamma: float = setting(1.0, unit="1/s", doc="O.U. decay rate of the input (eq 4.8)")
    V_IN: float = setting(0.5, unit="V", doc="DC gate bias u2 (not printed)")

    def __post_init__(self) -> None:
        check_params(self, positive=("U_T", "eta", "I_0", "W_L", "R_in", "C_GX", "C_S", "C_D",
                                     "C_B", "C_BS", "C_BD", "gamma"))


class MosfetPrinted(Model, name="mosfet_printed"):
    """Eq 4.15 with the printed ``A1 .. A4``."""

    state_names = ("v_G", "v_B", "v_S", "v_D")
    input_names = ("v_in",)
    output_names = ("v_D",)
    input_affine = True
    Params = PrintedParams
    variants = {"as_printed": {}}

    def __init__(self, variant: str | None = None, **overrides) -> None:
        super().__init__(variant, **overrides)
        p = self.params
        self.s = printed_s(p.C_S, p.C_D, p.C_B, p.C_BS, p.C_BD, p.I_0, p.W_L, p.U_T, p.V_T0,
                           p.eta)
        m = printed_matrices(self.s, p.R_in, p.C_GX, p.U_T, p.gamma)
        self.A1, self.A2, self.A3, self.A4 = m["A1"], m["A2"], m["A3"], m["A4"]
        self._T = self.A2.reshape(4, 4, 4)

    def f_and_jacobian(self, x: np.ndarray, u: np.ndarray,
                       t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(x, float)
        xx = (x[..., :, None] * x[..., None, :]).reshape(x.shape[:-1] + (16,))
        with np.errstate(over="ignore", invalid="ignore"):
            fx = (x @ self.A1.T + xx @ self.A2.T + np.asarray(u, float)[..., :1] * self.A3
                  + self.params.V_IN * self.A4)
            J = self.A1 + np.einsum("iab,...b->...ia", self._T + self._T.swapaxes(1, 2), x)
        return fx, J

    def input_jacobian(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        return self.A3[:, None].copy()

    def hessian(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        H = np.zeros((4, 5, 5))
        H[:, :4, :4] = self._T + self._T.swapaxes(1, 2)
        return H

    output_row = ((3, 1.0),)

    def source_to_input(self, source: np.ndarray, dt: float) -> np.ndarray:
        """The source value at the start of each interval, held over it."""
        return np.asarray(source, float)[..., :-1, :]

    def operating_point(self, x_guess: np.ndarray | None = None,
                        u: np.ndarray | None = None) -> np.ndarray:
        """The printed model has no isolated DC point (its ``v_D`` column of ``A1`` is
        zero); eq 4.52 starts its filter at ``x = 0``."""
        return np.zeros(4)
