"""Junction capacitances as SPICE stores charge (ngspice's ``dioload.c`` and
``mos1load.c``, at the nominal temperature): a diode's depletion capacitance of ``cjo vj m
fc`` and its diffusion capacitance ``tt g(v)``,

    C(v) = cjo (1 - v/vj)^-m                                   v <  fc vj
         = cjo / F2 (F3 + m v / vj)                            v >= fc vj
           + tt dI/dv,          F2 = (1 - fc)^(1 + m),  F3 = 1 - fc (1 + m),

the two depletion branches meeting in value and slope at ``fc vj``; a Gummel-Poon BJT's
base-emitter (``cje vje mje tf``) and base-collector (``cjc vjc mjc tr``) junctions by the
same law (:func:`_bjt_charges`); a level-1 MOSFET's
bulk-drain and bulk-source junctions by the same depletion law, ``cbd`` and ``cbs`` for
``cjo``, ``pb`` for ``vj`` and ``mj`` for ``m`` (their diodes conduct nothing here, as
estim's level 1 and the ngspice deck have ``is=0``). In a netlist each capacitance joins
the nodal capacitance matrix between its two nodes, so the drift is ``C(x)^-1`` times the
currents (:class:`estim.spice.netlist_model.NetlistModel`). A diode's ``rs`` beside a
capacitance is a resistor to an internal node by then (:mod:`estim.spice.internal_nodes`),
as the capacitance sits at the junction behind it. ``tt`` without ``cjo`` is refused (the
capacitance would vanish in reverse bias and leave the node's row of ``C`` empty).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from estim.spice.breakdown import breakdown
from estim.spice.devices import (
    DIODE,
    DIODE_VT,
    REVERSE_KNEE,
    diode,
    diode_params,
    diode_reverse,
)
from estim.spice.gummel_poon import GUMMEL_POON, base_charge, inverse, is_gummel_poon
from estim.spice.level1 import LEVEL1
from estim.spice.parser import Element, NetlistError


@dataclass(frozen=True)
class Charge:
    """One junction capacitance of a netlist: its name (``d1.cjo``, ``m1.cbd``), its
    device, its anode and cathode, and its law's parameters (``cjo vj m fc tt``, with the
    diode's ``is n`` for ``tt``)."""

    name: str
    device: Element
    nodes: tuple[str, str]
    p: dict

    def capacitor(self) -> Element:
        """The zero-bias capacitance as a capacitor element: it makes the two nodes states
        and stands for the junction in the constant part of ``C``."""
        return Element("c", self.name, self.nodes, self.p["cjo"], line=self.device.line)


def _checked(p: dict, keys: tuple[str, ...], netlist, model) -> None:
    """Refuse a negative capacitance or transit time, or a grading, potential or ``fc``
    out of the law's range, naming the ``.model`` and its keys."""
    where = (netlist.source, model.line)
    for key in keys[:2]:
        if p[key] < 0:
            raise NetlistError(*where, f".model {model.name}: {key} {p[key]:g}; "
                               "expected 0 or more")
    vj, m, fc = (p[k] for k in keys[2:])
    if vj <= 0 or not 0 <= m < 1 or not 0 <= fc < 1:
        raise NetlistError(*where, f".model {model.name}: {keys[2]} {vj:g}, {keys[3]} {m:g}, "
                           f"fc {fc:g}; expected {keys[2]} > 0, 0 <= {keys[3]} < 1, "
                           "0 <= fc < 1")


def junction_capacitors(netlist) -> list[Charge]:
    """Every junction capacitance of the netlist's diodes, Gummel-Poon BJTs and level-1
    MOSFETs that is not zero. A ``.model`` whose charge (or a diode's breakdown)
    parameters estim cannot take is refused by name."""
    out = []
    for e in netlist.elements:
        model = netlist.models.get(e.ref) if e.kind in "dqm" else None
        if model is None:
            continue
        if e.kind == "d" and model.type == "d":
            raw = {**DIODE, **model.params}
            if ("bv" in model.params and raw["bv"] <= 0) or raw["ibv"] <= 0 or raw["nbv"] < 0:
                raise NetlistError(netlist.source, model.line, f".model {model.name}: bv "
                                   f"{raw['bv']:g}, ibv {raw['ibv']:g}, nbv {raw['nbv']:g}; "
                                   "expected bv > 0, ibv > 0, nbv >= 0 (0: n)")
            p = diode_params(model.params)
            _checked(p, ("cjo", "tt", "vj", "m", "fc"), netlist, model)
            if p["cjo"] == 0 and p["tt"] == 0:
                continue
            if p["cjo"] == 0:
                raise NetlistError(netlist.source, model.line, f".model {model.name}: tt "
                                   "without cjo; the capacitance would vanish in reverse "
                                   "bias: give cjo too")
            out.append(Charge(f"{e.name}.cjo", e, e.nodes[:2], p))
        elif e.kind == "q" and model.type in ("npn", "pnp") and is_gummel_poon(model.params):
            out += _bjt_charges(e, model, netlist)
        elif e.kind == "m" and "level" in model.params:
            q = {**LEVEL1, **model.params}
            _checked(q, ("cbd", "cbs", "pb", "mj", "fc"), netlist, model)
            law = {"vj": q["pb"], "m": q["mj"], "fc": q["fc"], "tt": 0.0}
            drain, _, source, bulk = e.nodes
            for key, node in (("cbd", drain), ("cbs", source)):
                if q[key] > 0:
                    out.append(Charge(f"{e.name}.{key}", e, (bulk, node), {**law, "cjo": q[key]}))
    return out


def _bjt_charges(e, model, netlist) -> list[Charge]:
    """A Gummel-Poon BJT's base-emitter (``cje vje mje``, diffusion ``tf`` of the forward
    current ``is (exp(v_BE / (nf V_T)) - 1)``) and base-collector (``cjc vjc mjc``, ``tr`` of
    the reverse current) junction capacitances; for a PNP the junctions point the other
    way. Beside ``vaf var ikf ikr`` or ``xtf`` the forward transit charge depends on
    ``v_BC`` too (:func:`transit_charge`): a charge of its own, ``q1.tf``, of both
    voltages (a transcapacitance)."""
    q = {**GUMMEL_POON, **model.params}
    c, b, em = e.nodes[:3]
    out = []
    for name, tt, n, node in (("cje", "tf", "nf", em), ("cjc", "tr", "nr", c)):
        vj, m = f"v{name[1:]}", f"m{name[1:]}"
        _checked(q, (name, tt, vj, m, "fc"), netlist, model)
        if q[name] == 0 and q[tt] == 0:
            continue
        if q[name] == 0:
            raise NetlistError(netlist.source, model.line, f".model {model.name}: {tt} "
                               f"without {name}; the capacitance would vanish in reverse "
                               f"bias: give {name} too")
        law = {"cjo": q[name], "vj": q[vj], "m": q[m], "fc": q["fc"], "tt": q[tt],
               "is": q["is"], "n": q[n], "rs": 0.0}
        ends = (b, node) if model.type == "npn" else (node, b)
        if tt == "tf" and q["tf"] and any(q[k] for k in ("vaf", "var", "ikf", "ikr", "xtf")):
            law["tt"] = 0.0                 # the transit charge on its own: two voltages
            controls = (ends, (b, c) if model.type == "npn" else (c, b))
            out.append(Charge(f"{e.name}.tf", e, ends,
                              {**q, "transit": True, "controls": controls, "cjo": 0.0}))
        out.append(Charge(f"{e.name}.{name}", e, ends, law))
    return out


def capacitance(v, p: dict) -> tuple[np.ndarray, np.ndarray]:
    """The junction capacitance at junction voltage ``v`` and its derivative in ``v``
    (a diode's has ``rs = 0``)."""
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
        if p.get("xbv") is not None:                    # breakdown: ngspice's tt g there too
            _, _, dgb, vj = breakdown(v, {**p, "rs": 0.0}, DIODE_VT)
            dg = np.where(vj < -p["xbv"], dgb, dg)
        C, dC = C + tt * g, dC + tt * dg
    return C, dC


@dataclass(frozen=True)
class Junction:
    """A charge in a model: its controlling voltages' node numbers (``(+, -)`` each), its
    law (:func:`law_of`: the charge's slopes in those voltages ``(..., r)`` and its second
    slopes ``(..., r, r)``), the capacitance the constant ``C`` holds for it on its first
    voltage, the KCL rows its current leaves (``+1`` the anode's, ``-1`` the cathode's,
    ``(k,)``) and its voltages' gradients in the states ``(r, n)``."""

    nodes: tuple
    law: object
    held: float
    rows: np.ndarray
    grads: np.ndarray


def _one_voltage(v: np.ndarray, p: dict) -> tuple[np.ndarray, np.ndarray]:
    """:func:`capacitance` of ``v (..., 1)`` as a slope ``(..., 1)`` and a second slope
    ``(..., 1, 1)``."""
    c, dc = capacitance(v[..., 0], p)
    return c[..., None], dc[..., None, None]


def law_of(ch: Charge):
    """A :class:`Charge`'s law as :class:`Junction` takes it: one voltage, ``C(v)`` and
    ``C'(v)`` (:func:`capacitance`); a BJT's transit charge, two (:func:`transit_law`)."""
    return functools.partial(transit_law if "transit" in ch.p else _one_voltage, p=ch.p)


def transit_charge(v_be, v_bc, p: dict):
    """A Gummel-Poon BJT's forward transit charge (ngspice's ``bjtload.c``): for ``v_BE >
    0``, ``tf I_F (1 + xtf (I_F / (I_F + itf))^2 exp(v_BC / (1.44 vtf))) / q_b`` with ``I_F
    = is (exp(v_BE / (nf V_T)) - 1)`` and the base charge ``q_b``
    (:func:`estim.spice.gummel_poon.base_charge`); ``tf I_F`` below. Complex arguments
    too."""
    i_f = p["is"] * (np.exp(v_be / (p["nf"] * DIODE_VT)) - 1)
    arg = 0.0
    if p["xtf"]:
        arg = p["xtf"] * np.exp(v_bc * inverse(1.44 * p["vtf"]))
        if p["itf"]:
            arg = arg * (i_f / (i_f + p["itf"])) ** 2
    on = np.real(v_be) > 0
    qb = base_charge(v_be, v_bc, p, DIODE_VT)
    return p["tf"] * np.where(on, i_f * (1 + arg) / qb, i_f)


STEP = 1e-6
"""The central difference's step (V) of the transit charge's second slopes."""


def transit_law(v: np.ndarray, p: dict) -> tuple[np.ndarray, np.ndarray]:
    """The transit charge's slopes in ``(v_BE, v_BC)`` ``(..., 2)`` by the complex step (to
    rounding) and its second slopes ``(..., 2, 2)`` by central differences of them (the
    step :data:`STEP`: some 1e-8 of them)."""
    def slopes(w):
        return np.stack([np.imag(transit_charge(*(w[..., i] + 1e-30j * (i == k)
                                                  for i in range(2)), p)) / 1e-30
                         for k in range(2)], axis=-1)

    v = np.asarray(v, float)
    second = np.stack([(slopes(v + STEP * e) - slopes(v - STEP * e)) / (2 * STEP)
                       for e in np.eye(2)], axis=-1)
    return slopes(v), second


def junction_rows(model) -> list[Junction]:
    """The model's charges (:attr:`estim.spice.circuit.Circuit.junctions`); one whose
    voltage follows an input or an inductor's current is refused by name (its charge
    current would need their slope)."""
    c = model.circuit
    k = len(c.state_nodes)
    out = []
    for ch in c.junctions:
        pairs = ch.p.get("controls", (ch.nodes,))
        nodes = tuple(tuple(model._node[n] for n in pair) for pair in pairs)
        grads = np.array([model._P[a] - model._P[b] for a, b in nodes])
        if np.any(grads[:, k:]) or any(np.any(model._Q[a] - model._Q[b]) for a, b in nodes):
            raise NetlistError(c.netlist.source, ch.device.line, f"{ch.name}: the junction "
                               "capacitance's voltage follows an input or an inductor's "
                               "current, whose slope its charge current would need; put a "
                               "resistor between them")
        rows = np.zeros(k)
        for node, sign in zip((model._node[n] for n in ch.nodes), (1.0, -1.0), strict=True):
            if 0 <= model._rowmap[node] < k:
                rows[model._rowmap[node]] += sign
        out.append(Junction(nodes, law_of(ch), ch.p["cjo"], rows, grads))
    return out


def _values(model, V: np.ndarray) -> list:
    """Each charge's slopes and second slopes at node voltages ``V``."""
    return [j.law(np.stack([V[..., a] - V[..., b] for a, b in j.nodes], axis=-1))
            for j in model._junctions]


def capacitance_matrix(model, V: np.ndarray, values: list | None = None) -> np.ndarray:
    """The nodal capacitance matrix at node voltages ``V (..., nodes)``: the circuit's
    constant one (each charge's ``held`` capacitance) plus, for each charge, its rows times
    ``sum_i dQ/dv_i grad_i`` less what the constant one holds (``values``: :func:`_values`,
    if known)."""
    C = np.broadcast_to(model.circuit.C, V.shape[:-1] + model.circuit.C.shape).copy()
    k = C.shape[-1]
    for j, (c, _) in zip(model._junctions, values or _values(model, V), strict=True):
        row = c @ j.grads[:, :k] - j.held * j.grads[0, :k]
        C += j.rows[:, None] * row[..., None, :]
    return C


def charged_drift(model, out: np.ndarray, d_out: np.ndarray,
                  V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The node states' drift ``x' = -C(x)^-1 (currents out)`` and its Jacobian
    ``-C^-1 (d out/dx + sum_charges rows (sum_ij d2Q/dv_i dv_j (grad_i . x') grad_j)^T)``
    (the derivative of ``C(x) x' = -out``)."""
    values = _values(model, V)
    C = capacitance_matrix(model, V, values)
    k = C.shape[-1]
    dxdt = -np.linalg.solve(C, out[..., None])[..., 0]
    slope = d_out.copy()
    for j, (_, h) in zip(model._junctions, values, strict=True):
        rate = dxdt @ j.grads[:, :k].T                          # (..., r): each v_i'
        row = np.einsum("...i,...ij,jn->...n", rate, h, j.grads)
        slope += j.rows[:, None] * row[..., None, :]
    return dxdt, -np.linalg.solve(C, slope)
