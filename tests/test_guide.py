"""The docs' guides (docs/extending.md, docs/your-circuit.md, docs/your-data.md), followed as
written: the
model, estimator and config files are taken from their code blocks, run through the CLI,
and seen in the tables; the Python example runs as written from another folder."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from estim.cli.main import main

ROOT = Path(__file__).resolve().parents[1]


GUIDES = ("extending.md", "your-circuit.md", "your-data.md")
"""The docs pages whose guides this follows."""


def section(title: str) -> str:
    """The part of a guide page from the heading ``title`` to the next heading of its
    level (the page's end for a page's own title)."""
    for page in GUIDES:
        text = (ROOT / "docs" / page).read_text()
        if title in text:
            start = text.index(title)
            level = title.split(" ")[0]
            if level == "#":
                return text[start:]
            end = text.find(f"\n{level} ", start + len(title))
            return text[start:end if end > 0 else None]
    raise AssertionError(f"no guide in docs/ has the heading {title!r}")


def blocks(text: str) -> list[str]:
    return re.findall(r"```(?:python|yaml)\n(.*?)```", text, re.S)


def guide_files(tmp_path: Path) -> Path:
    """Write every code block of the guide that starts with ``# <file name>``; return the
    config's path."""
    config = None
    for block in blocks(section("## Adding a model or an estimator")):
        first = block.splitlines()[0]
        match = re.fullmatch(r"# ([\w.-]+\.(?:py|yaml))", first)
        assert match, f"a guide block without its file name: {first!r}"
        (tmp_path / match.group(1)).write_text(block)
        if match.group(1).endswith(".yaml"):
            config = tmp_path / match.group(1)
    assert config is not None
    return config


def test_the_guide_runs_as_written(tmp_path, monkeypatch):
    """Steps 3 and 4 as the README gives them, in the folder of the guide's files."""
    config = guide_files(tmp_path)
    monkeypatch.chdir(tmp_path)
    for name, plugin, key in (("diode_rc", "diode_rc.py", "I_S"),
                              ("iekf", "iterated_ekf.py", "iterations")):
        listed = CliRunner().invoke(main, ["settings", name, "--plugin", plugin])
        assert listed.exit_code == 0, listed.output
        assert f"`{name}`" in listed.output and f"| {key} |" in listed.output
    result = CliRunner().invoke(main, ["run", config.name])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "scratch" / "rectifier"
    printed = CliRunner().invoke(main, ["table", "rmse", "--results", "scratch"])
    assert printed.exit_code == 0, printed.output
    assert "IEKF" in printed.output
    rmse = pd.read_csv(folder / "rmse.csv")
    assert {"EKF", "IEKF", "measurement"} <= set(rmse["estimator"])
    assert np.isfinite(rmse["rmse"]).all()
    claims = pd.read_csv(folder / "claims.csv")
    assert "IEKF RMSE < EKF RMSE" in set(claims["claim"])
    assert {"EKF", "IEKF"} <= set(pd.read_csv(folder / "states.csv")["estimator"])
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["models"]["model.params"]["name"] == "diode_rc"
    iekf = next(e for e in manifest["config"]["estimators"] if e["type"] == "iekf")
    assert iekf["settings"]["iterations"] == 3 and iekf["settings"]["noise_units"] == "thesis"
    listed = CliRunner().invoke(main, ["validate", str(config)])
    assert listed.exit_code == 0, listed.output


def test_the_guides_iterated_ekf_is_the_ekf_for_a_linear_output(tmp_path):
    """With one iteration, or any number on a model whose output is linear in the state, the
    iterated update is the EKF's update: the two filters agree to rounding."""
    config = guide_files(tmp_path)
    from estim.config import registry
    from estim.config.loading import load_file

    load_file(config)                                   # imports the plugins
    model = registry.MODELS["diode_rc"]()
    ekf = registry.ESTIMATORS["ekf"](Q=1e-6, R=4e-4, P0=1e-4)
    rng = np.random.default_rng(3)
    z = 0.5 + 0.02 * rng.standard_normal((3, 50, 1))
    u = 0.5 + np.sin(np.linspace(0, 6, 50))[:, None]
    x0 = model.operating_point(u=np.array([0.5]))
    a = ekf.run(model, z, u, 5e-4, x0=x0)
    for iterations in (1, 4):
        iekf = registry.ESTIMATORS["iekf"](Q=1e-6, R=4e-4, P0=1e-4, iterations=iterations)
        b = iekf.run(model, z, u, 5e-4, x0=x0)
        np.testing.assert_allclose(b.y_hat, a.y_hat, rtol=1e-12, atol=1e-14)


def test_a_plugin_is_seen_only_by_the_config_that_loads_it(tmp_path):
    """Validating the guide's config first (which loads its plugins into this process) does
    not make their names valid for another config: the second file fails exactly as it does
    alone, and the estimator list it is told of leaves the plugin's out."""
    config = guide_files(tmp_path)
    spec = yaml.safe_load(config.read_text())
    del spec["plugins"]
    spec["name"] = "no_plugins"
    other = tmp_path / "sub" / "no_plugins.yaml"
    other.parent.mkdir()
    other.write_text(yaml.safe_dump(spec))
    alone = CliRunner().invoke(main, ["validate", str(other)])
    both = CliRunner().invoke(main, ["validate", str(config), str(other)])
    assert alone.exit_code == both.exit_code == 2, both.output
    assert f"{other}: model.name: " in both.output
    assert alone.output.splitlines()[-1] == both.output.splitlines()[-1]
    from estim.config import registry

    assert "iekf" in registry.ESTIMATORS                 # visible outside any config


def test_a_bad_plugin_is_one_line_naming_the_config_and_the_file(tmp_path):
    config = guide_files(tmp_path)
    (tmp_path / "diode_rc.py").write_text("raise RuntimeError('broken on purpose')\n")
    result = CliRunner().invoke(main, ["validate", str(config)])
    assert result.exit_code == 2
    assert result.output.count("\n") == 1
    assert f"{config}: plugins[0]: importing diode_rc.py failed: RuntimeError" in result.output
    (tmp_path / "diode_rc.py").write_text("import sys\nsys.exit(0)\n")   # would end estim, exit 0
    result = CliRunner().invoke(main, ["validate", str(config)])
    assert result.exit_code == 2 and "importing diode_rc.py called sys.exit(0)" in result.output


def test_the_python_example_runs_as_written_from_another_folder(tmp_path):
    code = next(b for b in blocks(section("## From Python")) if "import estim" in b)
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "rmse" in done.stdout and "exponential" in done.stdout


@pytest.mark.parametrize("title", ["## Adding a model or an estimator", "## From Python"])
def test_the_guide_sections_exist(title):
    assert blocks(section(title))


def saved_files(title: str, folder: Path) -> dict[str, Path]:
    """Write every block of a guide section introduced by "Save as `NAME`"."""
    found = {}
    for name, body in re.findall(r"Save as `([\w.-]+)`[^\n]*\n(?:[^\n]*\n)*?\n```\w+\n(.*?)```",
                                 section(title), re.S):
        (folder / name).write_text(body)
        found[name] = folder / name
    return found


def test_your_own_circuit_runs_as_written(tmp_path, monkeypatch):
    """The netlist guide (docs/your-circuit.md), step by step: the netlist and the config
    from its blocks, `estim run`, `estim table rmse --results scratch`, and (where ngspice
    is installed) `estim spice`."""
    files = saved_files("# Your own circuit", tmp_path)
    assert set(files) == {"rectifier.cir", "rectifier_spice.yaml"}
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    result = runner.invoke(main, ["run", "rectifier_spice.yaml", "--quiet"])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "scratch" / "rectifier_spice"
    rmse = pd.read_csv(folder / "rmse.csv")
    assert set(rmse["estimator"]) == {"EKF", "RLS", "measurement"}
    assert np.isfinite(rmse["rmse"]).all()
    assert "EKF RMSE < RLS RMSE" in set(pd.read_csv(folder / "claims.csv")["claim"])
    assert {"nees_mean", "nis_mean"} <= set(pd.read_csv(folder / "health.csv").columns)
    shown = runner.invoke(main, ["table", "rmse", "--results", "scratch"])
    assert shown.exit_code == 0 and "rectifier_spice" in shown.output, shown.output
    if __import__("shutil").which("ngspice") is None:
        pytest.skip("ngspice is not installed here (Debian: apt-get install ngspice); the "
                    "guide's last step, estim spice, is left out")
    checked = runner.invoke(main, ["spice", "rectifier_spice.yaml"])
    assert checked.exit_code == 0, checked.output
    assert "within their bars" in checked.output


def test_your_own_data_runs_as_written(tmp_path, monkeypatch):
    """The measured-data guide (docs/your-data.md): the shipped record copied as its step 1
    says, the config from its block, `estim run`, and the tables it names."""
    import shutil

    files = saved_files("# Your own data", tmp_path)
    assert set(files) == {"my_record.yaml"}
    shutil.copy(ROOT / "configs" / "data" / "rectifier_measured.csv", tmp_path / "record.csv")
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["run", "my_record.yaml", "--quiet"])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "scratch" / "my_record"
    rows = pd.read_csv(folder / "innovation.csv")
    assert list(rows["estimator"]) == ["last measurement", "EKF", "RLS"]
    claims = pd.read_csv(folder / "claims.csv").set_index("claim")
    assert claims.loc["EKF prediction MSE < last measurement prediction MSE",
                      "verdict"] == "holds"
    estimates = pd.read_csv(folder / "estimates.csv")
    assert {"v(out)", "output"} <= set(estimates["quantity"])
    assert (folder / "figures" / "estimates.png").is_file()


def test_settings_lists_a_plugin_only_when_named_and_names_a_bad_one(tmp_path, monkeypatch):
    """``estim settings NAME --plugin FILE``: the plugin's classes are listed with the flag
    and not without it (docs/settings.md stays estim's own); a file that cannot be read or
    imported is one line naming the flag's file, exit 2."""
    guide_files(tmp_path)
    monkeypatch.chdir(tmp_path)
    named = CliRunner().invoke(main, ["settings", "iekf", "--plugin", "iterated_ekf.py"])
    assert named.exit_code == 0 and "| iterations |" in named.output
    assert "### estimator `iekf`" in CliRunner().invoke(
        main, ["settings", "--plugin", "iterated_ekf.py"]).output
    alone = CliRunner().invoke(main, ["settings", "iekf"])
    assert alone.exit_code == 2 and "no analysis, estimator or model named 'iekf'" in alone.output
    assert "`iekf`" not in CliRunner().invoke(main, ["settings"]).output
    missing = CliRunner().invoke(main, ["settings", "iekf", "--plugin", "nothere.py"])
    assert missing.exit_code == 2
    assert "error: --plugin nothere.py: cannot read 'nothere.py'" in missing.output
    (tmp_path / "broken.py").write_text("raise ValueError('boom')\n")
    broken = CliRunner().invoke(main, ["settings", "iekf", "--plugin", "broken.py"])
    assert broken.exit_code == 2
    assert ("error: --plugin broken.py: importing broken.py failed: ValueError: boom"
            in broken.output)


def test_the_python_api_refuses_what_the_cli_refuses(tmp_path):
    """estim.run(..., quick=True).save() replaced a stored full run (the CLI's --quick never
    writes results/); runs=None deleted the config's value; a '.yml' typo ran the shipped
    '.yaml'; jobs="2" failed deep inside with a TypeError."""
    import estim
    from estim.errors import ConfigError, UsageError

    full = estim.run("kalman_differentiator", runs=2)
    full.save(tmp_path)
    quick = estim.run("kalman_differentiator", quick=True, runs=None)
    with pytest.raises(UsageError, match="holds a full run's results"):
        quick.save(tmp_path)
    assert quick.save(tmp_path / "q").is_dir()
    quick.save(tmp_path / "q")                                  # a quick one it may replace
    with pytest.raises(ConfigError, match="kalman_differentiator.yml: no such file"):
        estim.run("kalman_differentiator.yml")
    for bad in ("2", 0, None):
        with pytest.raises(ValueError, match="jobs: expected an integer >= 1"):
            estim.run("kalman_differentiator", jobs=bad)
