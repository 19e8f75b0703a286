"""Chapter 2: the zeroth- and first-order systems integrated (the old algorithm) against
their exact propagation (:func:`estim.numerics.expansion.propagate_expanded`), in one process.

Run on demand (not part of the tests):  python bench/bench_expansion.py

For the first row of every perturbation config, both amplitudes, from rest: the stacked
system ``[x0, x1]`` integrated by the batched Radau IIA at the config's tolerance (what
estim did before, and still does beyond ``EXACT_STIFFNESS_LIMIT``), and the exact
propagation, whose only error is the rounding of one matrix exponential (about
``eps max|eig(A)| dt`` of the output). Printed: the stiffness, which path estim uses, seconds
of each, their ratio, and the largest difference in the zeroth- and first-order outputs.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import record
import yaml

from estim.config.loading import parse_data
from estim.experiments import perturbation
from estim.numerics.expansion import (
    EXACT_STIFFNESS_LIMIT,
    ExpandedSystem,
    expand,
    propagate_expanded,
)
from estim.numerics.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]


def case(path: Path) -> dict:
    exp = parse_data(yaml.safe_load(path.read_text()), str(path), path.stem)
    row = exp.config.rows[0]
    amplitudes = np.array([row.amplitude_v, row.amplitude_v / 2])
    src, dt = perturbation.source(exp, row, amplitudes)
    model = exp.plan.models[row.s_no]
    bias = np.asarray(exp.config.excitation.bias_v, float)
    u_in = model.source_to_input(src, dt)
    u_op = model.source_to_input(np.broadcast_to(bias, (2, src.shape[-1])), dt)[0]
    e = expand(model, model.operating_point(u=u_op), u_op)
    du = u_in - u_op
    start = np.zeros((2, 2 * model.n_states))
    sim = exp.config.simulation
    t0 = time.perf_counter()
    old = simulate(ExpandedSystem(e, model.name), start, du, dt, rtol=sim.rtol, atol=sim.atol)
    t_old = time.perf_counter() - t0
    t0 = time.perf_counter()
    new = propagate_expanded(e, du, dt, start)[:, 1:]
    t_new = time.perf_counter() - t0
    n = model.n_states
    y = [(traj[..., :n] @ e.C.T, traj[..., n:] @ e.C.T) for traj in (old, new)]
    stiff = float(np.max(np.abs(np.linalg.eigvals(e.A)))) * dt
    return {"config": path.stem, "steps": du.shape[1], "integrated_s": t_old, "stiffness": stiff,
            "exact_s": t_new, "ratio": t_old / t_new,
            "max_dy0": float(np.max(np.abs(y[0][0] - y[1][0]))),
            "max_dy1": float(np.max(np.abs(y[0][1] - y[1][1]))),
            "y1_scale": float(np.max(np.abs(y[1][1])))}


def main() -> None:
    print(f"{'config':32s} {'steps':>6s} {'|eig|dt':>8s} {'used':>10s} {'integrated s':>12s} "
          f"{'exact s':>9s} {'ratio':>7s} {'max|dy0|':>9s} {'max|dy1|':>9s} {'max|y1|':>9s}")
    rows = []
    for path in sorted((ROOT / "configs").glob("*distortion.yaml")):
        r = case(path)
        used = "exact" if r["stiffness"] <= EXACT_STIFFNESS_LIMIT else "integrated"
        rows.append({"config": r["config"], "steps": r["steps"], "|eig| dt": r["stiffness"],
                     "estim uses": used, "integrated s": r["integrated_s"],
                     "exact s": r["exact_s"], "ratio": r["ratio"], "max |dy0|": r["max_dy0"],
                     "max |dy1|": r["max_dy1"], "max |y1|": r["y1_scale"]})
        print(f"{r['config']:32s} {r['steps']:6d} {r['stiffness']:8.1e} {used:>10s} "
              f"{r['integrated_s']:12.3f} {r['exact_s']:9.4f} "
              f"{r['ratio']:7.0f} {r['max_dy0']:9.2e} {r['max_dy1']:9.2e} {r['y1_scale']:9.2e}")
    record.save("expansion", rows, __doc__)


if __name__ == "__main__":
    main()
