"""Start-up: a command imports what it uses. Each check runs the command in a fresh
interpreter and lists which heavy modules were really loaded (a module that ``lazy_loader``
has only registered is not loaded). No timing here: ``bench/bench_startup.py`` measures."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("matplotlib", "pandas", "numba", "scipy.stats", "scipy.signal", "scipy.optimize",
         "scipy.integrate", "scipy.sparse", "pywt", "skimage", "estim.numerics.kernels")

_PROBE = """
import importlib.util, json, sys
from estim.cli.entry import main
try:
    main(sys.argv[1:], standalone_mode=False)
except SystemExit as exc:
    assert not exc.code, exc.code
heavy = {heavy!r}
loaded = [m for m in heavy if m in sys.modules
          and not isinstance(sys.modules[m], importlib.util._LazyModule)]
print("LOADED=" + json.dumps(loaded))
print("ANALYSES=" + json.dumps(sorted(
    m for m in sys.modules if m.startswith("estim.experiments.") and m.count(".") == 2
    and m.rsplit(".", 1)[1] not in ("base", "shared")
    and not isinstance(sys.modules[m], importlib.util._LazyModule))))
"""


def probe(*args: str, env: dict | None = None) -> dict[str, set[str]]:
    """``{"LOADED": heavy modules, "ANALYSES": analysis modules}`` that ``estim ARGS``
    loads, run in a fresh interpreter (with ``env`` added to the environment)."""
    out = subprocess.run([sys.executable, "-c", _PROBE.format(heavy=HEAVY), *args],
                         capture_output=True, text=True, cwd=ROOT, timeout=300,
                         env={**os.environ, **(env or {})})
    assert out.returncode == 0, out.stderr
    found = {}
    for key in ("LOADED", "ANALYSES"):
        line = next(x for x in out.stdout.splitlines() if x.startswith(key + "="))
        found[key] = set(json.loads(line[len(key) + 1:]))
    return found


def loaded_by(*args: str) -> set[str]:
    """The heavy modules that ``estim ARGS`` loads, run in a fresh interpreter."""
    return probe(*args)["LOADED"]


def test_validate_loads_only_the_analysis_its_config_names():
    """The table command's metric list (which imports every analysis) is made when that
    command runs or shows its help, not when the CLI is imported."""
    loaded = probe("validate", "configs/dipole_field.yaml")["ANALYSES"]
    assert loaded == {"estim.experiments.dipole", "estim.experiments.dipole_field"}, loaded


def test_validate_of_every_default_config_draws_nothing_and_reads_no_tables():
    configs = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "configs").glob("*.yaml"))
    loaded = loaded_by("validate", *configs)
    assert not loaded & {"matplotlib", "pandas", "scipy.stats", "scipy.signal"}, loaded


@pytest.mark.parametrize("config", ["configs/dipole_field.yaml",
                                    "configs/diffamp_distortion.yaml",
                                    "configs/netlist/ce_amp_distortion.yaml"])
def test_validate_of_a_config_without_a_settling_run_loads_no_compiled_code(config):
    """These configs' checks (a grid, a DC point by Newton) need neither numba nor the
    compiled kernels; the MOSFET configs' DC point lets the circuit settle first, with the
    compiled integrator, where Newton fails from zero (models/base.py)."""
    loaded = loaded_by("validate", config)
    assert not loaded & {"numba", "estim.numerics.kernels", "matplotlib", "pandas"}, loaded


def test_validate_again_reads_the_kept_dc_point_and_loads_no_solver(tmp_path):
    """With the DC-point cache on, the second validate of a MOSFET config (whose first
    lets the circuit settle with the compiled integrator) imports neither scipy's root
    finder nor numba."""
    env = {"ESTIM_CACHE_DIR": str(tmp_path)}
    first = probe("validate", "configs/mosfet_saturation.yaml", env=env)["LOADED"]
    assert {"numba", "scipy.optimize"} <= first, first
    again = probe("validate", "configs/mosfet_saturation.yaml", env=env)["LOADED"]
    assert not again & {"numba", "scipy.optimize", "estim.numerics.kernels"}, again


def test_list_reads_only_the_configs_heads():
    """estim list imports neither numpy nor any analysis: it reads each config's head."""
    found = probe("list", "--json")
    assert not found["ANALYSES"], found
    out = subprocess.run([sys.executable, "-c", "import sys\nfrom estim.cli.entry import main\n"
                          "try:\n    main(['list'], standalone_mode=False)\nfinally:\n"
                          "    print('NUMPY', 'numpy' in sys.modules)"],
                         capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.returncode == 0 and "NUMPY False" in out.stdout, out.stdout + out.stderr


def test_a_config_head_is_what_the_full_loader_reads(tmp_path):
    """Every shipped config's head (name, title, analysis, tables) equals the validated
    config's; a head that is not plain is read by the full loader, whose error it gives."""
    from estim.config.header import read_head
    from estim.config.loading import load_file
    from estim.errors import ConfigError

    for path in sorted(p for folder in ("", "studies", "netlist")
                       for p in (ROOT / "configs" / folder).glob("*.yaml")):
        head, exp = read_head(path), load_file(path, plan=False)
        assert (head.name, head.title, head.analysis, list(head.reproduces)) == \
            (exp.name, exp.spec["title"], exp.analysis, list(exp.spec["reproduces"])), path
    bad = ROOT / "configs" / "mosfet_saturation.yaml"
    text = bad.read_text().replace('reproduces: ["3.2", "3.4"]', "reproduces: [3.2, 3.4]")
    assert text != bad.read_text()
    copy = tmp_path / "head.yaml"
    copy.write_text(text)
    with pytest.raises(ConfigError, match="reproduces"):
        read_head(copy)


def test_table_reads_csv_without_pandas_drawing_or_compiling():
    loaded = loaded_by("table", "distortion")
    assert not loaded & {"pandas", "numba", "estim.numerics.kernels", "matplotlib",
                         "scipy.stats", "scipy.optimize", "skimage", "pywt"}, loaded
    assert "pandas" in loaded_by("summary")        # the probe sees a real load


def test_table_of_one_experiment_loads_only_its_analysis():
    found = probe("table", "rmse", "mosfet_saturation", "--thesis")
    assert found["ANALYSES"] == {"estim.experiments.estimation"}, found
    assert not found["LOADED"] & {"pandas", "matplotlib"}, found


def test_a_dc_point_is_kept_on_disk_and_read_back_bit_for_bit(tmp_path, monkeypatch):
    """The second search of the same model's DC point reads the first one's result, equal to
    the last bit; another parameter, guess or input is another point; a netlist's model and
    an unwritable folder keep nothing and still give the point."""
    from estim.models.mosfet_ekv import MosfetEKV
    from estim.spice import model_class

    cache = tmp_path / "cache"
    monkeypatch.setenv("ESTIM_CACHE_DIR", str(cache))
    kept = cache / "operating_points"
    model = MosfetEKV(V_IN=0.35, drain_current="ekv")
    first = model.operating_point()
    assert len(list(kept.iterdir())) == 1
    monkeypatch.setattr(MosfetEKV, "_find_operating_point",
                        lambda *args: pytest.fail("searched again"))
    again = model.operating_point()
    assert again.tobytes() == first.tobytes()
    monkeypatch.undo()
    monkeypatch.setenv("ESTIM_CACHE_DIR", "off")
    assert MosfetEKV(V_IN=0.35, drain_current="ekv").operating_point().tobytes() \
        == first.tobytes()
    monkeypatch.setenv("ESTIM_CACHE_DIR", str(cache))
    MosfetEKV(V_IN=0.36, drain_current="ekv").operating_point()
    model.operating_point(x_guess=first + 1e-3)
    assert len(list(kept.iterdir())) == 3
    twin = model_class(ROOT / "circuits" / "mosfet_ekv.cir", "VIN", "v(d)",
                       name="netlist:test_dc_cache")(vin_bias=0.35)
    twin.operating_point()
    assert len(list(kept.iterdir())) == 3
    blocked = tmp_path / "file"
    blocked.write_text("")
    monkeypatch.setenv("ESTIM_CACHE_DIR", str(blocked))
    assert np.allclose(MosfetEKV(V_IN=0.37, drain_current="ekv").operating_point()[0], 0.37)
