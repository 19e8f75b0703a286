"""A netlist model with element values as states (issue 47): a resistor's resistance
(``R1``), an inductor's inductance (``L1``) or a device's ``.model`` parameter (``D1.is``)
estimated along with the circuit's states, each a random walk

    d theta / dt = 0,      theta_k = theta_{k-1} + w_k,   w_k ~ N(0, drift^2 / start^2),

on the augmented state ``[x, theta]``. ``theta`` is the value over the filter's first guess
``start`` (so it starts at 1 and a filter's bound on ``|x|`` reads it without units); the
drift ``f(x, u; theta start)`` is the netlist model's with that value, per run (each run's
estimate of it); its columns in ``theta`` are exact for a resistor and an inductor and
central differences of the one device's currents for a device parameter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.models.base import Model
from estim.spice import terminals
from estim.spice.level1 import mirrored
from estim.spice.netlist_model import NetlistModel
from estim.util import lazy

optimize = lazy.load("scipy.optimize")

ESTIMABLE = {"d": ("is", "n"), "npn": ("ies", "alpha_f", "alpha_r"),
             "pnp": ("ies", "alpha_f", "alpha_r"), "nmos": ("i_0", "v_t0"),
             "pmos": ("i_0", "v_t0")}
"""The ``.model`` parameters a device's entry may name (``D1.is``), by device type; a
level-1 MOSFET's are :data:`LEVEL1_ESTIMABLE`, a Gummel-Poon BJT's
:data:`GUMMEL_POON_ESTIMABLE`. A resistor's entry is its name (``R1``)."""

LEVEL1_ESTIMABLE = ("vto", "kp", "lambda")
GUMMEL_POON_ESTIMABLE = ("is", "bf", "br", "vaf")

STEP = 1e-6
"""The central difference's step in ``theta`` (relative to the first guess): its error is
~1e-10 of the device's current (its rounding over the step; the truncation ~1e-12)."""


@dataclass(frozen=True)
class Parameter:
    """One estimated value: its name as the config gives it, the element, the ``.model``
    parameter (``None``: a resistor's resistance or an inductor's inductance) and the
    filter's first guess."""

    name: str
    element: str
    field: str | None
    start: float


def split(model: NetlistModel, name: str) -> tuple[str, str | None]:
    """``(element, .model parameter or None)`` of ``name``: ``R1`` or ``X1.R1`` (an element,
    a subcircuit's too) or ``D1.is``, ``X1.D1.is`` (a device's parameter), lower case."""
    lower = name.lower()
    if model.circuit.netlist.element(lower) is not None:
        return lower, None
    element, _, field = lower.rpartition(".")
    return (element, field or None) if element else (lower, None)


def allowed(kind: str, prm: dict) -> tuple[str, ...]:
    """The ``.model`` parameters of a device of type ``kind`` that may be states (none of
    a diode that breaks down)."""
    if "xbv" in prm:
        return ()
    return (LEVEL1_ESTIMABLE if "level" in prm else
            GUMMEL_POON_ESTIMABLE if "bf" in prm else ESTIMABLE[kind])


def estimable(model: NetlistModel) -> list[str]:
    """Every name ``model``'s config may give in ``estimate``: each resistor whose value can
    be a state, each device parameter that can (``estim settings CONFIG`` lists them); none
    beside a junction capacitance (whose ``C(x)`` the parameter states do not carry)."""
    if model.circuit.junctions:
        return []
    names = []
    for e in model.circuit.netlist.elements:
        if e.kind == "l":
            names.append(e.name.upper())
        elif e.kind == "r":
            try:
                _check_apart(model, e.name)
            except ValueError:
                continue
            names.append(e.name.upper())
        elif e.name in model._device_of:
            kind, prm, _ = model._device_of[e.name]
            names += [f"{e.name.upper()}.{a}" for a in allowed(kind, prm)]
    return names


def value_of(model: NetlistModel, name: str) -> float:
    """The value ``name`` (``R1`` or ``D1.is``) has in ``model``; ``ValueError`` saying what
    may be named when it names nothing estimable."""
    element, field = split(model, name)
    e = model.circuit.netlist.element(element)
    if e is None:
        raise ValueError(f"no element {element.upper()!r} in the netlist")
    if not field:
        if e.kind not in ("r", "l"):
            raise ValueError(f"{name}: a resistor's or an inductor's value, or a device's "
                             "parameter as D1.is, may be a state")
        return float(e.value)
    if e.kind not in ("d", "q", "m"):
        raise ValueError(f"{name}: only a diode's, BJT's or MOSFET's parameter "
                         "(D1.is, Q1.ies, M1.kp) may be a state")
    kind, prm, _ = model._device_of[e.name]
    if "xbv" in prm:
        raise ValueError(f"{name}: {element.upper()} breaks down (bv), and its fitted "
                         "breakdown voltage depends on is and n: its parameters cannot be "
                         "states")
    if field not in allowed(kind, prm):
        names = ", ".join(f"{element.upper()}.{a}" for a in allowed(kind, prm))
        raise ValueError(f"{name}: expected one of {names}")
    value = prm[field]
    return float(-value if field == "vto" and kind == "pmos" else value)


def _check_apart(model: NetlistModel, element: str) -> None:
    """A resistor whose value is a state must meet only nodes whose KCL is a row of the
    drift (its conductance is not folded into the solved nodes or an H source's current)."""
    c = model.circuit
    e = c.netlist.element(element)
    folded = set(c.algebraic) | {node for _, node, _ in c.controls}
    touched = sorted(folded & set(e.nodes[:2]))
    if touched:
        raise ValueError(f"{element.upper()}: it meets node {touched[0]}, whose voltage is "
                         "solved from the resistors once (D71); its value cannot be a state")
    if any(term[0] in ("resistor", "device") and term[1] == e.name
           for term in c.output_terms):
        raise ValueError(f"{element.upper()}: an output is its current; its value cannot be "
                         "a state")


class ParameterStates(Model):
    """``base`` with ``parameters`` (:class:`Parameter`) appended to its states."""

    def __init__(self, base: NetlistModel, parameters: tuple[Parameter, ...]) -> None:
        self.base = base
        self.parameters = tuple(parameters)
        self.name = base.name
        self.params = base.params
        self.variant = base.variant
        self.state_names = tuple(base.state_names) + tuple(p.name for p in parameters)
        self.input_names = base.input_names
        self.output_names = base.output_names
        self.input_is_source_slope = base.input_is_source_slope
        self.input_affine = False
        self.regimes = base.regimes
        c = base.circuit
        summed = {c.controls[t[2]][1]: t[1] for t in c.output_terms if t[0] == "source"}
        for p in parameters:
            at = set(c.netlist.element(p.element).nodes[:4]) & set(summed)
            if at:
                raise ValueError(f"{p.name}: an output is the current of "
                                 f"{summed[min(at)].upper()}, which {p.element.upper()} "
                                 "carries; its value cannot be a state")
            if p.field is None and c.netlist.element(p.element).kind == "r":
                _check_apart(base, p.element)
            elif any(term[:2] == ("device", p.element) for term in base.circuit.output_terms):
                raise ValueError(f"{p.name}: an output is this device's current; its "
                                 "parameter cannot be a state")

    def __reduce__(self):
        """Pickled as the base and the parameters (the base's ``Params`` class is made at
        run time: :class:`NetlistModel`)."""
        return (ParameterStates, (self.base, self.parameters))

    @property
    def k(self) -> int:
        return len(self.parameters)

    @property
    def starts(self) -> np.ndarray:
        return np.array([p.start for p in self.parameters])

    @property
    def value_scales(self) -> tuple[float, ...]:
        """Each state in the units a table reports: the circuit's as they are, a value as
        ``theta`` times its first guess."""
        return (1.0,) * self.base.n_states + tuple(p.start for p in self.parameters)

    @property
    def state_scales(self) -> tuple[float, ...]:
        return tuple(self.base.state_scales) + (1.0,) * self.k

    @property
    def thesis_states(self) -> tuple | None:
        names = self.base.thesis_states
        return None if names is None else tuple(names) + tuple(p.name for p in self.parameters)

    @property
    def thesis_map(self) -> np.ndarray | None:
        """The base's map with the parameters mapped to themselves."""
        T = self.base.thesis_map
        if T is None:
            return None
        n = T.shape[0]
        out = np.eye(n + self.k)
        out[:n, :n] = T
        return out

    def extend(self, x: np.ndarray, values: np.ndarray | None = None) -> np.ndarray:
        """``x (..., n)`` with the parameters appended: ``values`` (as ``theta``, the value over
        the first guess) or the first guess itself (1)."""
        theta = np.ones(self.k) if values is None else np.asarray(values, float)
        x = np.asarray(x, float)
        return np.concatenate([x, np.broadcast_to(theta, x.shape[:-1] + (self.k,))], axis=-1)

    def _device(self, p: Parameter) -> int:
        """The index of ``p``'s device among the base's devices."""
        dev = self.base._device_of[p.element]
        return next(i for i, d in enumerate(self.base._devices) if d is dev)

    def _changes(self, theta: np.ndarray) -> tuple:
        """:meth:`NetlistModel._currents`' changes for parameters ``theta (..., k)``."""
        base = self.base
        resistors, devices = [], {}
        for j, p in enumerate(self.parameters):
            value = theta[..., j] * p.start
            e = base.circuit.netlist.element(p.element)
            if p.field is None and e.kind == "r":
                a, b = (base._node[x] for x in e.nodes[:2])
                resistors.append((a, b, 1.0 / value - 1.0 / e.value))
            elif p.field is not None:
                changed = devices.setdefault(self._device(p), {})
                changed.update(mirrored(base._device_of[p.element][0], {p.field: value})
                               if p.field == "vto" else {p.field: value})
        return resistors, devices

    def _columns(self, theta: np.ndarray, V: np.ndarray, changes: tuple) -> np.ndarray:
        """The currents leaving the base's rows, differentiated in ``theta``: ``(..., rows,
        k)``. A resistor's exactly (``d/dtheta (v_a - v_b) / (theta start)``); a device
        parameter's by a central difference (:data:`STEP`) of that device's currents alone."""
        base = self.base
        lead = V.shape[:-1]
        cols = np.zeros(lead + (base._G.shape[0], self.k))
        for j, p in enumerate(self.parameters):
            col = np.zeros(lead + (base._G.shape[0],))
            e = base.circuit.netlist.element(p.element)
            if p.field is None and e.kind == "l":
                continue                               # an inductor's: f_and_jacobian
            if p.field is None:
                a, b = (base._node[x] for x in e.nodes[:2])
                cur = -(V[..., a] - V[..., b]) / (theta[..., j] ** 2 * p.start)
                base._leave(col, None, ((a, cur, None), (b, -cur, None)))
            else:
                d = self._device(p)
                kind, prm, idx = base._devices[d]
                prm = {**prm, **changes[1][d]}
                for sign in (1.0, -1.0):
                    value = (theta[..., j] + sign * STEP) * p.start
                    moved = {**prm, **(mirrored(kind, {p.field: value}) if p.field == "vto"
                                       else {p.field: value})}
                    at = terminals.terms(base._P, kind, moved, idx, V)
                    base._leave(col, None, tuple((node, sign * cur / (2 * STEP), None)
                                                 for node, cur, _ in at))
            cols[..., j] = col
        return cols

    def f_and_jacobian(self, x, u, t: float = 0.0):
        """``[f(x, u; theta), 0]`` and its Jacobian: the netlist's in ``x``; in ``theta``
        :meth:`_columns` through the base's rows (``-C^-1`` of the currents' columns)."""
        x = np.asarray(x, float)
        base, n, k = self.base, self.base.n_states, self.k
        xs, theta = x[..., :n], x[..., n:]
        changes = self._changes(theta)
        out, d_out, V = base._currents(xs, u, changes)
        f, J = base._drift_of(out, d_out, V)
        lead = f.shape[:-1]
        Ja = np.zeros(lead + (n + k, n + k))
        Ja[..., :n, :n] = J
        if k:
            cols = self._columns(theta, V, changes)
            _, cols = base._sum_rows(np.zeros(cols.shape[:-1]), cols)
            rows = len(base.circuit.state_nodes)
            Ja[..., :rows, n:] = -np.einsum("ij,...jn->...in", base.circuit.C_inv, cols)
        for j, p in enumerate(self.parameters):        # di/dt = (v_a - v_b) / L
            e = base.circuit.netlist.element(p.element)
            if p.field is None and e.kind == "l":
                row = len(base.circuit.state_nodes) + base.circuit.inductors.index(e)
                ratio = e.value / (theta[..., j] * p.start)
                f[..., row] *= ratio
                Ja[..., row, :n] *= ratio[..., None]
                Ja[..., row, n + j] = -f[..., row] / theta[..., j]
        return np.concatenate([f, np.zeros(lead + (k,))], axis=-1), Ja

    def h(self, x):
        return self.base.h(np.asarray(x, float)[..., :self.base.n_states])

    def h_jacobian(self, x):
        H = self.base.h_jacobian(np.asarray(x, float)[..., :self.base.n_states])
        return np.concatenate([H, np.zeros(H.shape[:-1] + (self.k,))], axis=-1)

    def affine_output(self):
        return None

    def output_range(self):
        return self.base.output_range()

    def in_regime(self, regime, x, source):
        return self.base.in_regime(regime, np.asarray(x)[..., :self.base.n_states], source)

    def source_to_input(self, source, dt):
        return self.base.source_to_input(source, dt)

    def operating_point(self, x_guess=None, u=None):
        """The base's DC point at the first guesses, the parameters appended (1)."""
        guess = None if x_guess is None else np.asarray(x_guess, float)[:self.base.n_states]
        u0 = np.zeros(self.n_inputs) if u is None else np.asarray(u, float)
        start = self.base.operating_point(guess, u0)
        changes = self._changes(np.ones(self.k))
        sol = optimize.root(lambda v: self.base.drift(v, u0, changes)[0], start,
                            jac=lambda v: self.base.drift(v, u0, changes)[1], method="hybr",
                            options={"xtol": 1e-13})
        return self.extend(sol.x)
