"""Several robots in one world on one clock (robot_agent.engine.fleet): they collide with each other, and prioritized
plans with their holds keep them apart."""

from __future__ import annotations

import numpy as np
import pytest

from planners import parse_environment
from planners.prioritized import fleet_waypoints, plan_prioritized
from robot_agent.engine.fleet import MAX_FLEET, simulate_fleet
from robot_agent.engine.headless import PlacementRefused
from contract.params import robot_params

RADIUS = robot_params().collision_radius_m
SUB = (1.8, 1.8)
#: four robots at the corners of a sub-field, each bound for the diagonally opposite one
CORNERS = [[0.3, 0.3], [1.5, 0.3], [1.5, 1.5], [0.3, 1.5]]
OPPOSITE = [CORNERS[2], CORNERS[3], CORNERS[0], CORNERS[1]]
DOOR = parse_environment({"name": "door", "size": [1.8, 1.0], "blocks": [
    {"x": 0.9, "y": 0.2, "w": 0.06, "h": 0.4}, {"x": 0.9, "y": 0.8, "w": 0.06, "h": 0.4}]})


def straight(s, g) -> np.ndarray:
    a = float(np.arctan2(g[1] - s[1], g[0] - s[0]))
    return np.array([[s[0], s[1], a], [g[0], g[1], a]])


def min_distance(fleet) -> float:
    """Closest approach (m) of two robots' centres over the tracker poses, sampled every 20 ms."""
    t = np.arange(0.0, max(r.poses[-1, 0] for r in fleet.runs), 0.02)
    xy = np.stack([np.column_stack([np.interp(t, r.poses[:, 0], r.poses[:, c]) for c in (1, 2)]) for r in fleet.runs])
    d = np.hypot(xy[:, None, :, 0] - xy[None, :, :, 0], xy[:, None, :, 1] - xy[None, :, :, 1])
    d[np.arange(len(xy)), np.arange(len(xy))] = np.inf
    return float(d.min())


def planned(env, starts, goals):
    plan = plan_prioritized(env, starts, goals, planning_margin=0.02)
    wps = [fleet_waypoints(p) for p in plan.paths]
    return [w for w, _ in wps], [d for _, d in wps], [[*s, float(w[0, 2])] for s, (w, _) in zip(starts, wps)]


def test_uncoordinated_straight_paths_collide_in_the_middle():
    paths = [straight(s, g) for s, g in zip(CORNERS, OPPOSITE)]
    fleet = simulate_fleet(paths, [p[0] for p in paths], seed=1, area=SUB)
    assert fleet.outcomes == ["COLLISION"] * 4
    assert all(r.obstacle is None for r in fleet.runs)  # robots, not moving obstacles
    assert min_distance(fleet) < 2 * RADIUS + 0.01  # they met near the centre
    for r in fleet.runs:
        assert np.hypot(r.poses[-1, 1] - 0.9, r.poses[-1, 2] - 0.9) < 0.15


def test_prioritized_paths_swap_the_corners_without_touching():
    paths, depart, starts = planned(parse_environment({"name": "swap", "size": list(SUB)}), CORNERS, OPPOSITE)
    fleet = simulate_fleet(paths, starts, depart=depart, seed=1, area=SUB)
    assert fleet.outcomes == ["DONE"] * 4
    assert min_distance(fleet) > 2 * RADIUS
    for r, g in zip(fleet.runs, OPPOSITE):
        assert np.hypot(r.poses[-1, 1] - g[0], r.poses[-1, 2] - g[1]) < 0.02
    again = simulate_fleet(paths, starts, depart=depart, seed=1, area=SUB)
    assert all(np.array_equal(a.poses, b.poses) for a, b in zip(fleet.runs, again.runs))


def test_a_robot_holds_where_the_plan_waits():
    """Through the doorway: robot 1 steps aside and waits for robot 0; the fleet holds it there."""
    paths, depart, starts = planned(DOOR, [[0.3, 0.5], [1.5, 0.5]], [[1.5, 0.5], [0.3, 0.5]])
    assert np.isfinite(depart[1]).any()  # the plan waits
    blocks = [[b.x, b.y, b.w, b.h, b.angle] for b in DOOR.blocks]
    fleet = simulate_fleet(paths, starts, depart=depart, seed=3, area=DOOR.size, blocks=blocks)
    assert fleet.outcomes == ["DONE", "DONE"] and min_distance(fleet) > 2 * RADIUS
    k = int(np.flatnonzero(np.isfinite(depart[1]))[0])
    assert [w for w, _ in fleet.holds[1]] == [k]
    # one START and one DONE per robot; WP indices of the whole path
    ev = fleet.runs[1].events
    assert [e.kind for e in ev].count("START") == 1 and ev[-1].kind == "DONE"
    assert sorted({e.index for e in ev if e.kind == "WP"}) == list(range(len(paths[1])))


def test_a_long_hold_keeps_the_robot_still_and_the_obstacles_run_on_the_fleet_clock():
    """A disc crosses the robot's way at x = 0.9 around t = 3 s.  Driving at once, the robot meets it; held at
    its start until 8 s it passes behind it -- the disc's clock is the fleet's, not the leg's."""
    disc = [((0.05, 0.2, 0, 0.0), [(0.9, 0.3), (0.9, 1.7)])]
    path = np.array([[0.3, 0.9, 0.0], [1.5, 0.9, 0.0]])
    hit = simulate_fleet([path], [(0.3, 0.9, 0.0)], seed=2, area=SUB, moving=disc)
    assert hit.outcomes == ["COLLISION"] and hit.runs[0].obstacle == 0
    held = simulate_fleet([path], [(0.3, 0.9, 0.0)], seed=2, area=SUB, moving=disc, depart=[[8.0, np.nan]])
    assert held.outcomes == ["DONE"] and held.runs[0].t_start == pytest.approx(8.0)
    assert held.holds == [[]]  # a hold at the start is a delayed start, not a hold at a waypoint
    poses = held.runs[0].poses
    assert (poses[:, 0] >= 8.0 - 1e-9).all() or np.ptp(poses[poses[:, 0] < 8.0, 1]) == 0.0


def test_bad_fleets_are_refused_naming_the_robot():
    p = straight(CORNERS[0], OPPOSITE[0])
    with pytest.raises(PlacementRefused, match="robot 1: robot 0 stands 0.050 m from it"):
        simulate_fleet([p, p], [(0.3, 0.3, 0.0), (0.35, 0.3, 0.0)], seed=1, area=SUB)
    with pytest.raises(PlacementRefused, match="cannot place robot 1: the robot would touch a block"):
        simulate_fleet([p, p], [(0.3, 0.3, 0.0), (0.9, 0.9, 0.0)], seed=1, area=SUB, blocks=[[0.9, 0.9, 0.2, 0.2, 0]])
    with pytest.raises(ValueError, match=f"1 to {MAX_FLEET} robots, got 65"):
        simulate_fleet([p] * 65, [(0.3, 0.3, 0.0)] * 65, seed=1, area=SUB)
    with pytest.raises(ValueError, match="2 paths but 1 starts"):
        simulate_fleet([p, p], [(0.3, 0.3, 0.0)], seed=1, area=SUB)
    with pytest.raises(ValueError, match="robot 0: 2 path points but 3 departure times"):
        simulate_fleet([p], [(0.3, 0.3, 0.0)], seed=1, area=SUB, depart=[[1, 2, 3]])


# ---------------------------------------------------------------- metrics (planners.fleet_metrics)

from planners.fleet_metrics import FleetSettings, collision_kind, fleet_metrics  # noqa: E402


def measured(fleet):
    return fleet_metrics([r.poses for r in fleet.runs], fleet.outcomes, [r.t_end for r in fleet.runs],
                         [r.obstacle for r in fleet.runs], FleetSettings(robot_radius=RADIUS))


def test_metrics_of_the_two_swaps():
    paths = [straight(s, g) for s, g in zip(CORNERS, OPPOSITE)]
    crash = measured(simulate_fleet(paths, [p[0] for p in paths], seed=1, area=SUB))
    assert crash["collisions_robot"] == 4 and crash["collisions_static"] == crash["collisions_moving"] == 0
    assert crash["success_rate"] == 0.0 and crash["makespan_s"] is None and crash["time_sum_s"] is None
    assert crash["robot_distance_min_m"] < 2 * RADIUS + 0.01
    assert [r["collision"] for r in crash["robots"]] == ["robot"] * 4
    paths, depart, starts = planned(parse_environment({"name": "swap", "size": list(SUB)}), CORNERS, OPPOSITE)
    fleet = simulate_fleet(paths, starts, depart=depart, seed=1, area=SUB)
    ok = measured(fleet)
    assert ok["success_rate"] == 1.0 and ok["collisions_robot"] == 0 and not ok["deadlock"]
    assert ok["makespan_s"] == pytest.approx(max(r.t_end for r in fleet.runs))
    assert ok["time_sum_s"] == pytest.approx(sum(r.t_end for r in fleet.runs))
    assert ok["robot_distance_min_m"] == pytest.approx(min_distance(fleet), abs=1e-9)
    assert ok["robot_distance_min_m"] == min(r["robot_distance_min_m"] for r in ok["robots"])
    lengths = [float(np.hypot(*np.diff(r.poses[:, 1:3], axis=0).T).sum()) for r in fleet.runs]
    assert ok["path_length_sum_m"] == pytest.approx(sum(lengths), rel=0.02)  # resampled every 20 ms


def test_a_collision_is_with_whatever_was_nearer_to_touching():
    """Tracker poses lag: two field robots that hit each other may be logged more than 5 mm beyond a touch;
    with the clearance to the blocks and walls known, the nearer of the two is what was hit."""
    assert collision_kind("COLLISION", None, 0.09, 0.04) == "static"  # without the clearance: 5 mm at most
    assert collision_kind("COLLISION", None, 0.09, 0.04, static_clearance_m=0.6) == "robot"
    assert collision_kind("COLLISION", None, 0.3, 0.04, static_clearance_m=0.045) == "static"
    assert collision_kind("COLLISION", 2, 0.09, 0.04, static_clearance_m=0.6) == "moving"
    assert collision_kind("DONE", None, 0.09, 0.04, static_clearance_m=0.6) is None


def test_deadlock_and_safety_time_on_made_up_poses():
    """Two robots drive towards each other for 2 s, then stand 0.15 m apart for 8 s without ending their paths."""
    t = np.arange(0.0, 10.0 + 1e-9, 0.02)
    x = np.minimum(t, 2.0) * 0.1  # 0 .. 0.2 m, then still
    a = np.column_stack([t, 0.3 + x, np.full_like(t, 0.5), np.zeros_like(t)])
    b = np.column_stack([t, 0.85 - x, np.full_like(t, 0.5), np.full_like(t, np.pi)])
    m = fleet_metrics([a, b], ["TIMEOUT_SIM"] * 2, [None, None], settings=FleetSettings(safety_radius=0.2))
    assert m["robot_distance_min_m"] == pytest.approx(0.15)
    assert m["deadlock"] and m["no_progress_max_s"] == pytest.approx(8.0, abs=0.1)
    # closer than 0.2 m from x = 0.3 + 0.1 t, 0.85 - 0.1 t: from t = 1.75 s on
    assert m["safety_time_s"] == pytest.approx(10.0 - 1.75, abs=0.05)
    assert m["robots"][0]["safety_time_s"] == m["safety_time_s"]
    with pytest.raises(ValueError, match="`deadlock_s` must be a positive number"):
        FleetSettings(deadlock_s=0)
    with pytest.raises(ValueError, match="2 robots, 1 outcomes"):
        fleet_metrics([a, b], ["DONE"], [1.0, 1.0])


# ---------------------------------------------------------------- the server's pure parts: the task, the pre-flight

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from planners import load_environment  # noqa: E402
from server.errors import PreflightError  # noqa: E402
from robot_agent.engine import jobs  # noqa: E402
from server.validation import preflight_fleet  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "fleet"


def test_the_swap_job_as_one_task_uncoordinated_collides_prioritized_completes():
    env = json.loads((Path(__file__).resolve().parents[1] / "planners" / "data" / "swap.json").read_text())
    out = {}
    for name in ("uncoordinated", "prioritized"):
        job = json.loads((EXAMPLES / f"swap-{name}.json").read_text())
        out[name] = jobs.fleet_job(env, job["robots"], job["planner"], {}, job["seed"], 120.0, 0.045)
    bad, good = out["uncoordinated"], out["prioritized"]
    assert [r["outcome"] for r in bad["robots"]] == ["COLLISION"] * 4 and bad["metrics"]["collisions_robot"] == 4
    assert [r["outcome"] for r in good["robots"]] == ["DONE"] * 4
    m = good["metrics"]
    assert m["success_rate"] == 1.0 and m["robot_distance_min_m"] > 2 * RADIUS and m["makespan_s"] > 0
    assert json.dumps(m)  # JSON-ready
    for r in good["robots"]:
        assert r["lines"][0][1].startswith("T,T,P,") and r["lines"][-1][1].startswith("EV,DONE")


def test_fleet_task_planning_errors_name_the_robot():
    env = json.loads((Path(__file__).resolve().parents[1] / "planners" / "data" / "room.json").read_text())
    robots = [{"start": [0.3, 0.3], "goal": [1.5, 1.5]}, {"start": [1.5, 0.3], "goal": [0.9, 0.9]}]
    assert jobs.fleet_job(env, robots, "fmm", {}, 1, 60.0, 0.045)["planning_error"].startswith("robot 1:")


def test_fleet_preflight_names_the_field():
    env = load_environment("room")
    ok = [{"start": [0.3, 0.3], "goal": [1.5, 1.5]}, {"start": [1.5, 0.3], "goal": [0.3, 1.5]}]
    preflight_fleet(env, ok, 0.045)
    cases = [
        (ok[:1], "robots: a multi-robot job has 2 to 16 robots, got 1"),
        (ok * 9, "got 18"),
        ([ok[0], {"start": [0.35, 0.3], "goal": [0.3, 1.5]}], r"robots\[1\]\.start is 0.050 m from robots\[0\]\.start"),
        ([ok[0], {"start": [1.5, 0.3], "goal": [1.5, 1.5]}], r"robots\[1\]\.goal is 0.000 m from robots\[0\]\.goal"),
        ([ok[0], {"start": [0.9, 0.9], "goal": [0.3, 1.5]}], r"robots\[1\]\.start: "),
        ([ok[0], {"start": [1.5, 0.3], "goal": [0.9, 0.9]}], r"robots\[1\]\.goal: "),
    ]
    for robots, match in cases:
        with pytest.raises(PreflightError, match=match):
            preflight_fleet(env, robots, 0.045)


def test_an_uncoordinated_fleet_that_replans_swaps_some_corners_and_counts_the_replans():
    """Replanning robots (regulated pure pursuit, ``replan`` = 1) of the uncoordinated swap avoid each other
    where they stand: without it all four collide in the middle, with it some arrive; the replans are
    counted per robot and in all, and the same seed replays them."""
    from contract.controller_specs import select

    env = json.loads((Path(__file__).resolve().parents[1] / "planners" / "data" / "swap.json").read_text())
    job = json.loads((EXAMPLES / "swap-uncoordinated.json").read_text())
    runs = {}
    for on in (0, 1, 1):
        params = select("regulated_pure_pursuit", {"replan": on}).params
        runs.setdefault(on, []).append(jobs.fleet_job(env, job["robots"], job["planner"], {}, job["seed"], 120.0,
                                                         0.045, controller="regulated_pure_pursuit",
                                                         controller_params=params))
    off, on, again = runs[0][0], runs[1][0], runs[1][1]
    assert [r["outcome"] for r in off["robots"]] == ["COLLISION"] * 4 and "replans" not in off["metrics"]
    m = on["metrics"]
    assert m["success_rate"] > 0 and m["replans"] >= 1
    assert m["replans"] == sum(r["replans"] for r in m["robots"])
    assert m["replans"] + m["replan_failures"] == sum(1 for r in on["robots"] for _, line, _ in r["lines"]
                                                      if line.startswith("EV,REPLAN,"))
    for a, b in zip(on["robots"], again["robots"]):
        assert np.array_equal(a["poses"], b["poses"]) and a["outcome"] == b["outcome"]


def test_a_coordinated_fleet_refuses_to_replan():
    with pytest.raises(ValueError, match="controller_params.replan: a coordinated fleet"):
        simulate_fleet([straight(CORNERS[0], OPPOSITE[0])] * 2, [[0.3, 0.3, 0.0], [1.5, 1.5, 0.0]], seed=1,
                       depart=[None, np.full(2, np.nan)], controller="regulated_pure_pursuit",
                       controller_params={"replan": 1})
