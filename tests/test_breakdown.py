"""A diode's breakdown (issue 47, item 4): ngspice's fit of the breakdown voltage to
``bv`` and ``ibv``, the law below it, and a zener regulator against ngspice's own diode."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest
from ngspice_cases import ngspice_op, outside_bars, sine_case

from estim.spice import model_class
from estim.spice.devices import DIODE_VT, diode, diode_params, diode_slope
from estim.spice.parser import NetlistError

NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")
REGULATOR = """a zener regulator
VIN in 0 DC 8
R1 in a 1k
DZ 0 a dz
CA a 0 10n
RL a 0 10k
.model dz d(is=1e-14 n=1 rs=2 bv=5.6 ibv=5m nbv=1.5)
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "z.cir"
    path.write_text(text)
    return path


def test_the_fitted_breakdown_passes_ibv_at_bv():
    """``xbv`` puts the current at ``v = -bv`` at ``ibv`` (within ngspice's default reltol of
    it, as its fit stops), so below ``bv`` by ``nbv V_T ln(ibv / is)`` or so; with an
    ``ibv`` under ``is bv / V_T`` it is ``bv`` itself; ``nbv`` defaults to ``n``."""
    p = diode_params({"is": 1e-14, "bv": 5.6, "ibv": 5e-3, "nbv": 1.5})
    assert diode(-5.6, p)[0] == pytest.approx(-5e-3, rel=1e-3)
    assert p["xbv"] == pytest.approx(5.6 - 1.5 * DIODE_VT * math.log(5e-3 / 1e-14), abs=1e-3)
    assert diode_params({"is": 1e-14, "bv": 5.6, "ibv": 1e-13})["xbv"] == 5.6
    assert (diode_params({"is": 1e-14, "n": 1.5, "bv": 5.6})["xbv"]
            == diode_params({"is": 1e-14, "n": 1.5, "bv": 5.6, "nbv": 1.5})["xbv"])


@pytest.mark.parametrize("rs", [0.0, 5.0])
def test_the_law_below_the_breakdown(rs):
    """Below ``-xbv`` (at the junction, ``v - rs i``): ``-is exp(-(xbv + v_j)/(nbv V_T))``;
    the conductance and its slope against differences of the current and the conductance,
    forward, reverse and in breakdown (away from the regions' edges)."""
    p = {**diode_params({"is": 1e-14, "bv": 5.6, "ibv": 5e-3, "nbv": 1.5}), "rs": rs}
    i, _ = diode(-6.5, p)
    vj = -6.5 - rs * float(i)
    assert float(i) == pytest.approx(-1e-14 * math.exp(-(p["xbv"] + vj) / (1.5 * DIODE_VT)),
                                     rel=1e-12)
    for v in (-7.0, -6.0, -4.0, -1.0, 0.5, 0.7):
        cur, g = diode(v, p)
        gd = (diode(v + 1e-7, p)[0] - diode(v - 1e-7, p)[0]) / 2e-7
        dg = diode_slope(v, float(cur), float(g), p)
        dgd = (diode(v + 1e-7, p)[1] - diode(v - 1e-7, p)[1]) / 2e-7
        assert float(g) == pytest.approx(float(gd), rel=1e-6, abs=1e-22)
        assert dg == pytest.approx(float(dgd), rel=1e-5, abs=1e-20)


@NGSPICE
def test_the_regulators_dc_point_is_ngspices_own(tmp_path):
    """ngspice's own diode with the same ``bv ibv nbv`` (its own fit, at reltol 1e-9): the
    DC point at three input levels, in and out of breakdown, to 1e-13 V."""
    model = model_class(_write(tmp_path, REGULATOR), "VIN", "v(a)", name="netlist:test_zener")()
    assert model.kernel() is None
    for vin in (3.0, 8.0, 12.0):
        theirs = ngspice_op(REGULATOR.replace("DC 8", f"DC {vin}"), ("a",), tmp_path)
        assert model.operating_point(u=[vin])[0] == pytest.approx(theirs["a"], abs=1e-13)


@pytest.mark.slow
@NGSPICE
def test_the_regulator_agrees_with_ngspice_over_time(tmp_path):
    """Every state over a noisy 1 kHz sine into breakdown and the AC gain within estim
    spice's bars (slow: estim's integrator at rtol 1e-10 on the numpy path)."""
    model = model_class(_write(tmp_path, REGULATOR), "VIN", "v(a)",
                        name="netlist:test_zener_t")()
    rows = sine_case(model, 1e3, 1e-5, 200, 8.0, 3.0, 0.05, 7)
    assert not outside_bars(rows), outside_bars(rows)


@pytest.mark.parametrize("params, message", [
    ("bv=-5", "bv -5, ibv 0.001, nbv 0; expected bv > 0, ibv > 0, nbv >= 0"),
    ("bv=5 ibv=0", "expected bv > 0, ibv > 0, nbv >= 0"),
])
def test_a_bad_breakdown_is_refused(tmp_path, params, message):
    text = REGULATOR.replace("rs=2 bv=5.6 ibv=5m nbv=1.5", params)
    with pytest.raises(NetlistError, match=message):
        model_class(_write(tmp_path, text), "VIN", "v(a)", name="netlist:test_zener_bad")()


def test_a_breaking_diodes_parameters_cannot_be_states(tmp_path):
    from estim.spice.parameter_states import estimable, value_of

    model = model_class(_write(tmp_path, REGULATOR), "VIN", "v(a)",
                        name="netlist:test_zener_ps")()
    assert not any(name.startswith("DZ.") for name in estimable(model))
    with pytest.raises(ValueError, match="DZ breaks down"):
        value_of(model, "DZ.is")
