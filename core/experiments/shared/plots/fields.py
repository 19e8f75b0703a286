"""The Chapter 5 field figures: slices of |E| and |H|, the ensembles' rank and NIS, and
the field filter's studies."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from estim.experiments.shared.plots.style import drawn, subplots, tight_layout

if TYPE_CHECKING:
    from matplotlib.figure import Figure


@drawn
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
            ax.set_title(f"${field}$ magnitude: {label}")
            if row == 1:
                ax.set_xlabel("$x$ [wavelengths]")
            if col == 0:
                ax.set_ylabel("$z$ [wavelengths]")
        fig.colorbar(image, ax=axes[row, :], shrink=0.8, label=f"${field}$ magnitude (normalised)")
    fig.suptitle(title)
    return fig


@drawn
def ensemble_rank(health) -> Figure:
    """The ensembles' effective rank over the record, per filter and scenario (lowest over
    runs and noise rows), with the NIS per reading on a second panel (Chapter 5)."""
    fig, (top, bottom) = subplots(2, 1, figsize=(8.0, 6.0), sharex=True)
    for (scenario, name), g in health.groupby(["scenario", "estimator"], sort=False):
        by_step = g.groupby("time", sort=True)
        top.plot(by_step["effective_rank_min"].min(), label=f"{name}, {scenario}")
        bottom.plot(by_step["nis"].mean(), label=f"{name}, {scenario}")
    top.set_ylabel("effective rank")
    bottom.set_ylabel("NIS per reading")
    bottom.set_yscale("log")
    bottom.axhline(1.0, color="k", lw=0.5)
    bottom.set_xlabel("time [periods]")
    top.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    top.set_title(r"ensemble rank (singular values above $10^{-6}$ of the largest) and NIS")
    tight_layout(fig)
    return fig


GREEK = {"theta", "phi"}


def component(name: str) -> str:
    """A field component's name in mathtext: ``E_theta`` as :math:`E_\\theta`."""
    field, _, axis = name.partition("_")
    if not axis:
        return name
    return f"${field}_{{\\{axis}}}$" if axis in GREEK else f"${field}_{{{axis}}}$"


@drawn
def field_study(df, setting: str, estimators) -> Figure:
    """Relative RMSE (real part) against the studied setting's value (``setting``: its name
    in words, with its unit): one panel per zone and component, one line per estimator and
    scenario (Chapter 5 studies)."""
    real = df[df["part"] == "real"]
    zones = list(dict.fromkeys(real["zone"]))
    comps = list(dict.fromkeys(real["field_component"]))
    fig, axes = subplots(len(zones), len(comps), figsize=(4.0 * len(comps),
                                                              3.2 * len(zones)),
                             squeeze=False, sharex=True)
    for i, zone in enumerate(zones):
        for j, comp in enumerate(comps):
            ax = axes[i, j]
            cell = real[(real["zone"] == zone) & (real["field_component"] == comp)]
            for name in estimators:
                for scenario, g in cell[cell["estimator"] == name].groupby("scenario",
                                                                          sort=False):
                    g = g.sort_values("value")
                    ax.plot(g["value"], g["relative"], label=f"{name} ({scenario})")
            beta = cell["beta_r"].iloc[0] if len(cell) else ""
            ax.set_title(rf"{zone} ($\beta r$ = {beta}): {component(comp)}")
            ax.set_yscale("log")
            if i == len(zones) - 1:
                ax.set_xlabel(setting)
            ax.set_ylabel("RMSE / field RMS")
    axes[0, -1].legend(*axes[0, 0].get_legend_handles_labels(), loc="upper left",
                       bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(f"field filter against the {setting}")
    tight_layout(fig)
    return fig
