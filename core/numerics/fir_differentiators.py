"""FIR digital differentiators for high frequencies (the maximally linear design of the
paper in ``shared/seeds/002_a5009dd315ab9542.txt``, Table II and Fig 3), and the minimax
relative-error designs it is compared with.

The proposed structure (with a half-sample delay) has the frequency response

    D(w) = sum_{k=1..n} c_k sin(k w) + sum_{k=1..n} d_k sin((k - 1/2) w),     N2 = 2n,

and the maximally linear coefficients (the paper's eq 8 is missing from the text; this
closed form reproduces every numeric N2 cell of Table II, ``tests/test_differentiators.py``)

    c_k = -2 (n!)^2 / (k (n-k)! (n+k)!),
    d_k = pi [(2n-1)!!]^2 / (4^{n-1} (2k-1) (n-k)! (n+k-1)!),

computed as exact rationals (``fractions``): solving the moment equations in float64
instead gives wrong cells from n = 7. The relative error is
``RE = 20 log10 max |D(w) - w| / w`` over ``[w_p, pi]``; ``RE(pi) = 0`` exactly (the design
is maximally flat there).
"""

from __future__ import annotations

from fractions import Fraction
from math import factorial

import numpy as np

from estim.util import lazy

signal = lazy.load("scipy.signal")


def _double_factorial(k: int) -> int:
    out = 1
    while k > 1:
        out *= k
        k -= 2
    return out


def maximally_linear(n: int) -> tuple[list[Fraction], list[Fraction]]:
    """``c_1..c_n`` and ``d_1..d_n / pi`` as exact rationals (``d_k`` is ``pi`` times the
    second list)."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    c = [Fraction(-2 * factorial(n) ** 2, k * factorial(n - k) * factorial(n + k))
         for k in range(1, n + 1)]
    d = [Fraction(_double_factorial(2 * n - 1) ** 2,
                  4 ** (n - 1) * (2 * k - 1) * factorial(n - k) * factorial(n + k - 1))
         for k in range(1, n + 1)]
    return c, d


def response(n: int, w: np.ndarray) -> np.ndarray:
    """``D(w)`` of the maximally linear design of order ``N2 = 2n``."""
    c, d = maximally_linear(n)
    w = np.asarray(w, float)
    k = np.arange(1, n + 1)
    return (np.sin(np.multiply.outer(w, k)) @ np.array([float(v) for v in c])
            + np.pi * np.sin(np.multiply.outer(w, k - 0.5)) @ np.array([float(v) for v in d]))


def band(omega_p: float, points: int = 20_000) -> np.ndarray:
    """``points`` frequencies in ``[omega_p pi, pi)`` (``RE`` is 0/0 at no point of it)."""
    return np.linspace(omega_p * np.pi, np.pi, points, endpoint=False)


def relative_error_db(estimate: np.ndarray, w: np.ndarray) -> float:
    """``20 log10 max |D(w) - w| / w``."""
    return float(20 * np.log10(np.max(np.abs(estimate - w) / w)))


def minimax_full_band(taps: int) -> np.ndarray:
    """The minimax relative-error differentiator of Rabiner and Schafer [1] over the whole
    band ``[0, pi]`` (``scipy.signal.remez``, type differentiator: gain ``w``, weight
    ``1/w``), its amplitude response evaluated with the linear phase removed."""
    return signal.remez(taps, [0, 0.5], [2 * np.pi], type="differentiator", fs=1.0)


def minimax_response(h: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Amplitude of ``h`` at ``w`` with its linear phase (and the ``j`` of a
    differentiator) removed."""
    _, H = signal.freqz(h, worN=w)
    return np.abs(H)


def order_maximally_linear(omega_p: float, threshold_db: float, max_n: int = 40) -> int | None:
    """Smallest ``N2 = 2n`` whose RE over ``[omega_p pi, pi]`` is at most ``threshold_db``."""
    w = band(omega_p)
    for n in range(1, max_n + 1):
        if relative_error_db(response(n, w), w) <= threshold_db:
            return 2 * n
    return None


def order_minimax(omega_p: float, threshold_db: float, max_taps: int = 128) -> int | None:
    """Smallest even ``N1`` (taps) of the full-band minimax design whose RE over
    ``[omega_p pi, pi]`` is at most ``threshold_db``; ``None`` beyond ``max_taps``."""
    w = band(omega_p, 4_000)
    for taps in range(4, max_taps + 1, 2):
        if relative_error_db(minimax_response(minimax_full_band(taps), w), w) <= threshold_db:
            return taps
    return None


def minimax_band(n: int, omega_p: float, points: int = 1500) -> tuple[np.ndarray, float]:
    """The minimax relative-error design of the same mixed structure (``n`` sine terms of
    each kind) over ``[omega_p pi, pi]`` only, by linear programming
    (``scipy.optimize.linprog``, HiGHS): minimise ``delta`` subject to
    ``|D(w) - w| / w <= delta`` on ``points`` frequencies. Returns the coefficients
    ``[c, d]`` and the relative error in dB on a grid ten times finer."""
    from scipy.optimize import linprog

    w = band(omega_p, points)
    k = np.arange(1, n + 1)
    basis = np.hstack([np.sin(np.multiply.outer(w, k)), np.sin(np.multiply.outer(w, k - 0.5))])
    rel = basis / w[:, None]
    ones = np.ones((w.size, 1))
    A = np.vstack([np.hstack([rel, -ones]), np.hstack([-rel, -ones])])
    b = np.concatenate([np.ones(w.size), -np.ones(w.size)])
    cost = np.zeros(2 * n + 1)
    cost[-1] = 1.0
    sol = linprog(cost, A_ub=A, b_ub=b, bounds=[(None, None)] * (2 * n) + [(0, None)],
                  method="highs")
    if not sol.success:
        raise RuntimeError(f"linprog: {sol.message}")
    coef = sol.x[:-1]
    fine = band(omega_p, 10 * points)
    kf = np.arange(1, n + 1)
    D = (np.sin(np.multiply.outer(fine, kf)) @ coef[:n]
         + np.sin(np.multiply.outer(fine, kf - 0.5)) @ coef[n:])
    return coef, relative_error_db(D, fine)


def order_minimax_band(omega_p: float, threshold_db: float, max_n: int = 20) -> int | None:
    """Smallest ``2n`` of the band-limited minimax design meeting ``threshold_db``."""
    for n in range(1, max_n + 1):
        if minimax_band(n, omega_p)[1] <= threshold_db:
            return 2 * n
    return None
