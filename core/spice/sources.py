"""The netlist's own waveform on the model input (a ``SIN``, ``PULSE`` or ``PWL`` source) as
an estimation config's input, where the config's ``input`` block gives none
(:mod:`estim.experiments.estimation.source` makes the samples).

``SIN(vo va f)``: a sine of amplitude ``va`` and frequency ``f`` about ``vo``.
``PULSE(v1 v2 td tr tf pw per)``: a pulse from ``v1`` to ``v2`` from ``td``, high for
``pw / per`` of each period ``per``; without ``pw`` and ``per`` (SPICE: both the run's
length) a step at ``td``. ``PWL(t1 v1 t2 v2 ...)``: its knots. Rise and fall times are not
kept: every source is held over each sample interval, so an edge takes one sample time.
"""

from __future__ import annotations

import warnings

from estim.errors import ConfigError, Notice

GIVES_WAVEFORM = ("waveform", "amplitude_v", "frequencies_hz", "points", "file")
"""Keys of the ``input`` block by which a config gives its own waveform."""


def input_from_netlist(data: dict, cls, source: str) -> None:
    """Fill ``data["input"]`` from the netlist of ``cls`` where its input source has a
    waveform and the block gives none; where both give one, a notice says that the config's
    waveform drives the model."""
    timed = [(name, cls.circuit.netlist.element(name).waveform) for name in cls.circuit.inputs]
    timed = [(name, wave) for name, wave in timed if wave[0] != "dc"]
    if not timed:
        return
    block = data.setdefault("input", {})
    if not isinstance(block, dict):
        return                                          # the schema names the mistake
    given = [key for key in GIVES_WAVEFORM if key in block]
    if given or len(cls.circuit.inputs) > 1:
        for name, wave in timed:
            why = (f"the config gives input.{given[0]}" if given
                   else "the model has several inputs, which input.mix drives")
            warnings.warn(f"{source}: the netlist's {wave[0].upper()} waveform on input "
                          f"{name.upper()} is replaced by the config's input block ({why})",
                          Notice, stacklevel=3)
        return
    name, wave = timed[0]
    bias = block.get("bias_v", None)
    for key, value in keys(name, wave, source, bias).items():
        block.setdefault(key, value)


def keys(name: str, wave: tuple, source: str, bias: list | None) -> dict:
    """The ``input`` keys of the waveform ``wave`` (the parser's tuple) on source ``name``;
    ``bias`` is the block's ``bias_v`` if it gives one (a PWL's values are then taken from
    it)."""
    kind, *args = wave

    def refuse(what: str) -> ConfigError:
        return ConfigError(source, "model.netlist", f"{name.upper()}: {kind.upper()} {what}; "
                           "give the waveform in the config's input block instead")

    if kind == "sin":
        vo, va, f, *rest = args
        if any(rest):
            raise refuse("with a delay, damping or phase is not an input estim makes")
        return {"waveform": "sine", "amplitude_v": va, "frequencies_hz": [f], "bias_v": [vo]}
    if kind == "pulse":
        v1, v2, *rest = args
        td, _tr, _tf, pw, per = (rest + [None] * 5)[:5]
        out = {"bias_v": [v1], "amplitude_v": v2 - v1, "delay_s": td or 0.0}
        if pw is None and per is None:
            return {**out, "waveform": "step"}
        if pw is None or per is None or not 0 < pw < per:
            raise refuse("that is neither a step (no pw, no per) nor a repeating pulse "
                         "(0 < pw < per)")
        return {**out, "waveform": "pulse", "duty": pw / per, "frequencies_hz": [1.0 / per]}
    level = float(bias[0]) if isinstance(bias, list) and bias else 0.0
    knots = [[args[i], args[i + 1] - level] for i in range(0, len(args), 2)]
    return {"waveform": "pwl", "points": knots, "bias_v": [level]}
