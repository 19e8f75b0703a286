"""A config's head: the four keys ``estim list`` shows (name, title, analysis, the thesis
tables it reproduces), read without loading the analyses, models or numpy.

A head whose keys are not plain (a name that is not text, tables that are not a list of
text) is read by the full loader instead, which says what is wrong as ``estim validate``
does; everything else in the config is left to ``validate`` and ``run``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from estim.config.yaml_reader import load_yaml, read_config


@dataclass(frozen=True)
class Head:
    name: str
    title: str
    analysis: str
    reproduces: tuple[str, ...]
    source: str


def read_head(path: Path) -> Head:
    """The head of the config file ``path`` (:class:`estim.errors.ConfigError` when its text
    or its head is not a config's)."""
    path = Path(path)
    data = load_yaml(read_config(path), str(path))
    name, title = data.get("name"), data.get("title", "")
    analysis, tables = data.get("analysis") or "estimation", data.get("reproduces", [])
    plain = (isinstance(name, str) or name is None) and isinstance(title, str) \
        and isinstance(analysis, str) and isinstance(tables, list) \
        and all(isinstance(t, str) for t in tables)
    if not plain:
        from estim.config.loading import load_file

        exp = load_file(path, plan=False)
        name, title, analysis = exp.name, exp.spec["title"], exp.analysis
        tables = list(exp.spec["reproduces"])
    return Head(name=name or path.stem, title=title, analysis=analysis,
                reproduces=tuple(tables), source=str(path))
