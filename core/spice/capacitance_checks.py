"""Two checks of a netlist's structure before its model is built: every state node has a
DC path to ground, and the nodal capacitance matrix is invertible (each refused naming the
nodes)."""

from __future__ import annotations

import numpy as np

from estim.spice.parser import NetlistError


def check_dc_paths(circuit, ground: tuple[str, ...]) -> None:
    """Refuse nodes with no DC path to ground (through R, L, D, Q, M and the voltage
    sources): a group reached only through capacitors and current sources (a cut-set of
    current sources) has no DC point, and its voltage would drift with any current put
    in."""
    reached = set(ground)
    edges = []
    for e in circuit.netlist.elements:
        if e.kind in "rldveh":
            edges.append(e.nodes[:2])
        elif e.kind == "q":
            edges += [(e.nodes[0], e.nodes[1]), (e.nodes[1], e.nodes[2])]
        elif e.kind == "m":
            edges.append((e.nodes[0], e.nodes[2]))
    grew = True
    while grew:
        grew = False
        for a, b in edges:
            if (a in reached) != (b in reached):
                reached |= {a, b}
                grew = True
    cut = sorted(n for n in circuit.state_nodes if n not in reached)
    if cut:
        raise NetlistError(circuit.netlist.source, 0, f"node(s) {', '.join(cut)} have no DC "
                           "path to ground (only capacitors and current sources reach "
                           "them): add a resistor to ground")


def floating_group(state_nodes: list[str], C: np.ndarray) -> list[str]:
    """The state nodes in the null space of the nodal capacitance matrix ``C`` (a group
    that moves together with no capacitor to anything else)."""
    _, s, Vt = np.linalg.svd(C)
    null = Vt[s <= s[0] * 1e-12 * len(s)]
    weight = np.abs(null).max(axis=0)
    return [state_nodes[i] for i in np.flatnonzero(weight > 1e-9 * weight.max())]


def check_invertible(circuit, C: np.ndarray) -> None:
    """Refuse a singular nodal capacitance matrix, naming the group of nodes that
    capacitors join only to each other (and which of them are series resistances'
    internal nodes, which no capacitor of the netlist can reach)."""
    k = len(circuit.state_nodes)
    if not k or np.linalg.matrix_rank(C) == k:
        return
    group = floating_group(circuit.state_nodes, C)
    inner = [n for n in group if n in circuit.internal]
    hint = (f" ({', '.join(inner)}: internal nodes of series resistances, which no "
            "capacitor of the netlist reaches; leave one of the resistances out)"
            if inner else "")
    raise NetlistError(circuit.netlist.source, 0, "the nodal capacitance matrix is singular: "
                       f"node(s) {', '.join(group)} are joined only by capacitors, with no "
                       f"capacitor to the rest: add a shunt capacitor to one of them{hint}")
