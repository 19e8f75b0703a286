"""Nodes no capacitor meets (issue 47, item 1; D71): their voltages solved from KCL as affine
in the states and inputs, in the numpy drift, the compiled kernel and against ngspice."""

from __future__ import annotations

import importlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from estim.spice import model_class
from estim.spice.parser import NetlistError

NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")
KERNELS = pytest.mark.skipif(not importlib.import_module("estim.numerics.kernels").AVAILABLE,
                             reason="numba absent")


def _model(tmp_path: Path, text: str, inputs, output: str, name: str):
    path = tmp_path / f"{name}.cir"
    path.write_text(text)
    return model_class(path, inputs, output, name=f"netlist:test_{name}")()


DIVIDER = """an RC behind a divider with no capacitor at its middle
V1 in 0 DC 1
R1 in a 1k
C1 a 0 1u
R2 a b 1k
R3 b 0 1k
"""

SERIES_RLC = """series RLC: the inductor between two resistors' nodes, no shunt capacitor
V1 in 0 DC 1
R1 in a 100
L1 a b 10m
C1 b 0 1u
R2 b 0 1k
"""


def test_a_divider_node_is_solved_not_a_state(tmp_path):
    """b, between two 1k resistors with no capacitor, is not a state: ``v(b) = v(a) / 2``,
    so ``C1 v(a)' = (u - v(a)) / R1 - v(a) / (R2 + R3)``, the output at b is ``v(a) / 2``
    and the DC point ``u (R2 + R3) / (R1 + R2 + R3)``."""
    model = _model(tmp_path, DIVIDER, "V1", "v(b)", "divider")
    assert model.state_names == ("v(a)",)
    x, u = np.array([0.4]), np.array([1.0])
    np.testing.assert_allclose(model.f(x, u), ((1.0 - 0.4) / 1e3 - 0.4 / 2e3) / 1e-6,
                               rtol=1e-14)
    np.testing.assert_allclose(model.h(x), [0.2], rtol=1e-14)
    np.testing.assert_allclose(model.operating_point(u=u), [2 / 3], rtol=1e-12)


def test_an_inductor_needs_no_shunt_capacitor(tmp_path):
    """The series RLC with a and b joined only by L1: ``v(a) = u - R1 i``, so ``L i' = u -
    R1 i - v(b)`` and ``C v(b)' = i - v(b) / R2``; drift and Jacobian in closed form."""
    model = _model(tmp_path, SERIES_RLC, "V1", "v(b)", "series_rlc")
    assert model.state_names == ("v(b)", "i(l1)")
    x, u = np.array([0.3, 2e-3]), np.array([1.0])
    f, J = model.f_and_jacobian(x, u)
    np.testing.assert_allclose(f, [(2e-3 - 0.3 / 1e3) / 1e-6, (1.0 - 100 * 2e-3 - 0.3) / 10e-3],
                               rtol=1e-13)
    np.testing.assert_allclose(J, [[-1 / (1e3 * 1e-6), 1 / 1e-6], [-1 / 10e-3, -100 / 10e-3]],
                               rtol=1e-13)
    np.testing.assert_allclose(model.input_jacobian(x, u), [[0.0], [1 / 10e-3]], atol=1e-9)


EVERYTHING = """nodes without capacitors beside sources and a device
V1 in 0 DC 1
R1 in a 1k
R2 a 0 2k
E1 e 0 a 0 0.5
R3 e b 1k
C1 b 0 1n
G1 b 0 a 0 1e-4
L1 a c 1m
R4 c 0 100
I1 0 c DC 0
D1 b d dm
R5 d 0 3k
C2 d 0 1n
.model dm d(is=1e-14 n=1.2)
"""


@KERNELS
def test_the_compiled_kernel_takes_the_solved_nodes(tmp_path):
    """Two nodes without a capacitor (a behind the input, c between an inductor and a
    current input), read by an E and a G source: the compiled drift and Jacobian equal the
    numpy ones, the Jacobian its differences, and the input Jacobian the differences of
    ``f`` in both inputs."""
    from estim.numerics import kernels

    model = _model(tmp_path, EVERYTHING, ["V1", "I1"], "v(d)", "everything")
    assert sorted(model.circuit.algebraic) == ["a", "c"]
    kind, P = model.kernel()
    rng = np.random.default_rng(4)
    n = model.n_states
    for _ in range(10):
        x, u = rng.uniform(-0.2, 0.8, n), np.array([rng.uniform(0.5, 1.5),
                                                    rng.uniform(-1e-3, 1e-3)])
        f, J = model.f_and_jacobian(x, u)
        fk, Jk = np.empty(n), np.empty((n, n))
        kernels.evaluate(kind, x, u, P, fk, Jk)
        np.testing.assert_allclose(fk, f, rtol=1e-12, atol=1e-12 * np.abs(f).max())
        np.testing.assert_allclose(Jk, J, rtol=1e-12, atol=1e-12 * np.abs(J).max())
        scale = np.array([1e-7, 1e-10])
        Jd = np.stack([(model.f(x + 1e-7 * e, u) - model.f(x - 1e-7 * e, u)) / 2e-7
                       for e in np.eye(n)], axis=-1)
        assert np.abs(Jd - J).max() < 1e-5 * np.abs(J).max()
        Bd = np.stack([(model.f(x, u + s * e) - model.f(x, u - s * e)) / (2 * s)
                       for s, e in zip(scale, np.eye(2), strict=True)], axis=-1)
        B = model.input_jacobian(x, u)
        assert np.abs(B - Bd).max() < 1e-5 * np.abs(B).max()


@pytest.mark.parametrize("text, message", [
    ("d\nV1 in 0 DC 1\nR1 in a 1k\nD1 a b dm\nR2 b 0 1k\nC1 a 0 1n\n.model dm d\n",
     "node(s) b have no capacitive path and carry the current of d1"),
    ("l\nV1 in 0 DC 1\nR1 in a 1k\nC1 a 0 1n\nL1 a b 1m\nL2 b 0 1m\n",
     "node(s) b have no capacitive path and no conductance that fixes their voltage"),
    ("o\nV1 in 0 DC 1\nR1 in b 1k\nR2 b 0 1k\nR3 b a 1k\nC1 a 0 1n\n",
     "output 'v(b)' follows the model input directly"),
])
def test_a_node_without_a_capacitor_that_cannot_be_solved_is_refused(tmp_path, text,
                                                                        message):
    path = tmp_path / "bad.cir"
    path.write_text(text)
    with pytest.raises(NetlistError, match=message.replace("(", r"\(").replace(")", r"\)")):
        model_class(path, "V1", "v(b)", name="netlist:test_bad_algebraic")()


@NGSPICE
def test_the_series_rlc_without_a_shunt_capacitor_agrees_with_ngspice(tmp_path):
    """The series RLC driven by a noisy 1 kHz sine: the DC point, both states (the inductor's
    current among them) and the AC gain within estim spice's bars of ngspice's."""
    from estim.engine import ngspice_check as compare

    model = _model(tmp_path, SERIES_RLC, "V1", "v(b)", "series_rlc_ngspice")
    dt = 1e-5
    t = np.arange(201) * dt
    rng = np.random.default_rng(9)
    source = 1 + 0.5 * np.sin(2e3 * np.pi * t) + 0.01 * rng.standard_normal(t.size)
    rows = compare._tightening("1 kHz", model, source[:, None], dt, 1e3, None, 1e-10, 1e-7, 2)
    assert {r["quantity"] for r in rows if r["check"] == "transient"} == {
        "v(b)", "i(l1)", "v(b) (output)"}
    bad = [r for r in rows if r["difference"] > compare.BARS[r["check"]]]
    assert not bad, bad
