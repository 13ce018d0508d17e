"""Moving obstacles end to end: the built-in `crossing` scenario, the space-time planner and exact replay
(docs/planners.md, "Moving obstacles" and "Space-time A*").  Runs are the agent's simulation core stepped headless
(robot_agent.engine.headless), which the pipeline tests show equal to the same run over TCP."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners import DEFAULT_PLANNING_MARGIN, load_environment, parse_environment, plan_path
from planners.metrics import obstacle_gaps
from planners.moving import positions
from robot_agent.engine.headless import simulate_run
from robot_agent.engine.run_data import block_tuples, moving_tuples

CROSSING = load_environment("crossing")


def execute(env, planner: str, plan: str = "A", seed: int = 5, **params):
    """Plan with the testbed's defaults and drive the path headless in the environment's world."""
    p = env.plan(plan)
    r = plan_path(env, p.start, p.goal, planner, planning_margin=DEFAULT_PLANNING_MARGIN, params=params, seed=seed)
    data = env.to_dict()
    run = simulate_run(r.path, p.start, seed=seed, blocks=block_tuples(data), moving=moving_tuples(data),
                       area=env.size)
    return r, run


def test_crossing_is_room_with_discs_crossing_plan_a():
    room = load_environment("room")
    assert CROSSING.blocks == room.blocks and CROSSING.plans == room.plans
    assert len(CROSSING.moving_obstacles) == 2


def test_uncoordinated_fmm_collides_with_the_crossing_disc_and_st_astar_does_not():
    fmm, hit = execute(CROSSING, "fmm")
    assert hit.outcome == "COLLISION" and hit.obstacle == 0
    plan, run = execute(CROSSING, "st_astar")
    assert run.outcome == "DONE" and run.obstacle is None
    assert np.hypot(*(run.poses[-1, 1:3] - CROSSING.plan("A").goal[:2])) < 0.05
    # executed, it kept clear of both discs (gap of the collision radius 0.04 m disc to theirs)
    gaps = obstacle_gaps(CROSSING, run.poses[:, 1:3], run.poses[:, 0] - run.t_start, 0.04)
    assert gaps.min() > 0.03
    # the same seed replays exactly, plan and run
    again_plan, again = execute(CROSSING, "st_astar")
    assert np.array_equal(again_plan.path, plan.path)
    assert np.array_equal(again.poses, run.poses) and again.events == run.events


def test_st_astar_plans_clear_of_the_obstacles_at_its_own_times():
    p = CROSSING.plan("A")
    r = plan_path(CROSSING, p.start, p.goal, "st_astar", planning_margin=DEFAULT_PLANNING_MARGIN)
    times = np.array(r.info["times_s"])
    assert len(times) == len(r.raw_path) and np.all(np.diff(times) > 0) and r.info["waits"] == 0
    legs = np.hypot(*np.diff(r.raw_path, axis=0).T)
    np.testing.assert_allclose(np.diff(times), legs / r.info["speed_m_s"], rtol=1e-3, atol=1e-3)
    centres = positions(CROSSING.moving_obstacles, times)  # (M, N, 2)
    radii = np.array([o.radius for o in CROSSING.moving_obstacles])[:, None]
    gap = np.hypot(*(centres - r.raw_path[None]).transpose(2, 0, 1)) - radii
    assert gap.min() > 0.045 + DEFAULT_PLANNING_MARGIN  # robot radius + margin, at every waypoint's time


def test_without_moving_obstacles_st_astar_is_a_grid_shortest_path():
    room = load_environment("room")
    p = room.plan("A")
    st = plan_path(room, p.start, p.goal, "st_astar", planning_margin=DEFAULT_PLANNING_MARGIN)
    astar = plan_path(room, p.start, p.goal, "astar", planning_margin=DEFAULT_PLANNING_MARGIN)
    assert st.info["moving_obstacles"] == 0 and st.length_m < astar.length_m * 1.05


DOOR = parse_environment({
    "name": "door", "size": [1.0, 1.0],
    "blocks": [{"x": 0.5, "y": 0.15, "w": 0.06, "h": 0.3}, {"x": 0.5, "y": 0.85, "w": 0.06, "h": 0.3}],
    "moving_obstacles": [{"radius": 0.1, "waypoints": [[0.5, 0.5], [0.8, 0.85]], "speed": 0.1, "delay_s": 6.0}]})


def test_a_disc_in_the_only_doorway_is_waited_out_or_looped_around():
    start, goal = (0.2, 0.5, 0.0), (0.85, 0.5, 0.0)
    waiting = plan_path(DOOR, start, goal, "st_astar", params={"wait": True})
    moving = plan_path(DOOR, start, goal, "st_astar")
    assert waiting.info["waits"] > 0 and moving.info["waits"] == 0
    # both pass the doorway (x = 0.5) only after the disc left it at t = 6 s
    for r in (waiting, moving):
        t = np.array(r.info["times_s"])
        assert t[np.argmax(r.raw_path[:, 0] >= 0.5)] > 6.0
    assert moving.length_m > waiting.length_m + 0.5  # it dawdled in the left room instead of waiting
    # executed (no waits on the robot), the path that moves all the time keeps clear of the disc
    run = simulate_run(moving.path, start, seed=2, blocks=block_tuples(DOOR.to_dict()),
                       moving=moving_tuples(DOOR.to_dict()), area=DOOR.size)
    assert run.outcome == "DONE"


def test_st_astar_reports_a_start_taken_by_a_disc():
    from planners import NoPathFound

    env = parse_environment({"name": "taken", "size": [1.0, 1.0],
                             "moving_obstacles": [{"radius": 0.05, "waypoints": [[0.2, 0.5]], "speed": 0.1}]})
    with pytest.raises(NoPathFound, match="moving obstacle is at the start"):
        plan_path(env, (0.22, 0.5), (0.8, 0.5), "st_astar")
    assert math.isfinite(plan_path(env, (0.5, 0.8), (0.8, 0.5), "st_astar").length_m)


def test_on_the_emulated_field_the_discs_move_the_same_and_the_run_replays_exactly():
    """The field backend (tracker noise, track dynamics) meets the same discs: fmm's path on crossing A still
    ends on disc 0, st_astar's still passes, and a seed replays bit for bit."""
    data = CROSSING.to_dict()
    p = CROSSING.plan("A")
    outcomes = {}
    for planner in ("fmm", "st_astar"):
        r = plan_path(CROSSING, p.start, p.goal, planner, planning_margin=DEFAULT_PLANNING_MARGIN)
        runs = [simulate_run(r.path, p.start, seed=11, blocks=block_tuples(data), moving=moving_tuples(data),
                             area=CROSSING.size, backend="field") for _ in range(2)]
        assert np.array_equal(runs[0].poses, runs[1].poses) and runs[0].events == runs[1].events
        outcomes[planner] = (runs[0].outcome, runs[0].obstacle)
    assert outcomes == {"fmm": ("COLLISION", 0), "st_astar": ("DONE", None)}
