"""SPICE's Gummel-Poon bipolar transistor, its static law (ngspice's ``BJT``, level 1, without
the temperature terms; its junction capacitances are :mod:`estim.spice.junctions`', its
series resistances :mod:`estim.spice.internal_nodes`'): for an NPN with
``v_BE``, ``v_BC`` and ``V_T = kT/q``,

    I_BE = IS (exp(v_BE / (NF V_T)) - 1),      I_BC = IS (exp(v_BC / (NR V_T)) - 1),
    I_LE = ISE (exp(v_BE / (NE V_T)) - 1),     I_LC = ISC (exp(v_BC / (NC V_T)) - 1),
    q_1 = 1 / (1 - v_BC / VAF - v_BE / VAR),   q_2 = I_BE / IKF + I_BC / IKR,
    q_b = q_1 (1 + sqrt(1 + 4 q_2)) / 2        (q_b = q_1 where IKF and IKR are infinite),
    I_C = (I_BE - I_BC) / q_b - I_BC / BR - I_LC,
    I_B = I_BE / BF + I_LE + I_BC / BR + I_LC,          I_E = -(I_C + I_B),

with SPICE's convention that ``VAF``, ``VAR``, ``IKF``, ``IKR`` of 0 (their default) are
infinite. A PNP is the NPN of the negated voltages with its currents negated. With only
``IS``, ``BF`` and ``BR`` it is Ebers-Moll in transport form (``I_ES = IS / alpha_F``,
``alpha_F = BF / (1 + BF)``; tests/test_gummel_poon.py).
"""

from __future__ import annotations

import numpy as np

from estim.models.devices.ebers_moll import TerminalCurrents

GUMMEL_POON = {"is": 1e-16, "bf": 100.0, "br": 1.0, "nf": 1.0, "nr": 1.0, "vaf": 0.0,
               "var": 0.0, "ikf": 0.0, "ikr": 0.0, "ise": 0.0, "ne": 1.5, "isc": 0.0,
               "nc": 2.0, "cje": 0.0, "vje": 0.75, "mje": 0.33, "cjc": 0.0, "vjc": 0.75,
               "mjc": 0.33, "tf": 0.0, "tr": 0.0, "fc": 0.5, "rb": 0.0, "rc": 0.0, "re": 0.0,
               "xtf": 0.0, "vtf": 0.0, "itf": 0.0, "xti": 3.0, "eg": 1.11, "xtb": 0.0}
"""A Gummel-Poon ``.model``'s parameters and SPICE's defaults (0: infinite for ``vaf``,
``var``, ``ikf``, ``ikr``, and for ``vtf``); the junction capacitances' and transit
times' (``cje`` to ``fc``, ``xtf vtf itf``) are :mod:`estim.spice.junctions`', the series
resistances' :mod:`estim.spice.internal_nodes`'; the temperature terms ``xti eg xtb`` have
no effect at the nominal temperature, where estim and its ngspice decks run."""

STATIC = ("is", "bf", "br", "nf", "nr", "vaf", "var", "ikf", "ikr", "ise", "ne", "isc", "nc")
"""The parameters of the static law (the ngspice deck's and the compiled kernel's)."""

DYNAMIC = ("irb", "rbm", "xcjc", "cjs", "vjs", "mjs", "ptf", "kf", "af", "tnom")
"""SPICE BJT parameters outside the law here: refused by name (:func:`check`)."""


def is_gummel_poon(params: dict) -> bool:
    """Whether a ``.model npn/pnp`` gives SPICE's parameters (``is bf ...``) rather than
    estim's Ebers-Moll ones (``ies alpha_f ...``)."""
    return bool(set(params) & (set(GUMMEL_POON) | set(DYNAMIC)))


def base_charge(v_be, v_bc, p: dict, vt: float):
    """``q_b`` of the module's text at ``v_BE``, ``v_BC`` (complex too: the transit charge's
    slopes are taken by the complex step, :func:`estim.spice.junctions.transit_law`)."""
    i_be = p["is"] * (np.exp(v_be / (p["nf"] * vt)) - 1)
    i_bc = p["is"] * (np.exp(v_bc / (p["nr"] * vt)) - 1)
    q1 = 1.0 / (1.0 - inverse(p["vaf"]) * v_bc - inverse(p["var"]) * v_be)
    if not (p["ikf"] or p["ikr"]):
        return q1
    q2 = inverse(p["ikf"]) * i_be + inverse(p["ikr"]) * i_bc
    return q1 * (1.0 + np.sqrt(1.0 + 4.0 * q2)) / 2.0


def inverse(value):
    """SPICE's reading of ``VAF``, ``IKF``, ...: 1 / value, with 0 for a value of 0."""
    value = np.asarray(value, float)
    with np.errstate(divide="ignore"):
        return np.where(value != 0, 1.0 / np.where(value != 0, value, 1.0), 0.0)


def currents(v_be, v_bc, p: dict, vt: float) -> TerminalCurrents:
    """The NPN's currents into collector, emitter and base and their slopes w.r.t. ``v_BE``
    and ``v_BC`` (module docstring), on arrays of any shape."""
    v_be, v_bc = np.asarray(v_be, float), np.asarray(v_bc, float)
    with np.errstate(over="ignore", invalid="ignore"):
        e_f = np.exp(v_be / (p["nf"] * vt))
        e_r = np.exp(v_bc / (p["nr"] * vt))
        e_le = np.exp(v_be / (p["ne"] * vt))
        e_lc = np.exp(v_bc / (p["nc"] * vt))
    i_be, g_be = p["is"] * (e_f - 1), p["is"] * e_f / (p["nf"] * vt)
    i_bc, g_bc = p["is"] * (e_r - 1), p["is"] * e_r / (p["nr"] * vt)
    i_le, g_le = p["ise"] * (e_le - 1), p["ise"] * e_le / (p["ne"] * vt)
    i_lc, g_lc = p["isc"] * (e_lc - 1), p["isc"] * e_lc / (p["nc"] * vt)
    ova, ovb = inverse(p["vaf"]), inverse(p["var"])
    oik, oikr = inverse(p["ikf"]), inverse(p["ikr"])
    q1 = 1.0 / (1.0 - ova * v_bc - ovb * v_be)
    dq1_be, dq1_bc = q1 * q1 * ovb, q1 * q1 * ova
    q2 = oik * i_be + oikr * i_bc
    root = np.sqrt(np.maximum(1.0 + 4.0 * q2, 0.0))
    high = (oik != 0) | (oikr != 0)
    qb = np.where(high, q1 * (1.0 + root) / 2.0, q1)
    with np.errstate(divide="ignore", invalid="ignore"):
        dqb_q2 = np.where(high, q1 / np.where(root > 0, root, 1.0), 0.0)
    dqb_q1 = np.where(high, (1.0 + root) / 2.0, 1.0)
    dqb_be = dqb_q1 * dq1_be + dqb_q2 * oik * g_be
    dqb_bc = dqb_q1 * dq1_bc + dqb_q2 * oikr * g_bc
    i_t = (i_be - i_bc) / qb
    dit_be = g_be / qb - i_t / qb * dqb_be
    dit_bc = -g_bc / qb - i_t / qb * dqb_bc
    bf, br = p["bf"], p["br"]
    i_c = i_t - i_bc / br - i_lc
    i_b = i_be / bf + i_le + i_bc / br + i_lc
    dic_be, dic_bc = dit_be, dit_bc - g_bc / br - g_lc
    dib_be, dib_bc = g_be / bf + g_le, g_bc / br + g_lc
    return TerminalCurrents(I_C=i_c, I_E=-(i_c + i_b), I_B=i_b,
                            dIC_be=dic_be, dIC_bc=dic_bc, dIE_be=-(dic_be + dib_be),
                            dIE_bc=-(dic_bc + dib_bc), dIB_be=dib_be, dIB_bc=dib_bc)
