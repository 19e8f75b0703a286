"""Issue 47, item 5: the netlist's SIN, PULSE or PWL on the model input is the config's input
waveform where the config gives none (estim.spice.sources), and a notice says when the
config's own waveform replaces it."""

import numpy as np
import pytest
import yaml

import estim
from estim.errors import ConfigError, Notice
from estim.experiments import estimation

RECTIFIER = """Half-wave rectifier
VIN in 0 {source}
D1 in out dmod
C1 out 0 1u
R1 out 0 10k
.model dmod d(is=1e-12 n=1)
.end
"""


def project(tmp_path, source: str, **inp) -> "estim.config.experiment.Experiment":
    (tmp_path / "rectifier.cir").write_text(RECTIFIER.format(source=source))
    spec = {"title": "rectifier",                  # analysis: estimation by default
            "model": {"netlist": "rectifier.cir", "input": "VIN", "output": "v(out)"},
            "input": inp, "noise": {"input_levels": [0.05], "measurement_sigma": 0.02},
            "estimators": [{"label": "EKF", "type": "ekf",
                            "settings": {"Q": 1.0e-2, "R": 4.0e-4, "P0": 1.0e-4}}],
            "monte_carlo": {"runs": 2, "seed": 1}, "tables": {"rmse": "ours"}}
    path = tmp_path / "rectifier.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_a_sin_source_is_the_configs_sine_and_gives_the_tables_of_the_same_sine_given(
        tmp_path):
    (tmp_path / "a").mkdir()
    from_netlist = project(tmp_path / "a", "SIN(0.5 1 50)", samples_per_period=20, periods=2)
    exp = estim.experiment(from_netlist)
    inp = exp.config.input
    assert (inp.waveform, inp.amplitude_v, inp.frequencies_hz, inp.bias_v) == (
        "sine", 1.0, [50.0], [0.5])
    (tmp_path / "b").mkdir()
    given = project(tmp_path / "b", "DC 0", amplitude_v=1.0, frequencies_hz=[50],
                    bias_v=[0.5], samples_per_period=20, periods=2)
    assert estim.run(from_netlist).tables["rmse"].equals(estim.run(given).tables["rmse"])


@pytest.mark.parametrize("source, expected", [
    ("PULSE(0 1 1m 0 0 5m 10m)", {"waveform": "pulse", "amplitude_v": 1.0, "delay_s": 1e-3,
                                  "duty": 0.5, "frequencies_hz": [100.0], "bias_v": [0.0]}),
    ("PULSE(0.2 -0.3 2m)", {"waveform": "step", "amplitude_v": -0.5, "delay_s": 2e-3,
                            "bias_v": [0.2]}),
])
def test_a_pulse_source_is_a_pulse_or_without_pw_and_per_a_step(tmp_path, source, expected):
    timing = ({"samples_per_period": 20, "periods": 2} if "10m" in source
              else {"sample_time_s": 1e-4, "duration_s": 5e-3})
    inp = estim.experiment(project(tmp_path, source, **timing)).config.input
    for key, value in expected.items():
        got = getattr(inp, key)
        assert got == value if isinstance(value, str) else np.allclose(got, value), key


def test_a_pwl_source_is_the_configs_pwl_about_the_bias_given(tmp_path):
    path = project(tmp_path, "PWL(0 0.2 1m 0.7 2m 0.7 2m 0.2)", sample_time_s=1e-4,
                   duration_s=4e-3, bias_v=[0.2])
    exp = estim.experiment(path)
    point = estimation.sweep(exp)[0]
    data = estimation.simulate_point(exp, point.frequency_hz, 0.0, 1,
                                     np.random.default_rng(0))
    t = np.arange(len(data["clean"])) * 1e-4
    assert np.allclose(data["clean"][:19, 0], np.interp(t[:19], [0, 1e-3], [0.2, 0.7]))
    assert np.allclose(data["clean"][21:, 0], 0.2)          # after the vertical edge at 2 ms


def test_the_configs_own_waveform_wins_with_a_notice_naming_the_key(tmp_path):
    path = project(tmp_path, "SIN(0.5 1 50)", amplitude_v=0.2, frequencies_hz=[100],
                   samples_per_period=20, periods=2)
    with pytest.warns(Notice, match="SIN waveform on input VIN is replaced by the config's "
                                    "input block \\(the config gives input.amplitude_v\\)"):
        exp = estim.experiment(path)
    assert (exp.config.input.amplitude_v, exp.config.input.frequencies_hz) == (0.2, [100])


@pytest.mark.parametrize("source, expected", [
    ("SIN(0.5 1 50 0 0 90)", "SIN with a delay, damping or phase"),
    ("PULSE(0 1 0 0 0 5m)", "neither a step"),
])
def test_a_netlist_waveform_estim_does_not_make_is_one_error(tmp_path, source, expected):
    with pytest.raises(ConfigError, match=f"model.netlist.*{expected}"):
        estim.experiment(project(tmp_path, source, samples_per_period=20, periods=2))
