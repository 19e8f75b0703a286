"""Chapter 5's ensemble filter against DAPPER's ETKF (``EnKF('Sqrt')``), the reference
implementation the field filter takes its conventions from (one member per row, symmetric
square-root transform).

DAPPER pins ``tabulate~=0.8`` and estim needs ``tabulate>=0.9`` (pandas' Markdown tables), so
the two cannot share one resolved environment. Run it in a venv of its own, as CI does::

    python -m venv .venv-dapper && . .venv-dapper/bin/activate
    pip install . && pip install 'dapper==1.7.1'     # pip warns about tabulate: expected
    python bench/crosscheck_dapper.py                # --full: the default config's cycle

Three checks, each failing the script (exit 1) beyond its stated tolerance:

1. One analysis on random ensembles, for both of DAPPER's branches (members > state size:
   its SVD form; members < state size: its eigen form): estim's ``etkf.analysis`` and DAPPER's
   ``EnKF_analysis(..., upd_a='Sqrt')`` give the same ensemble, member by member.
2. Inflation: estim inflates the forecast covariance inside the analysis by ``inflation``;
   DAPPER's ``infl`` scales the anomalies after it. The same thing through DAPPER is its
   analysis of a forecast ensemble whose anomalies were scaled by ``sqrt(inflation)``.
3. The whole ``dipole_field`` cycle (simulation, sensors, analysis every step, errors, RLS),
   run twice from the same seeds: once with estim's analysis, once with DAPPER's in its
   place. Every table cell must agree. Default: a reduced grid (N = 16, 1 run, 1 noise row,
   both scenarios); ``--full``: the stored config itself (about five minutes).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ANALYSIS_RTOL = 1e-9        # one analysis: rounding of two eigen-solvers of the same matrix
CYCLE_RTOL = 1e-7           # table cells after hundreds of cycled analyses


def dapper_analysis(E: np.ndarray, Y: np.ndarray, y: np.ndarray, R: np.ndarray,
                    inflation: float = 1.0) -> np.ndarray:
    """DAPPER's symmetric square-root ETKF with estim's call signature and inflation."""
    from dapper.da_methods.ensemble import EnKF_analysis
    from dapper.tools.matrices import CovMat
    from dapper.tools.randvars import GaussRV

    if inflation != 1.0:
        root = np.sqrt(inflation)
        E = E.mean(axis=0) + root * (E - E.mean(axis=0))
        Y = Y.mean(axis=0) + root * (Y - Y.mean(axis=0))
    noise = GaussRV(C=CovMat(np.asarray(R, float), "diag"))
    return EnKF_analysis(E, Y, noise, y, "Sqrt")


def _largest_relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def check_single_analyses() -> list[tuple[str, float, float]]:
    from estim.fields import etkf

    rng = np.random.default_rng(20191)
    out = []
    for label, m, n, p, infl in (("members > states (DAPPER's SVD form)", 40, 12, 7, 1.0),
                                 ("members < states (DAPPER's eigen form)", 20, 300, 45, 1.0),
                                 ("inflation 1.3", 20, 300, 45, 1.3),
                                 ("inflation 1.3, members > states", 40, 12, 7, 1.3)):
        E = rng.standard_normal((m, n)) @ rng.standard_normal((n, n)) + rng.standard_normal(n)
        H = rng.standard_normal((p, n))
        R = rng.uniform(0.1, 2.0, p)
        y = H @ rng.standard_normal(n) + np.sqrt(R) * rng.standard_normal(p)
        ours = etkf.analysis(E, E @ H.T, y, R, infl)
        theirs = dapper_analysis(E, E @ H.T, y, R, infl)
        out.append((label, _largest_relative(ours, theirs), ANALYSIS_RTOL))
    return out


def _reduced(spec: dict) -> dict:
    spec = dict(spec)
    spec.update(grid={**spec["grid"], "n": 16, "length": 3.0},
                time={"spinup_periods": 3, "periods": 1},
                zones=[{"name": "near", "r": [0.3, 0.55]}, {"name": "far", "r": [0.9, 1.3]}],
                monte_carlo={**spec["monte_carlo"], "runs": 1})
    spec["sensors"] = {**spec["sensors"], "r": [0.3, 1.3], "fraction": 0.05}
    spec["filter"] = {**spec["filter"], "members": 20}
    spec["noise"] = {**spec["noise"], "source_levels": spec["noise"]["source_levels"][:1]}
    return spec


def check_cycle(full: bool) -> list[tuple[str, float, float]]:
    import pandas as pd
    import yaml

    from estim.analyses import dipole_field
    from estim.config import parse_data
    from estim.fields import etkf

    root = Path(__file__).resolve().parents[1]
    spec = yaml.safe_load((root / "configs" / "dipole_field.yaml").read_text())
    spec.pop("check", None)
    if not full:
        spec = _reduced(spec)
    exp = parse_data(spec, "dipole_field.yaml", "dipole_field")
    keys = [(s, r, lv) for s in range(len(spec["scenarios"]))
            for r in range(len(spec["noise"]["readings"]))
            for lv in range(len(spec["noise"]["source_levels"]))]
    ours, theirs = [], []
    original = etkf.analysis
    try:
        for key in keys:
            ours += dipole_field.run_point(exp, key)[0]
            etkf.analysis = dapper_analysis
            theirs += dipole_field.run_point(exp, key)[0]
            etkf.analysis = original
    finally:
        etkf.analysis = original
    a, b = pd.DataFrame(ours), pd.DataFrame(theirs)
    kf = a["estimator"] == dipole_field.KF
    numeric = [c for c in a.columns if a[c].dtype.kind == "f"]
    cells = a.loc[kf, numeric].to_numpy(float), b.loc[kf, numeric].to_numpy(float)
    finite = np.isfinite(cells[1])
    rel = np.abs(cells[0] - cells[1])[finite] / np.maximum(np.abs(cells[1][finite]), 1e-300)
    others = a.loc[~kf, numeric].to_numpy(float), b.loc[~kf, numeric].to_numpy(float)
    same_baselines = bool(np.array_equal(others[0], others[1], equal_nan=True))
    label = (f"dipole_field cycle ({'stored config' if full else 'N = 16'}, "
             f"{int(kf.sum())} filter rows x {len(numeric)} columns)")
    return [(label, float(rel.max()), CYCLE_RTOL),
            ("baselines untouched by the swap", 0.0 if same_baselines else np.inf, 0.0)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true",
                        help="cycle the stored dipole_field config (about five minutes)")
    args = parser.parse_args()
    try:
        import dapper  # noqa: F401
    except ImportError:
        print("DAPPER is not installed here: see this script's docstring", file=sys.stderr)
        return 2
    from importlib.metadata import version

    print(f"DAPPER {version('dapper')}, numpy {np.__version__}")
    failed = False
    for label, value, tol in check_single_analyses() + check_cycle(args.full):
        ok = value <= tol
        failed |= not ok
        print(f"{'ok  ' if ok else 'FAIL'} {label}: largest relative difference "
              f"{value:.2e} (tolerance {tol:.0e})")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
