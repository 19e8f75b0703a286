"""Every code block of the README and of docs/ is run by a test: the command lines here (each
`estim` line is parsed by the command line itself, and the read-only ones are run on the
stored results), the guides' files by tests/test_guide.py, the package tree by
tests/test_layout.py. A block no test runs fails this file: a new block needs a runner."""

import re
import shlex
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from estim.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)

ELSEWHERE = {
    ("extending.md", "python"): "tests/test_guide.py (the model, the filter, From Python)",
    ("extending.md", "yaml"): "tests/test_guide.py (the guide's config, run)",
    ("your-circuit.md", "spice"): "tests/test_guide.py (the netlist, run)",
    ("your-circuit.md", "yaml"): "tests/test_guide.py (the netlist's config, run)",
    ("your-data.md", "yaml"): "tests/test_guide.py (the measured record's config, run)",
    ("layout.md", ""): "tests/test_layout.py (the tree against the package and the contract)",
}
"""Blocks another test runs, by page and language."""

READ_ONLY = ("table", "summary", "list", "validate", "settings")
"""Commands that only read the stored results or configs: run as written."""


def blocks() -> list[tuple[str, str, str]]:
    return [(page.name, lang, body) for page in PAGES
            for lang, body in FENCE.findall(page.read_text())]


def command_lines(body: str) -> list[list[str]]:
    """The commands of a shell block, each ``&&``-joined part apart, comments dropped."""
    out = []
    for line in body.splitlines():
        command: list[str] = []
        for token in shlex.split(line, comments=True) + ["&&"]:
            if token == "&&":
                if command:
                    out.append(command)
                command = []
            else:
                command.append(token)
    return out


def test_every_block_has_a_runner():
    for page, lang, body in blocks():
        if (page, lang) in ELSEWHERE:
            continue
        if lang == "yaml" and page == "commands.md":
            continue                                # test_the_sweep_block_validates
        assert lang == "", f"{page}: a {lang} block no test runs:\n{body[:200]}"
        assert command_lines(body), f"{page}: a block that is not command lines:\n{body}"


def shell_commands() -> list[tuple[str, list[str]]]:
    return [(page, cmd) for page, lang, body in blocks() if lang == "" and
            (page, lang) not in ELSEWHERE for cmd in command_lines(body)]


@pytest.mark.parametrize("page,argv", shell_commands(),
                         ids=lambda v: " ".join(v) if isinstance(v, list) else v)
def test_the_command_lines_are_valid_and_the_read_only_ones_run(page, argv, monkeypatch):
    """pip and pytest lines are what .ci/run runs; every `estim` line parses (its command,
    options and arguments exist: click's own parsing), and one that only reads runs on the
    stored results and exits 0."""
    if argv[0] in ("pip", "pytest", "python3", "."):
        assert argv[0] != "pip" or argv[1] == "install"
        return
    assert argv[0] == "estim", (page, argv)
    args = argv[1:]
    monkeypatch.chdir(ROOT)
    with main.make_context("estim", list(args), resilient_parsing=False) as ctx:
        command = main.get_command(ctx, args[0])
        assert command is not None, (page, argv)
        command.make_context(args[0], list(args[1:]), parent=ctx)
    for name in (a for a in args[1:] if a.endswith(".yaml")):
        assert (ROOT / name).is_file(), (page, name)
    if args[0] in READ_ONLY:
        out = CliRunner().invoke(main, args)
        assert out.exit_code == 0, (page, argv, out.output[-500:])


def test_the_sweep_block_validates():
    """docs/commands.md's sweep block, added to configs/mosfet_saturation.yaml, is a valid
    config (`estim validate`)."""
    from estim.config.loading import load_data, sweep_cells

    body = next(b for page, lang, b in blocks() if page == "commands.md" and lang == "yaml")
    spec = yaml.safe_load((ROOT / "configs" / "mosfet_saturation.yaml").read_text())
    spec.update(yaml.safe_load(body))
    exp = load_data(spec, "mosfet_saturation.yaml", "mosfet_saturation")
    assert len(list(sweep_cells(exp))) == 3 * 2


def _duration(seconds: float) -> str:
    minutes, rest = divmod(round(seconds), 60)
    return f"{minutes} min {rest} s"


def _memory(mb: float) -> str:
    return f"{mb / 1024:.1f} GB" if mb >= 1024 else f"{round(mb)} MB"


def test_the_quick_start_times_are_the_measured_ones():
    """README: the quick start's wall times and peak memory are bench/quickstart.csv's (made
    by bench/bench_quickstart.py in a fresh clone and virtual environment), and git stayed
    clean after the first command there."""
    import csv

    rows = list(csv.DictReader((ROOT / "bench" / "quickstart.csv").open()))
    readme = (ROOT / "README.md").read_text()
    block = readme[readme.index("<!-- quickstart -->"):readme.index("<!-- /quickstart -->")]
    for row in rows:
        line = next(r for r in block.splitlines() if f"`{row['command']}`" in r)
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[1:] == [_duration(float(row["wall_s"])), _memory(float(row["peak_mb"]))]
    assert rows[0]["git_status_clean"] == "yes"
    assert [row["exit"] for row in rows] == ["0", "0"]       # both commands passed
    assert f"commit {rows[0]['commit']}" in readme and rows[0]["machine"] in readme


def test_the_deviations_index_lists_every_entry_of_the_pages():
    """docs/deviations.md is what docs/deviation_index.py makes of the chapter pages: one
    row per D-number, each linking to its page's anchor; every number is on one page."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("deviation_index",
                                                  ROOT / "docs" / "deviation_index.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert (ROOT / "docs" / "deviations.md").read_text() == module.index(), (
        "stale: run python docs/deviation_index.py")
    numbers = [n for page in module.PAGES for n, _ in module.entries(page)]
    assert len(numbers) == len(set(numbers)) >= 77
    anchors = re.findall(r'<a id="d(\d+)"></a>', "".join(
        (ROOT / "docs" / "deviations" / f"{p}.md").read_text() for p in module.PAGES))
    assert sorted(map(int, anchors)) == sorted(numbers)


def test_the_speed_page_is_the_benchmarks_output_files():
    """docs/speed.md is what bench/speed_page.py makes of bench/results/*.csv: every table on
    it is a benchmark's file, with the command and machine that made it."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("speed_page", ROOT / "bench" / "speed_page.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert (ROOT / "docs" / "speed.md").read_text() == module.page(), (
        "stale: run python bench/speed_page.py")
    text = (ROOT / "docs" / "speed.md").read_text()
    assert text.count("- command: `") == text.count("\n## ") >= 8
