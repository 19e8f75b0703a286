"""Settings declared once (estim.config.settings): the schema, defaults, checks, listing and
manifest all come from the one declaration."""

from pathlib import Path

import pytest

from estim.config import listing, registry, settings
from estim.config.registry import ANALYSES
from estim.config.settings import REQUIRED, validate
from estim.errors import ConfigError
from estim.experiments.shared.blocks import MonteCarlo

ROOT = Path(__file__).resolve().parents[1]


def test_docs_settings_is_the_listing_of_the_declarations():
    text = (ROOT / "docs" / "settings.md").read_text()
    assert text.endswith(listing.listing()), "stale: run 'estim settings --out docs/settings.md'"


def test_every_analysis_schema_is_its_config_declaration():
    for name, module in ANALYSES.items():
        assert module.SCHEMA.keys() == module.Config.schema().keys(), name


def test_every_declared_setting_has_a_doc():
    for name, module in ANALYSES.items():
        for path, _, _, _, doc in settings.describe(module.Config):
            assert doc, f"{name}: {path} has no doc"
    for name in registry.ESTIMATORS:
        for path, _, _, _, doc in settings.describe(registry.ESTIMATORS[name]):
            assert doc, f"estimator {name}: {path} has no doc"


def test_a_block_fills_its_defaults_and_checks_its_values():
    spec = validate({"runs": 3, "seed": 1}, MonteCarlo.schema(), "x.yaml", "monte_carlo")
    assert MonteCarlo.build(spec).to_spec() == {"runs": 3, "seed": 1}
    with pytest.raises(ConfigError, match="monte_carlo.runs: missing required key"):
        validate({"seed": 1}, MonteCarlo.schema(), "x.yaml", "monte_carlo")
    with pytest.raises(ValueError, match="runs: expected an integer from 1"):
        MonteCarlo(runs=0, seed=1)
    with pytest.raises(TypeError, match="missing required setting 'seed'"):
        MonteCarlo(runs=1)
    assert MonteCarlo.schema()["runs"][1] is REQUIRED


def test_an_estimator_made_in_code_is_checked_like_a_config():
    ekf = registry.ESTIMATORS["ekf"]
    with pytest.raises(ValueError, match="substeps: expected an integer from 1"):
        ekf(Q=1.0, R=1.0, P0=1.0, substeps=0)
    made = ekf(Q=1.0, R=1.0, P0=1.0)
    assert made.to_spec()["discretization"] == "exponential"      # defaults, in its spec
    assert set(made.to_spec()) == set(ekf.schema())


def test_a_subclass_adds_settings_without_repeating_its_parents():
    ukf, ekf = registry.ESTIMATORS["ukf"], registry.ESTIMATORS["ekf"]
    assert set(ukf.schema()) - set(ekf.schema()) == {"alpha", "beta", "kappa"}
    assert ukf.schema()["Q"][0] is ekf.schema()["Q"][0]          # one declaration


def test_the_manifest_records_every_default_and_every_model_parameter(tmp_path):
    import json

    from click.testing import CliRunner

    from estim.cli.main import main

    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(ROOT / "configs" / "mosfet_saturation.yaml"),
                                       "--quick", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    manifest = json.loads((out / "mosfet_saturation" / "manifest.json").read_text())
    rls = next(e for e in manifest["config"]["estimators"] if e["type"] == "rls")
    assert rls["settings"]["delta"] == 100.0 and rls["settings"]["p_max"] is None
    assert manifest["config"]["health"]["growth"] == 10.0
    truth = manifest["models"]["model.params"]
    assert truth["name"] == "mosfet_ekv" and truth["params"]["R_D"] == 1e5


def test_list_items_without_a_mapping_setting_get_a_dict_of_their_own():
    """Two estimator entries that give no settings: each gets its own filled-in dict (an
    analysis completes it in place with the estimator's defaults; a shared one made the
    second entry inherit the first's, refused as unknown keys of another type)."""
    from estim.experiments.shared.blocks import EstimatorEntry

    spec = ("list", EstimatorEntry.schema(), True, 10, False)
    out = validate([{"label": "a", "type": "rls"}, {"label": "b", "type": "ekf"}],
                   spec, "x.yaml", "estimators")
    assert out[0]["settings"] == {} and out[0]["settings"] is not out[1]["settings"]
    out[0]["settings"]["order"] = 3
    assert out[1]["settings"] == {}
