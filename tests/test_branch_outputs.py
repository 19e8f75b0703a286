"""Currents as the measured output of a netlist model (issue 47, item 2): a resistor's,
a diode's, a BJT terminal's and a MOSFET drain's, by the laws the drift uses."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from estim.spice import model_class
from estim.spice.parser import NetlistError

ROOT = Path(__file__).resolve().parents[1]
NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")


def _model(circuit: str, output: str, tag: str):
    return model_class(ROOT / "circuits" / circuit, "VIN", output,
                       name=f"netlist:test_out_{tag}")()


def _jacobian_matches(model, x):
    eps = 1e-7
    Hd = np.stack([(model.h(x + eps * e) - model.h(x - eps * e)) / (2 * eps)
                   for e in np.eye(model.n_states)], axis=-1)
    H = model.h_jacobian(x)
    assert H.shape == (1, model.n_states)
    assert np.abs(H - Hd).max() <= 1e-6 * np.abs(H).max()


def test_a_resistors_current_is_an_affine_output():
    """i(R1) of the rectifier's load is v(out) / R1, affine (the compiled loops take it)."""
    model = _model("rectifier.cir", "i(r1)", "r")
    x = np.array([0.3])
    np.testing.assert_allclose(model.h(x), [0.3 / 10e3], rtol=1e-14)
    H, c = model.affine_output()
    np.testing.assert_allclose(H, [[1 / 10e3]], rtol=1e-14)
    assert c.tolist() == [0.0]


def test_the_bjts_terminal_currents_obey_kcl_and_their_law():
    """ic + ib + ie = 0 (all three into the device) at states around the DC point; ic / ib
    at the DC point is the forward beta of alpha_f = 0.995 to 1e-3 (the collector junction
    reverse-biased); each Jacobian equals the differences of its output; none is affine."""
    models = {t: _model("ce_amp.cir", f"{t}(q1)", t) for t in ("ic", "ib", "ie")}
    x0 = models["ic"].operating_point(u=[0.0])
    rng = np.random.default_rng(0)
    for x in [x0, *(x0 + rng.normal(0, 1e-3, x0.size) for _ in range(5))]:
        total = sum(m.h(x) for m in models.values())
        assert abs(total[0]) <= 1e-12 * abs(models["ic"].h(x)[0])
    ratio = models["ic"].h(x0)[0] / models["ib"].h(x0)[0]
    assert ratio == pytest.approx(0.995 / 0.005, rel=1e-3)
    for m in models.values():
        assert m.affine_output() is None
        _jacobian_matches(m, x0)


def test_a_mosfets_drain_current_is_what_its_source_resistor_carries():
    """id(M1) of the level-1 stage at its DC point equals v(s) / RS (KCL at the source, the
    bulk carrying nothing), and its Jacobian the differences."""
    model = _model("cmos_level1.cir", "id(m1)", "id")
    x = model.operating_point(u=[0.85])
    s = model.state_names.index("v(s)")
    assert model.h(x)[0] == pytest.approx(x[s] / 2e3, rel=1e-9)
    _jacobian_matches(model, x)


@pytest.mark.parametrize("circuit, output, message", [
    ("rectifier.cir", "i(c1)", "i() of an inductor, resistor, diode or voltage source"),
    ("rectifier.cir", "ic(d1)", "ic() of a BJT"),
    ("rectifier.cir", "id(q1)", "id() of a MOSFET"),
    ("rectifier.cir", "i(d1)", "follows the model input directly"),
    ("ce_amp.cir", "i(rs)", "follows the model input directly"),
])
def test_an_output_the_model_cannot_give_is_refused(circuit, output, message):
    with pytest.raises(NetlistError, match=message.replace("(", r"\(").replace(")", r"\)")):
        _model(circuit, output, "bad")


def test_a_branch_current_is_no_thesis_state():
    with pytest.raises(NetlistError, match="thesis_states: 'i\\(r1\\)' is a branch current"):
        _ = model_class(ROOT / "circuits" / "rectifier.cir", "VIN", "v(out)",
                        name="netlist:test_out_thesis", thesis_states=["i(r1)"])().thesis_map


@NGSPICE
@pytest.mark.parametrize("output, checks", [("ic(q1)", {"dc", "transient"}),
                                            ("i(rl)", {"dc", "transient", "ac"})])
def test_estim_spice_compares_current_outputs(output, checks):
    """The common-emitter amplifier measured by its collector current (no AC row: ngspice's
    AC analysis gives no device current) and by its load's current (the AC gain as the
    voltage across the load over its resistance): every bar holds."""
    from estim.engine import ngspice_check as compare

    model = _model("ce_amp.cir", output, f"ng{output[:2]}")
    dt = 5e-5
    t = np.arange(201) * dt
    rng = np.random.default_rng(3)
    source = 2e-3 * np.sin(2e3 * np.pi * t) + 5e-4 * rng.standard_normal(t.size)
    rows = compare._tightening("1 kHz", model, source[:, None], dt, 1e3, None, 1e-10, 1e-7, 2)
    assert {r["check"] for r in rows} == checks
    bad = [r for r in rows if r["difference"] > compare.BARS[r["check"]]]
    assert not bad, bad


def test_filters_run_on_a_collector_current(tmp_path):
    """An estimation config measuring the amplifier's collector current: the EKF and the UKF
    take the nonlinear output (the numpy loops: no affine output for the compiled ones), no
    run breaks, and the states table has every node."""
    import csv

    import yaml
    from click.testing import CliRunner

    from estim.cli.main import main

    settings = {"Q": [1.0e-6, 1.5e-2, 1.0e-8, 1.5e-2, 1.0e-6], "R": 4.0e-12,
                "P0": [1.0e-6, 1.0e-2, 1.0e-6, 1.0e-2, 1.0e-6]}
    config = {
        "name": "ce_ic", "title": "collector current measured", "analysis": "estimation",
        "model": {"netlist": str(ROOT / "circuits" / "ce_amp.cir"), "input": "VIN",
                  "output": "ic(q1)"},
        "input": {"amplitude_v": 0.002, "bias_v": [0.0], "frequencies_hz": [1000],
                  "samples_per_period": 20, "periods": 3},
        "noise": {"input_levels": [0.0005], "measurement_sigma": 2.0e-6,
                  "filters_see": "nominal"},
        "estimators": [{"label": "EKF", "type": "ekf", "settings": settings},
                       {"label": "UKF", "type": "ukf", "settings": settings}],
        "monte_carlo": {"runs": 3, "seed": 1}, "tables": {"rmse": "ours"}}
    path = tmp_path / "ce_ic.yaml"
    path.write_text(yaml.safe_dump(config))
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "out"),
                                       "--jobs", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(open(tmp_path / "out" / "ce_ic" / "rmse.csv")))
    assert {r["estimator"] for r in rows} == {"EKF", "UKF", "measurement"}
    assert all(np.isfinite(float(r["rmse"])) and r["diverged"] == "0" for r in rows)
    states = list(csv.DictReader(open(tmp_path / "out" / "ce_ic" / "states.csv")))
    assert {r["state"] for r in states} == {"v(b)", "v(c)", "v(e)", "v(o)", "v(s)"}


def test_the_new_circuits_do_what_their_comments_say():
    """circuits/diode_limiter.cir: at the 2 V peaks of its config's sine the node stays within
    a diode drop beyond the +-0.5 V references (clamped: unclamped it would follow RL / (R1 +
    RL) of the source), while 0.3 V passes as the divider. circuits/diode_mirror.cir: at 0 V
    the diode is off and RO carries nothing; at 2 V RO carries five times the diode's
    current (KCL at a: what R1 brings minus what CA takes, nothing at the DC point)."""
    limiter = _model("diode_limiter.cir", "i(rl)", "limiter")
    for u, low, high in ((2.0, 0.5, 1.2), (-2.0, -1.2, -0.5)):
        a = limiter.operating_point(u=[u])[limiter.state_names.index("v(a)")]
        assert low < a < high and abs(a) < 2.0 * 10e3 / 11e3
    v = limiter.operating_point(u=[0.3])[limiter.state_names.index("v(a)")]
    assert v == pytest.approx(0.3 * 10e3 / 11e3, rel=1e-3)
    mirror = _model("diode_mirror.cir", "i(ro)", "mirror")
    assert abs(mirror.h(mirror.operating_point(u=[0.0]))[0]) < 1e-12
    x = mirror.operating_point(u=[2.0])
    diode_current = (2.0 - x[mirror.state_names.index("v(a)")]) / 2e3
    assert mirror.h(x)[0] == pytest.approx(5 * diode_current, rel=1e-9)
