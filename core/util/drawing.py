"""The lock every figure is built and rendered under."""

from __future__ import annotations

import threading

DRAWING = threading.RLock()
"""Held while a figure is built or rendered: matplotlib is not thread-safe (its mathtext
parser is one shared object), and :mod:`estim.engine.scheduler` runs several configs' drivers in
threads. :func:`estim.store.io.write_figure` renders under it too."""
