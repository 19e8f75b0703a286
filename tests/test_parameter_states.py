"""Element values as states (issue 47, item 3; the config's ``estimate``): the augmented drift
is the netlist's with the value changed, its columns in the value are right, a filter's
estimate of a resistor converges to the actual circuit's within its own three standard
deviations, and every way to name a value wrongly is one line at its key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from estim.spice import model_class
from estim.spice.parameter_states import Parameter, ParameterStates, value_of

ROOT = Path(__file__).resolve().parents[1]

LIMITER = """Diode limiter with a diode of its own model
VIN in 0 DC 0
R1 in a {r1}
CA a 0 10n
D1 a p dup
VP p 0 DC 0.5
D2 n a dlim
VN n 0 DC -0.5
RL a 0 10k
.model dup d(is={is_up} n=1.05 rs=10)
.model dlim d(is=1e-14 n=1.05 rs=10)
.end
"""


def _limiter(tmp_path, tag, r1=1000.0, is_up=1e-14):
    path = tmp_path / f"lim_{tag}.cir"
    path.write_text(LIMITER.format(r1=r1, is_up=is_up))
    return model_class(path, "VIN", "i(rl)", name=f"netlist:test_ps_{tag}")()


def test_the_drift_is_the_netlists_with_the_value_changed(tmp_path):
    """At theta (the values over their first guesses) the augmented drift equals, to
    rounding, the drift of the netlist written with those values; the parameters' own rows
    are zero; the Jacobian's block in the states is that netlist's Jacobian."""
    base = _limiter(tmp_path, "base")
    model = ParameterStates(base, (Parameter("R1", "r1", None, 1300.0),
                                   Parameter("D1.is", "d1", "is", 3e-14)))
    assert model.state_names == ("v(a)", "R1", "D1.is")
    for v, theta in ((0.3, (1.0, 1.0)), (1.2, (0.8, 0.5)), (-0.9, (1.2, 2.0))):
        changed = _limiter(tmp_path, f"{v}", r1=1300.0 * theta[0], is_up=3e-14 * theta[1])
        x, u = np.array([v, *theta]), np.array([1.5])
        f, J = model.f_and_jacobian(x, u)
        f0, J0 = changed.f_and_jacobian(x[:1], u)
        np.testing.assert_allclose(f[:1], f0, rtol=1e-12, atol=1e-9)
        assert f[1:].tolist() == [0.0, 0.0]
        np.testing.assert_allclose(J[:1, :1], J0, rtol=1e-12)
        assert not J[1:].any()


def test_the_columns_in_the_values_are_their_derivatives(tmp_path):
    """Each column of the Jacobian in a value equals the central difference of the drifts
    of netlists written with the value moved (where the diode conducts, its parameter moves
    the drift well above rounding)."""
    base = _limiter(tmp_path, "cols")
    model = ParameterStates(base, (Parameter("R1", "r1", None, 1000.0),
                                   Parameter("D1.is", "d1", "is", 1e-14)))
    x, u = np.array([1.2, 1.0, 1.0]), np.array([2.0])
    J = model.jacobian(x, u)
    h = 1e-4
    up = _limiter(tmp_path, "r_up", r1=1000.0 * (1 + h)).f(x[:1], u)
    down = _limiter(tmp_path, "r_down", r1=1000.0 * (1 - h)).f(x[:1], u)
    assert J[0, 1] == pytest.approx((up - down)[0] / (2 * h), rel=1e-7)
    up = _limiter(tmp_path, "is_up", is_up=1e-14 * (1 + h)).f(x[:1], u)
    down = _limiter(tmp_path, "is_down", is_up=1e-14 * (1 - h)).f(x[:1], u)
    assert J[0, 2] == pytest.approx((up - down)[0] / (2 * h), rel=1e-6)
    assert abs(J[0, 2]) > 1e3


def test_a_pmos_threshold_is_estimated_in_spice_s_sign(tmp_path):
    """M2.vto of the level-1 PMOS load is -0.8 V as the .model gives it; the drift at a
    changed value equals the netlist written with it (the mirror applied to the state)."""
    text = (ROOT / "circuits" / "cmos_level1.cir").read_text()
    base = model_class(ROOT / "circuits" / "cmos_level1.cir", "VIN", "v(d)",
                       name="netlist:test_ps_cmos")()
    assert value_of(base, "M2.vto") == -0.8
    assert value_of(base, "m1.KP") == pytest.approx(110e-6)
    path = tmp_path / "cmos.cir"
    path.write_text(text.replace("vto=-0.8", "vto=-0.9"))
    changed = model_class(path, "VIN", "v(d)", name="netlist:test_ps_cmos2")()
    model = ParameterStates(base, (Parameter("M2.vto", "m2", "vto", -0.8),))
    x0 = base.operating_point(u=[0.85])
    x = np.concatenate([x0, [0.9 / 0.8]])
    np.testing.assert_allclose(model.f(x, np.array([0.85])), [*changed.f(x0, [0.85]), 0.0],
                               rtol=1e-12, atol=1e-6)


def _config(tmp_path, **changes) -> Path:
    spec = yaml.safe_load((ROOT / "configs" / "netlist" / "diode_limiter_ekf.yaml")
                          .read_text())
    spec["model"]["netlist"] = str(ROOT / "circuits" / "diode_limiter.cir")
    spec.pop("check")
    spec["input"].update(frequencies_hz=[1000], periods=6)
    spec["noise"].update(input_levels=[0.02])
    spec["monte_carlo"]["runs"] = 12
    for est in spec["estimators"]:
        est["settings"].update(Q=3e-4, substeps=10)
    spec["estimate"] = [{"name": "R1", "start": 1300.0, "sigma0": 300.0}]
    spec["figures"] = {"kinds": ["parameters"]}
    for key, value in changes.items():
        spec[key] = value
    path = tmp_path / "pe.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_a_resistors_estimate_converges_to_the_actual_value(tmp_path):
    """The limiter's R1 (1 kOhm in the actual circuit) from a first guess of 1.3 kOhm +- 300:
    every run's final estimate is within three of the filter's own standard deviations of
    1 kOhm, the mean estimate within three standard errors; states.csv reports the value's
    RMSE in ohms and the figure of the values is drawn."""
    import pandas as pd

    from estim.cli.main import main

    path = _config(tmp_path)
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "out"),
                                       "--quiet", "--jobs", "1"])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "out" / "diode_limiter_ekf"
    table = pd.read_csv(folder / "parameters.csv")
    assert sorted(table["estimator"]) == ["EKF", "UKF"]
    for _, row in table.iterrows():
        assert row["true"] == 1000.0 and row["start"] == 1300.0
        assert row["within_3_sigma"] == row["runs"] == 12
        assert abs(row["error"]) <= 3 * row["estimate_se"]
        assert 5.0 < row["sigma"] < 100.0
    states = pd.read_csv(folder / "states.csv")
    r1 = states[states["state"] == "R1"]
    assert len(r1) == 2 and (r1["rmse"] > 1.0).all() and (r1["rmse"] < 300.0).all()
    assert [p.name for p in (folder / "figures").glob("*.png")] == ["parameters.png"]


@pytest.mark.parametrize("entry,key,message", [
    ({"name": "R9", "start": 1.0, "sigma0": 1.0}, "estimate[0].name", "no element 'R9'"),
    ({"name": "CA", "start": 1.0, "sigma0": 1.0}, "estimate[0].name",
     "a resistor's or an inductor's value"),
    ({"name": "D1.rs", "start": 1.0, "sigma0": 1.0}, "estimate[0].name", "D1.is, D1.n"),
    ({"name": "VP.dc", "start": 1.0, "sigma0": 1.0}, "estimate[0].name", "only a diode's"),
    ({"name": "R1", "start": 0.0, "sigma0": 1.0}, "estimate[0].start", "other than 0"),
    ({"name": "R1", "start": 1.0, "sigma0": -1.0}, "estimate[0].sigma0", "positive"),
    ({"name": "RL", "start": 1.0, "sigma0": 1.0}, "estimate", "an output is its current"),
    ({"name": "R1", "start": "x", "sigma0": 1.0}, "estimate[0].start", "a finite number"),
    ({"name": "R1", "sigma0": 1.0}, "estimate[0].start", "missing required key"),
    ({"name": "R1", "start": 1.0, "sigma0": 1.0, "drift": -1}, "estimate[0].drift",
     "a number >= 0"),
])
def test_a_value_named_wrongly_is_one_line_at_its_key(tmp_path, entry, key, message):
    from estim.cli.main import main

    path = _config(tmp_path, estimate=[entry])
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2, result.output
    assert key in result.output and message in result.output, result.output
    assert str(path) in result.output and "Traceback" not in result.output


def test_a_value_named_twice_or_for_a_filter_without_covariance_is_refused(tmp_path):
    from estim.cli.main import main

    result = CliRunner().invoke(main, ["validate", str(_config(tmp_path, estimate="R1"))])
    assert result.exit_code == 2 and "estimate: expected a list, got str" in result.output

    twice = [{"name": "R1", "start": 1.0, "sigma0": 1.0}, {"name": "r1", "start": 2.0,
                                                           "sigma0": 1.0}]
    result = CliRunner().invoke(main, ["validate", str(_config(tmp_path, estimate=twice))])
    assert result.exit_code == 2 and "estimate[1].name" in result.output
    assert "already estimate[0]" in result.output
    rls = yaml.safe_load(_config(tmp_path).read_text())
    rls["estimators"].append({"label": "RLS", "type": "rls", "settings": {}})
    path = tmp_path / "rls.yaml"
    path.write_text(yaml.safe_dump(rls))
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2 and "estimators[2].type" in result.output, result.output
    assert "no state covariance" in result.output


def test_a_hand_written_model_has_no_element_values_to_estimate(tmp_path):
    from test_cli import tiny_config

    from estim.cli.main import main

    spec = tiny_config()
    spec["estimate"] = [{"name": "R1", "start": 1.0, "sigma0": 1.0}]
    path = tmp_path / "hand.yaml"
    path.write_text(yaml.safe_dump(spec))
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2 and "estimate:" in result.output
    assert "hand-written" in result.output and "Traceback" not in result.output


def test_the_limiter_configs_comment_and_the_bias_of_one_step(tmp_path):
    """diode_limiter_r1.yaml's comment: v(a)'s time constant CA (R1 || RL) is 9.1 us (the
    drift's Jacobian with both diodes off), the sample intervals 25 and 12.5 us. Predicting
    in one step instead of its 10 substeps, the EKF's estimate of R1 is biased: its mean
    error over the runs is more than three standard errors, and with the substeps it is not."""
    import pandas as pd

    from estim.cli.main import main

    spec = yaml.safe_load((ROOT / "configs" / "netlist" / "diode_limiter_r1.yaml")
                          .read_text())
    inp = spec["input"]
    assert [1 / (inp["samples_per_period"] * f) for f in inp["frequencies_hz"]] == \
        pytest.approx([25e-6, 12.5e-6])
    base = model_class(ROOT / spec["model"]["netlist"], "VIN", "i(rl)",
                       name="netlist:test_ps_tau")()
    tau = -1 / base.jacobian(np.array([0.0]), np.array([0.0]))[0, 0]
    assert tau == pytest.approx(9.1e-6, abs=0.05e-6)
    assert "9.1 us" in (ROOT / "configs" / "netlist" / "diode_limiter_r1.yaml").read_text()
    errors = {}
    for substeps in (1, 10):
        path = _config(tmp_path)
        spec = yaml.safe_load(path.read_text())
        spec["estimators"] = spec["estimators"][:1]
        spec["estimators"][0]["settings"]["substeps"] = substeps
        spec["monte_carlo"]["runs"] = 20
        spec["figures"] = {"kinds": []}
        path.write_text(yaml.safe_dump(spec))
        out = tmp_path / f"out{substeps}"
        result = CliRunner().invoke(main, ["run", str(path), "--out", str(out), "--quiet"])
        assert result.exit_code == 0, result.output
        row = pd.read_csv(out / "diode_limiter_ekf" / "parameters.csv").iloc[0]
        errors[substeps] = abs(row["error"]) / row["estimate_se"]
    assert errors[1] > 3 and errors[10] < 3, errors


def test_estim_settings_lists_the_values_estimate_accepts(tmp_path):
    """Every value `estim settings CONFIG` lists for a netlist is accepted (its value read,
    the model made with it as a state), a subcircuit's named with its instance (X1.M1.i_0);
    the limiter's RL, whose current is the output, is not listed."""
    from estim.cli.main import main
    from estim.spice.parameter_states import estimable, split

    listed = CliRunner().invoke(main, ["settings", str(ROOT / "configs" / "netlist" /
                                                       "diode_limiter_r1.yaml")])
    assert listed.exit_code == 0, listed.output
    assert "`R1`, `D1.is`, `D1.n`, `D2.is`, `D2.n`" in listed.output
    assert "`RL`" not in listed.output
    darlington = model_class(ROOT / "circuits" / "mosfet_darlington.cir", "VIN", "v(s2)",
                             name="netlist:test_ps_darlington")()
    names = estimable(darlington)
    assert any(n.startswith("X1.") and n.count(".") == 2 for n in names), names
    for name in names:
        element, field = split(darlington, name)
        start = value_of(darlington, name) * 1.1 or 1.0
        model = ParameterStates(darlington, (Parameter(name, element, field, start),))
        x = model.extend(darlington.operating_point(u=[0.0]))
        assert np.all(np.isfinite(model.f(x, np.array([0.0]))))


def test_an_inductors_value_may_be_a_state(tmp_path):
    """L1 of the RLC tank: the drift at a moved value equals the netlist written with it,
    the column in the value equals the drift's difference, and estim settings lists L1."""
    from estim.spice.parameter_states import estimable

    text = (ROOT / "circuits" / "rlc_current.cir").read_text()
    base = model_class(ROOT / "circuits" / "rlc_current.cir", "IIN", "i(l1)",
                       name="netlist:test_ps_l")()
    assert "L1" in estimable(base) and value_of(base, "L1") == pytest.approx(10e-3)
    model = ParameterStates(base, (Parameter("L1", "l1", None, 8e-3),))
    path = tmp_path / "rlc.cir"
    path.write_text(text.replace("L1 top 0 10m", "L1 top 0 12m"))
    changed = model_class(path, "IIN", "i(l1)", name="netlist:test_ps_l2")()
    x0 = np.array([0.3, 2e-4])
    u = np.array([1e-3])
    x = np.concatenate([x0, [1.5]])
    np.testing.assert_allclose(model.f(x, u)[:2], changed.f(x0, u), rtol=1e-13)
    h = 1e-6
    e = np.array([0.0, 0.0, h])
    column = (model.f(x + e, u) - model.f(x - e, u)) / (2 * h)
    np.testing.assert_allclose(model.jacobian(x, u)[:, 2], column, rtol=1e-7)
