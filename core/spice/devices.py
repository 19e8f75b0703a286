"""The device laws of a netlist's ``.model`` lines, with their default parameters: Shockley
diodes with series resistance (``d``: ``is n rs``; closed form by the Lambert W function),
Ebers-Moll NPN/PNP (``npn``, ``pnp``; :mod:`estim.models.devices.ebers_moll`), EKV NMOS
(``nmos``; the laws of :mod:`estim.models.mosfet_ekv`, ``law`` the index in
:data:`NMOS_LAWS`) and its mirror, the PMOS (``pmos``, :func:`mosfet`)."""

from __future__ import annotations

import numpy as np

from estim.spice.breakdown import breakdown, breakdown_voltage
from estim.spice.gummel_poon import GUMMEL_POON, is_gummel_poon
from estim.spice.level1 import LEVEL1, level1
from estim.util import lazy

special = lazy.load("scipy.special")
kernels = lazy.load("estim.numerics.kernels")


DIODE_VT = 0.025852
"""The diode's thermal voltage (300 K), as the BJT model's default ``vt``."""


DIODE = {"is": 1e-14, "n": 1.0, "rs": 0.0, "cjo": 0.0, "vj": 1.0, "m": 0.5, "tt": 0.0,
         "fc": 0.5, "bv": 0.0, "ibv": 1e-3, "nbv": 0.0, "eg": 1.11, "xti": 3.0}
"""A diode ``.model``'s parameters and SPICE's defaults (the charge ones:
:mod:`estim.spice.junctions`; ``bv`` 0 for none and ``nbv`` 0 for ``n``:
:mod:`estim.spice.breakdown`; the temperature terms ``eg xti`` have no effect at the
nominal temperature, where estim and its ngspice decks run)."""


def diode_params(params: dict) -> dict:
    """A diode ``.model``'s parameters with the defaults, and ``xbv``, the fitted
    breakdown voltage, where it gives ``bv``."""
    p = {**DIODE, **params}
    if p["bv"] > 0:
        p["xbv"] = breakdown_voltage(p, DIODE_VT)
    return p


BJT = {"ies": 1e-14, "alpha_f": 0.99, "alpha_r": 0.5, "vt": 0.025852, "ics": None}


EKV = {"u_t": 0.0256, "v_t0": 0.5, "eta": 1.0, "i_0": 1e-9, "w_l": 1.0, "law": 0.0}


NMOS_LAWS = ("ekv", "weak_inversion", "weak_saturation", "taylor_conduction",
             "taylor_saturation")
"""The drain-current laws of an ``nmos`` ``.model``'s ``law`` (its index here): those of
:mod:`estim.models.mosfet_ekv` (``drain_current``), so that a filter can model the
transistor with the thesis' approximations as the hand-written model's filters do (D77)."""


DEFAULTS = {"d": DIODE, "npn": BJT, "pnp": BJT, "nmos": EKV, "pmos": EKV}


def model_defaults(model) -> dict:
    """The parameters a ``.model`` may give and their defaults: a MOSFET with ``level``
    (1 only) takes SPICE's level-1 parameters (:mod:`estim.spice.level1`), else estim's EKV
    ones; a BJT that gives SPICE's (``is bf ...``) the Gummel-Poon ones
    (:mod:`estim.spice.gummel_poon`), else estim's Ebers-Moll ones."""
    if model.type in ("nmos", "pmos") and "level" in model.params:
        return LEVEL1
    if model.type in ("npn", "pnp") and is_gummel_poon(model.params):
        return GUMMEL_POON
    return DEFAULTS[model.type]


def collector_saturation(p: dict) -> float:
    """The collector junction's saturation current: the ``.model``'s ``ics`` where given
    (``ics=0``: no collector junction, the base-emitter-diode law of eqs 2.48-2.51), else by
    reciprocity ``alpha_f ies / alpha_r`` (the thesis gives neither; docs/deviations.md D23)."""
    return p["alpha_f"] * p["ies"] / p["alpha_r"] if p.get("ics") is None else p["ics"]


REVERSE_KNEE = 3.0
"""SPICE's diode law turns to its reverse form below ``-3 n V_T`` (ngspice's dioload.c):
``i = -Is (1 + (3 n V_T / (e v))^3)``, which meets Shockley's law there in value and slope."""


def diode(vd, p):
    """Shockley diode with series resistance: current and conductance. With ``rs > 0`` the
    junction voltage is eliminated in closed form: ``i = a W(b e^{(v + Is rs)/a}) / rs - Is``
    with ``a = n V_T``, ``b = Is rs / a`` (Lambert W). Below the knee (a junction voltage
    under ``-3 a``) SPICE's reverse law instead (:data:`REVERSE_KNEE`), and below ``-xbv``
    its breakdown law where ``p`` has ``xbv`` (:func:`diode_params`,
    :mod:`estim.spice.breakdown`)."""
    a = p["n"] * DIODE_VT
    Is, rs = p["is"], p["rs"]
    if rs <= 0:
        with np.errstate(over="ignore"):
            e = np.exp(vd / a)
        i, g = Is * (e - 1), Is * e / a
    else:
        z = np.log(Is * rs / a) + (vd + Is * rs) / a           # log of W's argument
        w = np.where(z < 500, np.real(special.lambertw(np.exp(np.minimum(z, 500)))),
                     z - np.log(np.maximum(z, 1.0)))
        i = a * w / rs - Is
        g = (i + Is) / (a + rs * (i + Is))
    vd = np.asarray(vd, float)
    reverse = vd - rs * i < -REVERSE_KNEE * a
    if np.any(reverse):
        ir, gr, _ = diode_reverse(np.where(reverse, vd, -REVERSE_KNEE * a - 1.0), Is, a, rs)
        i, g = np.where(reverse, ir, i), np.where(reverse, gr, g)
    if p.get("xbv") is not None:
        ib, gb, _, vj = breakdown(vd, p, DIODE_VT)
        down = vj < -p["xbv"]
        i, g = np.where(down, ib, i), np.where(down, gb, g)
    return i, g


def diode_reverse(vd, Is: float, a: float, rs: float):
    """SPICE's reverse law below the knee: the current, the conductance and its derivative
    at terminal voltage ``vd`` (the junction's ``vj = vd - rs i``, by a fixed point that
    converges at once: ``rs Is`` is volts times 1e-12 or less)."""
    vj = np.asarray(vd, float)
    for _ in range(3 if rs > 0 else 1):
        arg = (REVERSE_KNEE * a / (vj * np.e)) ** 3
        i = -Is * (1 + arg)
        vj = vd - rs * i
    arg = (REVERSE_KNEE * a / (vj * np.e)) ** 3
    i = -Is * (1 + arg)
    gj = 3 * Is * arg / vj
    dgj = -4 * gj / vj
    return i, gj / (1 + rs * gj), dgj / (1 + rs * gj) ** 3


def diode_slope(vd, cur, g, p):
    """The derivative of :func:`diode`'s conductance at ``vd`` (its current ``cur`` and
    conductance ``g``, one point)."""
    aa = p["n"] * DIODE_VT
    if p.get("xbv") is not None and vd - p["rs"] * cur < -p["xbv"]:
        return float(breakdown(vd, p, DIODE_VT)[2])
    if vd - p["rs"] * cur < -REVERSE_KNEE * aa:
        return float(diode_reverse(vd, p["is"], aa, p["rs"])[2])
    y = cur + p["is"]
    return aa * g / (aa + p["rs"] * y) ** 2 if p["rs"] > 0 else g / aa


def mosfet(kind: str, vd, vg, vs, vb, p, second: bool = False):
    """:func:`nmos` (or, for a ``.model`` with ``level``, :func:`estim.spice.level1.level1`)
    for an ``nmos`` device; a ``pmos`` is its mirror, the same law of the negated terminal
    voltages with the current negated, ``I_p(v) = -I_n(-v)`` (so an EKV PMOS's ``v_t0`` is
    the magnitude of the threshold, as the NMOS's is, and a level-1 PMOS's parameters come
    mirrored, :func:`estim.spice.level1.mirrored`; the gradient is the NMOS's at ``-v``, the
    Hessian its negative)."""
    law = level1 if "level" in p else nmos
    if kind == "nmos":
        return law(vd, vg, vs, vb, p, second)
    cur, grad, hess = law(-np.asarray(vd, float), -np.asarray(vg, float),
                          -np.asarray(vs, float), -np.asarray(vb, float), p, second)
    return -cur, grad, -hess


def nmos(vd, vg, vs, vb, p, second: bool = False):
    """The drain-to-source current of an ``nmos`` device by its ``.model``'s ``law``
    (:data:`NMOS_LAWS`, the laws of :meth:`estim.models.mosfet_ekv.MosfetEKV.drain_current`),
    its gradient w.r.t. the drain, gate, source and bulk voltages (last axis), and with
    ``second`` (one point) its 4x4 Hessian."""
    from estim.models.mosfet_ekv import _sigmoid, _softplus

    ut, vt0, eta = p["u_t"], p["v_t0"], p["eta"]
    Is = p["i_0"] * p["w_l"]
    law = NMOS_LAWS[int(p.get("law", 0))]
    vd, vg, vs, vb = np.broadcast_arrays(*(np.asarray(v, float) for v in (vd, vg, vs, vb)))
    hess = np.zeros((4, 4))
    if law == "taylor_conduction":
        xr = vt0 / (eta * ut)
        c0 = 1 - xr + xr**2 / 2 - xr**3 / 6
        c1 = (1 - xr + xr**2 / 2) / (eta * ut)
        k, q = Is / ut, 1 / (2 * ut)
        cur = k * (c0 * ((vd - vs) + q * (vs**2 - vd**2 - 2 * (vs * vb - vd * vb)))
                   + c1 * (vg * vd - vb * vd - vg * vs + vb * vs))
        grad = k * np.stack([c0 * (1 + q * (2 * vb - 2 * vd)) + c1 * (vg - vb),
                             c1 * (vd - vs),
                             c0 * (-1 + q * (2 * vs - 2 * vb)) + c1 * (vb - vg),
                             c0 * q * 2 * (vd - vs) + c1 * (vs - vd)], axis=-1)
        hess = k * np.array([[-2 * c0 * q, c1, 0.0, 2 * c0 * q - c1],
                             [c1, 0.0, -c1, 0.0],
                             [0.0, -c1, 2 * c0 * q, c1 - 2 * c0 * q],
                             [2 * c0 * q - c1, 0.0, c1 - 2 * c0 * q, 0.0]])
        return cur, grad, hess
    if law == "taylor_saturation":
        vgs = vg - vs
        a1 = 1 / ut - vt0 / ut**2
        cur = Is * ((1 - vt0 / ut + vt0**2 / ut**2) + vgs * a1 + vgs**2 / (2 * ut**2))
        d = Is * (a1 + vgs / ut**2)
        zero = np.zeros_like(d)
        c = Is / ut**2
        hess = np.array([[0.0, 0.0, 0.0, 0.0], [0.0, c, -c, 0.0], [0.0, -c, c, 0.0],
                         [0.0, 0.0, 0.0, 0.0]])
        return cur, np.stack([zero, d, -d, zero], axis=-1), hess
    vp = (vg - vb - vt0) / eta
    a_s = (vp - (vs - vb)) / (2 * ut)
    a_d = (vp - (vd - vb)) / (2 * ut)
    ga_s = np.array([0.0, 1 / eta, -1.0, 1 - 1 / eta]) / (2 * ut)
    ga_d = np.array([-1.0, 1 / eta, 0.0, 1 - 1 / eta]) / (2 * ut)
    if law == "ekv" and second:
        d1, d2 = np.zeros(4), np.zeros((4, 4))
        for a_, ga, sign in ((a_s, ga_s, 1.0), (a_d, ga_d, -1.0)):
            sp, sg = np.logaddexp(0.0, a_), 0.5 * (1.0 + np.tanh(0.5 * a_))
            d1 += sign * Is * 2 * sp * sg * ga
            d2 += sign * Is * (2 * sg * sg + 2 * sp * sg * (1 - sg)) * np.outer(ga, ga)
        return Is * (_softplus(a_s) ** 2 - _softplus(a_d) ** 2), d1, d2
    if law == "ekv":
        Fs, Fd = _softplus(a_s) ** 2, _softplus(a_d) ** 2
        dFs = 2 * _softplus(a_s) * _sigmoid(a_s) / (2 * ut)
        dFd = 2 * _softplus(a_d) * _sigmoid(a_d) / (2 * ut)
        cur = Is * (Fs - Fd)
        grad = np.stack([Is * dFd, Is * (dFs - dFd) / eta, -Is * dFs,
                         Is * (dFs - dFd) * (1 - 1 / eta)], axis=-1)
        return cur, grad, hess
    with np.errstate(over="ignore"):
        e_s, e_d = np.exp(2 * a_s), np.exp(2 * a_d)
    if law == "weak_saturation":
        e_d = np.zeros_like(e_d)
    cur = Is * (e_s - e_d)
    grad = Is * (2 * e_s[..., None] * ga_s - 2 * e_d[..., None] * ga_d)
    if second:
        hess = Is * (4 * e_s * np.outer(ga_s, ga_s) - 4 * e_d * np.outer(ga_d, ga_d))
    return cur, grad, hess
