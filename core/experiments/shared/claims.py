"""One rule for every claim: a paired comparison on the same draws (docs/claims.md).

A claim says that estimator ``better`` has a smaller loss than estimator ``worse`` (RMSE,
mean absolute error, MSE, taps, multiplications: whatever the table measures, smaller is
better) in one table cell. Both were run on the same noise draws, so the claim is judged on
the paired per-run differences ``d_i = loss_better_i - loss_worse_i``, at the level
:data:`LEVEL`. The estimand is the same whatever the data: the **median** of ``d``.

``exact``  a deterministic computation (one "run" with no noise, the analysis declares it):
           the difference itself; a tie when it is within :data:`TIE_RTOL` of the larger
           loss (rounding), or when both diverged.
``sign``   Monte Carlo runs: the distribution-free interval of the median difference from
           the sign test (order statistics ``d_(k), d_(n-k+1)``). A diverged run is a loss for
           its filter larger than any finite one (``d = +inf`` where only ``better``
           diverged, ``-inf`` where only ``worse`` did, ``0`` where both did), which order
           statistics carry without dropping the run, so a broken run never changes the
           question. Fewer than six runs give no such interval at 95 %: undecided, thin
           evidence whatever the differences.

The verdict reads the interval: ``holds`` when it lies below zero, ``fails`` when it lies
above zero, ``undecided`` when it contains zero. Analyses declare which pairs they compare;
they never judge (``tests/test_analyses.py`` checks that every claims table comes from
:func:`table`).

A claim judged in many cells is a **family**: each cell also has the ``p_value`` of its
test (two-sided; the exact sign test, or 0 / 1 for a deterministic difference),
and ``verdict_family`` is its verdict after Holm's step-down correction within the claim's
cells (:func:`families`), so that the chance of any wrong decided verdict in the family is
at most 1 - :data:`LEVEL`. A cell keeps its verdict only where Holm's test rejects "no
difference"; elsewhere it is ``undecided``.

A config may set a **margin of practical significance** (``claim_margin``, a fraction of the
worse loss; 0 by default and for every thesis claim): a difference whose interval does not
clear it is undecided (:func:`with_margin`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from estim.reference.tablespec import TableSpec
from estim.util import lazy

pd = lazy.load("pandas")

LEVEL = 0.95
"""Two-sided coverage of every claim's interval."""

TIE_RTOL = 1e-9
"""A deterministic difference within this fraction of the larger loss is rounding: a tie."""

HOLDS, FAILS, UNDECIDED = "holds", "fails", "undecided"
VERDICTS = (HOLDS, FAILS, UNDECIDED)
METHODS = ("exact", "sign")

KEYS = ("claim", "cell", "better", "worse", "metric")
VALUES = ("runs", "diverged_better", "diverged_worse", "loss_better", "loss_worse",
          "difference", "difference_low", "difference_high", "ratio",
          "ratio_low", "ratio_high", "method", "verdict", "p_value", "verdict_family")

TABLE = TableSpec(
    "claims.csv", KEYS, VALUES, text=("method", "verdict", "verdict_family"),
    title="claims: paired comparisons on the same draws, holds / fails / undecided "
          "(docs/claims.md)")
"""The claims table of every analysis: the same columns everywhere."""


@dataclass(frozen=True)
class Losses:
    """One estimator's loss in one cell, per run (``values``), and which runs diverged by
    the analysis' stated criterion (``None``: none did; a non-finite loss always counts)."""

    values: np.ndarray
    diverged: np.ndarray | None = None

    def flags(self) -> np.ndarray:
        values = np.atleast_1d(np.asarray(self.values, float))
        out = ~np.isfinite(values)
        if self.diverged is not None:
            out |= np.atleast_1d(np.asarray(self.diverged, bool))
        return out


def _median_loss(values: np.ndarray, flags: np.ndarray) -> float:
    """Median loss over every run; a run that diverged, or whose loss is not finite, counts as
    a loss larger than any finite one (``inf``)."""
    return float(np.median(np.where(flags, np.inf, values)))


def sign_interval_rank(n: int, level: float = LEVEL) -> int:
    """The largest ``k`` with ``P(Binomial(n, 1/2) <= k - 1) <= (1 - level) / 2``: the
    interval ``[d_(k), d_(n-k+1)]`` covers the median with probability at least ``level``.
    0 when no such interval exists (``n < 6`` at 95 %)."""
    tail = Fraction((1.0 - level) / 2.0)
    k, below = 0, 1                          # below: 2^n P(Binomial(n, 1/2) <= k), exact
    while k + 1 <= n // 2 + 1 and Fraction(below, 2**n) <= tail:
        k += 1
        below += math.comb(n, k)
    return k


def sign_p_value(d: np.ndarray) -> float:
    """Two-sided p-value of the exact sign test of a zero median difference: zero
    differences (ties, runs where both diverged) are left out; ``2 P(Binomial(m, 1/2) <=
    min(n+, n-))`` over the ``m`` others, at most 1."""
    pos, neg = int(np.sum(d > 0)), int(np.sum(d < 0))
    m = pos + neg
    if m == 0:
        return 1.0
    tail = sum(math.comb(m, i) for i in range(min(pos, neg) + 1))
    return float(min(Fraction(1), Fraction(2 * tail, 2**m)))


def holm(p_values: Sequence[float], level: float = LEVEL) -> np.ndarray:
    """Holm's step-down test at family level ``level``: the p-values sorted ascending,
    ``p_(i)`` is rejected while ``p_(i) <= (1 - level) / (m - i + 1)`` holds for it and every
    smaller one. Returns which hypotheses (in the order given) are rejected."""
    p = np.asarray(p_values, float)
    alpha = 1.0 - level
    out = np.zeros(p.size, bool)
    for rank, i in enumerate(np.argsort(p, kind="stable")):
        if not p[i] <= alpha / (p.size - rank):
            break
        out[i] = True
    return out


def families(df: pd.DataFrame, level: float = LEVEL) -> pd.DataFrame:
    """``verdict_family`` of every row of a claims table: each claim is a family over its
    cells, corrected by :func:`holm`; a cell keeps its ``verdict`` where Holm rejects,
    else it is ``undecided``."""
    out = df.copy()
    family = pd.Series(UNDECIDED, index=out.index, dtype=object)
    for _, part in out.groupby("claim", sort=False):
        rejected = holm(part["p_value"].to_numpy(float), level)
        decided = part["verdict"].astype(str) != UNDECIDED
        keep = part.index[rejected & decided.to_numpy()]
        family.loc[keep] = part.loc[keep, "verdict"].astype(str)
    out["verdict_family"] = family
    return out


def _verdict(low: float, high: float, tie: float = 0.0) -> str:
    if high < -tie:
        return HOLDS
    if low > tie:
        return FAILS
    return UNDECIDED


def with_margin(df: pd.DataFrame, margin: float, level: float = LEVEL) -> pd.DataFrame:
    """The claims table ``df`` judged with a margin of practical significance: a cell holds
    only where its interval lies below ``-margin * L`` and fails only where it lies above
    ``+margin * L``, ``L`` the worse (larger) of the two median losses (the finite one when
    only one is; 0 when neither is), and is undecided otherwise; ``verdict_family`` follows
    (:func:`families`). ``margin`` 0 leaves every verdict as it is."""
    if not margin or df.empty:
        return df
    out = df.copy()
    losses = out[["loss_better", "loss_worse"]].to_numpy(float)
    finite = np.where(np.isfinite(losses), np.abs(losses), -np.inf)
    larger = finite.max(axis=1)
    tie = margin * np.where(np.isfinite(larger), larger, 0.0)
    out["verdict"] = [
        _verdict(low, high, t) if verdict != UNDECIDED else UNDECIDED
        for low, high, t, verdict in zip(out["difference_low"], out["difference_high"], tie,
                                         out["verdict"].astype(str), strict=True)]
    return families(out, level)


def judge(better: Losses, worse: Losses, level: float = LEVEL, exact: bool = False) -> dict:
    """The claim ``better`` < ``worse`` on paired per-run losses, by the rule of the module
    docstring: the columns :data:`VALUES` of one row of the claims table. ``exact``: the
    losses come from a deterministic computation, one value each."""
    b = np.atleast_1d(np.asarray(better.values, float))
    w = np.atleast_1d(np.asarray(worse.values, float))
    if b.shape != w.shape or b.ndim != 1 or b.size == 0:
        raise ValueError(f"paired losses need one value per run on both sides, got {b.shape} "
                         f"and {w.shape}")
    fb, fw = better.flags(), worse.flags()
    n = b.size
    out = {"runs": n, "diverged_better": int(fb.sum()), "diverged_worse": int(fw.sum()),
           "loss_better": _median_loss(b, fb), "loss_worse": _median_loss(w, fw)}
    if exact:
        if n != 1:
            raise ValueError(f"an exact claim compares one value a side, got {n}")
        method = "exact"
        if fb[0] and fw[0]:
            d = 0.0
        elif fb[0]:
            d = float("inf")
        elif fw[0]:
            d = -float("inf")
        else:
            d = float(b[0] - w[0])
            if abs(d) <= TIE_RTOL * max(abs(b[0]), abs(w[0])):
                d = 0.0
        low = high = d
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = float(np.inf if fb[0] and not fw[0] else 0.0 if fw[0] and not fb[0]
                          else 1.0 if fb[0] else b[0] / w[0])
        out.update(difference=d, difference_low=low, difference_high=high,
                   ratio=ratio, ratio_low=ratio, ratio_high=ratio)
        verdict = UNDECIDED if d == 0 else _verdict(low, high)
        p = 1.0 if d == 0 else 0.0
    else:
        method = "sign"
        with np.errstate(invalid="ignore", divide="ignore"):
            d = np.where(fb & fw, 0.0, np.where(fb, np.inf, np.where(fw, -np.inf, b - w)))
            r = np.where(fb & fw, 1.0, np.where(fb, np.inf, np.where(fw, 0.0, b / w)))
        d, r = np.sort(d), np.sort(r)
        k = sign_interval_rank(n, level)
        low, high = (float(d[k - 1]), float(d[n - k])) if k else (-np.inf, np.inf)
        r_low, r_high = (float(r[k - 1]), float(r[n - k])) if k else (0.0, np.inf)
        out.update(difference=float(np.median(d)), difference_low=low,
                   difference_high=high, ratio=float(np.median(r)), ratio_low=r_low,
                   ratio_high=r_high)
        verdict = _verdict(low, high)
        p = sign_p_value(d)
    out["method"], out["verdict"], out["p_value"] = method, verdict, p
    return out


CELL_SEPARATOR = "; "


def cell(**keys) -> str:
    """A table cell named by its key values: ``"s_no=3; frequency_hz=1000"`` (floats as
    ``%g``, missing values left out)."""
    parts = []
    for key, value in keys.items():
        if value is None or (isinstance(value, float) and np.isnan(value)) or value is pd.NA:
            continue
        if isinstance(value, (float, np.floating)):
            value = f"{float(value):g}"
        parts.append(f"{key}={value}")
    return CELL_SEPARATOR.join(parts)


def cell_keys(text: str) -> dict[str, str]:
    """The key values of a cell named by :func:`cell`."""
    return dict(part.split("=", 1) for part in text.split(CELL_SEPARATOR) if "=" in part)


def table(cells: Iterable[tuple[str, Mapping[str, Losses]]], pairs: Sequence[tuple[str, str]],
          metric: str, claim: str | None = None, exact: bool = False) -> pd.DataFrame:
    """The claims table: every pair ``(better, worse)`` judged in every cell that has both.

    ``cells`` gives each cell's description (:func:`cell`) and its losses by estimator;
    ``claim`` names the claim (default ``"<better> <metric> < <worse> <metric>"``);
    ``exact``: the losses are deterministic (one value each, judged exactly)."""
    rows = []
    cells = list(cells)
    for better, worse in pairs:
        for where, losses in cells:
            if better not in losses or worse not in losses:
                continue
            rows.append({"claim": claim or f"{better} {metric} < {worse} {metric}",
                         "cell": where, "better": better, "worse": worse, "metric": metric,
                         **judge(losses[better], losses[worse], exact=exact),
                         "verdict_family": UNDECIDED})
    return families(pd.DataFrame(rows, columns=TABLE.columns))


def counts(df: pd.DataFrame, column: str = "verdict_family") -> pd.DataFrame:
    """Verdict counts per claim (of ``column``: the family-corrected verdicts, or the
    cells' own): ``holds``, ``fails``, ``undecided`` and ``cells``, in the order the claims
    first appear."""
    out = []
    for claim, part in df.groupby("claim", sort=False):
        v = part[column].astype(str)
        out.append({"claim": claim, HOLDS: int((v == HOLDS).sum()),
                    FAILS: int((v == FAILS).sum()), UNDECIDED: int((v == UNDECIDED).sum()),
                    "cells": len(part)})
    return pd.DataFrame(out, columns=["claim", HOLDS, FAILS, UNDECIDED, "cells"])
