"""Behavioural current sources, SPICE's ``B ... I={expression}`` (issue 47, item 9): a B
source written as a diode's law is that diode, to rounding, in the drift, its Jacobian and
its Hessian; expressions take parameters, SI suffixes, differences of nodes and functions,
in subcircuits too; ngspice's own B source agrees; what estim cannot take is refused by
name."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from estim.spice import model_class
from estim.spice.parser import NetlistError

TWIN = """B source written as the diode beside it
VIN in 0 DC 0
R1 in a 1k
CA a 0 10n
B1 a 0 I={is0 * (exp(v(a) / (1.05 * 25.852m)) - 1)}
R2 in b 1k
CB b 0 10n
D1 b 0 dd
.param is0=1e-14
.model dd d(is=1e-14 n=1.05)
.end
"""

GM = """A tanh transconductor in a subcircuit, driving an RC load
VIN in 0 DC 0
RI in g 1k
CG g 0 1n
X1 g o gm params: gm0=2m
RO o 0 1k
CO o 0 1n
.subckt gm i o params: gm0=1m
B1 o 0 I={gm0 * 0.1 * tanh(v(i, 0) / 0.1) + 1u * v(i) ^ 2}
.ends
.end
"""


def _model(tmp_path, text, output, tag):
    path = tmp_path / f"{tag}.cir"
    path.write_text(text)
    return model_class(path, "VIN", output, name=f"netlist:test_b_{tag}")()


def test_a_b_source_written_as_a_diodes_law_is_that_diode(tmp_path):
    """Two twin branches, one a D element, one a B source of Shockley's law: their states'
    drift, Jacobian, input Jacobian and Hessian agree (the B source's slopes by the complex
    step, exact; its second slopes central differences of them, to 1e-8)."""
    model = _model(tmp_path, TWIN, "v(a)", "twin")
    assert model.kernel() is None                        # the numpy path
    rng = np.random.default_rng(2)
    for _ in range(5):
        v = rng.uniform(0.3, 0.75)
        x, u = np.array([v, v]), np.array([rng.uniform(0, 2)])
        f, J = model.f_and_jacobian(x, u)
        assert f[0] == pytest.approx(f[1], rel=1e-13)
        assert J[0, 0] == pytest.approx(J[1, 1], rel=1e-13)
        B = model.input_jacobian(x, u)
        assert B[0, 0] == pytest.approx(B[1, 0], rel=1e-13)
        H = model.hessian(x, u)
        assert H[0, 0, 0] == pytest.approx(H[1, 1, 1], rel=1e-6)


def test_expressions_take_parameters_suffixes_differences_and_subcircuits(tmp_path):
    """The subcircuit's B source: gm0 from the call (2m, not the default 1m), v(i, 0) and
    v(i)^2 of the renamed node; the drift equals the law written out, the Jacobian the
    drift's differences."""
    model = _model(tmp_path, GM, "v(o)", "gm")
    assert model.state_names == ("v(g)", "v(o)")
    x, u = np.array([0.05, 0.01]), np.array([0.1])
    law = 2e-3 * 0.1 * np.tanh(0.05 / 0.1) + 1e-6 * 0.05**2
    expected = (-(0.01 / 1e3) - law) / 1e-9
    assert model.f(x, u)[1] == pytest.approx(expected, rel=1e-12)
    eps = 1e-7
    Jd = np.stack([(model.f(x + eps * e, u) - model.f(x - eps * e, u)) / (2 * eps)
                   for e in np.eye(2)], axis=-1)
    np.testing.assert_allclose(model.jacobian(x, u), Jd, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("line, message", [
    ("B1 a 0 V={2 * v(a)}", "a behavioural voltage source (V=)"),
    ("B1 a 0 I={foo(v(a))}", "function 'foo'"),
    ("B1 a 0 I={k * v(a)}", "unknown name 'k'"),
    ("B1 a 0 I={v(a).real}", "attribute not allowed"),
    ("B1 a 0 I={v(zz) * 1m}", "v(zz) names no node of the circuit"),
    ("B1 a 0 {v(a)}", "expected I={expression}"),
])
def test_what_a_b_source_cannot_be_is_refused_by_name(tmp_path, line, message):
    text = f"t\nVIN in 0 DC 0\nR1 in a 1k\nCA a 0 1n\n{line}\n.end\n"
    with pytest.raises(NetlistError, match=message.replace("(", r"\(").replace(")", r"\)")
                       .replace("{", r"\{").replace("}", r"\}")):
        _model(tmp_path, text, "v(a)", "bad")


def test_a_b_source_into_a_node_without_a_capacitor_is_refused(tmp_path):
    text = "t\nVIN in 0 DC 0\nR1 in a 1k\nR2 a 0 1k\nB1 a 0 I={1m * v(a)}\n.end\n"
    with pytest.raises(NetlistError, match="carry the current of b1"):
        _model(tmp_path, text, "v(a)", "nocap")


@pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice is not installed here")
def test_the_transconductor_agrees_with_ngspices_b_source(tmp_path):
    """estim spice on the subcircuit's B source (ngspice reads the expression as written
    out for it): DC point, transients and AC gain within their bars."""
    from estim.cli.main import main

    (tmp_path / "gm.cir").write_text(GM)
    spec = yaml.safe_load((Path(__file__).resolve().parents[1] / "configs" / "netlist" /
                           "diode_limiter_ekf.yaml").read_text())
    spec["model"] = {"netlist": str(tmp_path / "gm.cir"), "input": "VIN", "output": "v(o)"}
    spec["input"].update(amplitude_v=0.2, frequencies_hz=[100000], periods=3)
    spec["noise"].update(input_levels=[0.01], measurement_sigma=1e-3)
    for est in spec["estimators"]:
        est["settings"].update(R=1e-6, Q=1e-6, P0=1e-6)
    spec.pop("check")
    path = tmp_path / "gm.yaml"
    path.write_text(yaml.safe_dump(spec))
    result = CliRunner().invoke(main, ["spice", str(path)])
    assert result.exit_code == 0, result.output
    assert "within their bars" in result.output
