"""Current sources as model inputs (issue 47, item 1): a current into the KCL rows of its two
nodes, in the numpy drift, the compiled kernel and against ngspice."""

from __future__ import annotations

import importlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from estim.spice import model_class
from estim.spice.parser import NetlistError

ROOT = Path(__file__).resolve().parents[1]
RLC = ROOT / "circuits" / "rlc_current.cir"
NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "c.cir"
    path.write_text(text)
    return path


@pytest.mark.parametrize("nodes, sign", [("0 a", 1.0), ("a 0", -1.0)])
def test_a_current_input_is_the_closed_form_rc(tmp_path, nodes, sign):
    """I into R || C: ``C v' = s u - v / R`` with ``s`` +1 for a source from ground into the
    node (SPICE's current flows from + through the source to -), -1 the other way round;
    the DC point ``v = s R u``; the input Jacobian ``s / C``."""
    R, C = 2e3, 1e-6
    model = model_class(_write(tmp_path, f"rc\nI1 {nodes} DC 0\nR1 a 0 {R}\nC1 a 0 {C}\n"),
                        "I1", "v(a)", name=f"netlist:test_i_rc{int(sign)}")()
    assert model.input_names == ("i1",)
    x, u = np.array([0.3]), np.array([2e-4])
    f, J = model.f_and_jacobian(x, u)
    np.testing.assert_allclose(f, (sign * u - x / R) / C, rtol=1e-14)
    np.testing.assert_allclose(J, [[-1 / (R * C)]], rtol=1e-14)
    np.testing.assert_allclose(model.input_jacobian(x, u), [[sign / C]], rtol=1e-14)
    np.testing.assert_allclose(model.operating_point(u=u), sign * R * u, rtol=1e-12)


TWO_INPUTS = """a voltage and a current input, the current summed where an F source reads VD
VIN in 0 DC 1
R1 in a 2k
C1 a 0 1n
D1 a s dmod
VD s 0 0
F1 0 o VD 3
IX 0 s DC 0
R2 o 0 1k
C2 o 0 1n
IY o a DC 0
L1 o 0 1m
.model dmod d(is=1e-14 n=1.2 rs=5)
"""


def kernel_matches(model, x: np.ndarray, u: np.ndarray) -> None:
    """The compiled netlist kernel's drift and Jacobian at ``(x, u)`` equal numpy's to
    rounding."""
    from estim.numerics import kernels

    kind, P = model.kernel()
    n = model.n_states
    f, J = model.f_and_jacobian(x, u)
    fk, Jk = np.empty(n), np.empty((n, n))
    kernels.evaluate(kind, x, u, P, fk, Jk)
    np.testing.assert_allclose(fk, f, rtol=1e-12, atol=1e-12 * np.abs(f).max())
    np.testing.assert_allclose(Jk, J, rtol=1e-12, atol=1e-12 * np.abs(J).max())


@pytest.mark.skipif(not importlib.import_module("estim.numerics.kernels").AVAILABLE,
                    reason="numba absent")
def test_the_compiled_kernel_takes_current_inputs(tmp_path):
    """A netlist with a voltage input and two current inputs, one of them into the node
    where F1's controlling current is summed (its current then reaches F1's output): the
    compiled drift and Jacobian equal the numpy ones, and the analytic input Jacobian the
    differences of ``f``."""
    model = model_class(_write(tmp_path, TWO_INPUTS), ["VIN", "IX", "IY"], "v(o)",
                        name="netlist:test_i_kernel")()
    rng = np.random.default_rng(3)
    n = model.n_states
    for _ in range(10):
        x, u = rng.uniform(-0.5, 1, n), np.concatenate([[1.0], rng.uniform(-1e-3, 1e-3, 2)])
        kernel_matches(model, x, u)
        eps = 1e-9
        Bd = np.stack([(model.f(x, u + eps * e) - model.f(x, u - eps * e)) / (2 * eps)
                       for e in np.eye(3)], axis=-1)
        B = model.input_jacobian(x, u)
        assert np.abs(B - Bd).max() < 1e-5 * np.abs(B).max()
    # 0.1 mA more of IX into s leaves through VD (from its + node s to 0), so F1 (from its +
    # node 0 to o) puts 0.3 mA more into o: C2 v(o)' grows by 0.3 mA
    f0 = model.f(x, u)
    du = np.array([0.0, 1e-4, 0.0])
    i_o = model.state_names.index("v(o)")
    assert (model.f(x, u + du) - f0)[i_o] * 1e-9 == pytest.approx(3e-4, rel=1e-9)


@pytest.mark.parametrize("text, inputs, message", [
    ("h\nVIN in 0 DC 1\nR1 in a 1k\nC1 a 0 1n\nVX b 0 0\nR2 a b 1k\nI1 0 b DC 0\n"
     "H1 h 0 VX 100\nR3 h k 1k\nC3 k 0 1n\n", ["VIN", "I1"],
     "which i1 meets: a model input"),
    ("s\nVIN in 0 DC 1\nC1 in a 1n\nR1 a 0 1k\nI1 0 a DC 0\n", ["VIN", "I1"],
     "current sources among them"),
    ("r\nVIN in 0 DC 1\nR1 in a 1k\nC1 a 0 1n\n", ["R1"],
     "input 'r1' is not a voltage or current source"),
])
def test_a_current_input_the_model_cannot_take_is_refused(tmp_path, text, inputs, message):
    with pytest.raises(NetlistError, match=message):
        model_class(_write(tmp_path, text), inputs, "v(a)", name="netlist:test_i_bad")


@NGSPICE
def test_the_rlc_tank_and_its_inductor_current_agree_with_ngspice():
    """circuits/rlc_current.cir driven by a noisy 5 kHz current about 1 mA: its DC point,
    the node voltage and the inductor current (a branch current ngspice solves for in its
    modified nodal analysis) within estim spice's bars, and the AC gain from the source's
    current to the inductor's."""
    from estim.engine import ngspice_check as compare

    model = model_class(RLC, "IIN", "i(l1)", name="netlist:test_rlc_ngspice")()
    L, C, R = 10e-3, 100e-9, 1e3
    f0 = 1 / (2 * np.pi * np.sqrt(L * C))
    print(f"f0 {f0:.0f} Hz, Q {R * np.sqrt(C / L):.2f}")
    dt = 1 / (5e3 * 100)
    rng = np.random.default_rng(5)
    t = np.arange(401) * dt
    source = 1e-3 + 1e-3 * np.sin(2 * np.pi * 5e3 * t) + 1e-5 * rng.standard_normal(401)
    rows = compare._tightening("5 kHz", model, source[:, None], dt, 5e3, None, 1e-10, 1e-7, 2)
    assert {r["quantity"] for r in rows if r["check"] == "transient"} == {
        "v(top)", "i(l1)", "i(l1) (output)"}
    bad = [r for r in rows if r["difference"] > compare.BARS[r["check"]]]
    assert not bad, bad
    # the AC gain at resonance is Q (the tank's current is Q times the source's)
    A, B = model.jacobian(model.operating_point(u=[1e-3]), [1e-3]), model.input_jacobian(
        model.operating_point(u=[1e-3]), [1e-3])
    w = 2j * np.pi * f0
    gain = (model.h_jacobian(np.zeros(2)) @ np.linalg.solve(w * np.eye(2) - A, B))[0, 0]
    assert abs(gain) == pytest.approx(R * np.sqrt(C / L), rel=1e-9)
