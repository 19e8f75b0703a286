"""Compiled drift-and-Jacobian kernels, one per model that has one, and their dispatch.

A kernel ``k(x, u, P, f, J)`` writes the drift ``f(x, u)`` into ``f`` and its Jacobian into
``J``, reading the model's parameters from the vector ``P`` (each model's ``kernel()`` method
builds it). The integrator in :mod:`estim.compiled` calls :func:`evaluate` with the kernel's
number, so every compiled function is a module-level function that numba can cache on disk:
a kernel passed as a function argument was compiled anew in every process (10 s each).
Adding a kernel is one function here, one number and one branch in :func:`evaluate`.
"""

from __future__ import annotations

import numpy as np

try:
    import numba
except ImportError:  # pragma: no cover - the numpy path serves then
    numba = None

AVAILABLE = numba is not None


def jit(fn):
    """``numba.njit`` (cached on disk, numpy float semantics: 1/0 is inf, not an exception)
    where numba is installed, else the plain function."""
    return numba.njit(cache=True, error_model="numpy")(fn) if AVAILABLE else fn

MOSFET, DIFFAMP, EXPANDED = 0, 1, 2


def _mosfet(x, u, P, f, J):
    """The EKV MOSFET (``estim.models.mosfet_ekv``): ``MosfetEKV.f_and_jacobian`` with the
    laws ``ekv``, ``weak_inversion`` and ``weak_saturation``, in scalar form.

    ``P = [law, I_s, eta, U_T, V_T0, C^-1 (16, row-major), -g (4), i0 (4), b (4)]``."""
    law, Is, eta, UT, VT0 = P[0], P[1], P[2], P[3], P[4]
    vG, vB, vS, vD = x[0], x[1], x[2], x[3]
    vp = (vG - vB - VT0) / eta
    a_s = (vp - (vS - vB)) / (2 * UT)
    a_d = (vp - (vD - vB)) / (2 * UT)
    if law == 0.0:
        sp_s = max(a_s, 0.0) + np.log1p(np.exp(-abs(a_s)))
        sp_d = max(a_d, 0.0) + np.log1p(np.exp(-abs(a_d)))
        Fs, Fd = sp_s * sp_s, sp_d * sp_d
        dFs = 2 * sp_s * 0.5 * (1.0 + np.tanh(0.5 * a_s))
        dFd = 2 * sp_d * 0.5 * (1.0 + np.tanh(0.5 * a_d))
    else:
        Fs, Fd = np.exp(2 * a_s), np.exp(2 * a_d)
        dFs, dFd = 2 * Fs, 2 * Fd
    if law == 2.0:
        Fd, dFd = 0.0, 0.0
    current = Is * (Fs - Fd)
    k = Is / (2 * UT)
    g0 = (dFs - dFd) * k / eta
    g1 = (dFs - dFd) * k * (1 - 1 / eta)
    g2 = -dFs * k
    g3 = dFd * k
    i0 = P[21] * vG + P[25]
    i1 = P[22] * vB + P[26]
    i2 = P[23] * vS + P[27] + current
    i3 = P[24] * vD + P[28] - current
    for a in range(4):
        row = 5 + 4 * a
        f[a] = (P[row] * i0 + P[row + 1] * i1 + P[row + 2] * i2 + P[row + 3] * i3
                + u[0] * P[29 + a])
        # J = C^-1 (diag(-g) + inc grad^T), inc = [0, 0, 1, -1]
        s = P[row + 2] - P[row + 3]
        J[a, 0] = P[row] * P[21] + s * g0
        J[a, 1] = P[row + 1] * P[22] + s * g1
        J[a, 2] = P[row + 2] * P[23] + s * g2
        J[a, 3] = P[row + 3] * P[24] + s * g3


def _diffamp(x, u, P, f, J):
    """The differential amplifier (``estim.models.diffamp_em``, ``diffamp_exp``):
    ``DiffAmpEbersMoll.f_and_jacobian`` and the plain-exponential pair's, in scalar form.
    ``P = [kind (0 Ebers-Moll, 1 exponential), I_ES,
    I_CS, alpha_F, alpha_R, V_T, V_EE, V_CC, R_E, R_L, C_L, R_C1, R_C2, C_par, beta I_0,
    I_0/(1 - alpha)]``."""
    kind, I_ES, I_CS, aF, aR, VT = P[0], P[1], P[2], P[3], P[4], P[5]
    V_EE, V_CC, R_E, R_L, C_L, R_C1, R_C2, Cp = (P[6], P[7], P[8], P[9], P[10], P[11], P[12],
                                                  P[13])
    vE, qL, vC1, vC2 = x[0], x[1], x[2], x[3]
    IC = np.empty(2)
    IE = np.empty(2)
    dIC_be = np.empty(2)
    dIC_bc = np.empty(2)
    dIE_be = np.empty(2)
    dIE_bc = np.empty(2)
    for k in range(2):
        vC = vC1 if k == 0 else vC2
        eF = np.exp((u[k] - vE) / VT)
        if kind == 0.0:
            eR = np.exp((u[k] - vC) / VT)
            fF, fR = I_ES * (eF - 1), I_CS * (eR - 1)
            gF, gR = I_ES * eF / VT, I_CS * eR / VT
            IC[k], IE[k] = aF * fF - fR, -fF + aR * fR
            dIC_be[k], dIC_bc[k], dIE_be[k], dIE_bc[k] = aF * gF, -gR, -gF, aR * gR
        else:
            IC[k], IE[k] = P[14] * (eF - 1), -P[15] * (eF - 1)
            dIC_be[k], dIC_bc[k] = P[14] * eF / VT, 0.0
            dIE_be[k], dIE_bc[k] = -P[15] * eF / VT, 0.0
    iL = (vC1 - vC2 - qL / C_L) / R_L
    f[0] = ((V_EE - vE) / R_E - IE[0] - IE[1]) / Cp
    f[1] = iL
    f[2] = ((V_CC - vC1) / R_C1 - IC[0] - iL) / Cp
    f[3] = ((V_CC - vC2) / R_C2 - IC[1] + iL) / Cp
    J[:, :] = 0.0
    J[0, 0] = (-1 / R_E + dIE_be[0] + dIE_be[1]) / Cp
    J[0, 2] = dIE_bc[0] / Cp
    J[0, 3] = dIE_bc[1] / Cp
    J[1, 1] = -1 / (R_L * C_L)
    J[1, 2] = 1 / R_L
    J[1, 3] = -1 / R_L
    J[2, 0] = dIC_be[0] / Cp
    J[2, 1] = 1 / (R_L * C_L * Cp)
    J[2, 2] = (-1 / R_C1 + dIC_bc[0] - 1 / R_L) / Cp
    J[2, 3] = 1 / (R_L * Cp)
    J[3, 0] = dIC_be[1] / Cp
    J[3, 1] = -1 / (R_L * C_L * Cp)
    J[3, 3] = (-1 / R_C2 + dIC_bc[1] - 1 / R_L) / Cp
    J[3, 2] = 1 / (R_L * Cp)


def _expanded(x, u, P, f, J):
    """:meth:`estim.expansion.ExpandedSystem.f_and_jacobian` in scalar form (compiled)."""
    n, p = int(P[0]), int(P[1])
    m = n + p
    oA, oB, oH = 2, 2 + n * n, 2 + n * n + n * p
    z = np.empty(m)
    for a in range(n):
        z[a] = x[a]
    for c in range(p):
        z[n + c] = u[c]
    J[:, :] = 0.0
    for a in range(n):
        f0 = 0.0
        f1 = 0.0
        for b in range(n):
            A_ab = P[oA + a * n + b]
            f0 += A_ab * x[b]
            f1 += A_ab * x[n + b]
            J[a, b] = A_ab
            J[n + a, n + b] = A_ab
        for c in range(p):
            f0 += P[oB + a * p + c] * u[c]
        q = 0.0
        for i in range(m):
            row = 0.0
            for j in range(m):
                row += P[oH + (a * m + i) * m + j] * z[j]
            q += row * z[i]
            if i < n:
                J[n + a, i] = row
        f[a] = f0
        f[n + a] = f1 + 0.5 * q


mosfet = jit(_mosfet)
diffamp = jit(_diffamp)
expanded = jit(_expanded)


def _evaluate(kind, x, u, P, f, J):
    if kind == MOSFET:
        mosfet(x, u, P, f, J)
    elif kind == DIFFAMP:
        diffamp(x, u, P, f, J)
    else:
        expanded(x, u, P, f, J)


evaluate = jit(_evaluate)
