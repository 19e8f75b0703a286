"""The Ebers-Moll bipolar transistor (thesis eqs 2.6-2.7 and 3.48-3.51).

With ``f_F = I_ES (exp(v_BE/V_T) - 1)`` and ``f_R = I_CS (exp(v_BC/V_T) - 1)`` the currents
into the terminals are

    I_C = alpha_F f_F - f_R,      I_E = -f_F + alpha_R f_R,      I_B = -(I_C + I_E),

and ``alpha_F I_ES = alpha_R I_CS`` (reciprocity) is left to the caller's parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TerminalCurrents:
    """Currents into collector, emitter and base, and their slopes w.r.t. v_BE and v_BC."""

    I_C: np.ndarray
    I_E: np.ndarray
    I_B: np.ndarray
    dIC_be: np.ndarray
    dIC_bc: np.ndarray
    dIE_be: np.ndarray
    dIE_bc: np.ndarray
    dIB_be: np.ndarray
    dIB_bc: np.ndarray


def currents(v_be: np.ndarray, v_bc: np.ndarray, I_ES: float, I_CS: float, alpha_F: float,
             alpha_R: float, V_T: float) -> TerminalCurrents:
    """Ebers-Moll terminal currents (eqs 3.48-3.51) on arrays of any shape."""
    with np.errstate(over="ignore", invalid="ignore"):
        eF = np.exp(v_be / V_T)
        eR = np.exp(v_bc / V_T)
    fF, fR = I_ES * (eF - 1), I_CS * (eR - 1)
    gF, gR = I_ES * eF / V_T, I_CS * eR / V_T
    return TerminalCurrents(
        I_C=alpha_F * fF - fR, I_E=-fF + alpha_R * fR,
        I_B=(1 - alpha_F) * fF + (1 - alpha_R) * fR,
        dIC_be=alpha_F * gF, dIC_bc=-gR, dIE_be=-gF, dIE_bc=alpha_R * gR,
        dIB_be=(1 - alpha_F) * gF, dIB_bc=(1 - alpha_R) * gR,
    )
