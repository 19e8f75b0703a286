"""Series resistances as SPICE lays them out: a resistor to an internal node, the device's
junction at that node. A diode's ``rs`` with a junction capacitance (which sits at the
junction, behind ``rs``) and a Gummel-Poon BJT's ``rb``, ``rc`` and ``re`` become resistor
elements (``d1.rs``, ``q1.rb``, ...) to internal nodes (``d1.a``, ``q1.b``, ``q1.c``,
``q1.e``), and the device's ``.model`` drops them. Each internal node is then a state
through the junction capacitance that meets it (deviations D71: a node without one that
carries a device's current is refused), so a BJT's ``rb`` needs ``cje`` or ``cjc``,
``rc`` needs ``cjc`` and ``re`` ``cje``: refused by name otherwise. A diode's ``rs``
without a capacitance stays in its law (eliminated in closed form). The netlist ngspice
runs is this one, so its internal nodes are compared too.
"""

from __future__ import annotations

import dataclasses

from estim.spice.devices import DIODE
from estim.spice.gummel_poon import GUMMEL_POON, is_gummel_poon
from estim.spice.parser import Element, Netlist, NetlistError

BJT_RESISTANCES = (("rb", 1, ("cje", "cjc")), ("rc", 0, ("cjc",)), ("re", 2, ("cje",)))
"""Each BJT series resistance: its terminal (collector, base, emitter) and the junction
capacitances of which one must meet its internal node."""


def _fresh(name: str, used: set[str]) -> str:
    """``name`` as a node name no other node has (in ngspice's flattened form too)."""
    while name in used or name.replace(".", "_") in used:
        name += "_"
    used |= {name, name.replace(".", "_")}
    return name


def expand(net: Netlist) -> Netlist:
    """``net`` with its series resistances laid out as resistors to internal nodes (the
    module's text); ``net`` itself where it has none to lay out."""
    models, elements = dict(net.models), []
    used = {n for e in net.elements for n in e.nodes}
    for e in net.elements:
        model = net.models.get(e.ref) if e.kind in "dq" else None
        if e.kind == "d" and model is not None and model.type == "d":
            p = {**DIODE, **model.params}
            if p["rs"] > 0 and (p["cjo"] > 0 or p["tt"] > 0):
                inner = _fresh(f"{e.name}.a", used)
                elements += [Element("r", f"{e.name}.rs", (e.nodes[0], inner), p["rs"],
                                     line=e.line),
                             dataclasses.replace(e, nodes=(inner, *e.nodes[1:]))]
                models[model.name] = dataclasses.replace(model,
                                                         params={**model.params, "rs": 0.0})
                continue
        if (e.kind == "q" and model is not None and model.type in ("npn", "pnp")
                and is_gummel_poon(model.params)):
            p = {**GUMMEL_POON, **model.params}
            nodes = list(e.nodes)
            for key, terminal, caps in BJT_RESISTANCES:
                if p[key] <= 0:
                    continue
                if not any(p[c] > 0 for c in caps):
                    raise NetlistError(net.source, model.line, f".model {model.name}: {key} "
                                       f"without {' or '.join(caps)}; its internal node "
                                       f"({e.name}) would have no capacitance, which estim "
                                       "needs (D71): give the junction capacitance, or the "
                                       "resistance as an element with a capacitor at the "
                                       "device's node")
                inner = _fresh(f"{e.name}.{'cbe'[terminal]}", used)
                elements.append(Element("r", f"{e.name}.{key}", (nodes[terminal], inner),
                                        p[key], line=e.line))
                nodes[terminal] = inner
            if nodes != list(e.nodes):
                elements.append(dataclasses.replace(e, nodes=tuple(nodes)))
                models[model.name] = dataclasses.replace(model, params={
                    k: v for k, v in model.params.items() if k not in ("rb", "rc", "re")})
                continue
        elements.append(e)
    if len(elements) == len(net.elements):
        return net
    return dataclasses.replace(net, elements=elements, models=models)
