"""ngspice as the actual circuit of an estimation run (issue 47, item 6; D78)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from estim.config.loading import load_file
from estim.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")
CONFIG = {
    "name": "rc_diode_ngspice", "title": "diode clipper, ngspice as the actual circuit",
    "analysis": "estimation",
    "model": {"netlist": str(ROOT / "circuits" / "rectifier.cir"), "input": "VIN",
              "output": "v(out)"},
    "input": {"amplitude_v": 1.0, "bias_v": [0.5], "frequencies_hz": [50],
              "samples_per_period": 40, "periods": 2},
    "noise": {"input_levels": [0.05], "measurement_sigma": 0.02},
    "estimators": [{"label": "EKF", "type": "ekf",
                    "settings": {"Q": 1.0e-2, "R": 4.0e-4, "P0": 1.0e-4}}],
    "monte_carlo": {"runs": 3, "seed": 1},
    "tables": {"rmse": "ours"},
}


def _load(tmp_path: Path, **changes):
    data = {**CONFIG, **changes}
    path = tmp_path / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_file(path)


@NGSPICE
def test_ngspice_gives_the_actual_circuit_within_estim_spices_bars(tmp_path):
    """The same draws through both solvers: ngspice's trajectories (its own DC point, the
    staircase estim's model sees, its reltol 1e-9: the diode's turn-on needs it, D78)
    against estim's at the default tolerances within estim spice's transient bar of the
    largest node voltage, and not identical (they are ngspice's)."""
    from estim.engine.ngspice_check import BARS
    from estim.experiments import estimation

    ours = _load(tmp_path)
    theirs = _load(tmp_path, name="rc_diode_ngspice2",
                   simulation={"solver": "ngspice", "rtol": 1e-9})
    a = estimation.simulate_point(ours, 50.0, 0.05, 3, np.random.default_rng(4))
    b = estimation.simulate_point(theirs, 50.0, 0.05, 3, np.random.default_rng(4))
    np.testing.assert_array_equal(a["source"], b["source"])
    scale = np.abs(b["states"]).max()
    gap = np.abs(a["states"] - b["states"]).max() / scale
    assert 0 < gap <= BARS["transient"], gap


@pytest.mark.parametrize("config, message", [
    ("mosfet_saturation.yaml", "ngspice simulates a netlist; this config's model"),
    ("mosfet_distortion.yaml", "ngspice is the actual circuit of an estimation config only"),
    ("kronecker_table_4_1.yaml", "ngspice is the actual circuit of an estimation config only"),
])
def test_ngspice_is_refused_where_it_cannot_be_the_actual_circuit(config, message):
    """A hand-written model, a perturbation and a Kronecker config: one line naming the key,
    exit 2, before any work."""
    from click.testing import CliRunner

    from estim.cli.main import main

    result = CliRunner().invoke(main, ["validate", str(ROOT / "configs" / config),
                                       "simulation.solver=ngspice"])
    assert result.exit_code == 2, result.output
    assert "simulation.solver" in result.output and message in result.output
    assert "Traceback" not in result.output


def test_a_missing_ngspice_is_one_error_before_any_work(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(ConfigError, match="simulation.solver: ngspice not found on PATH"):
        _load(tmp_path, simulation={"solver": "ngspice"})


@NGSPICE
def test_estim_run_with_ngspice_as_the_actual_circuit(tmp_path):
    """A fresh process (as a user runs it): estim run writes the tables, and its manifest
    records the solver."""
    import json
    import subprocess
    import sys

    path = tmp_path / "rect.yaml"
    path.write_text(yaml.safe_dump({**CONFIG, "name": "rect",
                                    "simulation": {"solver": "ngspice", "rtol": 1e-9}}))
    done = subprocess.run([sys.executable, "-m", "estim", "run", str(path), "--out",
                           str(tmp_path / "out"), "--jobs", "1"], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    folder = tmp_path / "out" / "rect"
    assert (folder / "rmse.csv").is_file()
    assert "ngspice" in json.dumps(json.loads((folder / "manifest.json").read_text()))
