"""Large arrays served from the heap rather than fresh pages from the kernel.

glibc gives every allocation above its mmap threshold (at most 32 MB by default) pages of
its own and returns them when the array is freed; the next array of that size faults
every page in again, zeroed by the kernel. The field filter allocates and frees
ensemble-sized arrays (tens of MB) many times per step, and that page traffic was a quarter
of its wall time (measured on one N = 32 case: 17.3 s with 5.5 s in the kernel, 13.2 s with
1.7 s after this call). Raising the thresholds keeps freed memory in the process for the
next array. Elsewhere than glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_done = False


def reuse_freed_memory() -> None:
    """Raise glibc's mmap and trim thresholds to 1 GB and 2 GB (once per process)."""
    global _done
    if _done or not sys.platform.startswith("linux"):
        return
    _done = True
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt(_M_MMAP_THRESHOLD, 1 << 30)
        libc.mallopt(_M_TRIM_THRESHOLD, 1 << 31)
    except (OSError, AttributeError):
        pass
