"""Issue 47, item 8: the filters on measured data (analysis: measured), with no actual
circuit: innovations, NIS and estimates, and the claims on the one-step prediction error."""

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from test_cli import apply_changes

import estim
from estim.errors import ConfigError
from estim.experiments import measured

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "configs" / "rectifier_measured.yaml"


def config_with(tmp_path, csv_text: str | None = None, **data) -> Path:
    """The shipped config beside ``csv_text`` (default: the shipped record), its data block
    changed by ``data``."""
    spec = yaml.safe_load(SHIPPED.read_text())
    (tmp_path / "record.csv").write_text(
        csv_text or (ROOT / "configs" / "data" / "rectifier_measured.csv").read_text())
    spec["data"].update({"file": "record.csv", **data})
    path = tmp_path / "measured.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def own_record(runs_seed: int = 3, sigma: float = 0.02) -> str:
    """A record the rectifier model itself makes (estim's integrator), with measurement
    noise of ``sigma``: the EKF's own assumptions hold on it."""
    from estim.numerics.simulate import SOLVERS

    exp = estim.experiment(SHIPPED)
    model, dt = exp.plan.model, 1.0 / 2000
    t = np.arange(401) * dt
    source = (0.5 + np.sin(2 * np.pi * 50 * t))[:, None]
    x0 = model.operating_point(u=model.source_to_input(source[None, :2], dt)[0, 0])
    states = SOLVERS["batched_radau"](model, x0, model.source_to_input(source[None], dt), dt,
                                      rtol=1e-9, atol=1e-12)
    out = np.concatenate([model.h(x0[None, None])[0, :, 0], model.h(states)[0, :, 0]])
    z = out + sigma * np.random.default_rng(runs_seed).standard_normal(out.size)
    return "t_s,v_in,v_out\n" + "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in
                                        zip(t.tolist(), source[:, 0].tolist(), z.tolist(),
                                            strict=True))


def test_on_a_record_its_own_model_made_the_ekf_is_consistent_and_beats_the_last_sample(
        tmp_path):
    result = estim.run(config_with(tmp_path, own_record()))
    rows = result.tables["innovation"].set_index("estimator")
    ekf = rows.loc["EKF"]
    assert 0.9 < ekf["nis_mean"] < 1.3                   # NIS about m = 1: Q, R as the data
    assert ekf["innovation_rms"] < 1.2 * 0.02 * np.sqrt(1 + 0.25)
    assert abs(ekf["innovation_mean"]) < 3 * ekf["innovation_mean_se"] + 1e-3
    claims = result.tables["claims"].set_index("claim")
    assert claims.loc["EKF prediction MSE < last measurement prediction MSE",
                      "verdict"] == "holds"


def test_the_tables_are_the_filters_run_directly_on_the_same_arrays(tmp_path):
    exp = estim.experiment(config_with(tmp_path))
    result = estim.run(config_with(tmp_path))
    plan = exp.plan
    dt = plan.t[1] - plan.t[0]
    label, est, model = plan.filters[0]
    direct = est.run(model, plan.z[None, 1:, None],
                     model.source_to_input(plan.source[None], dt), dt, x0=plan.x0)
    rows = result.tables["estimates"]
    output = rows[(rows["estimator"] == label) & (rows["quantity"] == "output")]
    assert np.array_equal(output["value"].to_numpy(), direct.y_hat[0, :, 0])
    state = rows[(rows["estimator"] == label) & (rows["quantity"] == model.state_names[0])]
    assert np.array_equal(state["sd"].to_numpy(), np.sqrt(direct.P[0, :, 0, 0]))
    e = direct.innovation[0, :, 0]
    row = result.tables["innovation"].set_index("estimator").loc[label]
    assert row["innovation_rms"] == pytest.approx(np.sqrt(np.mean(e ** 2)), rel=1e-12)
    last = result.tables["innovation"].set_index("estimator").loc[measured.PERSISTENCE]
    assert last["innovation_rms"] == pytest.approx(np.sqrt(np.mean(np.diff(plan.z) ** 2)),
                                                   rel=1e-12)


@pytest.mark.parametrize("csv_text, data, key, expected", [
    (None, {"output": "v_nosuch"}, "data.output", "no column 'v_nosuch'.*t_s, v_in, v_out"),
    ("t_s,v_in,v_out\n0,0.5,0.1\n1e-3,0.5,0.1\n3e-3,0.5,0.1\n" * 1, {"file": "record.csv"},
     "data.file", "at least"),
    ("t_s,v_in,v_out\n" + "".join(f"{k * 1e-3 + (1e-4 if k == 7 else 0)},0.5,0.1\n"
                                  for k in range(60)), {}, "data.time", "line 9: the times"),
    ("t_s,v_in,v_out\n0,0.5,x\n", {}, "data.output", "line 2: column 'v_out' is not a number"),
    (None, {"file": "nosuch.csv"}, "data.file", "no file 'nosuch.csv'"),
])
def test_a_record_that_does_not_fit_is_one_error_at_its_key(tmp_path, csv_text, data, key,
                                                            expected):
    with pytest.raises(ConfigError, match=f"{key}: .*{expected}"):
        estim.experiment(config_with(tmp_path, csv_text, **data))


def test_the_shipped_record_is_what_its_script_makes(tmp_path):
    """configs/data/rectifier_measured.py re-made with ngspice gives the shipped numbers."""
    if shutil.which("ngspice") is None:
        pytest.skip("ngspice is not installed")
    made = tmp_path / "made.csv"
    subprocess.run([sys.executable, str(ROOT / "configs" / "data" / "rectifier_measured.py"),
                    str(made)], check=True, cwd=ROOT)
    shipped = pd.read_csv(ROOT / "configs" / "data" / "rectifier_measured.csv")
    again = pd.read_csv(made)
    assert list(again.columns) == list(shipped.columns)
    assert np.allclose(again.to_numpy(), shipped.to_numpy(), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("key, value, expected", [
    ("data.time", 3, "non-empty string"),
    ("data.bias_v", "0.5", "list"),
    ("blocks", 2, "integer"),
    ("seed", -1, "integer"),
    ("figure", "a/b", "it names a file"),
])
def test_a_wrong_measured_key_is_one_line_naming_the_file_and_the_key(tmp_path, key, value,
                                                                      expected):
    """The measured analysis' keys through the command line: one error line naming the
    config file, the key path and what was expected, exit 2."""
    from click.testing import CliRunner

    from estim.cli.main import main

    spec = apply_changes(yaml.safe_load(config_with(tmp_path).read_text()), {key: value})
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(spec))
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2, result.output
    assert f"{path}: {key}: " in result.output and expected in result.output, result.output
