"""GET /api/v1/comparisons against a real `twb up`: a small real study's comparisons.csv is what the endpoint,
`twb results ID ID ...`, the SDK and the dashboard's compare page show for its experiments; ownership (404),
bad parameters (422); the job fields `label` and `problem` and how the server names a job without them."""

from __future__ import annotations

import asyncio
import csv
import io
import json
import math
import re

import pytest

from client_sdk import AsyncClient, Client
from client_sdk.study import plan_jobs, StudySpec
from client_sdk.study._data import write_csv_stream
from contract.vocabulary import run_outcome
from planners.comparisons import COLUMNS, compare
from planners.stats import proportion
from planners.compared import (COMPARED_METRICS, DIRECTION, enters, flat_metrics, job_configuration, plain,
                               problem_label)
from sdk_helpers import invoke, study_process
from servers import STANDARD, wait_for
from test_dashboard import OUTPUT, login, no_horizontal_overflow
from test_dashboard import browser, page  # noqa: F401  (the shared fixtures: Chromium against this module's testbed)

#: three problems (room's plans A and B, and C given here) x two planners, five jittered repetitions in simulation:
#: repetitions differ, every problem has a bootstrap interval, and there is a verdict over problems
STUDY = {"name": "cmp", "environments": ["room"],
         "plans": ["A", "B", {"name": "C", "start": [0.3, 1.5, 0.0], "goal": [1.5, 0.3, -1.5708]}],
         "planners": ["fmm", "fm2"], "repetitions": 5, "modes": ["sim"], "seed": 4,
         "jitter": {"xy_m": 0.01, "theta_rad": 0.05}}


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


@pytest.fixture(scope="module")
def study(testbed, tmp_path_factory):
    """The study run by `twb study`: its directory, and its experiment ids in study order."""
    r, out = study_process(testbed, STUDY, tmp_path_factory.mktemp("cmp-study"), "--no-progress")
    assert r.returncode == 0, r.stderr
    assert "study cmp: 30/30 runs completed" in r.stdout, r.stdout
    ids = [e["experiment_id"] for e in json.loads((out / "study.json").read_text())["experiments"]]
    return out, ids


@pytest.fixture(scope="module")
def answer(testbed, study):
    """GET /api/v1/comparisons of the study's experiments in study order."""
    _, ids = study
    with testbed.client() as c:
        r = c.get("/api/v1/comparisons", params={"experiments": ",".join(map(str, ids))})
    assert r.status_code == 200, r.text
    return r.json()


def text_of(path) -> str:  # type: ignore[no-untyped-def]
    """A CSV file's text as written (its \\r\\n line ends kept)."""
    with open(path, newline="") as f:
        return f.read()


def as_csv(rows: list[dict]) -> str:
    """Rows written as a study writes comparisons.csv."""
    buf = io.StringIO(newline="")
    write_csv_stream(buf, list(COLUMNS), rows)
    return buf.getvalue()


# ----------------------------------------------------------------------------- names (no server)


def test_a_job_is_named_as_a_study_names_it():
    assert job_configuration(planner="fm2") == "fm2"
    assert job_configuration(planner="fm2", planner_params={"saturation": 0.1, "a": 2}) == "fm2(a=2,saturation=0.1)"
    assert job_configuration(planner="fmm", controller="schema") == "fmm"
    assert job_configuration(planner="fmm", controller="schema", always_controller=True) == "fmm/schema"
    assert job_configuration(planner="fmm", controller="pure_pursuit",
                             controller_params={"lookahead_m": 0.1}) == "fmm/pure_pursuit(lookahead_m=0.1)"
    assert job_configuration(planner="fmm", profile_overrides={"tracker_noise_xy_m": 0.003}) == \
        "fmm · tracker_noise_xy_m=0.003"
    assert job_configuration(program=7, controller_program=8) == "program #7/controller program #8"
    assert job_configuration() == "explicit path"
    assert len(job_configuration(planner="prm", planner_params={f"p{i}": i for i in range(30)})) == 64
    plans = [{"name": "A", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708]}]
    assert problem_label("room", plans=plans, start=[0.3, 0.3, 0.0], goal=[1.5, 1.5, 1.5708]) == "room A"
    assert problem_label("room", plans=plans, start=[0.3, 0.3, 2 * math.pi], goal=[1.5, 1.5, 1.5708]) == "room A"
    assert problem_label("room", plans=plans, start=[0.3, 0.3], goal=[1.5, 1.5, 1.5708]) == \
        "room (0.30,0.30)→(1.50,1.50)"  # no heading: another problem than A's
    assert problem_label("room", plans=plans, start=[0.304, 0.3, 0.0], goal=[1.5, 1.5]) == \
        "room (0.30,0.30)→(1.50,1.50)"
    assert problem_label("swap", robots=[{}, {}, {}, {}]) == "swap 4 robots"


def test_a_study_sends_its_configuration_and_problem():
    from client_sdk import Environment, Plan

    spec = StudySpec.from_json({**STUDY, "controllers": ["schema", "pure_pursuit"],
                                "planners": ["fmm", {"name": "fm2", "params": {"saturation": 0.1}}]})
    env = Environment("room", [1.8, 1.8], [], [Plan("A", [0.3, 0.3, 0.0], [1.5, 1.5, 1.5708]),
                                               Plan("B", [1.5, 0.3, 1.5708], [0.3, 1.5, 3.1416])])
    jobs = plan_jobs(spec, {"room": env})
    assert [(j["body"]["label"], j["body"]["problem"]) for j in jobs[:4]] == [
        ("fmm/schema", "room A"), ("fmm/pure_pursuit", "room A"), ("fm2(saturation=0.1)/schema", "room A"),
        ("fm2(saturation=0.1)/pure_pursuit", "room A")]
    assert {j["body"]["problem"] for j in jobs} == {"room A", "room B", "room C"}
    assert all(j["body"]["label"] == j["configuration"] for j in jobs)


# ----------------------------------------------------------------------------- the study's numbers everywhere


def test_the_study_experiments_carry_its_configurations_and_problems(testbed, study):
    _, ids = study
    with testbed.client() as c:
        exps = [c.get(f"/api/v1/experiments/{i}").json() for i in ids]
        listed = {e["id"]: e for e in c.get("/api/v1/experiments", params={"limit": 100}).json()["data"]}
    assert [(e["label"], e["problem"]) for e in exps] == [
        (p, f"room {plan}") for plan in "ABC" for p in ("fmm", "fm2")]
    assert all((listed[e["id"]]["label"], listed[e["id"]]["problem"]) == (e["label"], e["problem"]) for e in exps)


def test_the_endpoint_gives_the_rows_of_the_studys_comparisons_csv(study, answer):
    out, ids = study
    assert as_csv(answer["rows"]) == text_of(out / "comparisons.csv")  # every number, to full precision
    assert answer["configurations"] == ["fmm", "fm2"] and answer["problems"] == ["room A", "room B", "room C"]
    assert answer["metrics"] == list(COMPARED_METRICS) and answer["n_resamples"] == 9999 and answer["seed"] == 0
    pooled = [r for r in answer["rows"] if r["problem"] == ""]
    assert pooled and all(r["n_problems"] == 3 and r["favour_a"] + r["favour_b"] <= 3 for r in pooled)
    length = next(r for r in answer["rows"] if r["metric"] == "length_m" and r["problem"] == "room A")
    assert length["paired"] and length["test"] == "paired-t" and length["ci_low"] is not None  # jittered: they differ
    assert "problem" in answer["method"] and "unit of inference" in answer["method"]
    # outcomes: as the study's outcomes.csv has them
    with open(out / "outcomes.csv", newline="") as f:
        study_outcomes = list(csv.DictReader(f))
    assert [(o["configuration"], o["mode"], o["runs"], o["counted"], o["success"]["k"], o["success"]["n"])
            for o in answer["outcomes"]] == [
        (o["configuration"], o["mode"], int(o["runs"]), int(o["counted"]), int(o["success"]), int(o["distinct_runs"]))
        for o in study_outcomes]
    for mine, theirs in zip(answer["outcomes"], study_outcomes):
        assert mine["success"]["ci_low"] == float(theirs["ci_low"]) and mine["success"]["ci_high"] == float(theirs["ci_high"])
        assert mine["experiments"] == (ids[0::2] if mine["configuration"] == "fmm" else ids[1::2])


def test_the_rows_are_planners_comparisons_of_the_same_runs(testbed, study, answer):
    """Rows built here from the experiments' JSON and compared by planners.comparisons.compare directly."""
    _, ids = study
    rows = []
    with testbed.client() as c:
        for i in ids:
            exp = c.get(f"/api/v1/experiments/{i}").json()
            for run in exp["runs"]:
                rows.append({"configuration": exp["label"], "problem": exp["problem"], "mode": run["mode"],
                             "repetition": run["repetition"], "status": run["status"],
                             "outcome": run_outcome(run["status"], run["failure"]), **flat_metrics(run["metrics"])})
    mine = compare(rows, COMPARED_METRICS, problem=lambda r: r["problem"], enters=enters, direction=DIRECTION)
    assert plain(mine.rows()) == answer["rows"]


def test_twb_results_of_several_experiments(capsys, monkeypatch, testbed, study):
    out, ids = study
    args = ("--url", testbed.url, "--token", testbed.token)
    r = invoke(capsys, monkeypatch, "results", *map(str, ids), "--format", "csv", *args)
    assert r.returncode == 0, r.stderr
    assert r.stdout == text_of(out / "comparisons.csv")
    r = invoke(capsys, monkeypatch, "results", *map(str, ids), "--format", "json", *args)
    doc = json.loads(r.stdout)
    assert as_csv(doc["rows"]) == text_of(out / "comparisons.csv")
    r = invoke(capsys, monkeypatch, "results", *map(str, ids), "--wide", *args, env={"COLUMNS": "200"})
    assert r.returncode == 0, r.stderr
    text = r.stdout
    titles = [re.search(rf"^ *{t} *$", text, re.M) for t in (
        r"outcomes per configuration \(success rate over the distinct counted runs\)",
        r"over 3 problems \(each problem one observation\)", "on room A", "on room B", "on room C")]
    assert all(titles) and [m.start() for m in titles] == sorted(m.start() for m in titles), text
    low = proportion(15, 15)["ci_low"]
    assert f"15/15 ({100 * low:.0f}–100 %)" in text  # fmm's runs: 15 distinct successes, Wilson 95%
    r = invoke(capsys, monkeypatch, "results", str(ids[0]), str(ids[1]), "--metrics", "length_m", *args,
               env={"COLUMNS": "200"})
    assert "No verdict over problems: 1 problem(s)" in r.stdout and "on room A" in r.stdout
    r = invoke(capsys, monkeypatch, "results", str(ids[0]), "--metrics", "length_m", *args)
    assert r.returncode == 2 and "--metrics compares several experiments" in r.stderr


def test_the_sdk_compares_as_the_endpoint(testbed, study, answer):
    _, ids = study
    with Client(testbed.url, testbed.token) as c:
        report = c.compare(ids)
    assert [r.row() for r in report.rows] == answer["rows"]
    assert report.configurations == ["fmm", "fm2"] and len(report.pooled()) == len(
        [r for r in answer["rows"] if not r["problem"]])
    length = report.get("length_m", "sim", "fmm", "fm2")
    assert length.pooled and length.n_problems == 3
    assert report.get("length_m", "sim", "fm2", "fmm", problem="room B").problem == "room B"
    assert report.outcomes[0].success["n"] == 15 and report.experiments[0].label == "fmm"

    async def go():
        async with AsyncClient(testbed.url, testbed.token) as c:
            return await c.compare(ids, metrics=["length_m"], test="rank", family="all", confidence=0.9)

    ranked = asyncio.run(go())
    assert {r.metric for r in ranked.rows} == {"success_rate", "length_m"} and ranked.test == "rank"
    assert next(r for r in ranked.rows if r.pooled and r.metric == "length_m").test == "problem-wilcoxon"


# ----------------------------------------------------------------------------- who may see, what is refused


def test_only_the_owner_compares_and_bad_parameters_are_refused(testbed, study):
    _, ids = study
    with testbed.client() as admin:
        token = admin.post("/api/v1/users", json={"name": "carol"}).json()["token"]
    experiments = ",".join(map(str, ids))
    with testbed.client(token) as carol:
        r = carol.get("/api/v1/comparisons", params={"experiments": experiments})
        assert r.status_code == 404 and r.json()["detail"] == f"Experiment {ids[0]} not found"
    with testbed.client() as c:
        for params, message in [
            ({"experiments": str(ids[0])}, "experiments: give at least 2 experiments"),
            ({"experiments": f"{ids[0]},{ids[0]}"}, "experiments: give at least 2 experiments"),
            ({"experiments": "1,x"}, "experiments: 'x' is not an experiment id"),
            ({"experiments": ",".join(map(str, range(1, 202)))}, "experiments: at most 200 experiments"),
            ({"experiments": experiments, "metrics": "length_m,bogus_m"}, "metrics: unknown metric 'bogus_m'"),
            ({"experiments": experiments, "metrics": "mode"}, "metrics: unknown metric 'mode'"),
            ({"experiments": experiments, "metrics": "length m"}, "metrics: 'length m' is not a metric name"),
            ({"experiments": experiments, "test": "z"}, "query.test: Input should be 't' or 'rank'"),
            ({"experiments": experiments, "family": "some"}, "query.family: Input should be 'metric' or 'all'"),
            ({"experiments": experiments, "confidence": "1.5"}, "query.confidence: Input should be less than 1"),
            ({}, "query.experiments: Field required"),
        ]:
            r = c.get("/api/v1/comparisons", params=params)
            assert r.status_code == 422 and r.json()["detail"] == message or r.json()["detail"].startswith(message), \
                (params, r.text)
        assert c.get("/api/v1/comparisons", params={"experiments": f"{ids[0]},999999"}).status_code == 404
    with testbed.client(token=None) as anon:
        assert anon.get("/api/v1/comparisons", params={"experiments": experiments}).status_code == 401


def test_a_job_without_names_is_named_and_twins_stay_apart(testbed):
    job = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fmm",
           "modes": ["sim"], "repetitions": 2}
    with testbed.client() as c:
        a, b = (c.post("/api/v1/experiments", json={**job, "seed": s}).json() for s in (1, 2))
        assert (a["label"], a["problem"]) == ("fmm", "room A")
        off = c.post("/api/v1/experiments", json={**job, "goal": [1.5, 1.2],
                                                  "label": "my fmm", "problem": "room to the door"}).json()
        assert (off["label"], off["problem"]) == ("my fmm", "room to the door")
        named = c.post("/api/v1/experiments", json={**job, "goal": [1.5, 1.2], "controller": "pure_pursuit",
                                                    "modes": ["sim"]}).json()
        assert (named["label"], named["problem"]) == ("fmm/pure_pursuit", "room (0.30,0.30)→(1.50,1.20)")
        for bad in ({"label": ""}, {"label": "x" * 65}, {"problem": "y" * 101}, {"label": "  "}, {"label": "a\nb"}):
            assert c.post("/api/v1/experiments", json={**job, **bad}).status_code == 422, bad
        for e in (a, b, named):
            wait_for(c, e["id"], timeout=120)
        r = c.get("/api/v1/comparisons", params={"experiments": f"{b['id']},{a['id']},{named['id']}"}).json()
    assert r["configurations"] == [f"#{b['id']} fmm", f"#{a['id']} fmm", "fmm/pure_pursuit"]
    assert [e["configuration"] for e in r["experiments"]] == r["configurations"]
    assert r["problems"] == ["room A", "room (0.30,0.30)→(1.50,1.20)"] and not [x for x in r["rows"] if not x["problem"]]
    # different seeds: repetitions are not paired (no common random numbers)
    rate = next(x for x in r["rows"] if x["metric"] == "length_m" and x["problem"] == "room A")
    assert rate["paired"] is False and rate["a"] == f"#{b['id']} fmm"
    # the fmm/pure_pursuit configuration has no problem in common with the others: no row of its own
    assert not [x for x in r["rows"] if "fmm/pure_pursuit" in (x["a"], x["b"])]
    assert r["metrics"] == list(COMPARED_METRICS) + ["cross_track_error_mean_m", "heading_error_rms_rad",
                                                     "time_to_goal_s", "jerk_linear_rms_m_s3"]


# ----------------------------------------------------------------------------- the dashboard shows the same numbers


def js_num(v, digits: int = 3) -> str:
    """dom.js num(): fixed decimals, exponential below 10^-digits and from 1e5, "–" for none."""
    if v is None:
        return "–"
    a = abs(v)
    if a < 1e-12:
        return f"{0:.{digits}f}"
    if a < 10 ** -digits or a >= 1e5:
        mantissa, exp = f"{v:.2e}".split("e")
        return f"{mantissa}e{'+' if int(exp) >= 0 else '-'}{abs(int(exp))}"
    return f"{v:.{digits}f}"


def js_round(x: float) -> int:
    """JavaScript's Math.round: halves up."""
    return math.floor(x + 0.5)


def pct(v) -> str:  # type: ignore[no-untyped-def]
    return "–" if v is None else f"{js_round(100 * v)} %"


def points(v: float) -> str:
    return f"{'+' if v > 0 else ''}{js_round(100 * v)}"


def fmt_p(p) -> str:  # type: ignore[no-untyped-def]
    """compare.js fmtP: two significant digits (Number.toPrecision(2)), "< 0.001" below."""
    if p is None:
        return "–"
    if p < 0.001:
        return "< 0.001"
    exp = int(f"{p:.1e}".split("e")[1])
    return f"{p:.{max(0, 1 - exp)}f}"


TEST_WORDS = {"paired-t": "paired t", "welch-t": "Welch's t", "fisher-exact": "Fisher's exact",
              "problem-t": "t over problems", "": "–"}

CELLS = """() => [...document.querySelectorAll('#compare-pooled tbody tr, #compare-differences tbody tr')].map((tr) => ({
  ...tr.dataset,
  cells: Object.fromEntries([...tr.querySelectorAll('td')].map((td) => [td.dataset.k, {text: td.textContent, v: td.dataset.v ?? null}])),
}))"""


def shown(row: dict, unit: str) -> dict[str, str]:
    """A comparisons.csv row as the compare page formats it."""
    value = {k: (None if row[k] == "" else float(row[k])) for k in
             ("mean_a", "mean_b", "diff", "ci_low", "ci_high", "p", "p_holm", "heterogeneity_i2")}
    rate = row["metric"] == "success_rate"
    out = {"mean_a": pct(value["mean_a"]) if rate else js_num(value["mean_a"]),
           "mean_b": pct(value["mean_b"]) if rate else js_num(value["mean_b"]),
           "diff": "–" if value["diff"] is None else f"{points(value['diff'])} points" if rate
           else f"{js_num(value['diff'])} {unit}",
           "ci": "–" if value["ci_low"] is None else
           f"[{points(value['ci_low'])}, {points(value['ci_high'])}]" if rate else
           f"[{js_num(value['ci_low'])}, {js_num(value['ci_high'])}]",
           "p": fmt_p(value["p"]), "p_holm": fmt_p(value["p_holm"]), "test": TEST_WORDS[row["test"]],
           "note": row["note"]}
    if row["problem"]:
        out.update(n_a=row["n_a"], n_b=row["n_b"])
    else:
        out.update(favour=f"{row['favour_a']} / {row['favour_b']} of {row['n_problems']}",
                   i2=pct(value["heterogeneity_i2"]))
    return out


UNITS = {"length_m": "m", "execution_time_s": "s", "average_speed_m_s": "m/s", "deviation_mean_m": "m",
         "smoothness_rad": "rad", "clearance_min_m": "m"}


def test_the_dashboard_compare_page_shows_the_studys_numbers(page, testbed, study):
    """The compare page of the study's experiments in a real browser: every row of comparisons.csv, pooled and
    per problem, with its numbers formatted as the page formats them (and the raw numbers behind them equal
    to full precision); the outcomes as outcomes.csv has them."""
    from playwright.sync_api import expect

    out, ids = study
    login(page, testbed.url)
    page.goto(f"{testbed.url}/#/compare?ids={','.join(map(str, ids))}")
    expect(page.locator("#compare-pooled")).to_be_visible()
    expect(page.locator("#compare-no-verdict")).to_have_count(0)
    expect(page.locator("#compare-differences section.compare-problem h3")).to_have_text(
        ["On room A", "On room B", "On room C"])
    with open(out / "comparisons.csv", newline="") as f:
        expected = list(csv.DictReader(f))
    seen = page.evaluate(CELLS)
    key = ("metric", "mode", "a", "b", "problem")
    # the pooled rows first (the server's order within them), then each problem's
    assert [tuple(tr[k] for k in key) for tr in seen] == [tuple(r[k] for k in key) for r in expected if not r["problem"]] \
        + [tuple(r[k] for k in key) for p in ("room A", "room B", "room C") for r in expected if r["problem"] == p]
    rows = {tuple(r[k] for k in key): r for r in expected}
    for tr in seen:
        row = rows[tuple(tr[k] for k in key)]
        texts = {k: c["text"] for k, c in tr["cells"].items()}
        want = shown(row, UNITS.get(row["metric"], ""))
        assert {k: texts[k] for k in want} == want, row
        for column in ("mean_a", "mean_b", "diff", "p", "p_holm"):
            raw = tr["cells"][column]["v"]
            assert (raw is None and row[column] == "") or float(raw) == float(row[column]), (column, row)
    with open(out / "outcomes.csv", newline="") as f:
        for o in csv.DictReader(f):
            cell = page.locator(f'#compare-outcomes tr[data-configuration="{o["configuration"]}"][data-mode="{o["mode"]}"] '
                                'td[data-rate]')
            lo, hi = float(o["ci_low"]), float(o["ci_high"])
            expect(cell).to_have_text(f"{o['success']}/{o['distinct_runs']} ({pct(lo)}–{pct(hi)})")
            assert float(cell.get_attribute("data-ci-low")) == lo and float(cell.get_attribute("data-ci-high")) == hi
    page.screenshot(path=OUTPUT / "compare-study.png", full_page=True)
    assert no_horizontal_overflow(page)
    assert page.console.errors == []
