"""Compiled drift-and-Jacobian kernels, one per model that has one, and their dispatch.

A kernel ``k(x, u, P, f, J)`` writes the drift ``f(x, u)`` into ``f`` and its Jacobian into
``J``, reading the model's parameters from the vector ``P`` (each model's ``kernel()`` method
builds it). The integrator in :mod:`estim.numerics.radau_compiled` calls :func:`evaluate` with the
kernel's number, so every compiled function is a module-level function that numba can cache on disk:
a kernel passed as a function argument was compiled anew in every process (10 s each).
Adding a kernel is one function here, one number and one branch in :func:`evaluate`.
numba's disk cache of the integrator (:mod:`estim.numerics.radau_compiled`) is keyed on that file
only and does not notice a change here: after editing a kernel, delete the caches (``find . -name
'*.nb[ic]' -delete``) or the cached integrator keeps calling the old kernel.
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


def plain(a) -> np.ndarray:
    """``a`` as a C-contiguous, writable float64 array (a copy only where it is not one):
    numba types a read-only or strided array apart, and compiles a function a second time
    for it (about 19 s for the integrator on a fresh install)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


MOSFET, DIFFAMP, EXPANDED, NETLIST = 0, 1, 2, 3


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
    """:meth:`estim.numerics.expansion.ExpandedSystem.f_and_jacobian` in scalar form (compiled)."""
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


def _lambertw_exp(z):
    """``W(e^z)`` (the principal branch of Lambert's W at ``e^z``) by Newton's method on
    ``w + ln w = z``, to rounding; no overflow for large ``z``."""
    w = z - np.log(z) if z > 1.0 else np.exp(z) / (1.0 + np.exp(z)) * (1.0 + max(z, 0.0))
    if w <= 0.0:
        w = np.exp(z)
        if w == 0.0:
            return 0.0
    for _ in range(60):
        step = (w + np.log(w) - z) * w / (w + 1.0)
        w_new = w - step
        if w_new <= 0.0:
            w_new = 0.5 * w
        if abs(w_new - w) <= 1e-16 * w_new:
            return w_new
        w = w_new
    return w


DEVICE_ROW = 19
"""A device's row in the netlist kernel's data: its type, four node indices and up to 14
parameters (:func:`_netlist`)."""


def _netlist(x, u, P, f, J):
    """A netlist model (``estim.spice.netlist_model.NetlistModel``) in scalar form, in the numpy
    path's order: the currents of each row (a state node's supernode, then each controlling
    source of an F or H), linear part ``Y x + W u + c`` (R, G, I and the sources), plus each
    device (D, Q, M) from its terminal voltages ``V = Pm x + Qm u + r``, added to its node's
    rows; each F source's current (``A`` times the control rows) added to the state rows;
    then ``f = -C^-1 (currents)`` on the node states and the inductor drift (the last rows of
    ``Y, W, c``) as is. The currents are summed before ``C^-1`` is applied: folding ``C^-1``
    (entries 1/C_par ~ 1e12) into the coefficients made sums of 1e9-sized terms that left a
    rounding bias in ``f`` which the slow load capacitor integrated into 1e-10 V over 3 ms.
    One kernel for every netlist: the circuit is data in ``P``, so numba compiles it once
    and caches it.

    ``P = [n, k, p, N, devices, nc, Y (R n), W (R p), c (R), Pm (N n), Qm (N p), r (N),
    -C^-1 (k k), A (k nc), row (N), control row (N), device rows (DEVICE_ROW each)]`` with
    ``R = k + nc + n - k`` rows (``row``: a node's KCL row, -1 for none; ``control row``: its
    row among the ``nc`` control rows, numbered from ``k``, or -1); a device row is ``[type,
    four node indices (-1: none), its parameters (zeros after them)]``: type 0 a diode
    (``a, b``; ``I_s, n V_T, r_s``), 1/2 an NPN/PNP (``c, b, e``; ``I_ES, I_CS, alpha_F,
    alpha_R, V_T``), 3 an NMOS (``d, g, s, b``; ``U_T, V_T0, eta, I_s``, law: 0 EKV, 1 weak
    inversion, 2 weak saturation, 3 and 4 the Taylor polynomials,
    ``estim.spice.devices.NMOS_LAWS``), 4 a PMOS (the same, of the negated voltages, its
    current negated), 5/6 a level-1 NMOS/PMOS
    (``d, g, s, b``; ``VTO`` (a PMOS's negated), ``KP W / L``, ``LAMBDA``, ``GAMMA``, ``PHI``:
    :mod:`estim.spice.level1`), 7/8 a Gummel-Poon NPN/PNP (``c, b, e``; ``IS, BF, BR, NF, NR``,
    ``1/VAF, 1/VAR, 1/IKF, 1/IKR`` (0: infinite), ``ISE, NE, ISC, NC, V_T``:
    :mod:`estim.spice.gummel_poon`)."""
    n, k, p, N, nd, nc = int(P[0]), int(P[1]), int(P[2]), int(P[3]), int(P[4]), int(P[5])
    kc = k + nc
    R = kc + n - k
    oA = 6
    oB = oA + R * n
    oc = oB + R * p
    oP = oc + R
    oQ = oP + N * n
    orr = oQ + N * p
    oM = orr + N
    oF = oM + k * k
    orow = oF + k * nc
    ocrow = orow + N
    odev = ocrow + N
    scratch = np.empty(19 + n + R * (n + 1))            # one allocation per call
    v = scratch[0:4]
    term = scratch[4:7]
    dterm = scratch[7:19].reshape(3, 4)
    grad = scratch[19:19 + n]
    cur = scratch[19 + n:].reshape(R, n + 1)
    for a in range(R):
        s = P[oc + a]
        for b in range(n):
            s += P[oA + a * n + b] * x[b]
            cur[a, b] = P[oA + a * n + b]
        for c in range(p):
            s += P[oB + a * p + c] * u[c]
        cur[a, n] = s
    for d in range(nd):
        row = odev + DEVICE_ROW * d
        kind = P[row]
        for c in range(4):
            node = int(P[row + 1 + c])
            if node >= 0:
                s = P[orr + node]
                for b in range(n):
                    s += P[oP + node * n + b] * x[b]
                for q in range(p):
                    s += P[oQ + node * p + q] * u[q]
                v[c] = s
        dterm[:, :] = 0.0
        term[:] = 0.0
        if kind == 0.0:
            Is, a_, rs = P[row + 5], P[row + 6], P[row + 7]
            vd = v[0] - v[1]
            if rs <= 0.0:
                e = np.exp(vd / a_)
                i_d, g = Is * (e - 1.0), Is * e / a_
            else:
                w = lambertw_exp(np.log(Is * rs / a_) + (vd + Is * rs) / a_)
                i_d = a_ * w / rs - Is
                g = (i_d + Is) / (a_ + rs * (i_d + Is))
            if vd - rs * i_d < -3.0 * a_:                  # SPICE's reverse law (devices.py)
                vj = vd
                for _ in range(3 if rs > 0.0 else 1):
                    arg = (3.0 * a_ / (vj * np.e)) ** 3
                    vj = vd + rs * Is * (1.0 + arg)
                arg = (3.0 * a_ / (vj * np.e)) ** 3
                i_d = -Is * (1.0 + arg)
                gj = 3.0 * Is * arg / vj
                g = gj / (1.0 + rs * gj)
            term[0], term[1] = i_d, -i_d
            dterm[0, 0], dterm[0, 1] = g, -g
            dterm[1, 0], dterm[1, 1] = -g, g
            t0, t1, t2 = 0, 1, -1
        elif kind == 1.0 or kind == 2.0:
            sign = 1.0 if kind == 1.0 else -1.0
            I_ES, I_CS, aF, aR, VT = P[row + 5], P[row + 6], P[row + 7], P[row + 8], P[row + 9]
            eF = np.exp(sign * (v[1] - v[2]) / VT)
            eR = np.exp(sign * (v[1] - v[0]) / VT)
            fF, fR = I_ES * (eF - 1.0), I_CS * (eR - 1.0)
            gF, gR = I_ES * eF / VT, I_CS * eR / VT
            # currents into collector, base and emitter; by (v_c, v_b, v_e) through
            # v_be = sign (v_b - v_e) and v_bc = sign (v_b - v_c): the signs cancel
            term[0] = sign * (aF * fF - fR)
            term[1] = sign * ((1.0 - aF) * fF + (1.0 - aR) * fR)
            term[2] = sign * (-fF + aR * fR)
            dterm[0, 0], dterm[0, 1], dterm[0, 2] = gR, aF * gF - gR, -aF * gF
            dterm[1, 0] = -(1.0 - aR) * gR
            dterm[1, 1] = (1.0 - aF) * gF + (1.0 - aR) * gR
            dterm[1, 2] = -(1.0 - aF) * gF
            dterm[2, 0], dterm[2, 1], dterm[2, 2] = -aR * gR, -gF + aR * gR, gF
            t0, t1, t2 = 0, 1, 2
        elif kind == 5.0 or kind == 6.0:                  # level 1 (estim.spice.level1)
            pm = 1.0 if kind == 5.0 else -1.0
            vto, beta, lam, gam, phi = (P[row + 5], P[row + 6], P[row + 7], P[row + 8],
                                        P[row + 9])
            vd, vg, vs, vb = pm * v[0], pm * v[1], pm * v[2], pm * v[3]
            rev = vd < vs
            if rev:
                vd, vs = vs, vd
            vgs, vds, vbs = vg - vs, vd - vs, vb - vs
            root = np.sqrt(phi)
            if vbs <= 0.0:
                sarg = np.sqrt(max(phi - vbs, 0.0))
                dsarg = -0.5 / sarg
            else:
                sarg = max(0.0, root - vbs / (2 * root))
                dsarg = -0.5 / root if sarg > 0.0 else 0.0
            vgst = vgs - vto - gam * (sarg - root)
            grow = 1.0 + lam * vds
            F, Fg, Fd = 0.0, 0.0, 0.0
            if vgst > 0.0 and vds < vgst:
                F = beta * vds * (vgst - vds / 2) * grow
                Fg = beta * vds * grow
                Fd = beta * (vgst - vds) * grow + beta * lam * vds * (vgst - vds / 2)
            elif vgst > 0.0:
                F = beta / 2 * vgst * vgst * grow
                Fg = beta * vgst * grow
                Fd = beta / 2 * lam * vgst * vgst
            # d(current)/d(drain, gate, source, bulk) in the mode's own order
            gd_, gg_, gs_, gb_ = Fd, Fg, -Fd + Fg * (-1.0 + gam * dsarg), -Fg * gam * dsarg
            if rev:
                term[0], term[1] = -pm * F, pm * F
                dterm[0, 0], dterm[0, 1], dterm[0, 2], dterm[0, 3] = -gs_, -gg_, -gd_, -gb_
            else:
                term[0], term[1] = pm * F, -pm * F
                dterm[0, 0], dterm[0, 1], dterm[0, 2], dterm[0, 3] = gd_, gg_, gs_, gb_
            for c in range(4):
                dterm[1, c] = -dterm[0, c]
            t0, t1, t2 = 0, 2, -1
        elif kind == 7.0 or kind == 8.0:                  # Gummel-Poon (spice/gummel_poon.py)
            sign = 1.0 if kind == 7.0 else -1.0
            Is_, bf, br, nf, nr = P[row + 5], P[row + 6], P[row + 7], P[row + 8], P[row + 9]
            ova, ovb, oik, oikr = P[row + 10], P[row + 11], P[row + 12], P[row + 13]
            ise, ne, isc, nc_, vt = (P[row + 14], P[row + 15], P[row + 16], P[row + 17],
                                     P[row + 18])
            vbe, vbc = sign * (v[1] - v[2]), sign * (v[1] - v[0])
            ef, er = np.exp(vbe / (nf * vt)), np.exp(vbc / (nr * vt))
            ibe, gbe = Is_ * (ef - 1.0), Is_ * ef / (nf * vt)
            ibc, gbc = Is_ * (er - 1.0), Is_ * er / (nr * vt)
            ele, elc = np.exp(vbe / (ne * vt)), np.exp(vbc / (nc_ * vt))
            ile, gle = ise * (ele - 1.0), ise * ele / (ne * vt)
            ilc, glc = isc * (elc - 1.0), isc * elc / (nc_ * vt)
            q1 = 1.0 / (1.0 - ova * vbc - ovb * vbe)
            if oik == 0.0 and oikr == 0.0:
                qb, dqbe, dqbc = q1, q1 * q1 * ovb, q1 * q1 * ova
            else:
                root = np.sqrt(max(1.0 + 4.0 * (oik * ibe + oikr * ibc), 0.0))
                qb = q1 * (1.0 + root) / 2.0
                dq2 = q1 / root if root > 0.0 else 0.0
                dqbe = (1.0 + root) / 2.0 * q1 * q1 * ovb + dq2 * oik * gbe
                dqbc = (1.0 + root) / 2.0 * q1 * q1 * ova + dq2 * oikr * gbc
            it = (ibe - ibc) / qb
            dic_be = gbe / qb - it / qb * dqbe
            dic_bc = -gbc / qb - it / qb * dqbc - gbc / br - glc
            ic = it - ibc / br - ilc
            ib = ibe / bf + ile + ibc / br + ilc
            dib_be, dib_bc = gbe / bf + gle, gbc / br + glc
            # into collector, base and emitter, by (v_c, v_b, v_e): the signs cancel
            term[0], term[1], term[2] = sign * ic, sign * ib, -sign * (ic + ib)
            dterm[0, 0], dterm[0, 1], dterm[0, 2] = -dic_bc, dic_be + dic_bc, -dic_be
            dterm[1, 0], dterm[1, 1], dterm[1, 2] = -dib_bc, dib_be + dib_bc, -dib_be
            for c in range(3):
                dterm[2, c] = -(dterm[0, c] + dterm[1, c])
            t0, t1, t2 = 0, 1, 2
        else:
            UT, VT0, eta, Is, law = P[row + 5], P[row + 6], P[row + 7], P[row + 8], P[row + 9]
            pm = 1.0 if kind == 3.0 else -1.0              # a PMOS: -I_n(-v), same gradient
            for c in range(4):
                v[c] = pm * v[c]
            if law == 3.0:                                 # taylor_conduction (eq 3.7)
                xr = VT0 / (eta * UT)
                c0 = 1 - xr + xr**2 / 2 - xr**3 / 6
                c1 = (1 - xr + xr**2 / 2) / (eta * UT)
                k_, q_ = Is / UT, 1 / (2 * UT)
                vd, vg, vs, vb = v[0], v[1], v[2], v[3]
                i_ds = k_ * (c0 * ((vd - vs) + q_ * (vs**2 - vd**2 - 2 * (vs * vb - vd * vb)))
                             + c1 * (vg * vd - vb * vd - vg * vs + vb * vs))
                dterm[0, 0] = k_ * (c0 * (1 + q_ * (2 * vb - 2 * vd)) + c1 * (vg - vb))
                dterm[0, 1] = k_ * c1 * (vd - vs)
                dterm[0, 2] = k_ * (c0 * (-1 + q_ * (2 * vs - 2 * vb)) + c1 * (vb - vg))
                dterm[0, 3] = k_ * (c0 * q_ * 2 * (vd - vs) + c1 * (vs - vd))
            elif law == 4.0:                               # taylor_saturation (eq 3.13)
                vgs = v[1] - v[2]
                a1 = 1 / UT - VT0 / UT**2
                i_ds = Is * ((1 - VT0 / UT + VT0**2 / UT**2) + vgs * a1 + vgs**2 / (2 * UT**2))
                dterm[0, 1] = Is * (a1 + vgs / UT**2)
                dterm[0, 2] = -dterm[0, 1]
            else:
                vp = (v[1] - v[3] - VT0) / eta
                a_s = (vp - (v[2] - v[3])) / (2 * UT)
                a_d = (vp - (v[0] - v[3])) / (2 * UT)
                if law == 0.0:                             # EKV
                    sp_s = max(a_s, 0.0) + np.log1p(np.exp(-abs(a_s)))
                    sp_d = max(a_d, 0.0) + np.log1p(np.exp(-abs(a_d)))
                    dFs = 2 * sp_s * 0.5 * (1.0 + np.tanh(0.5 * a_s)) / (2 * UT)
                    dFd = 2 * sp_d * 0.5 * (1.0 + np.tanh(0.5 * a_d)) / (2 * UT)
                    i_ds = Is * (sp_s * sp_s - sp_d * sp_d)
                else:                                      # weak inversion (eqs 3.6, 3.12)
                    e_s = np.exp(2 * a_s)
                    e_d = np.exp(2 * a_d) if law == 1.0 else 0.0
                    dFs, dFd = 2 * e_s / (2 * UT), 2 * e_d / (2 * UT)
                    i_ds = Is * (e_s - e_d)
                dterm[0, 0], dterm[0, 1] = Is * dFd, Is * (dFs - dFd) / eta
                dterm[0, 2], dterm[0, 3] = -Is * dFs, Is * (dFs - dFd) * (1 - 1 / eta)
            term[0], term[1] = pm * i_ds, -pm * i_ds
            for c in range(4):
                dterm[1, c] = -dterm[0, c]
            t0, t1, t2 = 0, 2, -1
        for t_ in range(3):
            slot = t0 if t_ == 0 else (t1 if t_ == 1 else t2)
            if slot < 0:
                continue
            at = int(P[row + 1 + slot])
            i1, i2 = int(P[orow + at]), int(P[ocrow + at])
            if i1 < 0 and i2 < 0:
                continue
            for b in range(n):
                grad[b] = 0.0
            for c in range(4):
                g = dterm[t_, c]
                node = int(P[row + 1 + c])
                if g == 0.0 or node < 0:
                    continue
                for b in range(n):
                    grad[b] += g * P[oP + node * n + b]
            for i in (i1, i2):
                if i < 0:
                    continue
                cur[i, n] += term[t_]
                for b in range(n):
                    cur[i, b] += grad[b]
    for a in range(k):
        for j in range(nc):
            w = P[oF + a * nc + j]
            if w != 0.0:
                for b in range(n + 1):
                    cur[a, b] += w * cur[k + j, b]
    for a in range(k):
        s = 0.0
        for i in range(k):
            s += P[oM + a * k + i] * cur[i, n]
        f[a] = s
        for b in range(n):
            s = 0.0
            for i in range(k):
                s += P[oM + a * k + i] * cur[i, b]
            J[a, b] = s
    for a in range(k, n):
        f[a] = cur[kc + a - k, n]
        for b in range(n):
            J[a, b] = cur[kc + a - k, b]


mosfet = jit(_mosfet)
diffamp = jit(_diffamp)
expanded = jit(_expanded)
lambertw_exp = jit(_lambertw_exp)
netlist = jit(_netlist)


def _evaluate(kind, x, u, P, f, J):
    if kind == MOSFET:
        mosfet(x, u, P, f, J)
    elif kind == DIFFAMP:
        diffamp(x, u, P, f, J)
    elif kind == EXPANDED:
        expanded(x, u, P, f, J)
    else:
        netlist(x, u, P, f, J)


evaluate = jit(_evaluate)
