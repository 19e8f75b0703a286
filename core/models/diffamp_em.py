"""BJT differential amplifier with Ebers-Moll transistors (thesis §3.2, eqs 3.43-3.56).

States ``x = [v_E, q_L, v_C1, v_C2]`` (eq 3.60), inputs the base voltages
``u = [v_B1, v_B2]``, output ``y = v_C1 - v_C2`` (eq 3.56).

The printed circuit (Fig 3.8) has one capacitor, C_L, so v_E, v_C1 and v_C2 are fixed by
KCL (3.44-3.46) at every instant; the thesis differentiates those constraints to obtain
ODEs driven by v_1', v_2' (3.52-3.55, whose r-coefficients carry typos: docs/thesis-notes.md,
note 8).
Here each of the three nodes carries a small parasitic capacitance ``C_par`` to ground
(the junction and wiring capacitance every real node has), which turns the index-1 DAE
into a stiff ODE with the same four states; as ``C_par -> 0`` it tends to the DAE. The
drift and its Jacobian come from the circuit equations directly:

    C_par v_E'  = (V_EE - v_E)/R_E - I_E1 - I_E2          (3.44)
    q_L'        = i_L = (v_C1 - v_C2 - q_L/C_L)/R_L        (3.43, 3.47)
    C_par v_C1' = (V_CC - v_C1)/R_C1 - I_C1 - i_L          (3.45)
    C_par v_C2' = (V_CC - v_C2)/R_C2 - I_C2 + i_L          (3.46)

with the Ebers-Moll terminal currents of eqs 3.48-3.51 (into the terminals) and
``V_EE = -12 V`` as a signed supply voltage (docs/thesis-notes.md, note 3).

Variants: ``completed`` (default) biases the pair where it amplifies, ``R_E = 48.3 kΩ``
(tail current about 0.25 mA, differential gain about 23.5 dB with R_L: tests/test_diffamp.py);
``thesis_printed`` keeps the printed ``R_E = 100 Ω`` of §3.2.3, with which both transistors
saturate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.config.settings import setting
from estim.models.base import Model, check_params
from estim.models.devices import ebers_moll
from estim.util import lazy

kernels = lazy.load("estim.numerics.kernels")


@dataclass(frozen=True)
class DiffAmpCircuit:
    """Circuit elements shared by the Ebers-Moll and the plain-exponential amplifier."""

    V_CC: float = setting(12.0, unit="V", doc="collector supply")
    V_EE: float = setting(-12.0, unit="V", doc="emitter supply (signed)")
    R_C1: float = setting(8.0e3, unit="Ohm", doc="collector resistor of Q1")
    R_C2: float = setting(8.0e3, unit="Ohm", doc="collector resistor of Q2")
    R_E: float = setting(48.3e3, unit="Ohm", doc="tail resistor")
    R_L: float = setting(10.0e3, unit="Ohm", doc="load resistor between the collectors")
    C_L: float = setting(10.0e-6, unit="F", doc="load capacitor in series with R_L")
    C_par: float = setting(1.0e-12, unit="F", doc="parasitic capacitance of nodes E, C1, C2")
    V_T: float = setting(0.025852, unit="V", doc="thermal voltage (300 K)")

    def _check(self, positive: tuple[str, ...], unit_interval: tuple[str, ...]) -> None:
        check_params(self, ("R_C1", "R_C2", "R_E", "R_L", "C_L", "C_par", "V_T", *positive),
                     unit_interval)


@dataclass(frozen=True)
class DiffAmpParams(DiffAmpCircuit):
    I_ES: float = setting(1.0e-14, unit="A", doc="emitter-junction saturation current (both)")
    alpha_F: float = setting(0.99, unit="-", doc="forward common-base current gain (both)")
    alpha_R: float = setting(0.5, unit="-", doc="reverse common-base current gain (both)")

    def __post_init__(self) -> None:
        self._check(("I_ES",), ("alpha_F", "alpha_R"))

    @property
    def I_CS(self) -> float:
        """Collector-junction saturation current from reciprocity, alpha_F I_ES = alpha_R I_CS."""
        return self.alpha_F * self.I_ES / self.alpha_R


class DiffAmpEbersMoll(Model, name="diffamp_em"):
    """Emitter-coupled BJT pair with an R_L-C_L load between the collectors."""

    state_names = ("v_E", "q_L", "v_C1", "v_C2")
    input_names = ("v_B1", "v_B2")
    output_names = ("v_C1 - v_C2",)
    Params = DiffAmpParams
    variants = {"completed": {}, "thesis_printed": {"R_E": 100.0}}

    def _terminal_currents(self, x: np.ndarray, u: np.ndarray):
        """Collector and emitter currents (into the terminals) of both transistors, shape
        ``(..., 2)``, and their slopes w.r.t. v_BE and v_BC (eqs 3.48-3.51)."""
        p = self.params
        vE, vC = x[..., 0:1], x[..., 2:4]
        vB = np.asarray(u, float)[..., 0:2]
        tc = ebers_moll.currents(vB - vE, vB - vC, p.I_ES, p.I_CS, p.alpha_F, p.alpha_R, p.V_T)
        return tc.I_C, tc.I_E, tc.dIC_be, tc.dIC_bc, tc.dIE_be, tc.dIE_bc

    def f_and_jacobian(self, x: np.ndarray, u: np.ndarray,
                       t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        x = np.asarray(x, float)
        IC, IE, dIC_be, dIC_bc, dIE_be, dIE_bc = self._terminal_currents(x, u)
        vE, qL, vC1, vC2 = np.moveaxis(x, -1, 0)
        iL = (vC1 - vC2 - qL / p.C_L) / p.R_L
        f = np.stack([
            ((p.V_EE - vE) / p.R_E - IE[..., 0] - IE[..., 1]) / p.C_par,
            iL,
            ((p.V_CC - vC1) / p.R_C1 - IC[..., 0] - iL) / p.C_par,
            ((p.V_CC - vC2) / p.R_C2 - IC[..., 1] + iL) / p.C_par,
        ], axis=-1)
        # v_BE = v_B - v_E and v_BC = v_B - v_C: d/dv_E = -d/dv_BE, d/dv_C = -d/dv_BC
        J = np.zeros(x.shape + (4,))
        J[..., 0, 0] = (-1 / p.R_E + dIE_be[..., 0] + dIE_be[..., 1]) / p.C_par
        J[..., 0, 2] = dIE_bc[..., 0] / p.C_par
        J[..., 0, 3] = dIE_bc[..., 1] / p.C_par
        J[..., 1, 1] = -1 / (p.R_L * p.C_L)
        J[..., 1, 2] = 1 / p.R_L
        J[..., 1, 3] = -1 / p.R_L
        for row, side, sign in ((2, 0, -1.0), (3, 1, 1.0)):
            J[..., row, 0] = dIC_be[..., side] / p.C_par
            J[..., row, 1] = -sign / (p.R_L * p.C_L * p.C_par)
            J[..., row, 2 + side] = (-1 / (p.R_C1 if side == 0 else p.R_C2)
                                     + dIC_bc[..., side] - 1 / p.R_L) / p.C_par
            J[..., row, 3 - side] = 1 / (p.R_L * p.C_par)
        return f, J

    @property
    def state_scales(self) -> tuple[float, ...]:
        """The thesis' state (eq 3.60) has the load capacitor's charge ``q_L``, as this model
        does; its printed ``Q`` is read as voltage variances, the ``q_L`` entry as that of
        the capacitor's voltage ``v_L = q_L / C_L`` (docs/deviations.md D36)."""
        return (1.0, self.params.C_L, 1.0, 1.0)

    def _kernel_params(self) -> list[float]:
        p = self.params
        return [0.0, p.I_ES, p.I_CS, p.alpha_F, p.alpha_R, p.V_T, 0.0, 0.0]

    def kernel(self):
        """The compiled drift for :mod:`estim.numerics.radau_compiled`."""
        p = self.params
        head = self._kernel_params()
        P = np.array([*head[:6], p.V_EE, p.V_CC, p.R_E, p.R_L, p.C_L, p.R_C1, p.R_C2,
                      p.C_par, *head[6:]], float)
        return kernels.DIFFAMP, P

    regimes = ("active",)

    def in_regime(self, regime: str, x: np.ndarray, source: np.ndarray) -> np.ndarray:
        """``active``: both transistors forward active, ``v_BE > 0.5 V`` (conducting) and
        ``v_BC < 0`` (collector junction reverse biased) for each; ``source`` holds the base
        voltages."""
        if regime not in self.regimes:
            raise ValueError(f"unknown regime {regime!r}; expected one of {list(self.regimes)}")
        x, vB = np.asarray(x, float), np.asarray(source, float)[..., 0:2]
        vBE, vBC = vB - x[..., 0:1], vB - x[..., 2:4]
        return np.all((vBE > 0.5) & (vBC < 0.0), axis=-1)

    def output_range(self) -> tuple[float, float]:
        """Both collectors lie between ``V_EE`` and ``V_CC``: their difference within the span
        of the supplies."""
        span = self.params.V_CC - self.params.V_EE
        return -span, span

    output_row = ((2, 1.0), (3, -1.0))

    def source_to_input(self, source: np.ndarray, dt: float) -> np.ndarray:
        """Base voltages on each interval: the mean of the source samples at its two ends."""
        return 0.5 * (source[..., 1:, :] + source[..., :-1, :])

    def operating_point(self, x_guess: np.ndarray | None = None,
                        u: np.ndarray | None = None) -> np.ndarray:
        """DC point for base voltages ``u`` (default 1 V on both bases, as in Chapter 2)."""
        p = self.params
        u = np.array([1.0, 1.0]) if u is None else np.asarray(u, float)
        guess = np.array([u[0] - 0.6, 0.0, p.V_CC / 2, p.V_CC / 2]) if x_guess is None else x_guess
        return super().operating_point(guess, u)
