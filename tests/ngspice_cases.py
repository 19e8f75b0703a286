"""Helpers of the tests that hold a netlist model against ngspice's own devices: a noisy
sine case through estim spice's comparison, and a DC point from ngspice's ``op``."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np

from estim.engine import ngspice_check as compare
from estim.spice.devices import DIODE_VT
from estim.spice.ngspice import K_OVER_Q


def sine_case(model, frequency: float, dt: float, steps: int, bias: float, amplitude: float,
              noise: float, seed: int, reltol: float = 1e-7, tighten: int = 2) -> list[dict]:
    """The rows estim spice's comparison (:func:`compare._tightening`, from ngspice's
    ``reltol`` tightened up to ``tighten`` times) gives for a sine of ``amplitude`` about
    ``bias`` at ``frequency`` with Gaussian noise of ``noise``, ``steps`` samples ``dt``
    apart after the first."""
    t = np.arange(steps + 1) * dt
    rng = np.random.default_rng(seed)
    source = (bias + amplitude * np.sin(2 * np.pi * frequency * t)
              + noise * rng.standard_normal(t.size))
    return compare._tightening(f"{frequency:g} Hz", model, source[:, None], dt, frequency,
                               None, 1e-10, reltol, tighten)


def outside_bars(rows: list[dict]) -> list[dict]:
    """The rows whose difference is above its check's bar."""
    return [r for r in rows if r["difference"] > compare.BARS[r["check"]]]


def ngspice_op(text: str, nodes: tuple[str, ...], folder: Path) -> dict[str, float]:
    """ngspice's DC point of the netlist ``text`` as written (its own devices), at estim's
    temperature and a tight ``reltol``: the voltage of each of ``nodes``, 15 digits."""
    temp = DIODE_VT / K_OVER_Q - 273.15
    deck = (text + f".options temp={temp!r} tnom={temp!r} reltol=1e-9 abstol=1e-15 "
            "vntol=1e-12 gmin=1e-30\n.control\nset numdgt=15\nop\n"
            f"print {' '.join(f'v({n})' for n in nodes)}\n.endc\n.end\n")
    (folder / "op.cir").write_text(deck)
    out = subprocess.run(["ngspice", "-b", str(folder / "op.cir")], capture_output=True,
                         text=True).stdout
    return {n: float(re.search(rf"v\({re.escape(n)}\) = (\S+)", out).group(1)) for n in nodes}
