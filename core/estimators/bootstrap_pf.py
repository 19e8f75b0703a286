"""The bootstrap particle filter (Gordon, Salmond and Smith 1993): the particles move
through the model with their process noise (the prior as proposal), are weighted by the
Gaussian likelihood of the measurement, give the weighted mean and covariance, and are
resampled every step (systematic resampling, one uniform draw per run)."""

from __future__ import annotations

import numpy as np

from estim.config.settings import integer, setting, settings_class
from estim.estimators.ensemble import EnsembleFilter, sample_covariance


@settings_class
class BootstrapParticleFilter(EnsembleFilter, name="bootstrap_pf"):
    """Bootstrap particle filter; its estimate is the weighted mean of the particles. The
    weights are normalised in logarithms, so the likeliest particle keeps one even for a
    measurement no particle explains (the filter then follows that particle); a run breaks
    as any filter's does, its estimate non-finite or beyond the bound."""

    members: int = setting(1000, integer(2, 100_000), doc="particles")

    def analyse(self, model, forecast, z, R, rng):
        runs, count, _ = forecast.shape
        predicted = model.h(forecast)
        d = z[:, None, :] - predicted
        log_w = -0.5 * np.einsum("rim,mk,rik->ri", d, np.linalg.inv(R), d)
        log_w -= log_w.max(axis=1, keepdims=True)
        w = np.exp(log_w)
        w /= w.sum(axis=1, keepdims=True)
        estimate = np.einsum("ri,rin->rn", w, forecast)
        P = sample_covariance(forecast, w)
        S = sample_covariance(predicted) + R
        cumulative = np.cumsum(w, axis=1)
        cumulative[:, -1] = 1.0
        points = (rng.random((runs, 1)) + np.arange(count)) / count
        chosen = np.empty((runs, count), int)
        for r in range(runs):
            if np.all(np.isfinite(cumulative[r])):
                chosen[r] = np.searchsorted(cumulative[r], points[r], side="right")
            else:
                chosen[r] = np.arange(count)
        members = np.take_along_axis(forecast, chosen[..., None], axis=1)
        return members, estimate, P, S, z - predicted.mean(axis=1)
