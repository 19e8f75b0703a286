"""BJT differential amplifier with the plain exponential transistor law (thesis §2.2).

The circuit is the one of :mod:`estim.models.diffamp_em` (eqs 2.44-2.47: tail resistor,
collector resistors, R_L-C_L load between the collectors); only the transistor differs.
Eqs 2.48-2.51 model each transistor by its base-emitter diode alone,

    I_C = beta I_0 (exp(v_BE/V_T) - 1),     I_E = I_0/(1 - alpha) (exp(v_BE/V_T) - 1),

with ``beta = alpha/(1 - alpha)``, so the base-collector junction never conducts and the
transistor cannot saturate. ``I_E`` here is the current into the emitter terminal, i.e.
minus eq 2.49 (docs/thesis-notes.md, note 3: the printed sign differs from the Ebers-Moll eq 2.7).
The default ``I_0 = (1 - alpha) I_ES`` gives the same forward collector current as the
Ebers-Moll model's default, so both amplifiers share an operating point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.config.settings import setting
from estim.models.diffamp_em import DiffAmpCircuit, DiffAmpEbersMoll


@dataclass(frozen=True)
class DiffAmpExpParams(DiffAmpCircuit):
    I_0: float = setting(1.0e-16, unit="A", doc="saturation current of eqs 2.48-2.51 (both)")
    alpha: float = setting(0.99, unit="-", doc="common-base current gain (both)")

    def __post_init__(self) -> None:
        self._check(("I_0",), ("alpha",))

    @property
    def beta(self) -> float:
        return self.alpha / (1 - self.alpha)


class DiffAmpExponential(DiffAmpEbersMoll, name="diffamp_exp"):
    """Emitter-coupled pair whose transistors follow eqs 2.48-2.51."""

    Params = DiffAmpExpParams
    variants = {"completed": {}, "thesis_printed": {"R_E": 80.0}}

    def _kernel_params(self) -> list[float]:
        p = self.params
        return [1.0, 0.0, 0.0, 0.0, 0.0, p.V_T, p.beta * p.I_0, p.I_0 / (1 - p.alpha)]

    def _terminal_currents(self, x: np.ndarray, u: np.ndarray):
        p = self.params
        vE = x[..., 0:1]
        vB = np.asarray(u, float)[..., 0:2]
        with np.errstate(over="ignore", invalid="ignore"):
            e = np.exp((vB - vE) / p.V_T)
        scale_c, scale_e = p.beta * p.I_0, p.I_0 / (1 - p.alpha)
        zero = np.zeros_like(e)
        return (scale_c * (e - 1), -scale_e * (e - 1), scale_c * e / p.V_T, zero,
                -scale_e * e / p.V_T, zero)
