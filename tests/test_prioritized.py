"""Prioritized planning in space-time (planners.prioritized): several robots' timed paths that keep apart."""

from __future__ import annotations

import numpy as np
import pytest

from planners import NoPathFound, PlanningError, parse_environment
from planners.moving import positions
from planners.prioritized import min_separation, plan_prioritized

#: two rooms joined by a 0.2 m doorway: one robot at a time passes it
DOOR = parse_environment({"name": "door", "size": [1.8, 1.0], "blocks": [
    {"x": 0.9, "y": 0.2, "w": 0.06, "h": 0.4}, {"x": 0.9, "y": 0.8, "w": 0.06, "h": 0.4}]})
RADIUS = 0.045


def test_a_swap_through_a_doorway_keeps_the_robots_apart():
    starts, goals = [[0.3, 0.5], [1.5, 0.5]], [[1.5, 0.5], [0.3, 0.5]]
    plan = plan_prioritized(DOOR, starts, goals)
    first, second = plan.paths
    assert np.array_equal(first.points[0], starts[0]) and np.array_equal(first.points[-1], goals[0])
    assert np.array_equal(second.points[0], starts[1]) and np.array_equal(second.points[-1], goals[1])
    assert min_separation(plan.paths, dt=0.01) >= 2 * RADIUS
    # robot 0 goes first and straight; robot 1 gets out of its way and passes the door after it
    assert plan.info[0]["waits"] == 0 and first.times[-1] < second.times[-1]
    t_door = lambda p: p.times[np.argmax(p.points[:, 0] <= 0.9)]  # noqa: E731 - when robot 1 passes x = 0.9
    assert t_door(second) > first.times[np.argmax(first.points[:, 0] >= 0.9)]
    assert plan.makespan_s == pytest.approx(max(first.times[-1], second.times[-1]))
    # deterministic: the same plan again
    again = plan_prioritized(DOOR, starts, goals)
    assert all(np.array_equal(a.points, b.points) and np.array_equal(a.times, b.times)
               for a, b in zip(plan.paths, again.paths))


def test_robots_avoid_the_moving_obstacles_too():
    env = parse_environment({"name": "disc", "size": [1.8, 1.8], "moving_obstacles": [
        {"radius": 0.05, "waypoints": [[0.9, 0.1], [0.9, 1.7]], "speed": 0.1, "repeat": "pingpong"}]})
    starts, goals = [[0.2, 0.9], [0.2, 0.5], [1.6, 1.3]], [[1.6, 0.9], [1.6, 0.5], [0.2, 1.3]]
    plan = plan_prioritized(env, starts, goals)
    assert min_separation(plan.paths, dt=0.01) >= 2 * RADIUS
    for p in plan.paths:
        t = np.arange(0.0, p.times[-1], 0.01)
        disc = positions(env.moving_obstacles, t)[0]
        assert (np.hypot(*(p.position(t) - disc).T) - 0.05).min() >= RADIUS


def test_sixteen_robots_cross_the_field():
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from bench.planners import full_field
    from bench.prioritized import fleet

    starts, goals = fleet(16)
    plan = plan_prioritized(full_field(), starts, goals, planning_margin=0.02)
    assert len(plan.paths) == 16 and min_separation(plan.paths) >= 2 * (RADIUS + 0.02)


@pytest.mark.slow
def test_bad_fleets_are_refused_naming_the_robots():
    with pytest.raises(PlanningError, match="robots 0 and 1 have starts 0.050 m apart"):
        plan_prioritized(DOOR, [[0.3, 0.5], [0.35, 0.5]], [[1.5, 0.5], [1.5, 0.2]])
    with pytest.raises(PlanningError, match="2 starts but 1 goals"):
        plan_prioritized(DOOR, [[0.3, 0.5], [0.6, 0.5]], [[1.5, 0.5]])
    # robot 0 parks in the doorway for good: robot 1 cannot get through (the other order could)
    with pytest.raises(NoPathFound, match=r"robot 1 \(of 2, planned in order\)"):
        plan_prioritized(DOOR, [[0.75, 0.5], [0.3, 0.5]], [[0.9, 0.5], [1.5, 0.5]])
    assert len(plan_prioritized(DOOR, [[0.3, 0.5], [0.75, 0.5]], [[1.5, 0.5], [0.9, 0.5]]).paths) == 2


def test_a_search_too_large_for_a_worker_is_refused_before_it_allocates():
    """Within the parameters' bounds a long horizon on a fine lattice can still ask for more states than a
    planning worker holds: refused at once, naming the sizes and what to change (a planning failure, the job's)."""
    import tracemalloc

    from planners import plan_path
    from planners.st_astar import PlanTooLarge

    tracemalloc.start()
    try:
        with pytest.raises(PlanTooLarge, match=r"would hold 6\.55e\+08 states \(181 x 181 lattice points x 20000 "
                                               r"time steps .* at most 5e\+07: choose a larger `cell`"):
            plan_path("room", [0.3, 0.3], [1.5, 1.5], "st_astar", params={"cell": 0.01, "horizon_s": 3000})
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6, peak  # nothing of the 655 MB table was built (numpy reports its buffers to tracemalloc)
