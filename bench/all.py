"""Every benchmark in one run:  pip install '.[bench]' && python bench/all.py"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_expansion  # noqa: E402
import bench_field  # noqa: E402
import bench_filters  # noqa: E402
import bench_image  # noqa: E402
import bench_simulate  # noqa: E402

if __name__ == "__main__":
    for name, module in (("Chapter 3 actual signal", bench_simulate),
                         ("Chapter 2 expansion", bench_expansion),
                         ("filters", bench_filters),
                         ("Chapter 5 field", bench_field),
                         ("image filters", bench_image)):
        print(f"== {name}")
        sys.argv = sys.argv[:1]
        module.main()
        print()
