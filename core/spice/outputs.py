"""A netlist model's measured output when it is not a state: an affine map of the node
voltages (a node, a difference, a resistor's current), a device's current, by the
device's own law at the node voltages, or a voltage source's current, summed at the node it
fixes (:meth:`estim.spice.circuit.Circuit._output`)."""

from __future__ import annotations

import numpy as np

from estim.spice import terminals
from estim.spice.parser import NetlistError


def output_map(model, term: tuple, text: str) -> tuple | None:
    """``(row, constant)`` with ``y = row . x + constant`` for an output at nodes or through
    a resistor, else None; an output that follows the model input directly (a node the
    input drives through resistors only, or a device at one) is refused by name: the
    model's output has no input term."""
    c = model.circuit
    if term[0] == "node":
        a, b = (model._node[x] if x else None for x in term[1:])
        rows, scale = ([a, b] if b is not None else [a]), 1.0
    elif term[0] == "resistor":
        e = c.netlist.element(term[1])
        rows, scale = [model._node[x] for x in e.nodes[:2]], 1.0 / e.value
    elif term[0] == "device":
        rows, scale = model._device_of[term[1]][2], None
    elif term[0] == "source":
        row = len(c.state_nodes) + term[2]
        node = model._node[c.controls[term[2]][1]]
        linear = (model._G @ model._Q + model._U)[row]
        device = any(node in idx and np.any(model._Q[idx] != 0) for _, _, idx in model._devices)
        if device or np.any(linear != 0):
            raise NetlistError(c.netlist.source, 0, f"output {text!r} follows the model "
                               "input directly (an element at the node its source fixes is "
                               "driven by the input); measure a source away from the input")
        return None
    else:
        return None
    signs = np.array([1.0, -1.0][:len(rows)]) if scale is not None else None
    through = model._Q[rows] if scale is None else signs @ model._Q[rows]
    if np.any(through != 0):
        raise NetlistError(c.netlist.source, 0, f"output {text!r} follows the model "
                           "input directly; take a node (or element) behind an element")
    if scale is None:
        return None
    return (scale * (signs @ model._P[rows]), float(scale * (signs @ model._r[rows])))


def device_output(model, x: np.ndarray, term: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The device current ``term`` measures (``("device", name, terminal)``), ``(..., 1)``
    at states ``x``, and its Jacobian ``(..., 1, n)``: a diode's from anode to cathode, a
    BJT's into the terminal the output names, a MOSFET's into its drain (the laws the drift
    uses)."""
    _, name, terminal = term
    kind, p, idx = model._device_of[name]
    V = x @ model._P.T + model._r
    at = terminals.terms(model._P, kind, p, idx, V)
    # a BJT's terms are the collector's, the emitter's, the base's; the output names c, b, e
    _, cur, dcur = at[(0, 2, 1)[terminal]] if kind in ("npn", "pnp") else at[0]
    return np.asarray(cur)[..., None], np.asarray(dcur)[..., None, :]


def thesis_map(model) -> np.ndarray:
    """``M`` with ``x = M z + const`` from the quantities ``z`` of ``model.thesis_states``
    (node voltages, differences and inductor currents: the coordinates a filter's Q and P0
    are written in, D77) to the model's states; each must be affine in the states alone and
    together they must determine them."""
    src, n = model.circuit.netlist.source, model.n_states
    if len(model.thesis_states) != n:
        raise NetlistError(src, 0, f"thesis_states: {len(model.thesis_states)} given, the "
                           f"netlist has {n} states ({', '.join(model.state_names)})")
    rows = []
    for text in model.thesis_states:
        term = model.circuit._output(text)
        if term[0] in ("resistor", "device"):
            raise NetlistError(src, 0, f"thesis_states: {text!r} is a branch current; "
                               "expected v(node), v(node,node) or i(inductor)")
        if term[0] == "i":
            rows.append(np.eye(n)[term[1]])
            continue
        names = (model.circuit.state_nodes[term[1]], None if term[2] is None else
                 model.circuit.state_nodes[term[2]]) if term[0] == "v" else term[1:]
        a, b = (model._node[x] if x else None for x in names)
        row, qrow = model._P[a].copy(), model._Q[a].copy()
        if b is not None:
            row, qrow = row - model._P[b], qrow - model._Q[b]
        if np.any(qrow != 0):
            raise NetlistError(src, 0, f"thesis_states: {text!r} follows the model input")
        rows.append(row)
    T = np.array(rows)
    if np.linalg.matrix_rank(T) < n:
        raise NetlistError(src, 0, "thesis_states: the quantities do not determine the "
                           "states (one is a combination of the others)")
    return np.linalg.inv(T)


def source_output(model, x: np.ndarray, term: tuple) -> tuple[np.ndarray, np.ndarray]:
    """A voltage source's current (SPICE's, from its + terminal through it to its -) that
    ``term`` (``("source", name, control index)``) measures, ``(..., 1)`` at states ``x``,
    and its Jacobian ``(..., 1, n)``: the currents leaving the node it fixes through every
    other element there, its control row (input-free: :func:`output_map` checks)."""
    c = model.circuit
    row = len(c.state_nodes) + term[2]
    sign = c.controls[term[2]][2]
    x = np.asarray(x, float)
    out, d_out, _ = model._currents(x, np.zeros(model.n_inputs), raw=True)
    return sign * out[..., row:row + 1], sign * d_out[..., row:row + 1, :]
