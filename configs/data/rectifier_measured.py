"""Makes rectifier_measured.csv, the measured record of configs/rectifier_measured.yaml:
circuits/rectifier.cir simulated by ngspice (not by estim) driven by a 1 V, 50 Hz sine about
0.5 V, sampled 40 times a period for 10 periods, its output with white noise of 20 mV
(seed 2019). Run from the repository's root: ``python configs/data/rectifier_measured.py``
(ngspice on the PATH); tests/test_measured.py checks that it writes the file as shipped."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from estim.spice import ngspice
from estim.spice.parser import parse

HERE = Path(__file__).resolve().parent
NETLIST = HERE.parent.parent / "circuits" / "rectifier.cir"
BIAS, AMPLITUDE, FREQUENCY = 0.5, 1.0, 50.0
SAMPLES, PERIODS, SIGMA, SEED = 40, 10, 0.02, 2019


def record() -> str:
    """The CSV text: t_s, v_in (the source) and v_out (the measured output)."""
    net = parse(NETLIST.read_text(), str(NETLIST))
    dt = 1.0 / (SAMPLES * FREQUENCY)
    t = np.arange(SAMPLES * PERIODS + 1) * dt
    v_in = BIAS + AMPLITUDE * np.sin(2 * np.pi * FREQUENCY * t)
    actual = ngspice.transient(net, t, {"vin": v_in}, ["out"], reltol=1e-9)[:, 0]
    noise = SIGMA * np.random.default_rng(SEED).standard_normal(t.size)
    lines = ["t_s,v_in,v_out"]
    lines += [f"{float(a)!r},{float(b)!r},{float(c)!r}"
              for a, b, c in zip(t, v_in, actual + noise, strict=True)]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "rectifier_measured.csv"
    out.write_text(record())
