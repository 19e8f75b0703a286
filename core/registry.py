"""Names used in configs -> implementations. Adding a model or filter is one line here.

Analyses register in :data:`core.analyses.ANALYSES` the same way.
"""

from __future__ import annotations

from core.estimators.ekf import ExtendedKalmanFilter
from core.estimators.kf import KalmanFilter
from core.estimators.rls import RecursiveLeastSquares
from core.estimators.ukf import UnscentedKalmanFilter
from core.models.cco import CrossCoupledOscillator
from core.models.diffamp_em import DiffAmpEbersMoll
from core.models.diffamp_exp import DiffAmpExponential
from core.models.mosfet_ekv import MosfetEKV

MODELS = {
    "cco": CrossCoupledOscillator,
    "diffamp_em": DiffAmpEbersMoll,
    "diffamp_exp": DiffAmpExponential,
    "mosfet_ekv": MosfetEKV,
}

ESTIMATORS = {
    "ekf": ExtendedKalmanFilter,
    "kf": KalmanFilter,
    "rls": RecursiveLeastSquares,
    "ukf": UnscentedKalmanFilter,
}
