"""How far another machine's arithmetic moves the stored tables (docs/checking.md).

Run from the project folder: ``python docs/studies/arithmetic_spread.py [CONFIGS]`` (default:
every config of ``configs/`` and ``configs/netlist/``). For each arithmetic variant below it
runs the configs in a fresh process whose environment makes OpenBLAS take another CPU's
kernels (``OPENBLAS_CORETYPE``) and numpy leave out its AVX-512 loops
(``NPY_DISABLE_CPU_FEATURES``), which is what another x86-64 machine with the same package
versions changes; then it compares every numeric cell with ``results/`` and prints, per config
and column, the largest relative difference and whether the config's ``check.tolerances``
hold (the rule of ``estim check``).

A variant needs a CPU that has the instructions of the kernels it names (Haswell and Zen:
AVX2 and FMA; every x86-64 CPU of the last ten years). ``--avx512`` prints numpy's AVX-512
targets, the value ``.ci/run`` gives ``NPY_DISABLE_CPU_FEATURES``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from estim import api, store
from estim.config.registry import ANALYSES
from estim.engine import compare


def avx512_targets() -> str:
    """numpy's AVX-512 dispatch targets in this build (``X86_V4 AVX512_ICL ...``), for
    ``NPY_DISABLE_CPU_FEATURES``; their names change between numpy versions."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__
    except ImportError:                       # numpy 1.x
        from numpy.core._multiarray_umath import __cpu_dispatch__
    return " ".join(t for t in __cpu_dispatch__ if "AVX512" in t or t == "X86_V4")


VARIANTS = {
    "Zen kernels": {"OPENBLAS_CORETYPE": "Zen"},
    "Haswell kernels, numpy without AVX-512": {
        "OPENBLAS_CORETYPE": "Haswell", "NPY_DISABLE_CPU_FEATURES": avx512_targets()},
}
"""Arithmetic variants: environment settings read when numpy and OpenBLAS load."""


def spread(stored: pd.DataFrame, new: pd.DataFrame) -> dict[str, float]:
    """Largest relative difference ``|new - stored| / |stored|`` of each numeric column
    (``inf`` where a finite cell became non-finite or the reverse; 0 where all agree)."""
    out = {}
    for col in stored.columns:
        a, b = pd.to_numeric(new[col], errors="coerce"), pd.to_numeric(stored[col],
                                                                       errors="coerce")
        if b.isna().all() and a.isna().all():
            continue
        x, y = a.to_numpy(float), b.to_numpy(float)
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(same, 0.0, np.abs(x - y) / np.abs(y))
        out[col] = float(np.nanmax(np.where(np.isnan(rel), np.inf, rel)))
    return out


def _rtol(tol: dict) -> float | str:
    """A column's ``rtol`` where it is the only criterion; else how it is compared."""
    if tol.get("skip"):
        return "skipped"
    if tol.get("se") is not None or tol.get("binomial") is not None:
        return "statistical"
    return tol.get("rtol", 0.0)


def measure(configs: list[str], env: dict[str, str], jobs: int) -> list[dict]:
    """Run ``configs`` under ``env`` and compare their tables with results/."""
    rows = []
    with tempfile.TemporaryDirectory() as out:
        subprocess.run(["estim", "run", *configs, "--out", out, "--jobs", str(jobs)],
                       env={**os.environ, **env}, check=True, stdout=subprocess.DEVNULL)
        for config in configs:
            exp = api.experiment(config)
            tol, specs = exp.spec["check"]["tolerances"], ANALYSES[exp.analysis].TABLES
            for new_csv in sorted((Path(out) / exp.name).glob("*.csv")):
                stored = store.read_table(Path("results") / exp.name / new_csv.name,
                                       specs.get(new_csv.stem))
                new = store.read_table(new_csv)
                failing = {d["column"] for d in compare.compare_tables(stored, new, tol)}
                for col, rel in spread(stored, new).items():
                    if rel > 0 or col in failing:
                        rows.append({"config": exp.name, "table": new_csv.stem,
                                     "column": col, "largest relative difference": rel,
                                     "rtol": _rtol(tol.get(col, {})),
                                     "tolerances hold": col not in failing})
    return rows


def main(argv: list[str]) -> None:
    if argv == ["--avx512"]:      # for .ci/run
        print(avx512_targets())
        return
    configs = argv or sorted(str(p) for p in [*Path("configs").glob("*.yaml"),
                                              *Path("configs/netlist").glob("*.yaml")])
    jobs = len(os.sched_getaffinity(0))
    for name, env in VARIANTS.items():
        print(f"== {name}: {' '.join(f'{k}={v!r}' for k, v in env.items())}")
        rows = measure(configs, env, jobs)
        if not rows:
            print("every cell of every table equals results/ byte for byte\n")
            continue
        table = pd.DataFrame(rows)
        print(table.to_markdown(index=False, floatfmt=".2g"))
        finite = table[np.isfinite(table["largest relative difference"])]
        worst = finite.groupby("config")["largest relative difference"].max()
        print("\nlargest finite relative difference per config:")
        print(worst.to_frame().to_markdown(floatfmt=".2g"))
        moved = sorted(set(table["config"]))
        print(f"\n{len(moved)} of {len(configs)} configs moved: {', '.join(moved)}; "
              f"tolerances fail in {int((~table['tolerances hold']).sum())} columns\n")


if __name__ == "__main__":
    main(sys.argv[1:])
