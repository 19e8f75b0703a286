"""The current of a voltage source, as the netlist model sums it at the node the source
fixes (:meth:`estim.spice.circuit.Circuit._controls`): an H source's controlling current
from the linear branches there, while the model's node voltages are being set."""

from __future__ import annotations

import numpy as np


def control_nodes(c, ref: str) -> list[str]:
    """The nodes whose voltages set the current of source ``ref`` (an H's control) in
    circuit ``c``."""
    vx, node, _ = c.controls[c.control_index(ref)]
    out = [node]
    for e in c.netlist.elements:
        if e is not vx and node in e.nodes[:2] and e.kind in "rg":
            out += list(e.nodes[:2] if e.kind == "r" else e.nodes[2:4])
    return out


def control_current(c, ref: str, v: dict, x: np.ndarray) -> float:
    """SPICE's current through source ``ref`` from the linear branches (R, G, I, L) at
    the node it fixes (:meth:`estim.spice.circuit.Circuit._controls`)."""
    vx, node, sign = c.controls[c.control_index(ref)]
    total = 0.0
    for e in c.netlist.elements:
        if e is vx or node not in e.nodes[:2]:
            continue
        way = 1.0 if e.nodes[0] == node else -1.0      # the branch current leaves node
        if e.kind == "r":
            total += way * (v[e.nodes[0]] - v[e.nodes[1]]) / e.value
        elif e.kind == "g":
            total += way * e.value * (v[e.nodes[2]] - v[e.nodes[3]])
        elif e.kind == "i":
            total += way * e.waveform[1]
        elif e.kind == "l":
            j = len(c.state_nodes) + [y.name for y in c.inductors].index(e.name)
            total += way * x[j]
    return sign * total
