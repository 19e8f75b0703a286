"""SPICE's diode breakdown (ngspice's ``diotemp.c`` and ``dioload.c``, at the nominal
temperature). A diode whose ``.model`` gives ``bv`` conducts below the junction voltage
``-xbv`` by

    i = -is exp(-(xbv + v) / (nbv V_T))                 (``nbv`` defaults to ``n``),

``xbv`` fitted so that the current at ``v = -bv`` is ``ibv`` (default 1 mA): ngspice's
fixed-point iteration ``xbv = bv - nbv V_T ln(ibv / is + 1 - xbv / V_T)``, stopped where
``is (exp((bv - xbv) / (nbv V_T)) - 1 + xbv / V_T)`` is within ``reltol ibv`` of ``ibv``
(:data:`RELTOL`, ngspice's default; where ``ibv < is bv / V_T``, ``xbv = bv``). Where the
iteration converges within its first steps, as it does for a zener's ``ibv`` of
milliamperes, the fit does not depend on ``reltol``, and ngspice's own diode at any
``reltol`` gives the same DC point (tests/test_breakdown.py); where it converges slowly,
estim's fit is that of ngspice's default and ``estim spice`` (which runs ngspice's own
diode at a tighter ``reltol``) shows the difference. With ``rs`` the junction voltage is
``v - rs i``, solved in closed form (Lambert W).
"""

from __future__ import annotations

import math

import numpy as np

from estim.util import lazy

special = lazy.load("scipy.special")

RELTOL = 1e-3
"""ngspice's default ``reltol``, at which its fit of ``xbv`` stops."""


def breakdown_voltage(p: dict, vt: float) -> float:
    """``xbv`` of ``.model`` parameters ``p`` (``bv ibv nbv is n``) as ngspice fits it."""
    bv, cbv, Is = p["bv"], p["ibv"], p["is"]
    a = (p["nbv"] or p["n"]) * vt
    if cbv < Is * bv / vt:
        return bv
    xbv = bv - a * math.log(1 + cbv / Is)
    for _ in range(25):
        xbv = bv - a * math.log(cbv / Is + 1 - xbv / vt)
        if abs(Is * (math.exp((bv - xbv) / a) - 1 + xbv / vt) - cbv) <= RELTOL * cbv:
            break
    return xbv


def breakdown(vd, p: dict, vt: float):
    """The breakdown law at terminal voltage ``vd``: the current, the conductance, its
    derivative, and the junction voltage (``vd - rs i``), on arrays."""
    vd = np.asarray(vd, float)
    a, Is, rs, xbv = (p["nbv"] or p["n"]) * vt, p["is"], p["rs"], p["xbv"]
    if rs > 0:
        z = np.log(rs * Is / a) - (xbv + vd) / a            # log of W's argument
        w = np.where(z < 500, np.real(special.lambertw(np.exp(np.minimum(z, 500)))),
                     z - np.log(np.maximum(z, 1.0)))
        y = a * w / rs
    else:
        with np.errstate(over="ignore"):
            y = Is * np.exp(-(xbv + vd) / a)
    gj = y / a
    return -y, gj / (1 + rs * gj), -(gj / a) / (1 + rs * gj) ** 3, vd + rs * y
