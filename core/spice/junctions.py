"""A diode's junction capacitance, as SPICE's diode model stores charge (ngspice's
``dioload.c``, at the nominal temperature): the depletion capacitance of ``cjo vj m fc``
and the diffusion capacitance ``tt g(v)``,

    C(v) = cjo (1 - v/vj)^-m                                   v <  fc vj
         = cjo / F2 (F3 + m v / vj)                            v >= fc vj
           + tt dI/dv,          F2 = (1 - fc)^(1 + m),  F3 = 1 - fc (1 + m),

the two depletion branches meeting in value and slope at ``fc vj``. In a netlist the
capacitance joins the nodal capacitance matrix between the diode's nodes, so the drift is
``C(x)^-1`` times the currents (:class:`estim.spice.netlist_model.NetlistModel`). A diode
with ``rs`` and a capacitance is refused: its capacitance sits at the junction behind
``rs``, a node estim's closed form for ``rs`` eliminates (give ``rs`` as a resistor); so
is ``tt`` without ``cjo`` (the capacitance would vanish in reverse bias and leave the
node's row of ``C`` empty).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.spice.devices import DIODE, DIODE_VT, REVERSE_KNEE, diode, diode_reverse
from estim.spice.parser import Element, NetlistError

CHARGE = ("cjo", "vj", "m", "tt", "fc")
"""A diode ``.model``'s charge parameters (defaults in :data:`estim.spice.devices.DIODE`)."""


def capacitive(p: dict) -> bool:
    """Whether a diode of ``.model`` parameters ``p`` stores charge."""
    return p.get("cjo", 0.0) > 0 or p.get("tt", 0.0) > 0


def junction_capacitors(netlist) -> list[Element]:
    """Each charge-storing diode's zero-bias capacitance ``cjo`` as a capacitor element
    (``D1.cjo``, anode to cathode): it makes the diode's nodes states and stands for the
    diode in the constant part of ``C``; the model adds ``C(v) - cjo`` at each point. A
    ``.model`` whose charge parameters estim cannot take is refused by name."""
    caps = []
    for e in netlist.elements:
        model = netlist.models.get(e.ref) if e.kind == "d" else None
        if model is None or model.type != "d":
            continue
        p = {**DIODE, **model.params}
        where = (netlist.source, model.line)
        for key in ("cjo", "tt"):
            if p[key] < 0:
                raise NetlistError(*where, f".model {model.name}: {key} {p[key]:g}; "
                                   "expected 0 or more")
        if not capacitive(p):
            continue
        if p["vj"] <= 0 or not 0 <= p["m"] < 1 or not 0 <= p["fc"] < 1:
            raise NetlistError(*where, f".model {model.name}: vj {p['vj']:g}, m {p['m']:g}, "
                               f"fc {p['fc']:g}; expected vj > 0, 0 <= m < 1, 0 <= fc < 1")
        if p["rs"] > 0:
            raise NetlistError(*where, f".model {model.name}: rs with a junction "
                               f"capacitance ({e.name}); estim eliminates the node between "
                               "rs and the junction, where the capacitance sits: give rs as a "
                               "resistor of its own and the .model rs=0")
        if p["cjo"] == 0:
            raise NetlistError(*where, f".model {model.name}: tt without cjo; the "
                               "capacitance would vanish in reverse bias: give cjo too")
        caps.append(Element("c", f"{e.name}.cjo", e.nodes[:2], p["cjo"], line=e.line))
    return caps


def capacitance(v, p: dict) -> tuple[np.ndarray, np.ndarray]:
    """The junction capacitance at junction voltage ``v`` and its derivative in ``v``
    (the diode has ``rs = 0``)."""
    v = np.asarray(v, float)
    cjo, vj, m, fc, tt = p["cjo"], p["vj"], p["m"], p["fc"], p["tt"]
    below = v < fc * vj
    arg = np.where(below, 1 - v / vj, 1.0)
    sarg = arg ** -m
    f2, f3 = (1 - fc) ** (1 + m), 1 - fc * (1 + m)
    C = np.where(below, cjo * sarg, cjo / f2 * (f3 + m * v / vj))
    dC = np.where(below, cjo * m / vj * sarg / arg, cjo / f2 * m / vj)
    if tt:
        a = p["n"] * DIODE_VT
        _, g = diode(v, {**p, "rs": 0.0})
        reverse = v < -REVERSE_KNEE * a
        dg = np.where(reverse, diode_reverse(np.where(reverse, v, -REVERSE_KNEE * a - 1.0),
                                             p["is"], a, 0.0)[2], g / a)
        C, dC = C + tt * g, dC + tt * dg
    return C, dC


@dataclass(frozen=True)
class Junction:
    """A charge-storing diode in a model: its anode and cathode (node numbers), its
    ``.model`` parameters, the KCL rows its charge current leaves (``+1`` the anode's,
    ``-1`` the cathode's, ``(k,)``) and its voltage's gradient in the states ``(n,)``."""

    a: int
    b: int
    p: dict
    rows: np.ndarray
    grad: np.ndarray


def junction_rows(model) -> list[Junction]:
    """The model's charge-storing diodes (:attr:`estim.spice.circuit.Circuit.junctions`);
    one whose voltage follows an input or an inductor's current is refused by name (its
    charge current would need their slope)."""
    c = model.circuit
    k = len(c.state_nodes)
    out = []
    for e in c.junctions:
        _, p, (a, b) = model._device_of[e.name]
        grad = model._P[a] - model._P[b]
        if np.any(grad[k:]) or np.any(model._Q[a] - model._Q[b]):
            raise NetlistError(c.netlist.source, e.line, f"{e.name}: its junction "
                               "capacitance's voltage follows an input or an inductor's "
                               "current, whose slope its charge current would need; put a "
                               "resistor between them")
        rows = np.zeros(k)
        for node, sign in ((a, 1.0), (b, -1.0)):
            if 0 <= model._rowmap[node] < k:
                rows[model._rowmap[node]] += sign
        out.append(Junction(a, b, p, rows, grad))
    return out


def capacitance_matrix(model, V: np.ndarray, values: list | None = None) -> np.ndarray:
    """The nodal capacitance matrix at node voltages ``V (..., nodes)``: the circuit's
    constant one (each junction at ``cjo``) plus ``C(v) - cjo`` of each junction
    (``values``: each junction's :func:`capacitance` there, if known)."""
    C = np.broadcast_to(model.circuit.C, V.shape[:-1] + model.circuit.C.shape).copy()
    k = C.shape[-1]
    values = values or [capacitance(V[..., j.a] - V[..., j.b], j.p) for j in model._junctions]
    for j, (cj, _) in zip(model._junctions, values, strict=True):
        C += (cj - j.p["cjo"])[..., None, None] * np.outer(j.rows, j.grad[:k])
    return C


def charged_drift(model, out: np.ndarray, d_out: np.ndarray,
                  V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The node states' drift ``x' = -C(x)^-1 (currents out)`` and its Jacobian
    ``-C^-1 (d out/dx + sum_j C_j'(v_j) (grad_j . x') rows_j grad_j^T)`` (the derivative of
    ``C(x) x' = -out``)."""
    values = [capacitance(V[..., j.a] - V[..., j.b], j.p) for j in model._junctions]
    C = capacitance_matrix(model, V, values)
    k = C.shape[-1]
    dxdt = -np.linalg.solve(C, out[..., None])[..., 0]
    slope = d_out.copy()
    for j, (_, dc) in zip(model._junctions, values, strict=True):
        s = dc * (dxdt @ j.grad[:k])
        slope += s[..., None, None] * np.outer(j.rows, j.grad)
    return dxdt, -np.linalg.solve(C, slope)
