"""The Radau IIA tableau (3 stages, order 5) and its embedded error estimate (Hairer &
Wanner, Solving ODEs II, IV.8; as scipy), shared by the numpy integrator
(:mod:`estim.numerics.simulate`) and the compiled one (:mod:`estim.numerics.radau_compiled`) without
importing numba.
"""

from __future__ import annotations

import numpy as np

_S6 = np.sqrt(6.0)
A = np.array([
    [(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
    [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
    [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9],
])
"""Radau IIA coefficients."""
MU = 3 + 3 ** (2 / 3) - 3 ** (1 / 3)
"""The real eigenvalue of ``A^-1``."""
E = np.array([-13 - 7 * _S6, -13 + 7 * _S6, -1.0]) / 3
"""The embedded error estimate's weights."""
