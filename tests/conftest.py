import os

import numpy as np
import pytest
from scipy import linalg

from estim.models.base import Model

# The DC-point disk cache (estim.util.disk_cache) stays off in tests, where models are
# patched: a point kept by one test must not answer another. tests/test_startup.py turns it
# on in a folder of its own.
os.environ["ESTIM_CACHE_DIR"] = "off"


class LinearModel(Model):
    """dx/dt = A x + B u, y = C x: a fixture for filter tests."""

    name = "linear"

    def __init__(self, A, B, C):
        self.A, self.B, self.C = (np.atleast_2d(np.asarray(m, float)) for m in (A, B, C))
        n = self.A.shape[0]
        self.state_names = tuple(f"x{i}" for i in range(n))
        self.input_names = tuple(f"u{i}" for i in range(self.B.shape[1]))
        self.output_names = tuple(f"y{i}" for i in range(self.C.shape[0]))

    def f_and_jacobian(self, x, u, t=0.0):
        return (x @ self.A.T + u @ self.B.T,
                np.broadcast_to(self.A, np.shape(x)[:-1] + self.A.shape))

    def h(self, x):
        return x @ self.C.T

    def h_jacobian(self, x):
        return np.broadcast_to(self.C, np.shape(x)[:-1] + self.C.shape)

    def discrete(self, dt):
        """Exact zero-order-hold discretisation (A_d, B_d)."""
        n, p = self.B.shape
        aug = np.zeros((n + p, n + p))
        aug[:n, :n], aug[:n, n:] = self.A * dt, self.B * dt
        E = linalg.expm(aug)
        return E[:n, :n], E[:n, n:]


@pytest.fixture
def oscillator():
    return LinearModel([[0.0, 1.0], [-4.0, -0.4]], [[0.0], [1.0]], [[1.0, 0.0]])


@pytest.fixture
def linear_model():
    """The :class:`LinearModel` class, for tests that build their own linear system."""
    return LinearModel


def _rehash(folder) -> None:
    """Re-record the manifest of result ``folder`` over its files as they now are: a table
    edited as if an older estim had written it, which its manifest agrees with, so what
    reads it meets the content, not the sha256 check."""
    import json
    from pathlib import Path

    from estim import store

    folder = Path(folder)
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    data["config_sha256"] = store.spec_hash(data["config"])
    data["files"] = {rel: store.sha256(folder / rel) for rel in data["files"]
                     if (folder / rel).is_file()}
    manifest.write_text(json.dumps(data))


@pytest.fixture
def rehash():
    """:func:`_rehash`, for a test that edits a stored file on purpose."""
    return _rehash
