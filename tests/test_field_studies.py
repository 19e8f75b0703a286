"""The sentences on the Chapter 5 field filter in docs/results.md and docs/deviations.md
D59-D61, checked against the stored tables (results/dipole_field and the studies of
configs/studies/)."""

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


def test_over_per_run_layouts_the_field_filter_fails_against_the_fit_in_the_far_zone():
    """D61 and docs/results.md: 10 runs per cell, each with its own layout. Family verdicts: the
    field filter against the fit fails in 9 cells (every far E_r, 3 far E_theta, 2 far
    H_phi), holds in none, and the 12 near-zone cells are undecided; against the open loop
    it holds in 19, fails in the 4 far E_r cells, and one (true source, near E_theta, sigma
    row 1) is undecided; against RLS and the raw sensor it holds in all 24; RLS against the
    raw sensor holds in 16 and fails in the 8 near E_theta and H_phi cells."""
    claims = pd.read_csv(RESULTS / "dipole_field" / "claims.csv")
    assert set(claims["runs"]) == {10}
    keys = claims["cell"].str.extract(r"zone=(\w+).*field_component=(\w+)")
    claims["where"] = keys[0] + " " + keys[1]

    def verdicts(claim: str) -> dict:
        c = claims[claims["claim"] == claim]
        return c.groupby(["verdict_family", "where"]).size().to_dict()

    assert verdicts("KF RMSE < amplitude-only fit RMSE") == {
        ("fails", "far E_r"): 4, ("fails", "far E_theta"): 3, ("fails", "far H_phi"): 2,
        ("undecided", "far E_theta"): 1, ("undecided", "far H_phi"): 2,
        ("undecided", "near E_r"): 4, ("undecided", "near E_theta"): 4,
        ("undecided", "near H_phi"): 4}
    plain = claims[claims["claim"] == "KF RMSE < plain simulation RMSE"]
    assert plain["verdict_family"].value_counts().to_dict() == {"holds": 19, "fails": 4,
                                                                "undecided": 1}
    assert set(plain[plain["verdict_family"] == "fails"]["where"]) == {"far E_r"}
    assert plain[plain["verdict_family"] == "undecided"]["cell"].item() == (
        "scenario=true source; zone=near; noise_reading=sigma; noise_param=0.00025; "
        "field_component=E_theta")
    for worse in ("RLS", "measurement"):
        assert (claims[claims["claim"] == f"KF RMSE < {worse} RMSE"]["verdict_family"]
                == "holds").all()
    rls = claims[claims["claim"] == "RLS RMSE < measurement RMSE"]
    assert rls["verdict_family"].value_counts().to_dict() == {"holds": 16, "fails": 8}
    assert set(rls[rls["verdict_family"] == "fails"]["where"]) == {"near E_theta",
                                                                   "near H_phi"}


def test_by_the_means_the_field_filter_is_below_the_fit_near_the_source_and_above_far():
    """D61: in the real part of rmse.csv the field filter is below the fit in near E_theta
    and near H_phi in every row (by 0.004-0.009 of the field RMS), within 0.003 of it in
    near E_r, above it in every far-zone row; below RLS and the raw sensor in all 72 rows;
    the source-only filter within 0.002 of the fit in all 72 (below it in some, above in
    others)."""
    df = _rmse()
    keys = ["scenario", "zone", "noise_reading", "noise_param", "field_component", "part"]
    p = df.pivot_table(index=keys, columns="estimator", values="relative").reset_index()
    assert len(p) == 72
    real = p[p["part"] == "real"]
    gap = real[KF] - real[FIT]
    near = real["zone"] == "near"
    for comp in ("E_theta", "H_phi"):
        assert (gap[near & (real["field_component"] == comp)] < 0).all()
    assert _span(-gap[near & (real["field_component"] != "E_r")], "0.004", "0.009")
    assert (gap[near & (real["field_component"] == "E_r")].abs() <= 0.003).all()
    assert (gap[~near] > 0).all()
    assert (p[KF] < p["RLS"]).all() and (p[KF] < p["measurement"]).all()
    so = p["KF (source only)"] - p[FIT]
    assert (so.abs() <= 0.002).all() and (so < 0).any() and (so > 0).any()


def test_at_10_percent_sensors_the_field_filter_is_below_the_fit_but_in_far_E_r():
    cells = {(z, c) for z in ("near", "far") for c in ("E_r", "E_theta", "H_phi")}
    assert _below_fit("field_sensors", 0.1) == cells - {("far", "E_r")}


def test_on_a_48_cube_grid_the_field_filter_is_below_the_fit_in_the_near_zone():
    assert {z for z, _ in _below_fit("field_grid", 48)} == {"near"}
    assert len(_below_fit("field_grid", 48)) == 3


# ----- docs/deviations/chapter-5.md D59-D61: every number quoted, against the stored tables

DOC = (RESULTS.parent / "docs" / "deviations" / "chapter-5.md").read_text()
D61 = DOC[DOC.index("**D61."):]
ESTIMATORS = (KF, "KF (source only)", FIT, "plain simulation", "RLS")


def _close(value: float, quoted: str) -> bool:
    """``value`` rounds to ``quoted`` (half a unit of its last digit)."""
    digits = quoted.split(".")[1] if "." in quoted else ""
    return abs(value - float(quoted)) <= 0.5 * 10 ** -len(digits) + 1e-12


def _span(values, low: str, high: str) -> bool:
    return _close(min(values), low) and _close(max(values), high)


def _rmse(name="dipole_field"):
    return pd.read_csv(RESULTS / name / "rmse.csv")


def test_d61_table_is_the_stored_table():
    df = _rmse()
    df = df[(df["noise_param"] == 0.00025) & (df["part"] == "real")]
    rows = [r for r in D61.splitlines() if r.startswith("| true source") or
            r.startswith("| wrong source")]
    assert len(rows) == 12
    symbols = {"E_r": "E_r", "E_θ": "E_theta", "H_φ": "H_phi"}
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        scenario = "true source" if cells[0].startswith("true") else "wrong source"
        zone = cells[1].split()[0]
        for est, quoted in zip(ESTIMATORS, cells[3:], strict=True):
            v = df[(df["scenario"] == scenario) & (df["zone"] == zone)
                   & (df["field_component"] == symbols[cells[2]])
                   & (df["estimator"] == est)]["relative"].item()
            assert _close(v, quoted), (row, est, v)
        source_only, fit = float(cells[4]), float(cells[5])
        assert abs(source_only - fit) <= 0.002


def test_d59_to_d61_quoted_numbers():
    df = _rmse()
    beta = dict(zip(df["zone"], df["beta_r"], strict=False))
    assert beta == {"near": "1.57-2.83", "far": "7.54-11.31"}
    real = df[df["part"] == "real"]
    true1 = real[(real["scenario"] == "true source") & (real["noise_param"] == 0.00025)]

    def rel(frame, est, zone, comp):
        return frame[(frame["estimator"] == est) & (frame["zone"] == zone)
                     & (frame["field_component"] == comp)]["relative"]

    floor = "plain simulation"
    # D59: the floor
    assert _close(100 * rel(true1, floor, "near", "E_r").item(), "33")
    assert _span(100 * pd.concat([rel(true1, floor, "near", c) for c in ("E_theta", "H_phi")]),
                 "15", "16")
    assert _close(100 * rel(true1, floor, "far", "E_r").item(), "42")
    assert _span(100 * pd.concat([rel(true1, floor, "far", c) for c in ("E_theta", "H_phi")]),
                 "15", "17")
    grid = _rmse("field_grid")
    grid = grid[(grid["part"] == "real") & (grid["estimator"] == floor)
                & (grid["zone"] == "far")]
    for comp, quoted in (("E_theta", ("52", "25", "15", "7.8")),
                         ("E_r", ("124", "64", "40", "25"))):
        values = grid[grid["field_component"] == comp].sort_values("value")["relative"]
        assert all(_close(100 * v, q) for v, q in zip(values, quoted, strict=True)), comp
    # D60: health, RLS against the raw sensor
    health = pd.read_csv(RESULTS / "dipole_field" / "health.csv")
    kf, so = (health[health["estimator"] == e] for e in (KF, "KF (source only)"))
    assert set(kf["effective_rank_min"]) == set(kf["effective_rank_max"]) == {49}
    assert set(so["effective_rank_min"]) == set(so["effective_rank_max"]) == {2}
    assert _span(kf["nis"], "1.00", "1.05") and _span(so["nis"], "0.200", "0.210")
    not_far_er = real[~((real["zone"] == "far") & (real["field_component"] == "E_r"))]
    assert _span(not_far_er[not_far_er["estimator"] == "RLS"]["relative"], "0.63", "0.91")
    assert _span(not_far_er[not_far_er["estimator"] == "measurement"]["relative"], "0.62",
                 "0.94")
    assert all(_close(v, "1.8") for v in rel(real, "RLS", "far", "E_r"))
    assert all(_close(v, "3.3") for v in rel(real, "measurement", "far", "E_r"))
    # D61: words around the claims
    wrong = real[real["scenario"] == "wrong source"]
    assert _span(wrong[wrong["estimator"] == floor]["relative"], "0.37", "0.50")
    far1 = true1[true1["zone"] == "far"]
    assert _span(far1[far1["estimator"] == FIT]["rmse"], "0.0014", "0.0019")
    assert _span(far1[far1["estimator"] == floor]["rmse"], "0.0014", "0.0043")
    near1 = true1[(true1["zone"] == "near") & true1["estimator"].isin([FIT, floor])]
    assert _span(near1["rmse"], "0.008", "0.023")


def test_d61_study_numbers():
    def cell(name, value, zone, comp, est):
        d = _rmse(name)
        return d[(d["value"] == value) & (d["part"] == "real") & (d["zone"] == zone)
                 & (d["field_component"] == comp) & (d["estimator"] == est)]["relative"].item()

    quoted = {("near", "E_r"): ("0.206", "0.232"), ("near", "E_theta"): ("0.144", "0.147"),
              ("near", "H_phi"): ("0.056", "0.068"), ("far", "E_theta"): ("0.066", "0.072"),
              ("far", "H_phi"): ("0.054", "0.059"), ("far", "E_r"): ("0.429", "0.419")}
    for (zone, comp), (ours, fit) in quoted.items():
        assert _close(cell("field_sensors", 0.1, zone, comp, KF), ours), (zone, comp)
        assert _close(cell("field_sensors", 0.1, zone, comp, FIT), fit), (zone, comp)
    assert len(_below_fit("field_sensors", 0.05)) == 4
    assert ("near", "E_theta") not in _below_fit("field_sensors", 0.05)
    for value, quoted_value in ((0.005, "0.116"), (0.02, "0.192"), (0.1, "0.144")):
        assert _close(cell("field_sensors", value, "near", "E_theta", KF), quoted_value)
    assert all(cell("field_sensors", v, "far", "E_r", KF) > cell("field_sensors", v, "far",
                                                                  "E_r", FIT)
               for v in (0.005, 0.01, 0.02, 0.05, 0.1))
    gaps = [cell("field_grid", n, "far", c, KF) - cell("field_grid", n, "far", c, FIT)
            for n in (24, 32, 48) for c in ("E_r", "E_theta", "H_phi")]
    assert min(gaps) > 0 and _span(gaps, "0.001", "0.033")
    assert all(cell("field_grid", 16, "far", c, KF) > cell("field_grid", 16, "far", c, FIT)
               for c in ("E_r", "E_theta", "H_phi"))
    for comp, ours, fit in (("E_r", "0.085", "0.086"), ("E_theta", "0.062", "0.066"),
                            ("H_phi", "0.032", "0.034")):
        assert _close(cell("field_grid", 48, "near", comp, KF), ours)
        assert _close(cell("field_grid", 48, "near", comp, FIT), fit)
    m = _rmse("field_members")
    k = m[m["estimator"] == KF].pivot_table(index=["zone", "field_component", "part"],
                                            columns="value", values="relative")
    spread = k.max(axis=1) - k.min(axis=1)
    assert _close(spread.max(), "0.019")
    assert _close(spread.xs("real", level="part").max(), "0.013")
    for value in (20, 100):
        assert _below_fit("field_members", value) <= _below_fit("field_members", 50)
    near = m[(m["part"] == "real") & (m["zone"] == "near")].pivot_table(
        index=["value", "field_component"], columns="estimator", values="relative")
    gap = (near[KF] - near[FIT]).unstack()
    assert (gap["E_r"] < 0).all() and (gap["E_theta"] > 0).all() and (gap["H_phi"] > 0).all()
    e_r = near.xs("E_r", level="field_component")
    assert _span(e_r[KF], "0.18", "0.19") and _span(e_r[FIT], "0.23", "0.23")
