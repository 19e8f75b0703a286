"""Wavelet-domain identification by LMS and state rebuilt from the identified model
(thesis Sec 4.2, eqs 4.16-4.33 and 4.61): the block method Chapter 4 compares with the EKF.

For the measured states ``y`` (``measures``; eq 4.16 measures all four, ``H = I``), with
``y_0`` the known DC point and ``c_k = y_k - y_0``:

1. the regression of one sample step, ``y_{k+1} - y_k = Theta phi_k`` with
   ``phi_k = [c_k, c_i c_j (i <= j), u_k, 1]``: the Kronecker model (4.15) integrated over
   one interval, its unique quadratic terms only (``x (x) x`` repeats each ``x_i x_j``);
   the step difference replaces the thesis' derivative of the noisy ``y`` (eqs 4.20-4.21);
2. both sides are taken to the wavelet domain (PyWavelets ``wavedec``, orthogonal, mode
   ``periodization``) and only the coefficients of the resolution levels that reach the
   signal band are kept: detail level ``j`` (band ``[fs 2^-(j+1), fs 2^-j]``) is kept when
   its lower edge is below ``band_factor`` times the input's fundamental (the peak of the
   nominal input's spectrum); the approximation is always kept. The thesis' rule for
   ``N1, N2`` (eq 4.19) is undefined for a real wavelet (``|psi'|/|psi|`` is unbounded);
   this rule is ours (docs/deviations.md);
3. ``Theta`` is identified from the kept coefficients by normalised LMS (eq 4.33 by
   gradient search; ``step`` in (0, 2), ``epochs`` passes, columns scaled to unit RMS;
   compiled, :mod:`estim.estimators.wavelet_lms_compiled`),
   with batch least squares on the same coefficients as the reference it is compared with
   (``diagnostics["lms_ls_gap"]``: ``|Theta_LMS - Theta_LS| / |Theta_LS|``);
4. the states are rebuilt by running the identified model from ``y_0`` on the nominal
   input, noise set to zero (eq 4.61).
"""

from __future__ import annotations

import functools

import numpy as np

from estim.config.settings import integer, list_of, number, setting, settings_class, text
from estim.errors import SettingError
from estim.estimators.base import Estimate, Estimator, batch_input
from estim.numerics import opcount
from estim.util import lazy

pywt = lazy.load("pywt")
compiled_lms = lazy.load("estim.estimators.wavelet_lms_compiled")

STEP_BOUND = 2.0
"""Normalised LMS is mean-square stable only for a step in (0, 2)."""


def stable_step(value) -> str | None:
    """A step inside the stability bound of normalised LMS."""
    if number(positive=True, below=STEP_BOUND)(value) is None:
        return None
    return (f"a step in (0, {STEP_BOUND:g}), the stability bound of normalised LMS "
            "(mean-square stable only there)")


@functools.cache
def _pairs(q: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(q)``, made once per ``q`` (it is asked for at every rebuilt step)."""
    return np.triu_indices(q)


def regressors(c: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``phi = [c, c_i c_j (i <= j), u, 1]`` for deviations ``c (..., q)`` and input
    ``u (..., p)``: shape ``(..., q + q(q+1)/2 + p + 1)``."""
    i, j = _pairs(c.shape[-1])
    quad = opcount.mul(c[..., i], c[..., j], "regressors")
    return np.concatenate([c, quad, u, np.ones(c.shape[:-1] + (1,))], axis=-1)


def kept_levels(steps: int, wavelet: str, fundamental_hz: float, fs: float,
                band_factor: float) -> tuple[int, list[bool]]:
    """Decomposition depth and, per ``wavedec`` output ``[cA_L, cD_L, .., cD_1]``, whether it
    is kept."""
    level = max(1, pywt.dwt_max_level(steps, pywt.Wavelet(wavelet).dec_len))
    keep = [True]
    for j in range(level, 0, -1):
        keep.append(fs / 2 ** (j + 1) < band_factor * fundamental_hz)
    return level, keep


def to_wavelet(signal: np.ndarray, wavelet: str, level: int, keep: list[bool]) -> np.ndarray:
    """Kept wavelet coefficients of ``signal (runs, steps, k)`` along time:
    ``(runs, kept, k)``. The multiplications of the filter bank are counted."""
    parts = pywt.wavedec(signal, wavelet, mode="periodization", level=level, axis=1)
    taps = pywt.Wavelet(wavelet).dec_len
    for part in parts[1:]:
        # each level filters its input with the low- and high-pass filter, both subsampled
        opcount._add("wavelet transform", 2 * taps * part.size)
    return np.concatenate([p for p, k in zip(parts, keep, strict=True) if k], axis=1)


def fundamental(u: np.ndarray, dt: float) -> float:
    """Frequency of the largest non-DC peak of the input's spectrum (first run, first input)."""
    trace = np.asarray(u, float)[0, :, 0]
    spectrum = np.abs(np.fft.rfft(trace - trace.mean()))
    freqs = np.fft.rfftfreq(trace.size, dt)
    return float(freqs[1 + np.argmax(spectrum[1:])]) if trace.size > 2 else 1.0 / dt


@settings_class
class WaveletLMS(Estimator, name="wavelet_lms"):
    """Block identification in the wavelet domain, then simulation of the identified model."""

    measures: list | None = setting(None, list_of(text(max_length=40), max_length=256,
                                                  unique=True),
                                    doc="the states measured (names); none: every state "
                                        "(eq 4.16, H = I)")
    wavelet: str = setting("db4", text(max_length=20), doc="a discrete wavelet of PyWavelets")
    band_factor: float = setting(4.0, number(positive=True, maximum=1e6),
                                 doc="keep the detail levels whose lower band edge lies below "
                                     "this many times the input's fundamental")
    step: float = setting(0.5, stable_step, doc="normalised LMS step (stable in (0, 2))")
    epochs: int = setting(200, integer(1, 100_000), doc="LMS passes over the kept coefficients")
    solver: str = setting("lms", text({"lms", "least_squares"}),
                          doc="which identified model is rebuilt: LMS or batch least squares")
    divergence_bound: float = setting(1e3, number(positive=True, maximum=1e12), unit="state",
                                      doc="a rebuilt state beyond it (or not finite) breaks the "
                                          "run")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.wavelet not in pywt.wavelist(kind="discrete"):
            raise SettingError("wavelet", f"{self.wavelet!r} is not a discrete wavelet of "
                             "PyWavelets (e.g. db4, sym8, haar)")

    @classmethod
    def example(cls, model) -> WaveletLMS:
        return cls(measures=[model.state_names[0]], epochs=2)

    def measured_states(self, model) -> list[int]:
        """Indices of the states this estimator is given measurements of."""
        names = list(model.state_names)
        if self.measures is None:
            return list(range(len(names)))
        return [names.index(s) for s in self.measures]

    def output_state(self, model) -> int:
        """The state the model's output reads (models here have ``y = x_i``)."""
        H = np.asarray(model.h_jacobian(np.zeros(model.n_states)), float).reshape(-1)
        return int(np.argmax(np.abs(H)))

    def validate(self, model) -> None:
        names = list(model.state_names)
        for s in self.measures or []:
            if s not in names:
                raise SettingError("measures", f"{s!r} is not a state of {model.name}; "
                                 f"expected some of {names}")
        if self.output_state(model) not in self.measured_states(model):
            raise ValueError(f"measures must include the output state "
                             f"{names[self.output_state(model)]!r}: the state is rebuilt "
                             "from what is measured")

    def identify(self, y: np.ndarray, u: np.ndarray, y0: np.ndarray, dt: float,
                 fundamental_hz: float) -> dict:
        """``Theta`` by LMS and by least squares from measured ``y (runs, steps, q)`` and
        inputs ``u (runs, steps, p)``, and the fraction of coefficients kept."""
        runs, steps, q = y.shape
        prev = np.concatenate([np.broadcast_to(y0, (runs, 1, q)), y[:, :-1]], axis=1)
        target = y - prev
        phi = regressors(prev - y0, u)
        level, keep = kept_levels(steps, self.wavelet, fundamental_hz, 1.0 / dt,
                                  self.band_factor)
        Wt = to_wavelet(target, self.wavelet, level, keep)
        Wp = to_wavelet(phi, self.wavelet, level, keep)
        kept = Wt.shape[1]
        scale = np.sqrt(np.mean(Wp**2, axis=1, keepdims=True))
        scale[scale == 0] = 1.0
        Ws = Wp / scale
        theta_ls = np.stack([np.linalg.lstsq(Ws[r], Wt[r], rcond=None)[0].T
                             for r in range(runs)])
        theta = compiled_lms.lms_passes(Ws, Wt, self.step, self.epochs)
        if opcount.counting_active():
            d = phi.shape[-1]
            for _ in range(self.epochs * kept):      # as the batched form counted them
                for size in (q * d, d, d, q * d):
                    opcount._add("LMS", runs * size)
        gap = (np.linalg.norm(theta - theta_ls, axis=(1, 2))
               / np.maximum(np.linalg.norm(theta_ls, axis=(1, 2)), 1e-300))
        return {"lms": theta / scale, "least_squares": theta_ls / scale,
                "kept_fraction": kept / steps, "gap": gap}

    def rebuild(self, theta: np.ndarray, u: np.ndarray, y0: np.ndarray) -> tuple[np.ndarray,
                                                                               np.ndarray]:
        """States of the identified model (eq 4.61) from ``y0`` on ``u``; and the runs that
        left the bound or became non-finite (NaN from there on)."""
        runs, steps, _ = u.shape
        q = theta.shape[1]
        x = np.broadcast_to(y0, (runs, q)).astype(float)
        out = np.full((runs, steps, q), np.nan)
        alive = np.ones(runs, bool)
        with np.errstate(all="ignore"):
            for k in range(steps):
                x = x + (theta @ regressors(x - y0, u[:, k])[..., None])[..., 0]
                alive &= np.all(np.isfinite(x), axis=1) & np.all(
                    np.abs(x) <= self.divergence_bound, axis=1)
                x = np.where(alive[:, None], x, np.nan)
                out[:, k] = x
        return out, ~alive

    def measured(self, model) -> int | None:
        return len(self.measured_states(model))

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float,
            x0: np.ndarray | None = None) -> Estimate:
        """``z (runs, steps, q)``: measurements of :meth:`measured_states`, in that order."""
        runs, steps, q = z.shape
        seen = self.measured_states(model)
        u = batch_input(u, runs)
        start = model.operating_point() if x0 is None else np.asarray(x0, float)
        y0 = start[seen]
        fit = self.identify(z, u, y0, dt, fundamental(u, dt))
        states, broken = self.rebuild(fit[self.solver], u, y0)
        out = seen.index(self.output_state(model))
        y_hat = states[..., out:out + 1]
        return Estimate(y_hat=y_hat, innovation=z[..., out:out + 1] - y_hat, broken=broken,
                        diagnostics={"kept_fraction": np.full(runs, fit["kept_fraction"]),
                                     "lms_ls_gap": fit["gap"]})
