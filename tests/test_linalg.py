import numpy as np
import pytest
from scipy import linalg as sl

from estim.models.mosfet_ekv import MosfetEKV
from estim.numerics.linalg import expm


@pytest.mark.parametrize("scale", [1e-3, 1.0, 30.0])
def test_batched_expm_matches_scipy(scale):
    A = np.random.default_rng(0).normal(size=(50, 5, 5)) * scale
    A -= 2 * scale * np.eye(5)               # keep exp(A) bounded for large scales
    expected = np.stack([sl.expm(a) for a in A])
    np.testing.assert_allclose(expm(A), expected, rtol=1e-8, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("dt", [1e-5, 1e-4, 1e-3])
def test_batched_expm_on_stiff_circuit_jacobians(dt):
    model = MosfetEKV(drain_current="weak_saturation")
    x = model.operating_point() + 0.05 * np.random.default_rng(1).normal(size=(40, 4))
    J = model.jacobian(x, np.zeros((40, 1))) * dt
    expected = np.stack([sl.expm(a) for a in J])
    np.testing.assert_allclose(expm(J), expected, rtol=1e-6, atol=1e-9)


def test_batched_expm_of_diagonal_and_nonfinite():
    d = np.array([[-1.0, 0.0], [0.0, 2.0]])
    np.testing.assert_allclose(expm(d[None])[0], np.diag(np.exp([-1.0, 2.0])), rtol=1e-14)
    assert np.isnan(expm(np.full((1, 2, 2), np.inf))).all()
