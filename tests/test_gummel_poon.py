"""SPICE's Gummel-Poon BJT, its static law (issue 47, item 4): with IS, BF and BR alone it is
Ebers-Moll in transport form; its slopes are its differences; the compiled kernel equals
numpy; the two-stage amplifier of circuits/gp_two_stage.cir agrees with ngspice's own BJT;
SPICE parameters outside the static law are refused by name."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from estim.models.devices import ebers_moll
from estim.spice import gummel_poon, model_class
from estim.spice.gummel_poon import GUMMEL_POON
from estim.spice.parser import NetlistError

ROOT = Path(__file__).resolve().parents[1]
NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")
VT = 0.025852
FULL = {**GUMMEL_POON, "is": 1e-15, "bf": 150.0, "br": 2.0, "vaf": 80.0, "var": 20.0,
        "ikf": 0.05, "ikr": 0.01, "ise": 1e-14, "ne": 1.5, "isc": 1e-13, "nc": 1.8,
        "nf": 1.02, "nr": 1.05}


def test_with_is_bf_br_alone_it_is_ebers_moll_in_transport_form():
    """I_ES = IS / alpha_F, I_CS = IS / alpha_R, alpha = beta / (1 + beta): every current
    and slope of the two laws agree to rounding, forward, reverse and saturated."""
    p = {**GUMMEL_POON, "is": 1e-15, "bf": 150.0, "br": 2.0}
    a_f, a_r = 150.0 / 151.0, 2.0 / 3.0
    v_be = np.array([0.65, -0.4, 0.7, 0.3])
    v_bc = np.array([-4.0, 0.6, 0.65, 0.3])
    gp = gummel_poon.currents(v_be, v_bc, p, VT)
    em = ebers_moll.currents(v_be, v_bc, 1e-15 / a_f, 1e-15 / a_r, a_f, a_r, VT)
    for name in ("I_C", "I_B", "I_E", "dIC_be", "dIC_bc", "dIB_be", "dIB_bc", "dIE_be",
                 "dIE_bc"):
        mine, theirs = getattr(gp, name), getattr(em, name)
        np.testing.assert_allclose(mine, theirs, rtol=1e-12, atol=1e-12 * np.abs(theirs).max(),
                                   err_msg=name)


def test_its_slopes_are_its_differences():
    """Every slope of the full law (Early voltages, high injection, leakages) equals the
    central difference of its current, in forward, reverse and saturated operation."""
    for v_be, v_bc in ((0.72, -3.0), (-2.0, 0.68), (0.74, 0.55), (0.8, -1.0)):
        tc = gummel_poon.currents(v_be, v_bc, FULL, VT)
        h = 1e-7
        for name in ("C", "B", "E"):
            for which, dv in (("be", (h, 0.0)), ("bc", (0.0, h))):
                up = getattr(gummel_poon.currents(v_be + dv[0], v_bc + dv[1], FULL, VT),
                             f"I_{name}")
                down = getattr(gummel_poon.currents(v_be - dv[0], v_bc - dv[1], FULL, VT),
                               f"I_{name}")
                slope = getattr(tc, f"dI{name}_{which}")
                assert slope == pytest.approx((up - down) / (2 * h), rel=1e-6, abs=1e-12), \
                    (name, which, v_be, v_bc)


def _stage(tag: str):
    return model_class(ROOT / "circuits" / "gp_two_stage.cir", "VIN", "v(out)",
                       name=f"netlist:test_gp_{tag}")()


def test_the_compiled_kernel_and_the_hessian_of_a_gummel_poon_netlist():
    """The two-stage amplifier: the compiled drift and Jacobian equal numpy's; the analytic
    Jacobian equals the drift's differences; the Hessian's BJT terms (differences of the
    analytic slopes) equal second differences of the drift."""
    from test_current_inputs import kernel_matches

    model = _stage("kernel")
    x0 = model.operating_point(u=[1.7])
    rng = np.random.default_rng(5)
    n = model.n_states
    for _ in range(6):
        x, u = x0 + rng.normal(0, 0.02, n), np.array([1.7 + rng.normal(0, 0.05)])
        kernel_matches(model, x, u)
        J = model.jacobian(x, u)
        eps = 1e-7
        Jd = np.stack([(model.f(x + eps * e, u) - model.f(x - eps * e, u)) / (2 * eps)
                       for e in np.eye(n)], axis=-1)
        assert np.abs(J - Jd).max() < 1e-6 * np.abs(J).max()
    H = model.hessian(x0, np.array([1.7]))
    h = 1e-4
    z0 = np.concatenate([x0, [1.7]])
    for i, j in ((1, 0), (3, 1), (2, 2)):
        ei, ej = np.eye(n + 1)[i] * h, np.eye(n + 1)[j] * h

        def f_at(z):
            return model.f(z[:n], z[n:])
        second = (f_at(z0 + ei + ej) - f_at(z0 + ei - ej) - f_at(z0 - ei + ej)
                  + f_at(z0 - ei - ej)) / (4 * h * h)
        np.testing.assert_allclose(H[:, i, j], second, rtol=1e-4,
                                   atol=1e-4 * np.abs(H).max())


@NGSPICE
def test_the_two_stage_amplifier_agrees_with_ngspices_own_bjt(tmp_path):
    """estim spice on the stage's config: the DC point, every state's and the output's
    transient and the AC gain within their bars against ngspice's Gummel-Poon BJT (the
    .model passed through as it is)."""
    from estim.cli.main import main

    result = CliRunner().invoke(main, ["spice", str(ROOT / "configs" / "netlist" /
                                                   "gp_two_stage_ekf.yaml"),
                                       "--format", "csv"])
    assert result.exit_code == 0, result.output
    assert "gain VIN -> v(out)" in result.output and "v(c1)" in result.output


@pytest.mark.parametrize("model, message", [
    ("npn(is=1e-15 bf=100 rb=100)", "rb without cje or cjc; its internal node"),
    ("npn(is=1e-15 cjs=1p ptf=1)", "cjs, ptf: estim's Gummel-Poon"),
    ("npn(is=1e-15 ies=1e-14)", "unknown parameter(s) ['ies']"),
])
def test_spice_parameters_outside_the_static_law_are_refused_by_name(tmp_path, model,
                                                                     message):
    path = tmp_path / "q.cir"
    path.write_text(f"q\nVIN in 0 DC 0.7\nVCC c 0 DC 5\nQ1 c in e qn\nRE e 0 1k\n"
                    f"CE e 0 1n\n.model qn {model}\n.end\n")
    with pytest.raises(NetlistError, match=message.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[").replace("]", r"\]")):
        model_class(path, "VIN", "v(e)", name="netlist:test_gp_refused")()


def test_a_gummel_poon_parameter_may_be_a_state(tmp_path):
    """Q1.bf of the stage: the drift with the state moved equals the netlist written with
    that beta."""
    from estim.spice.parameter_states import Parameter, ParameterStates, value_of

    base = _stage("ps")
    assert value_of(base, "Q1.bf") == 150.0
    model = ParameterStates(base, (Parameter("Q1.bf", "q1", "bf", 100.0),))
    x0 = base.operating_point(u=[1.7])
    path = tmp_path / "gp.cir"
    text = (ROOT / "circuits" / "gp_two_stage.cir").read_text()
    own = next(line for line in text.splitlines() if line.startswith(".model qn"))
    path.write_text(text.replace("Q1 c1 b1 e1 qn", "Q1 c1 b1 e1 q1m").replace(
        ".end", own.replace("qn", "q1m").replace("bf=150", "bf=120") + "\n.end"))
    changed = model_class(path, "VIN", "v(out)", name="netlist:test_gp_ps2")()
    x = np.concatenate([x0, [1.2]])
    np.testing.assert_allclose(model.f(x, np.array([1.7]))[:-1], changed.f(x0, [1.7]),
                               rtol=1e-12, atol=1e-9)


def test_the_configs_comment_a_ukf_breaks_at_5_khz(tmp_path):
    """gp_two_stage_ekf.yaml's comment: a UKF with the EKF's settings breaks in every run of
    the 5 kHz cell (and health.csv names the step and the state)."""
    import pandas as pd

    from estim.cli.main import main

    config = ROOT / "configs" / "netlist" / "gp_two_stage_ekf.yaml"
    assert "breaks in every run at 5 kHz" in config.read_text()
    result = CliRunner().invoke(main, [
        "run", str(config), "estimators.0.type=ukf", "estimators.0.label=UKF",
        "input.frequencies_hz=[5000]", "--out", str(tmp_path), "--quiet"])
    assert result.exit_code == 0, result.output
    health = pd.read_csv(tmp_path / "gp_two_stage_ekf" / "health.csv")
    assert len(health) == 2                      # both noise levels, every run of each
    assert (health["broken"] == health["runs"]).all() and (health["runs"] == 30).all()
    assert health["first_break_state"].str.startswith("v(").all()
