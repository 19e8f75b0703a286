"""Curves against a parameter or a frequency: the Chapter 4 burden, the differentiators'
responses and the passive-network paper's records."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from estim.experiments.shared.plots.style import drawn, subplots, tight_layout

if TYPE_CHECKING:
    from matplotlib.figure import Figure


@drawn
def burden(timing, slopes) -> Figure:
    """Multiplications counted per step against ``n_x``, log-log (Tables 4.3, 4.4), with the
    fitted slopes in the legend."""
    return _burden_panel(timing, slopes, "counted_per_step", "multiplications per step "
                         "(counted)", "multiplications per step")


@drawn
def burden_timing(timing, slopes) -> Figure:
    """Wall time per step against ``n_x`` on the machine that ran it, log-log, with the
    fitted slopes in the legend."""
    return _burden_panel(timing, slopes, "seconds_per_step", "wall time per step (this "
                         "machine)", "wall time per step [s]")


def _burden_panel(timing, slopes, column: str, title: str, label: str) -> Figure:
    fig, ax = subplots(1, 1, figsize=(6.0, 4.5))
    drawn_: dict = {}
    for est, part in timing.groupby("estimator", sort=False):
        fit = slopes[slopes["estimator"] == est]["slope"]
        xy = (part["n_x"].to_numpy(), part[column].to_numpy())
        same = next((name for name, other in drawn_.items() if all(
            np.array_equal(a, b) for a, b in zip(xy, other, strict=True))), None)
        drawn_[est] = xy
        ax.loglog(*xy, label=f"{est} (slope {fit.iloc[0] if len(fit) else float('nan'):.2f})"
                  + (f"; the same points as {same}" if same else ""))
    ax.set_title(title)
    ax.set_xlabel(r"states $n_x$")
    ax.set_ylabel(label)
    ax.legend(loc="upper left")
    ax.grid(True, which="both")
    tight_layout(fig)
    return fig


@drawn
def relative_error_curves(w_over_pi, curves: dict) -> Figure:
    """RE in dB against ``ω/π`` for several orders (the FIR differentiator paper's
    Fig 3); RE -> -inf at ``pi``, so the axis stops at -160 dB."""
    fig, ax = subplots(figsize=(8.0, 5.0))
    for n, re in curves.items():
        ax.plot(w_over_pi, np.maximum(re, -160.0), label=f"$n$ = {n} ($N_2$ = {2 * n})")
    ax.set_ylim(-160, 10)
    ax.set_xlabel(r"normalised frequency $\omega/\pi$")
    ax.set_ylabel("relative error [dB]")
    ax.set_title("maximally linear FIR differentiators: relative error (Fig 3)")
    ax.legend(loc="lower left")
    tight_layout(fig)
    return fig


@drawn
def differentiator_response(f_hz, curves: dict) -> Figure:
    """Magnitude and phase of optimum differentiators against the ideal ``s``."""
    fig, (ax_m, ax_p) = subplots(2, 1, figsize=(8.0, 6.0), sharex=True)
    s = 2 * np.pi * np.asarray(f_hz)
    ax_m.loglog(f_hz, s, color="k", ls="--", marker="", label="ideal $|s|$")
    ax_p.semilogx(f_hz, np.full_like(s, 90.0), color="k", ls="--", marker="", label="ideal")
    for label, H in curves.items():
        ax_m.loglog(f_hz, np.abs(H), label=label)
        ax_p.semilogx(f_hz, np.degrees(np.angle(H)), label=label)
    ax_m.set_ylabel("magnitude $|H|$ [1/s]")
    ax_m.set_title("optimum (Kalman) differentiator against the ideal differentiator")
    ax_m.legend(loc="upper left")
    ax_p.set_ylabel("phase [°]")
    ax_p.set_xlabel("frequency [Hz]")
    ax_m.grid(True, which="both")
    ax_p.grid(True, which="both")
    tight_layout(fig)
    return fig


@drawn
def noisy_signal(t, clean: np.ndarray, noisy: np.ndarray, title: str) -> Figure:
    """A noisy record and the signal in it (the passive-network paper's Figs 4 and 6)."""
    fig, ax = subplots(figsize=(8.0, 3.2))
    ax.plot(t, noisy, lw=0.8, color="0.55", ls="-", marker="", label="$x + N$ (measured)")
    ax.plot(t, clean, lw=1.4, color="C0", ls="-", marker="", label="$x$")
    ax.set_title(title)
    ax.set_xlabel("time $t$ [s]")
    ax.set_ylabel("signal $x$")
    ax.legend(loc="upper right")
    tight_layout(fig)
    return fig


DIVERGED_PLOT = 1e100
"""A curve is drawn as diverged (and stops) where it is not finite or exceeds this: a log
axis cannot span values near the float limit."""


@drawn
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
            ax.semilogy(t, np.where(finite, np.clip(err, 1e-8, None), np.nan), label=label)
        ax.set_title(f"{reading}, {title} (run 1)")
        ax.set_ylabel("absolute error")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
        ax.grid(True, which="both")
    axes[-1, 0].set_xlabel("time $t$ [s]")
    tight_layout(fig)
    return fig

