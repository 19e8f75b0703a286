"""Issue 47, item 8: the RMSE of every state against the actual circuit's (states.csv of an
estimation config), not only the measured output's."""

import estim


def test_states_csv_gives_every_states_rmse_and_the_measured_state_equals_rmse_csv(tmp_path):
    """states.csv (issue 47, item 8): one row per filter and state; on the rectifier, whose
    output is its one state, the state's RMSE is the output's (rmse.csv) to the last bit, and
    the RLS (no state estimate) has no rows."""
    spec = {"model": {"netlist": "circuits/rectifier.cir", "input": "VIN", "output": "v(out)"},
            "input": {"amplitude_v": 1.0, "bias_v": [0.5], "frequencies_hz": [50],
                      "samples_per_period": 20, "periods": 2},
            "noise": {"input_levels": [0.05], "measurement_sigma": 0.02},
            "estimators": [{"label": "EKF", "type": "ekf",
                            "settings": {"Q": 1.0e-4, "R": 4.0e-4, "P0": 1.0e-4}},
                           {"label": "RLS", "type": "rls"}],
            "monte_carlo": {"runs": 4, "seed": 1}, "tables": {"rmse": "ours"}}
    tables = estim.run(spec).tables
    states, rmse = tables["states"], tables["rmse"]
    assert list(states["estimator"]) == ["EKF"] and list(states["state"]) == ["v(out)"]
    ekf = rmse[rmse["estimator"] == "EKF"].iloc[0]
    for column in ("rmse", "rmse_se", "rmse_kept", "runs", "diverged"):
        assert states[column].iloc[0] == ekf[column], column
