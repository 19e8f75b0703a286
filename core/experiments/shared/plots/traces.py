"""Signals against time: the estimation figures of Chapters 3 and 4 (input, output, each
estimate and its error; RMSE and residuals over time) and the perturbation figures of
Chapter 2."""

from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING

import numpy as np

from estim.experiments.shared.plots.style import (
        drawn,
    series_style,
    subplots,
    tight_layout,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _clipped(ax, t, y, lo: float, hi: float, label: str, **style) -> bool:
    """Draw the points of ``y`` inside ``[lo, hi]``; a curve that leaves the axis for good
    (runs away or stops being finite) is named with the time it left, one that leaves it
    now and then as partly off the axis. Returns False, drawing nothing, when no point is
    inside (the caller names the estimate instead)."""
    with np.errstate(invalid="ignore"):
        inside = np.isfinite(y) & (y >= lo) & (y <= hi)
    if not inside.any():
        return False
    if not inside.all():
        last = int(np.flatnonzero(inside)[-1])
        label = (f"{label} (leaves the axis at {t[last + 1]:.3g} ms)" if last + 1 < y.size
                 and not inside[last + 1:].any() else f"{label} (partly off the axis)")
    ax.plot(t, np.where(inside, y, np.nan), label=label, **style)
    return True


def _robust(values: np.ndarray) -> tuple[float, float] | None:
    """The 1st and 99th percentiles of the finite values (None when there are none)."""
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v)]
    return (float(np.percentile(v, 1)), float(np.percentile(v, 99))) if v.size else None


def output_limits(actual: np.ndarray, measured: np.ndarray,
                  estimates: dict) -> tuple[float, float]:
    """Output-axis limits that show the estimates: the robust range (1st-99th percentile)
    of the actual signal and the measurement, widened to take in each estimate's robust
    range that lies within ten times that width of it. An estimate beyond (one that ran
    away) is clipped and named instead of squeezing every other curve flat."""
    lo, hi = _robust(np.concatenate([np.ravel(actual), np.ravel(measured)])) or (-1.0, 1.0)
    span = hi - lo or max(abs(hi), 1e-3) * 1e-3
    reach = (lo - 10 * span, hi + 10 * span)
    for y in estimates.values():
        r = _robust(y)
        if r is not None and reach[0] <= r[0] and r[1] <= reach[1]:
            lo, hi = min(lo, r[0]), max(hi, r[1])
    pad = 0.05 * (hi - lo or span)
    return lo - pad, hi + pad


def _input_panel(ax, trace: dict, t_ms: np.ndarray, title: str) -> None:
    """(a) the source as applied and the nominal input, under the figure's title."""
    ax.plot(t_ms, trace["source"], lw=0.8, color="0.55", ls="-", marker="",
            label="source (as applied)")
    ax.plot(t_ms, trace["clean"], lw=1.2, color="k", ls="-", marker="", label="nominal input")
    ax.set_ylabel(r"input $v_\mathrm{in}$ [V]")
    ax.set_title(f"(a) input - {title}")


def _zoom_limits(actual: np.ndarray) -> tuple[float, float]:
    """The actual signal's range, widened by half its span on each side."""
    span = float(np.ptp(actual)) or 1e-3
    return float(actual.min()) - 0.5 * span, float(actual.max()) + 0.5 * span


def zoom_adds(trace: dict, whole: bool) -> bool:
    """Whether the zoomed panel shows something the whole-record panel does not: a part of
    the record, or the whole record on a range at most half as wide (an estimate that runs
    away stretches the whole-record axis). Otherwise the figure leaves it out instead of
    drawing the same panel twice."""
    if not whole:
        return True
    lo, hi = output_limits(trace["actual"], trace["z"], trace["y_hat"])
    z_lo, z_hi = _zoom_limits(trace["actual"])
    return hi - lo > 2 * (z_hi - z_lo)


def _output_panels(axes, trace: dict, t_ms: np.ndarray, zoom: slice, zoom_heading: str,
                   ylabel: str) -> None:
    """(b) the whole record on :func:`output_limits`, (c) a zoom (``zoom`` of the samples)
    held to the actual signal's range, where the waveform can be read, when ``axes`` has
    three panels, and last each estimate's error against the actual signal."""
    ax_all, ax_err = axes[0], axes[-1]
    ax_zoom = axes[1] if len(axes) == 3 else None
    actual, z, y_hat = trace["actual"], trace["z"], trace["y_hat"]
    lo, hi = output_limits(actual, z, y_hat)
    z_lo, z_hi = _zoom_limits(actual)
    styles = {label: series_style(i) for i, label in enumerate(y_hat)}
    ax_all.plot(t_ms, z, ".", ms=2, color="0.6", label="measurement")
    ax_all.plot(t_ms, actual, lw=1.6, color="k", ls="-", marker="", label="actual")
    away = [label for label, y in y_hat.items()
            if not _clipped(ax_all, t_ms, y, lo, hi, label, lw=1.0, **styles[label])]
    ax_all.set_ylim(lo, hi)
    ax_all.set_title("(b) estimates, whole record (run 1)"
                     + (f"; off the axis throughout: {', '.join(away)}" if away else ""))
    if ax_zoom is not None:
        _zoom_panel(ax_zoom, trace, t_ms, zoom, zoom_heading, styles)
        ax_zoom.set_ylabel(ylabel)
    for label, y in y_hat.items():
        with np.errstate(invalid="ignore"):
            error = np.abs(np.asarray(y, float) - actual)
        error = np.where(np.isfinite(error) & (error > 0), error, np.nan)
        if np.isfinite(error).any():
            ax_err.plot(t_ms, error, lw=0.9, **styles[label], label=label)
    ax_err.plot(t_ms, np.where(np.abs(z - actual) > 0, np.abs(z - actual), np.nan), ".",
                ms=1.5, color="0.6", label="measurement")
    ax_err.set_yscale("log")
    ax_err.set_title(f"({'d' if ax_zoom is not None else 'c'}) error |estimate - actual| "
                     "(run 1)")
    ax_err.set_ylabel(f"absolute error [{ylabel.rpartition('[')[2].rstrip(']') or 'V'}]")
    for ax in axes:
        ax.set_xlabel("time [ms]")
    ax_all.set_ylabel(ylabel)


def _zoom_panel(ax, trace: dict, t_ms: np.ndarray, zoom: slice, heading: str,
                styles: dict) -> None:
    """(c) of :func:`_output_panels`: the samples ``zoom`` on :func:`_zoom_limits`."""
    actual, z = trace["actual"], trace["z"]
    z_lo, z_hi = _zoom_limits(actual)
    ax.plot(t_ms[zoom], z[zoom], ".", ms=2, color="0.6", label="measurement")
    ax.plot(t_ms[zoom], actual[zoom], lw=1.6, color="k", ls="-", marker="", label="actual")
    outside = []
    for label, y in trace["y_hat"].items():
        part = y[zoom]
        with np.errstate(invalid="ignore"):
            inside = np.isfinite(part) & (part >= z_lo) & (part <= z_hi)
        if inside.any():
            ax.plot(t_ms[zoom], np.where(inside, part, np.nan), lw=1.0, **styles[label],
                    label=label)
        else:
            outside.append(label)
    ax.set_ylim(z_lo, z_hi)
    ax.set_title(f"(c) {heading}, on the actual signal's range"
                 + (f"; outside: {', '.join(outside)}" if outside else ""))


@drawn
def estimates(trace: dict, title: str, period_s: float | None = None,
              window_periods: int = 3) -> Figure:
    """Input and output, actual, measured and every estimate (Figs 3.2-3.5): (a) the input;
    (b) the output over the whole record, its axis spanning the estimates
    (:func:`output_limits`); (c) a zoom held to the actual signal's range, over the last
    ``window_periods`` periods with ``period_s`` (else the whole record), where the
    waveform can be read; (d) each estimate's error. Legends sit outside the data."""
    t = trace["t"]
    zoom = (period_s is not None and t[-1] - t[0] > 2 * window_periods * period_s)
    panels = 4 if zoom_adds(trace, whole=not zoom) else 3
    fig, axes = subplots(panels, 1, figsize=(10.0, 2.75 * panels))
    t_ms = t * 1e3
    _input_panel(axes[0], trace, t_ms, title)
    axes[0].set_xlabel("time [ms]")
    start = int(np.searchsorted(t, t[-1] - window_periods * period_s)) if zoom else 0
    _output_panels(axes[1:], trace, t_ms, slice(start, None),
                   f"the last {window_periods} periods" if zoom else "whole record",
                   "output [V]")
    for ax in axes:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    tight_layout(fig)
    return fig


def _series(trace: dict, key: str, ylabel: str, title: str) -> Figure:
    fig, ax = subplots(figsize=(10.0, 4.5))
    t_ms = trace["t"] * 1e3
    for i, (label, values) in enumerate(trace[key].items()):
        values = np.asarray(values, float)
        if not np.isfinite(values).any():
            label = f"{label} (no finite value: every run diverged)"
        elif not np.isfinite(values).all():
            label = f"{label} (not finite from {t_ms[np.argmax(~np.isfinite(values))]:.3g} ms)"
        ax.plot(t_ms, values, lw=1.0, **series_style(i), label=label)
    ax.set_xlabel("time [ms]")
    ax.set_ylabel(ylabel)
    ax.set_title(textwrap.fill(title, 70))     # the legend takes the right side
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.grid(True)
    tight_layout(fig)
    return fig


@drawn
def predictions(t: np.ndarray, measured: np.ndarray, predicted: dict, title: str) -> Figure:
    """A measured record (no truth) and each filter's one-step prediction of its samples
    after the first (:mod:`estim.experiments.measured`)."""
    fig, ax = subplots(figsize=(10.0, 4.5))
    t_ms = np.asarray(t, float) * 1e3
    ax.plot(t_ms, measured, ls="None", marker=".", ms=3.0, color="0.55", label="measured")
    for i, (label, values) in enumerate(predicted.items()):
        ax.plot(t_ms[1:], values, lw=1.0, **series_style(i), label=f"{label}, predicted")
    ax.set_xlabel("time [ms]")
    ax.set_ylabel("output [V]")
    ax.set_title(textwrap.fill(title, 70))
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    tight_layout(fig)
    return fig


@drawn
def running_rmse(trace: dict, title: str) -> Figure:
    """RMSE across the Monte Carlo runs that did not diverge, at each sample (Fig 3.6)."""
    return _series(trace, "running_rmse", "RMSE over runs [V]", title)


@drawn
def residuals(trace: dict, title: str) -> Figure:
    """Residual (prior innovation) of one run over time (Fig 3.7)."""
    return _series(trace, "innovation", "residual [V]", title)


@drawn
def parameters(t: np.ndarray, values: dict, title: str) -> Figure:
    """Element values estimated as states, one panel each: every filter's estimate of run 1
    with its +-3 standard deviation band, and the actual circuit's value (``values``: name
    -> ``{"true": value, "filters": {label: (estimate, sd)}}``)."""
    fig, axes = subplots(len(values), 1, figsize=(10.0, 2.0 + 2.5 * len(values)), sharex=True,
                         squeeze=False)
    t_ms = np.asarray(t, float) * 1e3
    for ax, (name, value) in zip(axes[:, 0], values.items(), strict=True):
        for i, (label, (estimate, sd)) in enumerate(value["filters"].items()):
            style = series_style(i)
            ax.plot(t_ms, estimate, lw=1.0, **style, label=f"{label} (+-3 sd)")
            ax.fill_between(t_ms, estimate - 3 * sd, estimate + 3 * sd, alpha=0.15,
                            color=style.get("color"))
        ax.axhline(value["true"], color="k", ls="--", lw=1.0, label="actual circuit")
        ax.set_ylabel(name)
        ax.grid(True)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[0, 0].set_title(textwrap.fill(title, 70))
    axes[-1, 0].set_xlabel("time [ms]")
    tight_layout(fig)
    return fig


UNITS = {"R": "\u03a9", "C": "F", "L": "H", "V": "V", "U": "V", "I": "A"}
"""The unit of a circuit parameter by its first letter (R_E, C_GX, L_1, V_CC, U_T, I_0)."""


def with_unit(name: str, value: float) -> str:
    """``L_1 = 6 \u00b5H`` for a parameter of a known kind, ``name = value`` otherwise."""
    from matplotlib.ticker import EngFormatter

    unit = UNITS.get(name[:1]) if "_" in name and name[:1].isupper() else None
    if unit is None or not isinstance(value, (int, float)):
        return f"{name} = {value:g}" if isinstance(value, (int, float)) else f"{name} = {value}"
    return f"{name} = {EngFormatter(unit=unit, sep=' ')(float(value))}"


@drawn
def perturbation(trace: dict, title: str) -> Figure:
    """Input (a); zeroth-order, zeroth + first-order and full nonlinear output (b); the
    first-order output beside the true nonlinear part ``full - zeroth`` (c), on one time
    axis (Figs 2.2, 2.4, 2.6, 2.8)."""
    fig, (ax_in, ax_out, ax_nl) = subplots(3, 1, figsize=(10.0, 8.0), sharex=True)
    t, unit = trace["t"], "s"
    for scale, name in ((1e3, "ms"), (1e6, "µs"), (1e9, "ns")):
        if t[-1] * scale >= 1.0:
            t, unit = trace["t"] * scale, name
            break
    ax_in.plot(t, trace["input"], lw=1.0, color="k", ls="-", marker="")
    ax_in.set_ylabel("input [V]")
    wrapped = "\n".join(textwrap.fill(line, 100) for line in title.splitlines())
    ax_in.set_title(f"{wrapped}\n(a) input (deviation from the bias)")
    ax_out.plot(t, trace["y_full"], lw=2.4, color="0.75", ls="-", marker="",
                label="full nonlinear")
    ax_out.plot(t, trace["y0"], lw=1.0, **series_style(0), label="zeroth order (linear)")
    ax_out.plot(t, trace["y0"] + trace["y1"], lw=1.0, **series_style(1),
                label="zeroth + first order")
    ax_out.set_ylabel("output [V]")
    ax_out.set_title("(b) output (deviation from the operating point)")
    ax_out.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax_nl.plot(t, trace["y_full"] - trace["y0"], lw=2.4, color="0.75", ls="-", marker="",
               label="full - zeroth order")
    ax_nl.plot(t, trace["y1"], lw=1.0, **series_style(2), label="first order")
    ax_nl.set_xlabel(f"time [{unit}]")
    ax_nl.set_ylabel("nonlinear part [V]")
    ax_nl.set_title("(c) first-order output and the true nonlinear part")
    ax_nl.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    tight_layout(fig)
    return fig


@drawn
def estimates_clipped(trace: dict, title: str) -> Figure:
    """Input (a) and output like :func:`estimates` (Figs 4.3-4.7): (b) the whole record on
    an axis that spans the estimates (one that runs away is drawn until it leaves and named
    with the time it left), (c) the same record held to the actual signal's range where
    that shows more (:func:`zoom_adds`), and each estimate's error. Legends outside the
    data."""
    panels = 4 if zoom_adds(trace, whole=True) else 3
    fig, axes = subplots(panels, 1, figsize=(10.0, 2.75 * panels), sharex=True)
    t_ms = trace["t"] * 1e3
    _input_panel(axes[0], trace, t_ms, title)
    _output_panels(axes[1:], trace, t_ms, slice(None), "whole record", r"output $v_D$ [V]")
    for ax in axes:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    tight_layout(fig)
    return fig
