"""The stored-vs-new comparison of ``estim check``: re-run a config and compare every cell
of its tables with the stored ones under the config's tolerances (docs/checking.md)."""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from concurrent.futures import Executor
from pathlib import Path

from estim import reference, store
from estim.config.experiment import Experiment
from estim.config.loading import load_data
from estim.config.registry import ANALYSES
from estim.engine import compare, runner
from estim.errors import ConfigError, ReferenceJoinError, UsageError
from estim.store import read_table


def config_differences(stored: dict, current: dict, path: str = "") -> list[str]:
    """Key paths where two resolved configs differ, with both values."""
    if isinstance(stored, dict) and isinstance(current, dict):
        out = []
        for key in sorted(set(stored) | set(current), key=str):
            sub = f"{path}.{key}" if path else str(key)
            out += config_differences(stored.get(key), current.get(key), sub)
        return out
    if stored != current:
        return [f"{path or '(config)'}: stored {stored!r}, config {current!r}"]
    return []


def same_settings(manifest: dict, exp: Experiment) -> bool:
    """Whether the stored results were made with ``exp``'s config: the manifest's hash is
    that of ``exp``'s resolved config, or the config the manifest records, read again by
    today's settings, is ``exp``'s. The second case is a setting added since the results were
    stored, which the reading fills with its default: the behaviour the stored run had, or
    the tables that ``estim check`` compares next show the difference."""
    if manifest.get("config_sha256") == store.spec_hash(exp.spec):
        return True
    recorded = manifest.get("config")
    if not isinstance(recorded, dict):
        return False
    try:
        again = load_data(copy.deepcopy(recorded), exp.source, exp.name)
    except (ConfigError, UsageError):
        return False
    return store.spec_hash(again.spec) == store.spec_hash(exp.spec)


def check(exp: Experiment, stored_dir: Path, tmp: Path, jobs: int, say: Callable[[str], None],
          same_config: bool = True, on_done: Callable[[], None] | None = None,
          note: Callable[[str], None] | None = None, pool: Executor | None = None) -> int:
    """Re-run ``exp`` into ``tmp`` and compare it with the stored results in ``stored_dir``:
    the number of differences, each reported through ``say`` (one line each; ``note`` gets
    progress, e.g. the run's time). With ``same_config`` the stored manifest must record
    this config. ``pool``: a process pool shared with other configs
    (:mod:`estim.engine.scheduler`)."""
    note = note or (lambda _text: None)
    if not stored_dir.is_dir():
        say(f"{exp.name}: no stored results in {stored_dir}")
        return 1
    try:                    # the whole manifest and every file it lists, before any work
        stored = store.open_stored(stored_dir, ANALYSES)
    except UsageError as exc:
        say(f"{exp.name}: {exc}")
        return 1
    damaged = stored.file_problems()
    for problem in damaged:
        say(f"{exp.name}: {problem}")
    if damaged:
        return len(damaged)
    manifest = stored.manifest
    if same_config and not same_settings(manifest, exp):
        changes = config_differences(manifest.get("config"), exp.spec)
        shown = "; ".join(changes[:5]) + (f"; and {len(changes) - 5} more" if
                                          len(changes) > 5 else "")
        say(f"{exp.name}: the stored results were made with another config than "
            f"{exp.source}: {shown or 'config hash differs'}")
        return 1
    total = runner.work_units(exp)
    note(f"{exp.name}: running {total} work units ...")
    start = time.perf_counter()
    result, _ = runner.run_to_folder(exp, tmp, jobs, on_done=on_done, pool=pool)
    note(f"{exp.name}: ran in {time.perf_counter() - start:.0f} s")
    tol = exp.tolerances
    for column in sorted(c for c, t in tol.items() if t.get("skip")):
        say(f"{exp.name}: column {column} not compared ({tol[column]['skip']})")
    analysis = ANALYSES[exp.analysis]
    machine = runner.machine_outputs(exp)
    if machine:
        say(f"{exp.name}: {', '.join(machine)} not compared (they measure the machine; "
            "written under machine/)")
    differing = 0
    for metric, new in result.tables.items():
        if metric in machine:
            continue
        spec = analysis.TABLES.get(metric)
        try:
            old = stored.table(spec) if spec is not None else None
        except UsageError as exc:
            say(f"{exp.name}/{metric}.csv: {exc}")
            differing += 1
            continue
        if old is None:
            say(f"{exp.name}/{metric}.csv: missing from the stored results")
            differing += 1
            continue
        diffs = compare.compare_tables(old, read_table(tmp / exp.name / f"{metric}.csv"), tol)
        for d in diffs:
            say(f"{exp.name}/{metric}.csv row {d['row']} {d['column']}: obtained "
                f"{d['obtained']}, expected {d['expected']}, difference {d['difference']}")
        differing += len(diffs)
        if spec.join:
            try:
                reference.with_reference(reference.view(old, spec), spec, allow_unmatched=True)
            except ReferenceJoinError as exc:
                say(f"{exp.name}/{metric}.csv: {exc}")
                differing += 1
        if not diffs:
            say(f"{exp.name}/{metric}.csv: {len(new)} rows match")
    for name in sorted(n for n in result.figures if n not in machine):   # (hashes: above)
        stored_as = [stored_dir / "figures" / f"{name}.{fmt}" for fmt in ("png", "svg", "pdf")]
        if not any(f.is_file() and f.stat().st_size > 0 for f in stored_as):
            say(f"{exp.name}/figures/{name}.png: missing from the stored results")
            differing += 1
    return differing
