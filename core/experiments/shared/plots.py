"""Figures (matplotlib, Agg only). Each function takes figure data and returns a Figure."""

from __future__ import annotations

import functools
import textwrap
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from estim.util.drawing import DRAWING

if TYPE_CHECKING:
    from matplotlib.figure import Figure


F = TypeVar("F", bound=Callable)


def _one_at_a_time(draw: F) -> F:
    """``draw`` under :data:`DRAWING`."""
    @functools.wraps(draw)
    def drawn(*args, **kwargs):
        with DRAWING:
            return draw(*args, **kwargs)
    return drawn  # type: ignore[return-value]


def subplots(nrows: int = 1, ncols: int = 1, *, figsize: tuple[float, float],
             **grid) -> tuple[Figure, object]:
    """A new figure and its grid of axes (``pyplot.subplots`` without pyplot): the figure is
    nobody's but the caller's (pyplot's registry of open figures is shared by every thread,
    and two configs may draw at once, :mod:`estim.engine.scheduler`), rendered by Agg when saved.
    matplotlib is imported at the first figure: a command that draws nothing (``estim
    validate``, ``estim table``) does not pay for it."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **grid)


def _tight_layout(fig: Figure) -> None:
    """``fig.tight_layout()``, done once: matplotlib keeps a placeholder layout engine after
    it, and a figure with any layout engine is drawn an extra time when saved (to lay it
    out again), a third of the time of saving it."""
    fig.tight_layout()
    fig.set_layout_engine(None)


SIZE = (8.0, 6.0)
LINESTYLES = ("-", "--", "-.", ":")
"""Estimates that coincide (an EKF and a UKF on a near-linear model) stay distinguishable."""
DPI = 100


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
    ax.plot(t_ms, trace["source"], lw=0.8, label="source (as applied)")
    ax.plot(t_ms, trace["clean"], lw=1.2, label="nominal input")
    ax.set_ylabel("v_in [V]")
    ax.set_title(f"(a) input - {title}", fontsize=10)


def _output_panels(axes, trace: dict, t_ms: np.ndarray, zoom: slice, zoom_heading: str,
                   ylabel: str) -> None:
    """(b) the whole record on :func:`output_limits`, (c) a zoom (``zoom`` of the samples)
    held to the actual signal's range, where the waveform can be read, and (d) each
    estimate's error against the actual signal."""
    ax_all, ax_zoom, ax_err = axes
    actual, z, y_hat = trace["actual"], trace["z"], trace["y_hat"]
    lo, hi = output_limits(actual, z, y_hat)
    span = float(np.ptp(actual)) or 1e-3
    z_lo, z_hi = float(actual.min()) - 0.5 * span, float(actual.max()) + 0.5 * span
    styles = {label: LINESTYLES[i % len(LINESTYLES)] for i, label in enumerate(y_hat)}
    ax_all.plot(t_ms, z, ".", ms=2, color="0.6", label="measurement")
    ax_all.plot(t_ms, actual, lw=1.6, color="k", label="actual")
    away = [label for label, y in y_hat.items()
            if not _clipped(ax_all, t_ms, y, lo, hi, label, lw=1.0, ls=styles[label])]
    ax_all.set_ylim(lo, hi)
    ax_all.set_title("(b) estimates, whole record (run 1)"
                     + (f"; off the axis throughout: {', '.join(away)}" if away else ""),
                     fontsize=10)
    ax_zoom.plot(t_ms[zoom], z[zoom], ".", ms=2, color="0.6", label="measurement")
    ax_zoom.plot(t_ms[zoom], actual[zoom], lw=1.6, color="k", label="actual")
    outside = []
    for label, y in y_hat.items():
        part = y[zoom]
        with np.errstate(invalid="ignore"):
            inside = np.isfinite(part) & (part >= z_lo) & (part <= z_hi)
        if inside.any():
            ax_zoom.plot(t_ms[zoom], np.where(inside, part, np.nan), lw=1.0, ls=styles[label],
                         label=label)
        else:
            outside.append(label)
    ax_zoom.set_ylim(z_lo, z_hi)
    ax_zoom.set_title(f"(c) {zoom_heading}, on the actual signal's range"
                      + (f"; outside: {', '.join(outside)}" if outside else ""), fontsize=10)
    for label, y in y_hat.items():
        with np.errstate(invalid="ignore"):
            error = np.abs(np.asarray(y, float) - actual)
        error = np.where(np.isfinite(error) & (error > 0), error, np.nan)
        if np.isfinite(error).any():
            ax_err.plot(t_ms, error, lw=0.9, ls=styles[label], label=label)
    ax_err.plot(t_ms, np.where(np.abs(z - actual) > 0, np.abs(z - actual), np.nan), ".",
                ms=1.5, color="0.6", label="measurement")
    ax_err.set_yscale("log")
    ax_err.set_title("(d) error |estimate - actual| (run 1)", fontsize=10)
    ax_err.set_ylabel(f"error [{ylabel.rpartition('[')[2].rstrip(']') or 'V'}]")
    for ax in axes:
        ax.set_xlabel("time [ms]")
    ax_all.set_ylabel(ylabel)
    ax_zoom.set_ylabel(ylabel)


@_one_at_a_time
def estimates(trace: dict, title: str, period_s: float | None = None,
              window_periods: int = 3) -> Figure:
    """Input and output, actual, measured and every estimate (Figs 3.2-3.5): (a) the input;
    (b) the output over the whole record, its axis spanning the estimates
    (:func:`output_limits`); (c) a zoom held to the actual signal's range, over the last
    ``window_periods`` periods with ``period_s`` (else the whole record), where the
    waveform can be read; (d) each estimate's error. Legends sit outside the data."""
    t = trace["t"]
    zoom = (period_s is not None and t[-1] - t[0] > 2 * window_periods * period_s)
    fig, axes = subplots(4, 1, figsize=(10.0, 11.0))
    t_ms = t * 1e3
    _input_panel(axes[0], trace, t_ms, title)
    axes[0].set_xlabel("time [ms]")
    start = int(np.searchsorted(t, t[-1] - window_periods * period_s)) if zoom else 0
    _output_panels(axes[1:], trace, t_ms, slice(start, None),
                   f"the last {window_periods} periods" if zoom else "whole record",
                   "output [V]")
    for ax in axes:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    _tight_layout(fig)
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
        ax.plot(t_ms, values, lw=1.0, ls=LINESTYLES[i % len(LINESTYLES)], label=label)
    ax.set_xlabel("time [ms]")
    ax.set_ylabel(ylabel)
    ax.set_title(textwrap.fill(title, 70), fontsize=10)     # the legend takes the right side
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(True, lw=0.3)
    _tight_layout(fig)
    return fig


@_one_at_a_time
def running_rmse(trace: dict, title: str) -> Figure:
    """RMSE across the Monte Carlo runs that did not diverge, at each sample (Fig 3.6)."""
    return _series(trace, "running_rmse", "RMSE over runs [V]", title)


@_one_at_a_time
def residuals(trace: dict, title: str) -> Figure:
    """Residual (prior innovation) of one run over time (Fig 3.7)."""
    return _series(trace, "innovation", "residual [V]", title)


UNITS = {"R": "\u03a9", "C": "F", "L": "H", "V": "V", "U": "V", "I": "A"}
"""The unit of a circuit parameter by its first letter (R_E, C_GX, L_1, V_CC, U_T, I_0)."""


def with_unit(name: str, value: float) -> str:
    """``L_1 = 6 \u00b5H`` for a parameter of a known kind, ``name = value`` otherwise."""
    from matplotlib.ticker import EngFormatter

    unit = UNITS.get(name[:1]) if "_" in name and name[:1].isupper() else None
    if unit is None or not isinstance(value, (int, float)):
        return f"{name} = {value:g}" if isinstance(value, (int, float)) else f"{name} = {value}"
    return f"{name} = {EngFormatter(unit=unit, sep=' ')(float(value))}"


@_one_at_a_time
def perturbation(trace: dict, title: str) -> Figure:
    """Input (a); zeroth-order, zeroth + first-order and full nonlinear output (b); the
    first-order output beside the true nonlinear part ``full - zeroth`` (c), on one time
    axis (Figs 2.2, 2.4, 2.6, 2.8)."""
    fig, (ax_in, ax_out, ax_nl) = subplots(3, 1, figsize=(10.0, 8.0), sharex=True)
    t, unit = trace["t"], "s"
    for scale, name in ((1e3, "ms"), (1e6, "us"), (1e9, "ns")):
        if t[-1] * scale >= 1.0:
            t, unit = trace["t"] * scale, name
            break
    ax_in.plot(t, trace["input"], lw=1.0, color="C0")
    ax_in.set_ylabel("input [V]")
    wrapped = "\n".join(textwrap.fill(line, 100) for line in title.splitlines())
    ax_in.set_title(f"{wrapped}\n(a) input (deviation from the bias)", fontsize=9)
    ax_out.plot(t, trace["y_full"], lw=2.4, color="0.75", label="full nonlinear")
    ax_out.plot(t, trace["y0"], lw=1.0, color="C1", label="zeroth order (linear)")
    ax_out.plot(t, trace["y0"] + trace["y1"], "--", lw=1.0, color="C2",
                label="zeroth + first order")
    ax_out.set_ylabel("output [V]")
    ax_out.set_title("(b) output (deviation from the operating point)")
    ax_out.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax_nl.plot(t, trace["y_full"] - trace["y0"], lw=2.4, color="0.75",
               label="full - zeroth order")
    ax_nl.plot(t, trace["y1"], "--", lw=1.0, color="C3", label="first order")
    ax_nl.set_xlabel(f"time [{unit}]")
    ax_nl.set_ylabel("nonlinear part [V]")
    ax_nl.set_title("(c) first-order output and the true nonlinear part")
    ax_nl.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    _tight_layout(fig)
    return fig


@_one_at_a_time
def burden(timing, slopes) -> Figure:
    """Multiplications counted per step against ``n_x``, log-log (Tables 4.3, 4.4), with the
    fitted slopes in the legend."""
    return _burden_panel(timing, slopes, "counted_per_step", "multiplications per step "
                         "(counted)", "multiplications")


@_one_at_a_time
def burden_timing(timing, slopes) -> Figure:
    """Wall time per step against ``n_x`` on the machine that ran it, log-log, with the
    fitted slopes in the legend."""
    return _burden_panel(timing, slopes, "seconds_per_step", "wall time per step (this "
                         "machine)", "seconds")


def _burden_panel(timing, slopes, column: str, title: str, label: str) -> Figure:
    fig, ax = subplots(1, 1, figsize=(6.0, 4.5))
    for est, part in timing.groupby("estimator", sort=False):
        fit = slopes[slopes["estimator"] == est]["slope"]
        ax.loglog(part["n_x"], part[column], "o-",
                  label=f"{est} (slope {fit.iloc[0] if len(fit) else float('nan'):.2f})")
    ax.set_title(title)
    ax.set_xlabel("n_x (states)")
    ax.set_ylabel(label)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, which="both", lw=0.3)
    _tight_layout(fig)
    return fig


@_one_at_a_time
def estimates_clipped(trace: dict, title: str) -> Figure:
    """Input (a) and output like :func:`estimates` (Figs 4.3-4.7): (b) the whole record on
    an axis that spans the estimates (one that runs away is drawn until it leaves and named
    with the time it left), (c) the same record held to the actual signal's range, (d) each
    estimate's error. Legends outside the data."""
    fig, axes = subplots(4, 1, figsize=(10.0, 11.0), sharex=True)
    t_ms = trace["t"] * 1e3
    _input_panel(axes[0], trace, t_ms, title)
    _output_panels(axes[1:], trace, t_ms, slice(None), "whole record", "output v_D [V]")
    for ax in axes:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    _tight_layout(fig)
    return fig


@_one_at_a_time
def field_slices(data: dict, title: str) -> Figure:
    """|E| (top) and |H| (bottom) in a plane, one panel per entry of ``data["labels"]``
    (default: truth, filter, RLS baseline, the filter's error), one shared logarithmic
    colour scale per row (Chapter 5)."""
    from matplotlib.colors import LogNorm

    labels = tuple(data.get("labels", ("truth", "KF", "RLS", "KF error")))
    fig, axes = subplots(2, 4, figsize=(14.0, 7.0), sharex=True, sharey=True)
    for row, field in enumerate(("E", "H")):
        truth = data[f"{field}|truth"]
        top = float(np.nanmax(truth))
        norm = LogNorm(vmin=top * 1e-3, vmax=top)
        for col, label in enumerate(labels):
            ax = axes[row, col]
            values = np.clip(data[f"{field}|{label}"], top * 1e-3, None)
            image = ax.imshow(values.T, origin="lower", extent=data["extent"], norm=norm,
                              cmap="viridis")
            ax.set_title(f"|{field}| {label}", fontsize=9)
            if row == 1:
                ax.set_xlabel("x [wavelengths]")
            if col == 0:
                ax.set_ylabel("z [wavelengths]")
        fig.colorbar(image, ax=axes[row, :], shrink=0.8, label=f"|{field}| (normalised)")
    fig.suptitle(title, fontsize=10)
    return fig


@_one_at_a_time
def ensemble_rank(health) -> Figure:
    """The ensembles' effective rank over the record, per filter and scenario (lowest over
    runs and noise rows), with the NIS per reading on a second panel (Chapter 5)."""
    fig, (top, bottom) = subplots(2, 1, figsize=(8.0, 6.0), sharex=True)
    for (scenario, name), g in health.groupby(["scenario", "estimator"], sort=False):
        by_step = g.groupby("time", sort=True)
        top.plot(by_step["effective_rank_min"].min(), lw=1.0, label=f"{name}, {scenario}")
        bottom.plot(by_step["nis"].mean(), lw=1.0, label=f"{name}, {scenario}")
    top.set_ylabel("effective rank")
    bottom.set_ylabel("NIS per reading")
    bottom.set_yscale("log")
    bottom.axhline(1.0, color="k", lw=0.5)
    bottom.set_xlabel("t [periods]")
    top.legend(fontsize=8)
    top.set_title("ensemble rank (singular values above 1e-6 of the largest) and NIS")
    _tight_layout(fig)
    return fig


@_one_at_a_time
def field_study(df, setting: str, estimators) -> Figure:
    """Relative RMSE (real part) against the studied setting's value: one panel per zone
    and component, one line per estimator and scenario (Chapter 5 studies)."""
    real = df[df["part"] == "real"]
    zones = list(dict.fromkeys(real["zone"]))
    comps = list(dict.fromkeys(real["field_component"]))
    fig, axes = subplots(len(zones), len(comps), figsize=(4.0 * len(comps),
                                                              3.2 * len(zones)),
                             squeeze=False, sharex=True)
    styles = ("-", "--", ":", "-.")
    for i, zone in enumerate(zones):
        for j, comp in enumerate(comps):
            ax = axes[i, j]
            cell = real[(real["zone"] == zone) & (real["field_component"] == comp)]
            for k, name in enumerate(estimators):
                for scenario, g in cell[cell["estimator"] == name].groupby("scenario",
                                                                          sort=False):
                    g = g.sort_values("value")
                    ax.plot(g["value"], g["relative"], styles[k % len(styles)], marker="o",
                            ms=3, lw=1.0, label=f"{name} ({scenario})")
            beta = cell["beta_r"].iloc[0] if len(cell) else ""
            ax.set_title(f"{zone} (beta r {beta}): {comp}", fontsize=9)
            ax.set_yscale("log")
            ax.grid(True, lw=0.3)
            if i == len(zones) - 1:
                ax.set_xlabel(setting)
            if j == 0:
                ax.set_ylabel("RMSE / field RMS")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"field filter against {setting}", fontsize=10)
    _tight_layout(fig)
    return fig


@_one_at_a_time
def relative_error_curves(w_over_pi, curves: dict) -> Figure:
    """RE in dB against ``w / pi`` for several orders (the FIR differentiator paper's
    Fig 3); RE -> -inf at ``pi``, so the axis stops at -160 dB."""
    fig, ax = subplots(figsize=(8.0, 5.0))
    for n, re in curves.items():
        ax.plot(w_over_pi, np.maximum(re, -160.0), lw=1.0, label=f"n = {n} (N2 = {2 * n})")
    ax.set_ylim(-160, 10)
    ax.set_xlabel("w / pi")
    ax.set_ylabel("relative error [dB]")
    ax.set_title("maximally linear FIR differentiators: relative error (Fig 3)")
    ax.grid(True, lw=0.3)
    ax.legend(loc="lower left", fontsize=8)
    _tight_layout(fig)
    return fig


@_one_at_a_time
def differentiator_response(f_hz, curves: dict) -> Figure:
    """Magnitude and phase of optimum differentiators against the ideal ``s``."""
    fig, (ax_m, ax_p) = subplots(2, 1, figsize=(8.0, 6.0), sharex=True)
    s = 2 * np.pi * np.asarray(f_hz)
    ax_m.loglog(f_hz, s, "k--", lw=1.0, label="ideal |s|")
    ax_p.semilogx(f_hz, np.full_like(s, 90.0), "k--", lw=1.0, label="ideal")
    for label, H in curves.items():
        ax_m.loglog(f_hz, np.abs(H), lw=1.2, label=label)
        ax_p.semilogx(f_hz, np.degrees(np.angle(H)), lw=1.2, label=label)
    ax_m.set_ylabel("|H| [1/s]")
    ax_m.set_title("optimum (Kalman) differentiator against the ideal differentiator")
    ax_m.legend(fontsize=8, loc="upper left")
    ax_p.set_ylabel("phase [deg]")
    ax_p.set_xlabel("frequency [Hz]")
    ax_m.grid(True, which="both", lw=0.3)
    ax_p.grid(True, which="both", lw=0.3)
    _tight_layout(fig)
    return fig


@_one_at_a_time
def noisy_signal(t, clean: np.ndarray, noisy: np.ndarray, title: str) -> Figure:
    """A noisy record and the signal in it (the passive-network paper's Figs 4 and 6)."""
    fig, ax = subplots(figsize=(8.0, 3.2))
    ax.plot(t, noisy, lw=0.8, color="0.55", label="x + N (measured)")
    ax.plot(t, clean, lw=1.4, color="C0", label="x")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("signal")
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(True, lw=0.3)
    _tight_layout(fig)
    return fig


DIVERGED_PLOT = 1e100
"""A curve is drawn as diverged (and stops) where it is not finite or exceeds this: a log
axis cannot span values near the float limit."""


@_one_at_a_time
def absolute_errors(t, data: dict, title: str) -> Figure:
    """Absolute estimation error against time, one panel per reading (the passive-network
    paper's Figs 5 and 7), log scale."""
    fig, axes = subplots(len(data), 1, figsize=(8.0, 2.6 * len(data)), sharex=True,
                             squeeze=False)
    for ax, (reading, curves) in zip(axes[:, 0], data.items(), strict=True):
        for name, err in curves.items():
            with np.errstate(invalid="ignore"):
                finite = np.isfinite(err) & (np.abs(err) < DIVERGED_PLOT)
            label = name if finite.all() else f"{name} (diverged at t = {t[~finite][0]:g})"
            ax.semilogy(t, np.where(finite, np.clip(err, 1e-8, None), np.nan), lw=1.0,
                        label=label)
        ax.set_title(f"{reading}, {title} (run 1)", fontsize=9)
        ax.set_ylabel("|error|")
        ax.legend(fontsize=8, loc="upper right")
        ax.grid(True, which="both", lw=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    _tight_layout(fig)
    return fig


@_one_at_a_time
def image_panels(images: dict, title: str) -> Figure:
    """Grey-scale panels on the 0-255 scale, two rows (the original, the noisy and the
    restored images)."""
    n = len(images)
    cols = (n + 1) // 2
    fig, axes = subplots(2, cols, figsize=(3.2 * cols, 7.2), squeeze=False)
    for ax, (name, img) in zip(axes.ravel(), images.items(), strict=False):
        ax.imshow(np.clip(img, 0, 255), cmap="gray", vmin=0, vmax=255,
                  interpolation="nearest")
        ax.set_title(name, fontsize=9)
    for ax in axes.ravel():
        ax.set_axis_off()
    fig.suptitle(title, fontsize=10)
    _tight_layout(fig)
    return fig


@_one_at_a_time
def pixel_series(pixels, series: dict, ylabel: str, title: str) -> Figure:
    """Quantities along a row of pixels, one line each (the 2-D Kalman paper's Figs 5-7)."""
    fig, ax = subplots(figsize=(8.0, 3.6))
    for name, values in series.items():
        ax.plot(pixels, values, lw=1.2, marker=".", ms=3, label=name)
    ax.set_xlabel("pixel")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.grid(True, lw=0.3)
    _tight_layout(fig)
    return fig
