"""The report's figures: each stored PNG shrunk for the page, its caption in words from the
figure's own description, and the figures a page need not draw twice."""

from __future__ import annotations

import io
import json
import re

WIDTH = 720
"""Widest embedded PNG, in pixels, unless ``full`` (the stored figures are 1,000-2,200 at
160 dpi; the page shows them at most 45em wide). With :data:`WEBP_QUALITY` and
:func:`alike`, this keeps the page of the shipped results under 3 MB."""
COLOURS = 64
"""Colours of an embedded palette PNG (line plots use a few dozen)."""
WEBP_QUALITY = 45
"""Quality of an embedded WebP (lossy; text stays legible at 720 pixels: 45 was looked at
on the MOSFET's four-panel figure, 8 % smaller than 55 over the shipped figures)."""
ALIKE = 0.004
"""Two figures of the same file name in two experiments whose 128-pixel grey thumbnails
differ by less than this on average (of the full scale) look the same (a circuit and its
netlist twin): the page draws the first and names the second."""


def shrink_png(data: bytes, width: int = WIDTH, colours: int = COLOURS) -> tuple[str, bytes]:
    """A stored PNG for the page: at most ``width`` pixels wide, as a PNG of ``colours``
    colours or a WebP of :data:`WEBP_QUALITY`, whichever is smaller; the original where
    neither is. Returns the media type and the bytes."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as image:
        image = image.convert("RGB")
        if image.width > width:
            image = image.resize((width, round(image.height * width / image.width)),
                                 Image.Resampling.LANCZOS)
        png, webp = io.BytesIO(), io.BytesIO()
        image.quantize(colours).save(png, format="PNG", optimize=True)
        image.save(webp, format="WEBP", quality=WEBP_QUALITY, method=6)
    return min((("image/png", data), ("image/png", png.getvalue()),
                ("image/webp", webp.getvalue())), key=lambda pair: len(pair[1]))


def caption(data: bytes) -> str:
    """A stored PNG's caption in words, from the description the figure carries
    (:func:`estim.experiments.shared.plots.style.described`): its title, else its first
    panel's title without the panel letter; empty where the file has none."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as image:
            described = json.loads(getattr(image, "text", {}).get("Description") or "{}")
    except (OSError, ValueError, SyntaxError):
        return ""
    if not isinstance(described, dict):
        return ""
    axes = described.get("axes") or [{}]
    first = axes[0].get("title", "") if isinstance(axes[0], dict) else ""
    text_ = str(described.get("suptitle") or first)
    return re.sub(r"^\([a-z]\) (input - )?", "", " ".join(text_.split()))


def _thumbnail(data: bytes):
    import numpy as np
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as image:
            grey = image.convert("L")
            small = grey.resize((128, max(1, round(128 * grey.height / grey.width))))
            return np.asarray(small, float) / 255.0
    except (OSError, ValueError, SyntaxError, ZeroDivisionError):
        return None


def alike(sections: list[tuple[str, list[tuple[str, bytes]]]]) -> dict[tuple[str, str], str]:
    """``{(experiment, figure name): earlier experiment}`` for each PNG that looks the same
    (:data:`ALIKE`) as the figure of the same name in an earlier experiment of
    ``sections`` (``(experiment, [(figure name, bytes)])`` in page order)."""
    import numpy as np

    seen: dict[str, list[tuple[str, object]]] = {}
    out = {}
    for experiment, figures in sections:
        for name, data in figures:
            if not name.endswith(".png"):
                continue
            thumb = _thumbnail(data)
            if thumb is None:
                continue
            match = next((other for other, t in seen.get(name, []) if t.shape == thumb.shape
                          and float(np.mean(np.abs(t - thumb))) < ALIKE), None)
            if match is not None:
                out[experiment, name] = match
            else:
                seen.setdefault(name, []).append((experiment, thumb))
    return out
