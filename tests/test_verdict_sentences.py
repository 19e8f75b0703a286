"""Verdict counts quoted in docs/deviations.md (D36, D39, D50, D66) and docs/claims.md,
read back from the stored claims and health tables."""

from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
DOC = " ".join(" ".join(p.read_text() for p in (ROOT / "docs" / "deviations").glob("*.md"))
               .split())
CLAIMS_DOC = " ".join((ROOT / "docs" / "claims.md").read_text().split())


def claims(name: str) -> pd.DataFrame:
    return pd.read_csv(ROOT / "results" / name / "claims.csv")


def test_d36_the_amplifier_headline_in_the_noisy_rows():
    assert ("the headline claim holds in 8 of the 10 noisy-measurement rows (each cell alone "
            "and after Holm's correction)" in DOC and "median per-run ratio is 1.007" in DOC)
    df = claims("diffamp_ekf")
    rows = df[(df["claim"] == "EKF RMSE < RLS RMSE") & df["cell"].str.contains(
        "measurement=noisy;")]
    assert len(rows) == 10
    for column in ("verdict", "verdict_family"):
        assert (rows[column] == "holds").sum() == 8
    first = rows[rows["cell"].str.startswith("s_no=1;") & rows["cell"].str.contains("sigma")]
    second = rows[rows["cell"].str.startswith("s_no=2;") & rows["cell"].str.contains("sigma")]
    assert first["verdict"].item() == "fails" and second["verdict"].item() == "undecided"
    assert f"{second['ratio'].item():.3f}" == "1.007"


def test_d39_the_fitted_ekf_and_the_ukf_against_the_measurement():
    assert ("The fitted EKF beats the measurement in 11 of 12 rows and the UKF in all 12" in DOC
            and "median per-run ratios 0.951–0.992 and 0.992–0.999" in DOC)
    df = claims("mosfet_saturation")
    for label, holds, low, high in (("EKF (fitted Q)", 11, "0.951", "0.992"),
                                    ("UKF", 12, "0.992", "0.999")):
        rows = df[df["claim"] == f"{label} RMSE < measurement RMSE"]
        assert len(rows) == 12 and (rows["verdict"] == "holds").sum() == holds
        assert (f"{rows['ratio'].min():.3f}", f"{rows['ratio'].max():.3f}") == (low, high)


def test_d50_the_ekf_against_the_measurement_at_100_hz_variance_reading():
    assert ("worse in 6 cells and undecided in 2" in DOC
            and "worse in the four σ² = 0.0025 cells and undecided in the four σ² = 0.001"
            in DOC)
    df = claims("kronecker_table_4_2")
    rows = df[(df["claim"] == "EKF RMSE < measurement RMSE")
              & df["cell"].str.contains("noise_reading=variance")
              & df["cell"].str.contains("frequency_hz=100;")]     # W/L follow it
    assert len(rows) == 8
    assert (rows["verdict"] == "fails").sum() == 6 and (rows["verdict"] == "undecided").sum() == 2
    for level, verdict in (("0.0025", "fails"), ("0.001", "undecided")):
        part = rows[rows["cell"].str.contains(f"noise_param={level};")]
        assert len(part) == 4 and (part["verdict_family"] == verdict).all()
    assert (df[df["claim"] == "EKF RMSE < LMS RMSE"]["verdict"] == "holds").all()


def test_d66_the_input_derivative_cells():
    assert "these nine cells `fails` alone; after Holm's correction eight do" in DOC
    assert "better in 5 of those 9 cells alone and in 3 after Holm's correction" in DOC
    df = claims("mosfet_input_derivative")
    rows = df[df["worse"] == "EKF (difference)"]
    high = rows[rows["cell"].str.contains("noise_param=0.1;")]
    low = rows[rows["cell"].str.contains("noise_param=0.001;")]
    assert len(high) == len(low) == 9
    assert (high["verdict"] == "fails").sum() == 9
    assert (high["verdict_family"] == "fails").sum() == 8
    assert (low["verdict"] == "holds").sum() == 5
    assert (low["verdict_family"] == "holds").sum() == 3
    held = low[low["verdict_family"] == "holds"]
    assert held["cell"].str.endswith("frequency_hz=100").all()
    rls = df[(df["better"] == "EKF (difference)") & (df["worse"] == "RLS (difference)")]
    assert (rls[rls["cell"].str.contains("noise_param=0.1;")]["verdict_family"] == "holds").all()
    assert (rls[rls["cell"].str.contains("noise_param=0.001;")]["verdict"] == "undecided").all()


def test_claims_md_divergence_counts_of_the_stored_conduction_tables():
    """The stored counts the fragile-verdict section quotes (the other arithmetics' counts
    are the study's measurement, with its command)."""
    assert "150 of 360 runs as stored" in CLAIMS_DOC and "twin, 152," in CLAIMS_DOC
    for name, count in (("mosfet_conduction", 150), ("mosfet_netlist_conduction", 152)):
        health = pd.read_csv(ROOT / "results" / name / "health.csv")
        ekf = health[health["estimator"] == "EKF"]
        assert int(ekf["diverged"].sum()) == count and int(ekf["runs"].sum()) == 360


def test_the_stored_wall_times_name_every_result_folder():
    """results/wall_times.csv (bench/record_wall_times.py), which a fresh clone's reproduce,
    run and check read for their order and progress, has one positive wall time per stored
    result folder and no other."""
    import pandas as pd

    df = pd.read_csv(ROOT / "results" / "wall_times.csv")
    folders = {p.parent.name for p in (ROOT / "results").glob("*/manifest.json")}
    assert set(df["name"]) == folders and len(df) == len(folders)
    assert (df["wall_time_s"] > 0).all()
