import numpy as np
import pandas as pd

from core import tables


def rmse_rows(ekf, rls, ekf_diverged=0):
    base = {"table_id": "3.2", "s_no": 1, "noise_reading": "sigma", "noise_param": 0.25,
            "noise_sigma": 0.25, "frequency_hz": 100.0, "rmse_se": 0.0, "runs": 30}
    return pd.DataFrame([{**base, "estimator": "EKF", "rmse": ekf, "diverged": ekf_diverged},
                         {**base, "estimator": "RLS", "rmse": rls, "diverged": 0}])


def test_claim_holds_fails_on_divergence_and_is_na_without_values():
    assert bool(tables.claims(rmse_rows(0.3, 0.6))["holds"].iloc[0]) is True
    assert bool(tables.claims(rmse_rows(0.7, 0.6))["holds"].iloc[0]) is False
    assert bool(tables.claims(rmse_rows(0.3, 0.6, ekf_diverged=2))["holds"].iloc[0]) is False
    assert bool(tables.claims(rmse_rows(np.nan, 0.6, ekf_diverged=30))["holds"].iloc[0]) is False
    assert pd.isna(tables.claims(rmse_rows(0.3, np.nan))["holds"].iloc[0])


def test_with_thesis_puts_printed_value_and_ratio_beside_ours():
    out = tables.with_thesis(rmse_rows(0.2012, 0.6043), "rmse")
    assert list(out["thesis_rmse"]) == [0.4024, 0.6043]
    np.testing.assert_allclose(out["ratio_rmse"], [0.5, 1.0])


def test_thesis_tables_ship_with_the_package():
    t = tables.thesis_table("3.1")
    assert len(t) == 12 and set(t["estimator"]) == {"EKF", "RLS"}
