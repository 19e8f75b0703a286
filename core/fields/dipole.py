"""The Hertzian (short) dipole: analytic phasors of its potentials and fields (thesis
eqs 5.33-5.41, corrected), for a z-directed current ``I0 cos(omega t)`` of length ``dl``.

With ``beta = omega / c``, ``eta = mu0 c`` and the ``e^{j omega t}`` convention (a quantity is
``Re{F e^{j omega t}}``):

    A_z   = mu0 I0 dl e^{-j beta r} / (4 pi r),  A_r = A_z cos(theta),  A_th = -A_z sin(theta)
    Phi   = I0 dl cos(theta) / (4 pi eps0 omega) (beta / r - j / r^2) e^{-j beta r}
                                                   (Lorenz gauge: div A + j omega Phi / c^2 = 0)
    E_r   = eta I0 dl cos(theta) / (2 pi r^2) (1 + 1/(j beta r)) e^{-j beta r}
    E_th  = j eta beta I0 dl sin(theta) / (4 pi r) (1 + 1/(j beta r) - 1/(beta r)^2) e^{-j beta r}
    H_phi = j beta I0 dl sin(theta) / (4 pi r) (1 + 1/(j beta r)) e^{-j beta r}

so that ``E = -grad Phi - j omega A`` and ``H = curl A / mu0`` (a test checks both by finite
differences). The printed eqs 5.35-5.36 miss the ``1/r`` of ``A``, and eq 5.41's ``Phi`` has
``omega`` where ``1/omega`` belongs (docs/deviations.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Dipole:
    """Source and medium; the defaults are normalised units (c = mu0 = eps0 = 1, period 1,
    wavelength 1, I0 dl = 1)."""

    I0: float = 1.0
    dl: float = 1.0
    omega: float = 2 * np.pi
    c: float = 1.0
    mu0: float = 1.0

    @property
    def eps0(self) -> float:
        return 1.0 / (self.mu0 * self.c**2)

    @property
    def beta(self) -> float:
        return self.omega / self.c

    @property
    def eta(self) -> float:
        return self.mu0 * self.c

    def phasors(self, r: np.ndarray, theta: np.ndarray) -> dict[str, np.ndarray]:
        """Complex phasors at spherical points ``(r, theta)`` (any matching shapes)."""
        r, theta = np.asarray(r, float), np.asarray(theta, float)
        b, m = self.beta, self.I0 * self.dl
        wave = np.exp(-1j * b * r)
        inv = 1 / (1j * b * r)
        A_z = self.mu0 * m * wave / (4 * np.pi * r)
        return {
            "A_r": A_z * np.cos(theta),
            "A_theta": -A_z * np.sin(theta),
            "Phi": m * np.cos(theta) / (4 * np.pi * self.eps0 * self.omega)
            * (b / r - 1j / r**2) * wave,
            "E_r": self.eta * m * np.cos(theta) / (2 * np.pi * r**2) * (1 + inv) * wave,
            "E_theta": 1j * self.eta * b * m * np.sin(theta) / (4 * np.pi * r)
            * (1 + inv - 1 / (b * r) ** 2) * wave,
            "H_phi": 1j * b * m * np.sin(theta) / (4 * np.pi * r) * (1 + inv) * wave,
        }
