"""The LETKF's symmetric inverse square root: numpy's batched ``eigh`` (today's,
estim.fields.letkf.transforms) against the cheaper ways issue 46 names, at dipole_field's size.

    python bench/bench_letkf_sqrt.py [--cubes 512] [--members 50]

Each cube's ``P^-1 = (m - 1) I + Y^T R^-1 Y`` is built from ``Y`` with 258 to 3,582 rows (the
observations a local domain of dipole_field sees), and each way computes the transform's
symmetric part ``T = sqrt(m - 1) P^{1/2}`` of every cube. Times are the fastest of three,
in this process, with BLAS on one thread as dipole_field runs it; "max difference" is against
today's ``T`` relative to its largest entry. A Cholesky factor is not the symmetric root
(another, valid ensemble transform that would move the results) and is listed only for its
time; ``eigvalsh`` (eigenvalues alone) bounds what any eigen-decomposition can cost.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402


def fastest(fn, *args, repeats: int = 3):
    best, out = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn(*args)
        best = min(best, time.perf_counter() - start)
    return best, out


def from_eig(s, V, m):
    return (V * np.sqrt((m - 1) / s)[:, None, :]) @ V.transpose(0, 2, 1)


def numpy_eigh(A, m):
    s, V = np.linalg.eigh(A)
    return from_eig(s, V, m)


def scipy_driver(driver):
    def run(A, m):
        pairs = [scipy.linalg.eigh(a, driver=driver, check_finite=False) for a in A]
        return from_eig(np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]), m)
    return run


def newton_schulz(iterations):
    """Coupled Newton-Schulz for ``A^{-1/2}``, batched, ``A`` scaled by its Frobenius norm."""
    def run(A, m):
        eye = np.eye(A.shape[-1])
        c = np.linalg.norm(A, axis=(1, 2))[:, None, None]
        Y, Z = A / c, np.broadcast_to(eye, A.shape).copy()
        for _ in range(iterations):
            T = 0.5 * (3 * eye - Z @ Y)
            Y, Z = Y @ T, T @ Z
        return np.sqrt(m - 1) * Z / np.sqrt(c)
    return run


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cubes", type=int, default=512)
    parser.add_argument("--members", type=int, default=50)
    args = parser.parse_args(argv)
    m, rng = args.members, np.random.default_rng(0)
    A = np.empty((args.cubes, m, m))
    for b in range(args.cubes):
        Y = rng.standard_normal((int(rng.integers(258, 3583)), m)) * rng.uniform(0.01, 1.0)
        A[b] = (m - 1) * np.eye(m) + Y.T @ Y
    with threadpool_limits(limits=1, user_api="blas"):
        rows = compare(A, m)
    print(f"{args.cubes} cubes of {m} members")
    for r in rows:
        diff = r["max difference"]
        print(f"{r['way']:40s} {r['seconds']:8.3f} s  x{r['speed vs today']:6.2f}  "
              f"{diff if isinstance(diff, str) else f'{diff:.1e}'}")
    record.save("letkf_sqrt", rows, __doc__)


def compare(A: np.ndarray, m: int) -> list[dict]:
    base = numpy_eigh(A, m)
    ways = [("numpy eigh, batched (today)", numpy_eigh),
            ("scipy eigh, driver evd, per cube", scipy_driver("evd")),
            ("scipy eigh, driver evr, per cube", scipy_driver("evr")),
            ("Newton-Schulz, 10 iterations, batched", newton_schulz(10)),
            ("Newton-Schulz, 20 iterations, batched", newton_schulz(20))]
    rows = []
    for name, fn in ways:
        sec, T = fastest(fn, A, m)
        diff = float(np.abs(T - base).max() / np.abs(base).max())
        rows.append({"way": name, "seconds": sec, "max difference": diff})
    for name, fn in (("eigvalsh alone (a bound)", np.linalg.eigvalsh),
                     ("Cholesky (not the symmetric root)", np.linalg.cholesky)):
        sec, _ = fastest(fn, A)
        rows.append({"way": name, "seconds": sec, "max difference": "-"})
    return [{**r, "speed vs today": rows[0]["seconds"] / r["seconds"]} for r in rows]


if __name__ == "__main__":
    main()
