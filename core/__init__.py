"""estim: reproduce and extend the result tables of Bansal (2019), state estimation in systems
modelled by ODEs and PDEs.

The library behind the ``estim`` command (:mod:`estim.cli`). From Python:

* :func:`estim.run` runs a config and returns a :class:`estim.Result` (tables as pandas
  DataFrames, figures, claims, ``save(folder)``); :func:`estim.load` reads stored results;
* :mod:`estim.models` and :mod:`estim.estimators` give every registered model and filter
  (``estim.models.get("mosfet_ekv")``) to use directly on arrays; :func:`estim.from_netlist`
  makes (and registers) the model of a SPICE netlist.

Importing ``estim`` loads nothing heavy: each name loads on first use.
"""

__version__ = "0.1.0"

_API = {"run": "estim.api", "load": "estim.api", "experiment": "estim.api",
        "Result": "estim.api", "from_netlist": "estim.api"}


def __getattr__(name: str):
    if name in _API:
        import importlib

        return getattr(importlib.import_module(_API[name]), name)
    if name in ("models", "estimators"):
        import importlib

        return importlib.import_module(f"estim.{name}")
    raise AttributeError(f"module 'estim' has no attribute {name!r}")


__all__ = ["Result", "__version__", "estimators", "experiment", "from_netlist", "load",
           "models", "run"]
