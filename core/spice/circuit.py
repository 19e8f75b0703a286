"""A parsed netlist as an estim model (:class:`estim.models.base.Model`) by nodal analysis.

States: the voltage of every node that no voltage source fixes and a capacitor meets, and
the current of every inductor. Nodes fixed by a voltage source (from ground or from another
fixed node) carry the source's value: the model's voltage inputs (the sources named in
``inputs``) or the source's DC value; an ``E`` (or ``H``) source fixes its node to a
function of the others. A source between two nodes no source ties to ground makes a
supernode: its minus node is the state, its plus node follows it, and they share one KCL
row (D76). Every node voltage is then
affine in the states and inputs, ``V = P x + Q u + r``. KCL at the state nodes (supernodes),
with the nodal capacitance matrix ``C``,

    C v' = - (the currents leaving each node through R, G, I, L, D, Q and M)
           + (a slope input's capacitor currents),

gives ``f``; inductors add ``L i' = v(n1) - v(n2)``. ``C`` must be invertible. A node no
capacitor meets is not a state: where only linear branches carry its current, its KCL gives
its voltage as affine in the states and inputs, folded into ``V = P x + Q u + r``; where a
device or an F source does, it is refused by name (deviations D71: a shunt capacitor, as the
hand-written models carry ``C_par``, keeps ``f`` explicit and its Jacobian exact, where a
Newton solve of such nodes inside ``f`` would not). A node with no
DC path (only capacitors and current sources reach it) is refused too. A current source
named as an input adds its value to the KCL rows of its two nodes (leaving the ``+`` node,
as SPICE's current flows from ``+`` through the source to ``-``). An input whose node
reaches the circuit only through capacitors drives it by its slope (D72).

Device laws and their ``.model`` parameters: Shockley diodes with series resistance
(``d``: ``is n rs``; closed form by the Lambert W function; junction capacitance ``cjo vj
m tt fc``, :mod:`estim.spice.junctions`; SPICE's reverse law below
``-3 n V_T``), Ebers-Moll NPN/PNP (``npn``,
``pnp``: ``ies alpha_f alpha_r vt``, ``I_CS`` by reciprocity unless ``ics`` is given;
:mod:`estim.models.devices.ebers_moll`, the thesis' law), EKV NMOS (``nmos``: ``u_t v_t0 eta i_0
w_l law``; the laws of :mod:`estim.models.mosfet_ekv`, ``law`` the index in
:data:`NMOS_LAWS`, 0 EKV) and PMOS (``pmos``: the same parameters, the NMOS law of the
negated voltages, negated: :func:`estim.spice.devices.mosfet`); with ``level=1`` in its
``.model``, an NMOS or PMOS is SPICE's level-1 MOSFET (``vto kp lambda gamma phi``, ``w=``
and ``l=`` on its line; :mod:`estim.spice.level1`), whose overlap capacitances ``cgso
cgdo cgbo`` join the nodal capacitance matrix as capacitors of their own. Jacobian, input
Jacobian and Hessian are analytic. ``F`` and ``H`` sources take the current of a voltage
source as KCL at the node it fixes (no capacitor there; for ``H`` only linear branches: D76).
"""


from __future__ import annotations

import dataclasses
import re

import numpy as np

from estim.spice.capacitance_checks import check_dc_paths, check_invertible
from estim.spice.devices import NMOS_LAWS, model_defaults
from estim.spice.gummel_poon import DYNAMIC, GUMMEL_POON
from estim.spice.internal_nodes import expand
from estim.spice.junctions import junction_capacitors
from estim.spice.level1 import overlap_capacitors
from estim.spice.parser import Netlist, NetlistError
from estim.util import lazy

special = lazy.load("scipy.special")
kernels = lazy.load("estim.numerics.kernels")


GROUND = ("0", "gnd")

OUTPUTS = ("v(node), v(node,node), i(inductor, resistor, diode or voltage source), "
           "ic/ib/ie(bjt) or id(mosfet)")
"""What a netlist model's output may be (:meth:`Circuit._output`)."""


@dataclasses.dataclass
class Circuit:
    """The nodal-analysis structure of a netlist: which nodes are states, fixed or derived,
    the capacitance matrix and the element lists, in index form."""

    netlist: Netlist
    inputs: tuple[str, ...]
    output: str | tuple[str, ...]
    """What is measured: one quantity (:data:`OUTPUTS`) or several."""

    def __post_init__(self) -> None:
        given = {n for e in self.netlist.elements for n in e.nodes}
        self.netlist = expand(self.netlist)      # series resistances to internal nodes
        net, src = self.netlist, self.netlist.source
        self.internal = {n for e in net.elements for n in e.nodes} - given
        """The internal nodes :func:`estim.spice.internal_nodes.expand` added."""
        self.junctions = junction_capacitors(net)
        """The junction capacitances (:mod:`estim.spice.junctions`): the model adds
        ``C(v) - cjo`` of each to the constant ``C``."""
        self.elements = [*net.elements, *overlap_capacitors(net),
                         *(ch.capacitor() for ch in self.junctions if ch.p["cjo"])]
        """The netlist's elements, the level-1 MOSFETs' overlap capacitors and each junction
        capacitance at zero bias."""
        self.outputs = (self.output,) if isinstance(self.output, str) else tuple(self.output)
        if not self.outputs:
            raise NetlistError(src, 0, f"no output; expected {OUTPUTS}")
        for e in net.elements:
            if e.kind in "fh":
                ctrl = net.element(e.ref)
                if ctrl is None or ctrl.kind != "v":
                    raise NetlistError(src, e.line, f"{e.name}: its controlling source "
                                       f"{e.ref!r} is not a voltage source of the netlist")
        met = {n for x in net.elements for n in (x.nodes[:2] if x.kind == "b" else x.nodes)}
        for e in net.elements:
            missing = [n for n in e.nodes[2:] if e.kind == "b" and n not in met]
            if missing:
                raise NetlistError(src, e.line, f"{e.name}: v({missing[0]}) names no node "
                                   "of the circuit")
        for e in net.elements:
            if e.kind in "vi" and e.waveform[0] != "dc" and e.name not in self.inputs:
                raise NetlistError(src, e.line, f"{e.name}: a {e.waveform[0].upper()} source "
                                   "that is not a model input; estim drives a circuit through "
                                   "its inputs (name it in model.input) and holds the other "
                                   "sources at their DC value")
        twice = sorted({n for n in self.inputs if self.inputs.count(n) > 1})
        if twice:
            raise NetlistError(src, 0, f"input {twice[0]!r} named more than once")
        for name in self.inputs:
            e = net.element(name)
            if e is None or e.kind not in "vi":
                raise NetlistError(src, 0, f"input {name!r} is not a voltage or current "
                                   "source of the netlist")
        nodes = sorted({n for e in self.elements for n in e.nodes} - set(GROUND))
        if not nodes:
            raise NetlistError(src, 0, "no node but ground")
        self.fixed, root = self._fix_nodes()
        self.root = root
        # every node no source fixes, until those without a capacitor are set apart below
        self.state_nodes = [n for n in nodes if n not in self.fixed]
        self.inductors = [e for e in net.elements if e.kind == "l"]
        self.index = {n: i for i, n in enumerate(self.state_nodes)}
        # a floating node: connected to only one element terminal
        touches: dict[str, int] = {}
        for e in self.elements:
            for n in e.nodes:
                touches[n] = touches.get(n, 0) + 1
        lonely = sorted(n for n in self.state_nodes if touches.get(n, 0) < 2)
        if lonely:
            raise NetlistError(src, 0, f"floating node(s) {', '.join(lonely)}: connected to "
                               "one terminal only")
        k = len(self.state_nodes)
        self.slope = self._input_mode(root)
        self.controls = self._controls()
        C = np.zeros((k, k))
        B = np.zeros((k, len(self.inputs)))
        for e in self.elements:
            if e.kind != "c":
                continue
            ends = [self._follows(n, e) for n in e.nodes]
            for this, other in ((ends[0], ends[1]), (ends[1], ends[0])):
                if this is None or this[0] != "x":
                    continue
                C[this[1], this[1]] += e.value
                if other is None:
                    continue
                if other[0] == "x":
                    C[this[1], other[1]] -= e.value
                else:
                    B[this[1], other[1]] += e.value
        check_dc_paths(self, GROUND)
        C, B = self._set_apart_algebraic(C, B, root)
        k = len(self.state_nodes)
        check_invertible(self, C)
        self.C = C
        self.C_inv = np.linalg.inv(C) if k else np.zeros((0, 0))
        self.B = B
        for e in net.elements:
            if e.kind in "dqm":
                model = net.models.get(e.ref)
                if model is None:
                    raise NetlistError(src, e.line, f"{e.name}: no .model {e.ref}")
                want = {"d": ("d",), "q": ("npn", "pnp"), "m": ("nmos", "pmos")}[e.kind]
                if model.type not in want:
                    raise NetlistError(src, model.line, f".model {model.name}: type "
                                       f"{model.type!r} for {e.name}; expected "
                                       f"{' or '.join(want)}")
                known = model_defaults(model)
                unknown = set(model.params) - set(known)
                if unknown & set(DYNAMIC) and known is GUMMEL_POON:
                    raise NetlistError(src, model.line, f".model {model.name}: "
                                       f"{', '.join(sorted(unknown & set(DYNAMIC)))}: estim's "
                                       "Gummel-Poon is the static law, its junction "
                                       "capacitances and series resistances (no substrate "
                                       "capacitance, irb/rbm, xtf/vtf/itf or temperature "
                                       "terms); give the nodes capacitors of their own")
                if unknown:
                    raise NetlistError(src, model.line, f".model {model.name}: unknown "
                                       f"parameter(s) {sorted(unknown)}; expected "
                                       f"{sorted(known)}")
                if "level" in model.params and model.params["level"] != 1:
                    raise NetlistError(src, model.line, f".model {model.name}: level "
                                       f"{model.params['level']:g}; estim has level 1 (and "
                                       "its EKV law without a level)")
                if e.size and "level" not in model.params:
                    raise NetlistError(src, e.line, f"{e.name}: w and l on an EKV device; "
                                       f"give its w_l in .model {model.name}")
                if (model.type in ("nmos", "pmos") and "level" not in model.params
                        and model.params.get("law", 0) not in range(5)):
                    raise NetlistError(src, model.line, f".model {model.name}: law "
                                       f"{model.params['law']!r}; expected 0-4 ("
                                       f"{', '.join(f'{i} {n}' for i, n in enumerate(NMOS_LAWS))})")
        self.output_terms = [self._output(text) for text in self.outputs]
        for i, term in enumerate(self.output_terms):
            if term in self.output_terms[:i]:
                raise NetlistError(src, 0, f"output {self.outputs[i]!r} measures what "
                                   f"{self.outputs[self.output_terms.index(term)]!r} does")

    def _set_apart_algebraic(self, C: np.ndarray, B: np.ndarray,
                             root: dict) -> tuple[np.ndarray, np.ndarray]:
        """The nodes (supernodes) no capacitor meets are not states: their KCL holds at every
        instant, and where only linear branches (R, G, I, L, and sources that fix their
        followers) carry their currents it gives their voltages as affine in the states and
        inputs (D71; :meth:`estim.spice.netlist_model.NetlistModel._prepare` solves it). A
        device or an F source carrying current into such a node would make that solve
        nonlinear: refused by name. Sets the states, their names, index and KCL rows, and
        ``algebraic`` (those nodes) with ``algebraic_row`` (each node's among them, for the
        nodes that follow one); returns ``C`` and ``B`` on the states."""
        k = len(self.state_nodes)
        cut = [i for i in range(k) if C[i, i] == 0]
        names = {self.state_nodes[i] for i in cut}
        group = {n: root.get(n, n) for n in root if root.get(n, n) in names} | {n: n for n in names}
        carried = []
        for e in self.netlist.elements:
            ends = {"d": e.nodes[:2], "q": e.nodes[:3], "m": e.nodes[0:3:2],
                    "f": e.nodes[:2], "b": e.nodes[:2]}.get(e.kind, ())
            hit = sorted({group[n] for n in ends if n in group})
            if hit:
                carried.append((hit, e.name))
        if carried:
            nodes = sorted({n for hit, _ in carried for n in hit})
            who = ", ".join(sorted({name for _, name in carried}))
            raise NetlistError(self.netlist.source, 0, f"node(s) {', '.join(nodes)} have no "
                               f"capacitive path and carry the current of {who}: estim solves a "
                               "node without a capacitor from its KCL for linear branches only; "
                               "add a small shunt capacitor (e.g. 1p to ground) to each")
        keep = [i for i in range(k) if i not in cut]
        self.algebraic = [self.state_nodes[i] for i in cut]
        self.state_nodes = [self.state_nodes[i] for i in keep]
        self.index = {n: i for i, n in enumerate(self.state_nodes)}
        names_ = [f"v({n})" for n in self.state_nodes] + [f"i({e.name})" for e in self.inductors]
        self.state_names = tuple(names_)
        # each node's KCL row: its own state's, or that of the state node whose voltage it
        # follows through voltage sources (a supernode); None for a node tied to ground or
        # one without a capacitor (``algebraic_row`` numbers those)
        every = set(root) | set(self.index) | names
        self.row = {n: self.index.get(root.get(n, n)) for n in every if n not in GROUND}
        where = {n: j for j, n in enumerate(self.algebraic)}
        self.algebraic_row = {n: where[g] for n, g in group.items()}
        return C[np.ix_(keep, keep)], B[keep]

    def _fix_nodes(self) -> tuple[dict, dict]:
        """Which node each voltage source (V, E, H) fixes: ``{node: (source, other end,
        sign)}`` with ``v(node) = v(other) + sign * value``, and each such node's root: ground,
        or the state node at the end of its chain of sources (a supernode, whose KCL is
        one row). Sources with an end already known go first, so every chain that reaches
        ground is rooted there; a source between two unknown nodes makes its minus node a
        state."""
        net, src = self.netlist, self.netlist.source
        root: dict[str, str] = {g: "0" for g in GROUND}
        fixed: dict[str, tuple] = {}
        pending = [e for e in net.elements if e.kind in "veh"]
        while pending:
            e = next((s for s in pending if s.nodes[0] in root or s.nodes[1] in root), None)
            if e is None:
                e = pending[0]
                root[e.nodes[1]] = e.nodes[1]
            p, m = e.nodes[:2]
            if p in root and m in root:
                raise NetlistError(src, e.line, f"{e.name}: a loop of voltage sources "
                                   f"(both {p} and {m} are already fixed)")
            node, other, sign = (p, m, 1.0) if m in root else (m, p, -1.0)
            fixed[node] = (e, other, sign)
            root[node] = root[other]
            pending.remove(e)
        return fixed, root

    def fixed_by(self, source) -> str:
        """The node that voltage source ``source`` fixes (:meth:`_fix_nodes`)."""
        return next(n for n, v in self.fixed.items() if v[0] is source)

    def control_index(self, ref: str) -> int:
        """The row among :attr:`controls` of the controlling source named ``ref``."""
        return next(i for i, ctl in enumerate(self.controls) if ctl[0].name == ref)

    def _follows(self, node: str, cap) -> tuple | None:
        """What a capacitor's terminal at ``node`` moves with: ``("x", i)`` a state (the
        node's own or its supernode's), ``("u", j)`` the slope of input ``j``, or None (a
        constant). A node that an input (other than directly), an E or an H source drives
        is refused: the model would need that source's slope."""
        if node in self.index:
            return ("x", self.index[node])
        if node in self.input_nodes:
            return ("u", self.input_nodes.index(node))
        n = node
        while n in self.fixed:
            e, other, _ = self.fixed[n]
            if e.kind in "eh" or e.name in self.inputs:
                raise NetlistError(self.netlist.source, cap.line, f"{cap.name}: a capacitor "
                                   f"to node {node}, which the model input (or an E or H "
                                   "source) drives; the model would need its slope (put the "
                                   "source behind a resistor)")
            n = other
        return ("x", self.index[n]) if n in self.index else None

    def _controls(self) -> list[tuple]:
        """The controlling sources of the F and H sources: ``(source, node, sign)`` with
        ``i(source) = sign * (the currents leaving node through its other elements)``, at the
        node the source fixes (SPICE's current flows into the + terminal: sign -1 there, +1
        at the - terminal). That node may meet no capacitor (its current would need the
        slope of the states), no other V, E, H or F source, and, for an H source (whose
        voltage must stay affine in the states), only R, G, I and L."""
        net, src = self.netlist, self.netlist.source
        out: list[tuple] = []
        for e in net.elements:
            if e.kind not in "fh":
                continue
            vx = net.element(e.ref)
            node = self.fixed_by(vx)
            sign = -1.0 if node == vx.nodes[0] else 1.0
            met = self._summed_at(vx, node, linear=e.kind == "h")
            if met:
                raise NetlistError(src, e.line, f"{e.name}: the current of {vx.name} is "
                                   f"summed at node {node}, which {met[0]} meets: {met[1]}; "
                                   f"move {vx.name} next to a branch of R, G, I, L"
                                   f"{'' if e.kind == 'h' else ', D, Q, M'} only")
            if not any(c[0] is vx for c in out):
                out.append((vx, node, sign))
        for text in self.outputs:                  # a voltage source's current measured
            m = re.fullmatch(r"\s*i\(\s*([^,()\s]+)\s*\)\s*", text.lower())
            vx = net.element(m.group(1)) if m else None
            if vx is None or vx.kind != "v" or any(c[0] is vx for c in out):
                continue
            node = self.fixed_by(vx)
            met = self._summed_at(vx, node, linear=False)
            if met:
                raise NetlistError(src, 0, f"output {text!r}: the current of {vx.name} is "
                                   f"summed at node {node}, which {met[0]} meets: {met[1]}")
            out.append((vx, node, -1.0 if node == vx.nodes[0] else 1.0))
        return out

    def _static(self, text: str, name: str, terminal: int) -> tuple:
        """A device's current as an output: its static law, refused by name for a device
        with a junction capacitance (whose current SPICE counts with its charge's)."""
        charged = [ch.name for ch in self.junctions if ch.device.name == name]
        if charged:
            raise NetlistError(self.netlist.source, 0, f"output {text!r}: {name} stores "
                               f"charge ({charged[0]}), and estim's device current is its "
                               "static one; measure the current of a resistor in series "
                               "with it")
        return ("device", name, terminal)

    def _summed_at(self, vx, node: str, linear: bool) -> tuple[str, str] | None:
        """``(element, why)`` of the first element at ``node`` (which voltage source ``vx``
        fixes) that keeps its current from being summed there: a capacitor (the current
        would need the states' slope), another source, and with ``linear`` a device or the
        model input; None where there is none."""
        for x in self.elements:
            if x is vx or node not in (x.nodes[:2] if x.kind in "veghfb" else x.nodes):
                continue
            if x.kind == "c":
                return x.name, "a capacitor (its current would need the states' slope)"
            if x.kind in "vehf":
                return x.name, "another source"
            if linear and x.kind in "dqmb":
                return x.name, "a device (an H source needs a linear controlling current)"
            if linear and x.name in self.inputs:
                return x.name, "a model input (an H source's voltage would follow it)"
        return None

    def _input_mode(self, root: dict) -> bool:
        """Whether the model input is the sources' slope (True) or their value. An input
        whose node reaches the circuit only through capacitors (a coupling capacitor, as the
        MOSFET's C_GX) drives it by its slope ``C dv/dt``; one that reaches it only through
        other elements drives it by its value. A node with both is refused (the model would
        need value and slope), as are inputs of both kinds in one netlist, and an input that
        floats between two nodes no other source ties to ground."""
        net, src = self.netlist, self.netlist.source
        self.input_nodes = []
        kinds = set()
        for name in self.inputs:
            e = net.element(name)
            if e.kind == "i":                   # a current into KCL rows: by its value
                self.input_nodes.append(None)
                kinds.add(False)
                continue
            node = self.fixed_by(e)
            if root[node] not in GROUND:
                raise NetlistError(src, e.line, f"{e.name}: a model input must be tied to "
                                   "ground or to a node a DC source fixes; it floats between "
                                   f"{e.nodes[0]} and {e.nodes[1]}")
            self.input_nodes.append(node)
            others = [x for x in self.elements if x is not e and node in x.nodes]
            caps = [x for x in others if x.kind == "c"]
            if caps and len(caps) < len(others):
                rest = next(x for x in others if x.kind != "c")
                cap = caps[0]
                own = cap in net.elements
                device, _, what = cap.name.rpartition(".")
                what = ("a junction capacitance" if what in ("cjo", "cbd", "cbs", "cje", "cjc")
                        else "an overlap capacitance")
                where = "this capacitor" if own else f"{cap.name} ({what} of {device})"
                fix = ("in series with the capacitor" if own else
                       f"between {e.name} and node {node}")
                raise NetlistError(src, cap.line, f"{cap.name}: input {e.name} drives node "
                                   f"{node} through {where} and through {rest.name}; estim "
                                   "takes an input by its slope (capacitors only) or by its "
                                   f"value (no capacitor): put a resistor {fix}")
            kinds.add(bool(caps))
        if len(kinds) > 1:
            raise NetlistError(src, 0, "inputs driving through capacitors (by their slope) "
                               "and inputs driving by their value (current sources among "
                               "them) in one netlist: not supported")
        return kinds == {True}

    def _output(self, text: str) -> tuple:
        """What ``text`` measures: ``("v", i, j)`` states (``j`` None or a second state),
        ``("node", a, b)`` node voltages, ``("i", i)`` an inductor's current (a state),
        ``("resistor", name)`` or ``("device", name, terminal)``: a resistor's current from
        its first node to its second, a diode's from anode to cathode, the current into a
        BJT's collector, base or emitter (``ic``, ``ib``, ``ie``) or a MOSFET's drain
        (``id``), as SPICE names them."""
        src = self.netlist.source
        m = re.fullmatch(r"\s*(ic|ib|ie|id)\(\s*([^,()\s]+)\s*\)\s*", text.lower())
        if m:
            e = self.netlist.element(m.group(2))
            want = "m" if m.group(1) == "id" else "q"
            if e is None or e.kind != want:
                raise NetlistError(src, 0, f"output {text!r}: {m.group(1)}() of a "
                                   f"{'MOSFET' if want == 'm' else 'BJT'} of the netlist")
            return self._static(text, e.name, "cbe".index(m.group(1)[1]) if want == "q" else 0)
        m = re.fullmatch(r"\s*([vi])\(\s*([^,()\s]+)\s*(?:,\s*([^,()\s]+)\s*)?\)\s*",
                         text.lower())
        if not m:
            raise NetlistError(src, 0, f"output {text!r}: expected {OUTPUTS}")
        if m.group(1) == "i":
            names = [e.name for e in self.inductors]
            e = self.netlist.element(m.group(2))
            if e is not None and e.kind == "v" and not m.group(3):
                return ("source", e.name, self.control_index(e.name))
            if m.group(3) or e is None or e.kind not in "lrd":
                raise NetlistError(src, 0, f"output {text!r}: i() of an inductor, resistor, "
                                   "diode or voltage source of the netlist (ic/ib/ie() of a "
                                   "BJT, id() of a MOSFET)")
            if e.kind == "l":
                return ("i", len(self.state_nodes) + names.index(m.group(2)))
            return ("resistor", e.name) if e.kind == "r" else self._static(text, e.name, 0)
        if m.group(3) is not None and (m.group(2) == m.group(3) or
                                       {m.group(2), m.group(3)} <= set(GROUND)):
            raise NetlistError(self.netlist.source, 0, f"output {text!r}: the voltage between "
                               "a node and itself is zero whatever the circuit does; name "
                               "two different nodes")
        if m.group(2) in GROUND and m.group(3) is None:
            raise NetlistError(self.netlist.source, 0, f"output {text!r}: ground's voltage is "
                               "zero whatever the circuit does; name a node of the circuit")
        for n in (m.group(2), m.group(3)):
            if n and self.row.get(n) is None and n not in self.algebraic_row:
                raise NetlistError(self.netlist.source, 0, f"output {text!r}: node {n} is "
                                   f"not a state node ({', '.join(self.state_nodes)}) nor "
                                   "follows one through voltage sources")
        if all(n is None or n in self.index for n in (m.group(2), m.group(3))):
            return ("v", self.index[m.group(2)],
                    self.index.get(m.group(3)) if m.group(3) else None)
        return ("node", m.group(2), m.group(3))
