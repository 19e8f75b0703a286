"""The claims engine (estim.experiments.shared.claims): one rule for every table
(docs/claims.md)."""

import numpy as np
import pytest

from estim.experiments.shared import claims
from estim.experiments.shared.claims import Losses


def paired(shift_in_se: float, runs: int = 30, seed: int = 0):
    """Losses of two estimators on the same draws whose paired difference has a sample mean
    of exactly ``shift_in_se`` of its own standard errors."""
    rng = np.random.default_rng(seed)
    worse = 1.0 + 0.1 * rng.standard_normal(runs)
    d = rng.standard_normal(runs)
    d = (d - d.mean()) / (d.std(ddof=1) / np.sqrt(runs))     # mean 0, SE 1
    better = worse + (d + shift_in_se) * 1e-3
    return Losses(better), Losses(worse)


def test_identical_errors_are_undecided():
    w = np.random.default_rng(1).uniform(0.5, 1.5, 30)
    out = claims.judge(Losses(w), Losses(w.copy()))
    assert out["verdict"] == "undecided" and out["method"] == "t"
    assert out["difference"] == 0 and out["ratio"] == 1


@pytest.mark.parametrize("shift, verdict", [(-3.0, "holds"), (3.0, "fails"), (0.5, "undecided"),
                                            (-0.5, "undecided")])
def test_a_difference_of_k_standard_errors(shift, verdict):
    better, worse = paired(shift)
    out = claims.judge(better, worse)
    assert out["method"] == "t"
    assert out["difference"] / out["difference_se"] == pytest.approx(shift)
    assert out["verdict"] == verdict
    assert out["difference_low"] < out["difference"] < out["difference_high"]


def test_the_t_interval_has_the_stated_coverage():
    """Over many pairs of draws with no true difference, the 95 % interval contains zero
    about 95 % of the time (so 'undecided' about 95 %)."""
    rng = np.random.default_rng(2)
    undecided = 0
    trials = 2000
    for _ in range(trials):
        w = rng.uniform(0.5, 1.5, 30)
        b = w + 0.05 * rng.standard_normal(30)
        undecided += claims.judge(Losses(b), Losses(w))["verdict"] == "undecided"
    assert 0.93 <= undecided / trials <= 0.97        # 95 % +- 4 binomial SD


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
    assert out["loss_better"] == np.inf and out["verdict"] == "holds"
    assert np.isfinite(out["difference_low"]) and np.isfinite(out["difference_high"])


def test_too_few_runs_with_a_divergence_are_undecided():
    out = claims.judge(Losses([0.1, 0.1, 0.1], [True, False, False]), Losses([1.0, 1.0, 1.0]))
    assert out["method"] == "sign" and out["verdict"] == "undecided"
    assert claims.sign_interval_rank(5) == 0 and claims.sign_interval_rank(6) == 1


def test_the_sign_rank_and_the_t_quantile_match_scipy_stats():
    """The sign interval's rank is computed exactly (integer binomial sums) and the t
    quantile with scipy.special.stdtrit, scipy.stats.t.ppf's own computation: the same
    ranks and quantiles as scipy.stats for every number of runs up to 400."""
    from scipy import stats

    for level in (0.9, 0.95, 0.99):
        for n in range(1, 401):
            tail, k = (1 - level) / 2, 0
            while k + 1 <= n // 2 + 1 and stats.binom.cdf(k, n, 0.5) <= tail:
                k += 1
            assert claims.sign_interval_rank(n, level) == k, (n, level)
            expected = float(stats.t.ppf(0.5 + level / 2, n - 1)) if n > 1 else float("inf")
            assert claims.t_quantile(n, level) == expected, (n, level)


def test_a_deterministic_value_is_judged_exactly_with_a_rounding_tie():
    def exact(a, b):
        return claims.judge(Losses([a]), Losses([b]), exact=True)

    assert exact(1.0, 2.0)["verdict"] == "holds"
    assert exact(2.0, 1.0)["verdict"] == "fails"
    tie = exact(1.0, 1.0 + 1e-12)
    assert tie["method"] == "exact" and tie["verdict"] == "undecided"
    assert exact(2.0, np.inf)["verdict"] == "holds"


def test_a_single_random_run_decides_nothing():
    out = claims.judge(Losses([1.0]), Losses([2.0]))
    assert out["method"] == "t" and out["verdict"] == "undecided"


def test_table_judges_every_pair_in_every_cell_that_has_both():
    better, worse = paired(-3.0)
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
    out = claims.judge(Losses(np.full(5, 0.1) + np.arange(5) * 1e-3), Losses(np.zeros(5)))
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
    """Twelve cells each 'holding' at 95 % alone by a difference of 2.3 standard errors (p
    about 0.03 with 30 runs) do not hold as a family; one 6-SE cell among them does."""
    rng = np.random.default_rng(5)
    cells = []
    for i in range(12):
        noise = rng.standard_normal(30)
        noise = (noise - noise.mean()) / noise.std(ddof=1)          # exactly mean 0, SD 1
        shift = 6.0 if i == 0 else 2.3
        worse = 10.0 + rng.standard_normal(30)
        better = worse - shift / np.sqrt(30) + noise
        cells.append((claims.cell(s_no=i), {"a": claims.Losses(better),
                                            "b": claims.Losses(worse)}))
    df = claims.table(cells, [("a", "b")], "RMSE")
    assert (df["verdict"] == "holds").all()
    assert (df["p_value"] < 0.05).all() and (df["p_value"].iloc[1:] > 0.05 / 12).all()
    assert df["verdict_family"].tolist() == ["holds"] + ["undecided"] * 11
    counted = claims.counts(df)
    assert counted.loc[0, ["holds", "fails", "undecided", "cells"]].tolist() == [1, 0, 11, 12]
    assert claims.counts(df, "verdict").loc[0, "holds"] == 12


def test_p_values_match_scipy_stats_and_the_exact_sign_test():
    from scipy import stats

    d = np.array([0.3, -0.1, 0.5, 0.2, 0.4, -0.2, 0.6, 0.1])
    se = d.std(ddof=1) / np.sqrt(d.size)
    assert claims.t_p_value(d.mean(), se, d.size) == pytest.approx(
        stats.ttest_1samp(d, 0.0).pvalue, rel=1e-12)
    signed = np.array([np.inf, 1.0, 2.0, -3.0, 0.0, 4.0, 5.0, np.inf])   # a tie left out
    assert claims.sign_p_value(signed) == pytest.approx(
        stats.binomtest(6, 7, 0.5).pvalue, rel=1e-12)
    better = claims.Losses(np.array([1.0, 1.0, 2.0, 1.0, 1.0, 1.0, 1.0]),
                           np.array([False] * 6 + [True]))
    worse = claims.Losses(np.full(7, 3.0))
    judged = claims.judge(better, worse)
    assert judged["method"] == "sign"
    assert judged["p_value"] == pytest.approx(stats.binomtest(1, 7, 0.5).pvalue, rel=1e-12)
