"""The claims engine (estim.experiments.shared.claims): one rule for every table
(docs/claims.md)."""

from pathlib import Path

import numpy as np
import pytest

from estim.experiments.shared import claims
from estim.experiments.shared.claims import Losses


def signed(better_in: int, runs: int = 30, seed: int = 0):
    """Paired losses on the same draws where ``better`` has the smaller loss in exactly
    ``better_in`` of ``runs`` runs (every difference nonzero)."""
    rng = np.random.default_rng(seed)
    worse = 1.0 + 0.1 * rng.standard_normal(runs)
    size = 1e-3 * (1.0 + rng.uniform(size=runs))
    sign = np.where(np.arange(runs) < better_in, -1.0, 1.0)
    return Losses(worse + sign * size), Losses(worse)


def test_identical_errors_are_undecided():
    w = np.random.default_rng(1).uniform(0.5, 1.5, 30)
    out = claims.judge(Losses(w), Losses(w.copy()))
    assert out["verdict"] == "undecided" and out["method"] == "sign"
    assert out["difference"] == 0 and out["ratio"] == 1 and out["p_value"] == 1


@pytest.mark.parametrize("better_in, verdict", [(21, "holds"), (20, "undecided"),
                                                (10, "undecided"), (9, "fails"),
                                                (30, "holds"), (0, "fails")])
def test_the_verdict_is_the_sign_test_of_the_median(better_in, verdict):
    """With 30 runs the interval is [d_(10), d_(21)] (P(Binomial(30, 1/2) <= 9) = 2.1 %
    <= 2.5 % < P(<= 10) = 4.9 %): it lies below zero when 21 or more runs are better,
    above zero when 9 or fewer are; the p-value is the exact two-sided binomial one."""
    from scipy import stats

    better, worse = signed(better_in)
    out = claims.judge(better, worse)
    assert out["method"] == "sign" and out["verdict"] == verdict
    assert out["difference_low"] <= out["difference"] <= out["difference_high"]
    assert out["p_value"] == pytest.approx(stats.binomtest(better_in, 30, 0.5).pvalue,
                                           rel=1e-12)
    d = np.sort(better.values - worse.values)
    assert out["difference"] == pytest.approx(np.median(d))
    assert (out["difference_low"], out["difference_high"]) == (d[9], d[20])


def test_the_sign_interval_has_the_stated_coverage():
    """Over many pairs of draws with no true difference, the 95 % interval contains zero
    at least 95 % of the time: 1 - 2 P(Binomial(30, 1/2) <= 9) = 95.7 % exactly."""
    rng = np.random.default_rng(2)
    undecided = 0
    trials = 2000
    for _ in range(trials):
        w = rng.uniform(0.5, 1.5, 30)
        b = w + 0.05 * rng.standard_normal(30)
        undecided += claims.judge(Losses(b), Losses(w))["verdict"] == "undecided"
    assert 0.943 <= undecided / trials <= 0.971        # 95.7 % +- 3 binomial SD


def test_one_broken_run_does_not_change_the_question():
    """A cell with a divergence keeps the estimand: the median paired difference, by the
    same method; a diverged run counts as a loss larger than any finite one, so it moves the
    median by at most one order statistic and the medians of the losses stay finite."""
    better, worse = signed(25)
    whole = claims.judge(better, worse)
    flags = np.zeros(30, bool)
    flags[0] = True                                    # the best run of 'better' breaks
    broke = claims.judge(Losses(better.values, flags), worse)
    assert whole["method"] == broke["method"] == "sign"
    d = np.sort(better.values - worse.values)
    assert d[14] <= broke["difference"] <= d[16]
    assert np.isfinite(broke["loss_better"]) and broke["verdict"] == "holds"
    assert broke["loss_better"] == pytest.approx(np.median(np.where(flags, np.inf,
                                                                    better.values)))


def test_a_diverged_run_is_a_loss_for_its_filter_and_switches_to_the_sign_test():
    rng = np.random.default_rng(3)
    worse = Losses(1.0 + 0.1 * rng.standard_normal(30))
    better = Losses(worse.values - 0.2 + 0.01 * rng.standard_normal(30))   # better every run
    flags = np.zeros(30, bool)
    flags[:3] = True                                 # 3 of 30 runs of 'better' diverged
    out = claims.judge(Losses(better.values, flags), worse)
    assert out["method"] == "sign" and out["diverged_better"] == 3
    assert out["difference_high"] < 0 and out["verdict"] == "holds"   # 27 of 30 still better
    flags[:15] = True                                # half diverged: the median is a loss
    out = claims.judge(Losses(better.values, flags), worse)
    assert out["verdict"] != "holds"
    out = claims.judge(better, Losses(worse.values, np.ones(30, bool)))
    assert out["verdict"] == "holds" and out["ratio"] == 0


def test_a_broken_run_needs_no_flag_and_infinities_do_not_break_the_interval():
    b = np.full(30, 0.5)
    b[4] = np.inf
    out = claims.judge(Losses(b), Losses(np.full(30, 1.0)))
    assert out["method"] == "sign" and out["diverged_better"] == 1
    assert out["loss_better"] == 0.5 and out["verdict"] == "holds"
    assert np.isfinite(out["difference_low"]) and np.isfinite(out["difference_high"])


def test_too_few_runs_with_a_divergence_are_undecided():
    out = claims.judge(Losses([0.1, 0.1, 0.1], [True, False, False]), Losses([1.0, 1.0, 1.0]))
    assert out["method"] == "sign" and out["verdict"] == "undecided"
    assert claims.sign_interval_rank(5) == 0 and claims.sign_interval_rank(6) == 1


@pytest.mark.slow
def test_the_sign_rank_matches_scipy_stats():
    """The sign interval's rank is computed exactly (integer binomial sums): the same ranks
    as scipy.stats for every number of runs up to 400."""
    from scipy import stats

    for level in (0.9, 0.95, 0.99):
        for n in range(1, 401):
            tail, k = (1 - level) / 2, 0
            while k + 1 <= n // 2 + 1 and stats.binom.cdf(k, n, 0.5) <= tail:
                k += 1
            assert claims.sign_interval_rank(n, level) == k, (n, level)


def test_a_deterministic_value_is_judged_exactly_with_a_rounding_tie():
    def exact(a, b):
        return claims.judge(Losses([a]), Losses([b]), exact=True)

    assert exact(1.0, 2.0)["verdict"] == "holds"
    assert exact(2.0, 1.0)["verdict"] == "fails"
    tie = exact(1.0, 1.0 + 1e-12)
    assert tie["method"] == "exact" and tie["verdict"] == "undecided"
    assert exact(2.0, np.inf)["verdict"] == "holds"


@pytest.mark.parametrize("runs", [1, 3, 5])
def test_fewer_than_six_runs_decide_nothing_however_clear(runs):
    """Thin evidence: three runs that all agree give no 95 % interval of the median."""
    out = claims.judge(Losses(np.zeros(runs)), Losses(np.ones(runs)))
    assert out["method"] == "sign" and out["verdict"] == "undecided"
    assert out["p_value"] >= 2 * 0.5 ** runs


def test_table_judges_every_pair_in_every_cell_that_has_both():
    better, worse = signed(30)
    cells = [("a=1", {"EKF": better, "RLS": worse}), ("a=2", {"EKF": better})]
    df = claims.table(cells, [("EKF", "RLS")], "RMSE")
    assert list(df.columns) == claims.TABLE.columns
    assert df["cell"].tolist() == ["a=1"] and df["claim"].iloc[0] == "EKF RMSE < RLS RMSE"
    counted = claims.counts(df)
    assert counted.iloc[0][["holds", "fails", "undecided", "cells"]].tolist() == [1, 0, 0, 1]


def test_cell_names_its_keys_and_leaves_out_missing_ones():
    text = claims.cell(s_no=3, f=1000.0, x=None, y=float("nan"), reading="a, b")
    assert text == "s_no=3; f=1000; reading=a, b"
    assert claims.cell_keys(text) == {"s_no": "3", "f": "1000", "reading": "a, b"}


def test_a_perfect_baseline_gives_an_infinite_ratio_not_an_error():
    """A noise-free measurement has zero error: no filter beats it, and the ratio is inf."""
    out = claims.judge(Losses(np.full(8, 0.1) + np.arange(8) * 1e-3), Losses(np.zeros(8)))
    assert out["verdict"] == "fails" and out["ratio"] == np.inf


def test_holm_on_p_values_whose_answer_is_known():
    """Holm at family level 95 % over four p-values: thresholds 0.05/4, 0.05/3, 0.05/2,
    0.05/1 in ascending order; the step-down stops at the first p above its threshold
    (0.02 > 0.05/3), so 0.03 and 0.04 are not rejected though each is below 0.05 alone."""
    assert claims.holm([0.04, 0.001, 0.03, 0.02]).tolist() == [False, True, False, False]
    assert claims.holm([0.04, 0.001, 0.013, 0.02]).tolist() == [True] * 4
    assert claims.holm([0.01, 0.02]).tolist() == [True, True]           # 0.025 and 0.05
    assert claims.holm([]).tolist() == []
    assert claims.holm([0.5]).tolist() == [False]


def test_a_family_keeps_only_the_verdicts_holm_rejects(tmp_path):
    """Twelve cells each 'holding' at 95 % alone, eleven with 22 of 30 runs better (p =
    0.016 > 0.05 / 12), do not hold as a family; one with all 30 runs better does."""
    cells = []
    for i in range(12):
        better, worse = signed(30 if i == 0 else 22, seed=i)
        cells.append((claims.cell(s_no=i), {"a": better, "b": worse}))
    df = claims.table(cells, [("a", "b")], "RMSE")
    assert (df["verdict"] == "holds").all()
    assert (df["p_value"] < 0.05).all() and (df["p_value"].iloc[1:] > 0.05 / 12).all()
    assert df["verdict_family"].tolist() == ["holds"] + ["undecided"] * 11
    counted = claims.counts(df)
    assert counted.loc[0, ["holds", "fails", "undecided", "cells"]].tolist() == [1, 0, 11, 12]
    assert claims.counts(df, "verdict").loc[0, "holds"] == 12


def test_a_family_of_24_cells_needs_10_runs_that_all_agree():
    """docs/claims.md: over 24 cells Holm judges the first at 0.05 / 24; all 10 runs better
    (p = 2^-9) clear it, all 9 (p = 2^-8) do not, nor do 9 of 10."""
    def family(runs: int, better_runs: int):
        rng = np.random.default_rng(runs)
        cells = []
        for i in range(24):
            worse = rng.uniform(1.0, 2.0, runs)
            sign = np.where(np.arange(runs) < better_runs, -0.5, 0.5)
            cells.append((claims.cell(s_no=i), {"a": Losses(worse + sign),
                                                 "b": Losses(worse)}))
        return claims.table(cells, [("a", "b")], "RMSE")

    assert (family(10, 10)["verdict_family"] == "holds").all()
    assert family(10, 10)["p_value"].iloc[0] == pytest.approx(2.0 ** -9)
    assert (family(9, 9)["verdict_family"] == "undecided").all()
    assert (family(9, 9)["verdict"] == "holds").all()
    assert (family(10, 9)["verdict_family"] == "undecided").all()


def test_a_margin_of_practical_significance_makes_a_tiny_difference_a_tie():
    """A difference of about 0.15 % of the loss, better in every run, holds with no margin and
    is undecided with a 1 % margin; a 20 % difference holds with either."""
    small, base = signed(30)
    large = Losses(base.values * 0.8)
    df = claims.table([("x=1", {"a": small, "b": base}), ("x=2", {"a": large, "b": base})],
                      [("a", "b")], "RMSE")
    assert df["verdict_family"].tolist() == ["holds", "holds"]
    tied = claims.with_margin(df, 0.01)
    assert tied["verdict"].tolist() == ["undecided", "holds"]
    assert tied["verdict_family"].tolist() == ["undecided", "holds"]
    assert claims.with_margin(df, 0.0) is df


def test_p_values_match_scipy_stats_exact_sign_test():
    from scipy import stats

    signed = np.array([np.inf, 1.0, 2.0, -3.0, 0.0, 4.0, 5.0, np.inf])   # a tie left out
    assert claims.sign_p_value(signed) == pytest.approx(
        stats.binomtest(6, 7, 0.5).pvalue, rel=1e-12)
    better = claims.Losses(np.array([1.0, 1.0, 2.0, 1.0, 1.0, 1.0, 1.0]),
                           np.array([False] * 6 + [True]))
    worse = claims.Losses(np.full(7, 3.0))
    judged = claims.judge(better, worse)
    assert judged["method"] == "sign"
    assert judged["p_value"] == pytest.approx(stats.binomtest(1, 7, 0.5).pvalue, rel=1e-12)


def test_the_stored_tables_follow_the_thin_evidence_rule_the_docs_state():
    """docs/claims.md: fewer than six runs decide nothing; dipole_field and image_kalman run
    10 per cell, and a family verdict of dipole_field's means all 10 runs agreed. Read from
    results/."""
    import pandas as pd

    root = Path(__file__).resolve().parents[1] / "results"
    for path in root.glob("*/claims.csv"):
        df = pd.read_csv(path)
        thin = df[(df["method"] == "sign") & (df["runs"] < 6)]
        assert (thin["verdict"] == "undecided").all(), path
        assert set(df["method"]) <= {"sign", "exact"}, path
    field = pd.read_csv(root / "dipole_field" / "claims.csv")
    assert set(field["runs"]) == {10}
    decided = field[field["verdict_family"] != "undecided"]
    unanimous = np.isclose(decided["p_value"], 2.0 ** -9, rtol=1e-12, atol=0)
    assert len(decided) == 114 and unanimous.sum() == 113
    assert set(pd.read_csv(root / "image_kalman" / "claims.csv")["runs"]) == {10}


def test_a_config_claim_margin_reaches_the_claims_table():
    """``claim_margin`` of a config is applied by the runner: with a margin of half the worse
    loss a cell is decided only where its interval clears it; the differences stay."""
    import yaml

    from estim import api

    root = Path(__file__).resolve().parents[1]
    spec = yaml.safe_load((root / "configs" / "mosfet_saturation.yaml").read_text())
    spec["input"].update(frequencies_hz=[1000], periods=2)
    spec["noise"].update(input_levels=[0.01], readings=["sigma"])
    spec["figures"].update(noise_level=0.01)
    plain = api.run(spec, runs=8)
    assert (plain.claims["verdict"] != "undecided").any()
    wide = api.run(spec, runs=8, claim_margin=0.5)
    assert wide.claims["difference"].tolist() == plain.claims["difference"].tolist()
    assert (wide.claims["verdict"] == "undecided").sum() > (plain.claims["verdict"]
                                                            == "undecided").sum()
    for _, row in wide.claims.iterrows():      # decided only beyond half the worse loss
        tie = 0.5 * max(v for v in (row["loss_better"], row["loss_worse"]) if np.isfinite(v))
        assert (row["verdict"] == "undecided"
                or row["difference_high"] < -tie or row["difference_low"] > tie)
    assert set(wide.claims["verdict_family"]) <= {"undecided", *set(wide.claims["verdict"])}


def test_a_bad_claim_margin_is_one_line_naming_the_file_and_the_key(tmp_path):
    """claim_margin is a fraction in [0, 1): a word, a negative number or 1 exit 2 before
    any work, naming the file, the key and what was expected."""
    import yaml
    from click.testing import CliRunner

    from estim.cli.main import main

    root = Path(__file__).resolve().parents[1]
    spec = yaml.safe_load((root / "configs" / "mosfet_saturation.yaml").read_text())
    for value, expected in (("big", "expected a finite number"), (-0.1, "a number >= 0"),
                            (1.0, "a number < 1")):
        path = tmp_path / "margin.yaml"
        path.write_text(yaml.safe_dump({**spec, "claim_margin": value}))
        out = CliRunner().invoke(main, ["validate", str(path)])
        assert out.exit_code == 2
        (line,) = out.output.strip().splitlines()
        assert str(path) in line and "claim_margin" in line and expected in line, line
