"""SPICE's level-1 MOSFET in netlists (issue 47, item 4): the law by region, its derivatives,
the compiled kernel, and ngspice's own MOS1 model as the independent check."""

from __future__ import annotations

import importlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from estim.spice import model_class
from estim.spice.level1 import LEVEL1, level1
from estim.spice.parser import NetlistError

NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")
P = {**LEVEL1, "vto": 0.7, "kp": 1e-4, "lambda": 0.05, "gamma": 0.4, "phi": 0.65}


def test_the_law_by_region():
    """Cut-off, linear and saturation at zero body bias by the textbook formulas with
    ``beta = KP W / L``; body bias raises the threshold by ``GAMMA (sqrt(PHI - v_BS) -
    sqrt(PHI))``; with drain and source swapped the current changes sign."""
    beta = 1e-4 * 2.0
    p = {**P, "w_over_l": 2.0}
    assert level1(1.0, 0.6, 0.0, 0.0, p)[0] == 0.0
    assert level1(0.2, 1.5, 0.0, 0.0, p)[0] == pytest.approx(
        beta * 0.2 * (0.8 - 0.1) * 1.01, rel=1e-14)
    assert level1(2.0, 1.5, 0.0, 0.0, p)[0] == pytest.approx(
        beta / 2 * 0.8**2 * 1.1, rel=1e-14)
    vth = 0.7 + 0.4 * (np.sqrt(0.65 + 1.0) - np.sqrt(0.65))
    assert level1(2.0, 1.5, 0.0, -1.0, p)[0] == pytest.approx(
        beta / 2 * (1.5 - vth) ** 2 * 1.1, rel=1e-14)
    assert level1(0.0, 1.5, 2.0, 0.0, p)[0] == -level1(2.0, 1.5, 0.0, 0.0, p)[0] < 0


def test_gradient_and_hessian_are_the_differences_of_the_law():
    """At random points of every region and both modes (forward body bias too): the gradient
    against central differences of the current, the Hessian against those of the
    gradient."""
    p = {**P, "w_over_l": 3.0}
    rng = np.random.default_rng(0)
    eps = 1e-6
    for _ in range(400):
        v = rng.uniform(-2, 3, 4)
        cur, g, H = level1(*v, p, second=True)
        gd = np.array([(level1(*(v + eps * e), p)[0] - level1(*(v - eps * e), p)[0]) / (2 * eps)
                       for e in np.eye(4)])
        Hd = np.array([(level1(*(v + eps * e), p)[1] - level1(*(v - eps * e), p)[1]) / (2 * eps)
                       for e in np.eye(4)])
        assert np.abs(gd - g).max() <= 1e-7 * max(np.abs(g).max(), 1e-9)
        assert np.abs(Hd - H).max() <= 1e-4 * max(np.abs(H).max(), 1e-6)


STAGE = """a level-1 NMOS stage with body effect, and a level-1 PMOS load
VDD dd 0 DC 5
VIN in 0 DC 0.85
RG in g 10k
CG g 0 1p
M1 d g s 0 mn w=20u l=2u
RS s 0 2k
CS s 0 2p
M2 d dd2 dd dd mp w=4u l=2u
VB dd2 0 DC 3.6
CD d 0 1p
RL d 0 200k
.model mn nmos(level=1 vto=0.7 kp=110u lambda=0.04 gamma=0.45 phi=0.7)
.model mp pmos(level=1 vto=-0.8 kp=50u lambda=0.05 gamma=0.4 phi=0.65)
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "stage.cir"
    path.write_text(text)
    return path


@pytest.mark.skipif(not importlib.import_module("estim.numerics.kernels").AVAILABLE,
                    reason="numba absent")
def test_the_compiled_kernel_is_the_numpy_drift(tmp_path):
    """The level-1 NMOS (body effect, degenerated source) and PMOS (a current-source load)
    of one stage: compiled drift and Jacobian against numpy at random points, both modes of
    both devices; the numpy Jacobian against differences; the analytic Hessian against
    differences of the analytic Jacobian."""
    from estim.numerics import kernels

    model = model_class(_write(tmp_path, STAGE), "VIN", "v(d)", name="netlist:test_l1")()
    kind, Pk = model.kernel()
    rng = np.random.default_rng(1)
    n = model.n_states
    for _ in range(20):
        x, u = rng.uniform(-1, 5, n), rng.uniform(0.5, 2.5, 1)
        f, J = model.f_and_jacobian(x, u)
        fk, Jk = np.empty(n), np.empty((n, n))
        kernels.evaluate(kind, x, u, Pk, fk, Jk)
        np.testing.assert_allclose(fk, f, rtol=1e-12, atol=1e-12 * np.abs(f).max())
        np.testing.assert_allclose(Jk, J, rtol=1e-12, atol=1e-12 * np.abs(J).max())
        Jd = np.stack([(model.f(x + 1e-7 * e, u) - model.f(x - 1e-7 * e, u)) / 2e-7
                       for e in np.eye(n)], axis=-1)
        assert np.abs(Jd - J).max() < 1e-5 * np.abs(J).max()
    x, u = model.operating_point(u=[0.85]), np.array([0.85])

    def jac(z):
        return np.hstack([model.jacobian(z[:n], z[n:]), model.input_jacobian(z[:n], z[n:])])

    z = np.concatenate([x, u])
    Hd = np.stack([(jac(z + 1e-6 * e) - jac(z - 1e-6 * e)) / 2e-6 for e in np.eye(n + 1)],
                  axis=-1)
    H = model.hessian(x, u)
    assert np.abs(H - Hd).max() < 1e-5 * np.abs(H).max()


@NGSPICE
def test_the_stage_agrees_with_ngspices_own_level_1(tmp_path):
    """ngspice runs its own MOS1 model (its junction diodes off), not a translation of
    estim's law: the DC point, every state over a noisy 1 kHz sine and the AC gain within
    estim spice's bars."""
    from estim.engine import ngspice_check as compare

    model = model_class(_write(tmp_path, STAGE), "VIN", "v(d)", name="netlist:test_l1_ng")()
    dt = 1e-5
    t = np.arange(201) * dt
    rng = np.random.default_rng(2)
    source = 0.85 + 0.03 * np.sin(2e3 * np.pi * t) + 0.002 * rng.standard_normal(t.size)
    rows = compare._tightening("1 kHz", model, source[:, None], dt, 1e3, None, 1e-10, 1e-7, 2)
    bad = [r for r in rows if r["difference"] > compare.BARS[r["check"]]]
    assert not bad, bad
    d = model.state_names.index("v(d)")
    assert 1.0 < model.operating_point(u=[0.85])[d] < 4.0      # both devices saturated


@pytest.mark.parametrize("model_line, element, message", [
    (".model mn nmos(level=2 vto=0.7)", "M1 d g 0 0 mn", "level 2; estim has level 1"),
    (".model mn nmos(level=1 vto=0.7 tox=1e-8)", "M1 d g 0 0 mn", "unknown parameter(s) "
                                                                  "['tox']"),
    (".model mn nmos(v_t0=0.5)", "M1 d g 0 0 mn w=2u l=1u", "w and l on an EKV device"),
    (".model mn nmos(level=1)", "M1 d g 0 0 mn w=2u q=1u", "expected w=VALUE and l=VALUE"),
    (".model mn nmos(level=1)", "M1 d g 0 0 mn w=-2u l=1u", "w must be positive"),
])
def test_a_level_1_device_estim_cannot_take_is_refused(tmp_path, model_line, element,
                                                       message):
    text = f"m\nVIN g 0 DC 1\nRD dd d 10k\nVDD dd 0 DC 3\nCD d 0 1p\n{element}\n{model_line}\n"
    with pytest.raises(NetlistError, match=message.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[").replace("]", r"\]")):
        model_class(_write(tmp_path, text), "VIN", "v(d)", name="netlist:test_l1_bad")()


OVERLAP_STAGE = """a level-1 NMOS stage whose only capacitances are its overlap capacitances
VIN in 0 DC 0.9
RG in g 50k
M1 d g s 0 mn w=20u l=2u
RS s 0 2k
RD dd d 20k
VDD dd 0 DC 5
.model mn nmos(level=1 vto=0.7 kp=110u lambda=0.04 cgso=0.5n cgdo=0.4n cgbo=0.2n)
"""


def test_overlap_capacitances_join_the_capacitance_matrix(tmp_path):
    """``cgso`` and ``cgdo`` times the width, ``cgbo`` times the length, from the gate to
    the source, drain and bulk: the gate, drain and source become states through them
    alone, the nodal capacitance matrix is theirs, and the static law (so the DC point) is
    that of the same device without them."""
    model = model_class(_write(tmp_path, OVERLAP_STAGE), "VIN", "v(d)",
                        name="netlist:test_l1_overlap")()
    assert model.state_names == ("v(d)", "v(g)", "v(s)")
    cgs, cgd, cgb = 0.5e-9 * 20e-6, 0.4e-9 * 20e-6, 0.2e-9 * 2e-6
    C = np.array([[cgd, -cgd, 0.0], [-cgd, cgs + cgd + cgb, -cgs], [0.0, -cgs, cgs]])
    np.testing.assert_allclose(np.linalg.inv(model.circuit.C_inv), C, rtol=1e-12, atol=1e-27)
    plain = OVERLAP_STAGE.replace(" cgso=0.5n cgdo=0.4n cgbo=0.2n", "").replace(
        "RD dd d 20k", "RD dd d 20k\nCD d 0 1p\nCG g 0 1p\nCS s 0 1p")
    other = model_class(_write(tmp_path, plain), "VIN", "v(d)", name="netlist:test_l1_no")()
    np.testing.assert_allclose(model.operating_point(u=[0.9]), other.operating_point(u=[0.9]),
                               rtol=1e-12)


def test_a_device_without_a_size_has_ngspices_default_width(tmp_path):
    """No ``w=``/``l=``: ngspice's 100 um by 100 um, so ``cgdo`` alone gives ``cgdo *
    1e-4`` from gate to drain."""
    text = ("m\nVIN in 0 DC 0.9\nRG in g 50k\nCG g 0 1p\nM1 d g 0 0 mn\nRD dd d 20k\n"
            "VDD dd 0 DC 5\n.model mn nmos(level=1 vto=0.7 cgdo=0.4n)\n")
    model = model_class(_write(tmp_path, text), "VIN", "v(d)", name="netlist:test_l1_w")()
    C = np.linalg.inv(model.circuit.C_inv)
    assert model.state_names == ("v(d)", "v(g)")
    np.testing.assert_allclose(C, [[4e-14, -4e-14], [-4e-14, 1e-12 + 4e-14]], rtol=1e-12,
                               atol=1e-27)


@NGSPICE
def test_overlap_capacitances_agree_with_ngspices_own_level_1(tmp_path):
    """ngspice's MOS1 with the same ``cgso cgdo cgbo`` (its Meyer capacitances zero without
    ``tox``): DC point, every state over a noisy 10 MHz sine (the gate's time constant some
    nanoseconds, the Miller capacitance among it) and the AC gain within estim spice's
    bars."""
    from ngspice_cases import outside_bars, sine_case

    model = model_class(_write(tmp_path, OVERLAP_STAGE), "VIN", "v(d)",
                        name="netlist:test_l1_overlap_ng")()
    rows = sine_case(model, 1e7, 1e-9, 200, 0.9, 0.03, 0.002, 3)
    assert not outside_bars(rows), outside_bars(rows)
    assert {r["check"] for r in rows} >= {"dc", "ac"}


def test_a_negative_overlap_capacitance_is_refused(tmp_path):
    text = ("m\nVIN g 0 DC 1\nRD dd d 10k\nVDD dd 0 DC 3\nCD d 0 1p\nM1 d g 0 0 mn\n"
            ".model mn nmos(level=1 vto=0.7 cgdo=-1n)\n")
    with pytest.raises(NetlistError, match="cgdo -1e-09; an overlap capacitance is not "
                                           "negative"):
        model_class(_write(tmp_path, text), "VIN", "v(d)", name="netlist:test_l1_neg")()


def test_an_input_at_a_gate_with_overlap_capacitance_is_refused_by_name(tmp_path):
    """An input source straight at the gate would drive it by its value (the device) and
    by its slope (the overlap capacitor): refused, naming the capacitance and its device."""
    text = ("m\nVIN g 0 DC 1\nRD dd d 10k\nVDD dd 0 DC 3\nCD d 0 1p\nM1 d g 0 0 mn\n"
            ".model mn nmos(level=1 vto=0.7 cgdo=1n)\n")
    with pytest.raises(NetlistError, match=r"m1.cgdo: input vin drives node g through "
                                           r"m1.cgdo \(an overlap capacitance of m1\) and "
                                           r"through m1; .* put a resistor between vin and "
                                           r"node g"):
        model_class(_write(tmp_path, text), "VIN", "v(d)", name="netlist:test_l1_gate")()
