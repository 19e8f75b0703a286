"""Write docs/deviations.md, the index of the deviation pages of docs/deviations/: one row
per D-number with its page and its title, read from the pages themselves.

    python docs/deviation_index.py

tests/test_docs_blocks.py fails when the index is stale.
"""

from __future__ import annotations

import re
from pathlib import Path

DOCS = Path(__file__).resolve().parent
PAGES = ("chapter-2", "chapter-3", "chapter-4", "chapter-5", "netlists", "papers")
"""The deviation pages, in the order the index lists them (the thesis' chapter order)."""

INTRO = """\
# Deviations from the thesis, and choices where it is silent

Every entry names the equation or table, what the thesis prints, what estim does, and why.
Where a choice is a number, it is a config value (the key is given), so it can be changed
and its effect measured with `estim run` and `estim table ... --thesis`. Nothing here was
tuned to bring a result closer to the thesis. "Thesis note N" cites [the list of the
thesis' inconsistencies](thesis-notes.md); each entry also says what the note found.

The entries are on one page per chapter:

{pages}

A config, a docstring or `estim report` cites an entry by its number (D12); the table below
finds it.

| entry | page | what it decides |
|---|---|---|
"""


def entries(page: str) -> list[tuple[int, str]]:
    """``(number, title)`` of every entry of a page, in its order: the bold sentence that
    opens it."""
    text = (DOCS / "deviations" / f"{page}.md").read_text()
    return [(int(n), " ".join(title.split()))
            for n, title in re.findall(r'<a id="d(\d+)"></a>\n\*\*D\1\. (.*?)\*\*', text,
                                       re.S)]


def title(page: str) -> str:
    first = (DOCS / "deviations" / f"{page}.md").read_text().splitlines()[0]
    return first.removeprefix("# Deviations: ")


def index() -> str:
    """The whole text of docs/deviations.md."""
    links = "\n".join(f"- [{title(p)}](deviations/{p}.md)" for p in PAGES)
    rows = [f"| [D{n}](deviations/{p}.md#d{n}) | {title(p).split(':')[0]} | "
            f"{t.replace('|', chr(92) + '|')} |"
            for p in PAGES for n, t in entries(p)]
    return INTRO.format(pages=links) + "\n".join(rows) + "\n"


if __name__ == "__main__":
    (DOCS / "deviations.md").write_text(index())
    print("docs/deviations.md written")
