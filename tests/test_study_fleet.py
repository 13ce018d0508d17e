"""Fleet studies (docs/study.md, "The fleet study" and "Fleets: robot counts and obstacle scenarios"): study files
that cross robot counts (fleet problems: explicit robots, the circle generator) and obstacle scenarios; their
validation, the circle's geometry, a small fleet study through a real testbed (outcomes by kind, fleet metrics with
intervals, figures) and the ready `twb study fleet`.

(Single-robot studies: tests/test_study.py; multi-robot jobs without a study: tests/test_fleet_rest.py.)
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from client_sdk import Client, Environment
from client_sdk.study import (ARENA, DISCS, FLEET, FLEET_DISCS, StudySpec, StudySpecError, export_ompl,
                              figure_fleet_paths, load_spec,
                              load_study, make_figures, plan_jobs, run_study)
from client_sdk.study._fleet import SEPARATION_M, circle_robots
from client_sdk.study._report import report_html
from client_sdk.study._fleet_results import FLEET_KINDS, fleet_outcome, fleet_row
from servers import STANDARD
from sdk_helpers import invoke, study_process

ROOT = Path(__file__).resolve().parents[1]
SWAP = json.loads((ROOT / "planners" / "data" / "swap.json").read_text())

#: prioritized against uncoordinated FMM on 2 and 4 robots in the empty sub-field, 2 repetitions x sim and field
SMALL = {"name": "fleet-small", "environments": ["swap"],
         "plans": [{"name": "circle-2", "circle": {"robots": 2, "radius_m": 0.6}},
                   {"name": "circle-4", "circle": {"robots": 4, "radius_m": 0.6}}],
         "planners": ["prioritized", "fmm"], "repetitions": 2, "modes": ["sim", "twb"], "seed": 3}
CIRCLE = {"name": "c", "circle": {"robots": 4, "radius_m": 0.6}}
BASE = {"environments": ["swap"], "planners": ["prioritized"], "plans": [CIRCLE]}


# ----------------------------------------------------------------------------- the study file


@pytest.mark.parametrize("change,message", [
    ({"plans": [CIRCLE, "A"]},
     "plans[0] (c) is a fleet of 4 robots but plans[1] (A) is one robot: a study compares either single robots or "
     "fleets"),
    ({"plans": ["A"]}, "planners[0]: `prioritized` plans several robots together: it needs fleet problems"),
    ({"plans": None}, "planners[0]: `prioritized` plans several robots together"),
    ({"planners": ["fmm", {"name": "corner", "waypoints": [[0.9, 0.7]]}]},
     "planners[1]: `waypoints` is an explicit path for one robot"),
    ({"jitter": {"xy_m": 0.005}}, "`jitter`: multi-robot jobs take no start-pose jitter"),
    ({"plans": [CIRCLE, CIRCLE]}, "plans[1] repeats the name of plans[0] (c)"),
    ({"plans": [{"name": "c", "circle": {"robots": 16, "radius_m": 0.2}}]},
     "plans[0].circle: 16 robots on a circle of radius 0.2 m stand 0.078 m apart; two robots need 0.130 m between "
     "their centres (a radius of at least 0.333 m)"),
    ({"plans": [{"name": "c", "circle": {"robots": 65, "radius_m": 1.5}}], "field": "full"},
     "plans[0].circle.robots must be an integer from 2 to 64, got 65"),
    ({"plans": [{"name": "c", "circle": {"robots": 17, "radius_m": 0.6}}]},
     "plans[0] (c) has 17 robots: a sub-field holds at most 16 (use \"field\": \"full\" for up to 64)"),
    ({"plans": [{"name": "c", "circle": {"robots": 1, "radius_m": 0.6}}]}, "plans[0].circle.robots must be"),
    ({"plans": [{"name": "c", "circle": {"robots": 4, "radius_m": 0}}]},
     "plans[0].circle.radius_m must be a number > 0 (m), got 0"),
    ({"plans": [{"name": "c", "circle": {"robots": 4, "radius_m": 0.6, "center": [1, 1]}}]},
     "plans[0].circle: unknown key(s) center (allowed: centre, radius_m, robots)"),
    ({"plans": [{"name": "c", "circle": {"robots": 4, "radius_m": 0.6, "centre": [1]}}]},
     "plans[0].circle.centre must be [x, y] (m)"),
    ({"plans": [{"name": "c", "robots": [{"start": [0.3, 0.3], "goal": [1.5, 1.5]}]}]},
     "plans[0].robots must be a list of 2 to 64"),
    ({"plans": [{"name": "c", "robots": [{"start": [0.3, 0.3], "goal": [1.5, 1.5]},
                                         {"start": [0.35, 0.3], "goal": [0.3, 1.5]}]}]},
     "plans[0].robots[1].start is 0.050 m from plans[0].robots[0].start: two robots need 0.130 m"),
    ({"plans": [{"name": "c", "robots": [{"start": [0.3, 0.3], "goal": [1.5, 1.5]},
                                         {"start": [1.5, 0.3], "goal": [0.3, "north"]}]}]},
     "plans[0].robots[1].goal must be [x, y] or [x, y, theta] (m, rad)"),
    ({"plans": [{"name": "c", "robots": [{"start": [0.3, 0.3], "goal": [1.5, 1.5], "path": []},
                                         {"start": [1.5, 0.3], "goal": [0.3, 1.5]}]}]},
     "plans[0].robots[0]: unknown key(s) path"),
    ({"plans": [{"name": "c", "start": [0.3, 0.3], "goal": [1.5, 1.5], "circle": CIRCLE["circle"]}]},
     "plans[0] must be a plan name, {\"name\", \"start\", \"goal\"}, {\"name\", \"robots\"} or {\"name\", "
     "\"circle\"}: give one of circle, start/goal, not both"),
    ({"plans": [{"name": "c", "circle": CIRCLE["circle"], "seed": 1}]},
     "plans[0]: unknown key(s) seed (allowed: name, circle)"),
])
def test_bad_fleet_study_files_name_the_file_and_the_field(tmp_path, change, message):
    f = tmp_path / "fleet.json"
    f.write_text(json.dumps({k: v for k, v in {**BASE, **change}.items() if v is not None}))
    with pytest.raises(StudySpecError) as err:
        load_spec(f)
    assert str(err.value).startswith(f"{f}: ") and message in str(err.value), str(err.value)


def test_a_fleet_study_file_round_trips_and_plans_fleet_jobs():
    spec = StudySpec.from_json({**SMALL, "plans": [*SMALL["plans"], {"name": "pair", "robots": [
        {"start": [0.3, 0.3, 0.7854], "goal": [1.5, 1.5]}, {"start": [1.5, 1.5], "goal": [0.3, 0.3]}]}]})
    assert spec.fleet and [p.robot_count for p in spec.plans] == [2, 4, 2]
    assert StudySpec.from_json(json.loads(json.dumps(spec.to_json()))) == spec
    jobs = plan_jobs(spec, {"swap": Environment.from_json(SWAP)})
    assert [(j["plan"], j["configuration"], j["robots"]) for j in jobs] == [
        (p, c, n) for p, n in (("circle-2", 2), ("circle-4", 4), ("pair", 2)) for c in ("prioritized", "fmm")]
    body = jobs[2]["body"]
    assert "start" not in body and "goal" not in body and body["planner"] == "prioritized"
    assert body["robots"] == circle_robots(4, 0.6, (0.9, 0.9))
    assert jobs[5]["body"]["robots"][0] == {"start": [0.3, 0.3, 0.7854], "goal": [1.5, 1.5]}
    assert not StudySpec.from_json({"environments": ["room"], "planners": ["fmm"], "plans": ["A"]}).fleet


def test_the_example_fleet_study_has_explicit_and_generated_fleets():
    spec = load_spec(ROOT / "examples" / "studies" / "fleet-swap.json")
    jobs = plan_jobs(spec, {"swap": Environment.from_json(SWAP)})
    assert [(j["plan"], j["robots"]) for j in jobs] == [("swap4", 4)] * 2 + [("circle-8", 8)] * 2
    assert [r["start"] for r in jobs[0]["body"]["robots"]] == [p["start"] for p in SWAP["plans"]]


def test_the_ready_fleet_study_compares_lacam_and_prioritized_up_to_64_robots_on_the_whole_field():
    spec = load_spec("fleet")
    assert spec == StudySpec.from_json(FLEET) and spec.fleet and spec.field == "full"
    jobs = plan_jobs(spec, {"arena": Environment.from_json(ARENA)})
    assert len(jobs) == 15 and len(jobs) * spec.runs_per_experiment == 60
    assert {(j["robots"], j["configuration"]) for j in jobs} == {
        (n, c) for n in (4, 8, 16, 32, 64) for c in ("lacam", "prioritized", "fmm")}
    assert all(j["body"]["field"] == "full" for j in jobs)


def test_the_ready_fleet_study_among_discs_crosses_robot_counts_and_obstacle_scenarios():
    spec = load_spec("fleet-discs")
    assert spec == StudySpec.from_json(FLEET_DISCS) and spec.fleet
    jobs = plan_jobs(spec, {"swap": Environment.from_json(SWAP), "discs": Environment.from_json(DISCS)})
    assert len(jobs) == 12 and len(jobs) * spec.runs_per_experiment == 72
    assert {(j["environment"], j["robots"], j["configuration"]) for j in jobs} == {
        (e, n, c) for e in ("swap", "discs") for n in (2, 4, 8) for c in ("prioritized", "fmm")}
    # every robot starts and ends clear of the discs' ways (they stay within 0.4 m of the centre)
    for job in jobs:
        for r in job["body"]["robots"]:
            for pose in (r["start"], r["goal"]):
                assert math.hypot(pose[0] - 0.9, pose[1] - 0.9) == pytest.approx(0.6)


# ----------------------------------------------------------------------------- the circle


def test_the_circle_puts_four_robots_at_exact_positions_facing_the_centre():
    robots = circle_robots(4, 0.6, (0.9, 0.9))
    assert robots == [
        {"start": [1.5, 0.9, math.pi], "goal": [0.3, 0.9, math.pi]},
        {"start": [0.9, 1.5, -math.pi / 2], "goal": [0.9, 0.3, -math.pi / 2]},
        {"start": [0.3, 0.9, 0.0], "goal": [1.5, 0.9, 0.0]},
        {"start": [0.9, 0.3, math.pi / 2], "goal": [0.9, 1.5, math.pi / 2]},
    ]


@pytest.mark.parametrize("n", [*range(2, 17), 32, 64])
def test_the_circle_geometry(n):
    radius, centre = (0.7, np.array([0.9, 1.0])) if n <= 16 else (1.55, np.array([1.8, 1.8]))  # the whole field
    robots = circle_robots(n, radius, centre)
    start = np.array([r["start"] for r in robots])
    goal = np.array([r["goal"] for r in robots])
    assert start.shape == goal.shape == (n, 3)
    angles = 2 * np.pi * np.arange(n) / n
    assert np.allclose(start[:, :2], centre + radius * np.column_stack([np.cos(angles), np.sin(angles)]), atol=1e-9)
    assert np.allclose(goal[:, :2], 2 * centre - start[:, :2], atol=1e-9)  # antipodal
    towards = (centre - start[:, :2]) / radius
    assert np.allclose(np.column_stack([np.cos(start[:, 2]), np.sin(start[:, 2])]), towards, atol=1e-8)
    assert np.all((start[:, 2] > -np.pi) & (start[:, 2] <= np.pi)) and np.array_equal(start[:, 2], goal[:, 2])
    for pts in (start[:, :2], goal[:, :2]):  # clear of each other: neighbours 2 r sin(pi / n) apart
        d = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
        d[np.diag_indices(n)] = np.inf
        assert d.min() == pytest.approx(2 * radius * math.sin(math.pi / n))
        assert d.min() > SEPARATION_M


def test_the_full_field_takes_a_circle_of_64_robots():
    spec = StudySpec.from_json({**BASE, "field": "full", "plans": [{"name": "c64", "circle": {"robots": 64,
                                                                                             "radius_m": 1.55}}]})
    assert spec.plans[0].robot_count == 64


def test_the_separation_is_the_planners_robot_radius_with_the_margin():
    from planners.api import DEFAULT_PLANNING_MARGIN, DEFAULT_ROBOT_RADIUS

    assert SEPARATION_M == pytest.approx(2 * (DEFAULT_ROBOT_RADIUS + DEFAULT_PLANNING_MARGIN))


# ----------------------------------------------------------------------------- how a fleet's run ended


@pytest.mark.parametrize("outcome,metrics,kind", [
    ("success", {}, "success"),
    ("collision", {"collisions_robot": 2, "collisions_moving": 1}, "robot-robot collision"),
    ("collision", {"collisions_robot": 0, "collisions_moving": 1, "collisions_static": 1}, "moving-obstacle collision"),
    ("collision", {"collisions_static": 1}, "block/wall collision"),
    ("timeout", {"deadlock": True}, "deadlock"),
    ("stalled", {"deadlock": True}, "deadlock"),
    ("timeout", {"deadlock": False}, "timeout"),
    ("planning", {}, "planning"),
    ("error", {}, "error"),
])
def test_a_fleet_run_ends_in_its_gravest_kind(outcome, metrics, kind):
    assert fleet_outcome(outcome, metrics) == kind


def test_a_fleet_row_renames_the_robot_share_and_lists_each_robot():
    metrics = {"success_rate": 0.5, "makespan_s": None, "collisions_robot": 1, "settings": {"dt": 0.02},
               "robots": [{"done": True}, {"done": False, "collision": "robot", "outcome": "COLLISION"}]}
    row = fleet_row(2, "collision", metrics)
    assert row == {"robots": 2, "fleet_outcome": "robot-robot collision", "robot_success_rate": 0.5,
                   "makespan_s": None, "collisions_robot": 1, "robots_arrived": 1, "robot_ends": "arrived hit-robot"}


# ----------------------------------------------------------------------------- a study through a real testbed


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


@pytest.fixture(scope="module")
def fleet_dir(testbed, tmp_path_factory):
    r, out = study_process(testbed, SMALL, tmp_path_factory.mktemp("fleet-study"), "--no-progress")
    assert r.returncode == 0, r.stderr  # failed runs (the uncoordinated fleets' crashes) are results
    assert "study fleet-small: 8/16 runs completed, 8 failed (collision 8)" in r.stdout, r.stdout
    assert "paper's findings" not in r.stdout  # they concern one robot: not checked, not written
    assert not (out / "findings.md").exists() and not (out / "findings.json").exists()
    return out


def test_a_fleet_study_counts_every_run_by_how_it_ended(fleet_dir):
    data = load_study(fleet_dir)
    assert len(data.rows) == 16 and all(r["status"] in ("completed", "failed") for r in data.rows)
    by = {(r["configuration"], r["plan"], r["mode"]): r["fleet_outcome"] for r in data.rows}
    assert {v for (c, *_), v in by.items() if c == "prioritized"} == {"success"}
    assert {v for (c, *_), v in by.items() if c == "fmm"} == {"robot-robot collision"}  # they meet in the centre
    fmm4 = next(r for r in data.rows if (r["configuration"], r["plan"]) == ("fmm", "circle-4"))
    assert fmm4["robots"] == 4 and fmm4["robots_arrived"] == 0 and fmm4["collisions_robot"] == 4
    assert fmm4["robot_ends"] == "hit-robot hit-robot hit-robot hit-robot" and fmm4["makespan_s"] is None
    with open(fleet_dir / "fleet_outcomes.csv") as f:
        outcomes = list(csv.DictReader(f))
    assert len(outcomes) == 2 * 2 * 2  # configuration x robot count x mode
    for row in outcomes:  # never silently dropped: every run is in one column
        assert sum(int(row[k]) for k in (*FLEET_KINDS, "other", "not_counted")) == int(row["runs"]) == 2
    fmm = [row for row in outcomes if row["configuration"] == "fmm"]
    assert all(row["robot-robot collision"] == "2" and row["success_rate"] == "0.0" for row in fmm)
    twb2 = next(row for row in outcomes if (row["configuration"], row["plan"], row["mode"]) ==
                ("prioritized", "circle-2", "twb"))
    assert twb2["success"] == "2" and float(twb2["ci_low"]) == pytest.approx(0.342, abs=1e-3)  # Wilson, 2/2


def test_a_fleet_study_reports_the_fleet_metrics_with_intervals(fleet_dir):
    summary = (fleet_dir / "summary.md").read_text()
    assert "## Fleet outcomes per configuration, environment and robot count" in summary
    assert "| fmm | swap | 4 | twb | 2 | 0 | 2 | 0 | 0 | 0 | 0 | 0 | 0 | 0/2 (95% CI 0–66 %) |" in summary
    assert "makespan (s) [completed]" in summary and "closest approach (m) [measured]" in summary
    # the metrics table (after the outcomes): the field's two repetitions differ, a mean with its t interval over
    # both; the simulation's repeat themselves and count once
    row = [line for line in summary.splitlines() if line.startswith("| prioritized | swap | 4 | twb |")][-1]
    assert row.count("(n = 2)") >= 4 and " [" in row, row
    row = [line for line in summary.splitlines() if line.startswith("| prioritized | swap | 4 | sim |")][-1]
    assert "(n = 1)" in row and "(n = 2)" not in row, row
    assert "- prioritized got every robot to its goal in 4 of 4 runs (95% CI 51–100 %)." in summary
    assert "- FMM got every robot to its goal in 0 of 4 runs (95% CI 0–49 %); collided 4 times." in summary
    # two repetitions a side give a paired t but no bootstrap interval: said so, never "+nan" (whether a metric is
    # also significant, and so gets a sentence of its own, depends on the field's noise)
    assert "fewer than 5 values a side: too few to bootstrap an interval" in summary
    assert "nan" not in summary.lower()
    with open(fleet_dir / "fleet.csv") as f:
        metrics = list(csv.DictReader(f))
    makespan = [m for m in metrics if m["metric"] == "makespan_s" and m["mode"] == "twb"
                and m["configuration"] == "prioritized"]
    assert len(makespan) == 2 and all(m["n"] == "2" and m["over"] == "completed" for m in makespan)
    assert all(float(m["ci_low"]) <= float(m["mean"]) <= float(m["ci_high"]) for m in makespan)
    closest = [m for m in metrics if m["metric"] == "robot_distance_min_m" and m["configuration"] == "fmm"]
    assert all(m["over"] == "measured" and float(m["mean"]) < 0.1 for m in closest)  # crashed fleets, measured
    with open(fleet_dir / "comparisons.csv") as f:
        compared = {(row["metric"], row["mode"]): row for row in csv.DictReader(f)}
    assert {m for m, _ in compared} == {"success_rate", "makespan_s", "time_sum_s", "path_length_sum_m",
                                        "robot_distance_min_m", "safety_time_s", "planning_time_s"}
    assert compared[("makespan_s", "twb")]["note"] == "no completed run of fmm"
    assert float(compared[("robot_distance_min_m", "twb")]["diff"]) > 0.05  # prioritized keeps them apart


def test_the_server_compares_a_fleet_studys_experiments_as_the_study_does(testbed, fleet_dir):
    """GET /api/v1/comparisons of the fleet study's experiments in study order: its comparisons.csv, byte for byte
    (a fleet's runs flattened and compared as the study does: its metrics, the safety metrics over every measured
    run, their directions)."""
    import io

    from client_sdk.study._data import write_csv_stream
    from planners.comparisons import COLUMNS
    from planners.compared import FLEET_COMPARED

    ids = [e["experiment_id"] for e in json.loads((fleet_dir / "study.json").read_text())["experiments"]]
    with testbed.client() as c:
        r = c.get("/api/v1/comparisons", params={"experiments": ",".join(map(str, ids))})
    assert r.status_code == 200, r.text
    answer = r.json()
    buf = io.StringIO(newline="")
    write_csv_stream(buf, list(COLUMNS), answer["rows"])
    with open(fleet_dir / "comparisons.csv", newline="") as f:
        assert buf.getvalue() == f.read()
    assert answer["problems"] == ["swap circle-2", "swap circle-4"] and answer["metrics"] == list(FLEET_COMPARED)
    assert "every robot reached its goal" in answer["method"]


def test_a_fleet_studys_poses_plans_and_figures(fleet_dir):
    data = load_study(fleet_dir)
    exp = next(e for e in data.experiments if (e["configuration"], e["plan"]) == ("prioritized", "circle-4"))
    assert exp["robots"] == circle_robots(4, 0.6, (0.9, 0.9)) and len(exp["planned_paths"]) == 4
    run = next(r for r in data.rows if r["run_id"] in exp["runs"] and r["mode"] == "twb")
    assert (fleet_dir / "poses" / f"run-{run['run_id']}.csv").read_text().startswith("t,x,y,theta,robot\n")
    poses = data.poses(run["run_id"])
    assert poses.shape[1] == 5 and set(poses[:, 4]) == {0, 1, 2, 3}
    for k, r in enumerate(exp["robots"]):
        mine = poses[poses[:, 4] == k]
        assert math.dist(mine[-1, 1:3], r["goal"][:2]) < 0.03
    figs = make_figures(data)
    assert set(figs) == {"fig5_outcomes", "fig6_fleet_metrics", "fig8_fleet_paths"}
    # the outcomes by kind: the uncoordinated fleets' robot-robot collisions
    assert {t.get_text() for t in figs["fig5_outcomes"].legends[0].get_texts()} == {"success", "robot-robot collision"}
    assert len(figs["fig6_fleet_metrics"].axes) == 3 * 1  # metrics x environments
    assert len(figs["fig8_fleet_paths"].axes) == 2 * 4  # problems x (configurations x modes)
    titles = [ax.get_title() for ax in figs["fig8_fleet_paths"].axes]
    assert titles[:4] == ["swap circle-2 · prioritized · T", "swap circle-2 · prioritized · S",
                          "swap circle-2 · FMM · T", "swap circle-2 · FMM · S"]
    for name, fig in figs.items():
        for ext in ("png", "svg"):
            assert (fleet_dir / f"{name}.{ext}").stat().st_size > 1000
        fig.canvas.draw()  # the legend and the title fit the figure (one environment: a narrow one)
        for artist in (fig.legends[0], fig._suptitle):
            box = artist.get_window_extent()
            assert 0 <= box.x0 and box.x1 <= fig.bbox.width, (name, type(artist).__name__)
    assert "fleet.csv" in (fleet_dir / "report.html").read_text()


def test_a_fleet_study_exports_to_ompl_without_progress(fleet_dir, tmp_path):
    import sqlite3

    done = export_ompl(load_study(fleet_dir), tmp_path / "fleet.db")
    assert done["runs"] == 16 and done["progress"] == 0
    con = sqlite3.connect(tmp_path / "fleet.db")
    setup = json.loads(con.execute("SELECT setup FROM experiments WHERE name = 'swap-circle-4'").fetchone()[0])
    # the fleet's plan is every robot's path: solved where all were planned, no one path's length
    runs = con.execute("SELECT status, solved, solution_length FROM runs").fetchall()
    con.close()
    assert setup["robots"] == circle_robots(4, 0.6, (0.9, 0.9))
    assert (6, 1) in {r[:2] for r in runs} and all(solved == (status == 6) for status, solved, _ in runs if status)
    assert all(length is None for *_, length in runs)


#: one fleet of two in the empty sub-field and one among the moving discs, simulation and field, once each
AMONG_DISCS = {"name": "fleet-discs", "environments": ["swap", DISCS],
               "plans": [{"name": "circle-2", "circle": {"robots": 2, "radius_m": 0.6}}],
               "planners": ["prioritized"], "repetitions": 1, "modes": ["sim", "twb"], "seed": 3}
TRACKED, EXACT = "moving obstacle (tracked)", "moving obstacle (exact track)"


def _panel(fig, title: str):  # type: ignore[no-untyped-def]
    return next(ax for ax in fig.axes if ax.get_title() == title)


def _obstacle_labels(ax) -> set[str]:  # type: ignore[no-untyped-def]
    return {line.get_label() for line in ax.get_lines()} & {TRACKED, EXACT}


def test_a_study_keeps_and_draws_a_field_runs_tracked_obstacle_robots(monkeypatch, testbed, tmp_path):
    """The field run among moving discs: its obstacle robots as the server stored them go to obstacles/ (asked
    for that run alone), are read back, and its panel of Fig. 8 draws them where the tracker saw them; the
    simulation's panel draws the exact tracks, and so does a study directory without obstacles/ (an older one)."""
    out = tmp_path / "out"
    with Client(testbed.url, token=testbed.token) as client:
        asked: list[int] = []
        get = client.get_obstacles
        monkeypatch.setattr(client, "get_obstacles", lambda run_id: asked.append(run_id) or get(run_id))
        data = run_study(client, StudySpec.from_json(AMONG_DISCS), progress=False, out=out)
        runs = {(r["environment"], r["mode"]): r["run_id"] for r in data.rows}
        field = runs[("discs", "twb")]
        assert asked == [field]  # not for the simulations, nor for the environment without moving obstacles
        served = get(field)
    assert not served.exact and len(served.tracks) == 2 and all(len(tr) > 10 for tr in served.tracks)
    assert sorted(f.name for f in (out / "obstacles").iterdir()) == [f"run-{field}.csv"]
    assert (out / "obstacles" / f"run-{field}.csv").read_text().startswith("obstacle,t,x,y,theta,radius\n")
    kept = load_study(out).obstacles(field)
    assert not kept.exact and kept.radii == served.radii
    assert [tr.shape for tr in kept.tracks] == [tr.shape for tr in served.tracks]
    for mine, theirs in zip(kept.tracks, served.tracks):
        assert np.allclose(mine, theirs, rtol=0, atol=5e-6)  # the file keeps 10 µm, 10 µs
    assert [load_study(out).obstacles(runs[k]) for k in runs if k != ("discs", "twb")] == [None] * 3

    fig = figure_fleet_paths(load_study(out))
    panel = _panel(fig, "discs circle-2 · prioritized · T")
    assert _obstacle_labels(panel) == {TRACKED}
    lines = [line.get_xydata() for line in panel.get_lines()]
    discs = [(p.center, p.radius) for p in panel.patches if hasattr(p, "center")]
    for tr, radius in zip(kept.tracks, kept.radii):  # each path where the tracker saw it, its disc at the first pose
        assert any(xy.shape == tr[:, 1:3].shape and np.array_equal(xy, tr[:, 1:3]) for xy in lines)
        assert any(np.array_equal(c, tr[0, 1:3]) and r == radius for c, r in discs)
    assert _obstacle_labels(_panel(fig, "discs circle-2 · prioritized · S")) == {EXACT}
    assert not _obstacle_labels(_panel(fig, "swap circle-2 · prioritized · T"))
    assert {TRACKED, EXACT} <= {t.get_text() for t in fig.legends[0].get_texts()}
    assert "obstacle robots as the tracker saw them in <code>obstacles/</code>" in report_html(load_study(out), [])

    # saved elsewhere, the obstacle robots go along; a study directory without obstacles/ draws exact tracks
    copy = tmp_path / "copy"
    load_study(out).save(copy)
    assert (copy / "obstacles" / f"run-{field}.csv").read_bytes() == (out / "obstacles" / f"run-{field}.csv").read_bytes()
    for f in (copy / "obstacles").iterdir():
        f.unlink()
    (copy / "obstacles").rmdir()
    older = load_study(copy)
    assert older.obstacles(field) is None
    fig = figure_fleet_paths(older)
    assert _obstacle_labels(_panel(fig, "discs circle-2 · prioritized · T")) == {EXACT}
    assert TRACKED not in {t.get_text() for t in fig.legends[0].get_texts()}


def test_a_circle_that_does_not_fit_the_environment_is_refused_before_anything_runs(capsys, monkeypatch, testbed,
                                                                                     tmp_path):
    small = {"name": "box", "size": [1.0, 1.0], "blocks": []}
    f = tmp_path / "s.json"
    f.write_text(json.dumps({**SMALL, "environments": [small]}))
    r = invoke(capsys, monkeypatch, "study", str(f), "--url", testbed.url, "--token", testbed.token, "--out",
               str(tmp_path / "o"), "--no-progress")
    assert r.returncode == 2 and r.stderr.count("twb: refused: plan 'circle-2': its circle of radius 0.6 m does not "
                                                "fit in environment 'box' (1 x 1 m)") == 1, r.stderr
