"""The image filters in pixels per second on camera (512 x 512) at 5 dB, as ratios to the
non-adaptive NSHP Kalman filter run in the same process.

Run on demand (not part of the tests):  python bench/bench_image.py

The NSHP filters are sequential in both directions and compiled with numba (the first call
compiles and is not timed); the strip filter runs all strips of the image as one batch.
"""

from __future__ import annotations

import numpy as np
import record
from bench_field import timed


def main() -> None:
    from scipy import signal
    from skimage import data
    from skimage.restoration import denoise_wavelet

    from estim.images import kalman2d, nshp, strip

    img = data.camera().astype(float)
    u = img - img.mean()
    sigma_v2 = float(u.var() / 10**0.5)
    y = u + np.sqrt(sigma_v2) * np.random.default_rng(0).standard_normal(u.shape)
    settings = {"H0": 1.0, "lambda0": 0.95, "v0": 1.0, "mu_u": 0.0}
    cases = {}
    for M in (1, 2):
        a, se2 = nshp.yule_walker(y, M, sigma_v2)
        A10, A01, _ = nshp.state_matrices(a, M)
        cases[f"NSHP Kalman, M = {M}"] = (
            lambda A10=A10, A01=A01, se2=se2, M=M: kalman2d.restore(y, A10, A01, se2,
                                                                      sigma_v2, M))
        for gradient in ("full", "approximate"):
            cases[f"NSHP Kalman adaptive, M = {M}, {gradient}"] = (
                lambda a=a, se2=se2, M=M, g=gradient: kalman2d.restore_adaptive(
                    y, a, se2, sigma_v2, M, {**settings, "gradient": g}))
    for W in (8, 16):
        cases[f"strip Kalman, W = {W}, P = 1"] = lambda W=W: strip.restore(y, W, 1, sigma_v2)
    cases["Wiener 7x7 (scipy)"] = lambda: signal.wiener(y, (7, 7), noise=sigma_v2)
    cases["wavelet BayesShrink (scikit-image)"] = lambda: denoise_wavelet(
        y, sigma=np.sqrt(sigma_v2), method="BayesShrink", mode="soft", rescale_sigma=True)
    for fn in cases.values():
        fn()                                           # compile and warm up, untimed
    seconds = {name: timed(fn, repeats=3) for name, fn in cases.items()}
    base = seconds["NSHP Kalman, M = 1"]
    print(f"{'filter':44s} {'s':>8s} {'pixels/s':>12s} {'x NSHP M=1':>11s}")
    for name, s in seconds.items():
        print(f"{name:44s} {s:8.3f} {y.size / s:12.0f} {base / s:11.2f}")
    record.save("image", [{"filter": name, "seconds": s, "pixels per s": y.size / s,
                           "x NSHP M=1": base / s} for name, s in seconds.items()], __doc__)


if __name__ == "__main__":
    main()
