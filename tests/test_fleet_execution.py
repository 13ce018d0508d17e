"""Executing a prioritized plan by its order of passage (planners.dependencies, robot_agent.engine.fleet): the
precedences of a hand-made crossing, and fleets that collide when driven by the clock but not by dependencies."""

from __future__ import annotations

import math

import numpy as np

from client_sdk.study._fleet import circle_robots
from planners import parse_environment
from planners.dependencies import NONE, fleet_dependencies
from planners.prioritized import plan_prioritized, timed_waypoints
from robot_agent.engine.fleet import simulate_fleet
from robot_agent.engine.jobs import fleet_job

SWAP = {"name": "swap", "size": [1.8, 1.8]}
DOOR = {"name": "door", "size": [1.8, 1.0], "blocks": [
    {"x": 0.9, "y": 0.2, "w": 0.06, "h": 0.4}, {"x": 0.9, "y": 0.8, "w": 0.06, "h": 0.4}]}
RADIUS = 0.065  # the server's: robot radius with the planning margin (m)


def job(env, robots, execution, backend="ideal", seed=0, planner="prioritized"):
    return fleet_job(env, robots, planner, {}, seed, 120.0, RADIUS, backend, execution=execution)


def outcomes(out) -> list[str]:
    return [r["outcome"] for r in out["robots"]]


def test_the_precedence_of_a_crossing():
    """Robot 0 crosses (1, 1) at t = 2 s; robot 1 waits at its start and comes by at t = 4 s: robot 1 may
    leave its waypoint 1 (the one before the crossing) once robot 0 reached its waypoint 3 (left the
    crossing); robot 0 waits for nobody."""
    line = np.linspace(0.0, 2.0, 5)
    xy = [np.column_stack([line, np.ones(5)]), np.column_stack([np.ones(5), line])]
    arrive = [np.arange(5.0), np.array([0.0, 3, 4, 5, 6])]
    leave = [np.r_[np.arange(4.0), np.inf], np.array([2.0, 3, 4, 5, np.inf])]
    dep = fleet_dependencies(xy, arrive, leave, 0.3)
    assert dep[0].tolist() == [[NONE] * 5, [NONE] * 5]
    assert dep[1].tolist() == [[NONE, 3, 3, 3, 3], [NONE] * 5]
    # the other way round: robot 1 first (it crosses at t = 1 s), robot 0 held until robot 1 left
    arrive[1], leave[1] = np.arange(5.0) - 1, np.r_[np.arange(4.0) - 1, np.inf]
    arrive[1][0] = leave[1][0] = 0.0
    dep = fleet_dependencies(xy, arrive, leave, 0.3)
    assert dep[0].tolist() == [[NONE] * 5, [NONE, 3, 3, 3, 3]]
    assert dep[1].tolist() == [[NONE] * 5, [NONE] * 5]


def test_eight_robots_on_the_circle_collide_by_the_clock_not_by_dependencies():
    """The fleet study's circle-8 in the empty sub-field, simulated (docs/study.md): robot 1 falls behind
    its plan and meets robot 3 when driven by the clock."""
    robots = circle_robots(8, 0.6, (0.9, 0.9))
    timed = job(SWAP, robots, "timed")
    assert "COLLISION" in outcomes(timed)
    adg = job(SWAP, robots, "dependencies")
    assert outcomes(adg) == ["DONE"] * 8
    assert adg["metrics"]["robot_distance_min_m"] > 2 * 0.045 + 0.05
    again = job(SWAP, robots, "dependencies")
    assert all(np.array_equal(a["poses"], b["poses"]) for a, b in zip(adg["robots"], again["robots"]))


def test_four_field_robots_swapping_the_whole_field_collide_by_the_clock_not_by_dependencies():
    """docs/planners.md's full-field swap on the emulated field: seed 5 collides when driven by the clock."""
    corners = [[0.4, 0.4], [3.2, 0.4], [3.2, 3.2], [0.4, 3.2]]
    robots = []
    for k, s in enumerate(corners):
        g = corners[(k + 2) % 4]
        a = math.atan2(g[1] - s[1], g[0] - s[0])
        robots.append({"start": [*s, a], "goal": [*g, a]})
    env = {"name": "full", "size": [3.6, 3.6]}
    assert "COLLISION" in outcomes(job(env, robots, "timed", "field", seed=5))
    assert outcomes(job(env, robots, "dependencies", "field", seed=5)) == ["DONE"] * 4


def test_a_late_robot_holds_up_the_robot_that_passes_after_it():
    """Through the doorway: robot 1 steps aside for robot 0.  Robot 0 is held 4 s at its start (late): by
    dependencies robot 1 waits for it (its hold names robot 0) and they do not meet."""
    env = parse_environment(DOOR)
    plan = plan_prioritized(env, [[0.3, 0.5], [1.5, 0.5]], [[1.5, 0.5], [0.3, 0.5]], robot_radius=RADIUS)
    sched = [timed_waypoints(t, dense=True) for t in plan.paths]
    dep = fleet_dependencies([w for w, _, _ in sched], [a for _, a, _ in sched], [lv for _, _, lv in sched],
                             plan.conflict_m)
    assert (dep[1][0] > NONE).any()  # robot 1 goes through the door after robot 0
    depart = [np.where(lv > a + 1e-9, lv, np.nan) for _, a, lv in sched]
    depart[0][0] = 4.0  # robot 0 starts 4 s late
    blocks = [[b.x, b.y, b.w, b.h, b.angle] for b in env.blocks]
    starts = [[*t.points[0], w[0, 2]] for t, (w, _, _) in zip(plan.paths, sched)]
    fleet = simulate_fleet([w for w, _, _ in sched], starts, depart=depart, depends=dep, seed=3, area=env.size,
                           blocks=blocks)
    assert fleet.outcomes == ["DONE", "DONE"]
    assert fleet.holds[1] and [0] in fleet.waited_for[1]
    k, held = fleet.holds[1][fleet.waited_for[1].index([0])]
    assert held > 1.0 and int(np.flatnonzero(dep[1][0] > NONE)[0]) <= k


def test_uncoordinated_paths_run_the_same_either_way():
    robots = circle_robots(4, 0.6, (0.9, 0.9))
    a, b = job(SWAP, robots, "timed", planner="fmm"), job(SWAP, robots, "dependencies", planner="fmm")
    assert all(np.array_equal(x["poses"], y["poses"]) for x, y in zip(a["robots"], b["robots"]))
    assert outcomes(a) == outcomes(b)
