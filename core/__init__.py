"""estim core: models, estimators, simulation, metrics and tables (no CLI, no file paths)."""

__version__ = "0.1.0"
