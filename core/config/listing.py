"""``estim settings``: every setting a config can give, as Markdown, from the declarations
(:mod:`estim.config.settings`) of the common keys, the analyses, the estimators and the
models."""

from __future__ import annotations

from collections.abc import Iterable

from estim.config import registry
from estim.config.loading import Common
from estim.config.registry import ANALYSES
from estim.config.settings import describe


def _table(rows: list[tuple[str, ...]], head: tuple[str, ...]) -> str:
    def cell(text_: str) -> str:
        return str(text_).replace("|", "\\|")

    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def listing(only: str | None = None, plugins: Iterable[str] = ()) -> str:
    """Every setting a config can give, as Markdown: each analysis' keys (the common ones
    first), each of estim's estimators' settings and each of its models' parameters, from
    their declarations; a plugin's only if its module is one of ``plugins`` (the names
    :func:`estim.config.loading.load_plugins` returns). ``only``: one analysis, estimator or
    model."""
    chosen = frozenset(plugins)

    def first(cls: type) -> str:
        paragraph = (cls.__doc__ or "").strip().split("\n\n")[0]
        return " ".join(line.strip() for line in paragraph.splitlines())

    parts = []
    head = ("key", "type", "default", "unit", "what")
    for name, module in ANALYSES.items():
        if only in (None, name) and hasattr(module, "Config"):
            doc = first(module.Config)
            parts.append(f"### analysis `{name}`\n\n{doc}\n\n"
                         + _table(describe(Common) + describe(module.Config), head))
    def own(cls: type) -> bool:
        """estim's declarations and the chosen plugins': not another plugin's, not a model
        built from a config's netlist (its parameters are the netlist's .param lines, not
        settings)."""
        if cls.__module__.startswith(registry.PLUGIN_PREFIX):
            return cls.__module__ in chosen
        return not getattr(cls, "from_netlist", False)

    for name in registry.ESTIMATORS:
        if only in (None, name) and own(registry.ESTIMATORS[name]):
            cls = registry.ESTIMATORS[name]
            doc = first(cls)
            parts.append(f"### estimator `{name}` (`estimators[i].settings`)\n\n{doc}\n\n"
                         + _table(describe(cls), head))
    for name in registry.MODELS:
        if only in (None, name) and own(registry.MODELS[name]):
            cls = registry.MODELS[name]
            doc = first(cls)
            variants = ", ".join(cls.variants) or "-"
            parts.append(f"### model `{name}` (`model.params`; variants: {variants})\n\n{doc}"
                         "\n\n" + _table(describe(cls.Params), head))
    return "\n\n".join(parts) + "\n"
