"""MOS analogue of the Darlington pair (thesis Fig 4.2), and longer chains of the same stage.

Each stage is the Chapter 3 circuit (:mod:`estim.models.mosfet_ekv`, ``completed`` variant):
the EKV transistor with its capacitor network, gate bias ``R_in`` to ``V_IN``, drain load
``R_D``, source and bulk returns ``R_S``, ``R_B``. Stage 1's gate is coupled to the source
``v_in`` through ``C_GX``; stage ``k > 1``'s gate is coupled through ``C_GX`` to the source
node of stage ``k - 1`` (``v_in2 = v_S1``, Sec 4.1). States ``[v_G1, v_B1, v_S1, v_D1, v_G2,
...]`` (``x^(2)`` of Sec 4.1), input ``u = dv_in/dt``, output the last stage's drain.

``stages`` (default 2, the Darlington pair) sets the length; longer chains serve the
computational-burden measurements of Tables 4.3-4.4 (``n_x = 4 stages``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from estim.config.settings import setting
from estim.models.base import Model
from estim.models.mosfet_ekv import MosfetEKV, MosfetParams


@dataclass(frozen=True)
class ChainParams(MosfetParams):
    """The stage's parameters (:class:`estim.models.mosfet_ekv.MosfetParams`) with the
    Chapter 4 defaults, and the number of stages."""

    W_L: float = setting(1.0, unit="-", doc="aspect ratio W/L of every stage")
    V_IN: float = setting(0.5, unit="V", doc="DC gate bias of every stage")
    R_D: float = setting(1.0e9, unit="Ohm", doc="drain load of every stage")
    stages: int = setting(2, unit="-", doc="number of stages (2: the Darlington pair of Fig 4.2)")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.stages, int) or isinstance(self.stages, bool) \
                or not 1 <= self.stages <= 64:
            raise ValueError(f"stages must be an integer in [1, 64], got {self.stages!r}")


class MosfetDarlington(Model, name="mosfet_darlington"):
    """A chain of EKV MOSFET stages, each gate driven by the previous stage's source."""

    input_names = ("dv_in/dt",)
    input_is_source_slope = True
    output_names = ("v_D",)
    input_affine = True
    Params = ChainParams
    variants = {"completed": {}}

    def __init__(self, variant: str | None = None, **overrides) -> None:
        super().__init__(variant, **overrides)
        p = self.params
        k = p.stages
        self.state_names = tuple(f"{v}{i + 1}" for i in range(k)
                                 for v in ("v_G", "v_B", "v_S", "v_D"))
        stage = {f.name: getattr(p, f.name) for f in dataclasses.fields(MosfetParams)}
        self.stage = MosfetEKV("completed", **stage)
        n = 4 * k
        C = np.zeros((n, n))
        for s in range(k):
            o = 4 * s
            C[o:o + 4, o:o + 4] = self.stage.capacitance
            if s > 0:      # C_GX from the previous source node (o - 2) to this gate (o)
                C[o - 2, o - 2] += p.C_GX
                C[o - 2, o] -= p.C_GX
                C[o, o - 2] -= p.C_GX
        self.capacitance = C
        self._Cinv = np.linalg.inv(C)
        self._b = self._Cinv[:, 0] * p.C_GX
        self._G = np.kron(np.eye(k), self.stage._G)
        self._i0 = np.tile(self.stage._i0, k)

    def f_and_jacobian(self, x: np.ndarray, u: np.ndarray,
                       t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Nodal analysis ``C x' = G x + i0 + i_D(x) + b u`` over all stages."""
        x = np.asarray(x, float)
        k = self.params.stages
        xs = x.reshape(x.shape[:-1] + (k, 4))
        current, grad = self.stage.drain_current(xs)
        inc = self.stage._incidence
        i = x @ self._G.T + self._i0 + (current[..., None] * inc).reshape(x.shape)
        fx = i @ self._Cinv.T + np.asarray(u, float)[..., :1] * self._b
        block = inc[:, None] * grad[..., None, :]            # (..., k, 4, 4)
        J = np.zeros(x.shape[:-1] + (4 * k, 4 * k)) + self._G
        for s in range(k):
            J[..., 4 * s:4 * s + 4, 4 * s:4 * s + 4] += block[..., s, :, :]
        return fx, self._Cinv @ J

    def output_range(self) -> tuple[float, float]:
        return -self.params.V_DD, 2 * self.params.V_DD

    output_row = ((-1, 1.0),)

    def source_to_input(self, source: np.ndarray, dt: float) -> np.ndarray:
        """Piecewise-linear source: the input on an interval is its slope."""
        return np.diff(source, axis=-2) / dt

    def operating_point(self, x_guess: np.ndarray | None = None,
                        u: np.ndarray | None = None) -> np.ndarray:
        if x_guess is None:
            x_guess = np.tile(self.stage.operating_point(), self.params.stages)
        return super().operating_point(x_guess)
