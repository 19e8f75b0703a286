"""Every benchmark in one run:  pip install '.[bench]' && python bench/all.py

``python bench/all.py --reproduce --baseline COMMIT_OR_FOLDER [CONFIGS]`` instead runs every
default config on this checkout and on the baseline and prints their CPU-seconds side by side
(:mod:`bench_reproduce`)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_expansion  # noqa: E402
import bench_field  # noqa: E402
import bench_filters  # noqa: E402
import bench_image  # noqa: E402
import bench_letkf_sqrt  # noqa: E402
import bench_newton  # noqa: E402
import bench_reproduce  # noqa: E402
import bench_simulate  # noqa: E402
import peers  # noqa: E402

if __name__ == "__main__":
    if "--reproduce" in sys.argv:
        bench_reproduce.main([a for a in sys.argv[1:] if a != "--reproduce"])
        sys.exit(0)
    for name, module in (("Chapter 3 actual signal", bench_simulate),
                         ("Chapter 2 expansion", bench_expansion),
                         ("filters", bench_filters),
                         ("EKF beside its peers", peers),
                         ("Newton iteration", bench_newton),
                         ("Chapter 5 field", bench_field),
                         ("LETKF square root", bench_letkf_sqrt),
                         ("image filters", bench_image)):
        print(f"== {name}")
        sys.argv = sys.argv[:1]
        module.main()
        print()
