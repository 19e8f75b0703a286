"""SPICE's level-1 MOSFET (Shichman and Hodges 1968), the static law of ngspice's ``MOS1``
with its junction diodes and capacitances left out: for an NMOS in normal mode
(``v_DS >= 0``),

    V_th = VTO + GAMMA (sqrt(PHI - v_BS) - sqrt(PHI))
    i_D  = 0                                                  v_GS <= V_th
         = beta v_DS (v_GS - V_th - v_DS / 2) (1 + LAMBDA v_DS)   v_DS < v_GS - V_th
         = beta / 2 (v_GS - V_th)^2 (1 + LAMBDA v_DS)             otherwise

with ``beta = KP W / L`` and, for ``v_BS > 0``, ``sqrt(PHI - v_BS)`` replaced by
``max(0, sqrt(PHI) - v_BS / (2 sqrt(PHI)))`` as ngspice does; in reverse mode (``v_DS <
0``) drain and source trade places and the current changes sign. A PMOS is the NMOS of the
negated voltages with ``VTO`` negated, its current negated (SPICE's ``type = -1``).

Its overlap capacitances (``cgso``, ``cgdo`` per metre of width, ``cgbo`` per metre of
length) are linear capacitors from the gate to the source, the drain and the bulk
(:func:`overlap_capacitors`), as ngspice's ``MOS1`` adds them; without ``tox`` its Meyer
gate capacitances are zero, as in ngspice. Its bulk junctions' capacitances ``cbd cbs``
(``pb mj fc``) are :mod:`estim.spice.junctions`'.
"""

from __future__ import annotations

import numpy as np

from estim.spice.parser import Element, NetlistError

LEVEL1 = {"level": 1.0, "vto": 0.0, "kp": 2e-5, "lambda": 0.0, "gamma": 0.0, "phi": 0.6,
          "cgso": 0.0, "cgdo": 0.0, "cgbo": 0.0, "cbd": 0.0, "cbs": 0.0, "pb": 0.8,
          "mj": 0.5, "fc": 0.5}
"""A level-1 ``.model``'s parameters and ngspice's defaults (``level=1`` selects the law)."""

OVERLAP = {"cgso": (2, "w"), "cgdo": (0, "w"), "cgbo": (3, "l")}
"""Each overlap capacitance: the terminal (of drain, gate, source, bulk) it joins to the
gate, and the size it is per metre of."""

DEFAULT_SIZE = {"w": 100e-6, "l": 100e-6}
"""ngspice's width and length of a MOSFET whose line gives none (its ``defw``, ``defl``)."""


def overlap_capacitors(netlist) -> list[Element]:
    """The overlap capacitances of the netlist's level-1 MOSFETs as capacitor elements
    (``M1.cgdo``: ``cgdo`` times the device's width, from its gate to its drain), those
    that are not zero; a device whose ``.model`` is missing or not level 1 has none. A
    negative one is refused."""
    caps = []
    for e in netlist.elements:
        model = netlist.models.get(e.ref) if e.kind == "m" else None
        if model is None or "level" not in model.params:
            continue
        size = {**DEFAULT_SIZE, **dict(e.size)}
        for name, (terminal, per) in OVERLAP.items():
            if model.params.get(name, 0.0) < 0:
                raise NetlistError(netlist.source, model.line, f".model {model.name}: {name} "
                                   f"{model.params[name]:g}; an overlap capacitance is not "
                                   "negative")
            value = model.params.get(name, 0.0) * size[per]
            if value:
                caps.append(Element("c", f"{e.name}.{name}", (e.nodes[1], e.nodes[terminal]),
                                    value, line=e.line))
    return caps


def level1(vd, vg, vs, vb, p: dict, second: bool = False):
    """The drain-to-source current of an NMOS by the level-1 law of ``.model`` parameters
    ``p`` (with the instance's width over length ``w_over_l``, default 1), its gradient
    w.r.t. the drain, gate, source and bulk voltages (last axis) and, with ``second`` (one
    point), its 4x4 Hessian."""
    vd, vg, vs, vb = np.broadcast_arrays(*(np.asarray(v, float) for v in (vd, vg, vs, vb)))
    rev = vd < vs
    d_, s_ = np.where(rev, vs, vd), np.where(rev, vd, vs)
    vgs, vds, vbs = vg - s_, d_ - s_, vb - s_
    vto, phi, gamma, lam = p["vto"], p["phi"], p["gamma"], p["lambda"]
    beta = p["kp"] * p.get("w_over_l", 1.0)
    root = np.sqrt(phi)
    below = vbs <= 0
    with np.errstate(invalid="ignore", divide="ignore"):
        sarg = np.where(below, np.sqrt(np.maximum(phi - vbs, 0.0)),
                        np.maximum(0.0, root - vbs / (2 * root)))
        dsarg = np.where(below, -0.5 / sarg, np.where(sarg > 0, -0.5 / root, 0.0))
        d2sarg = np.where(below, -0.25 / sarg**3, 0.0)
    vgst = vgs - vto - gamma * (sarg - root)
    on = vgst > 0
    lin = on & (vds < vgst)
    sat = on & ~lin
    grow = 1 + lam * vds
    F = np.where(lin, beta * vds * (vgst - vds / 2) * grow,
                 np.where(sat, beta / 2 * vgst**2 * grow, 0.0))
    Fg = np.where(lin, beta * vds * grow, np.where(sat, beta * vgst * grow, 0.0))
    Fd = np.where(lin, beta * (vgst - vds) * grow + beta * lam * vds * (vgst - vds / 2),
                  np.where(sat, beta / 2 * lam * vgst**2, 0.0))
    zero = np.zeros_like(vgst)
    one = np.ones_like(vgst)
    # vgst and vds as functions of (drain, gate, source, bulk) in the mode's own order
    dvgst = np.stack([zero, one, -1 + gamma * dsarg, -gamma * dsarg], axis=-1)
    dvds = np.stack([one, zero, -one, zero], axis=-1)
    grad = Fg[..., None] * dvgst + Fd[..., None] * dvds
    sign = np.where(rev, -1.0, 1.0)
    order = [2, 1, 0, 3]                                   # reverse mode: d and s swapped
    grad = np.where(rev[..., None], -grad[..., order], grad)
    cur = sign * F
    if not second:
        return cur, grad, np.zeros((4, 4))
    Fgg = float(np.where(lin, 0.0, np.where(sat, beta * grow, 0.0)))
    Fgd = float(np.where(lin, beta * (1 + 2 * lam * vds), np.where(sat, beta * lam * vgst,
                                                                    0.0)))
    Fdd = float(np.where(lin, beta * (-1 - lam * vds + 2 * lam * (vgst - vds)), 0.0))
    a, b = dvgst.reshape(4), dvds.reshape(4)
    wb = np.array([0.0, 0.0, -1.0, 1.0])                   # d v_BS
    hess = (Fgg * np.outer(a, a) + Fgd * (np.outer(a, b) + np.outer(b, a))
            + Fdd * np.outer(b, b) + float(Fg) * float(-gamma * d2sarg) * np.outer(wb, wb))
    if bool(rev):
        hess = -hess[np.ix_(order, order)]
    return cur, grad, hess


def mirrored(kind: str, p: dict) -> dict:
    """The NMOS parameters whose law, of the negated voltages and negated, is the ``kind``
    device's: a PMOS's threshold ``VTO`` is negative in SPICE's convention."""
    return {**p, "vto": -p["vto"]} if kind == "pmos" else p
