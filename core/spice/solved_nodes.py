"""The nodes no capacitor meets, solved from their KCL (deviations D71): their voltages as
affine in the states and inputs, folded into a netlist model's node map."""

from __future__ import annotations

import numpy as np

from estim.spice.parser import NetlistError


def solve_algebraic(circuit, n: int, P: np.ndarray, Q: np.ndarray, r: np.ndarray,
                    G: np.ndarray, K: np.ndarray, i0: np.ndarray, U: np.ndarray,
                    kc: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The node map ``V = P x + Q u + r`` on the ``n`` states alone, from the map ``P`` on
    the states followed by the voltages ``z`` of ``circuit.algebraic``, whose KCL rows
    (``kc`` on) carry linear branches only (:meth:`estim.spice.circuit.Circuit.
    _set_apart_algebraic`): ``G_z (P [x; z] + Q u + r) + K_z x + i0_z + U_z u = 0``, solved
    for ``z`` affine in ``x`` and ``u``. A node whose KCL does not fix its voltage (only
    inductors and current sources meet it) is refused by name."""
    Gz = G[kc:]
    Mz = Gz @ P[:, n:]
    if np.linalg.matrix_rank(Mz) < Mz.shape[0]:
        stuck = [circuit.algebraic[i] for i in range(len(circuit.algebraic))
                 if not Mz[i].any()] or circuit.algebraic
        raise NetlistError(circuit.netlist.source, 0, f"node(s) {', '.join(stuck)} have no "
                           "capacitive path and no conductance that fixes their voltage "
                           "(only inductors and current sources meet them): add a resistor "
                           "or a capacitor to each")
    Zx = -np.linalg.solve(Mz, Gz @ P[:, :n] + K[kc:])
    Zu = -np.linalg.solve(Mz, Gz @ Q + U[kc:])
    z0 = -np.linalg.solve(Mz, Gz @ r + i0[kc:])
    Pz = P[:, n:]
    return P[:, :n] + Pz @ Zx, Q + Pz @ Zu, r + Pz @ z0
