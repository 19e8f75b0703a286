"""The FIR differentiator paper: Table II's cells, the coefficients, the minimax facts."""

from fractions import Fraction

import numpy as np
import pytest

from estim import reference
from estim.numerics import fir_differentiators as fd


def test_n2_coefficients():
    c, d = fd.maximally_linear(2)
    assert c == [Fraction(-4, 3), Fraction(-1, 6)]
    assert d == [Fraction(9, 8), Fraction(1, 8)]


@pytest.mark.parametrize("n", [1, 2, 5, 10])
def test_relative_error_vanishes_at_pi(n):
    assert abs(fd.response(n, np.array([np.pi]))[0] - np.pi) < 1e-12


def test_every_numeric_n2_cell_of_table_ii():
    ref = reference.reference_table("fir_II")
    for _, row in ref.iterrows():
        got = fd.order_maximally_linear(row["omega_p"], row["threshold_db"])
        if np.isfinite(row["n2"]):
            assert got == row["n2"], row.to_dict()
        else:                                    # printed "> 22"
            assert got > 22


def test_minimax_full_band_facts():
    w = fd.band(0.0 + 1e-3, 4000)
    re = {taps: fd.relative_error_db(fd.minimax_response(fd.minimax_full_band(taps), w), w)
          for taps in (20, 22, 128)}
    assert re[20] == pytest.approx(-39.4, abs=0.1)
    assert re[22] == pytest.approx(-40.4, abs=0.1)
    assert re[128] == pytest.approx(-56.7, abs=0.2)     # -56.8 on this frequency grid
    assert fd.order_minimax(0.5, -60.0) is None          # "> 128"


def test_band_limited_minimax_of_the_same_structure_beats_the_maximally_linear_design():
    _, re_db = fd.minimax_band(2, 0.5)
    assert re_db == pytest.approx(-72.2, abs=0.5)
    w = fd.band(0.5)
    assert fd.relative_error_db(fd.response(2, w), w) == pytest.approx(-21.8, abs=0.2)
