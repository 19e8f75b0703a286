"""One experiment's part of the report page (:mod:`estim.report.html` fills it,
:mod:`estim.report.overview` summarises it)."""

from __future__ import annotations

from dataclasses import dataclass, field

from estim.util import lazy

pd = lazy.load("pandas")


@dataclass
class Section:
    """One experiment's part of the page."""

    name: str
    title: str
    manifest: dict
    tables: list[tuple[str, str, pd.DataFrame]] = field(default_factory=list)
    """``(metric, caption, table)``, joined to the printed values where there are any."""
    figures: list[tuple[str, bytes]] = field(default_factory=list)   # (file name, bytes)
    deviations: list[tuple[str, str]] = field(default_factory=list)
    empty: list[str] = field(default_factory=list)
    """Captions of the tables with no value in any cell (keys alone): named, not drawn."""
    fragile: int = 0
    """Claim cells whose verdict another machine's arithmetic moves (:mod:`.fragility`)."""
    fragile_cells: pd.DataFrame | None = None
    """The fragile verdicts' table (:func:`estim.report.fragility.read`) of the results."""
