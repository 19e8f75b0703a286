"""One stored experiment, read one way by every command (``table``, ``report``, ``summary``,
``check``, ``merge`` and :func:`estim.load`): its manifest checked against the schema
:func:`estim.store.writing.write_manifest` writes, and each file read through
:func:`estim.store.read.read_stored` (a bounded regular file) and compared with the sha256
its manifest records, so a folder damaged in one way gets the same verdict everywhere."""

from __future__ import annotations

import hashlib
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

from estim.errors import UsageError
from estim.store.read import (
    MAX_MANIFEST_BYTES,
    MAX_TABLE_BYTES,
    read_columns,
    read_manifest,
    read_run_record,
    read_stored,
    read_table,
    stored_table_path,
)
from estim.store.writing import MACHINE_DIR, RUN_RECORD, spec_hash
from estim.util import lazy

pd = lazy.load("pandas")

MAX_FIGURE_BYTES = 32 << 20
"""Largest stored figure read (the shipped ones are at most 0.4 MB)."""
_SHA256 = re.compile(r"[0-9a-f]{64}")
_SCHEMA = {"config": dict, "config_sha256": str, "models": dict, "overrides": dict,
           "versions": dict, "files": dict}
"""The manifest's keys and their JSON types (``seed`` and ``runs``: an integer or null)."""


def manifest_problems(manifest: dict, analyses: dict) -> list[str]:
    """What is wrong with a manifest read as a mapping, one phrase each (empty when it is a
    manifest :func:`~estim.store.writing.write_manifest` could have written): a key missing
    or of the wrong type, a config that does not hash to its ``config_sha256`` (edited), an
    unknown analysis, a seed or run count that is not an integer or not the config's, a
    file entry that is not a relative path with a sha256."""
    out = []
    for key, kind in _SCHEMA.items():
        if not isinstance(manifest.get(key), kind):
            out.append(f"no {key!r} {'mapping' if kind is dict else 'text'}")
    config = manifest.get("config")
    if not isinstance(config, dict):
        return out
    if isinstance(manifest.get("config_sha256"), str) and \
            spec_hash(config) != manifest["config_sha256"]:
        out.append("its config does not hash to its config_sha256 (edited after the run)")
    name = config.get("analysis", "estimation")
    if not (isinstance(name, str) and name in analyses):
        out.append(f"names an unknown analysis {str(name)[:60]!r}")
    mc = config.get("monte_carlo") if isinstance(config.get("monte_carlo"), dict) else {}
    for key in ("seed", "runs"):
        value = manifest.get(key, "missing")
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
            shown = "missing" if value == "missing" else (
                "nan" if isinstance(value, float) and math.isnan(value) else repr(value)[:40])
            out.append(f"{key!r} is {shown}, not an integer")
        elif value != mc.get(key):
            out.append(f"{key!r} is {value!r}, its config's {mc.get(key)!r}")
    files = manifest.get("files")
    for rel, digest in (files.items() if isinstance(files, dict) else ()):
        parts = Path(rel).parts
        if (not parts or Path(rel).is_absolute() or ".." in parts or parts[0] == MACHINE_DIR
                or rel in ("manifest.json", RUN_RECORD)):
            out.append(f"a file entry {rel[:60]!r} outside the folder's own files")
        elif not (isinstance(digest, str) and _SHA256.fullmatch(digest)):
            out.append(f"the file entry {rel[:60]!r} has no sha256")
    return out


@dataclass(frozen=True)
class Stored:
    """An experiment's result folder whose manifest passed :func:`manifest_problems`."""

    folder: Path
    manifest: dict
    analysis: object
    """The analysis module its config names (its ``TABLES`` say what the folder holds)."""

    @property
    def config(self) -> dict:
        return self.manifest["config"]

    @property
    def name(self) -> str:
        return self.folder.name

    def expected(self, path: Path) -> str | None:
        """The sha256 recorded for ``path``: in the manifest, or for a file under
        ``machine/`` in the untracked run record (None when that record has none)."""
        rel = path.relative_to(self.folder).as_posix()
        if rel.split("/", 1)[0] == MACHINE_DIR:
            recorded = read_run_record(self.folder).get("machine_files")
            return recorded.get(rel) if isinstance(recorded, dict) else None
        return self.manifest["files"].get(rel)

    def read(self, path: Path, limit: int, what: str) -> bytes:
        """The bytes of one of the folder's files (:func:`read_stored`), refused with a
        :class:`UsageError` when its manifest does not list it or records another sha256."""
        data = read_stored(path, limit, what)
        want = self.expected(path)
        rel = path.relative_to(self.folder).as_posix()
        if want is None and rel.split("/", 1)[0] != MACHINE_DIR:
            raise UsageError(f"{path}: not listed in its manifest (not written by this run)")
        if want is not None and hashlib.sha256(data).hexdigest() != want:
            raise UsageError(f"{path}: not the file its manifest records (sha256 differs: "
                             "damaged or edited)")
        return data

    def table_path(self, spec) -> Path | None:
        """The file of table ``spec``, None when the folder holds none
        (:func:`stored_table_path`)."""
        return stored_table_path(self.folder, spec)

    def table(self, spec) -> pd.DataFrame | None:
        """The stored table ``spec`` checked by :meth:`read` and :func:`read_table`; None
        when the folder holds none."""
        path = self.table_path(spec)
        if path is None:
            return None
        data = self.read(path, MAX_TABLE_BYTES, "table")
        return read_table(path, spec, data=data)

    def columns(self, spec):
        """:meth:`table` as plain columns (:func:`estim.store.read.read_columns`, no
        pandas)."""
        path = self.table_path(spec)
        if path is None:
            return None
        return read_columns(path, spec, data=self.read(path, MAX_TABLE_BYTES, "table"))

    def figures(self) -> list[Path]:
        """The figure files under ``figures/`` (PNG, SVG, PDF), by name."""
        return sorted(p for p in (self.folder / "figures").glob("*")
                      if p.suffix in (".png", ".svg", ".pdf"))

    def file_problems(self) -> list[str]:
        """Every listed file that is missing, not a bounded regular file or not its recorded
        sha256, and every file beside them its manifest does not list (the hidden ones
        and ``machine/`` aside): what ``estim check`` reports before re-running."""
        out = []
        for rel in sorted(self.manifest["files"]):
            path = self.folder / rel
            if not os.path.lexists(path):
                out.append(f"{path}: missing (its manifest lists it)")
                continue
            try:
                self.read(path, max(MAX_FIGURE_BYTES, MAX_TABLE_BYTES), "file")
            except UsageError as exc:
                out.append(str(exc))
        for path in sorted(self.folder.rglob("*")):
            rel = path.relative_to(self.folder)
            if (path.is_dir() and not path.is_symlink()) or rel.parts[0] == MACHINE_DIR \
                    or any(p.startswith(".") for p in rel.parts) \
                    or rel.as_posix() in ("manifest.json", RUN_RECORD):
                continue
            if rel.as_posix() not in self.manifest["files"]:
                out.append(f"{path}: not listed in its manifest (not written by this run)")
        return out


def open_stored(folder: Path, analyses: dict) -> Stored:
    """The experiment stored in ``folder``; a :class:`UsageError` naming its manifest and
    the first problem when the manifest is missing, not a bounded JSON mapping, or not one
    estim writes (:func:`manifest_problems`)."""
    folder = Path(folder)
    where = folder / "manifest.json"
    manifest = read_manifest(folder)
    if manifest is None:
        read_stored(where, MAX_MANIFEST_BYTES, "manifest")      # names why, when it can
        raise UsageError(f"{where}: not a readable estim manifest (not JSON)")
    problems = manifest_problems(manifest, analyses)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise UsageError(f"{where}: {problems[0]}{more}")
    name = manifest["config"].get("analysis", "estimation")
    return Stored(folder, manifest, analyses[name])


def stored_folders(results: Path, analyses: dict, only: tuple[str, ...] = ()) -> list[Stored]:
    """Every experiment stored under ``results`` (each folder with a manifest.json, by
    name), each opened by :func:`open_stored`; ``only``: just the folders of these names."""
    return [open_stored(m.parent, analyses)
            for m in sorted(Path(results).glob("*/manifest.json"))
            if not only or m.parent.name in only]


def stored_tables(results: Path, metric: str, analyses: dict, only: tuple[str, ...] = ()):
    """``(Stored, TableSpec)`` of every experiment stored under ``results`` that has the
    table ``metric`` (:func:`stored_folders`: a damaged manifest is a ``UsageError``);
    ``only``: of the folders of these names."""
    for stored in stored_folders(results, analyses, only):
        spec = stored.analysis.TABLES.get(metric)
        if spec is not None and stored.table_path(spec) is not None:
            yield stored, spec
