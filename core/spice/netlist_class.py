"""The model class of each netlist: :func:`model_class` makes a subclass of
:class:`estim.spice.netlist_model.NetlistModel` for a netlist file (its ``.param`` values as
the model's parameters) and registers it; :func:`rebuild` makes it again in a worker process
from the arguments it was made with."""

from __future__ import annotations

import copyreg
import dataclasses
import re
from pathlib import Path

from estim.config import registry
from estim.config.settings import setting
from estim.spice.circuit import Circuit
from estim.spice.netlist_model import NetlistClass, NetlistModel
from estim.spice.parser import read


def build_model_class(circuit: Circuit, name: str) -> type:
    """A :class:`Model` subclass for ``circuit``: its ``Params`` are the netlist's ``.param``
    values (overridable in a config's ``model.params``), re-evaluated into element values
    when they change."""
    net = circuit.netlist
    fields = [(k, float, setting(float(v), unit="-", doc="netlist .param"))
              for k, v in net.params.items()]
    Params = dataclasses.make_dataclass(f"{name}_params", fields, frozen=True)
    inputs = tuple(f"d({i})/dt" for i in circuit.inputs) if circuit.slope \
        else tuple(circuit.inputs)
    attrs = {"state_names": circuit.state_names, "input_names": inputs,
             "input_is_source_slope": circuit.slope, "input_affine": circuit.slope,
             "output_names": circuit.outputs, "Params": Params, "variants": {},
             "circuit": circuit, "__doc__": f"Netlist model of {net.source} ({net.title})."}
    clean = re.sub(r"\W", "_", name)
    return type(f"Netlist_{clean}", (NetlistModel,), attrs)


def model_class(path: Path, inputs, output: str | tuple, name: str | None = None,
                hold: str | None = None, thesis_states=None) -> type:
    """The model class of the netlist at ``path`` (registered under ``name``, default
    ``netlist:<stem>``); ``hold`` is how its value inputs hold a sample (``"mean"``, the
    default, ``"start"`` or ``"end"``: :meth:`NetlistModel.source_to_input`);
    ``thesis_states`` the quantities a filter's Q and P0 are written in
    (:attr:`NetlistModel.thesis_map`)."""
    inputs = (inputs,) if isinstance(inputs, str) else tuple(inputs)
    output = output if isinstance(output, str) else tuple(output)
    circuit = Circuit(read(path), tuple(i.lower() for i in inputs), output)
    name = name or f"netlist:{path.stem}"
    cls = build_model_class(circuit, name)
    cls.name = name
    cls.hold = hold or "mean"
    cls.thesis_states = tuple(thesis_states) if thesis_states else None
    cls.origin = (str(path), inputs, output, name, hold, cls.thesis_states)
    registry.MODELS.register(name, cls)
    return cls


def rebuild(origin: tuple) -> type:
    """The model class of ``origin`` (:attr:`NetlistModel.origin`): how a netlist model class
    crosses to a worker process (pickled as the arguments of :func:`model_class`)."""
    known = registry.MODELS.get(origin[3])
    if known is not None and getattr(known, "origin", None) == origin:
        return known
    return model_class(Path(origin[0]), *origin[1:])


def _reduce_class(cls: type):
    origin = getattr(cls, "origin", None)
    return (rebuild, (origin,)) if origin is not None else cls.__qualname__


copyreg.pickle(NetlistClass, _reduce_class)
