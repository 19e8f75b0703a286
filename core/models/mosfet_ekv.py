"""EKV MOSFET circuit of thesis Chapter 3 (Fig 3.1, eqs 3.1-3.17).

States ``x = [v_G, v_B, v_S, v_D]`` (eq 3.22), input ``u = dv_in/dt`` (the thesis' u of eq
3.26 less the constant V_IN/(R_in C_GX), which this model keeps inside ``f``), output the
drain voltage (eq 3.29).

The circuit is written as nodal analysis ``C x' = i(x) + b u`` with the full capacitance
matrix ``C`` of the network; ``f = C^-1 (i(x) + b u)``. This replaces the printed
coefficients p_1..p_10 (which do not follow from the printed KCL, see docs/deviations.md)
and the printed Jacobian 3.24 (which is not the derivative of 3.9-3.11).

Variants
--------
``thesis_literal``
    The network exactly as printed (eqs 3.1-3.4): drain, source and bulk reach the rest of
    the circuit only through capacitors, so no DC current can flow (D1, tested).
``completed`` (default)
    The same network plus what it needs to work as an amplifier: a load ``R_D`` from
    ``V_DD`` to the drain, ``R_S`` and ``R_B`` returning source and bulk to ground, and a
    coupling capacitor ``C_GX`` large enough to pass the 100 Hz - 10 kHz input.

Drain-current laws (``drain_current``)
--------------------------------------
``ekv``             EKV interpolation valid in all inversion levels (the "true" device).
``weak_inversion``  eq 3.6, the thesis' conduction-mode law.
``weak_saturation`` eq 3.12 with the slope factor restored (equal to 3.12 at eta = 1).
``taylor_conduction``  the printed Maclaurin polynomial eq 3.7 (coefficients p_7, p_8).
``taylor_saturation``  the printed Maclaurin polynomial eq 3.13, as printed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.config.settings import setting
from estim.models.base import Model, check_params
from estim.util import lazy

kernels = lazy.load("estim.numerics.kernels")

WEAK_INVERSION = 0.1
"""Upper bound of the forward inversion coefficient in weak inversion (EKV convention)."""

DRAIN_CURRENT_LAWS = (
    "ekv",
    "weak_inversion",
    "weak_saturation",
    "taylor_conduction",
    "taylor_saturation",
)


@dataclass(frozen=True)
class DeviceParams:
    """The EKV transistor and its capacitor network (eqs 3.1-3.4, 4.1-4.4): the values
    every MOSFET model here shares; each model adds its circuit around it."""

    U_T: float = setting(0.0256, unit="V", doc="thermal voltage")
    V_T0: float = setting(0.5, unit="V", doc="equilibrium threshold voltage")
    eta: float = setting(1.0, unit="-", doc="subthreshold slope factor")
    I_0: float = setting(1.0e-9, unit="A", doc="unary specific current")
    W_L: float = setting(1.0e5, unit="-", doc="aspect ratio W/L")
    R_in: float = setting(3.0e3, unit="Ohm", doc="gate bias resistor")
    C_GX: float = setting(1.0e-5, unit="F", doc="input coupling capacitor")
    C_S: float = setting(1.5e-10, unit="F", doc="gate-source capacitance")
    C_D: float = setting(1.5e-10, unit="F", doc="gate-drain capacitance")
    C_B: float = setting(4.0e-10, unit="F", doc="gate-bulk capacitance")
    C_BS: float = setting(0.99e-11, unit="F", doc="bulk-source capacitance")
    C_BD: float = setting(1.0e-11, unit="F", doc="bulk-drain capacitance")


@dataclass(frozen=True)
class MosfetParams(DeviceParams):
    V_IN: float = setting(0.435, unit="V", doc="DC gate bias")
    V_DD: float = setting(1.0, unit="V", doc="drain supply")
    R_D: float = setting(1.0e5, unit="Ohm", doc="drain load (inf: none)")
    R_S: float = setting(1.0e3, unit="Ohm", doc="source to ground (inf: none)")
    R_B: float = setting(1.0e5, unit="Ohm", doc="bulk to ground (inf: none)")
    drain_current: str = setting("ekv", unit="-",
                                 doc="drain-current law, one of DRAIN_CURRENT_LAWS")

    def __post_init__(self) -> None:
        if self.drain_current not in DRAIN_CURRENT_LAWS:
            raise ValueError(
                f"drain_current {self.drain_current!r}; expected one of {list(DRAIN_CURRENT_LAWS)}"
            )
        check_params(self, positive=("U_T", "eta", "I_0", "W_L", "R_in", "C_GX", "C_S", "C_D",
                                     "C_B", "C_BS", "C_BD", "R_D", "R_S", "R_B"))


def _softplus(a: np.ndarray) -> np.ndarray:
    return np.logaddexp(0.0, a)


def _sigmoid(a: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * a))


_LAWS = {"ekv": 0.0, "weak_inversion": 1.0, "weak_saturation": 2.0}




class MosfetEKV(Model, name="mosfet_ekv"):
    """EKV MOSFET with the capacitor network of eqs 3.1-3.4."""

    state_names = ("v_G", "v_B", "v_S", "v_D")
    input_names = ("dv_in/dt",)
    input_is_source_slope = True
    output_names = ("v_D",)
    input_affine = True
    Params = MosfetParams
    variants = {
        "completed": {},
        "thesis_literal": {
            "C_GX": 1.0e-11, "W_L": 1.0, "V_IN": 0.0, "V_DD": 0.0,
            "R_D": np.inf, "R_S": np.inf, "R_B": np.inf,
        },
    }

    def __init__(self, variant: str | None = None, **overrides) -> None:
        super().__init__(variant, **overrides)
        p = self.params
        C = np.zeros((4, 4))
        G, B, S, D = range(4)
        for i, j, c in ((G, S, p.C_S), (G, D, p.C_D), (G, B, p.C_B), (B, S, p.C_BS),
                        (B, D, p.C_BD)):
            C[i, i] += c
            C[j, j] += c
            C[i, j] -= c
            C[j, i] -= c
        C[G, G] += p.C_GX
        self.capacitance = C
        self._Cinv = np.linalg.inv(C)
        self._b = self._Cinv @ np.array([p.C_GX, 0.0, 0.0, 0.0])
        g = np.array([1.0 / p.R_in, 1.0 / p.R_B, 1.0 / p.R_S, 1.0 / p.R_D])
        self._G = np.diag(-g)
        self._i0 = np.array([p.V_IN / p.R_in, 0.0, 0.0, p.V_DD / p.R_D])
        self._incidence = np.array([0.0, 0.0, 1.0, -1.0])

    def drain_current(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Drain-to-source current and its gradient w.r.t. ``x``, shapes ``(...)``, ``(..., 4)``."""
        p = self.params
        vG, vB, vS, vD = np.moveaxis(np.asarray(x, float), -1, 0)
        Is = p.I_0 * p.W_L
        law = p.drain_current
        with np.errstate(over="ignore", invalid="ignore"):
            if law in ("ekv", "weak_inversion", "weak_saturation"):
                vp = (vG - vB - p.V_T0) / p.eta
                a_s = (vp - (vS - vB)) / (2 * p.U_T)
                a_d = (vp - (vD - vB)) / (2 * p.U_T)
                da_s = np.array([1 / p.eta, 1 - 1 / p.eta, -1.0, 0.0]) / (2 * p.U_T)
                da_d = np.array([1 / p.eta, 1 - 1 / p.eta, 0.0, -1.0]) / (2 * p.U_T)
                if law == "ekv":
                    Fs, Fd = _softplus(a_s) ** 2, _softplus(a_d) ** 2
                    dFs = 2 * _softplus(a_s) * _sigmoid(a_s)
                    dFd = 2 * _softplus(a_d) * _sigmoid(a_d)
                else:
                    Fs, Fd = np.exp(2 * a_s), np.exp(2 * a_d)
                    dFs, dFd = 2 * Fs, 2 * Fd
                if law == "weak_saturation":
                    Fd, dFd = np.zeros_like(Fd), np.zeros_like(dFd)
                current = Is * (Fs - Fd)
                grad = Is * (dFs[..., None] * da_s - dFd[..., None] * da_d)
            elif law == "taylor_conduction":
                xr = p.V_T0 / (p.eta * p.U_T)
                c0 = 1 - xr + xr**2 / 2 - xr**3 / 6
                c1 = (1 - xr + xr**2 / 2) / (p.eta * p.U_T)
                k = Is / p.U_T
                q = 1 / (2 * p.U_T)
                current = k * (
                    c0 * ((vD - vS) + q * (vS**2 - vD**2 - 2 * (vS * vB - vD * vB)))
                    + c1 * (vG * vD - vB * vD - vG * vS + vB * vS)
                )
                grad = k * np.stack([
                    c1 * (vD - vS),
                    c0 * q * 2 * (vD - vS) + c1 * (vS - vD),
                    c0 * (-1 + q * (2 * vS - 2 * vB)) + c1 * (vB - vG),
                    c0 * (1 + q * (2 * vB - 2 * vD)) + c1 * (vG - vB),
                ], axis=-1)
            else:
                vgs = vG - vS
                a1 = 1 / p.U_T - p.V_T0 / p.U_T**2
                current = Is * ((1 - p.V_T0 / p.U_T + p.V_T0**2 / p.U_T**2) + vgs * a1
                                + vgs**2 / (2 * p.U_T**2))
                d = Is * (a1 + vgs / p.U_T**2)
                zero = np.zeros_like(d)
                grad = np.stack([d, zero, -d, zero], axis=-1)
        return current, grad

    def f_and_jacobian(self, x: np.ndarray, u: np.ndarray,
                       t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Drift ``C^-1 (i(x) + b u)`` (KCL of eqs 3.1-3.4 with the completion) and its
        analytic Jacobian (in place of the printed eq 3.24)."""
        x = np.asarray(x, float)
        current, grad = self.drain_current(x)
        i = x @ self._G.T + self._i0 + current[..., None] * self._incidence
        fx = i @ self._Cinv.T + np.asarray(u, float)[..., :1] * self._b
        return fx, self._Cinv @ (self._G + self._incidence[:, None] * grad[..., None, :])

    def kernel(self):
        """The compiled drift for :mod:`estim.numerics.radau_compiled` (the device laws that have
        one)."""
        p = self.params
        if p.drain_current not in _LAWS:
            return None
        P = np.concatenate([[_LAWS[p.drain_current], p.I_0 * p.W_L, p.eta, p.U_T, p.V_T0],
                            self._Cinv.ravel(), np.diag(self._G), self._i0, self._b])
        return kernels.MOSFET, P

    regimes = ("weak_inversion", "weak_inversion_conduction", "weak_inversion_saturation")

    def in_regime(self, regime: str, x: np.ndarray, source: np.ndarray) -> np.ndarray:
        """EKV regions with the conventional boundaries (Enz, Krummenacher and Vittoz 1995;
        Enz and Vittoz 2006), from the forward inversion coefficient
        ``i_f = ln^2(1 + exp((v_P - v_S)/(2 U_T)))``, ``v_P = (v_G - V_T0)/eta``, all
        voltages bulk-referred.

        ``weak_inversion``: ``i_f < 0.1`` (the exponential law of eqs 3.6 and 3.12 holds to a
        few per cent). ``..._saturation`` adds ``v_DS >= U_T (2 sqrt(i_f) + 4)``, the EKV
        saturation voltage (in weak inversion about ``4 U_T``: the reverse current below
        e^-4 = 1.8 % of the forward one); ``..._conduction`` is the rest of weak inversion.
        """
        if regime not in self.regimes:
            raise ValueError(f"unknown regime {regime!r}; expected one of {list(self.regimes)}")
        p = self.params
        vG, vB, vS, vD = np.moveaxis(np.asarray(x, float), -1, 0)
        v_p = (vG - vB - p.V_T0) / p.eta
        i_f = np.logaddexp(0.0, (v_p - (vS - vB)) / (2 * p.U_T)) ** 2
        weak = i_f < WEAK_INVERSION
        if regime == "weak_inversion":
            return weak
        saturated = vD - vS >= p.U_T * (2 * np.sqrt(i_f) + 4)
        return weak & (saturated if regime == "weak_inversion_saturation" else ~saturated)

    def output_range(self) -> tuple[float, float]:
        """The drain lies between ground and ``V_DD`` at DC; a margin of one supply either
        side allows for capacitive overshoot."""
        return -self.params.V_DD, 2 * self.params.V_DD

    output_row = ((3, 1.0),)

    def source_to_input(self, source: np.ndarray, dt: float) -> np.ndarray:
        """Piecewise-linear source between samples: u on interval k is its slope (eq 3.26)."""
        return np.diff(source, axis=-2) / dt

    def operating_point(self, x_guess: np.ndarray | None = None,
                        u: np.ndarray | None = None) -> np.ndarray:
        """DC point (the input is a slope: only ``u = 0`` is a rest state)."""
        p = self.params
        if not np.isfinite(p.R_D) and not np.isfinite(p.R_S) and not np.isfinite(p.R_B):
            return np.full(4, p.V_IN)
        guess = np.array([p.V_IN, 0.0, 0.0, p.V_DD / 2]) if x_guess is None else x_guess
        return super().operating_point(guess)
