"""Results prose generated from the stored tables (estim.report.summary, ``estim summary``):
docs/results.md quotes only generated blocks, the README and the docs' home the generated
headline table, and a changed stored number makes them stale."""

import shutil
from pathlib import Path

import pandas as pd
from click.testing import CliRunner

from estim.cli.main import main
from estim.config.registry import ANALYSES
from estim.report import overview, summary

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "docs" / "results.md"
GENERATED = ("README.md", "docs/index.md", "docs/results.md")
"""Every Markdown file with generated blocks."""


def blocks(text: str) -> list[str]:
    return [m.group("name") for m in summary.BLOCK.finditer(text)]


def test_results_blocks_match_the_stored_tables():
    names = blocks(README.read_text())
    stored = {p.parent.name for p in (ROOT / "results").glob("*/manifest.json")}
    assert set(names) == stored, "every stored experiment has one block in docs/results.md"
    for name in GENERATED:
        text = (ROOT / name).read_text()
        _, stale = summary.refresh(text, ROOT / "results", ANALYSES)
        assert stale == [], f"stale blocks {stale}: run 'estim summary --readme {name}'"


def test_the_headline_table_names_every_row_and_counts_the_stored_family_verdicts():
    """README and docs/index.md: one row per thesis or paper table of summary.HEADLINE, its
    counts those of the stored claims table."""
    for name in ("README.md", "docs/index.md"):
        text = (ROOT / name).read_text()
        body = summary.HEADLINE_BLOCK.search(text).group("body")
        rows = [r for r in body.splitlines() if r.startswith("| ") and "`" in r]
        assert len(rows) == len(summary.HEADLINE)
    row = next(r for r in rows if "`mosfet_saturation`" in r)
    df = pd.read_csv(ROOT / "results" / "mosfet_saturation" / "claims.csv")
    ekf = df[df["claim"] == "EKF RMSE < RLS RMSE"]["verdict_family"]
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3:7] == [str((ekf == v).sum()) for v in ("holds", "fails", "undecided")] + [
        str(len(ekf))]


def test_changing_one_stored_number_makes_its_block_stale(tmp_path, rehash):
    results = tmp_path / "results"
    shutil.copytree(ROOT / "results", results, ignore=shutil.ignore_patterns("*.png", "*.svg"))
    text = README.read_text()
    assert summary.refresh(text, results, ANALYSES)[1] == []
    path = results / "mosfet_saturation" / "claims.csv"
    df = pd.read_csv(path)
    df.loc[0, "ratio"] = df["ratio"].max() * 1.5          # one number, outside the range
    df.to_csv(path, index=False)
    rehash(path.parent)
    _, stale = summary.refresh(text, results, ANALYSES)
    assert stale == ["mosfet_saturation"]
    out = CliRunner().invoke(main, ["summary", "--results", str(results), "--readme",
                                    str(README), "--check"])
    assert out.exit_code == 1 and "mosfet_saturation" in out.output


def test_a_flipped_verdict_changes_the_counts(tmp_path, rehash):
    results = tmp_path / "results"
    shutil.copytree(ROOT / "results" / "dipole_literal", results / "dipole_literal")
    before = summary.experiment(results / "dipole_literal", ANALYSES)
    path = results / "dipole_literal" / "claims.csv"
    df = pd.read_csv(path)
    for column in ("verdict", "verdict_family"):
        df.loc[0, column] = "fails" if df.loc[0, column] != "fails" else "holds"
    df.to_csv(path, index=False)
    rehash(path.parent)
    after = summary.experiment(results / "dipole_literal", ANALYSES)
    assert before[1] != after[1]


def test_a_fragile_verdict_is_counted_beside_its_claim(tmp_path):
    """A cell results/fragile_verdicts.csv names is counted as fragile on its claim's line
    in the summary and flagged in the report's summary table; other claims are not."""
    from estim.report import fragility, html

    results = tmp_path / "results"
    shutil.copytree(ROOT / "results" / "dipole_literal", results / "dipole_literal")
    df = pd.read_csv(results / "dipole_literal" / "claims.csv")
    row = df.iloc[0]
    pd.DataFrame([{"config": "dipole_literal", "claim": row["claim"], "cell": row["cell"],
                   "verdict": row["verdict"], "verdict_moved": "undecided",
                   "verdict_family": row["verdict_family"],
                   "verdict_family_moved": "undecided", "variant": "Zen kernels"}],
                 columns=fragility.COLUMNS).to_csv(results / fragility.FILE, index=False)
    lines = summary.experiment(results / "dipole_literal", ANALYSES)
    marked = [line for line in lines if "fragile" in line]
    assert len(marked) == 1 and f"`{row['claim']}`" in marked[0]
    assert "fragile in 1 (a verdict another machine's arithmetic moves)" in marked[0]
    (section,) = html.sections(results, "", ROOT / "configs", ANALYSES)
    flags = overview.summary(section)["flags"]
    assert any("1 fragile claim verdicts" in flag for flag in flags)


def test_summary_command_prints_every_experiment():
    out = CliRunner().invoke(main, ["summary", "--results", str(ROOT / "results")])
    assert out.exit_code == 0, out.output
    for name in ("mosfet_saturation", "passive_network", "kronecker_burden"):
        assert f"**{name}**" in out.output


def test_span_and_number_formats():
    assert summary.span([0.391, 0.52, float("nan")]) == "0.391–0.52"
    assert summary.span([1.0, float("inf")]) == "1–inf"
    assert summary.span([2.0, 2.0]) == "2"
    assert summary.number(float("nan")) == "nan"


def test_the_stored_fragile_verdicts_are_those_of_the_stored_claims():
    """results/fragile_verdicts.csv (docs/studies/verdict_fragility.py) names cells of the
    stored claims tables with their stored verdicts: re-made results that leave it stale
    fail here until the study is run again."""
    from estim.report import fragility

    table = fragility.read(ROOT / "results")
    assert (ROOT / "results" / fragility.FILE).is_file()
    for _, row in table.iterrows():
        claims = pd.read_csv(ROOT / "results" / row["config"] / "claims.csv")
        hit = claims[(claims["claim"] == row["claim"]) & (claims["cell"] == row["cell"])]
        assert len(hit) == 1, row.to_dict()
        assert hit["verdict"].item() == row["verdict"], row.to_dict()
        assert hit["verdict_family"].item() == row["verdict_family"], row.to_dict()
        assert (row["verdict_moved"], row["verdict_family_moved"]) != (
            row["verdict"], row["verdict_family"])


def test_the_conduction_twin_differs_in_the_verdicts_the_readme_says():
    """docs/results.md (circuits from netlists): the netlist twin of mosfet_conduction has another
    verdict in 1 of the 12 cells of `EKF RMSE < RLS RMSE` and the same in every other."""
    text = " ".join((ROOT / "docs" / "results.md").read_text().split())
    assert "another verdict in 1 of the 12 cells of `EKF RMSE < RLS RMSE`" in text
    a = pd.read_csv(ROOT / "results" / "mosfet_conduction" / "claims.csv")
    b = pd.read_csv(ROOT / "results" / "mosfet_netlist_conduction" / "claims.csv")
    both = a.merge(b, on=["claim", "cell"], suffixes=("", "_twin"), validate="1:1")
    assert len(both) == len(a) == len(b)
    differ = both[both["verdict"] != both["verdict_twin"]]
    assert set(differ["claim"]) == {"EKF RMSE < RLS RMSE"} and len(differ) == 1
    assert (both["claim"] == "EKF RMSE < RLS RMSE").sum() == 12


def test_docs_claims_fragile_section_is_the_stored_table():
    """docs/claims.md "Fragile verdicts": its counts, read back from the stored table."""
    from estim.report import fragility

    text = " ".join((ROOT / "docs" / "claims.md").read_text().split())
    table = fragility.read(ROOT / "results")
    header = (ROOT / "results" / fragility.FILE).read_text().splitlines()[0]
    assert "over 16 configs" in header and "(16 of them, `dipole_field` among them)" in text
    per_config = table["config"].value_counts().to_dict()
    assert per_config == {"mosfet_netlist_conduction": 1}
    assert set(table["claim"]) == {"EKF RMSE < RLS RMSE"}
    assert "1 fragile cell, of `EKF RMSE < RLS RMSE` in the netlist twin" in text
    assert (table["verdict"] == table["verdict_moved"]).all()
    assert (table["verdict_family"] != table["verdict_family_moved"]).all()
    assert "its own verdict stays and its family verdict moves" in text
    diverged = [pd.read_csv(ROOT / "results" / r["config"] / "claims.csv").set_index(
        ["claim", "cell"]).loc[(r["claim"], r["cell"]), "diverged_better"]
        for _, r in table.iterrows()]
    assert diverged == [23] and "diverges in 23 of 30 runs" in text


def test_summary_json_is_the_text_as_data():
    """estim summary --json: per experiment and claim the same counts as the text lines."""
    import json
    import re

    text = CliRunner().invoke(main, ["summary", "--results", str(ROOT / "results")])
    data = json.loads(CliRunner().invoke(main, ["summary", "--json", "--results",
                                                str(ROOT / "results")]).output)
    assert {e["name"] for e in data} == {
        p.parent.name for p in (ROOT / "results").glob("*/manifest.json")}
    counted = 0
    for entry in data:
        for c in entry["claims"]:
            pattern = (rf"- `{re.escape(c['claim'])}`: holds {c['holds']}, fails {c['fails']}, "
                       rf"undecided {c['undecided']} of {c['cells']} cells")
            block = text.output[text.output.index(f"**{entry['name']}**"):]
            assert re.search(pattern, block), (entry["name"], c["claim"])
            counted += 1
    assert counted > 100
    conduction = next(e for e in data if e["name"] == "mosfet_conduction")
    assert sum(c["fragile"] for c in conduction["claims"]) == 0
    twin = next(e for e in data if e["name"] == "mosfet_netlist_conduction")
    assert sum(c["fragile"] for c in twin["claims"]) == 1
    bad = CliRunner().invoke(main, ["summary", "--json", "--readme", "README.md"])
    assert bad.exit_code == 2


def test_more_runs_do_not_settle_the_fragile_cells_as_docs_claims_says():
    """docs/claims.md: at 100 runs per cell 1 cell of EKF RMSE < RLS RMSE still moves under
    another arithmetic, in the twin, as 1 does at 30 runs (the study's stored tables)."""
    from estim.report import fragility

    text = " ".join((ROOT / "docs" / "claims.md").read_text().split())
    path = ROOT / "docs" / "studies" / "verdict_fragility_runs100.csv"
    table = pd.read_csv(path, comment="#")
    assert list(table.columns) == fragility.COLUMNS
    assert set(table["claim"]) == {"EKF RMSE < RLS RMSE"}
    assert table["config"].value_counts().to_dict() == {"mosfet_netlist_conduction": 1}
    stored = fragility.read(ROOT / "results")
    assert len(stored) == 1 and set(stored["cell"]) != set(table["cell"])
    assert ("1 cell of `EKF RMSE < RLS RMSE` still moves, in the twin (another cell than at "
            "30 runs), as 1 does at 30 runs") in text


def test_markdown_is_rendered_on_a_terminal_and_kept_when_piped(capsys):
    """``estim summary`` and ``estim settings`` print Markdown: rich renders it on a terminal
    (no ``**`` or table rule left), and it stays Markdown when piped."""
    from estim.cli import output

    text = "**cco**: a title\n- `claim`: holds 2\n\n| key | type |\n|---|---|\n| Q | float |\n"
    output.markdown(text, terminal=False)
    assert capsys.readouterr().out == text
    output.markdown(text, terminal=True)
    shown = capsys.readouterr().out
    assert "cco" in shown and "float" in shown
    assert "**" not in shown and "|---|" not in shown and "\x1b[" in shown


def test_failing_cells_are_told_apart_by_what_was_printed():
    """A failing claim cell is a disagreement when the printed values of both estimators
    say the claim holds there, a finding when they fail it too or one side has no printed
    value; the headline's reading says so."""
    from estim.report.html import Section

    claims = pd.DataFrame({
        "claim": ["EKF RMSE < RLS RMSE"] * 3 + ["EKF RMSE < measurement RMSE"],
        "cell": ["f=1", "f=2", "f=3", "f=1"], "better": ["EKF"] * 4,
        "worse": ["RLS"] * 3 + ["measurement"], "verdict": ["fails"] * 4,
        "verdict_family": ["fails", "fails", "holds", "fails"]})
    rmse = pd.DataFrame({
        "f": [1, 1, 2, 2, 3, 3, 1], "estimator": ["EKF", "RLS"] * 3 + ["measurement"],
        "rmse": [0.5] * 7, "thesis_rmse": [0.1, 0.2, 0.3, 0.2, 0.1, 0.2, float("nan")]})
    section = Section("x", "t", {}, tables=[("rmse", "rmse", rmse), ("claims", "c", claims)])
    assert overview.fail_kinds(section) == {overview.AGAINST: 1, overview.AS_PRINTED: 1,
                                            overview.NOT_PRINTED: 1}
    assert overview.fail_kinds(section, "EKF RMSE < RLS RMSE")[overview.NOT_PRINTED] == 0
    row = {"holds": 1, "fails": 2, "undecided": 0, "cells": 3}
    assert overview.reading(row, overview.fail_kinds(section, "EKF RMSE < RLS RMSE")) == (
        "holds in 1 of 3 cells; fails in 2, 1 of them where the printed values say it holds")
    assert overview.reading({"holds": 3, "fails": 0, "undecided": 0, "cells": 3}, {}) == (
        "holds in every cell (3)")
