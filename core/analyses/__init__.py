"""The registered analyses: one line each (see :mod:`core.analyses.base` for the protocol)."""

from __future__ import annotations

from core.analyses import burden, dipole, estimation, kronecker, perturbation

ANALYSES = {
    "burden": burden,
    "dipole": dipole,
    "estimation": estimation,
    "kronecker": kronecker,
    "perturbation": perturbation,
}
