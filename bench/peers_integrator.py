"""estim's stiff integrator beside scipy's ``solve_ivp`` (Radau, analytic Jacobian) and
ngspice, on one run of a Chapter 3 row: the MOSFET circuit as its SPICE netlist
(circuits/mosfet_ekv.cir, the netlist twin of bench_simulate.py), driven by the row's noisy
input (ngspice: the source as ``estim spice`` gives it, here its samples joined by lines,
whose slope on each interval is estim's input).

Each integrator runs at tolerances 1e-3, 1e-5 and 1e-7, ngspice also at 1e-9 (scipy:
``rtol``, ``atol`` = rtol * 1e-3; estim: the same; ngspice: ``reltol``, largest step a
quarter sample, gear). The error is
the largest drain-voltage difference over the samples from the same engine's tight solution
of its own equations (estim, and scipy on estim's equations: estim at rtol 1e-11, atol 1e-14;
ngspice: reltol 1e-10, largest step 1/40 sample): how well each solves its circuit. The two
tight solutions differ by a few microvolts (ngspice's device equations and breakpoints are
its own; ``estim spice`` compares the circuits), printed and recorded as their own row. The
time is the fastest of ``--rounds`` rounds (ngspice's includes its start-up in batch mode,
~0.1 s), as seconds per simulated second. The ratios compare each
peer's fastest setting that is as accurate as estim at the config's own tolerance with estim
there (a peer that never is: its most accurate setting, marked).

    python bench/peers.py --integrator      # via the peers driver, or alone:
    python bench/peers_integrator.py
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import record
from bench_simulate import netlist_twin, row_with_source

from estim.numerics.simulate import simulate, simulate_scipy
from estim.spice import ngspice

TOLERANCES = {"estim (compiled Radau)": (1e-3, 1e-5, 1e-7),
              "scipy solve_ivp Radau": (1e-3, 1e-5, 1e-7),
              "ngspice": (1e-3, 1e-5, 1e-7, 1e-9)}


def fastest(call, rounds: int):
    best, out = np.inf, None
    for _ in range(rounds):
        start = time.perf_counter()
        out = call()
        best = min(best, time.perf_counter() - start)
    return out, best


def measure(rounds: int = 3) -> tuple[list[dict], list[dict]]:
    """The rows of every setting, and the matched-accuracy ratios."""
    model, x0, source, u, dt, sim = row_with_source(1)
    twin, xt = netlist_twin(model, x0)
    d = twin.state_names.index("v(d)")
    steps = u.shape[1]
    t = np.arange(steps + 1) * dt
    seconds = steps * dt
    simulate(twin, xt, u[:, :2], dt, engine="compiled")              # compile once
    reference = simulate(twin, xt, u, dt, rtol=1e-11, atol=1e-14, engine="compiled")[0, :, d]
    name = twin.circuit.inputs[0]                   # as estim spice drives it
    drive = {name: (t, source[0, :, 0]) if twin.circuit.slope else
             ngspice.staircase(t, u[0, :, 0], source[0, 0, 0])}

    def ours(tol):
        return simulate(twin, xt, u, dt, rtol=tol, atol=tol * 1e-3, engine="compiled")[0, :, d]

    def scipy_radau(tol):
        return simulate_scipy(twin, xt, u, dt, rtol=tol, atol=tol * 1e-3, method="Radau")[0, :, d]

    def spice(tol, step=dt / 4):
        out = ngspice.transient(twin.circuit.netlist, t, drive, ["v(d)"], reltol=tol,
                                max_step=step)
        return out[1:, 0]

    own = {"ngspice": spice(1e-10, dt / 40)}
    gap = float(np.max(np.abs(own["ngspice"] - reference)))
    print(f"tight estim against tight ngspice: {gap:.2e} V")
    rows = [{"integrator": "tight estim against tight ngspice", "tolerance": np.nan,
             "s per simulated s": np.nan, "max error [V]": gap}]
    for name, call in (("estim (compiled Radau)", ours), ("scipy solve_ivp Radau", scipy_radau),
                       ("ngspice", spice)):
        for tol in TOLERANCES[name]:
            out, sec = fastest(lambda call=call, tol=tol: call(tol), rounds)
            error = float(np.max(np.abs(out - own.get(name, reference))))
            rows.append({"integrator": name, "tolerance": tol,
                         "s per simulated s": sec / seconds, "max error [V]": error})
            print(f"{name:24s} tol {tol:7.0e}  {sec / seconds:10.3g} s per simulated s   "
                  f"error {error:9.2e} V")
    config_tol = sim["rtol"]
    out, sec = fastest(lambda: ours(config_tol), rounds)
    target, base = float(np.max(np.abs(out - reference))), sec / seconds
    matched = [{"integrator": "estim (compiled Radau)", "setting": f"rtol {config_tol:g}",
                "max error [V]": target, "s per simulated s": base, "this / estim": 1.0}]
    for name in ("scipy solve_ivp Radau", "ngspice"):
        mine = [r for r in rows if r["integrator"] == name]
        good = [r for r in mine if r["max error [V]"] <= target]
        pick = min(good, key=lambda r: r["s per simulated s"]) if good else \
            min(mine, key=lambda r: r["max error [V]"])
        matched.append({"integrator": name + ("" if good else " (never as accurate)"),
                        "setting": f"tolerance {pick['tolerance']:g}",
                        "max error [V]": pick["max error [V]"],
                        "s per simulated s": pick["s per simulated s"],
                        "this / estim": pick["s per simulated s"] / base})
    for m in matched:
        print(f"matched: {m['integrator']:40s} {m['setting']:16s} {m['this / estim']:8.3g}x "
              f"estim's time (error {m['max error [V]']:.2e} V)")
    return rows, matched


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    rows, matched = measure(args.rounds)
    record.save("peers_integrator", rows, __doc__)
    record.save("peers_integrator_matched", matched, __doc__)


if __name__ == "__main__":
    main()
