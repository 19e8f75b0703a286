"""The validated experiment a config becomes."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True, eq=False)
class Experiment:
    """A validated experiment.

    ``spec`` is the resolved config with every default filled (what the manifest records),
    ``config`` the same as the analysis' typed settings; ``plan`` holds what the analysis built from
    it once at parse time (models, estimators), so no work unit rebuilds or re-validates them.
    """

    name: str
    source: str
    spec: dict
    plan: Any = None
    models: dict = field(default_factory=dict)
    """Every model the config builds, by key path, with every parameter resolved (the
    manifest records them)."""
    config: Any = None
    """The analysis' typed settings (its ``Config``, :mod:`estim.config.settings`), built
    once from ``spec``: what the analysis, the runner and the estimators read."""

    @property
    def analysis(self) -> str:
        return self.spec["analysis"]
