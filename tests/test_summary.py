"""Results prose generated from the stored tables (estim.report.summary, ``estim summary``): the
README's results sections quote only generated blocks, and a changed stored number makes
them stale."""

import shutil
from pathlib import Path

import pandas as pd
from click.testing import CliRunner

from estim.cli.main import main
from estim.config.registry import ANALYSES
from estim.report import summary

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def blocks(text: str) -> list[str]:
    return [m.group("name") for m in summary.BLOCK.finditer(text)]


def test_readme_results_blocks_match_the_stored_tables():
    text = README.read_text()
    names = blocks(text)
    stored = {p.parent.name for p in (ROOT / "results").glob("*/manifest.json")}
    assert set(names) == stored, "every stored experiment has one block in the README"
    _, stale = summary.refresh(text, ROOT / "results", ANALYSES)
    assert stale == [], f"stale README blocks {stale}: run 'estim summary --readme README.md'"


def test_changing_one_stored_number_makes_its_block_stale(tmp_path):
    results = tmp_path / "results"
    shutil.copytree(ROOT / "results", results, ignore=shutil.ignore_patterns("*.png", "*.svg"))
    text = README.read_text()
    assert summary.refresh(text, results, ANALYSES)[1] == []
    path = results / "mosfet_saturation" / "claims.csv"
    df = pd.read_csv(path)
    df.loc[0, "ratio"] = df["ratio"].max() * 1.5          # one number, outside the range
    df.to_csv(path, index=False)
    _, stale = summary.refresh(text, results, ANALYSES)
    assert stale == ["mosfet_saturation"]
    out = CliRunner().invoke(main, ["summary", "--results", str(results), "--readme",
                                    str(README), "--check"])
    assert out.exit_code == 1 and "mosfet_saturation" in out.output


def test_a_flipped_verdict_changes_the_counts(tmp_path):
    results = tmp_path / "results"
    shutil.copytree(ROOT / "results" / "dipole_literal", results / "dipole_literal")
    before = summary.experiment(results / "dipole_literal", ANALYSES)
    path = results / "dipole_literal" / "claims.csv"
    df = pd.read_csv(path)
    for column in ("verdict", "verdict_family"):
        df.loc[0, column] = "fails" if df.loc[0, column] != "fails" else "holds"
    df.to_csv(path, index=False)
    after = summary.experiment(results / "dipole_literal", ANALYSES)
    assert before[1] != after[1]


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
