"""The currents a netlist's device draws from its nodes: for each terminal the node, the
current leaving the node into the device, and its gradient in the states, by the device's
law (:mod:`estim.spice.devices`) at node voltages ``V = P x + Q u + r``."""

from __future__ import annotations

import numpy as np

from estim.models.devices import ebers_moll
from estim.spice import behavioural, gummel_poon
from estim.spice.devices import DIODE_VT, collector_saturation, diode, mosfet


def terms(P: np.ndarray, kind: str, p: dict, idx: list, V: np.ndarray) -> tuple:
    """``((node, current, d current / dx), ...)`` of one device of type ``kind`` with
    ``.model`` parameters ``p`` at nodes ``idx``; ``P`` the node voltages' rows in the states,
    ``V (..., nodes)`` the node voltages."""
    if kind == "d":
        a, b = idx
        cur, g = diode(V[..., a] - V[..., b], p)
        dcur = g[..., None] * (P[a] - P[b])
        return (a, cur, dcur), (b, -cur, -dcur)
    if kind in ("npn", "pnp"):
        col, base, emi = idx
        sign = -1.0 if kind == "pnp" else 1.0
        v_be, v_bc = sign * (V[..., base] - V[..., emi]), sign * (V[..., base] - V[..., col])
        if "bf" in p:                                  # SPICE's Gummel-Poon
            tc = gummel_poon.currents(v_be, v_bc, p, DIODE_VT)
        else:
            tc = ebers_moll.currents(v_be, v_bc, p["ies"], collector_saturation(p),
                                     p["alpha_f"], p["alpha_r"], p["vt"])
        dbe = sign * (P[base] - P[emi])
        dbc = sign * (P[base] - P[col])
        # a terminal current flows into the device: it leaves the node
        return tuple((node, sign * cur, sign * (d_be[..., None] * dbe + d_bc[..., None] * dbc))
                     for node, cur, d_be, d_bc in ((col, tc.I_C, tc.dIC_be, tc.dIC_bc),
                                                   (emi, tc.I_E, tc.dIE_be, tc.dIE_bc),
                                                   (base, tc.I_B, tc.dIB_be, tc.dIB_bc)))
    if kind == "b":                                    # from n+ through the source to n-
        cur, slopes = behavioural.current_and_slopes(p["fn"], V, idx[2:])
        dcur = sum(slopes[..., j, None] * P[node] for j, node in enumerate(idx[2:]))
        dcur = dcur + np.zeros(np.shape(cur) + (P.shape[1],))
        return (idx[0], cur, dcur), (idx[1], -cur, -dcur)
    d_, g_, s_, b_ = idx
    cur, grad, _ = mosfet(kind, V[..., d_], V[..., g_], V[..., s_], V[..., b_], p)
    dcur = (grad[..., 0, None] * P[d_] + grad[..., 1, None] * P[g_]
            + grad[..., 2, None] * P[s_] + grad[..., 3, None] * P[b_])
    return (d_, cur, dcur), (s_, -cur, -dcur)


def gummel_poon_derivatives(kind: str, p: dict, idx: list, V: np.ndarray) -> list:
    """A Gummel-Poon BJT's terminals at one point (node voltages ``V``): ``(node, first
    derivatives, second derivatives)`` of the current leaving each node into the device,
    w.r.t. the voltages of its nodes ``idx`` (collector, base, emitter); the second by
    central differences of the first (step 1 uV: ~1e-9 of them, as the law's scale is
    ``V_T``)."""
    eye = np.eye(len(V))

    def first(at):
        return {node: dcur[idx] for node, _, dcur in terms(eye, kind, p, idx, at)}

    step = 1e-6
    d1 = first(V)
    d2 = {node: np.zeros((3, 3)) for node in idx}
    for k, node_k in enumerate(idx):
        up, down = first(V + step * eye[node_k]), first(V - step * eye[node_k])
        for node in idx:
            d2[node][:, k] = (up[node] - down[node]) / (2 * step)
    return [(node, d1[node], 0.5 * (d2[node] + d2[node].T)) for node in idx]


def behavioural_derivatives(fn, idx: list, V: np.ndarray) -> list:
    """A behavioural source's terminals (``idx[:2]``) at one point: ``(node, first
    derivatives, second derivatives)`` of the current leaving each into the source w.r.t.
    its control nodes' voltages (``idx[2:]``); the first exact (complex step), the second
    central differences of them (step 1 uV)."""
    controls = idx[2:]
    step = 1e-6
    d1 = behavioural.current_and_slopes(fn, V, controls)[1]
    d2 = np.zeros((len(controls), len(controls)))
    for k, node in enumerate(controls):
        e = np.zeros(len(V))
        e[node] = step
        up = behavioural.current_and_slopes(fn, V + e, controls)[1]
        down = behavioural.current_and_slopes(fn, V - e, controls)[1]
        d2[:, k] = (up - down) / (2 * step)
    d2 = 0.5 * (d2 + d2.T)
    return [(idx[0], d1, d2), (idx[1], -d1, -d2)]
