"""Aggregation across repetitions: mean, sample std, Student-t confidence intervals per group."""

import doctest
import math

import numpy as np
import pytest
from scipy import stats as st

import planners.stats as ps
from planners.stats import aggregate, summarize, table_rows


def test_docstring_examples():
    assert doctest.testmod(ps).failed == 0


def test_summary_hand_computed():
    s = summarize([1.0, 2.0, 3.0, 4.0])
    std = math.sqrt(5 / 3)  # squared deviations 2.25 + 0.25 + 0.25 + 2.25 over n - 1 = 3
    half = 3.182446305284263 * std / 2  # t(0.975, 3) * std / sqrt(4)
    assert s["n"] == 4 and s["mean"] == 2.5 and s["confidence"] == 0.95
    assert s["std"] == pytest.approx(std, rel=1e-12)
    assert s["ci_low"] == pytest.approx(2.5 - half, rel=1e-12)
    assert s["ci_high"] == pytest.approx(2.5 + half, rel=1e-12)


def test_summary_matches_scipy_on_random_samples():
    rng = np.random.default_rng(0)
    for n in (2, 3, 10, 50):
        x = rng.normal(3.0, 0.5, size=n)
        for c in (0.9, 0.95, 0.99):
            s = summarize(x, confidence=c)
            lo, hi = st.t.interval(c, n - 1, loc=x.mean(), scale=st.sem(x))
            assert s["ci_low"] == pytest.approx(lo, rel=1e-12)
            assert s["ci_high"] == pytest.approx(hi, rel=1e-12)


def test_summary_edge_cases():
    assert summarize([]) == {"n": 0, "mean": None, "std": None, "ci_low": None, "ci_high": None, "confidence": 0.95}
    one = summarize([2.5])
    assert one["n"] == 1 and one["mean"] == 2.5 and one["std"] is None and one["ci_low"] is None
    same = summarize([0.7, 0.7, 0.7])
    assert same["std"] == pytest.approx(0, abs=1e-15)
    assert same["ci_low"] == pytest.approx(0.7) and same["ci_high"] == pytest.approx(0.7)
    # None, NaN and inf are left out; bools are 0/1 (a rate)
    assert summarize([1.0, None, float("nan"), float("inf"), 3.0])["mean"] == 2.0
    assert summarize([True, False, False, True])["mean"] == 0.5
    with pytest.raises(ValueError, match="`confidence` must be in"):
        summarize([1, 2], confidence=1.0)
    with pytest.raises(ValueError, match="`confidence` must be a number"):
        summarize([1, 2], confidence="high")


def runs():
    rows = []
    for planner, base in (("fmm", 2.0), ("prm", 2.4)):
        for mode, factor in (("sim", 1.0), ("twb", 1.05)):
            for rep in range(5):
                rows.append({
                    "planner": planner, "mode": mode, "repetition": rep,
                    "length_m": base * factor + 0.01 * rep, "collided": rep == 4 and mode == "twb",
                    "clearance_min_m": None if rep == 0 else 0.05, "goal_reached": True,
                    "planned": {"length_m": base},  # nested: not aggregated
                    "status": "completed",
                })
    return rows


def test_aggregate_per_planner_and_mode():
    groups = aggregate(runs())
    assert [(g["planner"], g["mode"]) for g in groups] == [("fmm", "sim"), ("fmm", "twb"), ("prm", "sim"), ("prm", "twb")]
    g = groups[1]
    assert g["runs"] == 5
    assert list(g["metrics"]) == ["repetition", "length_m", "collided", "clearance_min_m", "goal_reached"]
    length = g["metrics"]["length_m"]
    assert length["mean"] == pytest.approx(2.1 + 0.02)
    assert length["std"] == pytest.approx(np.std([0.0, 0.01, 0.02, 0.03, 0.04], ddof=1))
    assert g["metrics"]["collided"]["mean"] == pytest.approx(0.2)  # collision rate
    assert g["metrics"]["clearance_min_m"]["n"] == 4  # the None is left out
    assert groups[0]["metrics"]["collided"]["mean"] == 0


def test_aggregate_with_chosen_keys_and_metrics():
    groups = aggregate(runs(), by=("mode",), metrics=["length_m", "missing"], confidence=0.9)
    assert [g["mode"] for g in groups] == ["sim", "twb"]
    assert groups[0]["runs"] == 10 and groups[0]["metrics"]["length_m"]["confidence"] == 0.9
    assert groups[0]["metrics"]["missing"]["n"] == 0
    rows = table_rows(groups)
    assert len(rows) == 4
    assert rows[0] == {"mode": "sim", "runs": 10, "metric": "length_m", **groups[0]["metrics"]["length_m"]}
    # a record without a group key lands in the None group
    assert aggregate([{"length_m": 1.0}])[0]["planner"] is None


def test_aggregate_bad_arguments():
    with pytest.raises(ValueError, match="`by` must be a sequence of key names"):
        aggregate(runs(), by="planner")
    with pytest.raises(ValueError, match=r"`records\[1\]` must be a mapping"):
        aggregate([{"a": 1}, [1, 2]])
    with pytest.raises(ValueError, match="`confidence` must be in"):
        aggregate(runs(), confidence=0)


# ----------------------------------------------------------------------------- comparisons

from planners.stats import MIN_BOOTSTRAP, compare_means, compare_rates, holm, proportion  # noqa: E402


def test_fisher_for_none_of_five_against_all_five():
    r = compare_rates(0, 5, 5, 5)
    assert r.test == "fisher-exact" and r.pvalue == pytest.approx(2 / 252) and round(r.pvalue, 4) == 0.0079
    assert r.difference == -1.0 and r.effect == "risk-difference" and r.effect_size == -1.0
    assert r.statistic == 0.0  # the sample odds ratio
    lo, hi = r.confidence_interval()
    # Newcombe's hybrid score interval from the two Wilson intervals (0/5: [0, 0.43]; 5/5: [0.57, 1])
    w = proportion(5, 5)
    assert lo == -1.0 and hi == pytest.approx(-1 + math.sqrt(2) * (1 - w["ci_low"]))
    assert hi < 0  # excludes 0: 0/5 is worse than 5/5, beyond chance
    assert compare_rates(0, 5, 5, 5, alternative="less").pvalue == pytest.approx(1 / 252)
    same = compare_rates(3, 5, 3, 5)
    assert same.pvalue == 1.0 and same.difference == 0.0
    none = compare_rates(0, 0, 2, 2)
    assert math.isnan(none.pvalue) and "without runs" in none.note and math.isnan(none.confidence_interval().low)
    with pytest.raises(ValueError, match="`k_a` must be in 0..n_a"):
        compare_rates(6, 5, 1, 5)


def test_newcombe_interval_matches_its_definition():
    r = compare_rates(8, 10, 3, 10)
    pa, pb = proportion(8, 10), proportion(3, 10)
    d = 0.5
    lo = d - math.sqrt((0.8 - pa["ci_low"]) ** 2 + (pb["ci_high"] - 0.3) ** 2)
    hi = d + math.sqrt((pa["ci_high"] - 0.8) ** 2 + (0.3 - pb["ci_low"]) ** 2)
    assert r.confidence_interval() == pytest.approx((lo, hi))
    assert r.confidence_interval(0.9).high < hi


def test_holm_hand_checked():
    # sorted: 0.005 x 4 = 0.02; 0.01 x 3 = 0.03; 0.03 x 2 = 0.06; 0.04 x 1 = 0.04 -> running max 0.06
    assert holm([0.01, 0.04, 0.03, 0.005]).tolist() == [0.03, 0.06, 0.06, 0.02]
    out = holm([0.2, None, float("nan"), 0.01])  # untested entries are not in the family (m = 2)
    assert out[0] == pytest.approx(0.2) and out[3] == pytest.approx(0.02) and np.isnan(out[1]) and np.isnan(out[2])
    assert holm([0.6, 0.7]).tolist() == [1.0, 1.0]  # clipped at 1
    assert holm([]).size == 0
    with pytest.raises(ValueError, match="must be in"):
        holm([1.5])


def test_holm_is_the_step_down_procedure():
    """Rejecting where the adjusted p <= alpha is exactly Holm's sequential procedure, at every alpha."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        p = rng.uniform(0, 0.2, size=rng.integers(1, 9))
        adjusted = holm(p)
        order = np.argsort(p)
        for alpha in (0.01, 0.05, 0.1):
            rejected = set()
            for i, j in enumerate(order):  # step down: stop at the first that fails
                if p[j] > alpha / (len(p) - i):
                    break
                rejected.add(int(j))
            assert {int(j) for j in np.flatnonzero(adjusted <= alpha)} == rejected


def test_welch_and_paired_t_are_scipys():
    rng = np.random.default_rng(5)
    a, b = rng.normal(1.0, 0.1, 8), rng.normal(1.1, 0.2, 6)
    r = compare_means(a, b)
    ref = st.ttest_ind(a, b, equal_var=False)
    assert r.test == "welch-t" and not r.paired
    assert (r.statistic, r.pvalue) == pytest.approx((ref.statistic, ref.pvalue))
    assert r.difference == pytest.approx(a.mean() - b.mean()) and (r.n_a, r.n_b) == (8, 6)
    sp = math.sqrt((7 * a.var(ddof=1) + 5 * b.var(ddof=1)) / 12)
    assert r.effect == "hedges-g" and r.effect_size == pytest.approx((1 - 3 / (4 * 14 - 9)) * (a.mean() - b.mean()) / sp)
    lo, hi = r.confidence_interval()
    assert lo < r.difference < hi
    b2 = a + rng.normal(0.05, 0.02, 8)
    p = compare_means(a, b2, paired=True)
    ref = st.ttest_rel(a, b2)
    assert p.test == "paired-t" and p.paired and (p.statistic, p.pvalue) == pytest.approx((ref.statistic, ref.pvalue))
    d = a - b2
    assert p.effect == "cohen-dz" and p.effect_size == pytest.approx(d.mean() / d.std(ddof=1))
    # pairing removes the shared variation: a much narrower interval than unpaired
    assert np.ptp(p.confidence_interval()) < 0.5 * np.ptp(compare_means(a, b2).confidence_interval())
    rank = compare_means(a, b, test="rank")
    assert rank.test == "mann-whitney-u" and rank.pvalue == pytest.approx(st.mannwhitneyu(a, b).pvalue)
    assert compare_means(a, b2, paired=True, test="rank").test == "wilcoxon"


def test_bootstrap_is_seeded_and_levels_nest():
    rng = np.random.default_rng(8)
    a, b = rng.normal(0, 1, 10), rng.normal(0.5, 1, 10)
    r1, r2 = compare_means(a, b, seed=4), compare_means(a, b, seed=4)
    assert r1.confidence_interval() == r2.confidence_interval()
    lo90, hi90 = r1.confidence_interval(0.9)
    lo95, hi95 = r1.confidence_interval()
    assert lo95 < lo90 < hi90 < hi95
    lo, hi = compare_means(a, b, alternative="less").confidence_interval()
    assert lo == -math.inf and math.isfinite(hi)


@pytest.mark.parametrize("paired", [False, True])
def test_bootstrap_interval_covers_the_true_difference_at_about_the_nominal_rate(paired):
    """200 synthetic studies of 8 runs a side (skewed noise, unequal spreads): the 95% interval covers the true
    difference 90-99 % of the time (BCa and the percentile interval cover only 82-89 % at this size)."""
    rng = np.random.default_rng(2024)
    true, hits = -0.3, 0
    for i in range(200):
        b = 1.0 + rng.exponential(0.2, 8)
        if paired:
            a = b + true + rng.normal(0, 0.1, 8)
        else:  # b's noise is skewed with mean 0.2: mean(a) - mean(b) = true
            a = 1.2 + true + rng.normal(0, 0.05, 8)
        lo, hi = compare_means(a, b, paired=paired, n_resamples=1999, seed=i).confidence_interval()
        hits += lo <= true <= hi
    assert 0.90 <= hits / 200 <= 0.99, hits


def test_no_spread_gives_no_interval_and_says_why():
    r = compare_means([2.268] * 5, [2.31] * 5)  # deterministic simulation: five copies each
    assert r.difference == pytest.approx(2.268 - 2.31)
    assert math.isnan(r.pvalue) and math.isnan(r.statistic) and r.test == ""
    assert all(math.isnan(v) for v in r.confidence_interval()) and "no spread" in r.note
    p = compare_means([1.0, 2.0, 3.0], [1.5, 2.5, 3.5], paired=True)  # every pair differs by exactly 0.5
    assert math.isnan(p.pvalue) and "same amount" in p.note and p.difference == pytest.approx(-0.5)
    one = compare_means([1.0], [2.0, 2.1])
    assert math.isnan(one.pvalue) and "at least two values" in one.note
    few = compare_means([1.0, 1.2, 1.1], [2.0, 2.1, 2.3])
    assert few.test == "welch-t" and few.pvalue < 0.05 and math.isnan(few.confidence_interval().low)
    assert f"fewer than {MIN_BOOTSTRAP}" in few.note
    # one constant side is fine: Welch's t takes the spread of the other
    ok = compare_means([1.0] * 6, [1.1, 1.2, 1.15, 1.3, 1.05, 1.25])
    assert ok.test == "welch-t" and math.isfinite(ok.pvalue) and math.isfinite(ok.confidence_interval().low)


def test_compare_means_bad_arguments():
    with pytest.raises(ValueError, match="`test` must be"):
        compare_means([1, 2], [3, 4], test="z")
    with pytest.raises(ValueError, match="`alternative` must be one of"):
        compare_means([1, 2], [3, 4], alternative="bigger")
    with pytest.raises(ValueError, match="same length"):
        compare_means([1, 2], [3], paired=True)
    with pytest.raises(ValueError, match="`n_resamples`"):
        compare_means([1, 2], [3, 4], n_resamples=10)


def test_quantised_values_get_a_finite_interval_not_a_billion():
    """Execution times come in control steps: paired differences [0.10, 0.05, 0.05, 0.05, 0.05] (+ rounding
    noise of 1e-12). A third of the bootstrap's resamples are all 0.05; their rounding noise made t* huge and the
    interval's upper end ~1e9 s. Such a side of the bootstrap says nothing: the interval is then Student's t."""
    from scipy import stats as st

    from planners.stats import COARSE, compare_means

    rng = np.random.default_rng(1)
    b = np.round(rng.uniform(5, 6, 5), 2)
    a = b + np.array([0.10, 0.05, 0.05, 0.05, 0.05]) + rng.normal(0, 1e-12, 5)
    r = compare_means(a, b, paired=True)
    ref = st.ttest_rel(a, b).confidence_interval(0.95)
    assert r.note == COARSE and tuple(r.confidence_interval()) == pytest.approx((ref.low, ref.high))
    assert r.confidence_interval().high < 0.1
    x, y = rng.normal(0, 1, 8), rng.normal(0.5, 1, 8)  # continuous values: the bootstrap as before
    assert compare_means(x, y).note == ""
