"""Parsing what the commands are given (kept apart so that cli/main.py holds the commands)."""

from __future__ import annotations

from pathlib import Path

from estim.cli.group import fail
from estim.config.overrides import OVERRIDE_KEY, parse_override
from estim.errors import UsageError


def overrides(given: dict, runs: int | None, seed: int | None) -> dict:
    """The key-path overrides of a command line with ``--runs`` and ``--seed`` among them;
    an option that sets a key an override also sets is a usage error."""
    options = {k: v for k, v in (("monte_carlo.runs", runs), ("monte_carlo.seed", seed))
               if v is not None}
    for key in options:
        if key in given:
            fail(f"{key} is given both as an override and as --{key.split('.')[1]}; give it "
                 "once")
    return {**given, **options}


def shard(text_: str) -> tuple[int, int]:
    """``K/N`` with ``1 <= K <= N`` (ASCII digits only)."""
    k, sep, n = text_.partition("/")
    if not (sep and k.isascii() and n.isascii() and k.isdigit() and n.isdigit()
            and 1 <= int(k) <= int(n)):
        fail(f"--shard {text_!r}: expected K/N with 1 <= K <= N")
    return int(k), int(n)


def metrics_help() -> str:
    """The metrics of the registered analyses, for ``estim table --help``."""
    from estim.engine import runner

    lines = ["\b", "Metrics (analyses that write them):"]
    for metric, specs in sorted(runner.table_specs().items()):
        titles = {s.title for s in specs.values() if s.title}
        title = titles.pop() if len(titles) == 1 else "(each analysis' own table of that name)"
        lines.append(f"  {metric:<11} {title} [{', '.join(sorted(specs))}]")
    return "\n".join(lines)


def split_arguments(args) -> tuple[list[Path], dict]:
    """Config paths and ``key.path=value`` overrides, in any order on a command line; an
    argument that names an existing file is a path even if it holds '='. A malformed
    override is a ``UsageError``."""
    paths, overrides = [], {}
    for arg in args:
        text_ = str(arg)
        key = text_.partition("=")[0]
        if "=" in text_ and not _exists(text_) and OVERRIDE_KEY.fullmatch(key.strip()):
            k, v = parse_override(text_)
            if k in overrides:
                raise UsageError(f"{text_!r}: {k} is already set on this command line "
                                 f"(to {overrides[k]!r}); give it once")
            overrides[k] = v
        elif "=" in text_ and not _exists(text_):
            raise UsageError(f"{text_!r}: expected a config file or key.path=value (list "
                             "items by index)")
        elif ":" in text_ and not _exists(text_) and "." in text_.partition(":")[0] \
                and OVERRIDE_KEY.fullmatch(text_.partition(":")[0].strip()):
            k, _, v = text_.partition(":")
            raise UsageError(f"{text_!r}: no such config file; an override is written "
                             f"key.path=value ({k.strip()}={v.strip()})")
        else:
            paths.append(Path(text_))
    return paths, overrides


def _exists(text_: str) -> bool:
    """Whether ``text_`` names an existing file (a name too long to be a path does not)."""
    try:
        return Path(text_).exists()
    except OSError:
        return False
