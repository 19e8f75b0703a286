"""Issue 47, item 8: the source of an estimation config as a pulse, a step, a piecewise-linear
source or a CSV file, beside the thesis' sine (estim.experiments.estimation.source)."""

import numpy as np
import pytest
import yaml
from test_cli import DELETE, apply_changes, tiny_config

import estim
from estim.errors import ConfigError
from estim.experiments import estimation

DT, DURATION = 1e-5, 1e-3


def aperiodic(kind: str, **more) -> dict:
    """The tiny saturation config with a source that does not repeat."""
    changes = {"input.waveform": kind, "input.frequencies_hz": DELETE,
               "input.periods": DELETE, "input.samples_per_period": DELETE,
               "input.sample_time_s": DT, "input.duration_s": DURATION,
               "figures.frequency_hz": DELETE}
    if kind not in ("step", "pulse"):
        changes["input.amplitude_v"] = DELETE
    return tiny_config(**{**changes, **{f"input.{k}": v for k, v in more.items()}})


def source_of(exp, runs: int = 2) -> dict:
    point = estimation.sweep(exp)[0]
    return estimation.simulate_point(exp, point.frequency_hz, 0.0, runs,
                                     np.random.default_rng(0))


def test_a_pwl_source_is_linear_between_its_knots_and_held_after_the_last():
    knots = [[0.0, 0.0], [2e-4, 0.05], [6e-4, -0.02]]
    exp = estim.experiment(aperiodic("pwl", points=knots))
    data = source_of(exp)
    t = np.arange(len(data["clean"])) * DT
    bias = exp.config.input.bias_v[0]
    expected = bias + np.interp(t, *np.array(knots).T)
    assert np.allclose(data["clean"][:, 0], expected, rtol=0, atol=1e-15)
    assert data["clean"][-1, 0] == pytest.approx(bias - 0.02)
    assert [p.frequency_hz for p in estimation.sweep(exp)] == [pytest.approx(1 / DURATION)]


def test_a_file_source_is_the_pwl_of_its_rows_and_gives_the_same_tables(tmp_path):
    knots = [[0.0, 0.0], [2e-4, 0.05], [6e-4, -0.02]]
    (tmp_path / "input.csv").write_text("t_s,v\n" + "".join(f"{t},{v}\n" for t, v in knots))
    config = tmp_path / "file.yaml"
    config.write_text(yaml.safe_dump(aperiodic("file", file="input.csv")))
    from_file = estim.run(config)
    from_points = estim.run(aperiodic("pwl", points=knots))
    assert from_file.tables["rmse"].equals(from_points.tables["rmse"])
    assert len(from_file.tables["rmse"]) == 1 + len(from_file.config["estimators"])


def test_a_step_is_zero_up_to_its_delay_and_its_height_after():
    exp = estim.experiment(aperiodic("step", delay_s=3e-4))
    clean = source_of(exp)["clean"][:, 0] - exp.config.input.bias_v[0]
    assert np.all(clean[:31] == 0.0)                    # t = 30 dt is the delay itself
    assert np.all(clean[31:] == exp.config.input.amplitude_v)


def test_a_pulse_is_high_for_its_duty_of_every_period_at_each_frequency():
    spec = tiny_config(**{"input.waveform": "pulse", "input.duty": 0.25,
                          "input.samples_per_period": 40, "input.periods": 4})
    exp = estim.experiment(spec)
    data = source_of(exp)
    high = data["clean"][:, 0] > exp.config.input.bias_v[0]
    assert high[1:].mean() == pytest.approx(0.25)
    for k in range(1, 4):                                   # one period is 40 samples
        assert high[40 * k:40 * k + 10].all() and not high[40 * k + 10:40 * k + 40].any()


def test_the_circuit_starts_at_its_dc_point_with_the_source_where_the_waveform_starts():
    start = estim.experiment(aperiodic("pwl", points=[[0.0, 0.04], [5e-4, 0.04], [6e-4, 0]]))
    level = estim.experiment(aperiodic("pwl", points=[[0.0, 0.0]]),
                             **{"input.bias_v": [start.config.input.bias_v[0] + 0.04]})
    assert np.allclose(start.plan.x0, level.plan.x0, rtol=1e-12, atol=1e-15)
    data = source_of(start)
    assert np.allclose(data["states"][:, :40], start.plan.x0, rtol=1e-6, atol=1e-9)  # at rest


@pytest.mark.parametrize("changes, key, expected", [
    ({"input.frequencies_hz": [1000]}, "input.frequencies_hz", "does not repeat"),
    ({"input.sample_time_s": DELETE}, "input.sample_time_s", "required for waveform pwl"),
    ({"input.points": DELETE}, "input.points", "required for waveform pwl"),
    ({"input.points": [[0.0, 0.0], [-1.0, 1.0]]}, "input.points", "must start at 0 s or "
                                                                  "later and not decrease"),
    ({"input.points": [[0.0, 0.0, 1.0]]}, "input.points", "at most 2"),
    ({"input.amplitude_v": 0.1}, "input.amplitude_v", "gives its own values"),
    ({"input.file": "x.csv"}, "input.file", "only for waveform file"),
    ({"estimators.0.input_derivative": "analytic"}, "estimators[0].input_derivative",
     "needs a sine input"),
])
def test_a_waveform_setting_that_does_not_fit_is_one_error_at_its_key(changes, key, expected):
    spec = apply_changes(aperiodic("pwl", points=[[0.0, 0.0], [1e-4, 0.01]]), changes)
    with pytest.raises(ConfigError) as error:
        estim.experiment(spec)
    assert key in str(error.value) and expected in str(error.value), str(error.value)


def test_a_missing_or_malformed_input_file_is_one_error_naming_it(tmp_path):
    config = tmp_path / "file.yaml"
    config.write_text(yaml.safe_dump(aperiodic("file", file="nosuch.csv")))
    with pytest.raises(ConfigError, match="input.file.*cannot read .*nosuch.csv"):
        estim.experiment(config)
    (tmp_path / "bad.csv").write_text("t,v\n0,zero\n")
    config.write_text(yaml.safe_dump(aperiodic("file", file="bad.csv")))
    with pytest.raises(ConfigError, match="input.file.*two numbers"):
        estim.experiment(config)


def test_the_sine_is_the_default_and_needs_its_frequencies():
    spec = tiny_config(**{"input.frequencies_hz": DELETE})
    with pytest.raises(ConfigError, match="input.frequencies_hz.*required for waveform sine"):
        estim.experiment(spec)


def test_results_stored_before_a_setting_existed_are_of_the_config_that_has_its_default():
    """estim check reads the stored config again with today's settings: a key added since
    (here the pulse's duty and delay) takes its default, which is how the stored run
    behaved; a key the stored run had with another value is another config."""
    import copy

    from estim.engine.check import same_settings

    exp = estim.experiment(tiny_config())
    before = copy.deepcopy(exp.spec)
    del before["input"]["duty"], before["input"]["delay_s"]
    assert same_settings({"config": before, "config_sha256": "0" * 64}, exp)
    other = copy.deepcopy(before)
    other["input"]["periods"] = 3
    assert not same_settings({"config": other, "config_sha256": "0" * 64}, exp)
    assert not same_settings({"config": None, "config_sha256": "0" * 64}, exp)



@pytest.mark.parametrize("key, value, expected", [
    ("input.waveform", "square", "expected one of"),
    ("input.duty", "half", "number"),
    ("input.duty", 1.5, "number < 1"),
    ("input.delay_s", -1.0, "number >= 0"),
    ("input.points", "0 0 1 1", "list"),
    ("input.file", 7, "non-empty string"),
])
def test_a_wrong_waveform_key_is_one_line_naming_the_file_and_the_key(tmp_path, key, value,
                                                                      expected):
    """The new input keys (issue 47, item 8) through the command line, as a user meets them:
    one error line naming the config file, the key path and what was expected, exit 2."""
    from click.testing import CliRunner

    from estim.cli.main import main

    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(apply_changes(tiny_config(), {key: value})))
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2, result.output
    assert f"{path}: {key}: " in result.output and expected in result.output, result.output
