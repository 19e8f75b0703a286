"""Why a run broke: the step, the state and the cause, for ``health.csv`` and the run's note
(issue 47, item 7).

A filter's loop marks a run broken at the first step whose prediction or estimate is not
finite or leaves ``|x| <= divergence_bound`` (or whose update fails), and leaves its outputs
NaN from that step on. The loops record which of these happened, and to which state, as they
break the run (:func:`estim.estimators.base.run_batch`, and the compiled loops through
:func:`estim.estimators.compiled_steps.broke`); a filter that does not is given the step
alone, read from its outputs (:func:`break_steps`).
"""

from __future__ import annotations

import numpy as np

CAUSES = ("", "prediction not finite", "prediction beyond the bound", "update failed",
          "estimate not finite", "estimate beyond the bound", "covariance not finite")
"""A break's cause by its number (0: not broken); the compiled loops record the number.
"update failed": the innovation covariance was not positive definite, which only the compiled
loops' update reports (the numpy loop's update then gives a non-finite estimate, and says
that)."""


def reasons(cause: np.ndarray, state: np.ndarray, step: np.ndarray) -> dict[str, np.ndarray]:
    """The ``diagnostics`` of an :class:`~estim.estimators.base.Estimate` from the loops'
    per-run records: ``broken_step`` (-1: not broken), ``broken_state`` (an index; -1: none)
    and ``broken_cause`` (text of :data:`CAUSES`)."""
    return {"broken_step": np.asarray(step, int), "broken_state": np.asarray(state, int),
            "broken_cause": np.array([CAUSES[int(c)] for c in cause], dtype=object)}


def cause_of(xp: np.ndarray, xu: np.ndarray, Pu: np.ndarray, bound: float) -> tuple[int, int]:
    """``(cause number, state)`` of one run's failed step, checked in the compiled loops'
    order: the prediction, then the estimate, then the covariance."""
    for values, first in ((xp, 1), (xu, 4)):
        finite = np.isfinite(values)
        if not finite.all():
            return first, int(np.argmin(finite))
        beyond = np.abs(values) > bound
        if beyond.any():
            return first + 1, int(np.argmax(beyond))
    finite = np.all(np.isfinite(Pu), axis=-1)
    return (6, int(np.argmin(finite))) if not finite.all() else (6, -1)


def break_steps(outputs: np.ndarray, broken: np.ndarray) -> np.ndarray:
    """``(runs,)`` the step at which each broken run's ``outputs (runs, steps, k)`` turn NaN
    for good (0: the first step), -1 for a run that did not break."""
    bad = ~np.all(np.isfinite(outputs), axis=-1)
    steps = np.where(bad.any(axis=1), np.argmax(bad, axis=1), -1)
    return np.where(np.asarray(broken, bool), steps, -1)


def first_break(steps: np.ndarray, states: np.ndarray | None, causes: np.ndarray | None,
                names: tuple) -> tuple[float, str, str]:
    """The earliest break of a batch (the lowest run at that step): its step counted from 1
    (the first sample after ``t_0``), its state's name and its cause; NaN and empty text
    when no run broke, empty text where the filter gives none."""
    steps = np.asarray(steps)
    if not (steps >= 0).any():
        return float("nan"), "", ""
    r = int(np.flatnonzero(steps == steps[steps >= 0].min())[0])
    j = -1 if states is None else int(states[r])
    return (float(steps[r] + 1), names[j] if 0 <= j < len(names) else "",
            "" if causes is None else str(causes[r]))
