"""``estim list``: the configs, read as far as their heads (:mod:`estim.config.header`), so
the command starts as fast as Python and click do (no numpy, no analyses)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from estim.cli import project
from estim.cli.group import fail
from estim.config.header import read_head


def table_span(ids: list[str]) -> str:
    """The thesis tables a config reproduces, a run of one chapter's consecutive tables
    written as a range: ``5.1-5.12``; ``no printed table`` for none."""
    if not ids:
        return "no printed table"
    parts = [i.split(".") for i in ids]
    if len(ids) > 2 and all(len(p) == 2 and p[0] == parts[0][0] and p[1].isdigit()
                            for p in parts):
        numbers = [int(p[1]) for p in parts]
        if numbers == list(range(numbers[0], numbers[0] + len(numbers))):
            return f"{ids[0]}-{ids[-1]}"
    return ", ".join(ids)


@click.command(name="list")
@click.option("--json", "as_json", is_flag=True,
              help="One JSON list: name, group, path, analysis, tables and title of each.")
def list_configs(as_json) -> None:
    """Show the configs, grouped as estim reproduce runs them (configs/; studies/ and
    netlist/ with --all), with the thesis tables each reproduces and its title (each
    config's head only: estim validate checks the rest)."""

    where = project.locate()
    groups = [("configs", "estim reproduce", where.config_dir)]
    groups += [(f"configs/{extra}", "estim reproduce --all", where.config_dir / extra)
               for extra in where.EXTRA]
    entries = []
    for group, runs, folder in groups:
        heads = [read_head(path) for path in sorted(folder.glob("*.yaml"))]
        names = [head.name for head in heads]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            fail(f"{folder}: two configs share the name {dupes[0]!r}")
        for head in heads:
            entries.append({"name": head.name, "group": group, "run_by": runs,
                            "path": str(Path(head.source).relative_to(where.config_dir.parent))
                            if where.root is not None else head.source,
                            "analysis": head.analysis, "tables": list(head.reproduces),
                            "title": head.title})
    if as_json:
        click.echo(json.dumps(entries, indent=1))
        return
    click.echo(where.describe(), err=True)
    width = max((len(e["name"]) for e in entries), default=0)
    span = max((len(table_span(e["tables"])) for e in entries), default=0)
    for group, runs, _ in groups:
        members = [e for e in entries if e["group"] == group]
        if not members:
            continue
        click.echo(f"\n{group}/ ({runs}, {len(members)} configs)")
        for e in members:
            click.echo(f"  {e['name']:<{width}}  {table_span(e['tables']):<{span}}  "
                       f"{e['title']}")
