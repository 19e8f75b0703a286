"""Figures (matplotlib, Agg only): each function takes figure data and returns a Figure drawn
in the project's one style (:mod:`.style`)."""

from estim.experiments.shared.plots.curves import (
                                                   absolute_errors,
                                                   burden,
                                                   burden_timing,
                                                   differentiator_response,
                                                   noisy_signal,
                                                   relative_error_curves,
)
from estim.experiments.shared.plots.fields import ensemble_rank, field_slices, field_study
from estim.experiments.shared.plots.images import image_panels, pixel_series
from estim.experiments.shared.plots.traces import (
                                                   estimates,
                                                   estimates_clipped,
                                                   output_limits,
                                                   parameters,
                                                   perturbation,
                                                   predictions,
                                                   residuals,
                                                   running_rmse,
                                                   with_unit,
)

__all__ = ["absolute_errors", "burden", "burden_timing", "differentiator_response",
           "ensemble_rank", "estimates", "estimates_clipped", "field_slices", "field_study",
           "image_panels", "noisy_signal", "output_limits", "parameters", "perturbation",
           "pixel_series", "predictions", "relative_error_curves", "residuals", "running_rmse",
           "with_unit"]
