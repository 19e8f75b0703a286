"""Circuit and field models sharing the interface of :class:`estim.models.base.Model`.

``get(name)`` gives a registered model's class, ``names()`` every name (each module of this
package registers the model of its name; a config's ``plugins:`` add others).
"""

from __future__ import annotations


def get(name: str) -> type:
    """The model class registered as ``name`` (``KeyError`` naming the known ones)."""
    from estim.config import registry

    try:
        return registry.MODELS[name]
    except KeyError:
        hint = ("; a netlist's model is registered when it is made: "
                "estim.from_netlist(path, input=..., output=...)"
                if isinstance(name, str) and name.startswith("netlist:") else "")
        raise KeyError(f"no model {name!r}; expected one of {list(registry.MODELS)}{hint}"
                       ) from None


def names() -> list[str]:
    """Every registered model's name."""
    from estim.config import registry

    return list(registry.MODELS)
