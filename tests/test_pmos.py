"""PMOS devices in a netlist (issue 47, item 9): the NMOS law mirrored, in the numpy drift,
the compiled kernel and against ngspice."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from estim.spice import model_class

NGSPICE = pytest.mark.skipif(shutil.which("ngspice") is None,
                             reason="ngspice is not installed here (Debian: apt-get install "
                                    "ngspice); CI installs it")

STAGE = """common-source {kind} stage
VDD dd 0 DC {vdd}
VIN in 0 DC {vin}
RG in g 10k
CG g 0 1p
RD dd d 20k
CD d 0 1p
RB b 0 1meg
CB b 0 1p
M1 d g 0 b mk
.model mk {kind}(v_t0=0.5 eta=1.3 i_0=1e-7 w_l=10 law={law})
"""


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("law", [0, 1, 2, 3, 4])
def test_a_pmos_stage_is_the_nmos_stage_mirrored(tmp_path, law):
    """Every source of an NMOS stage negated and the NMOS made a PMOS of the same
    parameters: every node voltage is negated, ``f_p(-x, -u) = -f_n(x, u)``, the Jacobians
    are equal, the Hessians opposite and the DC points opposite, by every law; the compiled
    kernel gives the numpy drift."""
    from estim.numerics import kernels

    n_model = model_class(_write(tmp_path, "n.cir", STAGE.format(kind="nmos", vdd=3, vin=0.8,
                                                                law=law)),
                          "VIN", "v(d)", name=f"netlist:test_nstage{law}")()
    p_model = model_class(_write(tmp_path, "p.cir", STAGE.format(kind="pmos", vdd=-3,
                                                                vin=-0.8, law=law)),
                          "VIN", "v(d)", name=f"netlist:test_pstage{law}")()
    assert n_model.state_names == p_model.state_names
    rng = np.random.default_rng(law)
    for _ in range(5):
        x, u = rng.uniform(0, 2, n_model.n_states), rng.uniform(0.5, 1.2, 1)
        fn, Jn = n_model.f_and_jacobian(x, u)
        fp, Jp = p_model.f_and_jacobian(-x, -u)
        np.testing.assert_allclose(fp, -fn, rtol=1e-13, atol=1e-13 * np.abs(fn).max())
        np.testing.assert_allclose(Jp, Jn, rtol=1e-13, atol=1e-13 * np.abs(Jn).max())
        np.testing.assert_allclose(p_model.input_jacobian(-x, -u), n_model.input_jacobian(x, u),
                                   rtol=1e-13)
        np.testing.assert_allclose(p_model.hessian(-x, -u), -n_model.hessian(x, u),
                                   rtol=1e-12, atol=1e-12 * np.abs(n_model.hessian(x, u)).max())
        if kernels.AVAILABLE:
            kind, P = p_model.kernel()
            fk, Jk = np.empty(fp.size), np.empty(Jp.shape)
            kernels.evaluate(kind, -x, -u, P, fk, Jk)
            np.testing.assert_allclose(fk, fp, rtol=1e-12, atol=1e-12 * np.abs(fp).max())
            np.testing.assert_allclose(Jk, Jp, rtol=1e-12, atol=1e-12 * np.abs(Jp).max())
    np.testing.assert_allclose(p_model.operating_point(u=[-0.8]),
                               -n_model.operating_point(u=[0.8]), rtol=1e-9, atol=1e-12)


INVERTER = """CMOS inverter driving a capacitor, its input through an RC
VDD dd 0 DC 3
VIN in 0 DC 1.2
RG in g 10k
CG g 0 1p
MP o g dd dd pk
MN o g 0 0 nk
CO o 0 10p
.model nk nmos(v_t0=0.5 eta=1.3 i_0=1e-7 w_l=10)
.model pk pmos(v_t0=0.6 eta=1.4 i_0=5e-8 w_l=20)
"""


@NGSPICE
def test_a_cmos_inverter_agrees_with_ngspice(tmp_path):
    """An NMOS and a PMOS in one inverter, driven through a 1 kHz sine across its switching
    point: estim's DC point, both states over the run and the AC gain within estim spice's
    bars of ngspice's, where the PMOS is the B source of the mirrored law."""
    from estim.engine import ngspice_check as compare

    model = model_class(_write(tmp_path, "inv.cir", INVERTER), "VIN", "v(o)",
                        name="netlist:test_inverter")()
    dt = 1e-5
    t = np.arange(201) * dt
    rng = np.random.default_rng(11)
    source = 1.2 + 0.3 * np.sin(2e3 * np.pi * t) + 0.005 * rng.standard_normal(t.size)
    rows = compare._tightening("1 kHz", model, source[:, None], dt, 1e3, None, 1e-10, 1e-7, 2)
    o = model.state_names.index("v(o)")      # the input crosses the switching point
    assert model.operating_point(u=[0.9])[o] - model.operating_point(u=[1.5])[o] > 1.0
    bad = [r for r in rows if r["difference"] > compare.BARS[r["check"]]]
    assert not bad, bad
