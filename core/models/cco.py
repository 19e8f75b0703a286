"""BJT cross-coupled oscillator with Ebers-Moll transistors (thesis §2.1, eqs 2.1-2.42).

The printed equations 2.1-2.5 do not describe one circuit (docs/thesis-notes.md, note 1: Z_2 and Z_4
swap roles, eq 2.4 carries I_B2 where 2.20 has I_B1, and nothing couples a collector to
the other base although the text says so). This model is the cross-coupled pair the text
and Table 2.1 describe, built from KCL (docs/deviations.md):

* collector loads: ``L_1`` (Q1) and ``L_4`` (Q2) from the supply ``V_CC``, each with a loss
  resistance ``R_P`` in parallel (the tank's finite Q);
* cross coupling: ``C_2`` from the collector of Q1 to the base of Q2 and ``C_3`` from the
  collector of Q2 to the base of Q1 (Table 2.1's column "C_4" is read as this second
  coupling capacitor: the circuit has no C_4);
* output capacitance ``C_o`` between the collectors (the ``Z_o`` of eq 2.3);
* bases biased from ``V_BB`` through ``R_B``, emitters to ground through ``R_E``;
* a parasitic ``C_par`` from every node to ground (junction and wiring capacitance), which
  makes the circuit an ODE rather than a DAE.

States ``x = [v_C1, v_C2, v_B1, v_B2, v_E1, v_E2, i_L1, i_L4]``, input the supply ``V_CC``
(the thesis excites the circuit by a supply step, eqs 2.27 and 2.33), output the collector
voltage of Q1.

Nodal equations ``C_n v' = i(v, i_L, V_CC)`` with the constant capacitance matrix ``C_n``,
and ``L_1 i_L1' = V_CC - v_C1``, ``L_4 i_L4' = V_CC - v_C2``. With emitter degeneration
``R_E`` the loop gain stays below one, so the operating point is stable and a supply step
makes the circuit ring and decay, like the thesis' linear solution 2.33; a pair that truly
oscillates has an unstable linearisation, about which a perturbation series diverges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.config.settings import setting
from estim.models.base import Model, check_params
from estim.models.devices import ebers_moll

NODES = ("C1", "C2", "B1", "B2", "E1", "E2")


@dataclass(frozen=True)
class CCOParams:
    V_BB: float = setting(1.5, unit="V", doc="base bias source")
    R_B: float = setting(10.0e3, unit="Ohm", doc="base bias resistors")
    R_E: float = setting(1.0e3, unit="Ohm", doc="emitter resistors (degeneration)")
    R_P: float = setting(1.0e3, unit="Ohm", doc="tank loss resistance across each inductor")
    L_1: float = setting(6.0e-6, unit="H", doc="collector inductor of Q1")
    L_4: float = setting(7.0e-6, unit="H", doc="collector inductor of Q2")
    C_2: float = setting(1.0e-9, unit="F", doc="coupling capacitor, collector Q1 -> base Q2")
    C_3: float = setting(5.0e-12, unit="F",
                         doc="coupling capacitor, collector Q2 -> base Q1 ('C_4')")
    C_o: float = setting(1.0e-12, unit="F", doc="output capacitance between the collectors")
    C_par: float = setting(0.1e-12, unit="F", doc="parasitic capacitance of every node to ground")
    V_T: float = setting(0.025852, unit="V", doc="thermal voltage (300 K)")
    I_ES: float = setting(1.0e-14, unit="A", doc="emitter-junction saturation current (both)")
    alpha_F: float = setting(0.99, unit="-", doc="forward common-base current gain (both)")
    alpha_R: float = setting(0.5, unit="-", doc="reverse common-base current gain (both)")

    def __post_init__(self) -> None:
        check_params(self, positive=("R_B", "R_E", "R_P", "L_1", "L_4", "C_2", "C_3", "C_o",
                                     "C_par", "V_T", "I_ES"),
                     unit_interval=("alpha_F", "alpha_R"))

    @property
    def I_CS(self) -> float:
        """Collector-junction saturation current from reciprocity, alpha_F I_ES = alpha_R I_CS."""
        return self.alpha_F * self.I_ES / self.alpha_R


# (base, collector, emitter) node indices of Q1 and Q2
_TRANSISTORS = ((2, 0, 4), (3, 1, 5))


class CrossCoupledOscillator(Model, name="cco"):
    """Cross-coupled BJT pair with inductive collector loads and capacitive cross coupling."""

    state_names = ("v_C1", "v_C2", "v_B1", "v_B2", "v_E1", "v_E2", "i_L1", "i_L4")
    input_names = ("V_CC",)
    output_names = ("v_C1",)
    Params = CCOParams
    variants = {"completed": {}}

    def __init__(self, variant: str | None = None, **overrides) -> None:
        super().__init__(variant, **overrides)
        p = self.params
        C = np.eye(6) * p.C_par
        for i, j, c in ((0, 3, p.C_2), (1, 2, p.C_3), (0, 1, p.C_o)):
            C[i, i] += c
            C[j, j] += c
            C[i, j] -= c
            C[j, i] -= c
        self._Cinv = np.linalg.inv(C)

    def f_and_jacobian(self, x: np.ndarray, u: np.ndarray,
                       t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Drift and Jacobian from KCL at the six nodes and the two inductor laws."""
        p = self.params
        x = np.asarray(x, float)
        vcc = np.asarray(u, float)[..., 0]
        v = x[..., :6]
        iL = x[..., 6:8]
        i = np.zeros(v.shape)
        G = np.zeros(v.shape + (8,))
        for node, load in ((0, 6), (1, 7)):
            i[..., node] = iL[..., load - 6] + (vcc - v[..., node]) / p.R_P
            G[..., node, node] = -1 / p.R_P
            G[..., node, load] = 1.0
        for node in (2, 3):
            i[..., node] = (p.V_BB - v[..., node]) / p.R_B
            G[..., node, node] = -1 / p.R_B
        for node in (4, 5):
            i[..., node] = -v[..., node] / p.R_E
            G[..., node, node] = -1 / p.R_E
        for b, c, e in _TRANSISTORS:
            tc = ebers_moll.currents(v[..., b] - v[..., e], v[..., b] - v[..., c], p.I_ES,
                                     p.I_CS, p.alpha_F, p.alpha_R, p.V_T)
            terminals = ((c, tc.I_C, tc.dIC_be, tc.dIC_bc), (e, tc.I_E, tc.dIE_be, tc.dIE_bc),
                         (b, tc.I_B, tc.dIB_be, tc.dIB_bc))
            for node, current, d_be, d_bc in terminals:
                i[..., node] -= current
                G[..., node, b] -= d_be + d_bc
                G[..., node, e] += d_be
                G[..., node, c] += d_bc
        f = np.concatenate([
            i @ self._Cinv.T,
            np.stack([(vcc - v[..., 0]) / p.L_1, (vcc - v[..., 1]) / p.L_4], axis=-1),
        ], axis=-1)
        J = np.zeros(x.shape + (8,))
        J[..., :6, :] = self._Cinv @ G
        J[..., 6, 0] = -1 / p.L_1
        J[..., 7, 1] = -1 / p.L_4
        return f, J

    output_row = ((0, 1.0),)

    def source_to_input(self, source: np.ndarray, dt: float) -> np.ndarray:
        """Supply held on each interval at its value at the interval's end (a step at
        ``t_0`` acts from the first interval on)."""
        return source[..., 1:, :]

    def operating_point(self, x_guess: np.ndarray | None = None,
                        u: np.ndarray | None = None) -> np.ndarray:
        """DC point at supply ``u`` (default 5 V): inductors short the collectors to V_CC."""
        p = self.params
        u = np.array([5.0]) if u is None else np.asarray(u, float)
        if x_guess is None:
            vE = max(p.V_BB - 0.65, 0.0)
            ic = vE / p.R_E
            x_guess = np.array([u[0], u[0], p.V_BB, p.V_BB, vE, vE, ic, ic])
        return super().operating_point(x_guess, u)
