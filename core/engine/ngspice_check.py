"""A netlist config's circuit in estim and in ngspice, on the config's own input
(``estim spice CONFIG``).

For each case of the config (a perturbation config: each distinct amplitude and frequency of
its rows; an estimation config: each input frequency, the clean waveform plus one draw of input
noise at the largest level, as the "actual" signal is made) both simulators start from their
own DC point and follow the same input: estim's integrator at a tight tolerance, ngspice's
transient analysis (gear, ``reltol`` 1e-7 by default, tightened tenfold up to twice
while a difference is above its bar, then its largest step cut from a quarter to a fortieth
of the sample interval and its ``reltol`` tightened once more) driven by a PWL source of
exactly what estim's model sees (the staircase of its held values,
:meth:`source_to_input`, or, for an input that drives through a capacitor, the
piecewise-linear source itself). Reported per case:

* ``dc``: the DC point, the largest node difference over the largest node voltage of the
  circuit (at the DC point or over the run: a circuit biased at 0 V is measured against the
  voltages its input drives);
* ``transient``: each state and the output, the largest difference over the run divided by
  the largest node voltage of the circuit's states (the scale SPICE's own tolerances work
  against; for an inductor current, its own largest magnitude; for a resistor's or a
  device's current, the larger of its own largest magnitude and what the node scale makes of
  it through the output's Jacobian, its largest row sum times the node scale). No scale is
  taken below
  SPICE's default absolute tolerances (:data:`FLOORS`: 1 uV, 1 pA), so a quantity that stays
  at zero is compared absolutely, not as 0/0. ``own_scale`` divides by
  the quantity's own largest magnitude instead: for a node that hardly moves (the MOSFET's
  bulk swings microvolts) it shows ngspice's absolute tolerances, not a disagreement of the
  circuits (it shrinks as ngspice's ``reltol`` is tightened);
* ``ac``: the small-signal gain from each input source to the output at the case's frequency
  (not for a device's current, which ngspice's AC analysis does not give),
  estim's ``C (j w - A)^-1 B`` (times ``j w`` for a slope input) against ngspice's AC
  analysis, the difference over the largest gain magnitude of the inputs.

Each difference is held against a bar (:data:`BARS`: what an independent check measured
estim's circuits at against ngspice), and ``holds`` says whether it is within it; a
difference above its bar is ``undecided`` where ngspice's own last two answers differ by
more than the bar, else it ``fails`` (``verdict``).
"""

from __future__ import annotations

import numpy as np

from estim.errors import ConfigError
from estim.numerics.simulate import simulate
from estim.spice import ngspice
from estim.util import lazy

pd = lazy.load("pandas")

BARS = {"dc": 1e-13, "transient": 5.5e-6, "ac": 1.7e-9}
"""Largest relative differences from ngspice that count as agreement."""

FLOORS = {"v": 1e-6, "i": 1e-12}
"""The smallest scale a voltage (V) or a current (A) difference is divided by: SPICE's default
``vntol`` and ``abstol``, below which a simulator's answer carries no digits."""


def cases(exp) -> list[tuple[str, object, np.ndarray, float, float | None]]:
    """``(label, model, source (steps + 1, p), dt, frequency or None)`` for each case of
    ``exp`` (the frequency of its sine, where the AC gain is compared)."""
    config = exp.config
    out = []
    if exp.analysis == "perturbation":
        from estim.experiments import perturbation

        seen = set()
        for row in config.rows:
            key = (row.amplitude_v, row.frequency_hz, repr(row.params))
            if key in seen:
                continue
            seen.add(key)
            src, dt = perturbation.source(exp, row, np.array([row.amplitude_v]))
            label = f"row {row.s_no}: {row.amplitude_v:g} V"
            if row.frequency_hz is not None:
                label += f", {row.frequency_hz:g} Hz"
            out.append((label, exp.plan.models[row.s_no], src[0], dt, row.frequency_hz))
    elif exp.analysis == "estimation":
        from estim.experiments import estimation
        from estim.experiments.estimation import source as waveforms

        inp, noise = config.input, config.noise
        mix, bias = np.asarray(inp.mix, float), np.asarray(inp.bias_v, float)
        level = max(noise.input_levels)
        rng = exp.config.monte_carlo.rng()
        for f in sorted(set(waveforms.frequencies(inp))):
            dt, steps = estimation.sampling(exp, f)
            t = np.arange(steps + 1) * dt
            clean = bias + waveforms.waveform(inp, exp.plan.knots, f, t) * mix
            noisy = level * rng.standard_normal((steps + 1, 1)) * mix
            noisy[0] = 0.0
            out.append((f"{waveforms.label(inp, f)}, input noise sigma {level:g}",
                        exp.plan.truth, clean + noisy, dt, f if inp.waveform == "sine" else None))
    else:
        raise ConfigError(exp.source, "analysis", f"estim spice compares the circuits of "
                          f"perturbation and estimation configs, not {exp.analysis!r}")
    return out


def compare_case(label: str, model, source: np.ndarray, dt: float, frequency: float | None,
                 executable: str | None, rtol: float = 1e-10,
                 reltol: float = 1e-7, step: float = 0.25) -> list[dict]:
    """The rows of :func:`compare` for one case (the AC gain only with a ``frequency``);
    ngspice's largest step is ``step`` times the sample interval."""
    circuit = model.circuit
    net = circuit.netlist
    steps = source.shape[0] - 1
    t = np.arange(steps + 1) * dt
    u_in = model.source_to_input(source[None], dt)[0]
    u_op = model.source_to_input(np.repeat(source[:1], 2, axis=0)[None], dt)[0, 0]
    x0 = model.operating_point(u=u_op)
    ours = np.vstack([x0, simulate(model, x0, u_in[None], dt, rtol=rtol,
                                   atol=rtol * 1e-3)[0]])
    theirs = ngspice.transient(net, t, ngspice.drive(model, source, t),
                               list(model.state_names), executable, reltol=reltol,
                               max_step=step * dt)
    rows = []
    nodes = [i for i, s in enumerate(model.state_names) if s.startswith("v(")]
    node_scale = max(np.abs(theirs[:, nodes]).max() if nodes else 0.0, FLOORS["v"])
    dc = np.abs(ours[0, nodes] - theirs[0, nodes]).max() / node_scale if nodes else 0.0
    rows.append({"case": label, "check": "dc", "quantity": "node voltages",
                 "difference": dc, "own_scale": dc})
    y_ours, y_theirs = model.h(ours), model.h(theirs)
    H = np.abs(model.h_jacobian(theirs))
    series = [(name, ours[:, j], theirs[:, j], 0.0) for j, name in enumerate(model.state_names)]
    for j, (output, term) in enumerate(zip(model.output_names, circuit.output_terms,
                                           strict=True)):
        # a current the node voltages set (a resistor's, a device's) moves by its
        # conductances times a node's difference: the node scale carried through its Jacobian
        carried = (H[:, j].sum(axis=-1).max() * node_scale
                   if term[0] in ("resistor", "device", "source") else 0.0)
        series.append((f"{output} (output)", y_ours[:, j], y_theirs[:, j], carried))
    for name, a, b, carried in series:
        gap = np.abs(a - b).max()
        own = np.abs(b).max()
        scale = node_scale if name.startswith("v(") else max(own, FLOORS["i"])
        if carried:
            scale = max(own, carried, FLOORS["i"])
        rows.append({"case": label, "check": "transient", "quantity": name,
                     "difference": gap / scale, "own_scale": gap / own if own else np.nan,
                     "_theirs": b, "_scale": scale})
    if frequency is not None:
        rows += _ac_rows(label, model, source, frequency, x0, u_op, executable)
    return rows


def _ac_rows(label: str, model, source: np.ndarray, frequency: float, x0: np.ndarray,
             u_op: np.ndarray, executable: str | None) -> list[dict]:
    """The AC gain from each input to each output at ``frequency`` against ngspice's AC
    analysis about the DC point (none for a device's or a voltage source's current, which
    the probe here does not read)."""
    circuit, net = model.circuit, model.circuit.netlist
    A = model.jacobian(x0, u_op)
    B = model.input_jacobian(x0, u_op)
    C = model.h_jacobian(x0)
    w = 2j * np.pi * frequency
    ours_all = C @ np.linalg.solve(w * np.eye(model.n_states) - A, B)
    if circuit.slope:
        ours_all = ours_all * w
    bias = {name: float(source[0, k]) for k, name in enumerate(circuit.inputs)}
    rows = []
    for j, (output, term) in enumerate(zip(model.output_names, circuit.output_terms,
                                           strict=True)):
        if term[0] in ("device", "source"):
            continue
        probe, scale = output, 1.0
        if term[0] == "resistor":                  # its current: the voltage across it / R
            e = net.element(term[1])
            a, b = (n for n in e.nodes[:2])
            probe = f"v({b})" if a in ("0", "gnd") else (
                f"v({a})" if b in ("0", "gnd") else f"v({a},{b})")
            scale = (-1.0 if a in ("0", "gnd") else 1.0) / e.value
        theirs_ac = scale * np.array([ngspice.ac(net, bias, name, [frequency], probe,
                                                 executable)[0] for name in circuit.inputs])
        ours_ac = ours_all[j]
        top = max(np.abs(theirs_ac).max(), 1e-12)      # a gain of zero: compared absolutely
        for k, name in enumerate(circuit.inputs):
            rows.append({"case": label, "check": "ac",
                         "quantity": f"gain {name.upper()} -> {output}",
                         "difference": abs(ours_ac[k] - theirs_ac[k]) / top,
                         "own_scale": abs(ours_ac[k] - theirs_ac[k]) / abs(theirs_ac[k])})
    return rows


def compare(exp, executable: str | None = None, rtol: float = 1e-10,
            reltol: float = 1e-7, tighten: int = 2) -> pd.DataFrame:
    """estim against ngspice on every case of the netlist config ``exp``: one row per
    case, check and quantity, with the relative ``difference``, the ngspice ``reltol`` it
    was measured at (:func:`_tightening`), its ``bar`` and whether it ``holds``."""
    model_block = exp.model_block
    if not model_block.get("netlist"):
        what = (f"model is {model_block.get('name')!r}, not built from a netlist"
                if model_block.get("name") else "analysis has no circuit model")
        raise ConfigError(exp.source, "model.netlist", "estim spice compares a netlist model "
                          f"with ngspice; this config's {what}")
    ngspice.find(executable)
    rows = []
    for label, model, source, dt, frequency in cases(exp):
        rows += _tightening(label, model, source, dt, frequency, executable, rtol, reltol,
                            tighten)
    table = pd.DataFrame(rows)
    table["bar"] = table["check"].map(BARS)
    table["holds"] = table["difference"] <= table["bar"]
    table["verdict"] = verdict(table)
    return table


def _tightening(label, model, source, dt, frequency, executable, rtol, reltol,
                tighten) -> list[dict]:
    """One case at ngspice's ``reltol``, then, while a difference is above its bar, at a
    ten times tighter one (up to ``tighten`` times), then at the tightest with ngspice's
    largest step cut from a quarter to a fortieth of the sample interval, and at ten times
    tighter again (its step control after the corners of a fast PWL input: D74): a
    difference that shrinks so is ngspice's truncation error, not a disagreement of the
    circuits. Each row says the ``reltol`` and ``step`` it was measured at and, for a
    transient quantity, ``ngspice_spread``: how far ngspice's last two answers differ, over
    the same scale (:func:`verdict`); a tighter run that fails (too slow) keeps the last."""
    rows, before = None, None
    tries = [(reltol / 10 ** k, 0.25) for k in range(tighten + 1)]
    tries += [(tries[-1][0], 0.025), (tries[-1][0] / 10, 0.025)]
    for tol, step in tries:
        try:
            new = compare_case(label, model, source, dt, frequency, executable, rtol, tol,
                               step)
        except ngspice.NgspiceError:
            if rows is None:
                raise
            break
        before, rows = rows, [{**r, "reltol": tol, "step": step} for r in new]
        if all(r["difference"] <= BARS[r["check"]] for r in rows):
            break
    for k, r in enumerate(rows):
        last = r.pop("_theirs", None)
        scale = r.pop("_scale", None)
        prior = before[k].get("_theirs") if before else None
        r["ngspice_spread"] = (np.abs(last - prior).max() / scale
                               if prior is not None and scale else np.nan)
    return rows


def verdict(table: pd.DataFrame) -> pd.Series:
    """Per row: ``holds`` (the difference within its bar), ``undecided`` (above it, but
    ngspice's own answers at its last two settings differ by more than the bar: its
    truncation error, not a measured disagreement of the circuits) or ``fails``."""
    over = ~(table["difference"] <= table["bar"])        # a NaN difference is no agreement
    loose = table["ngspice_spread"] > table["bar"]
    return pd.Series(np.where(~over, "holds", np.where(loose, "undecided", "fails")),
                     index=table.index)
