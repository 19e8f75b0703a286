"""The 2-D Kalman paper's figures: image panels and quantities along a row of pixels."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from estim.experiments.shared.plots.style import drawn, subplots, tight_layout

if TYPE_CHECKING:
    from matplotlib.figure import Figure


@drawn
def image_panels(images: dict, title: str) -> Figure:
    """Grey-scale panels on the 0-255 scale, two rows (the original, the noisy and the
    restored images)."""
    n = len(images)
    cols = (n + 1) // 2
    fig, axes = subplots(2, cols, figsize=(3.2 * cols, 7.2), squeeze=False)
    for ax, (name, img) in zip(axes.ravel(), images.items(), strict=False):
        ax.imshow(np.clip(img, 0, 255), cmap="gray", vmin=0, vmax=255,
                  interpolation="nearest")
        ax.set_title(name)
    for ax in axes.ravel():
        ax.set_axis_off()
    fig.suptitle(title)
    tight_layout(fig)
    return fig


@drawn
def pixel_series(pixels, series: dict, ylabel: str, title: str) -> Figure:
    """Quantities along a row of pixels, one line each (the 2-D Kalman paper's Figs 5-7)."""
    fig, ax = subplots(figsize=(8.0, 3.6))
    for name, values in series.items():
        ax.plot(pixels, values, label=name)
    ax.set_xlabel("pixel along the row")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5))
    tight_layout(fig)
    return fig

