"""Estimators: each a frozen dataclass of its settings (:mod:`estim.config.settings`) whose
``run(model, z, u, dt, x0)`` returns an :class:`estim.estimators.base.Estimate`.

``get(name)`` gives a registered estimator's class, ``names()`` every name (each module of
this package registers the estimator of its name; a config's ``plugins:`` add others).
"""

from __future__ import annotations


def get(name: str) -> type:
    """The estimator class registered as ``name`` (``KeyError`` naming the known ones)."""
    from estim.config import registry

    try:
        return registry.ESTIMATORS[name]
    except KeyError:
        raise KeyError(f"no estimator {name!r}; expected one of {list(registry.ESTIMATORS)}"
                       ) from None


def names() -> list[str]:
    """Every registered estimator's name."""
    from estim.config import registry

    return list(registry.ESTIMATORS)
