"""The model of a netlist (:class:`NetlistModel`, an :class:`estim.models.base.Model`): the
drift and its Jacobian by the nodal analysis of :class:`estim.spice.circuit.Circuit`, the
output, the operating point, and the compiled kernel. :mod:`estim.spice.netlist_class`
makes and registers a class of it for each netlist."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from estim.models.base import Model
from estim.models.devices import ebers_moll
from estim.spice import behavioural, controls, gummel_poon, junctions, terminals
from estim.spice.circuit import Circuit
from estim.spice.devices import (
    DIODE_VT,
    collector_saturation,
    diode,
    diode_params,
    diode_slope,
    model_defaults,
    mosfet,
)
from estim.spice.level1 import mirrored
from estim.spice.outputs import device_output, output_map, source_output, thesis_map
from estim.spice.parser import NetlistError
from estim.spice.solved_nodes import solve_algebraic
from estim.spice.terminals import behavioural_derivatives, gummel_poon_derivatives
from estim.util import lazy

special = lazy.load("scipy.special")
kernels = lazy.load("estim.numerics.kernels")


class NetlistClass(type):
    """The type of the netlist model classes: they are made at run time, so a worker
    process cannot import them by name; pickled, a class is the arguments that build it
    again (:func:`estim.spice.netlist_class.rebuild`, which registers that pickling)."""


def _rebuild_instance(cls: type, variant, overrides: dict):
    return cls(variant, **overrides)


class NetlistModel(Model, metaclass=NetlistClass):
    """Base of the netlist model classes :func:`build_model_class` makes."""

    circuit: Circuit
    from_netlist = True
    hold = "mean"
    thesis_states: tuple | None = None

    def __init__(self, variant: str | None = None, **overrides) -> None:
        super().__init__(variant, **overrides)
        self._made_with = (variant, overrides)
        net = self.circuit.netlist
        if any(getattr(self.params, k) != v for k, v in net.params.items()):
            from estim.spice.parser import parse, with_params
            text = self._source_text()
            values = dataclasses.asdict(self.params)
            lines = [f".param {k}={v!r}" for k, v in values.items()]
            net = parse(with_params(text, lines), net.source)
            self.circuit = Circuit(net, self.circuit.inputs, self.circuit.output)
        self._prepare()

    def __reduce__(self):
        """Pickled as its class and the arguments that made it (its ``Params`` class is made
        at run time too, and cannot be imported by name in a worker)."""
        variant, overrides = self._made_with
        return (_rebuild_instance, (type(self), variant, overrides))

    def _source_text(self) -> str:
        return Path(self.circuit.netlist.source).read_text()

    def _prepare(self) -> None:
        """Everything linear, once: every node's voltage as ``V = P x + Q u + r`` (states,
        inputs, DC sources and E and H sources are affine), the linear branches (R, G, I, L)
        as matrices, and the devices (D, Q, M) left for the per-call loop. The currents are
        summed in rows: one per state node (its supernode's KCL), then one per controlling
        source of an F or H (the currents leaving the node it fixes); ``A`` adds each F's
        current, gain times its control row, to the rows of its two nodes."""
        c = self.circuit
        nodes = ["0", *c.state_nodes, *c.algebraic, *c.fixed]
        self._node = {n: i for i, n in enumerate(nodes)}
        self._node["gnd"] = 0
        n, p, k = self.n_states, self.n_inputs, len(c.state_nodes)
        kc, a = k + len(c.controls), len(c.algebraic)
        self._rowmap = np.array([-1] + [
            c.row[x] if c.row.get(x) is not None else kc + c.algebraic_row.get(x, -1 - kc)
            for x in nodes[1:]], dtype=np.int64)
        control = {node: k + j for j, (_, node, _) in enumerate(c.controls)}
        self._crowmap = np.array([control.get(x, -1) for x in nodes], dtype=np.int64)
        self._control_sign = np.array([sign for _, _, sign in c.controls])
        zero = np.zeros(n + a)
        r = self._affine(zero, np.zeros(p))
        P = np.stack([self._affine(e, np.zeros(p)) - r for e in np.eye(n + a)], axis=-1)
        Q = np.stack([self._affine(zero, e) - r for e in np.eye(p)], axis=-1) \
            if p else np.zeros((len(nodes), 0))
        G = np.zeros((kc + a, len(nodes)))          # current leaving each row's node(s)
        K = np.zeros((kc + a, n))
        i0 = np.zeros(kc + a)
        L = np.zeros((n, len(nodes)))                # inductor rows of dx/dt
        A = np.zeros((k, len(c.controls)))
        U = np.zeros((kc + a, p))                     # the inputs' currents, by row
        U[:k] = -c.B                                   # a slope input's capacitor current
        self._devices = []
        self._device_of = {}

        def leave(node, col, value, where):
            for i in (self._rowmap[self._node[node]], self._crowmap[self._node[node]]):
                if i >= 0:
                    where[i, col] += value

        for e in c.netlist.elements:
            if e.kind == "r" or e.kind == "g":
                a, b = e.nodes[:2]
                cp, cm = (a, b) if e.kind == "r" else e.nodes[2:]
                g = 1 / e.value if e.kind == "r" else e.value
                for node, sign in ((a, 1.0), (b, -1.0)):
                    leave(node, self._node[cp], sign * g, G)
                    leave(node, self._node[cm], -sign * g, G)
            elif e.kind == "i":
                j = c.inputs.index(e.name) if e.name in c.inputs else None
                for node, sign in ((e.nodes[0], 1.0), (e.nodes[1], -1.0)):
                    for i in (self._rowmap[self._node[node]], self._crowmap[self._node[node]]):
                        if i >= 0 and j is None:
                            i0[i] += sign * e.waveform[1]
                        elif i >= 0:
                            U[i, j] += sign
            elif e.kind == "l":
                j = k + [x.name for x in c.inductors].index(e.name)
                a, b = e.nodes
                leave(a, j, 1.0, K)
                leave(b, j, -1.0, K)
                L[j, self._node[a]] += 1 / e.value
                L[j, self._node[b]] -= 1 / e.value
            elif e.kind == "f":
                j = c.control_index(e.ref)
                for node, sign in ((e.nodes[0], 1.0), (e.nodes[1], -1.0)):
                    i = self._rowmap[self._node[node]]
                    if i >= 0:
                        A[i, j] += sign * e.value * self._control_sign[j]
            elif e.kind == "b":
                law = {"fn": behavioural.compiled(e.ref), "expr": e.ref}
                self._devices.append(("b", law, [self._node[x] for x in e.nodes]))
                self._device_of[e.name] = self._devices[-1]
            elif e.kind in "dqm":
                model = c.netlist.models[e.ref]
                prm = (diode_params(model.params) if e.kind == "d"
                       else {**model_defaults(model), **model.params})
                if e.kind == "m" and "level" in prm:
                    size = {"w": 1.0, "l": 1.0, **dict(e.size)}
                    prm = {**mirrored(model.type, prm), "w_over_l": size["w"] / size["l"]}
                self._devices.append((model.type, prm, [self._node[x] for x in e.nodes]))
                self._device_of[e.name] = self._devices[-1]
        if a:
            P, Q, r = solve_algebraic(c, n, P, Q, r, G, K, i0, U, kc)
            G, K, i0, U = G[:kc], K[:kc], i0[:kc], U[:kc]
            self._rowmap[self._rowmap >= kc] = -1
        self._P, self._Q, self._r = P, Q, r
        self._G, self._K, self._i0, self._L = G, K, i0, L
        self._A = A if c.controls else None
        self._U = U
        self._linear = G @ self._P + K                # d(linear currents)/dx
        self._h = [output_map(self, term, text)
                   for term, text in zip(c.output_terms, c.outputs, strict=True)]
        self._junctions = junctions.junction_rows(self)

    def _sum_rows(self, out, d_out):
        """The state rows' currents with each F source's current added (``A``): the rows
        of the supernodes, before ``C^-1``."""
        k = len(self.circuit.state_nodes)
        if self._A is None:
            return out, d_out
        return (out[..., :k] + out[..., k:] @ self._A.T,
                d_out[..., :k, :] + np.einsum("ij,...jn->...in", self._A, d_out[..., k:, :]))

    def _affine(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Every node's voltage (in ``self._node`` order) at states ``x`` followed by the
        voltages of the nodes no capacitor meets, inputs ``u``."""
        c = self.circuit
        v = {"0": 0.0, "gnd": 0.0}
        k, n = len(c.state_nodes), self.n_states
        v.update(zip(c.state_nodes, x[:k], strict=True))
        v.update(zip(c.algebraic, x[n:], strict=True))
        todo = list(c.fixed)
        guard = 0
        while todo:
            guard += 1
            node = todo.pop(0)
            e, other, sign = c.fixed[node]
            need = [other] + (list(e.nodes[2:4]) if e.kind == "e" else [])
            if e.kind == "h":
                need += controls.control_nodes(c, e.ref)
            if not all(x_ in v for x_ in need):
                if guard > 10 * len(c.fixed) + 10:
                    raise NetlistError(c.netlist.source, e.line, f"{e.name}: its controlling "
                                       "nodes depend on it")
                todo.append(node)
                continue
            if e.kind == "v" and e.name in c.inputs:
                value = 0.0 if c.slope else u[c.inputs.index(e.name)]
            elif e.kind == "v":
                value = e.waveform[1]
            elif e.kind == "e":                    # v(p) - v(m) = gain (v(cp) - v(cm))
                value = e.value * (v[e.nodes[2]] - v[e.nodes[3]])
            else:                                  # H: v(p) - v(m) = gain i(control)
                value = e.value * controls.control_current(c, e.ref, v, x)
            v[node] = v[other] + sign * value
        nodes = sorted(self._node, key=self._node.get)
        return np.array([v[n] for n in nodes if n != "gnd"])

    def f_and_jacobian(self, x, u, t: float = 0.0):
        """``f = -C^-1 (currents leaving the state nodes)`` on the node states and
        ``L^-1 (v(n1) - v(n2))`` on the inductor currents, and its Jacobian."""
        return self.drift(x, u)

    def drift(self, x, u, changes: tuple | None = None):
        """:meth:`f_and_jacobian` with element values changed per point (``changes``, as
        :meth:`_currents` takes them: :mod:`estim.spice.parameter_states`)."""
        return self._drift_of(*self._currents(x, u, changes))

    def _drift_of(self, out, d_out, V):
        """The drift and its Jacobian from :meth:`_currents`' currents, their Jacobian and
        the node voltages."""
        c = self.circuit
        k = len(c.state_nodes)
        lead = out.shape[:-1]
        dxdt = V @ self._L.T
        J = np.broadcast_to(self._L @ self._P, lead + (self.n_states, self.n_states)).copy()
        if self._junctions:                      # C(x): junction capacitances
            dxdt[..., :k], J[..., :k, :] = junctions.charged_drift(self, out, d_out, V)
            return dxdt, J
        dxdt[..., :k] = -out @ c.C_inv.T
        J[..., :k, :] = -np.einsum("ij,...jn->...in", c.C_inv, d_out)
        return dxdt, J

    def _currents(self, x, u, changes: tuple | None = None, raw: bool = False):
        """The currents leaving each state node (KCL), their Jacobian w.r.t. the states, and
        every node's voltage (with ``raw``, every row's, before each F source's current is
        added to the state rows). ``changes``: ``(resistors, devices)``, the conductance each
        listed resistor adds, ``[(node a, node b, conductance (...))]``, and the parameters
        of listed devices, ``{device index: {name: values (...)}}``, each value an array over
        the leading axes (a parameter as a state per run)."""
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        lead = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
        V = x @ self._P.T + u @ self._Q.T + self._r          # every node's voltage
        out = V @ self._G.T + x @ self._K.T + self._i0 + u @ self._U.T   # leaving each row
        d_out = np.broadcast_to(self._linear, lead + self._linear.shape).copy()
        resistors, changed = changes or ((), {})
        for a, b, dg in resistors:
            cur = dg * (V[..., a] - V[..., b])
            dcur = dg[..., None] * (self._P[a] - self._P[b])
            self._leave(out, d_out, ((a, cur, dcur), (b, -cur, -dcur)))
        for d, (kind, p, idx) in enumerate(self._devices):
            if d in changed:
                p = {**p, **changed[d]}
            self._leave(out, d_out, terminals.terms(self._P, kind, p, idx, V))
        if raw:                                    # every row, the control rows too
            return out, d_out, V
        out, d_out = self._sum_rows(out, d_out)
        return out, d_out, V

    def _leave(self, out, d_out, terms) -> None:
        """Add each ``(node, current leaving it, its gradient in x)`` of ``terms`` to the
        rows of ``out`` and ``d_out`` (``d_out`` None: the currents alone)."""
        for node, cur, dcur in terms:
            for i in (self._rowmap[node], self._crowmap[node]):
                if i >= 0:
                    out[..., i] += cur
                    if d_out is not None:
                        d_out[..., i, :] += dcur

    def operating_point(self, x_guess: np.ndarray | None = None,
                        u: np.ndarray | None = None) -> np.ndarray:
        """DC point as SPICE finds it: Newton on KCL itself (the currents, not ``C^-1`` times
        them, whose rows differ by the ratio of the largest to the smallest capacitor) with
        inductors as shorts, each step limited to 0.1 V per node (junction limiting: a
        transistor's exponential cannot overshoot); then the default polish on ``f``."""
        u0 = np.zeros(self.n_inputs) if u is None else np.asarray(u, float)
        x = np.zeros(self.n_states) if x_guess is None else np.array(x_guess, float)
        k = len(self.circuit.state_nodes)
        LP = self._L @ self._P
        for _ in range(2000):
            out, d_out, V = self._currents(x, u0)
            g = np.concatenate([out, (V @ self._L.T)[k:]])
            G = np.vstack([d_out, LP[k:]])
            try:
                step = np.linalg.solve(G, -g)
            except np.linalg.LinAlgError:
                break
            big = np.abs(step[:k]).max(initial=0.0)
            if big > 0.1:
                step = step * (0.1 / big)
            x = x + step
            if big <= 1e-13 * max(1.0, np.abs(x[:k]).max(initial=0.0)):
                break
        return super().operating_point(x, u0)

    def kernel(self):
        """The compiled drift for :mod:`estim.numerics.radau_compiled`: the one netlist kernel of
        :mod:`estim.numerics.kernels` (``_netlist``) with this circuit laid out as data."""
        n, p = self.n_states, self.n_inputs
        k, N = len(self.circuit.state_nodes), self._P.shape[0]
        rows = []
        if (any(kind == "b" or "xbv" in prm for kind, prm, _ in self._devices)
                or self._junctions):
            return None                  # a B source, a breakdown or C(x): the numpy path
        for kind, prm, idx in self._devices:
            nodes = [*idx, -1, -1, -1][:4]
            if kind == "d":
                values = [prm["is"], prm["n"] * DIODE_VT, prm["rs"], 0.0, 0.0]
                code = 0.0
            elif kind in ("npn", "pnp") and "bf" in prm:    # Gummel-Poon
                values = [prm["is"], prm["bf"], prm["br"], prm["nf"], prm["nr"],
                          *(float(gummel_poon.inverse(prm[key]))
                            for key in ("vaf", "var", "ikf", "ikr")),
                          prm["ise"], prm["ne"], prm["isc"], prm["nc"], DIODE_VT]
                code = 7.0 if kind == "npn" else 8.0
            elif kind in ("npn", "pnp"):
                values = [prm["ies"], collector_saturation(prm),
                          prm["alpha_f"], prm["alpha_r"], prm["vt"]]
                code = 1.0 if kind == "npn" else 2.0
            elif "level" in prm:                       # the NMOS's parameters (mirrored)
                values = [prm["vto"], prm["kp"] * prm["w_over_l"], prm["lambda"],
                          prm["gamma"], prm["phi"]]
                code = 5.0 if kind == "nmos" else 6.0
            else:
                values = [prm["u_t"], prm["v_t0"], prm["eta"], prm["i_0"] * prm["w_l"],
                          float(prm.get("law", 0.0))]
                code = 3.0 if kind == "nmos" else 4.0
            rows.append([code, *nodes, *values] + [0.0] * (kernels.DEVICE_ROW - 5 - len(values)))
        Y = np.vstack([self._linear, (self._L @ self._P)[k:]])
        W = np.vstack([self._G @ self._Q + self._U, (self._L @ self._Q)[k:]])
        c = np.concatenate([self._G @ self._r + self._i0, (self._L @ self._r)[k:]])
        nc = len(self.circuit.controls)
        A = self._A if self._A is not None else np.zeros((k, 0))
        P = np.concatenate([[n, k, p, N, len(rows), nc], Y.ravel(), W.ravel(), c,
                            self._P.ravel(), self._Q.ravel(), self._r,
                            (-self.circuit.C_inv).ravel(), A.ravel(), self._rowmap,
                            self._crowmap, np.ravel(rows)]).astype(float)
        return kernels.NETLIST, P

    def source_to_input(self, source: np.ndarray, dt: float) -> np.ndarray:
        """Source voltages on each interval: the mean of the samples at its two ends (a
        netlist's inputs are source voltages, as the hand-written diffamp_em's are), or, for
        inputs that drive through capacitors, the slope of the piecewise-linear source (as
        the hand-written MOSFET's, eq 3.26); with ``model.hold`` ``start`` or ``end`` the
        sample at the interval's start (zero-order hold) or end (as the hand-written cco)."""
        if self.circuit.slope:
            return np.diff(source, axis=-2) / dt
        if self.hold in ("start", "end"):
            source = np.asarray(source)
            return source[..., :-1, :] if self.hold == "start" else source[..., 1:, :]
        return 0.5 * (source[..., 1:, :] + source[..., :-1, :])

    def _device_derivatives(self, V: np.ndarray):
        """At one point (node voltages ``V``): for each device its control nodes, and for each
        terminal the node, the first and second derivatives of the current leaving that node
        into the device w.r.t. the control nodes' voltages."""
        for kind, p, idx in self._devices:
            if kind == "d":
                a, b = idx
                cur, g = diode(V[a] - V[b], p)
                dg = diode_slope(V[a] - V[b], cur, g, p)
                d1 = np.array([g, -g])
                d2 = dg * np.array([[1.0, -1.0], [-1.0, 1.0]])
                yield [a, b], [(a, d1, d2), (b, -d1, -d2)]
            elif kind in ("npn", "pnp") and "bf" in p:
                yield idx, gummel_poon_derivatives(kind, p, idx, V)
            elif kind == "b":
                yield idx[2:], behavioural_derivatives(p["fn"], idx, V)
            elif kind in ("npn", "pnp"):
                c, b, e = idx
                s = -1.0 if kind == "pnp" else 1.0
                VT = p["vt"]
                tc = ebers_moll.currents(s * (V[b] - V[e]), s * (V[b] - V[c]), p["ies"],
                                         collector_saturation(p), p["alpha_f"], p["alpha_r"], VT)
                dbe, dbc = np.array([0.0, 1.0, -1.0]), np.array([-1.0, 1.0, 0.0])
                be, bc = np.outer(dbe, dbe), np.outer(dbc, dbc)
                # current into each terminal = s I(v_be, v_bc), v_.. = s (...); every term
                # is linear in e^(v/V_T), so its second derivative is its first over V_T
                terms = [(node, d_be * dbe + d_bc * dbc, s * (d_be * be + d_bc * bc) / VT)
                         for node, d_be, d_bc in ((c, tc.dIC_be, tc.dIC_bc),
                                                  (b, tc.dIB_be, tc.dIB_bc),
                                                  (e, tc.dIE_be, tc.dIE_bc))]
                yield [c, b, e], terms
            else:
                d_, g_, s_, b_ = idx
                _, d1, d2 = mosfet(kind, V[d_], V[g_], V[s_], V[b_], p, second=True)
                yield [d_, g_, s_, b_], [(d_, d1, d2), (s_, -d1, -d2)]

    def _node_voltages(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self._P @ np.asarray(x, float) + self._Q @ np.asarray(u, float) + self._r

    def input_jacobian(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        """``df/du`` at one point, analytic (through the node map's input columns ``Q``)."""
        k = len(self.circuit.state_nodes)
        dcur = self._G @ self._Q + self._U
        for nodes, terms in self._device_derivatives(self._node_voltages(x, u)):
            for node, d1, _ in terms:
                for i in (self._rowmap[node], self._crowmap[node]):
                    if i >= 0:
                        dcur[i] += d1 @ self._Q[nodes]
        if self._A is not None:
            dcur = dcur[:k] + self._A @ dcur[k:]
        out = self._L @ self._Q
        C_inv = (np.linalg.inv(junctions.capacitance_matrix(self, self._node_voltages(x, u)))
                 if self._junctions else self.circuit.C_inv)
        out[:k] = -C_inv @ dcur
        return out

    def hessian(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Second derivatives of ``f`` w.r.t. ``z = [x, u]`` at one point, analytic: only the
        devices are nonlinear, and each node voltage is affine in ``z`` (``V = P x + Q u +
        r``), so ``d2f/dz2 = -C^-1 sum_devices Z^T (d2 i / dV2) Z`` with ``Z`` the rows of
        ``[P Q]`` at the device's nodes. (The default second differences of ``f`` are at the
        mercy of its rounding: with shunt capacitors of 1 pF, ``f`` sums currents into 1e9 V/s,
        and the percent distortion moved by 3e-3 relative as the difference step changed.)"""
        if self._junctions:
            raise NetlistError(self.circuit.netlist.source, 0, "junction capacitances make "
                               "C depend on the state: the analytic Hessian (a distortion "
                               "analysis) takes a constant C")
        k, n = len(self.circuit.state_nodes), self.n_states
        Z = np.hstack([self._P, self._Q])
        m = Z.shape[1]
        Hcur = np.zeros((k + len(self.circuit.controls), m, m))
        for nodes, terms in self._device_derivatives(self._node_voltages(x, u)):
            Zd = Z[nodes]
            for node, _, d2 in terms:
                for i in (self._rowmap[node], self._crowmap[node]):
                    if i >= 0:
                        Hcur[i] += Zd.T @ d2 @ Zd
        if self._A is not None:
            Hcur = Hcur[:k] + np.einsum("ij,jab->iab", self._A, Hcur[k:])
        H = np.zeros((n, m, m))
        H[:k] = -np.einsum("ij,jab->iab", self.circuit.C_inv, Hcur)
        return H

    @property
    def thesis_map(self) -> np.ndarray | None:
        """``M`` with ``x = M z + const`` from the quantities ``z`` of ``thesis_states`` (the
        coordinates a filter's Q and P0 are written in, D77) to this model's states, or
        None where the config names none (the netlist's own states, :attr:`state_scales`)."""
        return thesis_map(self) if self.thesis_states else None

    def _measured(self, x: np.ndarray, jacobian: bool):
        """Each output's value ``(..., 1)`` at states ``x`` and, with ``jacobian``, its row
        ``(..., 1, n)`` (:attr:`Circuit.output_terms`, in the config's order)."""
        x = np.asarray(x, float)
        n = self.n_states
        for term, affine in zip(self.circuit.output_terms, self._h, strict=True):
            if term[0] in ("device", "source"):
                y, H = (device_output if term[0] == "device" else source_output)(self, x, term)
                yield y, (H if jacobian else None)
                continue
            if affine is not None:
                row, const = affine
                y = (x @ row + const)[..., None]
            else:                                   # states: taken as they are
                row = np.zeros(n)
                row[term[1]] = 1.0
                y = x[..., term[1]:term[1] + 1]
                if term[0] == "v" and term[2] is not None:
                    row[term[2]] = -1.0
                    y = (x[..., term[1]] - x[..., term[2]])[..., None]
            yield y, (np.broadcast_to(row, x.shape[:-1] + (1, n)) if jacobian else None)

    def h(self, x):
        """The outputs ``(..., m)``."""
        return np.concatenate([y for y, _ in self._measured(x, False)], axis=-1)

    def affine_output(self):
        """``(H, c)`` when no output is a device's or a voltage source's current, else
        None."""
        if any(term[0] in ("device", "source") for term in self.circuit.output_terms):
            return None
        H = np.vstack([H[0] for _, H in self._measured(np.zeros(self.n_states), True)])
        c = np.array([y[0] for y, _ in self._measured(np.zeros(self.n_states), False)])
        return H, c

    def h_jacobian(self, x):
        """The outputs' Jacobian ``(..., m, n)``."""
        return np.concatenate([H for _, H in self._measured(x, True)], axis=-2)
