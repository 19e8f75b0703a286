"""Names used in configs -> implementations. Adding a model or filter is one line here.

Analyses register in :data:`core.analyses.ANALYSES` the same way.
"""

from __future__ import annotations

from core.estimators.ekf import ExtendedKalmanFilter
from core.estimators.kf import KalmanFilter
from core.estimators.kronecker_ekf import KroneckerEKF
from core.estimators.rls import RecursiveLeastSquares
from core.estimators.ukf import UnscentedKalmanFilter
from core.estimators.wavelet_lms import WaveletLMS
from core.models.cco import CrossCoupledOscillator
from core.models.diffamp_em import DiffAmpEbersMoll
from core.models.diffamp_exp import DiffAmpExponential
from core.models.mosfet_darlington import MosfetDarlington
from core.models.mosfet_ekv import MosfetEKV
from core.models.mosfet_printed import MosfetPrinted

MODELS = {
    "cco": CrossCoupledOscillator,
    "diffamp_em": DiffAmpEbersMoll,
    "diffamp_exp": DiffAmpExponential,
    "mosfet_darlington": MosfetDarlington,
    "mosfet_ekv": MosfetEKV,
    "mosfet_printed": MosfetPrinted,
}

ESTIMATORS = {
    "ekf": ExtendedKalmanFilter,
    "kf": KalmanFilter,
    "kronecker_ekf": KroneckerEKF,
    "rls": RecursiveLeastSquares,
    "ukf": UnscentedKalmanFilter,
    "wavelet_lms": WaveletLMS,
}
