"""Every stored figure carries its axes' titles and labels in its metadata
(:func:`estim.experiments.shared.plots.style.described`): this walks them, so a figure with an
unlabelled axis, a config key path for a label or a unit in plain text fails here."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from estim.experiments.shared import plots
from estim.store.writing import write_figure

ROOT = Path(__file__).resolve().parents[1]

KEY_PATH = re.compile(r"\b[a-z_]+(?:\[\d+\])?\.[a-z_]+\b")
"""A config key path (``sensors.fraction``, ``model.params``)."""
PLAIN_UNITS = {"um": re.compile(r"\d\s*um\b"), "V^2": re.compile(r"\^2"),
               "beta r": re.compile(r"(?<!\\)\bbeta r\b"), "w / pi": re.compile(r"\bw / pi\b"),
               "sigma": re.compile(r"(?<![\\$])\bsigma\b"), "deg": re.compile(r"\[deg\]")}
"""Units and symbols written as plain text where mathtext or Unicode says them."""


def problems(description: str) -> list[str]:
    """What is wrong with one figure's recorded description."""
    data = json.loads(description)
    found = []
    texts = [data["suptitle"]]
    if not data["axes"]:
        return found
    for i, ax in enumerate(data["axes"]):
        texts += [ax["title"], ax["x"], ax["y"]]
        if not ax["x"] or not ax["y"]:
            found.append(f"axes {i} ({ax['title']!r}) has no {'x' if not ax['x'] else 'y'} label")
    for text in texts:
        if KEY_PATH.search(text):
            found.append(f"a config key path in {text!r}")
        found += [f"{name!r} in plain text in {text!r}" for name, rx in PLAIN_UNITS.items()
                  if rx.search(text)]
    return found


def stored_figures() -> list[Path]:
    return sorted(ROOT.glob("results/*/figures/*.png"))


def test_the_stored_results_have_figures():
    assert len(stored_figures()) >= 50


@pytest.mark.parametrize("path", stored_figures(), ids=lambda p: f"{p.parent.parent.name}/{p.name}")
def test_every_stored_figure_is_labelled_in_words(path):
    with Image.open(path) as image:
        description = image.text.get("Description")
        dpi = image.info.get("dpi", (0, 0))[0]
    assert description is not None, "no description in the PNG's metadata"
    assert problems(description) == []
    assert 150 <= round(dpi) <= 200


def test_the_check_finds_an_unlabelled_axis_and_a_key_path(tmp_path):
    """The walk above can fail: a figure drawn with a config key path for its x label and
    no y label is caught, and one in words passes."""
    t = np.linspace(0.0, 1.0, 50)

    def drawn(xlabel: str, ylabel: str) -> str:
        fig = plots.pixel_series(t, {"a": t}, ylabel, "a title")
        fig.axes[0].set_xlabel(xlabel)
        fig = plots.style.finish(fig)
        write_figure(fig, tmp_path / "f.png")
        with Image.open(tmp_path / "f.png") as image:
            return image.text["Description"]

    assert problems(drawn("sensors.fraction", "")) == [
        "axes 0 ('a title') has no y label", "a config key path in 'sensors.fraction'"]
    assert problems(drawn("fraction of grid points with a sensor", "RMSE [V]")) == []
    assert problems(drawn("width [um]", "W = 2 um")) == ["'um' in plain text in 'W = 2 um'"]
