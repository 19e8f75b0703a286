"""The registered analyses: one line each (see :mod:`core.analyses.base` for the protocol)."""

from __future__ import annotations

from core.analyses import burden, estimation, kronecker, perturbation

ANALYSES = {
    "burden": burden,
    "estimation": estimation,
    "kronecker": kronecker,
    "perturbation": perturbation,
}
