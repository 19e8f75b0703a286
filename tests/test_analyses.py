"""One contract over every registered analysis, and the cross-machine promise of check."""

from pathlib import Path

import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from estim.cli.main import main
from estim.config.loading import parse_data, quick_data
from estim.config.registry import ANALYSES
from estim.engine import compare
from estim.experiments.shared import claims

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = (sorted((ROOT / "configs").glob("*.yaml"))
           + sorted((ROOT / "configs" / "studies").glob("*.yaml")))


def shipped(analysis: str) -> list[Path]:
    return [p for p in CONFIGS
            if (yaml.safe_load(p.read_text()).get("analysis") or "estimation") == analysis]


def tiny_of(path: Path) -> dict:
    return quick_data(parse_data(yaml.safe_load(path.read_text()), str(path), path.stem,
                                 plan=False))


def write(tmp_path: Path, spec: dict, name: str) -> Path:
    """``spec`` as ``name.yaml``, named ``name`` (its results folder)."""
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump({**spec, "name": name}))
    return path


def test_every_analysis_has_a_shipped_config():
    for name in ANALYSES:
        assert shipped(name), f"analysis {name!r} has no config in configs/"


@pytest.mark.parametrize("name", sorted(ANALYSES))
def test_analysis_contract(tmp_path, name):
    module = ANALYSES[name]
    for attr in ("SCHEMA", "TABLES", "prepare", "work_units", "run", "printout", "tiny"):
        assert hasattr(module, attr), f"{name} lacks {attr}"
    spec = tiny_of(shipped(name)[0])
    path = write(tmp_path, spec, "contract")
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "out"),
                                       "--quiet"])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "out" / "contract"
    written = {p.name for p in folder.glob("*.csv")}
    assert written, "no table written"
    for metric, table in module.TABLES.items():
        if table.file in written:
            df = pd.read_csv(folder / table.file)
            assert [c for c in table.columns if c in df] == table.columns, metric
    assert (folder / "manifest.json").is_file()
    # every analysis' claims go through the one engine: its table, its columns, its verdicts
    assert module.TABLES.get("claims") is claims.TABLE, f"{name} declares its own claims table"
    table = pd.read_csv(folder / "claims.csv")
    assert list(table.columns) == claims.TABLE.columns and len(table), name
    assert set(table["verdict"]) <= set(claims.VERDICTS)
    assert set(table["method"]) <= set(claims.METHODS)
    for _, row in table.iterrows():
        low, high = row["difference_low"], row["difference_high"]
        expected = ("holds" if high < 0 else "fails" if low > 0 else "undecided")
        assert row["verdict"] == expected, (name, row["cell"], row["claim"])

    nested = next(k for k, (sub, _) in module.SCHEMA.items()
                  if isinstance(sub, dict) and isinstance(spec.get(k), dict))
    spec[nested]["no_such_key"] = 1
    bad = write(tmp_path, spec, "bad")
    result = CliRunner().invoke(main, ["validate", str(bad)])
    assert result.exit_code == 2
    assert f"{bad}: {nested}.no_such_key: unknown key" in result.output


def perturbed(spec, factor):
    """Every amplitude in the config scaled by ``factor``."""
    if isinstance(spec, dict):
        return {k: (v * factor if k == "amplitude_v" else perturbed(v, factor))
                for k, v in spec.items()}
    if isinstance(spec, list):
        return [perturbed(v, factor) for v in spec]
    return spec


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_inputs_perturbed_at_1e_12_stay_within_the_check_tolerances(tmp_path, path):
    """What another CPU's rounding does, in miniature: every cell of a run whose input
    amplitude moved by 1e-12 relative passes ``estim check``'s comparison."""
    spec = tiny_of(path)
    tolerances = parse_data(spec, str(path), path.stem).spec["check"]["tolerances"]
    out = {}
    for label, factor in (("base", 1.0), ("moved", 1.0 + 1e-12)):
        cfg = write(tmp_path, perturbed(spec, factor), label)
        result = CliRunner().invoke(main, ["run", str(cfg), "--out", str(tmp_path / label),
                                           "--quiet"])
        assert result.exit_code == 0, result.output
        out[label] = tmp_path / label / label
    written = sorted(p.name for p in out["base"].glob("*.csv"))
    assert written
    for table in written:
        # amplitude_v is the input itself, echoed as a key column: the rest must agree
        a, b = (pd.read_csv(out[k] / table).drop(columns="amplitude_v", errors="ignore")
                for k in ("base", "moved"))
        assert compare.compare_tables(a, b, tolerances) == [], table


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_stored_results_join_every_thesis_row(path):
    from estim import reference
    from estim.store import read_table
    exp = parse_data(yaml.safe_load(path.read_text()), str(path), path.stem)
    if not any(spec.join for spec in ANALYSES[exp.analysis].TABLES.values()):
        pytest.skip(f"{exp.analysis}: the paper prints no numbers to join")
    if exp.spec.get("tables") and set(exp.spec["tables"].values()) <= {"ours", None}:
        pytest.skip(f"{exp.name}: tables of our own (tables.<metric>: ours)")
    folder = ROOT / "results" / exp.name
    filled = 0
    for spec in ANALYSES[exp.analysis].TABLES.values():
        if spec.join and (folder / spec.file).is_file():
            # with_reference raises when a thesis row matches none of ours
            stored = reference.view(read_table(folder / spec.file), spec)
            df = reference.with_reference(stored, spec)
            if not spec.reference:      # a table of printed formulas (4.3, 4.4): rows only
                filled += len(df)
                continue
            filled += int(df[[f"thesis_{v}" for v in spec.reference]].notna().any().any())
    assert filled, f"no thesis value joined to {folder}"


@pytest.mark.parametrize("name", ["mosfet_conduction", "mosfet_saturation", "diffamp_ekf"])
def test_fitted_entries_are_the_ones_estim_tune_wrote(name):
    """A config's "EKF (fitted Q)" carries the values of the overlay `estim tune` wrote."""
    root = Path(__file__).resolve().parents[1] / "configs"
    written = yaml.safe_load((root / "fitted" / f"{name}.yaml").read_text())["estimators"][0]
    config = yaml.safe_load((root / f"{name}.yaml").read_text())
    entry = next(e for e in config["estimators"] if e["label"] == written["label"])
    assert entry["type"] == written["type"]
    assert entry["settings"] == written["settings"]
    assert (entry.get("model_params") or {}) == (written.get("model_params") or {})
