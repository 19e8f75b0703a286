"""Figures (matplotlib, Agg only). Each function takes figure data and returns a Figure."""

from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure


class _Pyplot:
    """``matplotlib.pyplot`` on the Agg backend, imported at the first figure: a command that
    draws nothing (``estim validate``, ``estim table``) does not pay matplotlib's import."""

    def __getattr__(self, name: str):
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot

        return getattr(matplotlib.pyplot, name)


plt = _Pyplot()

SIZE = (8.0, 6.0)
LINESTYLES = ("-", "--", "-.", ":")
"""Estimates that coincide (an EKF and a UKF on a near-linear model) stay distinguishable."""
DPI = 100


def _clipped(ax, t, y, lo: float, hi: float, label: str, **style) -> None:
    """Draw ``y`` until it first leaves ``[lo, hi]`` or stops being finite, and say so in its
    label (a diverged filter is named, not hidden)."""
    with np.errstate(invalid="ignore"):
        outside = ~np.isfinite(y) | (y < lo) | (y > hi)
    if outside.any():
        k = int(np.argmax(outside))
        label = f"{label} (leaves the axis at {t[k]:.3g} ms)" if k else f"{label} (off the axis)"
        y = np.where(np.arange(y.size) < k, y, np.nan)
    ax.plot(t, y, label=label, **style)


def estimates(trace: dict, title: str, period_s: float | None = None,
              window_periods: int = 3) -> Figure:
    """Input and output, actual, measured and every estimate (Figs 3.2-3.5): (a) the input
    and (b) the output over the whole record, and with ``period_s`` (c) the output over its
    last ``window_periods`` periods, where the waveform can be read. The output axis holds
    the actual signal's range; an estimate that leaves it is drawn until then and named.
    Legends sit outside the data."""
    zoom = period_s is not None and trace["t"][-1] - trace["t"][0] > 2 * window_periods * period_s
    rows = 3 if zoom else 2
    fig, axes = plt.subplots(rows, 1, figsize=(10.0, 3.0 * rows))
    t_ms = trace["t"] * 1e3
    ax_in = axes[0]
    ax_in.plot(t_ms, trace["source"], lw=0.8, label="source (as applied)")
    ax_in.plot(t_ms, trace["clean"], lw=1.2, label="nominal input")
    ax_in.set_ylabel("v_in [V]")
    ax_in.set_xlabel("time [ms]")
    ax_in.set_title(f"(a) input - {title}", fontsize=10)
    actual = trace["actual"]
    span = float(np.ptp(actual)) or 1e-3
    lo, hi = float(actual.min()) - span, float(actual.max()) + span
    panels = [(axes[1], slice(None), "(b) estimated output, whole record (run 1)")]
    if zoom:
        start = int(np.searchsorted(trace["t"], trace["t"][-1] - window_periods * period_s))
        panels.append((axes[2], slice(start, None),
                       f"(c) the last {window_periods} periods"))
    for ax, part, heading in panels:
        ax.plot(t_ms[part], trace["z"][part], ".", ms=2, color="0.6", label="measurement")
        ax.plot(t_ms[part], actual[part], lw=1.6, color="k", label="actual")
        for i, (label, y) in enumerate(trace["y_hat"].items()):
            _clipped(ax, t_ms[part], y[part], lo, hi, label, lw=1.0,
                     ls=LINESTYLES[i % len(LINESTYLES)])
        ax.set_ylim(lo, hi)
        ax.set_xlabel("time [ms]")
        ax.set_ylabel("output [V]")
        ax.set_title(heading, fontsize=10)
    for ax in axes:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    return fig


def _series(trace: dict, key: str, ylabel: str, title: str) -> Figure:
    fig, ax = plt.subplots(figsize=(10.0, 4.5))
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
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(True, lw=0.3)
    fig.tight_layout()
    return fig


def running_rmse(trace: dict, title: str) -> Figure:
    """RMSE across the Monte Carlo runs that did not diverge, at each sample (Fig 3.6)."""
    return _series(trace, "running_rmse", "RMSE over runs [V]", title)


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


def perturbation(trace: dict, title: str) -> Figure:
    """Input (a); zeroth-order, zeroth + first-order and full nonlinear output (b); the
    first-order output beside the true nonlinear part ``full - zeroth`` (c), on one time
    axis (Figs 2.2, 2.4, 2.6, 2.8)."""
    fig, (ax_in, ax_out, ax_nl) = plt.subplots(3, 1, figsize=(10.0, 8.0), sharex=True)
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
    fig.tight_layout()
    return fig


def burden(timing, slopes) -> Figure:
    """Multiplications counted and wall time per step against ``n_x``, log-log (Tables 4.3,
    4.4), with the fitted slopes in the legend."""
    fig, (ax_c, ax_t) = plt.subplots(1, 2, figsize=(10.0, 4.5))
    for est, part in timing.groupby("estimator", sort=False):
        fit = slopes[slopes["estimator"] == est].set_index("quantity")["slope"]
        ax_c.loglog(part["n_x"], part["counted_per_step"], "o-",
                    label=f"{est} (slope {fit.get('counted', float('nan')):.2f})")
        ax_t.loglog(part["n_x"], part["seconds_per_step"], "o-",
                    label=f"{est} (slope {fit.get('seconds', float('nan')):.2f})")
    ax_c.set_title("(a) multiplications per step (counted)")
    ax_t.set_title("(b) wall time per step (this machine)")
    for ax, label in ((ax_c, "multiplications"), (ax_t, "seconds")):
        ax.set_xlabel("n_x (states)")
        ax.set_ylabel(label)
        ax.legend(fontsize=8, loc="upper left")
        ax.grid(True, which="both", lw=0.3)
    fig.tight_layout()
    return fig


def estimates_clipped(trace: dict, title: str) -> Figure:
    """Input (a) and output (b) like :func:`estimates`, with the output axis held to the
    actual signal's range: an estimate that leaves it (or breaks) is drawn until then and
    named in the legend with the time it left (Figs 4.3-4.7). Legend outside the data."""
    fig, (ax_in, ax_out) = plt.subplots(2, 1, figsize=(10.0, 6.0), sharex=True)
    t_ms = trace["t"] * 1e3
    ax_in.plot(t_ms, trace["source"], lw=0.8, label="source (as applied)")
    ax_in.plot(t_ms, trace["clean"], lw=1.2, label="nominal input")
    ax_in.set_ylabel("v_in [V]")
    ax_in.set_title(f"(a) input - {title}", fontsize=10)
    ax_in.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    actual = trace["actual"]
    span = float(np.ptp(actual)) or 1e-3
    lo, hi = float(actual.min()) - span, float(actual.max()) + span
    ax_out.plot(t_ms, trace["z"], ".", ms=2, color="0.6", label="measurement")
    ax_out.plot(t_ms, actual, lw=1.6, color="k", label="actual")
    for label, y in trace["y_hat"].items():
        outside = ~np.isfinite(y) | (y < lo) | (y > hi)
        if outside.any():
            k = int(np.argmax(outside))
            where = f"leaves the axis at {t_ms[k]:.3g} ms" if k else "off the axis"
            label = f"{label} ({where})"
            y = np.where(np.arange(y.size) < k, y, np.nan)
        ax_out.plot(t_ms, y, lw=1.0, label=label)
    ax_out.set_ylim(lo, hi)
    ax_out.set_xlabel("time [ms]")
    ax_out.set_ylabel("output v_D [V]")
    ax_out.set_title("(b) estimated output (run 1 of the batch)", fontsize=10)
    ax_out.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    return fig


def field_slices(data: dict, title: str) -> Figure:
    """|E| (top) and |H| (bottom) in a plane, one panel per entry of ``data["labels"]``
    (default: truth, filter, RLS baseline, the filter's error), one shared logarithmic
    colour scale per row (Chapter 5)."""
    from matplotlib.colors import LogNorm

    labels = tuple(data.get("labels", ("truth", "KF", "RLS", "KF error")))
    fig, axes = plt.subplots(2, 4, figsize=(14.0, 7.0), sharex=True, sharey=True)
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


def ensemble_rank(health) -> Figure:
    """The ensembles' effective rank over the record, per filter and scenario (lowest over
    runs and noise rows), with the NIS per reading on a second panel (Chapter 5)."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8.0, 6.0), sharex=True)
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
    fig.tight_layout()
    return fig


def field_study(df, setting: str, estimators) -> Figure:
    """Relative RMSE (real part) against the studied setting's value: one panel per zone
    and component, one line per estimator and scenario (Chapter 5 studies)."""
    real = df[df["part"] == "real"]
    zones = list(dict.fromkeys(real["zone"]))
    comps = list(dict.fromkeys(real["field_component"]))
    fig, axes = plt.subplots(len(zones), len(comps), figsize=(4.0 * len(comps),
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
    fig.tight_layout()
    return fig


def relative_error_curves(w_over_pi, curves: dict) -> Figure:
    """RE in dB against ``w / pi`` for several orders (the FIR differentiator paper's
    Fig 3); RE -> -inf at ``pi``, so the axis stops at -160 dB."""
    fig, ax = plt.subplots(figsize=(8.0, 5.0))
    for n, re in curves.items():
        ax.plot(w_over_pi, np.maximum(re, -160.0), lw=1.0, label=f"n = {n} (N2 = {2 * n})")
    ax.set_ylim(-160, 10)
    ax.set_xlabel("w / pi")
    ax.set_ylabel("relative error [dB]")
    ax.set_title("maximally linear FIR differentiators: relative error (Fig 3)")
    ax.grid(True, lw=0.3)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    return fig


def differentiator_response(f_hz, curves: dict) -> Figure:
    """Magnitude and phase of optimum differentiators against the ideal ``s``."""
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(8.0, 6.0), sharex=True)
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
    fig.tight_layout()
    return fig


def noisy_signal(t, clean: np.ndarray, noisy: np.ndarray, title: str) -> Figure:
    """A noisy record and the signal in it (the passive-network paper's Figs 4 and 6)."""
    fig, ax = plt.subplots(figsize=(8.0, 3.2))
    ax.plot(t, noisy, lw=0.8, color="0.55", label="x + N (measured)")
    ax.plot(t, clean, lw=1.4, color="C0", label="x")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("signal")
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(True, lw=0.3)
    fig.tight_layout()
    return fig


DIVERGED_PLOT = 1e100
"""A curve is drawn as diverged (and stops) where it is not finite or exceeds this: a log
axis cannot span values near the float limit."""


def absolute_errors(t, data: dict, title: str) -> Figure:
    """Absolute estimation error against time, one panel per reading (the passive-network
    paper's Figs 5 and 7), log scale."""
    fig, axes = plt.subplots(len(data), 1, figsize=(8.0, 2.6 * len(data)), sharex=True,
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
    fig.tight_layout()
    return fig


def image_panels(images: dict, title: str) -> Figure:
    """Grey-scale panels on the 0-255 scale, two rows (the original, the noisy and the
    restored images)."""
    n = len(images)
    cols = (n + 1) // 2
    fig, axes = plt.subplots(2, cols, figsize=(3.2 * cols, 7.2), squeeze=False)
    for ax, (name, img) in zip(axes.ravel(), images.items(), strict=False):
        ax.imshow(np.clip(img, 0, 255), cmap="gray", vmin=0, vmax=255,
                  interpolation="nearest")
        ax.set_title(name, fontsize=9)
    for ax in axes.ravel():
        ax.set_axis_off()
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def pixel_series(pixels, series: dict, ylabel: str, title: str) -> Figure:
    """Quantities along a row of pixels, one line each (the 2-D Kalman paper's Figs 5-7)."""
    fig, ax = plt.subplots(figsize=(8.0, 3.6))
    for name, values in series.items():
        ax.plot(pixels, values, lw=1.2, marker=".", ms=3, label=name)
    ax.set_xlabel("pixel")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.grid(True, lw=0.3)
    fig.tight_layout()
    return fig
