"""The optimum differentiator from Kalman filter theory (the paper in
``shared/seeds/001_01b49ce744343ce9.txt``, eqs 4-11).

For a signal ``y = H'x`` of ``x' = F x + G u`` observed as ``z = y + w``
(``cov u = I delta``, ``cov w = R delta``), the Kalman-Bucy filter (eqs 5-7) gives ``x^``,
and when ``H'G = 0`` (eq 9) the derivative ``y' = (H^' + H'F) x`` has the minimum-variance
estimate ``y'^ = (H^' + H'F) x^`` (eq 11); ``H`` is constant here, so ``H^' = 0``. When
``H'G != 0`` (eq 12) ``y'`` contains white noise and has no such estimate: refused.

Sampled at ``dt``, the model is discretised exactly: ``Phi = e^{F dt}`` and the process
covariance ``Qd = int_0^dt e^{F s} G G' e^{F' s} ds`` (Van Loan's block exponential); the
measurement noise of density ``R`` sampled at ``dt`` has variance ``R / dt``. The discrete
filter is the project's :class:`~estim.estimators.kf.KalmanFilter`.

The double integrator ``F = [[0, 1], [0, 0]]``, ``G = [0, sqrt(q)]'``, ``H' = [1, 0]`` has a
closed form (:func:`double_integrator`): ``w0 = (q/r)^(1/4)``, ``K = [sqrt(2) w0, w0^2]``,
derivative error variance ``P22 = sqrt(2) q^(3/4) r^(1/4)``, and the differentiator is
``s w0^2 / (s^2 + sqrt(2) w0 s + w0^2)``.
"""

from __future__ import annotations

import numpy as np

from estim.estimators.kf import KalmanFilter
from estim.util import lazy

linalg = lazy.load("scipy.linalg")


def check_differentiable(G: np.ndarray, H: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``H'G = 0`` (eq 9)."""
    HG = np.atleast_2d(H).T @ np.atleast_2d(G) if np.ndim(H) == 1 else np.asarray(H).T @ G
    if not np.allclose(HG, 0.0, atol=1e-14):
        raise ValueError("H'G != 0 (eq 12): the signal's derivative contains white noise and "
                         "has no minimum-variance estimate; the differentiator needs H'G = 0 "
                         "(eq 9)")


def steady_state(F, G, H, R) -> tuple[np.ndarray, np.ndarray]:
    """The stationary solution of eq 7a and the gain of eq 6: ``(P, K)``. ``H`` is the
    ``n x m`` matrix of the paper (``y = H'x``)."""
    F, G, H = (np.atleast_2d(np.asarray(a, float)) for a in (F, G, H))
    R = np.atleast_2d(np.asarray(R, float))
    P = linalg.solve_continuous_are(F.T, H, G @ G.T, R)
    return P, P @ H @ np.linalg.inv(R)


def discretize(F, G, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``Phi = e^{F dt}`` and ``Qd`` by Van Loan's method."""
    F, G = np.atleast_2d(np.asarray(F, float)), np.atleast_2d(np.asarray(G, float))
    n = F.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -F, G @ G.T, F.T
    E = linalg.expm(M * dt)
    Phi = E[n:, n:].T
    return Phi, Phi @ E[:n, n:]


def double_integrator(q: float, r: float) -> dict[str, float]:
    """Closed form of the steady-state differentiator for the double integrator."""
    w0 = (q / r) ** 0.25
    return {"w0": w0, "K1": np.sqrt(2) * w0, "K2": w0**2,
            "P22": np.sqrt(2) * q**0.75 * r**0.25}


def frequency_response(F, H, K, f_hz: np.ndarray) -> np.ndarray:
    """``H'F (j 2 pi f I - F + K H')^-1 K`` of the steady-state differentiator."""
    F, H, K = (np.atleast_2d(np.asarray(a, float)) for a in (F, H, K))
    A = F - K @ H.T
    out = []
    for f in np.atleast_1d(f_hz):
        s = 2j * np.pi * f
        out.append((H.T @ F @ np.linalg.solve(s * np.eye(F.shape[0]) - A, K))[0, 0])
    return np.array(out)


def differentiate(z: np.ndarray, F, G, H, R, dt: float, x0=None, P0=None) -> dict:
    """Discrete-time optimum differentiator on measurements ``z (runs, steps, m)``: the
    estimates of ``y'`` and their variance ``(H'F) P (H'F)'`` at every step."""
    F, G, H = (np.atleast_2d(np.asarray(a, float)) for a in (F, G, H))
    check_differentiable(G, H)
    n = F.shape[0]
    Phi, Qd = discretize(F, G, dt)
    Rd = np.atleast_2d(np.asarray(R, float)) / dt
    P0 = np.eye(n) if P0 is None else P0
    kf = KalmanFilter(A=Phi, B=np.zeros((n, 1)), C=H.T, Q=Qd, R=Rd, P0=P0,
                      x0=np.zeros(n) if x0 is None else x0)
    est = kf.run(None, z, np.zeros((z.shape[1], 1)))
    D = H.T @ F
    return {"derivative": est.x_hat @ D.T,
            "variance": np.einsum("ij,rtjk,lk->rtil", D, est.P, D)[..., 0, 0],
            "Phi": Phi, "Qd": Qd, "Rd": Rd}


def with_bandwidth(samples: np.ndarray, dt: float, bandwidth_hz: float) -> np.ndarray:
    """Derivative estimates of sampled signals ``(runs, steps, p)`` at every sample, by the
    double-integrator differentiator whose corner is ``w0 = 2 pi bandwidth_hz``.

    Only ``q/r = w0^4`` sets the gain, so ``r = 1``. Each channel is filtered relative to its
    first sample (the derivative does not see a constant), from the filter's steady state:
    ``P0`` is the stationary posterior covariance, so the gain is constant from the first
    step.
    """
    samples = np.asarray(samples, float)
    w0 = 2 * np.pi * bandwidth_hz
    F = np.array([[0.0, 1.0], [0.0, 0.0]])
    G, H = np.array([[0.0], [w0**2]]), np.array([[1.0], [0.0]])
    Phi, Qd = discretize(F, G, dt)
    Rd = np.array([[1.0 / dt]])
    prior = linalg.solve_discrete_are(Phi.T, H, Qd, Rd)
    gain = prior @ H @ np.linalg.inv(H.T @ prior @ H + Rd)
    posterior = prior - gain @ H.T @ prior
    out = np.empty_like(samples)
    for c in range(samples.shape[-1]):
        z = samples[..., c:c + 1] - samples[..., :1, c:c + 1]
        out[..., c] = differentiate(z, F, G, H, 1.0, dt, P0=posterior)["derivative"][..., 0]
    return out
