"""The model interface shared by every circuit and field model.

A model is a continuous-time system

    dx/dt = f(x, u, t),        y = h(x),

evaluated on arrays with any number of leading batch axes: ``x`` has shape ``(..., n)``,
``u`` shape ``(..., p)``. Jacobians have shape ``(..., n, n)`` and ``(..., m, n)``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from scipy import optimize

from core.simulate import simulate


class ParameterError(ValueError):
    """A parameter override names an unknown parameter or has a bad value."""


def parameter_table(params_cls: type) -> dict[str, tuple[Any, str, str]]:
    """Return ``{name: (default, unit, description)}`` for a parameter dataclass."""
    out = {}
    for field in dataclasses.fields(params_cls):
        out[field.name] = (
            field.default,
            field.metadata.get("unit", "-"),
            field.metadata.get("doc", ""),
        )
    return out


def param(default: Any, unit: str = "-", doc: str = "") -> Any:
    """A dataclass field carrying a unit and a one-line description."""
    return dataclasses.field(default=default, metadata={"unit": unit, "doc": doc})


class Model:
    """Base class: subclasses set the names and implement ``f``, ``jacobian`` and ``h``.

    Subclasses hold their parameters in a frozen dataclass ``Params`` and accept
    keyword overrides of it in their constructor.
    """

    name: str = "model"
    state_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    Params: type = object
    variants: dict[str, dict[str, Any]] = {}

    def __init__(self, variant: str | None = None, **overrides: Any) -> None:
        variant = variant or next(iter(self.variants), None)
        if self.variants and variant not in self.variants:
            raise ParameterError(
                f"unknown variant {variant!r}; expected one of {sorted(self.variants)}"
            )
        values = dict(self.variants.get(variant, {}))
        known = {f.name for f in dataclasses.fields(self.Params)}
        for key, value in overrides.items():
            if key not in known:
                raise ParameterError(
                    f"unknown parameter {key!r}; expected one of {sorted(known)}"
                )
            values[key] = value
        self.variant = variant
        self.params = self.Params(**values)

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def n_outputs(self) -> int:
        return len(self.output_names)

    def f_and_jacobian(self, x: np.ndarray, u: np.ndarray,
                       t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Drift ``f(x, u)`` and its Jacobian ``df/dx``: the one method a model implements."""
        raise NotImplementedError

    def f(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        return self.f_and_jacobian(x, u, t)[0]

    def jacobian(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        return self.f_and_jacobian(x, u, t)[1]

    def h(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def h_jacobian(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def source_to_input(self, source: np.ndarray, dt: float) -> np.ndarray:
        """Map sampled source waveforms ``(..., steps, p)`` to the model input on each interval.

        The default passes the samples through (zero-order hold).
        """
        return source

    def operating_point(self, x_guess: np.ndarray | None = None,
                        u: np.ndarray | None = None) -> np.ndarray:
        """DC operating point: the root of ``f(x, u) = 0`` near ``x_guess`` (``u`` default 0).

        Where Newton fails from the guess (a saturated circuit, say), the circuit is first let
        settle for 20 us with the stiff integrator and Newton is tried again from there.
        """
        u0 = np.zeros(self.n_inputs) if u is None else np.asarray(u, float)
        guess = np.zeros(self.n_states) if x_guess is None else np.asarray(x_guess, float)

        def solve(start):
            return optimize.root(lambda x: self.f(x, u0), start,
                                 jac=lambda x: self.jacobian(x, u0), method="hybr",
                                 options={"xtol": 1e-13})

        sol = solve(guess)
        if not sol.success:
            held = np.broadcast_to(u0, (1, 20, self.n_inputs))
            sol = solve(simulate(self, guess, held, 1e-6, on_failure="nan")[0, -1])
        if not sol.success:
            raise RuntimeError(f"{self.name}: no DC operating point found ({sol.message})")
        return sol.x
