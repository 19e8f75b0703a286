"""SPICE netlists as estim models: :mod:`estim.spice.parser` reads the netlist,
:mod:`estim.spice.circuit` lays out the nodal analysis, :mod:`estim.spice.netlist_model` is
its model and :mod:`estim.spice.netlist_class` makes the model's class,
:mod:`estim.spice.ngspice` runs the same circuit in ngspice to compare. A config names a
netlist in its model block,

    model: {netlist: circuits/diffamp_em.cir, input: [VB1, VB2], output: "v(c1,c2)"}

and :func:`resolve_model_block` registers the model as ``netlist:<file stem>`` before the
config is validated, so every analysis takes it as it takes a hand-written model.
"""

from __future__ import annotations

import warnings
from pathlib import Path

from estim.config.settings import shown
from estim.errors import ConfigError, Notice
from estim.spice.netlist_class import model_class, rebuild
from estim.spice.parser import NetlistError
from estim.spice.sources import input_from_netlist
from estim.util.shipped import shipped_folder

__all__ = ["NetlistError", "find_netlist", "model_class", "rebuild", "resolve_model_block"]


def find_netlist(name: str, source: str) -> Path | None:
    """``name`` as given (absolute); else relative to the config ``source``'s folder or any
    folder above it (a project's ``circuits/`` beside its ``configs/``, also from
    ``configs/netlist/``), or to the working folder; else, for ``circuits/NAME``, the
    netlists installed with estim (``estim.circuits``)."""
    p = Path(name)
    if p.is_absolute():
        return p if p.is_file() else None
    here = Path(source).resolve().parent
    for folder in (here, *here.parents, Path.cwd()):
        if (folder / p).is_file():
            return folder / p
    if p.parts[:1] == ("circuits",):
        shipped = shipped_folder("circuits")
        if (shipped / Path(*p.parts[1:])).is_file():
            return shipped / Path(*p.parts[1:])
    return None


def resolve_model_block(data: dict, source: str) -> None:
    """If ``data["model"]`` names a ``netlist``, build and register its model and set the
    block's ``name`` to it; a netlist that cannot be used is a config error naming the
    netlist's file and line."""
    block = data.get("model") if isinstance(data, dict) else None
    if not isinstance(block, dict):
        return
    if block.get("netlist") is None:
        for key in ("input", "output", "hold", "thesis_states"):
            if block.get(key) is not None:
                raise ConfigError(source, f"model.{key}", "only with model.netlist (a "
                                  "registered model declares its own inputs and outputs)")
        return
    netlist = block["netlist"]
    if block.get("name") is not None and not (
            isinstance(netlist, str) and block["name"] == f"netlist:{Path(netlist).stem}"):
        raise ConfigError(source, "model.name", "give either a registered model's name or a "
                          "netlist, not both")      # (a resolved config carries the one it made)
    if block.get("hold") not in (None, "mean", "start", "end"):
        raise ConfigError(source, "model.hold", f"expected mean, start or end, got "
                          f"{block['hold']!r}")
    if not isinstance(netlist, str) or not netlist or "\0" in netlist:
        raise ConfigError(source, "model.netlist", f"expected a file name, got {shown(netlist)}")
    if len(netlist.encode("utf-8", "surrogateescape")) > 1024 or any(
            len(part.encode("utf-8", "surrogateescape")) > 255 for part in Path(netlist).parts):
        raise ConfigError(source, "model.netlist", f"{shown(netlist)}: a path longer than a "
                          "netlist's may be (1024 bytes, 255 per name)")
    path = find_netlist(netlist, source)
    if path is None:
        raise ConfigError(source, "model.netlist", f"no file {netlist!r} beside the config, "
                          "in a folder above it, in the working folder or (circuits/NAME) "
                          "among the netlists installed with estim")
    inputs = block.get("input")
    if not inputs or not (isinstance(inputs, str) or (
            isinstance(inputs, list) and all(isinstance(i, str) for i in inputs))):
        raise ConfigError(source, "model.input", "expected the name of the voltage source the "
                          "model input drives, or a list of them")
    output = block.get("output")
    if not (isinstance(output, str) or (isinstance(output, list) and output and all(
            isinstance(o, str) for o in output))):
        raise ConfigError(source, "model.output", "expected v(node), v(node,node), "
                          "i(inductor, resistor, diode or voltage source), ic/ib/ie(bjt) or "
                          "id(mosfet), or a list of them")
    states = block.get("thesis_states")
    if states is not None and (not isinstance(states, list)
                               or not all(isinstance(s, str) for s in states)):
        raise ConfigError(source, "model.thesis_states", "expected a list of v(node), "
                          "v(node,node) or i(inductor)")
    try:
        cls = model_class(path, inputs, output, hold=block.get("hold"), thesis_states=states)
    except NetlistError as exc:
        raise ConfigError(source, "model.netlist", str(exc)) from None
    if states is not None:
        try:
            cls().thesis_map  # noqa: B018 (building the map checks the quantities)
        except NetlistError as exc:
            raise ConfigError(source, "model.thesis_states", exc.message) from None
    if data.get("analysis", "estimation") == "estimation":
        input_from_netlist(data, cls, source)
    else:
        for name in cls.circuit.inputs:
            wave = cls.circuit.netlist.element(name).waveform
            if wave[0] != "dc":
                warnings.warn(f"{source}: the netlist's {wave[0].upper()} waveform on input "
                              f"{name.upper()} is replaced by the config's rows (a "
                              f"{data.get('analysis')} config gives its own inputs)", Notice,
                              stacklevel=2)
    block["name"] = cls.name
