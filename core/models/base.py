"""The model interface shared by every circuit and field model.

A model is a continuous-time system

    dx/dt = f(x, u, t),        y = h(x),

evaluated on arrays with any number of leading batch axes: ``x`` has shape ``(..., n)``,
``u`` shape ``(..., p)``. Jacobians have shape ``(..., n, n)`` and ``(..., m, n)``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import scipy

from estim.config import registry
from estim.config.settings import parameter_problem
from estim.errors import ParameterError, SimulationError
from estim.numerics.simulate import simulate
from estim.util import disk_cache, lazy

optimize = lazy.load("scipy.optimize")


def _exact(value: Any) -> Any:
    """``value`` for a cache key: an array as its dtype, shape and bytes (its ``repr``
    rounds and elides), anything else as itself (``repr`` is exact for Python's floats)."""
    if isinstance(value, (np.ndarray, list, tuple)):
        a = np.asarray(value)
        if a.dtype != object:
            return ("array", str(a.dtype), a.shape, a.tobytes().hex())
    return value


def _code_fingerprint() -> str:
    """sha256 of the model and numerics packages' sources: a DC point found by other code
    is never read back."""
    roots = [Path(__file__).parent, Path(__file__).parents[1] / "numerics"]
    files = sorted(str(p) for root in roots for p in root.rglob("*.py"))
    return disk_cache.fingerprint(*files)


def check_params(params: Any, positive: tuple[str, ...] = (),
                 unit_interval: tuple[str, ...] = ()) -> None:
    """Raise ``ValueError`` naming the first parameter that is not positive, or not in
    (0, 1), as required; for the ``__post_init__`` of parameter dataclasses."""
    for name in positive:
        if not getattr(params, name) > 0:
            raise ValueError(f"{name} must be positive, got {getattr(params, name)!r}")
    for name in unit_interval:
        if not 0 < getattr(params, name) < 1:
            raise ValueError(f"{name} must be in (0, 1), got {getattr(params, name)!r}")


class Model:
    """Base class: a subclass names its states, inputs and outputs, holds its parameters in
    a frozen dataclass ``Params`` (each a :func:`estim.config.settings.setting`: default,
    unit, doc), and implements
    ``f_and_jacobian`` and ``h`` (and ``h_jacobian``). It registers itself by the class
    keyword ``name``: ``class DiodeRC(Model, name="diode_rc")`` (:mod:`estim.config.registry`).
    The constructor takes a variant and keyword overrides of ``Params``.
    """

    name: str = "model"

    def __init_subclass__(cls, name: str | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if name is not None:
            cls.name = name
            registry.MODELS.register(name, cls)
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
        defaults = {f.name: f.default for f in dataclasses.fields(self.Params)}
        known = set(defaults)
        for key, value in overrides.items():
            if key not in known:
                raise ParameterError(
                    f"unknown parameter {key!r}; expected one of {sorted(known)}"
                )
            problem = parameter_problem(defaults[key], value)
            if problem:
                raise ParameterError(f"{key}: {problem}")
            values[key] = value.item() if isinstance(value, np.generic) else value
        self.variant = variant
        self.params = self.Params(**values)

    @property
    def state_scales(self) -> tuple[float, ...]:
        """Each state in units of the voltage a printed covariance entry is read as:
        ``x_model = scale * x_thesis``. One for a voltage state; a model whose state is a
        charge ``q = C v`` returns ``C`` there (the thesis prints its Q without units, read
        as voltage variances: docs/deviations.md D36). Filters map covariances given in
        these units with it (``S Q S``)."""
        return (1.0,) * self.n_states

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

    def input_jacobian(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        """``df/du`` at one point, shape ``(n, p)``; by default central differences with one
        Richardson step (error O(h^4)). Override where an analytic form is at hand."""
        x, u = np.asarray(x, float), np.asarray(u, float)

        def central(h):
            return np.stack([(self.f(x, u + h * e, t) - self.f(x, u - h * e, t)) / (2 * h)
                             for e in np.eye(self.n_inputs)], axis=-1)

        h = 1e-3 * max(1.0, float(np.max(np.abs(u), initial=0.0)))
        return (4 * central(h / 2) - central(h)) / 3

    def hessian(self, x: np.ndarray, u: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Second derivatives of ``f`` w.r.t. ``z = [x, u]`` at one point, shape
        ``(n, n + p, n + p)``: the quadratic part of the circuit equations used by the
        perturbation analysis (Chapter 2, the ``b``, ``d`` coefficients of eqs 2.8-2.10).

        By default the mixed central second difference of ``f`` with one Richardson step,
        on a step of 1 mV in every coordinate (the quadratic part is what matters at the
        thermal-voltage scale of 26 mV). Override with the analytic form where available.
        """
        x, u = np.asarray(x, float), np.asarray(u, float)
        n, size = self.n_states, self.n_states + self.n_inputs
        z0 = np.concatenate([x, u])

        def f_at(z):
            return self.f(z[..., :n], z[..., n:], t)

        def second(h):
            eye = h * np.eye(size)
            pp = eye[:, None, :] + eye[None, :, :]
            pm = eye[:, None, :] - eye[None, :, :]
            return (f_at(z0 + pp) - f_at(z0 + pm) - f_at(z0 - pm) + f_at(z0 - pp)) / (4 * h * h)

        h = 1e-3
        H = np.moveaxis((4 * second(h / 2) - second(h)) / 3, -1, 0)
        return 0.5 * (H + np.swapaxes(H, 1, 2))

    input_affine: bool = False
    """``f`` is affine in ``u`` (the input enters through a constant matrix): its second
    derivatives involving ``u`` are exactly zero, and
    :func:`estim.numerics.kronecker_form.from_model` sets them so instead of keeping the rounding of
    a numerical Hessian."""

    input_is_source_slope: bool = False
    """The model input is the source's time derivative (``dv_in/dt``, eq 3.26), so a filter
    can be fed other estimates of it (``estimators[i].input_derivative``)."""

    regimes: tuple[str, ...] = ()
    """Operating regimes :meth:`in_regime` can test (the regimes the thesis' tables name)."""

    def in_regime(self, regime: str, x: np.ndarray, source: np.ndarray) -> np.ndarray:
        """Whether each sample of states ``x (..., n)`` and source values ``source (..., p)``
        is in ``regime`` (one of :attr:`regimes`), shape ``x.shape[:-1]``."""
        raise ValueError(f"{self.name} declares no operating regimes")

    def output_range(self) -> tuple[float, float] | None:
        """The physical range of the measured output: an estimate outside it is no estimate of
        this circuit (:func:`estim.experiments.shared.health.diverged`). ``None``: no range."""
        return None

    def kernel(self):
        """``(compiled_fn, P)`` for :mod:`estim.numerics.radau_compiled`, or ``None`` (the numpy
        path)."""
        return None

    output_row: tuple[tuple[int, float], ...] = ()
    """The measured output as a linear row of the state, ``((state index, coefficient),
    ...)`` (``y = H x``, eq 3.5's ``H``): :meth:`h` and :meth:`h_jacobian` are made from it.
    A model whose output is not linear in the state overrides both instead."""

    def h(self, x: np.ndarray) -> np.ndarray:
        """The measured output ``y = H x`` of :attr:`output_row`, shape ``(..., 1)``."""
        if not self.output_row:
            raise NotImplementedError(f"{type(self).__name__} declares no output_row")
        x = np.asarray(x)
        (i, c), *rest = ((i % x.shape[-1], c) for i, c in self.output_row)
        y = x[..., i:i + 1] if c == 1.0 else c * x[..., i:i + 1]
        for i, c in rest:
            y = y + c * x[..., i:i + 1]
        return y

    def h_jacobian(self, x: np.ndarray) -> np.ndarray:
        """``H``, shape ``(..., 1, n)``."""
        if not self.output_row:
            raise NotImplementedError(f"{type(self).__name__} declares no output_row")
        H = np.zeros(np.shape(x)[:-1] + (1, np.shape(x)[-1]))
        for i, c in self.output_row:
            H[..., 0, i] = c
        return H

    def affine_output(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(H, c)`` with ``h(x) = H x + c`` (shapes ``(m, n)`` and ``(m,)``) when the output
        is affine in the state (the compiled filter loops need it), else ``None``."""
        if not self.output_row:
            return None
        H = np.zeros((1, self.n_states))
        for i, c in self.output_row:
            H[0, i % self.n_states] += c
        return H, np.zeros(1)

    def source_to_input(self, source: np.ndarray, dt: float) -> np.ndarray:
        """Map sampled sources ``(..., steps + 1, p)`` (at ``t_0 .. t_steps``) to the model
        input on each of the ``steps`` intervals, ``(..., steps, p)``.

        The default holds each interval at the source's value at its start (zero-order
        hold); a model whose input is another function of the source overrides it.
        """
        return np.asarray(source)[..., :-1, :]

    def operating_point(self, x_guess: np.ndarray | None = None,
                        u: np.ndarray | None = None) -> np.ndarray:
        """DC operating point: the root of ``f(x, u) = 0`` near ``x_guess`` (``u`` default 0).

        Where Newton fails from the guess (a saturated circuit, say), the circuit is first let
        settle for 20 us with the stiff integrator and Newton is tried again from there.
        """
        u0 = np.zeros(self.n_inputs) if u is None else np.asarray(u, float)
        guess = np.zeros(self.n_states) if x_guess is None else np.asarray(x_guess, float)
        name = self._operating_point_key(guess, u0)
        kept = disk_cache.load("operating_points", name) if name else None
        if kept is not None and kept.shape == (self.n_states,):
            return kept
        x = self._find_operating_point(guess, u0)
        if name:
            disk_cache.store("operating_points", name, x)
        return x

    def _operating_point_key(self, guess: np.ndarray, u0: np.ndarray) -> str | None:
        """The disk cache's key of a DC point (:mod:`estim.util.disk_cache`): the model's
        class, variant and parameters, the guess and the input, and the code that finds it
        (the model's modules, this one, the integrator). ``None`` (no cache) for a model
        that is not one of estim's own modules (a netlist's, a plugin's)."""
        classes = [c for c in type(self).__mro__ if c.__module__.startswith("estim.models.")]
        if not classes or classes[0] is not type(self):
            return None
        params = [(f.name, _exact(getattr(self.params, f.name)))
                  for f in dataclasses.fields(self.params)]
        return disk_cache.key(type(self).__module__, type(self).__qualname__, self.variant,
                              params, _exact(guess), _exact(u0), _code_fingerprint(),
                              np.__version__, scipy.__version__)

    def _find_operating_point(self, guess: np.ndarray, u0: np.ndarray) -> np.ndarray:
        """:meth:`operating_point`'s search, without the cache."""

        def solve(start):
            return optimize.root(lambda x: self.f(x, u0), start,
                                 jac=lambda x: self.jacobian(x, u0), method="hybr",
                                 options={"xtol": 1e-13})

        sol = solve(guess)
        if not sol.success:
            held = np.broadcast_to(u0, (1, 20, self.n_inputs))
            try:
                settled = simulate(self, guess, held, 1e-6, on_failure="nan",
                                   max_iterations=2_000)[0, -1]
            except SimulationError:
                raise RuntimeError(f"{self.name}: no DC operating point found (Newton failed "
                                   "and the circuit did not settle in 20 us)") from None
            sol = solve(settled)
        if not sol.success:
            raise RuntimeError(f"{self.name}: no DC operating point found ({sol.message})")
        return sol.x
