"""The one look of every figure: a matplotlib style (sizes, dpi, a colour, line-style and
marker cycle), the figure factory, and the finishing every figure gets before it is
returned (markers spread along dense lines, the axis labels recorded for the metadata)."""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

from estim.util.drawing import DRAWING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

F = TypeVar("F", bound=Callable)

DPI = 160
"""Dots per inch of a stored PNG: a 10-inch-wide figure is 1,600 pixels, sharp in a paper
column and on a high-density screen."""

COLOURS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000",
           "#F0E442")
"""Okabe and Ito's palette, told apart with every common colour-vision deficiency."""
LINESTYLES = ("-", "--", "-.", ":")
MARKERS = ("o", "s", "^", "D", "v", "x", "+", "P")
"""With :data:`COLOURS` and :data:`LINESTYLES`, the cycle every series takes: a series that
coincides with another (an EKF under a UKF on a near-linear model) still shows its own
markers, hollow and placed at other points along the line (:func:`finish`)."""


def series_style(i: int) -> dict:
    """The colour, line style and marker of the ``i``-th series, as the cycle gives them:
    for a figure that draws the same series on several panels, some of which leave one
    out."""
    return {"color": COLOURS[i % len(COLOURS)], "ls": LINESTYLES[i % len(LINESTYLES)],
            "marker": MARKERS[i % len(MARKERS)]}


def style() -> dict:
    """The rcParams every figure is drawn and saved under."""
    from cycler import cycler

    n = len(COLOURS)
    return {
        "figure.dpi": DPI, "savefig.dpi": DPI,
        "font.size": 9.0, "axes.titlesize": 9.0, "axes.labelsize": 9.0,
        "legend.fontsize": 8.0, "xtick.labelsize": 8.0, "ytick.labelsize": 8.0,
        "axes.grid": True, "grid.linewidth": 0.3, "grid.alpha": 0.7,
        "axes.spines.top": False, "axes.spines.right": False,
        "axes.prop_cycle": cycler(color=COLOURS, linestyle=[LINESTYLES[i % 4] for i in range(n)],
                                  marker=MARKERS),
        "lines.linewidth": 1.1, "lines.markersize": 4.0, "markers.fillstyle": "none",
        "legend.frameon": False,
        "image.cmap": "viridis",
    }


MARKS_PER_LINE = 12
"""Markers along a line of many points: about this many, each series' set offset from the
others' so that coinciding series show every marker."""


def finish(fig: Figure) -> Figure:
    """Spread the markers of every dense line (at most :data:`MARKS_PER_LINE`, each series
    starting at its own offset) and record each axes' labels in the figure's ``Description``
    (:func:`described`), which :func:`estim.store.writing.write_figure` stores in a PNG's
    metadata."""
    for ax in fig.axes:
        lines = [ln for ln in ax.get_lines() if ln.get_marker() not in ("None", "", None, " ")]
        for k, line in enumerate(lines):
            n = len(line.get_xdata())
            if n > 2 * MARKS_PER_LINE and line.get_linestyle() not in ("None", "", " "):
                step = max(1, n // MARKS_PER_LINE)
                line.set_markevery((k * step // max(2, len(lines)) % step, step))
    fig.estim_description = described(fig)
    return fig


def described(fig: Figure) -> str:
    """Each drawn axes' title and x and y labels (a label shared with a sibling axes
    counts), as JSON: what a reader of the stored file can check without looking at it."""
    out = []
    for ax in fig.axes:
        if not ax.axison or hasattr(ax, "_colorbar"):
            continue

        out.append({"title": ax.get_title(), "x": _label(ax, "x"), "y": _label(ax, "y")})
    return json.dumps({"suptitle": fig._suptitle.get_text() if fig._suptitle else "",
                       "axes": out}, ensure_ascii=False)


def _label(ax, axis: str) -> str:
    """The axes' own label on ``axis``, else one of the axes it shares that axis with."""
    shared = ax.get_shared_x_axes() if axis == "x" else ax.get_shared_y_axes()
    for a in [ax, *shared.get_siblings(ax)]:
        text = a.get_xlabel() if axis == "x" else a.get_ylabel()
        if text:
            return text
    return ""


def drawn(draw: F) -> F:
    """``draw`` under :data:`DRAWING` (matplotlib is not thread-safe) and :func:`style`,
    its figure :func:`finish`-ed."""
    @functools.wraps(draw)
    def wrapper(*args, **kwargs):
        with DRAWING:       # also the import: two threads importing matplotlib at once fail
            import matplotlib

            with matplotlib.rc_context(style()):
                return finish(draw(*args, **kwargs))
    return wrapper  # type: ignore[return-value]


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


def tight_layout(fig: Figure) -> None:
    """``fig.tight_layout()``, done once: matplotlib keeps a placeholder layout engine after
    it, and a figure with any layout engine is drawn an extra time when saved (to lay it
    out again), a third of the time of saving it."""
    fig.tight_layout()
    fig.set_layout_engine(None)
