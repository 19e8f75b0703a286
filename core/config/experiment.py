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

    @property
    def sweep(self) -> dict | None:
        """The config's ``sweep:`` block (key path -> values), or ``None``."""
        return self.spec.get("sweep") or None

    @property
    def tolerances(self) -> dict:
        """``check.tolerances``: column -> how ``estim check`` compares it."""
        return self.spec["check"]["tolerances"]

    @property
    def claim_margin(self) -> float:
        """``claim_margin``: the margin of practical significance of the config's claims."""
        return float(self.spec.get("claim_margin") or 0.0)

    @property
    def model_block(self) -> dict:
        """The config's ``model`` block as given (a netlist's file, inputs and output too),
        or an empty mapping."""
        return self.spec.get("model") or {}

    @property
    def title(self) -> str:
        """The config's title (figures), or its name."""
        return self.spec["title"] or self.name
