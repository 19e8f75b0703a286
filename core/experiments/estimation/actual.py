"""The actual circuit of an estimation run: estim's stiff solver (``simulation.solver``
``batched_radau`` or ``scipy``), or ngspice's transient analysis of the netlist
(``ngspice``: D78), while the filters keep estim's model of the same netlist."""

from __future__ import annotations

import numpy as np

from estim.errors import ConfigError
from estim.numerics.simulate import SOLVERS


def check(config, truth, source: str) -> None:
    """``simulation.solver: ngspice`` needs a model built from a netlist and ngspice itself,
    both known before any work."""
    if config.simulation.solver != "ngspice":
        return
    from estim.spice import ngspice  # here: only a netlist model needs it

    if not getattr(truth, "from_netlist", False):
        raise ConfigError(source, "simulation.solver", "ngspice simulates a netlist; this "
                          f"config's model {config.model.name!r} is not built from one "
                          "(model.netlist)")
    try:
        ngspice.find()
    except ngspice.NgspiceError as exc:
        raise ConfigError(source, "simulation.solver", str(exc)) from None


def states(truth, x0: np.ndarray, source: np.ndarray, dt: float, sim) -> np.ndarray:
    """The actual states ``(runs, steps, n)`` after ``t_0`` of the circuit driven by
    ``source`` ``(runs, steps + 1, p)``: estim's solver from ``x0``, or ngspice from its own
    DC point (:func:`estim.spice.ngspice.actual`)."""
    if sim.solver == "ngspice":
        from estim.spice import ngspice

        return ngspice.actual(truth, source, dt, reltol=sim.rtol)
    return SOLVERS[sim.solver](truth, x0, truth.source_to_input(source, dt), dt,
                               rtol=sim.rtol, atol=sim.atol)
