"""The same netlist in ngspice: the independent "actual" for a netlist model.

:func:`transient` writes the netlist for ngspice (the model inputs as PWL sources of the
given samples, estim's device models in SPICE's terms), runs ``ngspice -b``, and reads the
node voltages back, resampled on the input's time grid (ngspice's own time points are not
uniform: ``linearize``). ngspice finds its own DC operating point, so the comparison covers
the DC point too. Its exit code is unreliable (ngspice 39 exits 0 after some failures): the
log is read for "Error", "aborted" and "Timestep too small".

Translations: an ``npn``/``pnp`` model (``ies alpha_f alpha_r vt``) becomes SPICE's
transport form, ``IS = alpha_f ies``, ``BF = alpha_f / (1 - alpha_f)``, ``BR = alpha_r /
(1 - alpha_r)`` (the Gummel-Poon model with no other effects is Ebers-Moll), at the
temperature whose ``kT/q`` is ``vt``; a diode keeps ``is n rs`` (at the same temperature, or
at the one whose ``kT/q`` is estim's diode ``V_T`` where no transistor sets it); an
``nmos`` device becomes a behavioural current source (``B``) with its law written out,
and an Ebers-Moll transistor whose ``.model`` sets ``ics`` two of them.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import numpy as np

from estim.errors import EstimError
from estim.spice import behavioural
from estim.spice.devices import BJT, DIODE, DIODE_VT, EKV, NMOS_LAWS
from estim.spice.gummel_poon import GUMMEL_POON, is_gummel_poon
from estim.spice.level1 import LEVEL1
from estim.spice.parser import Netlist

K_OVER_Q = 1.38064852e-23 / 1.6021766208e-19
"""Boltzmann's constant over the elementary charge, V/K, with ngspice's values of the two
(CODATA 2014): with CODATA 2018's the junction voltages differ by 4e-7 relative."""


class NgspiceError(EstimError, RuntimeError):
    """ngspice is missing, or its run failed (the message quotes its log)."""


def find(executable: str | None = None) -> str:
    path = shutil.which(executable or "ngspice")
    if path is None and executable:
        raise NgspiceError(f"ngspice executable {executable!r} not found (or not executable)")
    if path is None:
        raise NgspiceError("ngspice not found on PATH (Debian: apt-get install ngspice)")
    return path


def _assigned(values: dict, keys) -> str:
    """``key=value`` for each of ``keys``, as a ``.model`` line gives them."""
    return " ".join(f"{k}={float(values[k])!r}" for k in keys)


def _models(net: Netlist) -> tuple[list[str], float | None]:
    lines, vt = [], None
    for m in net.models.values():
        p = m.params
        if m.type in ("nmos", "pmos") and "level" in p:
            q = {**LEVEL1, **p}          # ngspice's own MOS1, its junction diodes off
            lines.append(f".model {m.name} {m.type}({_assigned(q, LEVEL1)} is=0)")
            continue
        if m.type in ("nmos", "pmos"):
            continue                    # EKV devices become B sources (:func:`_ekv_source`)
        if m.type in ("npn", "pnp") and is_gummel_poon(p):
            q = {**GUMMEL_POON, **p}     # ngspice's own BJT: its static law and junctions
            vt = vt or DIODE_VT
            lines.append(f".model {m.name} {m.type}({_assigned(q, GUMMEL_POON)})")
            continue
        if m.type in ("npn", "pnp") and p.get("ics") is not None:
            continue                    # B sources (:func:`_em_sources`)
        if m.type in ("npn", "pnp"):
            aF, aR = p.get("alpha_f", 0.99), p.get("alpha_r", 0.5)
            vt = p.get("vt", 0.025852)
            lines.append(f".model {m.name} {m.type}(is={aF * p.get('ies', 1e-14)!r} "
                         f"bf={aF / (1 - aF)!r} br={aR / (1 - aR)!r})")
        elif m.type == "d":
            vt = vt or DIODE_VT
            q = {**DIODE, **p}          # bv only where given (ngspice: a breakdown at bv)
            keys = [k for k in DIODE if k not in ("bv", "ibv", "nbv") or k in p]
            lines.append(f".model {m.name} d({_assigned(q, keys)})")
        else:
            raise NgspiceError(f".model {m.name}: type {m.type} has no ngspice translation yet")
    return lines, vt


def _ekv_source(e, net: Netlist) -> str:
    """An NMOS as an ngspice B source from drain to source: the law of its ``.model``
    (:func:`estim.spice.devices.nmos`) written out; EKV's softplus as ``max(a, 0) +
    ln(1 + exp(-abs(a)))`` (no overflow, no loss for negative ``a``). A PMOS: the same law
    of the negated node voltages, its current negated (:func:`estim.spice.devices.mosfet`)."""
    p = {**EKV, **net.models[e.ref].params}
    pm = "-" if net.models[e.ref].type == "pmos" else ""
    d, g, s, b = (f"({pm}v({flat(n)}))" if n not in ("0", "gnd") else "0" for n in e.nodes)
    ut, vt0, eta = p["u_t"], p["v_t0"], p["eta"]
    vp = f"(({g} - {b} - ({vt0!r})) / {eta!r})"

    def softplus(a: str) -> str:
        return f"(max({a}, 0) + ln(1 + exp(-abs({a}))))"

    a_s = f"(({vp} - ({s} - {b})) / {2 * ut!r})"
    a_d = f"(({vp} - ({d} - {b})) / {2 * ut!r})"
    Is = p["i_0"] * p["w_l"]
    law = NMOS_LAWS[int(p.get("law", 0))]
    if law == "ekv":
        current = f"({softplus(a_s)}^2 - {softplus(a_d)}^2)"
    elif law == "weak_inversion":
        current = f"(exp(2 * {a_s}) - exp(2 * {a_d}))"
    elif law == "weak_saturation":
        current = f"exp(2 * {a_s})"
    elif law == "taylor_conduction":
        xr = vt0 / (eta * ut)
        c0 = 1 - xr + xr**2 / 2 - xr**3 / 6
        c1 = (1 - xr + xr**2 / 2) / (eta * ut)
        q = 1 / (2 * ut)
        current = (f"({1 / ut!r} * ({c0!r} * (({d} - {s}) + {q!r} * ({s}^2 - {d}^2 - 2 * "
                   f"({s} * {b} - {d} * {b}))) + {c1!r} * ({g} * {d} - {b} * {d} - {g} * {s} "
                   f"+ {b} * {s})))")
    else:
        a1 = 1 / ut - vt0 / ut**2
        current = (f"({1 - vt0 / ut + vt0**2 / ut**2!r} + ({g} - {s}) * {a1!r} + "
                   f"({g} - {s})^2 / {2 * ut**2!r})")
    return (f"B{flat(e.name)} {flat(e.nodes[0])} {flat(e.nodes[2])} "
            f"I={-Is if pm else Is!r} * {current}")


def _em_sources(e, net: Netlist) -> list[str]:
    """An Ebers-Moll transistor whose ``.model`` gives ``ics`` (which SPICE's transport form
    cannot: its collector junction shares ``IS``) as two behavioural current sources, the
    collector's and the base's currents into the device, both returning through the emitter
    (eqs 3.48-3.51 written out)."""
    model = net.models[e.ref]
    p = {**BJT, **model.params}
    sign = -1.0 if model.type == "pnp" else 1.0
    c, b, em = (f"v({flat(n)})" if n not in ("0", "gnd") else "0" for n in e.nodes)
    vt = p["vt"]
    fF = f"({p['ies']!r} * (exp({sign!r} * ({b} - {em}) / {vt!r}) - 1))"
    fR = f"({p['ics']!r} * (exp({sign!r} * ({b} - {c}) / {vt!r}) - 1))"
    aF, aR = p["alpha_f"], p["alpha_r"]
    name = flat(e.name)
    cn, bn, en = (flat(n) for n in e.nodes)
    return [f"B{name}_c {cn} {en} I={sign!r} * ({aF!r} * {fF} - {fR})",
            f"B{name}_b {bn} {en} I={sign!r} * ({1 - aF!r} * {fF} + {1 - aR!r} * {fR})"]


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


def netlist_text(net: Netlist, t: np.ndarray, inputs: dict[str, np.ndarray],
                 dc: dict[str, float] | None = None, ac_source: str | None = None) -> str:
    """ngspice's netlist: every element as parsed (values resolved), the sources named in
    ``inputs`` as PWL of the samples at times ``t`` (or, for a pair ``(times, values)``, of
    those corners), those in ``dc`` at the given value, ``ac_source`` with unit AC
    amplitude."""
    out = [f"* {net.title} (written by estim for ngspice)"]
    for e in net.elements:
        nodes = " ".join(flat(n) for n in e.nodes)
        name = flat(e.name, e.kind)
        if e.name in inputs:
            given = inputs[e.name]
            times, values = given if isinstance(given, tuple) else (t, given)
            pairs = " ".join(f"{a!r} {b!r}" for a, b in zip(np.asarray(times, float).tolist(),
                                                          np.asarray(values, float).tolist(),
                                                          strict=True))
            out.append(f"{name} {nodes} PWL({pairs})")
        elif e.kind in "vi":
            kind, *args = e.waveform
            if kind == "dc" or (dc and e.name in dc):
                value = dc[e.name] if dc and e.name in dc else args[0]
                ac_part = " AC 1" if e.name == ac_source else ""
                out.append(f"{name} {nodes} DC {float(value)!r}{ac_part}")
            else:
                out.append(f"{name} {nodes} {kind.upper()}"
                           f"({' '.join(repr(float(a)) for a in args)})")
        elif e.kind == "m" and "level" in net.models[e.ref].params:
            size = "".join(f" {k}={v!r}" for k, v in e.size)
            out.append(f"{name} {nodes} {e.ref}{size}")
        elif e.kind == "m":
            out.append(_ekv_source(e, net))
        elif e.kind == "q" and net.models[e.ref].params.get("ics") is not None:
            out += _em_sources(e, net)
        elif e.kind in "dq":
            out.append(f"{name} {nodes} {e.ref}")
        elif e.kind in "fh":
            out.append(f"{name} {nodes} {flat(e.ref, 'v')} {float(e.value)!r}")
        elif e.kind == "b":
            law = behavioural.ngspice(e.ref, e.nodes[2:], flat)
            out.append(f"{name} {flat(e.nodes[0])} {flat(e.nodes[1])} I={law}")
        else:
            out.append(f"{name} {nodes} {float(e.value)!r}")
    models, vt = _models(net)
    out += models
    if vt is not None:
        out.append(f".options temp={vt / K_OVER_Q - 273.15!r} tnom={vt / K_OVER_Q - 273.15!r}")
    return "\n".join(out)


def flat(name: str, kind: str | None = None) -> str:
    """A node's or an element's name for ngspice: a subcircuit's ``x1.g`` as ``x1_g``, and an
    element flattened out of a subcircuit (``x1.r1``) with its kind's letter in front
    (``r_x1_r1``): ngspice reads an element's kind from its first letter."""
    out = name.replace(".", "_")
    return out if kind is None or name[:1] == kind else f"{kind}_{out}"


def vector(name: str) -> str:
    """ngspice's name of a quantity: ``v(a)``, ``v(a,b)`` as they are, ``i(l1)`` as the
    inductor's branch current ``l1#branch``, a bare node ``a`` as ``v(a)`` (names through
    :func:`flat`)."""
    name = name.strip().lower()
    if name.startswith("i(") and name.endswith(")"):
        return f"{flat(name[2:-1].strip(), 'l')}#branch"
    inner = name[2:-1] if name.startswith("v(") and name.endswith(")") else name
    return "v(" + ",".join(flat(n.strip()) for n in inner.split(",")) + ")"


TIMEOUT_BASE = 30.0
"""Seconds any ngspice run may take before its work is counted (start-up, a DC point, an AC
sweep of a few frequencies)."""
TIMEOUT_PER_STEP = 1e-3
"""Seconds more per time step a transient asks for."""
TIMEOUT_PER_STEP_SQUARED = 1e-6
"""Seconds more per squared time step: driven by a staircase (a PWL source with a corner per
sample), ngspice's time grows with the square of the steps (measured on
circuits/diffamp_em.cir with other work beside it: 16,000 steps 16 s, 80,000 steps 346 s,
about 6e-8 s per squared step), so a long cross-check is not cut short while a hung short
one is stopped within seconds of its limit."""


def timeout(steps: int = 0) -> float:
    """Seconds an ngspice run of ``steps`` transient time steps may take."""
    n = max(int(steps), 0)
    return TIMEOUT_BASE + TIMEOUT_PER_STEP * n + TIMEOUT_PER_STEP_SQUARED * n * n


def _run(deck: str, tmp: Path, executable: str | None, steps: int = 0) -> None:
    """Run ngspice on ``deck`` in batch mode, within :func:`timeout` of ``steps``: a run
    that takes longer, or that this process is interrupted or terminated during, is
    killed (``subprocess.run`` kills its child on any exception)."""
    exe = find(executable)
    path = tmp / "deck.cir"
    path.write_text(deck)
    limit = timeout(steps)
    try:
        run = subprocess.run([exe, "-b", str(path)], capture_output=True, text=True,
                             errors="replace", timeout=limit)
    except subprocess.TimeoutExpired:
        raise NgspiceError(f"ngspice took more than {limit:.0f} s (the limit for "
                           f"{steps} time steps): stopped") from None
    log = run.stdout + run.stderr
    bad = re.search(r"(?im)^.*(error|aborted|timestep too small).*$", log)
    if bad:
        raise NgspiceError(f"ngspice failed: {bad.group(0).strip()}")


def _read(path: Path) -> np.ndarray:
    if not path.is_file():
        raise NgspiceError("ngspice failed: no output written")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")              # numpy's "empty input file"
            table = np.loadtxt(path, skiprows=1, ndmin=2)
    except ValueError as exc:
        raise NgspiceError(f"ngspice wrote output estim cannot read "
                           f"({str(exc).splitlines()[0][:80]})") from None
    if table.shape[0] == 0 or table.shape[1] < 2:
        raise NgspiceError("ngspice failed: its output holds no data")
    return table


OPTIONS = ".options reltol={reltol!r} method=gear gmin=1e-30 abstol=1e-15 vntol=1e-12"


def transient(net: Netlist, t: np.ndarray, inputs: dict[str, np.ndarray], nodes: list[str],
              executable: str | None = None, reltol: float = 1e-6,
              max_step: float | None = None) -> np.ndarray:
    """The quantities ``nodes`` (node names, ``v(..)`` or ``i(inductor)``, :func:`vector`)
    at the times ``t``, ``(len(t), len(nodes))``, from ngspice's transient analysis of
    ``net`` driven by ``inputs`` (source name -> samples at ``t``, or PWL corners ``(times,
    values)``, :func:`staircase`), from its own DC point."""
    dt = float(t[1] - t[0])
    step = max_step or dt / 4
    names = " ".join(vector(n) for n in nodes)
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "out.txt"
        deck = netlist_text(net, t, inputs) + "\n" + OPTIONS.format(reltol=reltol) + f"""
.control
set wr_singlescale
set wr_vecnames
option numdgt=15
tran {step!r} {float(t[-1])!r} 0 {step!r}
linearize {names}
wrdata {data} {names}
quit 0
.endc
.end
"""
        _run(deck, Path(tmp), executable, steps=math.ceil(float(t[-1]) / step))
        table = _read(data)
    times, values = table[:, 0], table[:, 1:]
    return np.stack([np.interp(t, times, values[:, k]) for k in range(values.shape[1])],
                    axis=-1)


def ac(net: Netlist, bias: dict[str, float], source: str, frequencies: list[float],
       output: str, executable: str | None = None, reltol: float = 1e-9) -> np.ndarray:
    """The small-signal gain from the voltage source ``source`` to ``output`` at each of
    ``frequencies`` (complex), from ngspice's AC analysis about its DC point with the model
    inputs held at ``bias`` (source name -> volts)."""
    out = vector(output)
    with tempfile.TemporaryDirectory() as tmp:
        files = [Path(tmp) / f"ac{k}.txt" for k in range(len(frequencies))]
        text = netlist_text(net, np.zeros(1), {}, dc=bias, ac_source=source)
        sweeps = "\n".join(f"ac lin 1 {float(f)!r} {float(f)!r}\nwrdata {path} {out}"
                           for f, path in zip(frequencies, files, strict=True))
        deck = text + "\n" + OPTIONS.format(reltol=reltol) + f"""
.control
set wr_singlescale
set wr_vecnames
option numdgt=15
{sweeps}
quit 0
.endc
.end
"""
        _run(deck, Path(tmp), executable)
        rows = [_read(path)[0] for path in files]
    return np.array([r[1] + 1j * r[2] for r in rows])


def actual(model, source: np.ndarray, dt: float, reltol: float = 1e-7,
           executable: str | None = None) -> np.ndarray:
    """The states ``(runs, steps, n)`` after ``t_0`` of the netlist model ``model`` driven by
    ``source`` ``(runs, steps + 1, p)``, from ngspice's transient analysis (its own DC
    point, ``reltol``, its largest step a quarter of ``dt``), one run at a time: each input
    as what estim's model sees (the staircase of its held values, or for an input that
    drives through a capacitor the piecewise-linear source itself), as ``estim spice``
    drives it."""
    steps = source.shape[1] - 1
    t = np.arange(steps + 1) * dt
    return np.stack([transient(model.circuit.netlist, t, drive(model, run, t),
                               list(model.state_names), executable, reltol=reltol,
                               max_step=dt / 4)[1:] for run in np.asarray(source, float)])


def drive(model, source: np.ndarray, t: np.ndarray) -> dict:
    """What ngspice's PWL sources play for one run's ``source`` ``(steps + 1, p)`` at times
    ``t``: the staircase of the values estim's model holds (:func:`staircase`), or for
    inputs that drive through a capacitor the piecewise-linear source itself."""
    circuit = model.circuit
    if circuit.slope:
        return {name: (t, source[:, k]) for k, name in enumerate(circuit.inputs)}
    held = model.source_to_input(source[None], float(t[1] - t[0]))[0]
    return {name: staircase(t, held[:, k], source[0, k])
            for k, name in enumerate(circuit.inputs)}
