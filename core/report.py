"""One self-contained HTML page of stored results (``estim report``): per experiment its
tables (ours beside the printed values and their ratio where there are any; rows where a
claim fails in red), every figure embedded as a data URI, the deviations its config cites,
and the seeds and versions of its manifest. :func:`sections` reads a results folder;
:func:`page` writes no file.
"""

from __future__ import annotations

import base64
import html
import re
from dataclasses import dataclass, field

from estim import lazy, tables

pd = lazy.load("pandas")

STYLE = """
body { font-family: sans-serif; margin: 2em; max-width: 110em; color: #222; }
h1 { font-size: 1.6em; } h2 { margin-top: 2.2em; border-bottom: 1px solid #bbb; }
table { border-collapse: collapse; font-size: 0.8em; margin: 0.6em 0 1.2em; }
th, td { border: 1px solid #ccc; padding: 0.15em 0.45em; text-align: right; }
th { background: #f0f0f0; } td.text { text-align: left; }
tr.fail td { background: #f8d0d0; } .meta { color: #555; font-size: 0.85em; }
figure { display: inline-block; margin: 0.5em; } figure img { max-width: 46em; }
figcaption { font-size: 0.8em; color: #555; } pre { white-space: pre-wrap; font-size: 0.85em; }
nav a { margin-right: 0.8em; }
"""


MEDIA = {"png": "image/png", "svg": "image/svg+xml"}


@dataclass
class Section:
    """One experiment's part of the page."""

    name: str
    title: str
    manifest: dict
    tables: list[tuple[str, pd.DataFrame]] = field(default_factory=list)
    figures: list[tuple[str, bytes]] = field(default_factory=list)   # (file name, bytes)
    deviations: list[tuple[str, str]] = field(default_factory=list)


def deviation_entries(markdown: str) -> dict[str, str]:
    """``{"D12": text}`` from docs/deviations.md: each entry runs from its bold ``**D12.``
    to the next entry or heading."""
    out: dict[str, str] = {}
    current, lines = None, []
    for line in markdown.splitlines():
        match = re.match(r"\*\*(D\d+)\.", line)
        if match or line.startswith("#"):
            if current:
                out[current] = "\n".join(lines).strip()
            current, lines = (match.group(1), [line]) if match else (None, [])
        elif current:
            lines.append(line)
    if current:
        out[current] = "\n".join(lines).strip()
    return out


def cited(text_: str) -> list[str]:
    """The deviation numbers a config's text cites (``D12``, ``D44-D47``), in order."""
    found: list[str] = []
    for a, b in re.findall(r"\bD(\d+)(?:\s*[-\u2013]\s*D?(\d+))?\b", text_):
        for n in range(int(a), int(b or a) + 1):
            if f"D{n}" not in found:
                found.append(f"D{n}")
    return found


def _table(caption: str, df: pd.DataFrame) -> str:
    failing = (df["verdict"].astype(str) == "fails") if "verdict" in df else None
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    rows = []
    for i, row in enumerate(df.itertuples(index=False)):
        cells = "".join(
            f'<td class="{"text" if isinstance(v, str) else "num"}">'
            f"{html.escape(tables.number(v))}</td>" for v in row)
        cls = ' class="fail"' if failing is not None and bool(failing.iloc[i]) else ""
        rows.append(f"<tr{cls}>{cells}</tr>")
    return (f"<h3>{html.escape(caption)}</h3><table><thead><tr>{head}</tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table>")


def _meta(manifest: dict) -> str:
    versions = manifest.get("versions") or {}
    parts = [f"seed {manifest.get('seed')}", f"runs {manifest.get('runs')}",
             f"wall time {manifest.get('wall_time_s')} s",
             f"command <code>{html.escape(str(manifest.get('command', '')))}</code>"]
    if manifest.get("git_commit"):
        parts.append(f"commit {html.escape(str(manifest['git_commit']))}")
    if manifest.get("overrides"):
        parts.append(f"overrides {html.escape(str(manifest['overrides']))}")
    parts.append("versions " + html.escape(", ".join(f"{k} {v}" for k, v in
                                                      sorted(versions.items()))))
    return '<p class="meta">' + "; ".join(parts) + "</p>"


def page(title: str, sections: list[Section]) -> str:
    """The whole page as one string (UTF-8 HTML5, no external resources)."""
    nav = "".join(f'<a href="#{html.escape(s.name)}">{html.escape(s.name)}</a>'
                  for s in sections)
    body = []
    for s in sections:
        part = [f'<h2 id="{html.escape(s.name)}">{html.escape(s.name)}: '
                f"{html.escape(s.title)}</h2>", _meta(s.manifest)]
        part += [_table(caption, df) for caption, df in s.tables]
        skipped = []
        for name, data in s.figures:
            kind = MEDIA.get(name.rpartition(".")[2])
            if kind is None:
                skipped.append(name)
                continue
            encoded = base64.b64encode(data).decode("ascii")
            part.append(f'<figure><img alt="{html.escape(name)}" '
                        f'src="data:{kind};base64,{encoded}"><figcaption>{html.escape(name)}'
                        "</figcaption></figure>")
        if skipped:
            part.append('<p class="meta">Not shown (a browser page cannot embed PDF as an '
                        "image; re-run with --figure-format png or svg): "
                        + html.escape(", ".join(skipped)) + "</p>")
        if s.deviations:
            part.append("<h3>Deviations this config cites (docs/deviations.md)</h3>")
            part += [f"<pre>{html.escape(text_)}</pre>" for _, text_ in s.deviations]
        body.append("\n".join(part))
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>"
            f"<h1>{html.escape(title)}</h1><nav>{nav}</nav>\n" + "\n".join(body)
            + "\n</body></html>\n")


def sections(results, deviations_text: str, config_dir, analyses: dict) -> list[Section]:
    """One :class:`Section` per experiment stored under ``results``: its tables (joined to
    the printed values where there are any), figures, and the deviations (from the text of
    docs/deviations.md) its config in ``config_dir`` cites. A manifest that cannot be read
    is a ``UsageError`` naming it."""
    from pathlib import Path

    from estim.errors import ReferenceJoinError, UsageError
    from estim.io import read_manifest, read_table

    entries = deviation_entries(deviations_text) if deviations_text else {}
    out = []
    for manifest_path in sorted(Path(results).glob("*/manifest.json")):
        folder = manifest_path.parent
        manifest = read_manifest(folder)
        if manifest is None or not isinstance(manifest.get("config"), dict):
            raise UsageError(f"{manifest_path}: not a readable estim manifest")
        config = manifest["config"]
        analysis = analyses.get(config.get("analysis", "estimation"))
        section = Section(folder.name, str(config.get("title") or ""), manifest)
        for metric, spec in (analysis.TABLES.items() if analysis else []):
            path = folder / spec.file
            if not path.is_file():
                continue
            df = tables.view(read_table(path, spec), spec)
            if spec.join and "table_id" in df and df["table_id"].astype(str).str.len().any():
                try:
                    df = tables.with_reference(df, spec, allow_unmatched=True)
                except ReferenceJoinError:
                    pass
            section.tables.append((f"{metric}: {spec.title}", df))
        for figure in sorted((folder / "figures").glob("*")):
            if figure.suffix in (".png", ".svg", ".pdf"):
                section.figures.append((figure.name, figure.read_bytes()))
        source = Path(config_dir) / f"{folder.name}.yaml" if config_dir else None
        text_ = source.read_text() if source is not None and source.is_file() else ""
        section.deviations = [(d, entries[d]) for d in cited(text_) if d in entries]
        out.append(section)
    return out
