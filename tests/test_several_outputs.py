"""Several measured quantities (issue 47, item 2): ``model.output`` a list, each with its own
noise (``noise.measurement_sigma`` a list) and its own row of ``outputs.csv``; the filters
get every one (``h`` and its Jacobian stacked)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from estim.cli.main import main
from estim.estimators.ekf import ExtendedKalmanFilter
from estim.spice import model_class
from estim.spice.parser import NetlistError

ROOT = Path(__file__).resolve().parents[1]
MIRROR = ROOT / "circuits" / "diode_mirror.cir"


def _mirror(output, tag):
    return model_class(MIRROR, "VIN", output, name=f"netlist:test_outs_{tag}")()


def test_the_outputs_are_each_ones_own_stacked():
    """h and its Jacobian of [i(ro), v(a), i(d1)] are those of the three one-output models,
    in that order; the pair without the diode's current is affine (the compiled loops take
    it), the three are not."""
    three = _mirror(["i(ro)", "v(a)", "i(d1)"], "three")
    ones = [_mirror(o, o.replace("(", "_").replace(")", "")) for o in three.output_names]
    assert three.output_names == ("i(ro)", "v(a)", "i(d1)")
    rng = np.random.default_rng(1)
    x = three.operating_point(u=[1.0]) + rng.normal(0, 1e-3, (4, three.n_states))
    np.testing.assert_array_equal(three.h(x), np.concatenate([m.h(x) for m in ones], axis=-1))
    np.testing.assert_array_equal(three.h_jacobian(x),
                                  np.concatenate([m.h_jacobian(x) for m in ones], axis=-2))
    assert three.affine_output() is None
    H, c = _mirror(["i(ro)", "v(a)"], "pair").affine_output()
    np.testing.assert_array_equal(H, np.vstack([ones[0].affine_output()[0],
                                                ones[1].affine_output()[0]]))
    assert c.shape == (2,)


def test_an_output_named_twice_is_refused():
    with pytest.raises(NetlistError, match="measures what 'v\\(a\\)' does"):
        _mirror(["v(a)", "v(A)"], "twice")


def _config(tmp_path, output, sigma, R, name="two.yaml", runs=20):
    spec = yaml.safe_load((ROOT / "configs" / "netlist" / "diode_mirror_ekf.yaml").read_text())
    spec["model"].update(netlist=str(MIRROR), output=output)
    spec.pop("check")
    spec["input"].update(frequencies_hz=[1000], periods=4)
    spec["noise"].update(input_levels=[0.02], measurement_sigma=sigma)
    spec["monte_carlo"]["runs"] = runs
    for est in spec["estimators"]:
        est["settings"]["R"] = R
    spec["figures"] = {"kinds": []}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(spec))
    return path


def _run(path, out):
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    return out / "diode_mirror_ekf"


def test_two_outputs_each_with_its_noise_and_its_rows(tmp_path):
    """The mirror measured by its output current (2 uA of noise) and its diode's node
    (10 mV): outputs.csv has a row per quantity and filter, each measurement's RMSE its own
    noise (to 5 %); rmse.csv holds the first quantity's rows; and the second measurement
    lowers the filters' error of the node it measures below the one-output filters'."""
    two = _run(_config(tmp_path, ["i(ro)", "v(a)"], [2e-6, 0.01], [4e-12, 1e-4]),
               tmp_path / "two")
    one = _run(_config(tmp_path, "i(ro)", 2e-6, 4e-12, "one.yaml"), tmp_path / "one")
    outputs = pd.read_csv(two / "outputs.csv")
    assert sorted(set(outputs["output"])) == ["i(ro)", "v(a)"]
    assert len(outputs) == 2 * 3
    raw = outputs[outputs["estimator"] == "measurement"].set_index("output")["rmse"]
    assert raw["i(ro)"] == pytest.approx(2e-6, rel=0.05)
    assert raw["v(a)"] == pytest.approx(0.01, rel=0.05)
    rmse = pd.read_csv(two / "rmse.csv")
    first = outputs[outputs["output"] == "i(ro)"].set_index("estimator")
    for _, row in rmse.iterrows():
        assert row["rmse"] == first.loc[row["estimator"], "rmse"]
    assert not (one / "outputs.csv").exists()
    node = {label: pd.read_csv(folder / "states.csv").query("state == 'v(a)'")
            .set_index("estimator")["rmse"] for label, folder in (("one", one), ("two", two))}
    for label in ("EKF", "UKF"):
        assert node["two"][label] < 0.9 * node["one"][label], node


@pytest.mark.parametrize("changes,key,message", [
    ({"sigma": [2e-6]}, "noise.measurement_sigma", "1 levels for 2 measured quantities"),
    ({"sigma": [2e-6, -1.0]}, "noise.measurement_sigma", "noise levels"),
    ({"R": 4e-12, "output": ["i(ro)", 3]}, "model.output", "a list of them"),
    ({"R": [4e-12, 1e-4, 1.0]}, "estimators[0].settings", "R"),
])
def test_several_outputs_set_up_wrongly_is_one_line_at_its_key(tmp_path, changes, key,
                                                               message):
    args = {"output": ["i(ro)", "v(a)"], "sigma": [2e-6, 0.01], "R": [4e-12, 1e-4], **changes}
    path = _config(tmp_path, **args)
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 2, result.output
    assert key in result.output and message in result.output, result.output
    assert "Traceback" not in result.output


@pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice is not installed here")
def test_estim_spice_compares_every_output(tmp_path):
    path = _config(tmp_path, ["i(ro)", "v(a)"], [2e-6, 0.01], [4e-12, 1e-4])
    result = CliRunner().invoke(main, ["spice", str(path), "--format", "csv"])
    assert result.exit_code == 0, result.output
    assert "i(ro) (output)" in result.output and "v(a) (output)" in result.output
    assert "gain VIN -> i(ro)" in result.output and "gain VIN -> v(a)" in result.output


def test_a_voltage_sources_current_is_an_output():
    """i(VS), the mirror's 0 V ammeter under the diode, is the diode's current (SPICE's
    sign: from VS's + node through it); i(VCC) of the two-stage amplifier is minus the
    current the supply gives its collector resistor and the follower, negative as ngspice
    prints it; both are nonlinear outputs whose Jacobians are their differences."""
    mirror = _mirror(["i(vs)", "i(d1)"], "ammeter")
    x = mirror.operating_point(u=[1.0]) + np.array([[0.0, 0.0], [0.01, -0.2], [0.05, 0.1]])
    y = mirror.h(x)
    np.testing.assert_allclose(y[:, 0], y[:, 1], rtol=1e-12, atol=1e-18)
    assert mirror.affine_output() is None
    stage = model_class(ROOT / "circuits" / "gp_two_stage.cir", "VIN", ["i(vcc)", "v(c1)"],
                        name="netlist:test_outs_vcc")()
    x0 = stage.operating_point(u=[1.7])
    v_c1 = x0[stage.state_names.index("v(c1)")]
    i_vcc = stage.h(x0)[0]
    follower = model_class(ROOT / "circuits" / "gp_two_stage.cir", "VIN", "ic(q2)",
                           name="netlist:test_outs_icq2")()
    assert i_vcc == pytest.approx(-((10.0 - v_c1) / 4.7e3 + follower.h(x0)[0]), rel=1e-12)
    assert i_vcc < 0
    eps = 1e-7
    for model, point in ((mirror, x[1]), (stage, x0)):
        Hd = np.stack([(model.h(point + eps * e) - model.h(point - eps * e)) / (2 * eps)
                       for e in np.eye(model.n_states)], axis=-1)
        np.testing.assert_allclose(model.h_jacobian(point), Hd, rtol=1e-6,
                                   atol=1e-9 * np.abs(Hd).max())


def test_a_source_current_the_model_cannot_give_is_refused(tmp_path):
    """The input source's own current follows the input; a source whose node meets a
    capacitor would need the states' slope: each refused by name."""
    with pytest.raises(NetlistError, match="follows the model input directly"):
        _mirror("i(vin)", "vin")
    path = tmp_path / "c.cir"
    path.write_text("c\nVIN in 0 DC 0\nR1 in a 1k\nCA a 0 1n\nVX a2 0 DC 1\nC2 a2 a 1n\n"
                    "R2 a2 a 1k\n.end\n")
    with pytest.raises(NetlistError, match="which c2 meets: a capacitor"):
        model_class(path, "VIN", "i(vx)", name="netlist:test_outs_cap")()


@pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice is not installed here")
def test_estim_spice_compares_a_supply_current(tmp_path):
    """The two-stage amplifier measured at its supply current and its output: both traces
    within their bars against ngspice (the supply current as estim's model gives it from
    ngspice's node voltages; no AC row for it)."""
    spec = yaml.safe_load((ROOT / "configs" / "netlist" / "gp_two_stage_ekf.yaml").read_text())
    spec["model"].update(netlist=str(ROOT / "circuits" / "gp_two_stage.cir"),
                         output=["i(vcc)", "v(out)"])
    spec["input"].update(frequencies_hz=[1000], periods=2)
    spec["noise"].update(input_levels=[0.01], measurement_sigma=[2e-5, 0.02])
    spec.pop("check")
    path = tmp_path / "vcc.yaml"
    path.write_text(yaml.safe_dump(spec))
    result = CliRunner().invoke(main, ["spice", str(path), "--format", "csv"])
    assert result.exit_code == 0, result.output
    assert "i(vcc) (output)" in result.output and "gain VIN -> i(vcc)" not in result.output


def test_the_compiled_ekf_takes_two_outputs_as_the_numpy_one(monkeypatch):
    """The mirror measured at i(ro) and v(a) (both affine, so the compiled EKF runs it): its
    estimates, covariances and innovations equal the numpy loop's to rounding."""
    from test_compiled_filters import assert_same, both

    model = _mirror(["i(ro)", "v(a)"], "compiled")
    rng = np.random.default_rng(4)
    dt, steps = 2.5e-5, 80
    t = np.arange(steps + 1) * dt
    u = model.source_to_input((1.0 + np.sin(2 * np.pi * 1e3 * t))[:, None], dt)
    x0 = model.operating_point(u=[1.0])
    z = model.h(x0)[None, None, :] + np.array([2e-6, 0.01]) * rng.standard_normal((5, steps, 2))
    ekf = ExtendedKalmanFilter(Q=[4e-5, 1e-6], R=[4e-12, 1e-4], P0=[1e-4, 1e-4])
    fast, slow = both(ekf, model, z, u, dt, x0, monkeypatch)
    assert fast.S.shape[-2:] == (2, 2)
    assert_same(fast, slow, 1e-9)
