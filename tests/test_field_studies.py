"""The README's sentences on the Chapter 5 field filter, checked against the stored tables
(results/dipole_field and the studies of configs/studies/)."""

from pathlib import Path

import pandas as pd

RESULTS = Path(__file__).resolve().parents[1] / "results"
KF, FIT = "KF", "amplitude-only fit"


def _below_fit(name: str, value=None, part: str = "real") -> set:
    df = pd.read_csv(RESULTS / name / "rmse.csv")
    if value is not None:
        df = df[df["value"] == value]
    df = df[(df["part"] == part) & df["estimator"].isin([KF, FIT])]
    p = df.pivot_table(index=["zone", "field_component"], columns="estimator", values="rmse")
    return {cell for cell, below in (p[KF] < p[FIT]).items() if below}


def test_at_2_percent_the_field_filter_beats_the_fit_only_in_near_E_r():
    claims = pd.read_csv(RESULTS / "dipole_field" / "claims.csv")
    held = claims[(claims["claim"] == "KF RMSE < amplitude-only fit RMSE")
                  & (claims["verdict"] == "holds")]
    assert len(held) == 12
    assert held["cell"].str.contains("zone=near").all()
    assert held["cell"].str.contains("field_component=E_r;").all()


def test_at_10_percent_sensors_the_field_filter_is_below_the_fit_but_in_far_E_r():
    cells = {(z, c) for z in ("near", "far") for c in ("E_r", "E_theta", "H_phi")}
    assert _below_fit("field_sensors", 0.1) == cells - {("far", "E_r")}


def test_on_a_48_cube_grid_the_field_filter_is_below_the_fit_in_the_near_zone():
    assert {z for z, _ in _below_fit("field_grid", 48)} == {"near"}
    assert len(_below_fit("field_grid", 48)) == 3
