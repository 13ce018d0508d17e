"""Multi-robot jobs (docs/server.md, "Multi-robot jobs") through a real `twb up`: POST /experiments with `robots`, one
task per run, poses per robot, the fleet's metrics, failures naming the robots, 422s naming the field, the SDK and
`twb submit FILE`.

(The migration's way up and down: tests/test_migrations.py; the fleet simulation and its metrics without a server:
tests/test_fleet.py.)
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from client_sdk import Client
from client_sdk.study import StudySpec, check_study
from contract.params import robot_params
from server.core.settings import Settings
from robot_agent.engine import jobs
from server.pipeline.fleet import fleet_failure, fleet_timeout_s
from servers import STANDARD, submit_watched, wait_for

ROOT = Path(__file__).resolve().parents[1]
RADIUS = robot_params().collision_radius_m
JOBS = {name: json.loads((ROOT / "examples" / "fleet" / f"swap-{name}.json").read_text())
        for name in ("prioritized", "uncoordinated")}
TWO = [{"start": [0.3, 0.3], "goal": [1.5, 1.5]}, {"start": [1.5, 0.3], "goal": [0.3, 1.5]}]


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


@pytest.fixture(scope="module")
def client(testbed):
    with testbed.client() as c:
        yield c


@pytest.fixture(scope="module")
def prioritized(client):
    """The prioritized swap in simulation, finished: (experiment, its run)."""
    exp = wait_for(client, client.post("/api/v1/experiments", json=JOBS["prioritized"]).json()["id"], timeout=120)
    return exp, exp["runs"][0]


def poses(client, run_id: int, **params) -> np.ndarray:
    body = client.get(f"/api/v1/runs/{run_id}/poses", params=params).json()
    return np.array(body["poses"], dtype=float).reshape(-1, len(body["columns"]))


def lines(client, run_id: int) -> list[str]:
    return [m["line"] for m in client.get(f"/api/v1/runs/{run_id}/messages", params={"limit": 5000}).json()["data"]]


def test_the_prioritized_swap_completes_with_the_robots_apart_and_poses_per_robot(client, prioritized):
    exp, run = prioritized
    assert exp["status"] == "completed" and run["status"] == "completed", exp
    assert exp["robots"] == JOBS["prioritized"]["robots"] and exp["start"] == exp["robots"][0]["start"]
    m = run["metrics"]
    assert m["robot_distance_min_m"] > 2 * RADIUS and m["success_rate"] == 1.0 and m["makespan_s"] > 0
    assert not m["collided"] and m["collisions_robot"] == 0 and [r["outcome"] for r in m["robots"]] == ["DONE"] * 4
    assert run["t_start"] == 0.0 and run["t_end"] == pytest.approx(m["makespan_s"])
    # the plan: robot 0's as the planned path, every robot's in the planning info
    assert exp["planned_path"] == exp["planning_info"]["robots"][0]["path"] and len(exp["planning_info"]["robots"]) == 4
    every = poses(client, run["id"])
    assert every.shape[1] == 5 and set(every[:, 4]) == {0, 1, 2, 3}
    for k, r in enumerate(JOBS["prioritized"]["robots"]):
        mine = poses(client, run["id"], robot=k)
        assert set(mine[:, 4]) == {k} and np.array_equal(mine, every[every[:, 4] == k])
        assert np.all(np.diff(mine[:, 0]) > 0)  # oldest first
        assert np.hypot(*(mine[-1, 1:3] - r["goal"][:2])) < 0.02
    csv = client.get(f"/api/v1/runs/{run['id']}/poses", params={"format": "csv", "robot": 3}).text.splitlines()
    assert csv[0] == "t,x,y,theta,robot" and all(row.endswith(",3") for row in csv[1:]) and len(csv) > 10
    log = lines(client, run["id"])
    assert log[0].startswith("a multi-robot run of 4 ideal robots")
    for k in range(4):
        mine = [x for x in log if x.startswith(f"robot {k}: ")]
        assert mine[0].startswith(f"robot {k}: T,T,P,") and mine[-1].startswith(f"robot {k}: EV,DONE,")


def direct(client, exp: dict, run: dict) -> dict:
    """jobs.fleet_job called here with the run's arguments."""
    env = client.get(f"/api/v1/environments/{exp['environment']}").json()
    platform = next(r["platform"] for r in client.get("/api/v1/robots").json()["data"] if r["robot_id"] == run["robot_id"])
    timeout_s = fleet_timeout_s(SimpleNamespace(settings=Settings()), exp["robots"])
    return jobs.fleet_job({k: env[k] for k in ("name", "size", "blocks", "plans", "description")}, exp["robots"],
                             exp["planner"], exp["planner_params"], run["seed"], timeout_s,
                             exp["robot_radius"] + exp["planning_margin"], "ideal", exp["controller"],
                             exp["controller_params"], platform or "BeBot", None, run["planner_seed"])


def test_the_same_seed_gives_the_same_poses_as_the_task_run_directly(client, prioritized):
    """jobs.fleet_job called here with the run's arguments: the server's stored poses, bit for bit."""
    exp, run = prioritized
    assert exp["planner_params"]["execution"] == "dependencies"  # the default, shown
    out = direct(client, exp, run)
    for k, r in enumerate(out["robots"]):
        assert np.array_equal(poses(client, run["id"], robot=k)[:, :4], r["poses"]), k
    assert out["metrics"]["robot_distance_min_m"] == run["metrics"]["robot_distance_min_m"]


def test_the_planner_list_offers_prioritized_with_the_parameters_a_fleet_job_takes(testbed, client, prioritized):
    """`GET /api/v1/planners` lists `prioritized` as the planner of multi-robot jobs only, its defaults those a job
    without `planner_params` is given; so a study may set any of them (`execution` too) and is not refused."""
    exp, _ = prioritized
    listed = {p["name"]: p for p in client.get("/api/v1/planners").json()["data"]}
    assert listed["prioritized"]["fleet_only"] is True and listed["prioritized"]["description"]
    assert {name for name, p in listed.items() if p["fleet_only"]} == {"prioritized", "lacam"}
    assert listed["lacam"]["defaults"] == {"cell": 0.15, "speed": 0.18, "time_limit_s": 5.0, "refine": 2000,
                                           "swap": True}
    assert listed["prioritized"]["defaults"] == exp["planner_params"]
    spec = StudySpec.from_json({"name": "timed", "environments": ["swap"], "modes": ["sim"],
                                "plans": [{"name": "circle-2", "circle": {"robots": 2, "radius_m": 0.6}}],
                                "planners": [{"name": "prioritized", "params": {"execution": "timed", "wait": False}},
                                             "fmm"]})
    with Client(testbed.url, testbed.token) as c:
        assert check_study(c, spec, limits={}) == []
        spec.planners[0].params["speed_m_s"] = 0.1
        assert check_study(c, spec, limits={}) == [
            f"planner 'prioritized' has no parameter(s) speed_m_s (its parameters: {', '.join(sorted(exp['planner_params']))})"]


def test_a_job_can_have_its_prioritized_plan_executed_by_the_clock(client, prioritized):
    """`planner_params.execution: "timed"`: the same plan kept by the clock alone (docs/planners.md), as
    fleet_job's `execution="timed"` drives it, and not as the default (in the plan's order of passing) does."""
    job = {**JOBS["prioritized"], "planner_params": {"execution": "timed"}}
    exp = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=120)
    run = exp["runs"][0]
    assert exp["planner_params"]["execution"] == "timed" and run["status"] == "completed", exp
    out = direct(client, exp, run)
    by_deps = poses(client, prioritized[1]["id"])
    for k, r in enumerate(out["robots"]):
        assert np.array_equal(poses(client, run["id"], robot=k)[:, :4], r["poses"]), k
    assert not np.array_equal(poses(client, run["id"]), by_deps)


def test_a_lacam_fleet_job_plans_together_and_completes(client):
    """`"planner": "lacam"`: the swap's four robots planned on the grid and driven by the order of passage."""
    body = {**JOBS["prioritized"], "planner": "lacam"}
    exp = wait_for(client, client.post("/api/v1/experiments", json=body).json()["id"], timeout=180)
    assert exp["status"] == "completed", exp
    assert exp["planner_params"] == {"cell": 0.15, "speed": 0.18, "time_limit_s": 5.0, "refine": 2000, "swap": True}
    m = client.get(f"/api/v1/runs/{exp['runs'][0]['id']}").json()["metrics"]
    assert m["success_rate"] == 1.0 and m["collisions_robot"] == 0 and m["planning_time_s"] > 0


def test_the_uncoordinated_swap_fails_with_its_collisions_counted_and_measured(client):
    exp = wait_for(client, client.post("/api/v1/experiments", json=JOBS["uncoordinated"]).json()["id"], timeout=120)
    run = exp["runs"][0]
    assert exp["status"] == "failed" and run["status"] == "failed" and run["failure"] == "collision", exp
    assert run["error"].startswith("collision: robot 0 hit robot ") and run["error"].count(" hit robot ") == 4
    assert "collision at (0.8" in exp["error"]  # where the first robot stopped, near the centre
    m = run["metrics"]  # measured although failed
    assert m["collided"] and m["collisions_robot"] == 4 and m["success_rate"] == 0.0 and m["makespan_s"] is None
    assert m["robot_distance_min_m"] < 2 * RADIUS + 0.01
    assert [r["collision"] for r in m["robots"]] == ["robot"] * 4
    assert set(poses(client, run["id"])[:, 4]) == {0, 1, 2, 3}
    got = client.get(f"/api/v1/experiments/{exp['id']}/metrics").json()
    assert got["runs"][0]["outcome"] == "collision" and got["direct"] == []


def test_a_robot_the_planner_finds_no_way_for_fails_the_experiment_as_a_whole(client):
    """Robot 0 parks in the doorway for good; robot 1, planned after it, cannot pass: the first run's planning
    fails, and the experiment's other runs fail with it without planning again."""
    door = {"name": "door", "size": [1.8, 1.0], "blocks": [{"x": 0.9, "y": 0.2, "w": 0.06, "h": 0.4},
                                                           {"x": 0.9, "y": 0.8, "w": 0.06, "h": 0.4}]}
    assert client.post("/api/v1/environments", json=door).status_code == 201
    job = {"environment": "door", "planner": "prioritized", "modes": ["sim", "twb"], "repetitions": 2,
           "robots": [{"start": [0.3, 0.5], "goal": [0.9, 0.5]}, {"start": [1.5, 0.5], "goal": [0.3, 0.5]}]}
    exp = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=120)
    assert exp["status"] == "failed" and exp["error"].startswith("planning failed: robot 1 (of 2, planned in order)"), exp
    assert [r["failure"] for r in exp["runs"]] == ["planning"] * 4 and exp["planned_path"] is None
    assert all(r["metrics"] == {} for r in exp["runs"])


def test_a_randomised_planner_plans_each_repetitions_fleet_with_its_planner_seed(client):
    """PRM plans each robot alone with the run's planner seed: both modes of a repetition drive the same paths,
    the repetitions their own draws, as fleet_job plans them with that seed; a fleet's planning is timed."""
    from server.store.experiments import planner_seed

    pillars = {"name": "pillars", "size": [1.8, 1.8], "blocks": [{"x": 0.4, "y": 0.9, "w": 0.3, "h": 0.3},
                                                                 {"x": 1.4, "y": 0.9, "w": 0.3, "h": 0.3}]}
    assert client.post("/api/v1/environments", json=pillars).status_code == 201
    apart = [{"start": [0.4, 0.3], "goal": [0.4, 1.5]}, {"start": [1.4, 0.3], "goal": [1.4, 1.5]}]  # around them
    job = {"environment": "pillars", "planner": "prm", "modes": ["sim", "twb"], "repetitions": 2, "seed": 5,
           "robots": apart}
    exp = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=180)
    assert exp["planner_stochastic"] is True and all(r["planned_path"] for r in exp["runs"]), exp
    reps = {}
    for r in exp["runs"]:
        assert r["planner_seed"] == planner_seed(5, r["repetition"])
        assert r["planning_time_s"] > 0 and r["planning_cpu_s"] > 0 and r["planning_repeats"] == 1
        reps.setdefault(r["repetition"], []).append(r["planned_path"])
    assert reps[1][0] == reps[1][1] and reps[2][0] == reps[2][1] and reps[1][0] != reps[2][0]
    sim1 = next(r for r in exp["runs"] if r["mode"] == "sim" and r["repetition"] == 1)
    assert direct(client, exp, sim1)["robots"][0]["path"] == sim1["planned_path"]


@pytest.mark.parametrize("job, detail", [
    ({"robots": [TWO[0], {"start": [0.35, 0.3], "goal": [0.3, 1.5]}]},
     r"robots[1].start is 0.050 m from robots[0].start"),
    ({"robots": [{"start": [0.1 * i + 0.2, 0.3], "goal": [0.1 * i + 0.2, 1.5]} for i in range(17)]},
     'robots: a multi-robot job has 2 to 16 robots, got 17; a sub-field holds at most 16 (use "field": "full"'),
    ({"robots": [{"start": [0.05 * i + 0.2, 0.3], "goal": [0.05 * i + 0.2, 1.5]} for i in range(65)], "field": "full"},
     "robots: List should have at most 64 items"),
    ({"robots": TWO[:1]}, "robots: List should have at least 2 items"),
    ({"environment": "room", "robots": [TWO[0], {"start": [0.9, 0.45], "goal": [0.3, 1.5]}]}, "robots[1].start: start"),
    ({"environment": "room", "robots": [TWO[0], {"start": [1.5, 0.3], "goal": [0.9, 0.45]}]}, "robots[1].goal: goal"),
    ({"robots": [TWO[0], {"start": [1.5, 0.3], "goal": [0.3, 1.5, "north"]}]}, "robots[1].goal[2]:"),
    ({"robots": [TWO[0], {"start": [1.5, 0.3], "goal": [0.3, 1.5], "path": [[1.5, 0.3], [0.3, 1.4]]}],
      "planner": None}, "robots[1].path must begin at robots[1].start and end at robots[1].goal"),
    ({"start": [0.3, 0.3], "goal": [1.5, 1.5], "planner": "prioritized"}, "planner: `prioritized` plans several robots"),
    ({"robots": TWO, "start": [0.3, 0.3]}, "start: give either `start`/`goal` or `robots`, not both"),
    ({"robots": TWO, "path": [[0.3, 0.3], [1.5, 1.5]]}, "path: a multi-robot job takes each robot's path"),
    ({"robots": TWO, "program": 1}, "give either `planner` or `program`, not both"),
    ({"robots": [TWO[0], {**TWO[1], "path": [[1.5, 0.3], [0.3, 1.5]]}], "program": 1, "planner": None},
     "robots[1].path: the program sends every robot's path; give no `path`"),
    ({"robots": TWO, "controller_program": 1}, "controller_program: a controller program drives one robot"),
    ({"robots": [TWO[0], {**TWO[1], "path": [[1.5, 0.3], [0.3, 1.5]]}], "planner": "prioritized"},
     "robots[1].path: `prioritized` plans every robot together"),
    ({"robots": TWO, "planner": "prioritized", "planner_params": {"speeed": 1}}, "planner_params: planner"),
    ({"robots": TWO, "planner": "prioritized", "planner_params": {"execution": "clock"}},
     "planner_params.execution: 'dependencies' or 'timed' (how the robots keep to the plan"),
    ({"robots": TWO, "planner": "prioritized", "controller": "regulated_pure_pursuit",
      "controller_params": {"replan": 1}}, "controller_params.replan: the robots of a prioritized plan"),
    ({"start": [0.3, 0.3], "goal": [1.5, 1.5], "planner": "lacam"}, "planner: `lacam` plans several robots"),
    ({"robots": TWO, "planner": "lacam", "planner_params": {"cell": 0.01}}, "planner_params: parameter lacam.cell"),
    ({"robots": TWO, "planner": "lacam", "planner_params": {"execution": "timed"}},
     "planner_params: planner 'lacam' has no parameter"),
    ({"robots": TWO, "planner": "lacam", "environment": "crossing"}, "planner: lacam plans among the blocks only"),
    # a probe's job whose 2 mm lattice grew its worker to 17.7 GB (the hardening issue, item 2)
    ({"robots": [{"start": [0.3, 0.3], "goal": [1.5, 1.5]}, {"start": [1.5, 1.5], "goal": [0.3, 0.3]}],
      "planner_params": {"cell": 0.002}}, "parameter prioritized.cell must be a number in [0.01, 0.5] (m), got 0.002"),
    ({"robots": TWO, "planner_params": {"horizon_s": 1e6}}, "parameter prioritized.horizon_s must be a number in"),
])
def test_bad_multi_robot_jobs_are_refused_naming_the_field(client, job, detail):
    body = {"environment": "swap", "planner": "prioritized", "modes": ["sim"], **job}
    if body.get("planner") is None:
        body.pop("planner")
    r = client.post("/api/v1/experiments", json=body)
    assert r.status_code == 422 and detail in r.json()["detail"], r.text


def test_a_multi_robot_program_job_needs_uploads(client):
    """Uploads are off on this testbed: a multi-robot job naming a program is refused as a single robot's is
    (tests/test_fleet_programs.py runs them where uploads are on)."""
    r = client.post("/api/v1/experiments", json={"environment": "swap", "robots": TWO, "program": 1, "modes": ["sim"]})
    assert r.status_code == 403 and r.json()["detail"] == "uploads are disabled on this testbed", r.text


def test_a_field_fleet_on_a_sub_field_is_the_emulated_field_robots_shown_live(testbed, client):
    """`twb` mode: the field robots of the run's sub-field, computed as one task; every robot's last pose is
    published live as robot "<field robot>/<k>" in field coordinates."""
    job = {**JOBS["prioritized"], "modes": ["twb"], "field": "sub"}
    exp, seen = submit_watched(testbed, client, job)
    run = exp["runs"][0]
    assert exp["status"] == "completed", exp
    assert run["robot_id"].startswith("field-") and run["subfield"] in (1, 2, 3, 4)
    assert run["metrics"]["robot_distance_min_m"] > 2 * RADIUS
    log = lines(client, run["id"])
    assert log[0].startswith("a multi-robot run of 4 emulated field robots (BeBot) on the field of field-")
    origin = next(r["origin"] for r in client.get("/api/v1/robots").json()["data"] if r["robot_id"] == run["robot_id"])
    live = {e["robot_id"]: e for e in seen if e["event"] == "pose" and e["run_id"] == run["id"]}
    assert set(live) == {f"{run['robot_id']}/{k}" for k in range(4)}, seen
    for k in range(4):
        mine, e = poses(client, run["id"], robot=k), live[f"{run['robot_id']}/{k}"]
        assert e["robot"] == k and e["t"] == mine[-1, 0]
        assert (e["x"], e["y"]) == pytest.approx((mine[-1, 1] + origin[0], mine[-1, 2] + origin[1]))


def test_a_field_job_counts_its_moving_obstacles_as_robots_of_the_field(client):
    """On the field each moving obstacle is a robot the testbed drives: 12 of them and 6 robots do not fit a
    sub-field's 16 (422 naming the field); 2 of them and 2 robots run, measured against the obstacle robots."""
    movers = [{"radius": 0.04, "speed": 0.1, "waypoints": [[0.2 + 0.1 * k, 1.6], [0.2 + 0.1 * k, 1.3]],
               "repeat": "pingpong"} for k in range(12)]
    for name, obstacles in (("twelve-movers", movers), ("two-movers", movers[:2])):
        env = {"name": name, "size": [1.8, 1.8], "blocks": [], "moving_obstacles": obstacles}
        assert client.post("/api/v1/environments", json=env).status_code == 201
    six = [{"start": [0.2 + 0.2 * k, 0.2], "goal": [0.2 + 0.2 * k, 0.8]} for k in range(6)]
    r = client.post("/api/v1/experiments", json={"environment": "twelve-movers", "robots": six, "planner": "astar",
                                                 "modes": ["sim", "twb"]})
    assert r.status_code == 422 and r.json()["detail"].startswith(
        "moving_obstacles: 12 moving obstacles and 6 robots need 18 robots of the field"), r.text
    job = {"environment": "two-movers", "robots": six[:2], "planner": "astar", "modes": ["twb"]}
    exp = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=120)
    run = exp["runs"][0]
    assert exp["status"] == "completed", (exp["error"], run["error"])
    m = run["metrics"]
    assert 0.3 < m["obstacle_distance_min_m"] < 1.0
    assert m["obstacle_distance_min_m"] == min(r["obstacle_distance_min_m"] for r in m["robots"])
    assert any("the 2 moving obstacle(s) are emulated BeBot robots the testbed drives" in line
               for line in lines(client, run["id"]))


def test_a_full_field_fleet_holds_the_whole_field(client):
    """`field: "full"`: the emulated field robots in the whole field's frame, the run on all four sub-fields;
    two robots pass each other in lanes 0.6 m apart across the middle of the field."""
    env = {"name": "open-field", "size": [3.6, 3.6], "blocks": []}
    assert client.post("/api/v1/environments", json=env).status_code == 201
    robots = [{"start": [0.4, 1.5], "goal": [3.2, 1.5]}, {"start": [3.2, 2.1], "goal": [0.4, 2.1]}]
    job = {"environment": "open-field", "robots": robots, "planner": "prioritized", "modes": ["twb"], "field": "full"}
    exp = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=180)
    run = exp["runs"][0]
    assert exp["status"] == "completed" and run["subfield"] is None, (exp["error"], run["error"])
    assert run["metrics"]["robot_distance_min_m"] > 2 * RADIUS and run["metrics"]["success_rate"] == 1.0
    for k, r in enumerate(robots):
        assert np.hypot(*(poses(client, run["id"], robot=k)[-1, 1:3] - r["goal"])) < 0.03
    assert client.post("/api/v1/experiments", json={**job, "field": "sub"}).json()["detail"].startswith("environment 'open-field' is 3.6 x 3.6 m; a sub-field job allows at most 1.8 x 1.8 m")


def test_the_whole_field_takes_more_robots_than_a_sub_field(client):
    """24 robots in lanes 0.14 m apart, each straight up the whole field (uncoordinated: A* each): more than a
    sub-field's 16, all arrive, none touches another."""
    if client.get("/api/v1/environments/open-field").status_code == 404:
        client.post("/api/v1/environments", json={"name": "open-field", "size": [3.6, 3.6], "blocks": []})
    robots = [{"start": [0.2 + 0.14 * i, 0.3, 1.5708], "goal": [0.2 + 0.14 * i, 3.3, 1.5708]} for i in range(24)]
    job = {"environment": "open-field", "robots": robots, "planner": "astar", "modes": ["sim"], "field": "full"}
    exp = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=180)
    (run,) = exp["runs"]
    assert exp["status"] == "completed", (exp["error"], run["error"])
    m = run["metrics"]
    assert len(m["robots"]) == 24 and m["success_rate"] == 1.0 and m["robot_distance_min_m"] > 2 * RADIUS
    assert len(np.unique(poses(client, run["id"])[:, 4])) == 24


def test_a_fleet_failure_names_each_robot_and_the_gravest_kind():
    still = np.array([[0.0, 0.5, 0.5, 0.0], [9.0, 0.5, 0.5, 0.0]])
    robots = [{"outcome": o, "obstacle": ob, "poses": still + [0, k, 0, 0]}
              for k, (o, ob) in enumerate([("DONE", None), ("TIMEOUT_SIM", None), ("STALLED", None),
                                           ("COLLISION", 1)])]
    metrics = {"robots": [{"collision": None}] * 3 + [{"collision": "moving"}], "deadlock": True,
               "no_progress_max_s": 7.5, "settings": {"progress_m": 0.01}}
    failure = fleet_failure(robots, metrics, 100.0)
    assert failure.kind == "collision" and failure.obstacle == 1
    assert str(failure) == ("collision: robot 1 did not reach its goal within 100 s of experiment time; robot 2 could "
                            "not make progress; robot 3 hit moving obstacle 1 (the environment's moving_obstacles[1]) "
                            "(deadlock: no robot under way moved 0.01 m for 7.5 s)")
    no_collision = fleet_failure(robots[:3], {**metrics, "robots": metrics["robots"][:3], "deadlock": False}, 100.0)
    assert no_collision.kind == "timeout" and str(no_collision).startswith("timeout: robot 1 did not")
    assert fleet_failure(robots[:1], metrics, 100.0) is None


def test_fleet_poses_go_in_by_each_databases_bulk_path(run_store):
    """A run's end with the robot column: COPY on PostgreSQL, executemany on SQLite; read back robot by robot."""
    from server.store.poses import add_poses, run_poses

    sessions = run_store
    t = np.arange(5) * 0.02
    rows = np.concatenate([np.column_stack([t, t + k, t, t, np.full(5, k)]) for k in (1, 0)])  # robot 1 first
    with sessions.begin() as s:
        add_poses(s, 1, rows)
        add_poses(s, 2, rows[:5, :4])  # one robot's: no robot column
    with sessions() as s:
        got = np.array(run_poses(s, 1, fleet=True))
        assert np.array_equal(got, np.concatenate([rows[5:], rows[:5]]))  # robot by robot, oldest first
        assert np.array_equal(np.array(run_poses(s, 1, robot=1)), rows[:5, :4])
        assert run_poses(s, 2, fleet=True) == [[*r, None] for r in rows[:5, :4].tolist()]


def test_the_sdk_and_twb_submit_take_multi_robot_jobs(testbed, twb, tmp_path):
    with Client(testbed.url, testbed.token) as c:
        exp = c.wait(c.submit("swap", robots=TWO, planner="prioritized", modes=["sim"], seed=3).id, timeout=120,
                     progress=False)
        assert exp.status == "completed" and exp.robots == TWO
        every = c.get_poses(exp.runs[0].id)
        one = c.get_poses(exp.runs[0].id, robot=1)
        assert every.shape[1] == 5 and np.array_equal(one, every[every[:, 4] == 1])
    auth = ["--url", testbed.url, "--token", testbed.token]
    out = twb("submit", str(ROOT / "examples" / "fleet" / "swap-prioritized.json"), "--wait", *auth)
    assert out.returncode == 0, out.stderr
    exp_id = out.stdout.split()[0]
    shown = twb("status", exp_id, "--wide", *auth)
    assert shown.returncode == 0 and "4 robots, robot 0" in shown.stdout and "makespan (s)" in shown.stdout, shown
    results = twb("results", exp_id, "--wide", *auth)
    assert results.returncode == 0 and "min robot dist." in results.stdout and "makespan" in results.stdout, results
    csv = twb("results", exp_id, "--csv", *auth)
    assert csv.returncode == 0 and "robot_distance_min_m" in csv.stdout.splitlines()[0], csv
    with Client(testbed.url, testbed.token) as c:
        run_id = str(c.get_experiment(int(exp_id)).runs[0].id)
    for extra in ((), ("--robot", "3")):
        gif = tmp_path / f"replay{len(extra)}.gif"
        out = twb("replay", run_id, "--out", str(gif), "--max-frames", "6", "--dpi", "30", *extra, *auth)
        assert out.returncode == 0 and gif.stat().st_size > 1000, out.stderr
    bad = twb("replay", run_id, "--robot", "4", "--out", str(tmp_path / "x.gif"), *auth)
    assert bad.returncode == 2 and "has 4 robots (0 to 3); --robot 4 is none" in bad.stderr, bad.stderr
