import shutil
from io import StringIO
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from estim.cli.main import main
from estim.config.overrides import parse_override
from estim.config.registry import ANALYSES

ROOT = Path(__file__).resolve().parents[1]


def tiny_config(**changes) -> dict:
    """The saturation config shrunk to seconds of work, with ``changes`` applied by key path."""
    spec = yaml.safe_load((ROOT / "configs" / "mosfet_saturation.yaml").read_text())
    spec.update(name="tiny")
    spec["input"].update(frequencies_hz=[1000], periods=2)
    spec["noise"].update(input_levels=[0.01], readings=["sigma"])
    spec["monte_carlo"].update(runs=3)
    spec["figures"].update(noise_level=0.01)
    return apply_changes(spec, changes)


def apply_changes(spec: dict, changes: dict) -> dict:
    """Set (or with ``DELETE`` remove) each dotted key path of ``changes`` in ``spec``."""
    for path, value in changes.items():
        *parents, last = path.split(".")
        node = spec
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node[key]
        if value is DELETE:
            del node[last]
        else:
            node[last] = value
    return spec


DELETE = object()


def write(tmp_path: Path, spec: dict, name: str = "tiny.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(spec))
    return path


@pytest.mark.parametrize("changes, key, expected", [
    ({"noise.bogus": 1}, "noise.bogus", "unknown key"),
    ({"input.periods": "ten"}, "input.periods", "integer"),
    ({"noise.input_levels": [0.1, -0.2]}, "noise.input_levels[1]", "positive number"),
    ({"noise.input_levels": [0.0]}, "noise.input_levels[0]", "positive number"),
    ({"input.samples_per_period": 0}, "input.samples_per_period", "integer from 2 to"),
    ({"input.frequencies_hz": []}, "input.frequencies_hz", "non-empty list"),
    ({"model.name": "bjt_magic"}, "model.name", "mosfet_ekv"),
    ({"estimators.0.type": "pf"}, "estimators[0].type",
     "'bootstrap_pf', 'ekf', 'enkf', 'kf', 'kronecker_ekf', 'rls', 'ukf'"),
    ({"estimators.1.settings": {"orderr": 3}}, "estimators[1].settings.orderr", "order"),
    ({"model.params": {"V_GG": 1.0}}, "model.params.V_GG", "unknown parameter"),
    ({"model.params": {"drain_current": "spice"}}, "model.params", "drain_current"),
    ({"monte_carlo": DELETE}, "monte_carlo", "missing required key"),
    ({"noise.readings": ["std"]}, "noise.readings[0]", "sigma"),
    ({"estimators.0.settings.Q": [1, 2]}, "estimators[0].settings.Q", "expected a scalar"),
    ({"estimators.0.settings.substeps": 0}, "estimators[0].settings.substeps", "integer from 1"),
    ({"estimators.0.type": "enkf", "estimators.0.settings.members": 1},
     "estimators[0].settings.members", "integer from 2"),
    ({"estimators.0.type": "bootstrap_pf", "estimators.0.settings.members": "many"},
     "estimators[0].settings.members", "integer from 2"),
    ({"estimators.1.settings": {"lambda_min": 1.5}}, "estimators[1].settings.lambda_min",
     "number <= 1"),
    ({"tables.rmse": "9.9"}, "tables.rmse", "expected one of ['3.1', '3.2', '3.5', 'ours']"),
    ({"tables.rmse": "4.1"}, "tables.rmse", "for a rmse table, got '4.1'"),
    ({"check.tolerances.rmse": {"rtol": None, "atol": "x"}}, "check.tolerances.rmse.atol",
     "number"),
    ({"name": "../../tmp/evil"}, "name", "results folder"),
    ({"input.mix": [0.5, -0.5]}, "input.mix", "one per model input"),
    ({"input.duration_s": 0.01}, "input.periods", "exactly one"),
    ({"noise.pairs": True, "noise.input_levels": [0.01, 0.02]}, "noise.pairs", "same length"),
    ({"noise.pairs": "yes"}, "noise.pairs", "true or false"),
    ({"input.sample_time_s": -1e-4}, "input.sample_time_s", "number >= 1e-12"),
    ({"input.duration_s": "long", "input.periods": DELETE}, "input.duration_s", "number"),
    ({"input.bias_v": [0.0, 1.0]}, "input.bias_v", "one per model input"),
    ({"input.mix": ["a"]}, "input.mix[0]", "a finite number"),
    ({"simulation.solver": "pspice"}, "simulation.solver", "batched_radau"),
    ({"figures.reading": "std"}, "figures.reading", "sigma"),
    ({"figures.extra_noisy": [{"noise_level": 0.1}]}, "figures.extra_noisy[0].name",
     "missing required key"),
    ({"figures.extra_noisy": [{"noise_level": 0, "name": "x"}]},
     "figures.extra_noisy[0].noise_level", "positive number"),
    ({"figures.names": {"noisey": "fig"}}, "figures.names.noisey", "unknown figure kind"),
    ({"regime": "triode"}, "regime", "expected one of ['weak_inversion'"),
    ({"regime": 3}, "regime", "non-empty string"),
    ({"health": {"consecutive": 0}}, "health.consecutive", "integer from 1"),
    ({"health": {"growth": 1.0}}, "health.growth", "number >= 1.5"),
    ({"health": {"whiteness_lag": "ten"}}, "health.whiteness_lag", "integer"),
    ({"health": {"band": 0.1}}, "health.band", "number >= 0.5"),
    ({"health": {"nees": 1}}, "health.nees", "unknown key"),
    ({"noise.measurement": ["clean"]}, "noise.measurement[0]", "noise_free"),
    ({"noise.measurement": ["noisy", "noisy"]}, "noise.measurement[1]", "repeats"),
    ({"estimators.0.label": "measurement"}, "estimators[0].label", "baseline row"),
    ({"estimators.1.settings.lambda0": 0.99}, "estimators[1].settings",
     "lambda0 is the constant factor of forgetting: fixed"),
    ({"estimators.1.settings.forgetting": "fixed"}, "estimators[1].settings.forgetting",
     "fixed needs lambda0"),
    ({"estimators.1.settings.forgetting": "sometimes"}, "estimators[1].settings.forgetting",
     "variable"),
    ({"estimators.1.settings.p_max": -1.0}, "estimators[1].settings.p_max", "positive number"),
    ({"estimators.3.settings.alpha": 0.0}, "estimators[3].settings.alpha", "positive number"),
    ({"estimators.3.settings.kappa": "x"}, "estimators[3].settings.kappa", "number"),
])
def test_config_errors_exit_2_naming_file_and_key(tmp_path, changes, key, expected):
    path = write(tmp_path, tiny_config(**changes))
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert str(path) in lines[0] and f": {key}: " in lines[0] and expected in lines[0]
    assert "Traceback" not in result.output


def test_paired_sweep_follows_the_thesis_rows():
    from estim.config.loading import parse
    from estim.experiments.estimation import sweep

    text = (ROOT / "configs" / "diffamp_ekf.yaml").read_text()
    points = sweep(parse(text, "diffamp_ekf.yaml", "diffamp_ekf"))
    pairs = [(p.reading, p.level, p.frequency_hz) for p in points]
    assert pairs[:5] == [("sigma", 0.005, 100), ("sigma", 0.01, 1000), ("sigma", 0.025, 10000),
                         ("sigma", 0.05, 100), ("sigma", 0.1, 1000)]
    assert pairs[5][0] == "variance" and points[6].sigma == 0.1 and len(points) == 20
    assert [p.measurement for p in points] == ["noisy"] * 10 + ["noise_free"] * 10
    assert pairs[10:] == pairs[:10]


def test_scipy_solver_backend_gives_the_same_table(tmp_path):
    fast = tiny_config(**{"monte_carlo.runs": 2, "input.periods": 1})
    slow = tiny_config(**{"monte_carlo.runs": 2, "input.periods": 1,
                          "simulation.solver": "scipy"})
    runner = CliRunner()
    for name, spec in (("fast", fast), ("slow", slow)):
        path = write(tmp_path, spec, f"{name}.yaml")
        result = runner.invoke(main, ["run", str(path), "--out", str(tmp_path / name), "--quiet"])
        assert result.exit_code == 0, result.output
    a = pd.read_csv(tmp_path / "fast/tiny/rmse.csv")
    b = pd.read_csv(tmp_path / "slow/tiny/rmse.csv")
    np.testing.assert_allclose(a["rmse"], b["rmse"], rtol=1e-3)


def test_missing_file_and_bad_yaml_exit_2(tmp_path):
    result = CliRunner().invoke(main, ["run", str(tmp_path / "nope.yaml")])
    assert result.exit_code == 2
    assert "nope.yaml" in result.output and "no such file" in result.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("model: [unclosed\n")
    result = CliRunner().invoke(main, ["validate", str(bad)])
    assert result.exit_code == 2 and "not valid YAML" in result.output


def test_non_utf8_config_exits_2(tmp_path):
    path = tmp_path / "latin.yaml"
    path.write_bytes(b"name: caf\xe9\n")
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2 and "UTF-8" in result.output


def test_stale_files_are_removed_from_a_result_folder(tmp_path):
    path = write(tmp_path, tiny_config())
    stale = tmp_path / "out/tiny/figures/old_name.png"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"old")
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "out"),
                                       "--quiet", "--runs", "2"])
    assert result.exit_code == 0, result.output
    assert not stale.exists()
    assert "old_name" not in (tmp_path / "out/tiny/manifest.json").read_text()


def test_shipped_configs_validate():
    configs = sorted(str(p) for p in (ROOT / "configs").glob("*.yaml"))
    result = CliRunner().invoke(main, ["validate", *configs])
    assert result.exit_code == 0, result.output


def test_run_is_deterministic_and_check_detects_drift(tmp_path, rehash):
    path = write(tmp_path, tiny_config())
    runner = CliRunner()
    for out in ("a", "b"):
        result = runner.invoke(main, ["run", str(path), "--out", str(tmp_path / out), "--quiet"])
        assert result.exit_code == 0, result.output
    for name in ("rmse.csv", "residual.csv", "claims.csv", "figures/fig_3_5.png"):
        first, second = (tmp_path / "a/tiny" / name), (tmp_path / "b/tiny" / name)
        assert first.read_bytes() == second.read_bytes()
    assert (tmp_path / "a/tiny/figures/fig_3_5.png").stat().st_size > 0
    manifest = (tmp_path / "a/tiny/manifest.json").read_text()
    assert '"seed": 2019' in manifest and "rmse.csv" in manifest

    ok = runner.invoke(main, ["check", str(path), "--results", str(tmp_path / "a")])
    assert ok.exit_code == 0, ok.output
    stored = tmp_path / "a/tiny/rmse.csv"
    lines = stored.read_text().splitlines()
    cells = lines[1].split(",")
    col = lines[0].split(",").index("rmse")
    cells[col] = str(float(cells[col]) * 1.01)
    stored.write_text("\n".join([lines[0], ",".join(cells), *lines[2:]]) + "\n")
    rehash(stored.parent)                   # as an older estim would have written it
    drift = runner.invoke(main, ["check", str(path), "--results", str(tmp_path / "a")])
    assert drift.exit_code == 1
    assert "rmse.csv row 0 rmse: obtained" in drift.output


def test_seed_changes_results(tmp_path):
    path = write(tmp_path, tiny_config())
    runner = CliRunner()
    runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "a"), "--quiet"])
    runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "b"), "--quiet", "--seed", "7"])
    first, second = (tmp_path / "a/tiny/rmse.csv"), (tmp_path / "b/tiny/rmse.csv")
    assert first.read_bytes() != second.read_bytes()


def test_table_prints_thesis_beside_ours(tmp_path):
    path = write(tmp_path, tiny_config(**{"input.frequencies_hz": [100],
                                          "noise.input_levels": [0.25],
                                          "figures.noise_level": 0.25,
                                          "figures.frequency_hz": 100}))
    runner = CliRunner()
    runner.invoke(main, ["run", str(path), "--out", str(tmp_path), "--quiet", "--runs", "2"])
    strict = runner.invoke(main, ["table", "rmse", "--results", str(tmp_path), "--thesis"])
    assert strict.exit_code == 2 and "Table 3.2: row 3 (s_no=2, estimator=EKF) matches none" \
        in strict.output, strict.output
    result = runner.invoke(main, ["table", "rmse", "--results", str(tmp_path), "--thesis",
                                  "--partial", "--format", "csv"])
    assert result.exit_code == 0, result.output
    header, *lines = result.output.splitlines()
    assert "thesis_rmse" in header and "ratio_rmse" in header
    ekf = next(line for line in lines if ",EKF," in line)
    assert ",0.4024," in ekf         # Table 3.2 row 1, EKF
    baseline = next(line for line in lines if ",measurement," in line)
    assert baseline.endswith(",,")   # the raw measurement has no thesis value
    for fmt in ("text", "markdown", "latex"):
        assert runner.invoke(main, ["table", "residual", "--results", str(tmp_path),
                                    "--format", fmt]).exit_code == 0


def chapter2_config(**changes) -> dict:
    """The oscillator config (a step: seconds of work) with ``changes`` applied by key path."""
    spec = yaml.safe_load((ROOT / "configs" / "cco_distortion.yaml").read_text())
    spec.update(name="tiny2")
    spec["excitation"]["samples"] = 300
    return apply_changes(spec, changes)


@pytest.mark.parametrize("changes, key, expected", [
    ({"excitation.waveform": "sine"}, "rows[0].frequency_hz", "missing required key"),
    ({"rows.0.duration_s": DELETE}, "rows[0].duration_s", "missing required key"),
    ({"rows.0.params": {"L_9": 1.0}}, "rows[0].params.L_9", "unknown parameter"),
    ({"rows.1.s_no": 1}, "rows[1].s_no", "duplicate row number"),
    ({"excitation.mix": [1.0, 0.0]}, "excitation.mix", "one per model input"),
    ({"excitation.mix": [0.0]}, "excitation.mix", "non-zero"),
    ({"figures.row": 7}, "figures.row", "s_no of a row"),
    ({"tables.distortion": "2.9"}, "tables.distortion", "expected one of ['2.1'"),
    ({"rows.0.amplitude_v": -1}, "rows[0].amplitude_v", "number >= 1e-09"),
    ({"noise": {"input_levels": [1]}}, "noise", "unknown key"),
    ({"analysis": "volterra"}, "analysis", "perturbation"),
    ({"rows.0.amplitude_v": float("inf")}, "rows[0].amplitude_v", "finite number"),
    ({"rows.0.frequency_hz": 1000}, "rows[0].frequency_hz", "not used"),
    ({"figures.name": "../escape"}, "figures.name", "names a file"),
    ({"simulation.rtol": 10}, "simulation.rtol", "< 0.1"),
    ({"excitation.waveform": "square"}, "excitation.waveform", "'sine', 'step'"),
    ({"excitation.samples": 3}, "excitation.samples", "integer from 8 to"),
    ({"excitation.samples_per_period": 4}, "excitation.samples_per_period", "integer from 8 to"),
    ({"excitation.bias_v": ["high"]}, "excitation.bias_v[0]", "finite number"),
    ({"excitation": DELETE}, "excitation", "missing required key"),
    ({"rows": []}, "rows", "non-empty list"),
    ({"rows.0.s_no": 0}, "rows[0].s_no", "integer from 1 to"),
    ({"rows.0.params": [1, 2]}, "rows[0].params", "a mapping"),
    ({"tables": {}}, "tables.distortion", "missing required key"),
    ({"figures.row": "first"}, "figures.row", "integer from 1 to"),
    ({"model.name": "cco2"}, "model.name", "'cco'"),
    ({"model.params": {"R_E": -1.0}}, "model.params", "R_E must be positive"),
])
def test_bad_chapter2_config_names_key(tmp_path, changes, key, expected):
    path = write(tmp_path, chapter2_config(**changes))
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2, result.output
    assert f"{path}: {key}:" in result.output and expected in result.output, result.output
    assert "Traceback" not in result.output


def test_distortion_and_gain_tables_beside_thesis(tmp_path):
    path = write(tmp_path, chapter2_config(), "tiny2.yaml")
    runner = CliRunner()
    result = runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "res"), "--quiet"])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "res" / "tiny2"
    assert (folder / "figures" / "fig_2_2.png").stat().st_size > 0
    shown = runner.invoke(main, ["table", "distortion", "--results", str(tmp_path / "res"),
                                 "--thesis", "--format", "csv"])
    assert shown.exit_code == 0, shown.output
    df = pd.read_csv(StringIO(shown.output))
    assert list(df["thesis_percent_distortion"]) == [0.333, 0.428]
    assert np.all(df["err_first_order_rms"] < df["err_linear_rms"])
    gain = runner.invoke(main, ["table", "gain", "--results", str(tmp_path / "res")])
    assert gain.exit_code == 2 and "no gain values" in gain.output    # a step has no gain
    check = runner.invoke(main, ["check", str(path), "--results", str(tmp_path / "res")])
    assert check.exit_code == 0, check.output


def fake_project(tmp_path: Path, monkeypatch) -> Path:
    """A project folder with the tiny config in configs/, as the working folder."""
    root = tmp_path / "proj"
    (root / "configs").mkdir(parents=True)
    (root / "pyproject.toml").write_text('[project]\nname = "estim"\n')
    (root / "configs" / "tiny.yaml").write_text(yaml.safe_dump(tiny_config()))
    (root / "sub").mkdir()
    monkeypatch.chdir(root / "sub")
    return root


@pytest.mark.slow
def test_overridden_run_never_writes_the_baseline(tmp_path, monkeypatch):
    root = fake_project(tmp_path, monkeypatch)
    config = str(root / "configs" / "tiny.yaml")
    runner = CliRunner()
    result = runner.invoke(main, ["run", config, "--runs", "2"])
    assert result.exit_code == 0, result.output
    assert f"writing to {root / 'scratch'}/" in result.output
    assert (root / "scratch/tiny/rmse.csv").is_file() and not (root / "results").exists()
    refused = runner.invoke(main, ["run", config, "--runs", "2", "--out", str(root / "results")])
    assert refused.exit_code == 2 and "--update-baseline" in refused.output
    assert not (root / "results").exists()
    forced = runner.invoke(main, ["run", config, "--runs", "2", "--update-baseline", "--quiet"])
    assert forced.exit_code == 0 and (root / "results/tiny/rmse.csv").is_file()
    # the stored 2-run baseline is not what the config says: check fails, naming the key
    check = runner.invoke(main, ["check"])
    assert check.exit_code == 1
    assert "monte_carlo.runs: stored 2, config 3" in check.output
    quick = runner.invoke(main, ["run", config, "--quick", "--quiet"])
    assert quick.exit_code == 0 and (root / "scratch/tiny/manifest.json").is_file()
    assert '"runs": 3' in (root / "scratch/tiny/manifest.json").read_text()
    refused = runner.invoke(main, ["run", config, "--quick", "--update-baseline"])
    assert refused.exit_code == 2 and "--quick never writes the baseline" in refused.output
    plain = runner.invoke(main, ["run", config, "--quiet"])
    assert plain.exit_code == 0
    assert runner.invoke(main, ["check"]).exit_code == 0


def test_unwritable_out_fails_before_any_work(tmp_path):
    path = write(tmp_path, tiny_config())
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(blocker / "sub")])
    assert result.exit_code == 2
    assert f"cannot write to {blocker / 'sub'}" in result.output
    assert "work units" not in result.output


def test_list_outside_a_project_uses_the_shipped_configs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["list"])
    assert result.exit_code == 0, result.output
    assert "configs shipped with estim" in result.output
    assert "mosfet_saturation" in result.output
    line = next(x for x in result.output.splitlines() if " passive_network " in x)
    assert "no printed table" in line and "Tables  " not in line     # was an empty "Tables"


def test_tune_writes_an_overlay_and_refuses_what_it_cannot_fit(tmp_path):
    path = write(tmp_path, tiny_config())
    runner = CliRunner()
    for label, message in (("EFK", "no estimator labelled 'EFK'"),
                           ("RLS", "'RLS' has no noise covariances to fit")):
        bad = runner.invoke(main, ["tune", str(path), "--estimator", label])
        assert bad.exit_code == 2 and message in bad.output, bad.output
    perturbation = ROOT / "configs" / "mosfet_distortion.yaml"
    bad = runner.invoke(main, ["tune", str(perturbation), "--estimator", "EKF"])
    assert bad.exit_code == 2 and "this config's analysis is 'perturbation'" in bad.output
    for new in ("", "RLS", "x" * 61):
        bad = runner.invoke(main, ["tune", str(path), "--estimator", "EKF", "--as", new])
        assert bad.exit_code == 2 and "expected a new label of 1 to 60" in bad.output, new
    swept = write(tmp_path, {**tiny_config(), "sweep": {"monte_carlo.runs": [2, 3]}},
                  "swept.yaml")
    bad = runner.invoke(main, ["tune", str(swept), "--estimator", "EKF"])
    assert bad.exit_code == 2 and "this one sweeps monte_carlo.runs" in bad.output, bad.output
    full = tiny_config()
    ekf = next(e for e in full["estimators"] if e["label"] == "EKF")
    n = len(ekf["settings"]["Q"])
    ekf["settings"]["Q"] = [[0.01 if i == j else 1e-4 * (abs(i - j) == 1) for j in range(n)]
                            for i in range(n)]
    bad = runner.invoke(main, ["tune", str(write(tmp_path, full, "full.yaml")),
                               "--estimator", "EKF"])
    assert bad.exit_code == 2 and "the Q of 'EKF' is a full matrix" in bad.output, bad.output
    blocked = tmp_path / "blocked"
    blocked.write_text("a file, not a folder")
    bad = runner.invoke(main, ["tune", str(path), "--estimator", "EKF", "--runs", "2",
                               "--out", str(blocked / "fit.yaml")])
    assert bad.exit_code == 2 and "cannot write to" in bad.output, bad.output
    assert "Innovation" not in bad.output                 # refused before fitting
    out = tmp_path / "fit.yaml"
    good = runner.invoke(main, ["tune", str(path), "--estimator", "EKF", "--runs", "2",
                                "--out", str(out)])
    assert good.exit_code == 0, good.output
    entry = yaml.safe_load(out.read_text())["estimators"][0]
    assert entry["label"] == "EKF (fitted Q)" and entry["type"] == "ekf"
    assert len(entry["settings"]["Q"]) == 4 and all(q > 0 for q in entry["settings"]["Q"])
    assert "Innovation log-likelihood" in out.read_text()


def test_every_package_of_the_tree_is_shipped():
    """A fresh-clone install failed once because a new package was not in pyproject.toml."""
    import tomllib

    root = Path(__file__).resolve().parents[1]
    setuptools = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(setuptools["packages"])
    for package, folder in setuptools["package-dir"].items():
        for init in (root / folder).rglob("__init__.py"):
            name = ".".join((package, *init.parent.relative_to(root / folder).parts))
            assert name in listed, f"{name} is not in pyproject.toml's packages"
    assert not {name.split(".")[0] for name in listed} - {"estim"}, "one import package"


def test_table_with_thesis_on_a_table_without_printed_values_says_so_in_one_line():
    result = CliRunner().invoke(main, ["table", "derivative", "--paper"])
    assert result.exit_code == 0, result.output
    (line,) = result.output.strip().splitlines()
    assert "no printed derivative table to compare with" in line


@pytest.mark.slow
def test_key_path_overrides_on_run_validate_and_check(tmp_path, monkeypatch):
    """``key.path=value`` among the configs: YAML-typed, applied before validation (errors
    keep the key path), recorded in the manifest, combined with --quick, and accepted by
    check, which then compares tables without requiring the stored config."""
    import json

    root = fake_project(tmp_path, monkeypatch)
    config = str(root / "configs" / "tiny.yaml")
    runner = CliRunner()
    ok = runner.invoke(main, ["run", config, "simulation.rtol=1e-6", "monte_carlo.runs=2",
                              "--quiet"])
    assert ok.exit_code == 0, ok.output
    manifest = json.loads((root / "scratch/tiny/manifest.json").read_text())
    assert manifest["overrides"] == {"simulation.rtol": 1e-6, "monte_carlo.runs": 2}
    assert "git_commit" not in manifest and "command" not in manifest
    record = json.loads((root / "scratch/tiny/run.json").read_text())
    assert "git_commit" in record and record["command"].startswith("estim")
    assert record["wall_time_s"] > 0 and set(manifest["files"]) == {
        str(p.relative_to(root / "scratch/tiny")) for p in (root / "scratch/tiny").rglob("*")
        if p.is_file() and p.name not in ("manifest.json", "run.json")}
    assert manifest["config"]["simulation"]["rtol"] == 1e-6
    assert manifest["config"]["monte_carlo"]["runs"] == 2
    listed = runner.invoke(main, ["run", config, "input.frequencies_hz=[1000]", "--quick",
                                  "--quiet"])
    assert listed.exit_code == 0, listed.output
    for args, expected in (
        (["simulation.rtol=-1"], ": simulation.rtol: "),
        (["simulation.rtl=1e-6"], ": simulation.rtl: unknown key"),
        (["estimators[7].settings.R=1"], ": estimators[7].settings.R: estimators is a list"),
        (["input.amplitude_v.x=1"], ": input.amplitude_v.x: input.amplitude_v is a value"),
        (["noise.input_levels=[0.1,"], "the value is not YAML"),
        (["=3"], "expected a config file or key.path=value"),
    ):
        bad = runner.invoke(main, ["validate", config, *args])
        assert bad.exit_code == 2 and expected in bad.output, (args, bad.output)
        assert "Traceback" not in bad.output
    runner.invoke(main, ["run", config, "--quiet"])
    same = runner.invoke(main, ["check", config, "simulation.rtol=1.0e-5"])
    assert same.exit_code == 0, same.output
    assert "with overrides simulation.rtol=1e-05" in same.output


def test_table_csv_is_one_valid_csv_with_an_experiment_column(tmp_path):
    runner = CliRunner()
    for name in ("one", "two"):
        path = write(tmp_path, {**tiny_config(), "name": name}, f"{name}.yaml")
        assert runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "res"), "--quiet",
                                    "--runs", "2"]).exit_code == 0
    shown = runner.invoke(main, ["table", "rmse", "--results", str(tmp_path / "res"),
                                 "--format", "csv"])
    assert shown.exit_code == 0, shown.output
    df = pd.read_csv(StringIO(shown.output))
    assert list(df.columns[:2]) == ["experiment", "table_id"]
    assert set(df["experiment"]) == {"one", "two"}
    assert shown.output.count("experiment,") == 1
    latex = runner.invoke(main, ["table", "rmse", "--results", str(tmp_path / "res"),
                                 "--format", "latex"])
    assert latex.output.count(r"\begin{tabular}") == 2 and "% one: RMSE" in latex.output


def test_every_config_mistake_at_once_with_suggestions(tmp_path):
    spec = tiny_config()
    spec["simulation"]["rtl"] = 1e-6
    spec["noise"]["readings"] = ["sigmaa"]
    spec["monte_carlo"]["runs"] = 0
    path = write(tmp_path, spec)
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 3 and all(line.startswith(f"error: {path}: ") for line in lines)
    assert any("simulation.rtl: unknown key (did you mean 'rtol'?)" in line for line in lines)
    assert any("noise.readings[0]" in line and "did you mean 'sigma'?" in line for line in lines)
    assert any("monte_carlo.runs: expected an integer" in line for line in lines)


@pytest.mark.parametrize("path", [p for folder in ("", "studies", "netlist")
                                  for p in sorted((ROOT / "configs" / folder).glob("*.yaml"))],
                         ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_every_shipped_config_has_a_valid_quick_profile(path):
    """``estim run CONFIG --quick`` validates the shrunk config again: it must pass (a config
    without ``reproduces`` used to fail here, and every netlist config did: its resolved
    model block carries the ``netlist:<stem>`` name beside the netlist)."""
    from estim.config.loading import load_file

    exp = load_file(path, quick=True)
    assert exp.name == load_file(path, plan=False).name


def test_entry_point_lists_commands_without_loading_them():
    """``estim --help`` and completion answer from cli.entry without importing the commands
    (numpy, pandas, matplotlib); the short help names every command of cli.main."""
    import subprocess
    import sys

    from estim.cli import entry

    assert set(entry.SHORT_HELP) == set(main.commands)
    code = ("import sys; from click.testing import CliRunner; from cli.entry import main; "
            "r = CliRunner().invoke(main, ['--help']); assert r.exit_code == 0, r.output; "
            "print(sorted(m for m in ('pandas', 'matplotlib', 'scipy', 'estim.cli.main') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, check=True).stdout.strip()
    assert out == "[]"
    config = str(ROOT / "configs/passive_network.yaml")
    result = CliRunner().invoke(entry.main, ["validate", config])
    assert result.exit_code == 0 and "ok (passive_network)" in result.output
    bad = CliRunner().invoke(entry.main, ["validate", config, "sample_time=-1"])
    assert bad.exit_code == 2 and "sample_time" in bad.output


@pytest.mark.parametrize("fmt, media", [("png", ("image/png", "image/webp")),
                                        ("svg", ("image/svg+xml",))])
def test_report_is_one_page_with_every_table_and_figure(tmp_path, fmt, media):
    from html.parser import HTMLParser

    path = write(tmp_path, tiny_config())
    runner = CliRunner()
    assert runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "res"), "--quiet",
                                "--runs", "2", "--figure-format", fmt]).exit_code == 0
    out = tmp_path / "page.html"
    result = runner.invoke(main, ["report", "--results", str(tmp_path / "res"), "--out",
                                  str(out)])
    assert result.exit_code == 0, result.output

    class Page(HTMLParser):
        def __init__(self):
            super().__init__()
            self.tables, self.images, self.failing, self.external = 0, [], 0, []

        def handle_starttag(self, tag, attrs):
            a = dict(attrs)
            self.tables += tag == "table" and "data" in a.get("class", "").split()
            self.failing += tag == "tr" and a.get("class") == "fail"
            if tag == "img":
                self.images.append(a.get("data-file"))
                if not a.get("src", "").startswith(tuple(f"data:{m};base64," for m in media)):
                    self.external.append(a.get("src"))
            if (tag == "link" or (tag == "script" and "src" in a)
                    or (tag == "a" and "://" in a.get("href", ""))):
                self.external.append(a)

    page = Page()
    page.feed(out.read_text())
    folder = tmp_path / "res" / "tiny"
    assert page.tables == len(list(folder.glob("*.csv")))
    assert page.images and sorted(page.images) == sorted(
        p.name for p in (folder / "figures").glob(f"*.{fmt}"))
    assert not page.external
    claims = pd.read_csv(folder / "claims.csv")
    assert page.failing == int((claims["verdict"] == "fails").sum())


@pytest.mark.slow
def test_the_report_of_the_shipped_results_is_under_3_mb(tmp_path):
    out = tmp_path / "report.html"
    result = CliRunner().invoke(main, ["report", "--results", str(ROOT / "results"), "--out",
                                       str(out)])
    assert result.exit_code == 0, result.output
    assert out.stat().st_size <= 3 * 1024 * 1024


@pytest.mark.slow
def test_a_dask_run_writes_the_same_bytes_as_jobs_1(tmp_path):
    pytest.importorskip("distributed")
    path = write(tmp_path, tiny_config())
    runner = CliRunner()
    local = runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "a"), "--quiet",
                                 "--runs", "2"])
    dask = runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "b"), "--quiet",
                                "--runs", "2", "--executor", "dask", "--jobs", "2"])
    assert local.exit_code == 0 and dask.exit_code == 0, dask.output
    a, b = tmp_path / "a" / "tiny", tmp_path / "b" / "tiny"
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file()
                   and p.name != "run.json")
    assert files and files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file()
                                     and p.name != "run.json")
    assert Path("manifest.json") in files           # the tracked record too: no wall time
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f
    refused = runner.invoke(main, ["run", str(path), "--scheduler", "tcp://x:1"])
    assert refused.exit_code == 2 and "--executor dask" in refused.output


@pytest.mark.slow
def test_an_interrupted_run_resumes_with_its_finished_cells(tmp_path, monkeypatch):
    from estim.experiments import estimation

    path = write(tmp_path, tiny_config(**{"input.frequencies_hz": [100, 1000, 10000]}))
    runner = CliRunner()
    # one process: the interruption and the count are made in this one (--jobs defaults to
    # the usable cores)
    args = ["run", str(path), "--quiet", "--runs", "2", "--jobs", "1"]
    assert runner.invoke(main, [*args, "--out", str(tmp_path / "full")]).exit_code == 0
    real, calls = estimation.run_point, []

    def counted(*a, **k):
        calls.append(1)
        if stop_after and len(calls) > stop_after:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(estimation, "run_point", counted)
    stop_after = 2
    stopped = runner.invoke(main, [*args, "--out", str(tmp_path / "res")])
    assert stopped.exit_code == 130 and not (tmp_path / "res" / "tiny").exists()
    assert len(list((tmp_path / "res").glob(".tiny.cells-*/cell-*.npz"))) == 2
    calls.clear()
    stop_after = 0
    resumed = runner.invoke(main, ["run", str(path), "--runs", "2", "--jobs", "1", "--out",
                                   str(tmp_path / "res")])
    assert resumed.exit_code == 0, resumed.output
    assert "resumed with 2 finished cell(s)" in resumed.output
    total = len(pd.read_csv(tmp_path / "full" / "tiny" / "rmse.csv")
                [["noise_reading", "noise_param", "frequency_hz"]].drop_duplicates())
    assert len(calls) == total - 2
    for name in ("rmse.csv", "residual.csv", "health.csv"):
        assert (tmp_path / "res" / "tiny" / name).read_bytes() == \
            (tmp_path / "full" / "tiny" / name).read_bytes()
    assert not list((tmp_path / "res").glob(".tiny.cells-*"))


@pytest.mark.slow
def test_shards_merged_give_the_tables_of_one_run(tmp_path):
    path = write(tmp_path, tiny_config(**{"input.frequencies_hz": [100, 1000, 10000]}))
    runner = CliRunner()
    args = [str(path), "monte_carlo.runs=2", "--quiet"]
    assert runner.invoke(main, ["run", *args, "--out", str(tmp_path / "one")]).exit_code == 0
    for k in (1, 2):
        shard = runner.invoke(main, ["run", *args, "--out", str(tmp_path / f"s{k}"),
                                     "--shard", f"{k}/2"])
        assert shard.exit_code == 0 and f"shard {k}/2" in shard.output, shard.output
        assert not (tmp_path / f"s{k}" / "tiny").exists()
    merged = runner.invoke(main, ["merge", *args, "--from", str(tmp_path / "s1"), "--from",
                                  str(tmp_path / "s2"), "--out", str(tmp_path / "m")])
    assert merged.exit_code == 0, merged.output
    for name in ("rmse.csv", "residual.csv", "health.csv", "claims.csv"):
        assert (tmp_path / "m" / "tiny" / name).read_bytes() == \
            (tmp_path / "one" / "tiny" / name).read_bytes()
    for bad in ("0/2", "3/2", "x"):
        refused = runner.invoke(main, ["run", *args, "--shard", bad])
        assert refused.exit_code == 2 and "expected K/N" in refused.output
    bare = runner.invoke(main, ["merge", "monte_carlo.runs=2", "--from", str(tmp_path / "s1"),
                                "--out", str(tmp_path / "m2")])
    assert bare.exit_code == 2 and "no config file given" in bare.output    # was exit 0, silent


def run_swept(tmp_path, spec: dict) -> tuple[Path, pd.DataFrame]:
    """Write ``spec`` (with its sweep block), run it with 2 runs into ``tmp_path/sw`` and
    return the config's path and its rmse table."""
    path = write(tmp_path, spec)
    swept = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "sw"),
                                      "--quiet", "--runs", "2"])
    assert swept.exit_code == 0, swept.output
    return path, pd.read_csv(tmp_path / "sw" / "tiny" / "rmse.csv")


def test_a_key_set_twice_on_one_command_line_is_refused(tmp_path):
    """Two overrides of one key (or an override and --runs/--seed) used to keep the last
    silently; each is a usage error naming the key."""
    path = write(tmp_path, tiny_config())
    runner = CliRunner()
    twice = runner.invoke(main, ["validate", str(path), "noise.measurement_sigma=0.1",
                                 "noise.measurement_sigma=0.2"])
    assert twice.exit_code == 2 and "noise.measurement_sigma is already set" in twice.output
    both = runner.invoke(main, ["run", str(path), "monte_carlo.runs=3", "--runs", "4",
                                "--out", str(tmp_path / "o")])
    assert both.exit_code == 2 and "both as an override and as --runs" in both.output
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_sweep_block_runs_each_cell_as_its_override_would(tmp_path):
    spec = tiny_config(**{"input.frequencies_hz": [1000], "noise.input_levels": [0.1],
                          "figures.noise_level": 0.1, "figures.frequency_hz": 1000})
    spec["sweep"] = {"model.params.V_IN": [0.3, 0.35], "noise.measurement_sigma": [0.05, 0.1]}
    path, table = run_swept(tmp_path, spec)
    runner = CliRunner()
    assert list(table.columns[:2]) == ["sweep:model.params.V_IN", "sweep:noise.measurement_sigma"]
    assert list(table.drop_duplicates(list(table.columns[:2])).iloc[:, :2].itertuples(
        index=False, name=None)) == [(0.3, 0.05), (0.3, 0.1), (0.35, 0.05), (0.35, 0.1)]
    del spec["sweep"]
    single = write(tmp_path, spec, "single.yaml")
    one = runner.invoke(main, ["run", str(single), "model.params.V_IN=0.35",
                               "noise.measurement_sigma=0.05", "--runs", "2", "--quiet",
                               "--out", str(tmp_path / "one")])
    assert one.exit_code == 0, one.output
    ref = pd.read_csv(tmp_path / "one" / "tiny" / "rmse.csv")
    cell = table[(table["sweep:model.params.V_IN"] == 0.35)
                 & (table["sweep:noise.measurement_sigma"] == 0.05)]
    pd.testing.assert_frame_equal(cell.iloc[:, 2:].reset_index(drop=True), ref)
    bad = runner.invoke(main, ["validate", str(path), "sweep={model.params.V_NO: [1]}"])
    assert bad.exit_code == 2 and ": sweep.model.params.V_NO[0]: " in bad.output


@pytest.mark.parametrize("fmt, magic", [("pdf", b"%PDF"), ("svg", b"<?xml")])
def test_vector_figures_are_deterministic(tmp_path, fmt, magic):
    path = write(tmp_path, tiny_config())
    runner = CliRunner()
    for out in ("a", "b"):
        assert runner.invoke(main, ["run", str(path), "--runs", "2", "--quiet", "--out",
                                    str(tmp_path / out), "--figure-format", fmt]).exit_code == 0
    figures = sorted((tmp_path / "a" / "tiny" / "figures").glob(f"*.{fmt}"))
    assert figures and not list((tmp_path / "a" / "tiny" / "figures").glob("*.png"))
    for f in figures:
        data = f.read_bytes()
        assert data.startswith(magic) and data == (tmp_path / "b" / "tiny" / "figures" /
                                                   f.name).read_bytes()


def test_table_help_lists_every_metric_with_its_analyses():
    from estim.engine import runner

    text = CliRunner().invoke(main, ["table", "--help"]).output
    for metric, specs in runner.table_specs().items():
        line = next(line for line in text.splitlines() if line.strip().startswith(metric + " "))
        assert all(name in line for name in specs), line


def test_without_a_terminal_progress_is_one_line_per_work_unit(tmp_path):
    path = write(tmp_path, tiny_config(**{"input.frequencies_hz": [100, 1000]}))
    result = CliRunner().invoke(main, ["run", str(path), "--runs", "2", "--out",
                                       str(tmp_path / "res")])
    assert result.exit_code == 0, result.output
    lines = [line for line in result.output.splitlines() if " done, " in line]
    total = int(lines[0].split("/")[1].split()[0])
    assert len(lines) == total and lines[-1].startswith(f"tiny: {total}/{total} done")
    assert all("s elapsed, about" in line and "s left" in line for line in lines)


def test_figure_streams_never_touch_the_tables(tmp_path):
    """A figure case that is no sweep point draws its own batch from the figures' key space
    (spawn key 2**31 + ...): adding one changes figures only, never a table."""
    runner = CliRunner()
    outs = []
    for i, level in enumerate((0.01, 0.07)):                 # 0.07 is not a sweep point
        path = write(tmp_path, tiny_config(**{"figures.noise_level": level}), f"c{i}.yaml")
        out = tmp_path / f"r{i}"
        assert runner.invoke(main, ["run", str(path), "--out", str(out), "--quiet"]).exit_code == 0
        outs.append(out / "tiny")
    for name in ("rmse.csv", "residual.csv", "health.csv", "claims.csv"):
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), name
    fig = "figures/fig_3_5.png"
    assert (outs[0] / fig).read_bytes() != (outs[1] / fig).read_bytes()


@pytest.mark.slow
def test_a_sweep_over_a_key_that_is_also_a_column_keeps_both(tmp_path):
    """``regime`` is a config key and an rmse column: the swept value gets its own column,
    and ``estim table`` shows it in front."""
    spec = tiny_config()
    spec["sweep"] = {"regime": ["weak_inversion_saturation", "weak_inversion_conduction"]}
    _, table = run_swept(tmp_path, spec)
    runner = CliRunner()
    assert (table["sweep:regime"] == table["regime"]).all()
    assert table["regime"].nunique() == 2
    shown = runner.invoke(main, ["table", "rmse", "--results", str(tmp_path / "sw"),
                                 "--format", "csv"])
    assert shown.exit_code == 0, shown.output
    assert list(pd.read_csv(StringIO(shown.output)).columns[:2]) == ["experiment",
                                                                     "sweep:regime"]


@pytest.mark.slow
def test_shards_of_a_sweep_share_every_cell_and_merge_to_one_run(tmp_path):
    spec = tiny_config(**{"input.frequencies_hz": [100, 1000]})
    spec["sweep"] = {"noise.measurement_sigma": [0.05, 0.1]}
    path = write(tmp_path, spec)
    runner = CliRunner()
    args = [str(path), "--runs", "2", "--quiet"]
    assert runner.invoke(main, ["run", *args, "--out", str(tmp_path / "one")]).exit_code == 0
    cells = []
    for k in (1, 2):
        shard = runner.invoke(main, ["run", *args, "--out", str(tmp_path / f"s{k}"),
                                     "--shard", f"{k}/2"])
        assert shard.exit_code == 0 and "finish with 'estim merge'" in shard.output
        cells += [p.name for p in (tmp_path / f"s{k}").glob(".tiny.cells-*/cell-*.npz")]
    assert {c.split("-")[1] for c in cells} == {"1", "2"}      # both sweep cells were shared
    merged = runner.invoke(main, ["merge", *args, "--from", str(tmp_path / "s1"), "--from",
                                  str(tmp_path / "s2"), "--out", str(tmp_path / "m")])
    assert merged.exit_code == 0, merged.output
    assert not merged.output.count("no cells")
    for name in ("rmse.csv", "residual.csv", "health.csv"):
        assert (tmp_path / "m" / "tiny" / name).read_bytes() == \
            (tmp_path / "one" / "tiny" / name).read_bytes()
    lost = runner.invoke(main, ["merge", str(path), "--quiet", "--from", str(tmp_path / "s1"),
                                "--out", str(tmp_path / "m3")])
    assert lost.exit_code == 0 and "no cells of this config" in lost.output
    for k in (1, 2, 3, 4):             # 4 work units over 2 sweep cells: one for each shard
        shard = runner.invoke(main, ["run", *args, "--out", str(tmp_path / "q"),
                                     "--shard", f"{k}/4"])
        assert f"shard {k}/4: 1 cell(s)" in shard.output, shard.output


def test_an_analysis_that_does_not_split_says_so_under_shard(tmp_path):
    spec = yaml.safe_load((ROOT / "configs" / "fir_differentiator.yaml").read_text())
    path = write(tmp_path, spec, "fir.yaml")
    result = CliRunner().invoke(main, ["run", str(path), "--shard", "1/2", "--out",
                                       str(tmp_path / "s")])
    assert result.exit_code == 0, result.output
    assert "does not split into work units" in result.output
    assert not list((tmp_path / "s").glob(".*cells-*"))


def test_quick_runs_the_first_cell_of_a_sweep_over_list_items(tmp_path):
    spec = tiny_config(**{"input.frequencies_hz": [100, 1000, 10000]})
    spec["sweep"] = {"input.frequencies_hz[2]": [20000, 30000]}
    path = write(tmp_path, spec)
    result = CliRunner().invoke(main, ["run", str(path), "--quick", "--quiet", "--out",
                                       str(tmp_path / "q")])
    assert result.exit_code == 0, result.output
    table = pd.read_csv(tmp_path / "q" / "tiny" / "rmse.csv")
    assert not [c for c in table.columns if c.startswith("sweep:")]


def test_exponent_floats_read_as_numbers_in_files_and_nested_overrides(tmp_path):
    text_ = (ROOT / "configs" / "mosfet_saturation.yaml").read_text()
    path = tmp_path / "e.yaml"
    path.write_text(text_.replace("rtol: 1.0e-5", "rtol: 1e-5"))
    assert "rtol: 1e-5" in path.read_text()
    assert CliRunner().invoke(main, ["validate", str(path)]).exit_code == 0
    key, value = parse_override("simulation={rtol: 1e-7, atol: 2E-9}")
    assert value == {"rtol": 1e-7, "atol": 2e-9}


def test_sweep_work_counts_what_each_value_costs(tmp_path):
    """A swept ``monte_carlo.runs`` scales the grid's work: the --max-work bound sees it."""
    from estim.config.loading import parse_data
    from estim.config.registry import ANALYSES

    spec = tiny_config()
    work = ANALYSES["estimation"].work_size(parse_data(spec, "t", "tiny").config)
    runner = CliRunner()
    spec["sweep"] = {"monte_carlo.runs": [3, 3]}
    cheap = write(tmp_path, spec, "cheap.yaml")
    limit = str(int(3.5 * work))                  # each cell below it, the grid of [3, 9] above
    assert runner.invoke(main, ["validate", str(cheap), "--max-work", limit]).exit_code == 0
    spec["sweep"] = {"monte_carlo.runs": [3, 9]}
    dear = write(tmp_path, spec, "dear.yaml")
    refused = runner.invoke(main, ["validate", str(dear), "--max-work", limit])
    assert refused.exit_code == 2 and ": sweep: 2 cells of about" in refused.output


def test_a_sweep_grid_is_validated_whole_and_overrides_of_swept_keys_are_refused(tmp_path):
    spec = tiny_config()
    spec["sweep"] = {"estimators[2].label": ["X", "Y"], "estimators[3].label": ["Y", "Z"]}
    path = write(tmp_path, spec)
    runner = CliRunner()
    bad = runner.invoke(main, ["validate", str(path)])
    assert bad.exit_code == 2 and ": sweep: the cell estimators.2.label='Y', " in bad.output
    assert "duplicate label 'Y'" in bad.output, bad.output
    spec["sweep"] = {"estimators[2].label": ["X"], "estimators.2.label": ["Y"]}
    twice = runner.invoke(main, ["validate", str(write(tmp_path, spec, "twice.yaml"))])
    assert twice.exit_code == 2 and "the same key path as another sweep key" in twice.output
    spec["sweep"] = {"noise.measurement_sigma": [0.05, 0.1], "monte_carlo.runs": [2, 3]}
    swept = write(tmp_path, spec, "swept.yaml")
    for args in (["noise.measurement_sigma=0.2"], ["--runs", "4"], ["noise=null"]):
        refused = runner.invoke(main, ["run", str(swept), *args, "--out", str(tmp_path / "o")])
        assert refused.exit_code == 2 and "the config's sweep block sets" in refused.output, \
            refused.output
    plain = write(tmp_path, tiny_config(), "plain.yaml")        # the sweep given as an override
    refused = runner.invoke(main, ["run", str(plain), "sweep={monte_carlo.runs: [2, 3]}",
                                   "--runs", "4", "--out", str(tmp_path / "o")])
    assert refused.exit_code == 2 and "sweep=... given here sets monte_carlo.runs" in \
        refused.output, refused.output


def test_quick_ignores_the_size_of_the_grid_it_does_not_run(tmp_path):
    spec = tiny_config()
    spec["sweep"] = {"monte_carlo.runs": [3, 4, 5]}
    path = write(tmp_path, spec)
    runner = CliRunner()
    from estim.config.loading import parse_data
    from estim.config.registry import ANALYSES

    work = ANALYSES["estimation"].work_size(parse_data(tiny_config(), "t", "tiny").config)
    limit = str(2 * work)                       # one cell fits, the grid of three does not
    assert runner.invoke(main, ["validate", str(path), "--max-work", limit]).exit_code == 2
    quick = runner.invoke(main, ["run", str(path), "--quick", "--quiet", "--max-work", limit,
                                 "--out", str(tmp_path / "q")])
    assert quick.exit_code == 0, quick.output


@pytest.mark.slow
def test_gain_table_skips_a_swept_experiment_without_gain_values(tmp_path):
    spec = yaml.safe_load((ROOT / "configs" / "cco_distortion.yaml").read_text())
    spec["sweep"] = {"title": ["a", "b"]}
    path = write(tmp_path, spec, "cco.yaml")
    runner = CliRunner()
    assert runner.invoke(main, ["run", str(path), "--quiet", "--out",
                                str(tmp_path / "r")]).exit_code == 0
    assert "sweep:title" in (tmp_path / "r" / "cco_distortion" / "distortion.csv").read_text()
    shown = runner.invoke(main, ["table", "gain", "--results", str(tmp_path / "r")])
    assert shown.exit_code == 2 and "no gain values" in shown.output, shown.output


@pytest.mark.slow
def test_a_sweep_holds_one_cells_figures_at_a_time(tmp_path, monkeypatch):
    import gc
    import weakref

    from estim import store

    spec = tiny_config()
    spec["sweep"] = {"noise.measurement_sigma": [0.05, 0.1, 0.15, 0.2]}
    path = write(tmp_path, spec)
    seen: weakref.WeakSet = weakref.WeakSet()
    alive_counts = []
    real = store.write_figure

    def counting(fig, where):
        seen.add(fig)
        gc.collect()
        alive_counts.append(len(seen))          # figures drawn so far and still held
        real(fig, where)

    monkeypatch.setattr(store, "write_figure", counting)
    result = CliRunner().invoke(main, ["run", str(path), "--runs", "2", "--quiet", "--out",
                                       str(tmp_path / "r")])
    assert result.exit_code == 0, result.output
    per_cell = len(alive_counts) // 4
    assert per_cell >= 1 and max(alive_counts) <= per_cell
    assert len(list((tmp_path / "r" / "tiny" / "figures").glob("*_sweep4.png"))) == per_cell


def test_jobs_defaults_to_the_usable_cores():
    """issue 27: --jobs defaults to the cores the process may run on (its affinity)."""
    import os

    import click

    for name in ("run", "reproduce", "check"):
        command = main.commands[name]
        option = next(p for p in command.params if p.name == "jobs")
        ctx = click.Context(command)
        assert option.get_default(ctx) == len(os.sched_getaffinity(0))


def test_report_renders_deviations_and_leaves_out_empty_tables_and_missing_metadata(
        tmp_path, rehash):
    from estim.report import html as report

    html_ = report.markdown("**D28.** The *printed* bias (eq 2.14):\n- one `x`\n  continued\n"
                            "- two [see](#D3), [away](https://example.org)\n\nLast.")
    assert html_.startswith("<p><strong>D28.</strong> The <em>printed</em> bias")
    assert "<li>one <code>x</code> continued</li>" in html_
    assert '<a href="#D3">see</a>' in html_ and "away" in html_ and "example.org" not in html_
    assert html_.endswith("<p>Last.</p>") and "**" not in html_
    empty = pd.DataFrame({"table_id": [""], "gain": [float("nan")]})
    section = report.Section("x", "t", {"seed": None, "runs": None, "wall_time_s": 1.5},
                             tables=[("gain", "gain: G", empty)])
    page = report.page("p", [section])
    assert "Left out, no values in any cell: gain: G" in page and "<h3>gain: G" not in page
    assert "seed None" not in page and "runs None" not in page and "wall time 1.5 s" in page
    results = tmp_path / "res"
    shutil.copytree(ROOT / "results" / "mosfet_distortion", results / "mosfet_distortion")
    gain = results / "mosfet_distortion" / "distortion.csv"
    df = pd.read_csv(gain)
    keys = ANALYSES["perturbation"].TABLES["distortion"].keys
    for column in (c for c in df.columns if c not in keys):
        df[column] = float("nan")
    df.to_csv(gain, index=False)
    rehash(gain.parent)                     # as if a run had made the empty table
    section = report.sections(results, "", None, ANALYSES)[0]
    assert sorted(c.split(":")[0] for c in section.empty) == ["distortion", "gain"]
    assert [m for m, _, _ in section.tables] == ["claims"]


def test_an_unexpected_error_is_one_line_and_debug_shows_its_traceback(monkeypatch, tmp_path):
    """An error no check foresaw (here a TypeError inside config loading) is one line with a
    pointer to --debug; with --debug (or ESTIM_DEBUG=1) the traceback is printed and written
    to the debug log; a config mistake stays one line either way."""
    from estim.cli import group, results

    def broken(*args, **kwargs):
        raise TypeError("boom inside the loader")

    monkeypatch.setattr(results.config, "load_files", broken)
    monkeypatch.setattr(group, "debug_log", lambda: str(tmp_path / "estim-debug.log"))
    plain = CliRunner().invoke(main, ["validate", "x.yaml"])
    assert plain.exit_code == 3
    assert plain.output.strip().splitlines() == [
        "error: TypeError: boom inside the loader (estim --debug shows the traceback)"]
    for args, env in ((["--debug", "validate", "x.yaml"], {}),
                      (["validate", "x.yaml"], {"ESTIM_DEBUG": "1"})):
        out = CliRunner().invoke(main, args, env=env)
        assert out.exit_code == 3
        assert "Traceback (most recent call last)" in out.output
        assert "in broken" in out.output
        log = (tmp_path / "estim-debug.log").read_text()
        assert "TypeError: boom inside the loader" in log and "in broken" in log
    monkeypatch.undo()
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(tiny_config(**{"monte_carlo.runz": 3})))
    out = CliRunner().invoke(main, ["--debug", "validate", str(bad)])
    assert out.exit_code == 2 and "Traceback" not in out.output
    assert "monte_carlo.runz" in out.output


def test_python_dash_m_estim_is_the_command():
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "estim", "--version"], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.startswith("estim, version ")


def test_a_colon_override_gets_a_syntax_hint_not_no_such_file(tmp_path):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(tiny_config()))
    out = CliRunner().invoke(main, ["validate", str(config), "monte_carlo.runs:5"])
    assert out.exit_code == 2
    assert out.output.strip() == ("error: 'monte_carlo.runs:5': no such config file; an "
                                  "override is written key.path=value (monte_carlo.runs=5)")
    drive = CliRunner().invoke(main, ["validate", "C:/nothing.yaml"])
    assert drive.exit_code == 2 and "override" not in drive.output


@pytest.mark.parametrize("command", ["run", "reproduce", "check", "table", "summary",
                                     "settings", "list", "report", "validate", "tune",
                                     "spice", "merge"])
def test_help_texts_carry_no_rest_markup(command):
    out = CliRunner().invoke(main, [command, "--help"])
    assert out.exit_code == 0 and "``" not in out.output and ":func:" not in out.output


def test_list_groups_every_config_aligned_and_as_json():
    """estim list shows configs/, configs/studies/ and configs/netlist/ under their own
    heads, names in one column; --json gives the same configs as data."""
    import json

    root = Path(__file__).resolve().parents[1] / "configs"
    out = CliRunner().invoke(main, ["list"])
    assert out.exit_code == 0
    lines = out.output.splitlines()
    heads = [line for line in lines if line.startswith("configs")]
    counts = {"configs": len(list(root.glob("*.yaml"))),
              "configs/studies": len(list((root / "studies").glob("*.yaml"))),
              "configs/netlist": len(list((root / "netlist").glob("*.yaml")))}
    assert [h.split("/ (")[0] for h in heads] == list(counts)
    for head in heads:
        assert head.endswith(f", {counts[head.split('/ (')[0]]} configs)")
    rows = [line for line in lines if line.startswith("  ")]
    assert len(rows) == sum(counts.values())
    starts = {line.index(line.split()[1], len(line.split()[0]) + 2) for line in rows}
    assert len(starts) == 1                          # the tables column is aligned
    assert any(" 5.1-5.12 " in line for line in rows)
    data = json.loads(CliRunner().invoke(main, ["list", "--json"]).output)
    assert len(data) == len(rows)
    assert {e["group"] for e in data} == set(counts)
    saturation = next(e for e in data if e["name"] == "mosfet_saturation")
    assert saturation["tables"] == ["3.2", "3.4"] and saturation["analysis"] == "estimation"


@pytest.mark.slow
def test_check_json_reports_each_config_and_keeps_the_exit_code(tmp_path):
    import json

    path = write(tmp_path, tiny_config())
    out = tmp_path / "out"
    assert CliRunner().invoke(main, ["run", str(path), "--out", str(out), "--quiet"]
                              ).exit_code == 0
    same = CliRunner().invoke(main, ["check", str(path), "--results", str(out), "--json"])
    assert same.exit_code == 0
    data = json.loads(same.stdout)
    assert data["differences"] == 0 and [c["config"] for c in data["configs"]] == ["tiny"]
    assert any(line.endswith("rows match") for line in data["configs"][0]["lines"])
    rmse = out / "tiny" / "rmse.csv"
    df = pd.read_csv(rmse)
    df.loc[0, "rmse"] *= 1.01
    df.to_csv(rmse, index=False)
    moved = CliRunner().invoke(main, ["check", str(path), "--results", str(out), "--json"])
    assert moved.exit_code == 1
    data = json.loads(moved.stdout)
    assert data["differences"] >= 1 and data["configs"][0]["differences"] >= 1
    assert any("rmse" in line for line in data["configs"][0]["lines"])


@pytest.mark.slow
def test_a_run_with_no_compiled_kernel_cached_says_numba_compiles_first(tmp_path):
    from estim.cli.output import COMPILING

    path = write(tmp_path, tiny_config())
    empty = tmp_path / "numba-cache"
    args = ["validate", str(path)]
    run = ["run", str(path), "--out", str(tmp_path / "out"), "monte_carlo.runs=2"]
    fresh = CliRunner().invoke(main, run, env={"NUMBA_CACHE_DIR": str(empty)})
    assert fresh.exit_code == 0 and COMPILING in fresh.stderr
    (empty / "sub").mkdir(parents=True)
    (empty / "sub" / "kernel-1.py311.nbi").write_bytes(b"")
    cached = CliRunner().invoke(main, run, env={"NUMBA_CACHE_DIR": str(empty)})
    assert cached.exit_code == 0 and COMPILING not in cached.stderr
    quiet = CliRunner().invoke(main, [*run, "--quiet"],
                               env={"NUMBA_CACHE_DIR": str(tmp_path / "none")})
    assert COMPILING not in quiet.stderr
    assert COMPILING not in CliRunner().invoke(main, args).output
