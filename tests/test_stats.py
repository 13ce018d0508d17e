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
