"""2-D adaptive Kalman filtering of images with an NSHP AR model (Azimi-Sadjadi and Bannour,
``shared/seeds/000_…``), against honest baselines.

For each image and Monte Carlo run: white Gaussian noise at the input SNR; the NSHP model's
parameters identified globally from the noisy image (noise-corrected Yule-Walker,
:func:`estim.images.nshp.yule_walker`); the non-adaptive filter of eqs 13a-e with them
(:func:`estim.images.kalman2d.restore`); the adaptive filter of Table I started from them
(:func:`estim.images.kalman2d.restore_adaptive`); the strip Kalman filter of the second
paper (``shared/seeds/002_…``, :func:`estim.images.strip.restore`), its model identified from
the noisy strips (all columns, or on line from the columns so far) and, as the paper
assumes, from the clean ones; ``scipy.signal.wiener`` told the noise variance, and left to
estimate it (its ``noise=None``: the mean of the local variances); scikit-image's
BayesShrink wavelet denoising told the noise variance; and the noisy image itself. Every
claim (:data:`CLAIMS`) is judged by :mod:`estim.experiments.shared.claims` on the per-run mean
squared errors.

SNR is variance based: ``10 log10(var(u) / mean((u - u_hat)^2))`` with ``u`` the clean
image (the paper's definition is not given); improvement in SNR is it minus the input's;
PSNR and SSIM (scikit-image) on the 0-255 scale.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estim.config.experiment import Experiment
from estim.config.settings import (
    REQUIRED,
    Settings,
    block,
    file_name,
    integer,
    list_of,
    number,
    setting,
    settings_class,
    text,
)
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, plots
from estim.experiments.shared.blocks import MonteCarlo
from estim.images import nshp, strip
from estim.numerics import metrics
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")
kalman2d = lazy.load("estim.images.kalman2d")

IMAGES = ("camera", "moon", "brick", "grass", "gravel", "coins", "text", "page", "astronaut")
"""scikit-image's images that ship inside its wheel (no download at run time)."""

NOISY, NON_ADAPTIVE, ADAPTIVE = "noisy (input)", "NSHP Kalman", "NSHP Kalman, adaptive"
STRIP, STRIP_ORACLE = "strip Kalman", "strip Kalman, model from clean image"
STRIP_ONLINE = "strip Kalman, online model (eq 15)"
WIENER, WIENER_ESTIMATED = "Wiener, noise given", "Wiener, noise estimated"
WAVELET = "wavelet (BayesShrink)"
RESTORATIONS = (NOISY, NON_ADAPTIVE, ADAPTIVE, STRIP, STRIP_ONLINE, STRIP_ORACLE, WIENER,
              WIENER_ESTIMATED, WAVELET)
CLAIMS = ((ADAPTIVE, NON_ADAPTIVE), (NON_ADAPTIVE, WIENER), (ADAPTIVE, WIENER),
          (NON_ADAPTIVE, WIENER_ESTIMATED), (NON_ADAPTIVE, WAVELET), (STRIP, NON_ADAPTIVE),
          (STRIP, WAVELET), *((est, NOISY) for est in RESTORATIONS if est != NOISY))
"""The paper's claim (adaptation improves the restoration), the NSHP filters against the
Wiener filter (told the noise variance, or left to estimate it) and wavelet denoising, the
strip filter against the NSHP filter and wavelet denoising, and every restoration against
the noisy image itself; the loss is each run's mean squared error."""
QUOTES = (Quote("SNR (dB) over the images", "snr", "snr_db", by="estimator"),)

@settings_class
class NSHP(Settings):
    """The NSHP AR model."""

    order: int = setting(1, integer(1, 3), doc="M: 2M^2 + 2M parameters")


@settings_class
class Adaptive(Settings):
    """Table I's recursion (eqs 23-25)."""

    H0: float = setting(1.0, number(positive=True, maximum=1e12), doc="H(0) = H0 I")
    lambda0: float = setting(0.95, number(minimum=0.0, maximum=1.0), doc="eq 24's lambda(0)")
    v0: float = setting(1.0, number(positive=True, maximum=1.0),
                        doc="the first pixel's step size")
    mu_u: float = setting(0.0, number(minimum=-1e3, maximum=1e3),
                          doc="Sigma_b(0)'s first row")
    gradient: str = setting("full", text({"full", "approximate"}),
                            doc="full: kappa and the row above's Sigma_a, as printed; "
                                "approximate: without them")


@settings_class
class Strip(Settings):
    """The strip Kalman filter (second paper)."""

    width: int = setting(8, integer(1, 64), doc="W, rows per strip")
    order: int = setting(1, integer(1, 4), doc="P, the vector AR order")
    covariance: str = setting("unbiased", text({"unbiased", "biased"}),
                              doc="eq 13's 1/(N - r) or 1/N")
    eigenvalue_floor: float = setting(0.1, number(positive=True, maximum=10.0),
                                      doc="T's eigenvalues raised to this times sigma_v^2")


@settings_class
class Baselines(Settings):
    """The Wiener filter's window."""

    wiener_size: int = setting(7, integer(3, 31), doc="the Wiener filter's window side")


@settings_class
class Paper(Settings):
    """The paper's one number."""

    input_snr_db: float = setting(5.0, number(), unit="dB", doc="the paper's input SNR")
    adaptive_snr_db: float = setting(11.0, number(), unit="dB",
                                     doc="the paper's adaptive filter's SNR")


@settings_class
class Figures(Settings):
    """Figs 5-8."""

    image: str = setting("camera", text(set(IMAGES)), doc="the figures' image")
    row: int = setting(256, integer(1, 100_000), doc="the row of Figs 5-7")
    pixels: int = setting(75, integer(2, 100_000), doc="pixels drawn")
    accuracy: str = setting("fig_5", file_name, doc="file name of Fig 5")
    gain: str = setting("fig_6", file_name, doc="file name of Fig 6")
    parameters: str = setting("fig_7", file_name, doc="file name of Fig 7")


@settings_class
class Config(Settings):
    """2-D adaptive and strip Kalman filtering of images, beside honest baselines."""

    images: list = setting(REQUIRED, list_of(text(set(IMAGES)), unique=True,
                                             max_length=len(IMAGES)),
                           doc="scikit-image's test images")
    input_snr_db: float = setting(5.0, number(minimum=-20.0, maximum=60.0), unit="dB",
                                  doc="input SNR")
    crop: int | None = setting(None, integer(16, 4096), unit="pixels",
                               doc="side of the square kept from each image's top left "
                                   "corner (none: the whole image; --quick: 256)")
    nshp: NSHP = block(NSHP, doc="the NSHP model")
    adaptive: Adaptive = block(Adaptive, doc="Table I")
    strip: Strip = block(Strip, doc="the strip filter")
    baselines: Baselines = block(Baselines, doc="the baselines")
    monte_carlo: MonteCarlo = block(MonteCarlo, required=True, doc="runs and seed")
    paper: Paper = block(Paper, doc="the paper's numbers")
    figures: Figures = block(Figures, doc="the figures")


SCHEMA: dict = Config.schema()

TABLES = {
    "snr": TableSpec("snr.csv", ("image", "input_snr_db", "estimator"),
                     ("snr_db", "snr_db_se", "isnr_db", "psnr_db", "psnr_db_se", "ssim",
                      "ssim_se", "runs", "diverged", "unstable_strips", "paper_snr_db"),
                     title="SNR, improvement in SNR, PSNR and SSIM of the restored images"),
    "claims": claims.TABLE,
    "parameters": TableSpec("parameters.csv", ("image", "parameter"),
                            ("global_mean", "global_se", "adaptive_row_mean",
                             "adaptive_row_min", "adaptive_row_max"),
                            title="NSHP parameters: global Yule-Walker, and the adaptive "
                                  "filter's along the figure row (run 1)"),
}


@dataclass(frozen=True)
class Plan:
    """The typed config: this analysis builds nothing else before its work units."""

    config: Config


def prepare(config: Config, source: str) -> Plan:
    from estim.errors import ConfigError

    if config.figures.image not in config.images:
        raise ConfigError(source, "figures.image", f"expected one of the images "
                          f"{config.images}, got {config.figures.image!r}")
    for image in config.images:
        full = _load(image).shape
        if config.crop is not None and config.crop > min(full):
            raise ConfigError(source, "crop", f"image {image!r} is {full[0]} x {full[1]} "
                              "pixels; give at most its smaller side")
        rows, columns = (min(side, config.crop or side) for side in full)
        if config.figures.row > rows:
            raise ConfigError(source, "figures.row", f"image {image!r} has {rows} rows")
        if config.figures.pixels > columns:
            raise ConfigError(source, "figures.pixels",
                              f"image {image!r} has {columns} columns")
    return Plan(config)


def work_units(exp: Experiment) -> int:
    return len(exp.config.images) * exp.config.monte_carlo.runs


def work_size(config: Config) -> int:
    side = min(512, config.crop or 512)
    return side * side * len(config.images) * config.monte_carlo.runs // 100


QUICK_CROP = 256
"""--quick keeps the first 256 rows and columns of one image: a quarter of the filtering,
and the figures' default row (256) is still in it."""


def tiny(config: Config) -> dict:
    """Seconds of work: one image, cropped to :data:`QUICK_CROP`, one run."""
    crop = min(QUICK_CROP, config.crop or QUICK_CROP)
    return {"images": config.images[:1], "figures.image": config.images[0],
            "monte_carlo.runs": 1, "crop": crop,
            "figures.row": min(config.figures.row, crop),
            "figures.pixels": min(config.figures.pixels, crop)}


def _load(name: str, crop: int | None = None) -> np.ndarray:
    """scikit-image's image ``name`` as gray levels 0-255, its first ``crop`` rows and
    columns (all where ``None``)."""
    from skimage import color, data

    img = getattr(data, name)()
    if img.ndim == 3:
        img = color.rgb2gray(img[..., :3]) * 255.0
    return img[:crop, :crop].astype(float)


def _quality(clean: np.ndarray, est: np.ndarray) -> dict:
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    if not np.all(np.isfinite(est)):
        return {"snr_db": -np.inf, "psnr_db": -np.inf, "ssim": np.nan, "finite": False,
                "mse": np.inf}
    mse = float(np.mean((clean - est) ** 2))
    return {"mse": mse, "snr_db": 10 * np.log10(np.var(clean) / mse),
            "psnr_db": peak_signal_noise_ratio(clean, est, data_range=255.0),
            "ssim": structural_similarity(clean, est, data_range=255.0), "finite": True}


def run_unit(exp: Experiment, image: str, run: int) -> dict:
    """Every estimator on one noisy copy of one image."""
    from scipy import signal
    from skimage.restoration import denoise_wavelet

    config = exp.config
    M = config.nshp.order
    clean = _load(image, config.crop)
    index = config.images.index(image)
    rng = exp.config.monte_carlo.rng(index, run)
    sigma_v2 = float(np.var(clean) / 10 ** (config.input_snr_db / 10))
    noisy = clean + np.sqrt(sigma_v2) * rng.standard_normal(clean.shape)
    y = noisy - noisy.mean()
    a, sigma_e2 = nshp.yule_walker(y, M, sigma_v2)
    A10, A01, _ = nshp.state_matrices(a, M)
    figure_row = config.figures.row - 1
    plain = kalman2d.restore(y, A10, A01, sigma_e2, sigma_v2, M)
    adaptive = kalman2d.restore_adaptive(y, a, sigma_e2, sigma_v2, M, config.adaptive.to_spec(),
                                         trace_row=figure_row)
    sc = config.strip
    unbiased = sc.covariance == "unbiased"
    strips = strip.restore(y, sc.width, sc.order, sigma_v2, unbiased,
                           sc.eigenvalue_floor)
    online = strip.restore(y, sc.width, sc.order, sigma_v2, unbiased,
                           sc.eigenvalue_floor, online=True)
    oracle = strip.restore(y, sc.width, sc.order, sigma_v2, unbiased,
                           model_from=clean - clean.mean())
    size = (config.baselines.wiener_size,) * 2
    wiener = signal.wiener(noisy, size, noise=sigma_v2)
    wiener_estimated = signal.wiener(noisy, size)
    wavelet = denoise_wavelet(noisy, sigma=np.sqrt(sigma_v2), method="BayesShrink",
                              mode="soft", rescale_sigma=True)
    restored = {NOISY: noisy, NON_ADAPTIVE: plain["image"] + noisy.mean(),
                ADAPTIVE: adaptive["image"] + noisy.mean(),
                STRIP: strips["image"] + noisy.mean(),
                STRIP_ONLINE: online["image"] + noisy.mean(),
                STRIP_ORACLE: oracle["image"] + noisy.mean(), WIENER: wiener,
                WIENER_ESTIMATED: wiener_estimated, WAVELET: wavelet}
    out = {"quality": {k: _quality(clean, v) for k, v in restored.items()}, "a": a,
           "trace": adaptive["trace"],
           "unstable": {STRIP: strips["unstable_strips"],
                        STRIP_ONLINE: online["unstable_strips"],
                        STRIP_ORACLE: oracle["unstable_strips"]}}
    if run == 0 and image == config.figures.image:
        n = config.figures.pixels
        out["figure"] = {
            "row": figure_row, "clean": clean, "restored": restored,
            "P_norm": {NON_ADAPTIVE: plain["P_norm"][figure_row, :n],
                       ADAPTIVE: adaptive["P_norm"][figure_row, :n]},
            "K_norm": {NON_ADAPTIVE: plain["K_norm"][figure_row, :n],
                       ADAPTIVE: adaptive["K_norm"][figure_row, :n]},
        }
    if run == 0:
        out["panels"] = {"original": clean, **restored}
    return out


def _run_unit_args(args):
    return run_unit(*args)


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    config = exp.config
    runs = config.monte_carlo.runs
    tasks = [(exp, image, r) for image in config.images for r in range(runs)]
    done = map_tasks(_run_unit_args, tasks, jobs, on_done)
    rows, params, figures, cells = [], [], {}, []
    names = nshp.names(config.nshp.order)
    for i, image in enumerate(config.images):
        units = done[i * runs:(i + 1) * runs]
        cells.append((claims.cell(image=image, input_snr_db=config.input_snr_db),
                      {est: claims.Losses(np.array([u["quality"][est]["mse"] for u in units]))
                       for est in RESTORATIONS}))
        snr_in = np.array([u["quality"][NOISY]["snr_db"] for u in units])
        for est in RESTORATIONS:
            q = [u["quality"][est] for u in units]
            ok = np.array([x["finite"] for x in q])
            snr, snr_se = metrics.mean_and_se(np.array([x["snr_db"] for x in q])[ok])
            psnr, psnr_se = metrics.mean_and_se(np.array([x["psnr_db"] for x in q])[ok])
            ssim, ssim_se = metrics.mean_and_se(np.array([x["ssim"] for x in q])[ok])
            rows.append({"image": image, "input_snr_db": config.input_snr_db,
                         "estimator": est, "snr_db": snr, "snr_db_se": snr_se,
                         "isnr_db": float(np.mean(np.array([x["snr_db"] for x in q])[ok]
                                                  - snr_in[ok])) if ok.any() else np.nan,
                         "psnr_db": psnr, "psnr_db_se": psnr_se, "ssim": ssim,
                         "ssim_se": ssim_se, "runs": int(ok.sum()),
                         "diverged": int((~ok).sum()),
                         "unstable_strips": float(np.mean([u["unstable"].get(est, np.nan)
                                                           for u in units])),
                         "paper_snr_db": (config.paper.adaptive_snr_db if est == ADAPTIVE
                                          else config.paper.input_snr_db if est == NOISY
                                          else np.nan)})
        a = np.array([u["a"] for u in units])
        trace = units[0]["trace"]
        for j, name in enumerate(names):
            m, se = metrics.mean_and_se(a[:, j]) if runs > 1 else (float(a[0, j]), np.nan)
            params.append({"image": image, "parameter": name, "global_mean": m,
                           "global_se": se, "adaptive_row_mean": float(np.mean(trace[:, j])),
                           "adaptive_row_min": float(np.min(trace[:, j])),
                           "adaptive_row_max": float(np.max(trace[:, j]))})
        side = config.crop
        shown = image if side is None else f"{image} ({side} x {side} corner)"
        figures[f"restored_{image}"] = plots.image_panels(
            units[0]["panels"], f"{shown}, input SNR {config.input_snr_db:g} dB (run 1)")
        if "figure" in units[0]:
            fig = units[0]["figure"]
            fs = config.figures
            pixels = np.arange(1, fs.pixels + 1)
            where = f"{shown}, row {fs.row}, pixels 1-{fs.pixels} (run 1)"
            figures[fs.accuracy] = plots.pixel_series(
                pixels, fig["P_norm"], r"accuracy $\Vert P_a \Vert_F$", f"Accuracy: {where}")
            figures[fs.gain] = plots.pixel_series(
                pixels, fig["K_norm"], r"gain $\Vert K \Vert$", f"Gain: {where}")
            traces = {name: trace[:fs.pixels, j] for j, name in enumerate(names)}
            figures[fs.parameters] = plots.pixel_series(
                pixels, traces, "parameter value", f"Adaptive parameters: {where}")
    tables = {"snr": pd.DataFrame(rows)[TABLES["snr"].columns],
              "claims": claims.table(cells, CLAIMS, "MSE"),
              "parameters": pd.DataFrame(params)[TABLES["parameters"].columns]}
    return Result(tables=tables, figures=figures)


def printout(result: Result) -> str:
    df = result.tables["snr"][["image", "estimator", "snr_db", "isnr_db", "psnr_db", "ssim",
                               "paper_snr_db"]]
    return df.to_string(index=False, float_format=lambda v: f"{v:.3g}")
