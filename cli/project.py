"""Where the configs and results are: the project folder, found from the working folder.

The project is the nearest folder at or above the working folder that has a ``configs/``
folder beside a ``pyproject.toml`` of the distribution ``estim``. Outside a project the
configs shipped inside the package are used and results go to ``./results``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from estim.util.shipped import shipped_folder


def _is_project(folder: Path) -> bool:
    pyproject = folder / "pyproject.toml"
    if not (pyproject.is_file() and (folder / "configs").is_dir()):
        return False
    try:
        text = pyproject.read_text()
    except (OSError, UnicodeDecodeError):
        return False
    return re.search(r'^name\s*=\s*"estim"\s*$', text, re.MULTILINE) is not None


@dataclass(frozen=True)
class Where:
    root: Path | None       # the project folder, or None outside one
    base: Path              # the project folder, or the working folder

    @property
    def results(self) -> Path:
        return self.base / "results"

    @property
    def scratch(self) -> Path:
        return self.base / "scratch"

    @property
    def config_dir(self) -> Path:
        if self.root is not None:
            return self.root / "configs"
        return shipped_configs()

    EXTRA = ("studies", "netlist")
    """Config folders the default reproduction leaves out (``--all`` adds them): the studies
    of Chapter 5's field filter, and the netlist configs (the thesis circuits and a new one
    from SPICE netlists, circuits/)."""

    def configs(self, studies: bool = False) -> list[Path]:
        """The default configs (``configs/*.yaml``); with ``studies`` also those of the
        :attr:`EXTRA` folders (``configs/studies/``, ``configs/netlist/``)."""
        found = sorted(self.config_dir.glob("*.yaml"))
        if studies:
            for extra in self.EXTRA:
                found += sorted((self.config_dir / extra).glob("*.yaml"))
        return found

    def is_own_config(self, path: Path) -> bool:
        try:
            parent = path.resolve().parent
            own = [self.config_dir.resolve()]
            own += [(self.config_dir / extra).resolve() for extra in self.EXTRA]
            return parent in own
        except OSError:
            return False

    def is_baseline(self, folder: Path) -> bool:
        return folder.resolve() == self.results.resolve()

    def output_folder(self, out: Path | None, sources: list[str], overridden: bool,
                      update_baseline: bool, quick: bool = False,
                      can_update: bool = True) -> tuple[Path, str]:
        """Where a run writes, and a note to show when that is not the baseline: the
        baseline ``results/`` only for the project's own configs run as they are (or with
        ``update_baseline``, never for a ``quick`` run); otherwise the scratch folder. An
        ``out`` that is the baseline for a run that may not write it is a ``UsageError``
        (``can_update``: whether the command has ``--update-baseline`` to offer)."""
        from estim.errors import UsageError

        own = all(self.is_own_config(Path(s)) for s in sources)
        if quick:
            if out is not None and self.is_baseline(out):
                raise UsageError(f"{out} holds the stored baseline, which a --quick run never "
                                 "writes; choose another --out")
            return (out, "") if out is not None else (
                self.scratch, f"a --quick run: writing to {self.scratch}/, never the baseline")
        if out is not None:
            if self.is_baseline(out) and (overridden or not own) and not update_baseline:
                why = "overrides its config" if overridden else "is not a config of configs/"
                advice = ("pass --update-baseline to replace it, or choose another --out"
                          if can_update else "choose another --out")
                raise UsageError(f"{out} holds the stored baseline and this run {why}; "
                                 + advice)
            return out, ""
        if (overridden or not own) and not update_baseline:
            why = "overrides the config" if overridden else "uses a config outside configs/"
            return self.scratch, (f"this run {why}: writing to {self.scratch}/, not the "
                                  f"baseline {self.results}/"
                                  + (" (--update-baseline to replace it)" if can_update else ""))
        return self.results, ""

    def describe(self, results: Path | None = None) -> str:
        """Where the configs come from, and where the results go (``results``: a command's
        --out, else the project's)."""
        results = results or self.results
        if self.root is not None:
            return (f"project {self.root}: configs from {self.config_dir}/, "
                    f"results in {results}/")
        return (f"no estim project at or above {self.base}: using the configs shipped with "
                f"estim ({self.config_dir}/), results in {results}/")


def shipped_configs() -> Path:
    """The configs shipped with estim (:func:`estim.util.shipped.shipped_folder`)."""
    return shipped_folder("configs")


def locate(start: Path | None = None) -> Where:
    start = (start or Path.cwd()).resolve()
    for folder in (start, *start.parents):
        if _is_project(folder):
            return Where(root=folder, base=folder)
    return Where(root=None, base=start)
