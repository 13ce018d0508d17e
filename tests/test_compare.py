"""Outcomes, comparisons and the answer in words on synthetic study data (no server): pairing, identical
repetitions, Holm's families, the words, the limits a study is checked against."""

from __future__ import annotations

import json
import math

import httpx
import numpy as np
import pytest

from client_sdk import Client
from client_sdk.study import (
    COMPARED_METRICS,
    StudyData,
    StudyRefused,
    StudySpec,
    StudySpecError,
    check_study,
    run_study,
    which_is_better,
)
from client_sdk.study._compare import COMPARISON_COLUMNS


def study(rows: list[dict], configs=("fm2", "fmm"), modes=("sim", "twb"), reps=5, problems=(("room", "A"),),
          rejected=()) -> StudyData:
    """A StudyData with one experiment per problem x configuration, holding the given run rows."""
    spec = StudySpec.from_json({"name": "synthetic", "environments": sorted({p[0] for p in problems}),
                                "planners": list(configs), "repetitions": reps, "modes": list(modes)})
    experiments, eid = [], 0
    for env, plan in problems:
        for c in configs:
            eid += 1
            mine = [r for r in rows if (r["environment"], r["plan"], r["configuration"]) == (env, plan, c)]
            for r in mine:
                r["experiment_id"] = eid
            status = "rejected" if (env, plan, c) in rejected else "completed"
            experiments.append({"experiment_id": eid if status != "rejected" else None, "environment": env,
                                "plan": plan, "planner": c, "configuration": c, "planner_params": {}, "start": [0, 0],
                                "goal": [1, 1], "status": status, "error": "", "planned_path": None,
                                "planning_time_s": None, "runs": [r["run_id"] for r in mine],
                                "repetitions": reps, "modes": list(modes)})
    return StudyData(spec, {}, experiments, rows, [])


def run(config, mode, rep, *, outcome="success", length=None, problem=("room", "A"), run_id=None, **metrics) -> dict:
    status = {"success": "completed", "error": "error", "cancelled": "cancelled"}.get(outcome, "failed")
    row = {"run_id": run_id or hash((config, mode, rep, problem)) % 10**6, "environment": problem[0],
           "plan": problem[1], "planner": config, "configuration": config, "mode": mode, "repetition": rep,
           "status": status, "outcome": outcome, "failure": None if status != "failed" else outcome,
           "length_m": length, **metrics}
    return row


def test_a_planner_that_only_fails_on_the_field():
    rng = np.random.default_rng(1)
    rows = []
    for rep in range(1, 6):
        for c, base in (("fm2", 2.0), ("corner", 1.8)):
            rows.append(run(c, "sim", rep, length=base + rng.normal(0, 0.01)))
            rows.append(run(c, "twb", rep, length=base * 1.1 + rng.normal(0, 0.02)) if c == "fm2" else
                        run(c, "twb", rep, outcome="collision", length=0.4 + rng.normal(0, 0.01)))
    data = study(rows, configs=("fm2", "corner"))
    outs = {(o.configuration, o.mode): o for o in data.outcomes()}
    o = outs["corner", "twb"]
    assert o.counts == {"collision": 5} and o.successes == 0 and o.counted == 5
    assert o.success["rate"] == 0 and o.success["ci_high"] == pytest.approx(0.4345, abs=1e-4)  # Wilson, 0/5
    assert o.rate_text() == "0/5 (95% CI 0–43 %)"
    comps = data.compare()
    assert [c.metric for c in comps[:2]] == ["success_rate", "success_rate"]
    rate = comps.get("success_rate", "twb", "fm2", "corner")
    assert rate.result.test == "fisher-exact" and round(rate.pvalue, 4) == 0.0079
    assert rate.family_size == 2 and rate.pvalue_holm == pytest.approx(2 * 2 / 252)  # Holm over sim and twb
    assert rate.difference == 1.0 and rate.confidence_interval().low > 0 and rate.better() == "fm2"
    # the failed field runs' metrics are kept (runs.csv) but not compared: no completed run
    length = comps.get("length_m", "twb", "fm2", "corner")
    assert length.result.n_b == 0 and not length.tested and length.note == "no completed run of corner"
    assert comps.get("length_m", "sim", "fm2", "corner").result.paired  # same problems and repetitions
    rows_out = comps.rows()
    assert list(rows_out[0])[:14] == ["metric", "mode", "a", "b", "n_a", "n_b", "mean_a", "mean_b", "diff", "ci_low",
                                      "ci_high", "test", "p", "p_holm"]
    assert rows_out[0]["problem"] == "room A" and rows_out[0]["n_problems"] == 1  # one problem: its row
    assert list(COMPARISON_COLUMNS[:14]) == list(rows_out[0])[:14]
    answers = which_is_better(data, comps)
    assert [a.mode for a in answers] == ["twb", "sim"]  # the field first
    field = answers[0]
    assert field.verdicts == ["FM² is better than corner on the field on room A: it reached the goal "
                              "significantly more often. (One problem: its answer says nothing about other problems.)"]
    text = " ".join(field.facts)
    assert "corner reached the goal in 0 of 5 runs (95% CI 0–43 %); collided 5 times." in text
    assert "5/5 vs 0/5" in text and "Fisher's exact p = 0.0079" in text and "Holm-adjusted p = 0.016" in text


def test_identical_repetitions_count_once_and_get_no_fake_interval():
    rows = []
    for rep in range(1, 6):  # the deterministic simulation: five copies of one run each
        rows.append(run("fm2", "sim", rep, length=2.268, execution_time_s=11.96 + rep * 1e-13))
        rows.append(run("fmm", "sim", rep, length=2.31, execution_time_s=11.2))
    data = study(rows, modes=("sim",))
    o = data.outcomes()[0]
    assert o.identical and o.counts == {"success": 5} and o.success["n"] == 1  # one distinct run
    assert "identical repetitions counted once: 1/1" in o.rate_text()
    c = data.compare().get("length_m", "sim", "fm2", "fmm")
    assert c.difference == pytest.approx(2.268 - 2.31)
    assert not c.tested and math.isnan(c.pvalue_holm) and all(math.isnan(v) for v in c.confidence_interval())
    assert c.note.startswith("identical repetitions (deterministic simulation): counted once")
    assert "no interval or test" in c.note
    row = c.row()
    assert row["ci_low"] != row["ci_low"] and row["p"] != row["p"]  # NaN: empty cells in comparisons.csv
    words = " ".join(which_is_better(data)[0].facts)
    assert "identical repetitions (deterministic simulation)" in words


def test_a_refused_job_leaves_its_problem_out_of_the_comparison():
    """prm's job on room B was refused: the two are compared where both ran (room A, paired by repetition);
    fm2's runs on room B compare with nothing, they do not enter room A's comparison."""
    rng = np.random.default_rng(4)
    rows = []
    for prob in (("room", "A"), ("room", "B")):
        for rep in range(1, 4):
            rows.append(run("fm2", "twb", rep, problem=prob, length=2 + rng.normal(0, 0.05)))
            if prob == ("room", "A"):
                rows.append(run("prm", "twb", rep, problem=prob, length=2.3 + rng.normal(0, 0.05)))
    data = study(rows, configs=("fm2", "prm"), modes=("twb",), reps=3, problems=(("room", "A"), ("room", "B")),
                 rejected={("room", "B", "prm")})
    prm = [o for o in data.outcomes() if o.configuration == "prm"][0]
    assert prm.not_submitted == 3 and prm.not_counted == 3 and prm.counted == 3
    comps = data.compare()
    assert {c.problem for c in comps} == {("room", "A")}  # no pooled row, no room B row
    c = comps.get("length_m", "twb", "fm2", "prm")
    assert c.problem == ("room", "A") and c.result.paired and (c.result.n_a, c.result.n_b) == (3, 3)
    assert c.result.test == "paired-t" and c.tested


def test_unpaired_when_the_repetitions_differ():
    rng = np.random.default_rng(5)
    rows = [run("fm2", "twb", rep, length=2 + rng.normal(0, 0.05)) for rep in range(1, 7)]
    rows += [run("prm", "twb", rep, length=2.3 + rng.normal(0, 0.05)) for rep in range(1, 5)]
    c = study(rows, configs=("fm2", "prm"), modes=("twb",), reps=6).compare().get("length_m", "twb", "fm2", "prm")
    assert not c.result.paired and (c.result.n_a, c.result.n_b) == (6, 4) and c.result.test == "welch-t"


def test_testbed_errors_are_not_the_planners():
    rows = [run("fm2", "twb", 1, length=2.0), run("fm2", "twb", 2, outcome="error"),
            run("fmm", "twb", 1, length=2.1), run("fmm", "twb", 2, outcome="stalled", length=0.5)]
    data = study(rows, modes=("twb",), reps=2)
    fm2, fmm = data.outcomes()
    assert fm2.counted == 1 and fm2.not_counted == 1 and fm2.success["n"] == 1
    assert fmm.count("other") == 1 and fmm.other_detail == "stalled 1"
    rate = data.compare().get("success_rate", "twb", "fm2", "fmm")
    assert (rate.result.k_a, rate.result.n_a, rate.result.k_b, rate.result.n_b) == (1, 1, 1, 2)


def test_holm_families_per_metric_or_all():
    rng = np.random.default_rng(9)
    rows = []
    for rep in range(1, 9):
        for c, shift in (("a", 0.0), ("b", 0.05), ("c", 0.3)):
            rows.append(run(c, "twb", rep, length=2 + shift + rng.normal(0, 0.1),
                            execution_time_s=10 + 3 * shift + rng.normal(0, 0.5)))
    data = study(rows, configs=("a", "b", "c"), modes=("twb",), reps=8)
    per_metric = data.compare(["length_m", "execution_time_s"], n_resamples=999)
    everything = data.compare(["length_m", "execution_time_s"], family="all", n_resamples=999)
    lengths = [c for c in per_metric if c.metric == "length_m"]
    assert {c.family_size for c in lengths} == {3}  # three pairs
    from planners.stats import holm

    assert [c.pvalue_holm for c in lengths] == pytest.approx(holm([c.pvalue for c in lengths]).tolist())
    assert {c.family_size for c in everything if c.tested} == {9}  # 3 success rates + 3 x 2 metrics
    assert all(e.pvalue_holm >= m.pvalue_holm - 1e-15 for e, m in zip(everything, per_metric) if e.tested)
    with pytest.raises(ValueError, match="`family` must be"):
        data.compare(family="everything")


def test_compare_defaults_and_result_objects():
    rng = np.random.default_rng(2)
    rows = [run(c, "twb", rep, length=2 + (c == "b") * 0.2 + rng.normal(0, 0.05))
            for rep in range(1, 7) for c in ("a", "b")]
    comps = study(rows, configs=("a", "b"), modes=("twb",), reps=6).compare()
    assert [c.metric for c in comps] == ["success_rate", *COMPARED_METRICS]
    c = comps.get("length_m", "twb", "b", "a")  # either order finds it
    assert c.a == "a" and c.b == "b" and c.difference < 0 and c.better() == "a"  # shorter is better
    assert c.significant() and c in comps.significant()
    low, high = c.confidence_interval()
    assert low < c.difference < high and c.confidence_interval(0.8).low > low
    assert c.statistic == c.result.statistic and c.result.effect == "cohen-dz"


# ----------------------------------------------------------------------------- limits, with a fake server


def fake_server(*, limits=None, refuse_at=None, refusal=(429, "you already have 3 queued experiments (limit 3)")):
    """A MockTransport testbed: planners fmm/fm2, environment room (plan A); submissions numbered from 1."""
    seen = {"submitted": [], "cancelled": []}

    def handler(request: httpx.Request) -> httpx.Response:
        path = request.url.path
        if path == "/api/v1/planners":
            return httpx.Response(200, json={"data": [{"name": "fmm", "defaults": {"speed": 1}},
                                                      {"name": "fm2", "defaults": {"saturation": 0.2}}], "count": 2})
        if path == "/api/v1/limits":
            return httpx.Response(200, json=limits) if limits is not None else \
                httpx.Response(404, json={"detail": "Not Found"})
        if path == "/api/v1/environments/room":
            return httpx.Response(200, json={"name": "room", "size": [1.8, 1.8], "blocks": [],
                                             "plans": [{"name": "A", "start": [0.3, 0.3, 0], "goal": [1.5, 1.5, 0]}]})
        if path.startswith("/api/v1/environments/"):
            return httpx.Response(404, json={"detail": "Environment not found"})
        if path == "/api/v1/experiments" and request.method == "GET":
            return httpx.Response(200, json={"data": [], "count": 2})
        if path == "/api/v1/experiments" and request.method == "POST":
            n = len(seen["submitted"]) + 1
            if refuse_at is not None and n >= refuse_at:
                return httpx.Response(refusal[0], json={"detail": refusal[1]})
            seen["submitted"].append(json.loads(request.content))
            return httpx.Response(202, json={"id": n, "status": "queued", "environment": "room"})
        if path.endswith("/cancel"):
            seen["cancelled"].append(int(path.split("/")[-2]))
            return httpx.Response(200, json={"id": int(path.split("/")[-2]), "status": "cancelled",
                                             "environment": "room"})
        return httpx.Response(500, json={"detail": f"unexpected {request.method} {path}"})

    return httpx.MockTransport(handler), seen


SPEC = {"name": "s", "environments": ["room"], "planners": ["fmm", "fm2"], "repetitions": 3, "modes": ["sim"]}


def test_a_study_is_checked_before_anything_is_submitted():
    transport, seen = fake_server(limits={"max_repetitions": 2, "max_queued_per_user": 2})
    spec = StudySpec.from_json({**SPEC, "planners": ["fmm", {"name": "fm2", "params": {"sat": 1}}, "rrt"],
                                "environments": ["room", "atlantis"]})
    with Client("http://testbed", "t", transport=transport) as c:
        reasons = check_study(c, spec)
        with pytest.raises(StudyRefused) as err:
            run_study(c, spec, progress=False)
    assert reasons == [
        "planner 'fm2' has no parameter(s) sat (its parameters: saturation)",
        "planner 'rrt' is not offered by this testbed (it offers fm2, fmm)",
        "unknown environment 'atlantis': create it first or give its file in the study's `environments`",
        "repetitions 3: the testbed allows at most 2 per experiment",
        "you already have 2 queued experiments and the testbed allows 2 per user: wait for them to finish or "
        "cancel some",
    ]
    assert err.value.reasons == reasons and seen["submitted"] == []


def test_a_quota_refusal_with_nothing_of_the_study_to_wait_for_stops_it():
    transport, seen = fake_server(refuse_at=1)  # no limits endpoint: the 429 of the first job tells
    with Client("http://testbed", "t", transport=transport) as c:
        with pytest.raises(StudyRefused) as err:
            run_study(c, StudySpec.from_json(SPEC), progress=False)
    (reason,) = err.value.reasons
    assert reason.startswith("the testbed refused experiment 1 of 2: you already have 3 queued experiments (limit 3)")
    assert reason.endswith("ask the operator to raise TWB_MAX_QUEUED_PER_USER")
    assert seen["submitted"] == [] and seen["cancelled"] == []


def test_a_repetitions_refusal_stops_the_study_at_once():
    transport, seen = fake_server(refuse_at=1, refusal=(422, "repetitions must be at most 2"))
    with Client("http://testbed", "t", transport=transport) as c:
        with pytest.raises(StudyRefused, match=r"repetitions 3: the testbed allows at most 2 per experiment"):
            run_study(c, StudySpec.from_json(SPEC), progress=False)
    assert seen["submitted"] == [] and seen["cancelled"] == []


@pytest.mark.parametrize("jitter,message", [
    ({"xy_m": 0.1}, r"jitter.xy_m must be a number in \[0, 0.05\]"),
    ({"theta": 0.1}, "jitter: unknown key"),
    ([0.005], "`jitter` must be an object"),
    ({"xy_m": True}, "jitter.xy_m must be a number"),
])
def test_jitter_is_validated(jitter, message):
    with pytest.raises(StudySpecError, match=message):
        StudySpec.from_json({**SPEC, "jitter": jitter})


def test_jitter_waypoints_and_labels_reach_the_jobs():
    from client_sdk import Environment, Plan
    from client_sdk.study import plan_jobs

    spec = StudySpec.from_json({**SPEC, "jitter": {"xy_m": 0.005, "theta_rad": 0.02},
                                "planners": ["fm2", {"name": "fm2", "params": {"saturation": 0.1}},
                                             {"name": "corner", "waypoints": [[0.9, 0.69]], "label": "corner path"}]})
    assert StudySpec.from_json(spec.to_json()) == spec
    jobs = plan_jobs(spec, {"room": Environment("room", [1.8, 1.8], [], [Plan("A", [0.9, 0.3, 1.57], [1.5, 0.69, 0])])})
    assert [j["configuration"] for j in jobs] == ["fm2", "fm2(saturation=0.1)", "corner path"]
    assert all(j["body"]["jitter"] == {"xy_m": 0.005, "theta_rad": 0.02} for j in jobs)
    corner = jobs[2]["body"]
    assert corner["path"] == [[0.9, 0.3, 1.57], [0.9, 0.69], [1.5, 0.69, 0]] and "planner" not in corner
    assert jobs[2]["planner"] == "path"
    with pytest.raises(StudySpecError, match=r"planners\[1\] repeats planners\[0\] \(fm2\)"):
        StudySpec.from_json({**SPEC, "planners": ["fm2", {"name": "fm2"}]})
    with pytest.raises(StudySpecError, match="either `params`"):
        StudySpec.from_json({**SPEC, "planners": [{"name": "x", "params": {"a": 1}, "waypoints": []}]})


# ----------------------------------------------------------------------------- the problem is the unit of inference

PROBLEMS = tuple(("env", p) for p in "ABCDEF")


def _problem_study(effects: dict, *, noise=0.005, reps=5, seed=3, configs=("fmm", "fm2"), mode="twb") -> StudyData:
    """Runs of two configurations on the problems of ``effects`` (problem -> a - b in length, m)."""
    rng = np.random.default_rng(seed)
    rows = []
    for prob, effect in effects.items():
        base = 2.0 + rng.uniform(-0.5, 0.5)  # problems differ in length; only a - b matters
        for rep in range(1, reps + 1):
            common = rng.normal(0, noise)  # common random numbers: the repetition's noise, shared
            rows.append(run(configs[0], mode, rep, problem=prob, length=base + effect + common + rng.normal(0, noise)))
            rows.append(run(configs[1], mode, rep, problem=prob, length=base + common + rng.normal(0, noise)))
    return study(rows, configs=configs, modes=(mode,), reps=reps, problems=tuple(effects))


def test_two_problems_that_disagree_give_no_pooled_verdict_and_say_so():
    """The issue's FMM vs FM² case: two problems whose differences are -0.062 and -0.500 m. Pooled as ten
    independent pairs they looked certain (p = 0.004); over two problems there is no verdict to draw."""
    data = _problem_study({("env", "A"): -0.062, ("env", "B"): -0.500})
    comps = data.compare(["length_m"], n_resamples=999)
    assert [c.problem for c in comps if c.metric == "length_m"] == [("env", "A"), ("env", "B")]  # no pooled row
    assert comps.get("length_m", "twb", "fmm", "fm2") is None
    a, b = (comps.get("length_m", "twb", "fmm", "fm2", p) for p in (("env", "A"), ("env", "B")))
    assert a.difference == pytest.approx(-0.062, abs=0.01) and b.difference == pytest.approx(-0.5, abs=0.01)
    assert a.significant() and b.significant() and a.result.paired  # each problem's own answer is clear
    verdict = which_is_better(data, comps)[0].verdicts[0]
    assert verdict == ("With 2 problems there is no verdict over problems (at least 3 are needed); on the field: "
                       "FMM is better than FM² on env A on path length; FMM is better than FM² on env B on path length.")


def test_opposite_signs_on_two_problems_name_each_problem():
    data = _problem_study({("env", "A"): -0.3, ("env", "B"): +0.3})
    comps = data.compare(["length_m"], n_resamples=999)
    answer = which_is_better(data, comps)[0]
    assert "FMM is better than FM² on env A on path length; FM² is better than FMM on env B on path length." \
        in answer.verdicts[0]
    assert all(not c.pooled for c in comps)


def test_a_pooled_verdict_comes_from_the_problems_and_names_the_exception():
    effects = {p: -0.1 for p in PROBLEMS}
    effects[("env", "D")] = +0.05  # on D fmm is longer
    data = _problem_study(effects, seed=7)
    comps = data.compare(["length_m"], n_resamples=999)
    c = comps.get("length_m", "twb", "fmm", "fm2")
    assert c.pooled and c.result.n_problems == 6 and c.result.test == "problem-t"
    # brute force: a one-sample t over the six per-problem differences of means
    per = comps.of("length_m", "twb", "fmm", "fm2")
    d = np.array([p.difference for p in per])
    from scipy import stats as st

    ref = st.ttest_1samp(d, 0.0)
    assert c.pvalue == pytest.approx(ref.pvalue) and c.difference == pytest.approx(d.mean())
    assert tuple(c.confidence_interval()) == pytest.approx(tuple(ref.confidence_interval(0.95)))
    assert c.favouring() == (5, 1, 0) and c.better() == "fmm"
    assert c.result.heterogeneity.i2 > 0.9  # D disagrees far beyond the repetitions' noise
    row = c.row()
    assert row["problem"] == "" and row["n_problems"] == 6 and (row["favour_a"], row["favour_b"]) == (5, 1)
    assert row["needed_unit"] == "problems" and row["n_needed"] >= 2
    from planners.stats import sample_size_mean

    assert row["n_needed"] == sample_size_mean(d.mean() / d.std(ddof=1))
    facts = " ".join(which_is_better(data, comps)[0].facts)
    assert "Path length: FMM is shorter on 5 of 6 problems; on env D it is longer (+0.05" in facts
    assert "the problems disagree (I² = " in facts


def test_mixed_problems_give_an_interval_over_zero_not_a_confident_verdict():
    data = _problem_study({("env", "A"): -0.2, ("env", "B"): +0.15, ("env", "C"): -0.05, ("env", "D"): +0.1})
    comps = data.compare(["length_m"], n_resamples=999)
    c = comps.get("length_m", "twb", "fmm", "fm2")
    assert c.pooled and not c.significant() and c.confidence_interval().low < 0 < c.confidence_interval().high
    assert all(p.significant() for p in comps.of("length_m", "twb", "fmm", "fm2"))  # each problem is clear
    verdict = which_is_better(data, comps)[0].verdicts[0]
    assert "over 4 problems" in verdict and "more problems would" in verdict and "more repetitions" in verdict


def test_holm_never_goes_below_the_unadjusted_p_value():
    from planners.stats import holm

    rng = np.random.default_rng(0)
    for _ in range(200):
        p = np.concatenate([10.0 ** -rng.uniform(0, 30, rng.integers(1, 8)), rng.uniform(0, 1, rng.integers(0, 5))])
        adj = holm(p)
        assert np.all(adj >= p) and np.all(adj <= 1)
    assert holm([8.4e-24, 0.3])[0] == pytest.approx(1.68e-23, rel=1e-12)  # not rounded to 0


def test_success_rates_are_pooled_over_problems_too():
    rows = []
    for i, prob in enumerate(PROBLEMS[:4]):
        for rep in range(1, 6):
            rows.append(run("a", "twb", rep, problem=prob, length=2.0))
            fail = rep <= 2 + (i % 2)  # b fails 2 or 3 of 5 on each problem
            rows.append(run("b", "twb", rep, problem=prob, length=2.0, outcome="collision" if fail else "success"))
    data = study(rows, configs=("a", "b"), modes=("twb",), problems=PROBLEMS[:4])
    rate = data.compare([]).get("success_rate", "twb", "a", "b")
    assert rate.pooled and rate.result.n_problems == 4 and rate.difference == pytest.approx(0.5)
    assert rate.significant() and rate.better() == "a" and rate.favouring() == (4, 0, 0)
    per = data.compare([]).of("success_rate", "twb", "a", "b")
    assert [p.result.test for p in per] == ["fisher-exact"] * 4 and per[0].needed() is not None


def test_the_same_difference_on_every_problem_gets_the_sign_test_not_a_fake_interval():
    """100 % against 0 % on each of 6 problems: no spread for a t interval; 6 of 6 on one side is what the
    problems can say (exact sign test: 2 / 2**6), and the words say it for every problem without calling it
    significant after Holm over both modes."""
    rows = []
    for prob in PROBLEMS:
        for mode in ("sim", "twb"):
            for rep in range(1, 4):
                rows.append(run("coordinated", mode, rep, problem=prob, length=2.0))
                rows.append(run("fmm", mode, rep, problem=prob, outcome="collision", length=1.0))
    data = study(rows, configs=("coordinated", "fmm"), problems=PROBLEMS, reps=3)
    rate = data.compare([]).get("success_rate", "twb", "coordinated", "fmm")
    assert rate.pooled and rate.result.test == "problem-sign" and rate.pvalue == pytest.approx(2 / 2 ** 6)
    assert math.isnan(rate.confidence_interval().low) and rate.pvalue_holm == pytest.approx(4 / 2 ** 6)
    facts = " ".join(which_is_better(data)[0].facts)
    assert "coordinated reached the goal more often than FMM on every one of the 6 problems, but over so few " \
           "problems that is not significant: +100 percentage points (the same on all 6 problems" in facts


def test_fig6_tick_labels_of_four_configurations_do_not_overlap():
    """Four configurations under a Fig. 6 panel: each tick label within its own slot (issue 32: "T 10/$0")."""
    from client_sdk.study._figures import figure_metrics

    configs = ("fm2", "fmm", "prm", "astar")
    rows = [run(c, m, rep, length=1.0 + 0.01 * rep, run_id=1000 * k + 10 * rep + (m == "twb"))
            for k, c in enumerate(configs) for m in ("sim", "twb") for rep in range(1, 11)]
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = figure_metrics(study(rows, configs=configs, reps=10))
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for ax in fig.axes:
        boxes = [t.get_window_extent(renderer) for t in ax.get_xticklabels() if t.get_text()]
        if not boxes:
            continue
        assert len(boxes) == 4
        assert all(a.x1 < b.x0 for a, b in zip(boxes, boxes[1:])), [(b.x0, b.x1) for b in boxes]
        assert all("$" not in t.get_text() or "\\$" in t.get_text() for t in ax.get_xticklabels())


def test_a_large_studys_summary_lists_its_comparisons_on_each_problem_only_in_the_csv(monkeypatch):
    """Beyond MAX_PROBLEM_ROWS per-problem comparisons the report keeps the pooled ones and points to
    comparisons.csv (the planner study's summary.md was 5,880 lines); a small study shows them all."""
    from client_sdk.study import _report
    from client_sdk.study._report import summary_tables

    data = _problem_study({p: -0.1 for p in PROBLEMS}, seed=7)
    comps = data.compare(["length_m"], n_resamples=199)
    title, header, body = next(t for t in summary_tables(data, comparisons=comps) if t[0].startswith("Comparisons"))
    where = [row[header.index("problem")] for row in body]
    assert "all 6" in where and "env A" in where and len(body) == len(comps)
    monkeypatch.setattr(_report, "MAX_PROBLEM_ROWS", 3)
    title, header, body = next(t for t in summary_tables(data, comparisons=comps) if t[0].startswith("Comparisons"))
    assert [row[header.index("problem")] for row in body] == ["all 6"] * len(body) and len(body) >= 1
    assert f"the {sum(not c.pooled for c in comps)} comparisons on each problem: comparisons.csv" in title
