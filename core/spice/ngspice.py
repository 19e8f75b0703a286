"""The same netlist in ngspice: the independent "actual" for a netlist model.

:func:`transient` writes the netlist for ngspice (the model inputs as PWL sources of the
given samples, estim's device models in SPICE's terms), runs ``ngspice -b``, and reads the
node voltages back, resampled on the input's time grid (ngspice's own time points are not
uniform: ``linearize``). ngspice finds its own DC operating point, so the comparison covers
the DC point too. Its exit code is unreliable (circuit-facts.md): the log is read for
"Error", "aborted" and "Timestep too small".

Translations: an ``npn``/``pnp`` model (``ies alpha_f alpha_r vt``) becomes SPICE's
transport form, ``IS = alpha_f ies``, ``BF = alpha_f / (1 - alpha_f)``, ``BR = alpha_r /
(1 - alpha_r)`` (the Gummel-Poon model with no other effects is Ebers-Moll), at the
temperature whose ``kT/q`` is ``vt``; a diode keeps ``is n rs`` (at the same temperature);
EKV ``nmos`` models are not translated yet.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from estim.errors import EstimError
from estim.spice.parser import Netlist

K_OVER_Q = 1.38064852e-23 / 1.6021766208e-19
"""Boltzmann's constant over the elementary charge, V/K, with ngspice's values of the two
(CODATA 2014): with CODATA 2018's the junction voltages differ by 4e-7 relative."""


class NgspiceError(EstimError, RuntimeError):
    """ngspice is missing, or its run failed (the message quotes its log)."""


def find(executable: str | None = None) -> str:
    path = shutil.which(executable or "ngspice")
    if path is None:
        raise NgspiceError("ngspice not found on PATH (Debian: apt-get install ngspice)")
    return path


def _models(net: Netlist) -> tuple[list[str], float | None]:
    lines, vt = [], None
    for m in net.models.values():
        p = m.params
        if m.type in ("npn", "pnp"):
            aF, aR = p.get("alpha_f", 0.99), p.get("alpha_r", 0.5)
            vt = p.get("vt", 0.025852)
            lines.append(f".model {m.name} {m.type}(is={aF * p.get('ies', 1e-14)!r} "
                         f"bf={aF / (1 - aF)!r} br={aR / (1 - aR)!r})")
        elif m.type == "d":
            lines.append(f".model {m.name} d(is={p.get('is', 1e-14)!r} n={p.get('n', 1.0)!r} "
                         f"rs={p.get('rs', 0.0)!r})")
        else:
            raise NgspiceError(f".model {m.name}: type {m.type} has no ngspice translation yet")
    return lines, vt


def staircase(t: np.ndarray, held: np.ndarray, first: float, edge: float = 1e-6) -> tuple:
    """PWL corners of an input held at ``held[k]`` on ``(t_k, t_{k+1}]`` (what estim's
    integrator sees), starting from ``first`` at ``t_0`` (the value estim's operating point
    is found at); each step takes ``edge`` of an interval: ``(times, values)``."""
    dt = np.diff(t)
    times = np.empty(2 * len(held) + 1)
    values = np.empty_like(times)
    times[0], values[0] = t[0], first
    times[1::2] = t[:-1] + edge * dt
    times[2::2] = t[1:]
    values[1::2] = held
    values[2::2] = held
    return times, values


def netlist_text(net: Netlist, t: np.ndarray, inputs: dict[str, np.ndarray]) -> str:
    """ngspice's netlist: every element as parsed (values resolved), the sources named in
    ``inputs`` as PWL of the samples at times ``t`` (or, for a pair ``(times, values)``, of
    those corners)."""
    out = [f"* {net.title} (written by estim for ngspice)"]
    for e in net.elements:
        nodes = " ".join(e.nodes)
        if e.name in inputs:
            given = inputs[e.name]
            times, values = given if isinstance(given, tuple) else (t, given)
            pairs = " ".join(f"{a!r} {b!r}" for a, b in zip(np.asarray(times, float).tolist(),
                                                          np.asarray(values, float).tolist(),
                                                          strict=True))
            out.append(f"{e.name} {nodes} PWL({pairs})")
        elif e.kind in "vi":
            kind, *args = e.waveform
            if kind == "dc":
                out.append(f"{e.name} {nodes} DC {float(args[0])!r}")
            else:
                out.append(f"{e.name} {nodes} {kind.upper()}"
                           f"({' '.join(repr(float(a)) for a in args)})")
        elif e.kind in "dqm":
            out.append(f"{e.name} {nodes} {e.ref}")
        else:
            out.append(f"{e.name} {nodes} {float(e.value)!r}")
    models, vt = _models(net)
    out += models
    if vt is not None:
        out.append(f".options temp={vt / K_OVER_Q - 273.15!r} tnom={vt / K_OVER_Q - 273.15!r}")
    return "\n".join(out)


def transient(net: Netlist, t: np.ndarray, inputs: dict[str, np.ndarray], nodes: list[str],
              executable: str | None = None, reltol: float = 1e-6,
              max_step: float | None = None) -> np.ndarray:
    """Node voltages ``(len(t), len(nodes))`` from ngspice's transient analysis of ``net``
    driven by ``inputs`` (source name -> samples at ``t``, or PWL corners ``(times,
    values)``, :func:`staircase`), from its own DC point."""
    exe = find(executable)
    dt = float(t[1] - t[0])
    step = max_step or dt / 4
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "out.txt"
        deck = netlist_text(net, t, inputs) + f"""
.options reltol={reltol!r} method=gear gmin=1e-30 abstol=1e-15 vntol=1e-12
.control
set wr_singlescale
set wr_vecnames
option numdgt=15
tran {step!r} {float(t[-1])!r} 0 {step!r}
linearize {" ".join(f"v({n})" for n in nodes)}
wrdata {data} {" ".join(f"v({n})" for n in nodes)}
quit 0
.endc
.end
"""
        path = Path(tmp) / "deck.cir"
        path.write_text(deck)
        run = subprocess.run([exe, "-b", str(path)], capture_output=True, text=True,
                             timeout=600)
        log = run.stdout + run.stderr
        bad = re.search(r"(?im)^.*(error|aborted|timestep too small).*$", log)
        if bad or not data.is_file():
            line = bad.group(0).strip() if bad else "no output written"
            raise NgspiceError(f"ngspice failed: {line}")
        table = np.loadtxt(data, skiprows=1, ndmin=2)
    times, values = table[:, 0], table[:, 1:]
    return np.stack([np.interp(t, times, values[:, k]) for k in range(values.shape[1])],
                    axis=-1)
