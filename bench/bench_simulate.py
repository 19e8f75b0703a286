"""One Chapter 3 row's "actual" signal: the numpy Radau integrator (the old path), the
compiled one (estim.numerics.radau_compiled, the default) and scipy's solve_ivp, in one process.

Run on demand (not part of the tests):  python bench/bench_simulate.py [--runs 30]

The netlist twin (circuits/mosfet_ekv.cir, the same circuit as a SPICE netlist through the
one compiled netlist kernel) runs the same row; issue 26 asks it within 2x of the hand-written
model's compiled time. Last, the time to parse each shipped netlist and build its model.

The row: configs/mosfet_saturation.yaml, input noise 0.25 (sigma), 1 kHz, 200 samples, at
the config's solver tolerance. Errors are against a tight reference (the compiled
integrator at rtol 1e-10, atol 1e-12), as the largest drain-voltage difference over the
runs and samples. scipy's solve_ivp runs either all runs stacked as one system with the
block-diagonal Jacobian (LSODA: its fastest way through a batch), or one run at a time,
timed on a few runs and scaled to the row (Radau and LSODA, analytic Jacobian).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import record
import yaml
from bench_filters import timed

from estim.config.loading import parse_data
from estim.experiments import estimation
from estim.numerics.simulate import simulate, simulate_scipy

ROOT = Path(__file__).resolve().parents[1]


def row(runs: int):
    """The row's truth model, its start, the input of its ``runs`` runs on each interval, the
    sample interval and the config's simulation settings."""
    truth, x0, _, u, dt, sim = row_with_source(runs)
    return truth, x0, u, dt, sim


def row_with_source(runs: int):
    """:func:`row` with the sampled source ``(runs, steps + 1, 1)`` the input is made from."""
    spec = yaml.safe_load((ROOT / "configs" / "mosfet_saturation.yaml").read_text())
    spec["monte_carlo"]["runs"] = runs
    exp = parse_data(spec, "mosfet_saturation.yaml", "mosfet_saturation")
    point = next(p for p in estimation.sweep(exp)
                 if p.reading == "sigma" and p.level == 0.25 and p.frequency_hz == 1000)
    rng = np.random.default_rng(np.random.SeedSequence(2019, spawn_key=(point.index,)))
    dt, steps = estimation.sampling(exp, point.frequency_hz)
    t = np.arange(steps + 1) * dt
    clean = np.asarray(exp.spec["input"]["bias_v"]) + 0.01 * np.sin(
        2 * np.pi * point.frequency_hz * t)[:, None]
    source = clean[None] + point.sigma * rng.standard_normal((runs, steps + 1, 1))
    source[:, 0] = clean[0]
    truth = exp.plan.truth
    return (truth, exp.plan.x0, source, truth.source_to_input(source, dt), dt,
            exp.spec["simulation"])


def netlist_twin(model, x0):
    """circuits/mosfet_ekv.cir at the row's gate bias, and ``x0`` in its state order
    (``twin.order`` maps its states back to the hand-written model's)."""
    from estim.spice import model_class

    cls = model_class(ROOT / "circuits" / "mosfet_ekv.cir", "VIN", "v(d)",
                      name="netlist:bench_mosfet")
    twin = cls(vin_bias=model.params.V_IN)
    twin.order = [twin.state_names.index(f"v({n})") for n in "gbsd"]
    xt = np.empty_like(x0)
    xt[twin.order] = x0
    return twin, xt


def stacked_scipy(model, x0, u, dt, rtol, atol, method="LSODA"):
    """All runs as one system for ``solve_ivp``, interval by interval, with the block-diagonal
    Jacobian (sparse for Radau and BDF, dense for LSODA, which takes no sparse matrix):
    scipy's fastest way through a batch."""
    from scipy import sparse
    from scipy.integrate import solve_ivp

    runs, steps, _ = u.shape
    n = model.n_states
    x = np.broadcast_to(x0, (runs, n)).reshape(-1).copy()
    out = np.empty((runs, steps, n))
    for k in range(steps):
        uk = u[:, k]

        def f(_t, y, uk=uk):
            return model.f(y.reshape(runs, n), uk).reshape(-1)

        def jac(_t, y, uk=uk):
            blocks = sparse.block_diag(list(model.jacobian(y.reshape(runs, n), uk)), "csc")
            return blocks.toarray() if method == "LSODA" else blocks   # LSODA takes dense

        sol = solve_ivp(f, (0.0, dt), x, method=method, jac=jac, rtol=rtol, atol=atol)
        x = sol.y[:, -1]
        out[:, k] = x.reshape(runs, n)
    return out


def build_times(repeats: int = 5) -> list[tuple[str, float]]:
    """Milliseconds to parse each shipped netlist and build its model (fastest of
    ``repeats``): issue 26 asks under 50 ms for the thesis circuits. The inputs and outputs
    are those of configs/netlist/ (the Darlington pair, which has no config: VIN, v(d2))."""
    import time

    from estim.spice import model_class

    wiring = {"mosfet_darlington": (["VIN"], "v(d2)")}
    for path in sorted((ROOT / "configs" / "netlist").glob("*.yaml")):
        model = yaml.safe_load(path.read_text())["model"]
        inputs = model["input"] if isinstance(model["input"], list) else [model["input"]]
        wiring.setdefault(Path(model["netlist"]).stem, (inputs, model["output"]))
    out = []
    for stem, (inputs, output) in sorted(wiring.items()):
        best = np.inf
        for k in range(repeats):
            start = time.perf_counter()
            model_class(ROOT / "circuits" / f"{stem}.cir", inputs, output,
                        name=f"netlist:bench_build_{stem}_{k}")()
            best = min(best, time.perf_counter() - start)
        out.append((stem, 1e3 * best))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--scipy-runs", type=int, default=2)
    args = parser.parse_args()
    model, x0, u, dt, sim = row(args.runs)
    rtol, atol = sim["rtol"], sim["atol"]
    simulate(model, x0, u[:1, :2], dt, engine="compiled")            # compile once
    reference = simulate(model, x0, u, dt, rtol=1e-10, atol=1e-12, engine="compiled")
    results = []
    out, sec = timed(lambda: simulate(model, x0, u, dt, rtol=rtol, atol=atol, engine="numpy"))
    results.append(("batched Radau, numpy (old)", sec, out))
    out, sec = timed(lambda: simulate(model, x0, u, dt, rtol=rtol, atol=atol,
                                      engine="compiled"))
    results.append(("batched Radau, compiled (new)", sec, out))
    out, sec = timed(lambda: stacked_scipy(model, x0, u, dt, rtol, atol))
    results.append(("solve_ivp LSODA, runs stacked", sec, out))
    k = args.scipy_runs
    for method in ("Radau", "LSODA"):
        out, sec = timed(lambda method=method: simulate_scipy(model, x0, u[:k], dt, rtol=rtol,
                                                                atol=atol, method=method))
        results.append((f"solve_ivp {method}, per run (x{args.runs / k:g})",
                        sec * args.runs / k, out))
    twin, xt = netlist_twin(model, x0)
    simulate(twin, xt, u[:1, :2], dt, engine="compiled")             # compile once
    out, sec = timed(lambda: simulate(twin, xt, u, dt, rtol=rtol, atol=atol, engine="compiled"))
    results.append(("netlist twin, compiled", sec, out[..., twin.order]))
    base = results[0][1]
    print(f"Chapter 3 row: {args.runs} runs x {u.shape[1]} samples, rtol {rtol:g}, "
          f"atol {atol:g}")
    print(f"{'integrator':42s} {'seconds':>9s} {'speed-up':>9s} {'max error [V]':>14s}")
    rows = []
    for name, sec, out in results:
        err = np.max(np.abs(model.h(out) - model.h(reference[:out.shape[0]])))
        print(f"{name:42s} {sec:9.2f} {base / sec:8.1f}x {err:14.2e}")
        rows.append({"integrator": name, "seconds": sec, "speed-up": base / sec,
                     "max error [V]": float(err)})
    record.save("simulate", rows, __doc__)
    print()
    print("Parse a shipped netlist and build its model (fastest of 5; issue 26's bar: 50 ms)")
    for stem, ms in build_times():
        print(f"{stem:42s} {ms:9.1f} ms")


if __name__ == "__main__":
    main()
