"""A diode's junction capacitance (issue 47, item 4): SPICE's depletion and diffusion
capacitance as ``C(v)`` in the nodal capacitance matrix, the drift ``C(x)^-1`` times the
currents and its Jacobian, against ngspice's own diode; what it cannot take, refused."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from ngspice_cases import ngspice_op, outside_bars, sine_case
from test_level1 import OVERLAP_STAGE

from estim.spice import model_class
from estim.spice.devices import DIODE
from estim.spice.junctions import capacitance
from estim.spice.parser import NetlistError

ROOT_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "netlist" / "diode_clipper_ekf.yaml"
NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")
P = {**DIODE, "is": 2.52e-9, "n": 1.752, "cjo": 4e-12, "m": 0.4, "vj": 0.75, "tt": 20e-9}
CLIPPER = """a diode clipper whose only capacitances are its diodes'
VIN in 0 DC 0
R1 in a 10k
D1 a 0 dj
D2 0 a dj
RL a 0 100k
.model dj d(is=2.52n n=1.752 cjo=4p m=0.4 vj=0.75 tt=20n fc=0.5)
"""


def _jacobian_is_its_differences(model, z: np.ndarray, u: np.ndarray) -> None:
    """The drift's Jacobian at ``z`` against central differences of the drift."""
    _, J = model.f_and_jacobian(z, u)
    Jd = np.stack([(model.f(z + 1e-7 * e, u) - model.f(z - 1e-7 * e, u)) / 2e-7
                   for e in np.eye(len(z))], axis=-1)
    np.testing.assert_allclose(J, Jd, rtol=1e-5, atol=1e-6 * np.abs(J).max())


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "c.cir"
    path.write_text(text)
    return path


def test_the_capacitance_by_region():
    """Zero bias: ``cjo`` plus ``tt`` times the conductance there; below ``fc vj`` the
    depletion law, above it the linear continuation, which meets it in value and slope;
    the derivative against central differences everywhere, forward and reverse."""
    a = P["n"] * 0.025852
    assert capacitance(0.0, P)[0] == pytest.approx(4e-12 + 20e-9 * P["is"] / a, rel=1e-14)
    depl = {**P, "tt": 0.0}
    assert capacitance(-1.0, depl)[0] == pytest.approx(4e-12 * (1 + 1 / 0.75) ** -0.4,
                                                       rel=1e-14)
    knee = 0.5 * 0.75
    for k in (0, 1):
        below, above = (capacitance(knee + s * 1e-9, depl)[k] for s in (-1, 1))
        assert above == pytest.approx(below, rel=1e-6)
    v = np.linspace(-3, 0.8, 40)
    C, dC = capacitance(v, P)
    dCd = (capacitance(v + 1e-7, P)[0] - capacitance(v - 1e-7, P)[0]) / 2e-7
    np.testing.assert_allclose(dC, dCd, rtol=1e-6)


def test_the_drift_is_C_of_x_inverse_times_the_currents(tmp_path):
    """One node: ``v' = (u - v)/R1 - v/RL - i_D1(v) + i_D1(-v)) / (C_1(v) + C_2(-v))``; the
    Jacobian and the input Jacobian against differences; no compiled kernel (the numpy
    path carries ``C(x)``)."""
    from estim.spice.devices import diode

    model = model_class(_write(tmp_path, CLIPPER), "VIN", "v(a)", name="netlist:test_jc")()
    assert model.state_names == ("v(a)",) and model.kernel() is None
    p = {**P, "fc": 0.5}
    for v, u in ((0.3, 1.0), (-0.5, -2.0), (0.65, 3.0), (0.0, 0.0)):
        x, uu = np.array([v]), np.array([u])
        cur = (u - v) / 1e4 - v / 1e5 - diode(v, p)[0] + diode(-v, p)[0]
        f, J = model.f_and_jacobian(x, uu)
        assert f[0] == pytest.approx(cur / (capacitance(v, p)[0] + capacitance(-v, p)[0]),
                                     rel=1e-12)
        Jd = (model.f(x + 1e-7, uu) - model.f(x - 1e-7, uu)) / 2e-7
        np.testing.assert_allclose(J[0], Jd, rtol=1e-6)
        Bd = (model.f(x, uu + 1e-6) - model.f(x, uu - 1e-6)) / 2e-6
        np.testing.assert_allclose(model.input_jacobian(x, uu)[0], Bd, rtol=1e-6)


@NGSPICE
def test_the_clipper_agrees_with_ngspices_own_diode(tmp_path):
    """ngspice's diode with the same ``cjo m vj tt fc``: the DC point, the node over a
    noisy 1 MHz sine of 2 V (both diodes conduct in turn, and their diffusion capacitance,
    some picofarads, sets the clipped edges) and the AC gain within estim spice's bars."""
    model = model_class(_write(tmp_path, CLIPPER), "VIN", "v(a)", name="netlist:test_jc_ng")()
    # ngspice's truncation error shrinks with its reltol: started at 1e-9, where it is
    # within the bar (estim spice tightens to there from 1e-7)
    rows = sine_case(model, 1e6, 1e-8, 300, 0.0, 2.0, 0.01, 4, reltol=1e-9, tighten=0)
    assert not outside_bars(rows), outside_bars(rows)
    assert {r["check"] for r in rows} >= {"dc", "ac"}


@pytest.mark.parametrize("model_line, message", [
    (".model dj d(tt=1n)", "tt without cjo"),
    (".model dj d(cjo=-1p)", "cjo -1e-12; expected 0 or more"),
    (".model dj d(cjo=1p m=1)", "expected vj > 0, 0 <= m < 1, 0 <= fc < 1"),
    (".model dj d(cjo=1p vj=0)", "expected vj > 0, 0 <= m < 1, 0 <= fc < 1"),
])
def test_a_charge_estim_cannot_take_is_refused(tmp_path, model_line, message):
    text = f"j\nVIN in 0 DC 0\nR1 in a 1k\nD1 a 0 dj\n{model_line}\n"
    with pytest.raises(NetlistError, match=message):
        model_class(_write(tmp_path, text), "VIN", "v(a)", name="netlist:test_jc_bad")()


def test_a_junction_at_an_input_and_its_current_as_output_are_refused(tmp_path):
    """The charge current of a junction at the input's node would need the input's
    slope; ``i(D1)`` would be the static current only: both refused by name."""
    text = "j\nVIN in 0 DC 0\nR1 in a 1k\nD1 in a dj\nC1 a 0 1p\n.model dj d(cjo=1p)\n"
    with pytest.raises(NetlistError, match=r"d1.cjo: input vin drives node in through "
                                           r"d1.cjo \(a junction capacitance of d1\)"):
        model_class(_write(tmp_path, text), "VIN", "v(a)", name="netlist:test_jc_in")()
    with pytest.raises(NetlistError, match="d1 stores charge"):
        model_class(_write(tmp_path, CLIPPER), "VIN", "i(D1)", name="netlist:test_jc_i")()


def test_no_value_is_a_state_beside_a_junction_capacitance(tmp_path):
    """``estim settings`` lists nothing to estimate, and a config's ``estimate`` is refused
    at its key, where the circuit has a junction capacitance."""
    from click.testing import CliRunner

    from estim.cli.main import main
    from estim.spice.parameter_states import estimable

    model = model_class(_write(tmp_path, CLIPPER), "VIN", "v(a)", name="netlist:test_jc_e")()
    assert estimable(model) == []
    config = tmp_path / "c.yaml"
    config.write_text(ROOT_CONFIG.read_text().replace(
        "netlist: circuits/diode_clipper.cir", f"netlist: {tmp_path / 'c.cir'}")
        + "estimate:\n  - {name: R1, start: 1.0e+4, sigma0: 0.1, drift: 0.0}\n")
    result = CliRunner().invoke(main, ["validate", str(config)])
    assert result.exit_code != 0
    assert "estimate: d1.cjo is a junction capacitance" in result.output


MOS_STAGE = OVERLAP_STAGE.replace("whose only capacitances are its overlap capacitances",
                                  "with overlap and bulk junction capacitances only").replace(
    "cgbo=0.2n)", "cbd=50f cbs=30f\n+ pb=0.7 mj=0.45)")


def test_a_mosfets_bulk_junctions_are_the_depletion_law(tmp_path):
    """``cbd`` from bulk to drain and ``cbs`` from bulk to source, each by the diode's
    depletion law with ``pb`` and ``mj`` (no diffusion): at the DC point the capacitance
    matrix is the overlap one plus each junction's ``C(v_bulk - v_node)`` on its node."""
    from estim.spice.junctions import capacitance_matrix

    model = model_class(_write(tmp_path, MOS_STAGE), "VIN", "v(d)", name="netlist:test_jm")()
    assert model.state_names == ("v(d)", "v(g)", "v(s)") and model.kernel() is None
    x, u = model.operating_point(u=[0.9]), np.array([0.9])
    law = {"vj": 0.7, "m": 0.45, "fc": 0.5, "tt": 0.0}
    cbd = capacitance(-x[0], {**law, "cjo": 50e-15})[0]
    cbs = capacitance(-x[2], {**law, "cjo": 30e-15})[0]
    cgs, cgd = 0.5e-9 * 20e-6, 0.4e-9 * 20e-6
    C = np.array([[cgd + cbd, -cgd, 0.0], [-cgd, cgs + cgd, -cgs], [0.0, -cgs, cgs + cbs]])
    np.testing.assert_allclose(capacitance_matrix(model, model._node_voltages(x, u)), C,
                               rtol=1e-12, atol=1e-27)
    _jacobian_is_its_differences(model, x + 0.01, u)


@pytest.mark.parametrize("params, message", [
    ("cbd=-1f", "cbd -1e-15; expected 0 or more"),
    ("cbd=1f mj=1.2", "expected pb > 0, 0 <= mj < 1, 0 <= fc < 1"),
])
def test_a_bulk_junction_estim_cannot_take_is_refused(tmp_path, params, message):
    text = MOS_STAGE.replace("+ pb=0.7 mj=0.45)", f"+ {params})").replace("cbd=50f cbs=30f", "")
    with pytest.raises(NetlistError, match=message):
        model_class(_write(tmp_path, text), "VIN", "v(d)", name="netlist:test_jm_bad")()


def test_the_drain_current_of_a_mosfet_with_a_bulk_junction_is_refused(tmp_path):
    with pytest.raises(NetlistError, match=r"m1 stores charge \(m1.cbd\)"):
        model_class(_write(tmp_path, MOS_STAGE), "VIN", "id(M1)", name="netlist:test_jm_id")()


GP_STAGE = """a Gummel-Poon common-emitter stage, its junction capacitances and a load capacitor
* (the junctions alone join b, c and e to each other, not to ground: C would be singular)
VIN in 0 DC 0.8
RB in b 10k
Q1 c b e qn
RE e 0 100
RC vcc c 5k
CL c 0 2p
VCC vcc 0 DC 10
.model qn npn(is=1e-15 bf=120 br=2 cje=2p vje=0.7 mje=0.35 cjc=1p vjc=0.6 mjc=0.4
+ tf=0.3n tr=10n)
"""


def test_a_bjts_junctions_are_the_diodes_law(tmp_path):
    """Base to emitter ``cje vje mje`` and ``tf`` times the forward current's slope, base
    to collector ``cjc vjc mjc`` and ``tr`` times the reverse current's: at the DC point the
    capacitance matrix is theirs; the Jacobian against differences."""
    from estim.spice.junctions import capacitance_matrix

    model = model_class(_write(tmp_path, GP_STAGE), "VIN", "v(c)", name="netlist:test_jq")()
    assert model.state_names == ("v(b)", "v(c)", "v(e)")
    x, u = model.operating_point(u=[0.8]), np.array([0.8])
    vb, vc, ve = x
    be = capacitance(vb - ve, {**DIODE, "cjo": 2e-12, "vj": 0.7, "m": 0.35, "tt": 0.3e-9,
                               "is": 1e-15})[0]
    bc = capacitance(vb - vc, {**DIODE, "cjo": 1e-12, "vj": 0.6, "m": 0.4, "tt": 10e-9,
                               "is": 1e-15})[0]
    C = np.array([[be + bc, -bc, -be], [-bc, bc + 2e-12, 0.0], [-be, 0.0, be]])
    np.testing.assert_allclose(capacitance_matrix(model, model._node_voltages(x, u)), C,
                               rtol=1e-12, atol=1e-27)
    z = x + np.array([0.01, -0.2, 0.005])
    _jacobian_is_its_differences(model, z, u)


@pytest.mark.parametrize("params, message", [
    ("tr=1n", "tr without cjc"),
    ("cjc=1p mjc=1", "expected vjc > 0, 0 <= mjc < 1, 0 <= fc < 1"),
    ("cje=1p cjc=1p cjs=1p", "cjs: estim's Gummel-Poon is the static law, its junction "
                             "capacitances"),
])
def test_a_bjt_charge_estim_cannot_take_is_refused(tmp_path, params, message):
    text = GP_STAGE.split(".model")[0] + f".model qn npn(is=1e-15 bf=120 {params})\n"
    with pytest.raises(NetlistError, match=message):
        model_class(_write(tmp_path, text), "VIN", "v(c)", name="netlist:test_jq_bad")()


@pytest.mark.slow
@NGSPICE
def test_rs_behind_which_the_capacitance_sits_is_ngspices_internal_node(tmp_path):
    """A diode with ``rs`` and a junction capacitance: ``rs`` a resistor to the internal
    node ``d1.a``, a state; ngspice runs the netlist as written (its own ``rs`` and
    internal node): the clipped node over a noisy 1 MHz sine's first peak and trough
    within estim spice's transient bar of the node scale. Slow: the internal nodes' time
    constants are about a nanosecond, and the numpy path integrates them at rtol 1e-9."""
    from estim.engine.ngspice_check import BARS
    from estim.numerics.simulate import simulate
    from estim.spice import ngspice
    from estim.spice.parser import read

    text = CLIPPER.replace("tt=20n fc=0.5)", "tt=20n fc=0.5 rs=200)").replace(
        "RL a 0 100k", "RL a 0 100k\nCA a 0 1p")     # D2's junction alone: C singular
    path = _write(tmp_path, text)
    model = model_class(path, "VIN", "v(a)", name="netlist:test_jc_rs")()
    assert model.state_names == ("v(a)", "v(d1.a)", "v(d2.a)")
    dt = 1e-8
    t = np.arange(101) * dt
    rng = np.random.default_rng(8)
    source = 2.0 * np.sin(2e6 * np.pi * t) + 0.01 * rng.standard_normal(t.size)
    u = model.source_to_input(source[None, :, None], dt)[0]
    x0 = model.operating_point(u=source[:1])
    ours = np.vstack([x0, simulate(model, x0, u[None], dt, rtol=1e-9, atol=1e-12)[0]])
    theirs = ngspice.transient(read(path), t, ngspice.drive(model, source[:, None], t),
                               ["v(a)"], reltol=1e-9, max_step=dt / 4)
    scale = np.abs(theirs).max()
    assert np.abs(ours[:, 0] - theirs[:, 0]).max() / scale <= BARS["transient"]


@NGSPICE
def test_a_bjts_series_resistances_are_ngspices_internal_nodes(tmp_path):
    """``rb`` and ``re`` resistors to the internal nodes ``q1.b`` and ``q1.e`` (states
    through the junction capacitances; ``b`` and ``e`` none now): the DC point at two
    input levels equals that of ngspice's own BJT (its own series resistances, the netlist
    as written) to 1e-12 V at the external nodes; with ``rc`` too the three internal nodes
    meet capacitances only among themselves, and ``C`` is singular: refused, saying so."""
    with pytest.raises(NetlistError, match=r"q1.b, q1.c, q1.e .* internal nodes"):
        model_class(_write(tmp_path, GP_STAGE.replace(
            "+ tf=0.3n tr=10n)", "+ tf=0.3n tr=10n rb=200 rc=30 re=3)")), "VIN", "v(c)",
            name="netlist:test_jq_rc")()
    text = GP_STAGE.replace("+ tf=0.3n tr=10n)", "+ tf=0.3n tr=10n rb=200 re=3)")
    model = model_class(_write(tmp_path, text), "VIN", "v(c)", name="netlist:test_jq_r")()
    assert model.state_names == ("v(c)", "v(q1.b)", "v(q1.e)")   # b, e: solved (D71)
    for vin in (0.8, 0.9):
        theirs = ngspice_op(text.replace("DC 0.8", f"DC {vin}"), ("b", "c", "e"), tmp_path)
        V = model._node_voltages(model.operating_point(u=[vin]), np.array([vin]))
        for node, value in theirs.items():
            assert V[model._node[node]] == pytest.approx(value, abs=1e-12)


def test_a_series_resistance_without_a_capacitance_at_its_node_is_refused(tmp_path):
    text = GP_STAGE.replace("cje=2p vje=0.7 mje=0.35 ", "").replace(
        "+ tf=0.3n tr=10n)", "+ tr=10n re=3)")
    with pytest.raises(NetlistError, match=r"re without cje; its internal node \(q1\)"):
        model_class(_write(tmp_path, text), "VIN", "v(c)", name="netlist:test_jq_rbad")()


TRANSIT = GP_STAGE.replace("+ tf=0.3n tr=10n)",
                           "+ tf=0.3n tr=10n vaf=50 ikf=20m xtf=2 vtf=4 itf=0.1)")


def test_a_transit_charge_with_the_base_charge_is_a_transcapacitance(tmp_path):
    """Beside ``vaf ikf`` and ``xtf vtf itf`` the forward transit charge is a charge of
    ``v_BE`` and ``v_BC`` both: at a point of forward bias its slope in ``v_BC`` is not
    zero (its part of ``C`` in the collector's column), and the drift's Jacobian equals
    its differences."""
    from estim.spice.junctions import transit_charge

    model = model_class(_write(tmp_path, TRANSIT), "VIN", "v(c)", name="netlist:test_jt")()
    x, u = model.operating_point(u=[0.8]), np.array([0.8])
    j = next(j for j in model._junctions if j.grads.shape[0] == 2)
    V = model._node_voltages(x, u)
    v = np.array([V[a] - V[b] for a, b in j.nodes])
    slopes, _ = j.law(v)
    p = model.circuit.junctions[[c.name for c in model.circuit.junctions].index("q1.tf")].p
    for i in range(2):
        e = np.eye(2)[i] * 1e-6
        assert slopes[i] == pytest.approx((transit_charge(*(v + e), p)
                                           - transit_charge(*(v - e), p)) / 2e-6, rel=1e-6)
    assert abs(slopes[1]) > 1e-5 * abs(slopes[0]) > 0
    z = x + np.array([0.01, -0.2, 0.005])
    _jacobian_is_its_differences(model, z, u)


@pytest.mark.slow
@NGSPICE
@pytest.mark.parametrize("text, output, case", [
    (MOS_STAGE, "v(d)", (1e7, 1e-9, 200, 0.9, 0.03, 0.002, 5)),
    (GP_STAGE, "v(c)", (1e6, 1e-8, 200, 0.8, 0.01, 0.001, 6)),
    (TRANSIT, "v(c)", (1e6, 1e-8, 200, 0.8, 0.01, 0.001, 9)),
], ids=["mosfet bulk junctions", "bjt junctions", "bjt transit charge"])
def test_a_stage_agrees_with_ngspices_own_device(tmp_path, text, output, case):
    """ngspice's own MOS1 (its junction diodes off) and BJT with the same capacitances,
    transit times and, for the transit charge, ``vaf ikf xtf vtf itf``: the DC point, every
    state over a noisy sine (10 MHz at the MOSFET, 1 MHz at the BJT) and the AC gain within
    estim spice's bars. Slow: the numpy path integrates time constants down to some 80 ps
    at rtol 1e-10."""
    model = model_class(_write(tmp_path, text), "VIN", output, name="netlist:test_j_ng")()
    rows = sine_case(model, *case)
    assert not outside_bars(rows), outside_bars(rows)
    assert {r["check"] for r in rows} >= {"dc", "ac"}
