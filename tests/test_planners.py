import math

import numpy as np
import pytest

from planners import (
    DEFAULT_ROBOT_RADIUS,
    InvalidPose,
    NoPathFound,
    PlanningError,
    UnknownPlanner,
    config_space,
    distance_to_obstacles,
    get_planner,
    load_environment,
    parse_environment,
    plan_path,
)
from planners.prm import PRMPlanner

PLANNERS = ["fmm", "fm2", "prm", "astar", "st_astar"]
CASES = [(env, plan) for env in ("room", "blocks") for plan in ("A", "B")]


def dense(path, step=0.001):
    """Points every ``step`` metres along the polyline (an independent re-implementation)."""
    out = [path[:1, :2]]
    for a, b in zip(path[:-1, :2], path[1:, :2]):
        n = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.vstack(out)


@pytest.fixture(scope="module")
def results():
    out = {}
    for env_name, plan_name in CASES:
        env = load_environment(env_name)
        plan = env.plan(plan_name)
        for planner in PLANNERS:
            out[env_name, plan_name, planner] = plan_path(env, plan.start, plan.goal, planner, seed=3)
    return out


@pytest.mark.parametrize("planner", PLANNERS)
@pytest.mark.parametrize("env_name, plan_name", CASES)
def test_paths_run_exactly_from_start_to_goal_and_never_touch_dilated_obstacles(results, env_name, plan_name, planner):
    env = load_environment(env_name)
    plan = env.plan(plan_name)
    r = results[env_name, plan_name, planner]
    space = config_space(env, DEFAULT_ROBOT_RADIUS)
    for path in (r.path, np.column_stack([r.raw_path, np.zeros(len(r.raw_path))])):
        assert np.array_equal(path[0, :2], plan.start[:2])
        assert np.array_equal(path[-1, :2], plan.goal[:2])
        pts = dense(path)
        assert space.is_free(pts).all(), "a 1 mm sample of the path lies in a dilated obstacle"
        # against the exact geometry: the grid decides at cell centres, so allow one cell
        assert distance_to_obstacles(env, pts).min() >= DEFAULT_ROBOT_RADIUS - 0.01
    assert r.path[-1, 2] == pytest.approx(plan.goal[2])
    steps = np.hypot(*np.diff(r.path[:, :2], axis=0).T)
    assert steps.max() <= 0.1 + 1e-9
    assert r.length_m == pytest.approx(steps.sum())
    # every heading but the last faces the next point
    assert np.allclose(r.path[:-1, 2], np.arctan2(*np.diff(r.path[:, :2], axis=0).T[::-1]))
    assert r.planning_time_s > 0


@pytest.mark.parametrize("env_name, plan_name", CASES)
def test_fmm_is_the_shortest(results, env_name, plan_name):
    fmm = results[env_name, plan_name, "fmm"].length_m
    for other in ("fm2", "prm", "astar"):
        assert fmm <= results[env_name, plan_name, other].length_m * 1.005, other


def test_fm2_keeps_more_clearance_than_fmm_on_room(results):
    env = load_environment("room")
    for plan in ("A", "B"):
        c = {p: distance_to_obstacles(env, dense(results["room", plan, p].path)).min() for p in ("fmm", "fm2")}
        assert c["fm2"] > c["fmm"] + 0.02, c
        # FMM hugs the doorway corners at the robot radius
        assert c["fmm"] < DEFAULT_ROBOT_RADIUS + 0.015


@pytest.mark.parametrize("planner", ["fmm", "fm2"])
def test_straight_line_in_an_empty_field(planner):
    env = parse_environment({"name": "empty", "size": [3.6, 3.6]})
    r = plan_path(env, (0.4, 0.5), (3.1, 2.9), planner)
    euclid = math.hypot(2.7, 2.4)
    assert r.length_m == pytest.approx(euclid, rel=0.01)
    # the raw descent stays within a centimetre of the straight line
    rel = r.raw_path - [0.4, 0.5]
    d = np.abs(2.7 * rel[:, 1] - 2.4 * rel[:, 0]) / euclid
    assert d.max() < 0.01


def test_symmetric_start_on_a_ridge_takes_one_way_round():
    # plan B of `blocks` starts right below a block: both ways round are equally short
    env = load_environment("blocks")
    plan = env.plan("B")
    fmm = plan_path(env, plan.start, plan.goal, "fmm")
    astar = plan_path(env, plan.start, plan.goal, "astar")
    assert fmm.length_m < astar.length_m
    assert fmm.info["descent_ridge_steps"] >= 1


def test_prm_is_deterministic_per_seed_and_reuses_its_roadmap():
    env = load_environment("blocks")
    plan = env.plan("A")
    prm = PRMPlanner()
    space = config_space(env, DEFAULT_ROBOT_RADIUS)
    a1, info1 = prm.solve(space, np.array(plan.start[:2]), np.array(plan.goal[:2]), {"samples": 300, "k": 8}, 11)
    a2, info2 = prm.solve(space, np.array(plan.start[:2]), np.array(plan.goal[:2]), {"samples": 300, "k": 8}, 11)
    assert np.array_equal(a1, a2)
    assert not info1["roadmap_cached"] and info2["roadmap_cached"]
    b, _ = prm.solve(space, np.array(plan.start[:2]), np.array(plan.goal[:2]), {"samples": 300, "k": 8}, 12)
    assert not np.array_equal(a1, b)
    r1 = plan_path(env, plan.start, plan.goal, "prm", seed=5)
    r2 = plan_path(env, plan.start, plan.goal, "prm", seed=5)
    assert np.array_equal(r1.path, r2.path)


def test_prm_roadmap_edges_are_free_and_nodes_unique():
    space = config_space(load_environment("room"), DEFAULT_ROBOT_RADIUS)
    rm, _ = get_planner("prm").roadmap(space, 400, 10, 0)
    assert len(rm.nodes) == 400
    assert space.is_free(rm.nodes).all()
    assert space.segments_free(rm.nodes[rm.edges[:, 0]], rm.nodes[rm.edges[:, 1]]).all()
    assert len(np.unique(rm.edges, axis=0)) == len(rm.edges)
    assert (rm.edges[:, 0] < rm.edges[:, 1]).all()


def test_prm_with_too_few_samples_says_what_to_do():
    env = load_environment("room")
    plan = env.plan("A")
    with pytest.raises(NoPathFound, match="try more samples"):
        plan_path(env, plan.start, plan.goal, "prm", params={"samples": 2, "k": 1, "grow": False})
    with pytest.raises(NoPathFound, match="sample budget of 4 samples"):
        plan_path(env, plan.start, plan.goal, "prm", params={"samples": 2, "k": 1, "max_samples": 4})


WALLED = parse_environment(
    {"name": "walled", "size": [1.0, 1.0], "blocks": [{"x": 0.5, "y": 0.5, "w": 0.06, "h": 1.0}]}
)


@pytest.mark.parametrize("planner", PLANNERS)
def test_unreachable_goal_is_reported_before_planning(planner):
    with pytest.raises(NoPathFound, match=r"cannot be reached .* separate free regions"):
        plan_path(WALLED, (0.2, 0.5), (0.8, 0.5), planner)


@pytest.mark.parametrize(
    "start, goal, message",
    [
        ((0.5, 0.5), (0.8, 0.5), r"start \(0.5, 0.5\) is inside an obstacle"),
        ((0.2, 0.5), (0.8, 0.02), r"goal \(0.8, 0.02\) is inside an obstacle or closer than the robot radius"),
        ((1.2, 0.5), (0.8, 0.5), r"start \(1.2, 0.5\) is outside the field 0..1 x 0..1 m"),
        ((0.2, float("nan")), (0.8, 0.5), "start must be finite"),
        ((0.2, 0.5, 1.0, 2.0), (0.8, 0.5), "start must have 2 or 3 numbers"),
        (("a", 0.5), (0.8, 0.5), "start must be numbers"),
    ],
)
def test_bad_poses_are_refused_with_a_clear_reason(start, goal, message):
    with pytest.raises(InvalidPose, match=message):
        plan_path(WALLED, start, goal, "fmm")


def test_unknown_planner_and_bad_parameters():
    with pytest.raises(UnknownPlanner, match=r"unknown planner 'rrt' \(available: fmm, fm2, prm, astar"):
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "rrt")
    with pytest.raises(PlanningError, match=r"planner 'prm' has no parameter 'n' \(parameters: grow, k, max_samples, "
                                            r"prm_star, samples, time_budget_s\)"):
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "prm", params={"n": 3})
    with pytest.raises(PlanningError, match="parameter prm.samples must be an integer"):
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "prm", params={"samples": 2.5})
    with pytest.raises(PlanningError, match="parameter fm2.saturation must be finite"):
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "fm2", params={"saturation": float("inf")})
    with pytest.raises(PlanningError, match=r"parameter fm2.saturation must be a number > 0 \(m\), got 0"):
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "fm2", params={"saturation": 0})
    with pytest.raises(PlanningError, match="`seed` must be an integer"):
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "prm", seed=-1)


def test_goal_heading_is_optional():
    r = plan_path("room", (0.3, 0.3), (0.6, 0.3), "fmm")
    assert r.path[-1, 2] == pytest.approx(0.0, abs=1e-9)


def test_default_radius_matches_the_bebot_profile():
    from contract.robot_profile import load_profile

    assert load_profile("bebot")["radius_m"] == DEFAULT_ROBOT_RADIUS


def test_an_environment_takes_as_many_moving_obstacles_as_a_robot_does():
    from planners.moving import MAX_MOVING_OBSTACLES
    from contract.protocol import MAX_MOVING

    assert MAX_MOVING_OBSTACLES == MAX_MOVING  # planners import nothing from robot_agent: the value is repeated


@pytest.mark.parametrize("env_name", ["room", "blocks"])
def test_random_queries_always_give_valid_paths(env_name):
    """Many seeded random start/goal pairs: every planner succeeds or reports a clean error."""
    env = load_environment(env_name)
    space = config_space(env, DEFAULT_ROBOT_RADIUS)
    rng = np.random.default_rng(42)
    pts = rng.random((200, 2)) * 1.8
    pts = pts[space.is_free(pts)][:40]
    for s, g in zip(pts[0::2], pts[1::2]):
        for planner in ("fmm", "fm2", "astar"):
            r = plan_path(env, s, g, planner)  # raises on any path through an obstacle
            assert np.array_equal(r.path[0, :2], s) and np.array_equal(r.path[-1, :2], g)
            assert space.is_free(dense(r.path)).all()


@pytest.mark.parametrize("where", [0.2, 0.35, 0.5, 0.65, 0.8])
@pytest.mark.parametrize("planner", ["fmm", "fm2"])
def test_a_block_right_on_the_straight_line_far_from_the_start(planner, where):
    """The start lies on a ridge of arrival time that only becomes sharp near the block."""
    c = 0.2 + 1.4 * where
    env = parse_environment({"name": "ridge", "size": [1.8, 1.8], "blocks": [{"x": c, "y": c, "w": 0.1, "h": 0.1}]})
    r = plan_path(env, (0.2, 0.2, 0.0), (1.6, 1.6, 0.0), planner, robot_radius=0.065)
    space = config_space(env, 0.065)
    assert space.is_free(dense(r.path)).all()
    if planner == "fmm":
        # one way round the block: about the straight line plus the detour, not more
        assert r.length_m < math.hypot(1.4, 1.4) + 0.15
