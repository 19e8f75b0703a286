"""Names used in configs -> implementations. Adding a model or filter is one line here.

Analyses register in :data:`estim.analyses.ANALYSES` the same way.
"""

from __future__ import annotations

from estim.estimators.ekf import ExtendedKalmanFilter
from estim.estimators.kf import KalmanFilter
from estim.estimators.kronecker_ekf import KroneckerEKF
from estim.estimators.rls import RecursiveLeastSquares
from estim.estimators.ukf import UnscentedKalmanFilter
from estim.estimators.wavelet_lms import WaveletLMS
from estim.models.cco import CrossCoupledOscillator
from estim.models.diffamp_em import DiffAmpEbersMoll
from estim.models.diffamp_exp import DiffAmpExponential
from estim.models.mosfet_darlington import MosfetDarlington
from estim.models.mosfet_ekv import MosfetEKV
from estim.models.mosfet_printed import MosfetPrinted

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
