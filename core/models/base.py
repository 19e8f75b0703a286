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

    def f(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        raise NotImplementedError

    def jacobian(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        raise NotImplementedError

    def f_and_jacobian(self, x: np.ndarray, u: np.ndarray,
                       t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Both at once; models override it when the two share work."""
        return self.f(x, u, t), self.jacobian(x, u, t)

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
        """DC operating point: the root of ``f(x, u) = 0`` near ``x_guess`` (``u`` default 0)."""
        u0 = np.zeros(self.n_inputs) if u is None else np.asarray(u, float)
        guess = np.zeros(self.n_states) if x_guess is None else np.asarray(x_guess, float)
        sol = optimize.root(
            lambda x: self.f(x, u0), guess, jac=lambda x: self.jacobian(x, u0), method="hybr",
            options={"xtol": 1e-13},
        )
        if not sol.success:
            raise RuntimeError(f"{self.name}: no DC operating point found ({sol.message})")
        return sol.x
