"""The registered analyses: one line each (see :mod:`estim.analyses.base` for the protocol)."""

from __future__ import annotations

from estim.analyses import (
    burden,
    differentiator,
    dipole,
    dipole_field,
    estimation,
    field_study,
    image_kalman,
    kalman_derivative,
    kronecker,
    passive_network,
    perturbation,
)

ANALYSES = {
    "burden": burden,
    "differentiator": differentiator,
    "dipole": dipole,
    "dipole_field": dipole_field,
    "estimation": estimation,
    "field_study": field_study,
    "image_kalman": image_kalman,
    "kalman_derivative": kalman_derivative,
    "kronecker": kronecker,
    "passive_network": passive_network,
    "perturbation": perturbation,
}
