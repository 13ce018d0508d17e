"""The fast marching that stops at the start (planners.fast_marching.FrontMarch) against the full field.

The full field is ``skfmm.travel_time`` (``fast_marching.travel_time``); the
early-terminated march must give the same arrival times wherever it computed
one (within 1e-9 relative: in practice bit for bit) and the same paths, and
still tell an unreachable goal.
"""

import math

import numpy as np
import pytest

from planners import (
    DEFAULT_ROBOT_RADIUS,
    NoPathFound,
    builtin_names,
    config_space,
    get_planner,
    load_environment,
    parse_environment,
    plan_path,
)
from planners.fast_marching import FrontMarch, descend, plan, travel_time
from planners.fm2 import SHORTCUT_TOLERANCE, band_shortcut, round_corners, smooth_descent, speed_map

REL = 1e-9


def xy(pose) -> np.ndarray:
    return np.array(pose[:2], dtype=float)


def assert_same_times(full: np.ndarray, part: np.ndarray, where: np.ndarray | None = None) -> None:
    """``part`` equals ``full`` (within REL) on ``where`` (default: everywhere, infinities included)."""
    if where is None:
        assert np.array_equal(np.isinf(full), np.isinf(part)), "reachable cells differ"
        where = np.isfinite(full)
    a, b = full[where], part[where]
    assert np.isfinite(b).all()
    rel = np.abs(a - b) / np.maximum(np.abs(a), 1e-300)
    assert rel.max(initial=0.0) <= REL, f"largest relative difference {rel.max():.3g}"


def speeds(space, kind: str, rng: np.random.Generator | None = None) -> np.ndarray | None:
    if kind == "unit":
        return None
    if kind == "fm2":
        return speed_map(space, 0.2, 0.01)
    return rng.uniform(0.01, 1.0, space.free.shape)  # "random": far rougher than any planner's


def random_environment(rng: np.random.Generator) -> tuple:
    """A random field with random blocks, a robot radius and a resolution (40 to 120 cells a side)."""
    w, h = rng.uniform(0.8, 2.0, 2)
    blocks = []
    for _ in range(rng.integers(0, 12)):
        bw, bh = rng.uniform(0.02, 0.35, 2)
        r = math.hypot(bw, bh) / 2 + 0.002
        blocks.append({"x": rng.uniform(r, w - r), "y": rng.uniform(r, h - r), "w": bw, "h": bh,
                       "angle": rng.uniform(0, math.pi)})
    env = parse_environment({"name": "random", "size": [float(w), float(h)], "blocks": blocks})
    return env, float(rng.uniform(0.0, 0.06)), float(max(w, h) / rng.integers(40, 120))


def free_points(space, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` random points in free cells (anywhere inside the cell)."""
    iy, ix = np.nonzero(space.free)
    pick = rng.integers(len(iy), size=n)
    return space.grid.cell_centres(iy[pick], ix[pick]) + rng.uniform(-0.49, 0.49, (n, 2)) * space.resolution


# --- arrival times ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["unit", "fm2"])
@pytest.mark.parametrize("resolution", [0.02, 0.01])
@pytest.mark.parametrize("env_name", builtin_names())
def test_the_whole_field_equals_scikit_fmm_on_every_builtin_problem(env_name, resolution, kind):
    env = load_environment(env_name)
    space = config_space(env, DEFAULT_ROBOT_RADIUS, resolution)
    for p in env.plans:
        speed = speeds(space, kind)
        assert_same_times(travel_time(space, xy(p.goal), speed), FrontMarch(space, xy(p.goal), speed).field())


@pytest.mark.parametrize("seed", range(12))
def test_the_whole_field_equals_scikit_fmm_on_random_problems(seed):
    rng = np.random.default_rng(seed)
    env, radius, resolution = random_environment(rng)
    space = config_space(env, radius, resolution)
    if not space.free.any():
        pytest.skip("no free cell")
    for goal in free_points(space, rng, 2):
        for kind in ("unit", "fm2", "random"):
            speed = speeds(space, kind, rng)
            assert_same_times(travel_time(space, goal, speed), FrontMarch(space, goal, speed).field())


@pytest.mark.parametrize("kind", ["unit", "fm2"])
@pytest.mark.parametrize("env_name", ["room", "blocks"])
def test_what_a_query_computes_is_the_full_field_and_it_stops_early(env_name, kind):
    env = load_environment(env_name)
    space = config_space(env, DEFAULT_ROBOT_RADIUS, 0.01)
    for p in env.plans:
        speed = speeds(space, kind)
        full = travel_time(space, xy(p.goal), speed)
        fm = FrontMarch(space, xy(p.goal), speed)
        fm.path(xy(p.start), xy(p.goal))
        t = fm.arrival()
        assert_same_times(full, t, np.isfinite(t))
        iy, ix = space.grid.cell_of(xy(p.start)[None])
        assert np.isfinite(t[iy[0], ix[0]])
        assert fm.accepted < space.free.sum()  # the front stopped before covering the field
        assert not fm.complete


def test_scikit_fmm_masks_speeds_below_the_machine_epsilon_and_so_does_the_march():
    env = load_environment("blocks")
    space = config_space(env, DEFAULT_ROBOT_RADIUS, 0.02)
    speed = np.ones(space.free.shape)
    speed[:, 40:43] = np.finfo(float).eps / 2  # a wall of (almost) zero speed across the field
    speed[:, 43] = np.finfo(float).eps
    for goal in ((0.3, 0.3), (1.5, 1.5)):
        full = travel_time(space, np.array(goal), speed)
        assert np.isinf(full[:, 40:43]).all()
        assert_same_times(full, FrontMarch(space, np.array(goal), speed).field())


# --- paths --------------------------------------------------------------------------------------------------


def full_path(space, start, goal, speed=None, step=1.0):
    return descend(space, travel_time(space, goal, speed), start, goal, step=step)


@pytest.mark.parametrize("kind", ["unit", "fm2"])
@pytest.mark.parametrize("resolution", [0.02, 0.01, 0.005])
@pytest.mark.parametrize("env_name", builtin_names())
def test_paths_equal_the_full_solve_on_every_builtin_problem(env_name, resolution, kind):
    env = load_environment(env_name)
    space = config_space(env, DEFAULT_ROBOT_RADIUS, resolution)
    for p in env.plans:
        s, g = xy(p.start), xy(p.goal)
        speed = speeds(space, kind)
        want, counters = full_path(space, s, g, speed)
        got, info = plan(space, s, g, speed)
        assert np.array_equal(got, want)
        assert {k: info[k] for k in counters} == counters
        assert 0 < info["cells_accepted"] < space.free.sum() and info["descents"] >= 1


@pytest.mark.parametrize("seed", range(12))
def test_paths_equal_the_full_solve_on_random_problems(seed):
    rng = np.random.default_rng(100 + seed)
    env, radius, resolution = random_environment(rng)
    space = config_space(env, radius, resolution)
    if not space.free.any():
        pytest.skip("no free cell")
    pts = free_points(space, rng, 8)
    for s, g in zip(pts[0::2], pts[1::2]):
        for kind in ("unit", "fm2", "random"):
            speed = speeds(space, kind, rng)
            step = float(rng.choice([1.0, 0.5]))
            try:
                want, counters = full_path(space, s, g, speed, step)
            except NoPathFound as exc:  # unreachable (or a descent that fails): the same error
                with pytest.raises(NoPathFound, match=str(exc)):
                    plan(space, s, g, speed, step=step)
                continue
            got, info = plan(space, s, g, speed, step=step)
            assert np.array_equal(got, want)
            assert {k: info[k] for k in counters} == counters


def test_a_descent_that_reads_beyond_the_first_band_marches_on_and_descends_again():
    """The first march covers the band around the start; a path that leaves it (slow cells near walls,
    a start in a corner) reads values not yet final: the march goes on and the descent is done again."""
    again = 0
    for seed in range(1000, 1012):
        rng = np.random.default_rng(seed)
        env, radius, resolution = random_environment(rng)
        space = config_space(env, radius, resolution)
        pts = free_points(space, rng, 6)
        for s, g in zip(pts[0::2], pts[1::2]):
            for kind in ("unit", "fm2"):
                speed = speeds(space, kind, rng)
                try:
                    want, _ = full_path(space, s, g, speed)
                except NoPathFound:
                    continue
                got, info = plan(space, s, g, speed)
                assert np.array_equal(got, want)
                again += info["descents"] > 1
    assert again >= 3


def test_one_march_answers_many_starts_as_the_full_field_does():
    """Studies that reuse one field: each start extends the front only as far as it needs."""
    env = load_environment("room")
    space = config_space(env, DEFAULT_ROBOT_RADIUS, 0.01)
    goal = xy(env.plan("A").goal)
    full = travel_time(space, goal)
    fm = FrontMarch(space, goal)
    rng = np.random.default_rng(7)
    accepted = 0
    starts = free_points(space, rng, 12)
    starts = starts[np.argsort(np.hypot(*(starts - goal).T))]  # nearest first: the front grows query by query
    for s in starts:
        got, _ = fm.path(s, goal)
        assert np.array_equal(got, descend(space, full, s, goal)[0])
        assert fm.accepted >= accepted
        accepted = fm.accepted
    assert np.array_equal(fm.field(), full)


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.004, -0.003), (0.011, 0.0), (0.0, 0.021)])
def test_starts_at_and_around_the_goal(offset):
    """The start in the goal's cell, inside the one-cell circle where the front starts, or next to it."""
    env = load_environment("blocks")
    space = config_space(env, DEFAULT_ROBOT_RADIUS, 0.01)
    g = np.array([0.9, 1.65])
    s = g + np.array(offset)
    for speed in (None, speed_map(space, 0.2, 0.01)):
        want, _ = full_path(space, s, g, speed)
        got, _ = plan(space, s, g, speed)
        assert np.array_equal(got, want)


def test_the_planners_give_the_paths_of_the_full_field():
    env = load_environment("room")
    for name in ("fmm", "fm2"):
        impl = get_planner(name)
        params = impl.validate_params({})
        space = config_space(env, DEFAULT_ROBOT_RADIUS, 0.01)
        for p in env.plans:
            s, g = xy(p.start), xy(p.goal)
            speed = speed_map(space, params["saturation"], params["min_speed"]) if name == "fm2" else None
            got, info = impl.solve(space, s.copy(), g.copy(), params, 0)
            want = full_path(space, s, g, speed)[0]
            if name == "fm2":  # FM² smooths its descent (the same descent, the same passes), straightens it and
                want = smooth_descent(space, want, params["smooth"])[0]  # cuts its corners
                want = band_shortcut(space, want, SHORTCUT_TOLERANCE * space.resolution)[0]
                want = round_corners(space, want, params["round"])[0]
            assert np.array_equal(got, want)
            assert info["cells_accepted"] > 0


def test_fm2_can_cut_the_corners_of_its_straightened_path():
    """``round``: each Chaikin pass halves a corner's largest turn and keeps the ends; a pass that would cross a
    block is refused, the path then kept as it was; the planner reports the refusals."""
    open_space = config_space(parse_environment({"name": "open", "size": [1.0, 1.0], "blocks": []}),
                              DEFAULT_ROBOT_RADIUS, 0.01)
    corner = np.array([[0.2, 0.2], [0.7, 0.2], [0.7, 0.7]])  # a right angle
    got, refused = round_corners(open_space, corner, 3)
    assert refused == 0 and len(got) == 10  # points: 3 -> 4 -> 6 -> 10
    assert np.array_equal(got[0], corner[0]) and np.array_equal(got[-1], corner[-1])
    turn = np.degrees(np.abs(np.diff(np.unwrap(np.arctan2(*np.diff(got, axis=0).T[::-1])))))
    assert turn.max() < 90 / 4 and turn.sum() == pytest.approx(90)
    # a block just inside the corner (its corner 1.5 cm beyond the robot's radius from both legs): cutting the
    # corner would cross it, so nothing is cut
    blocked = config_space(parse_environment({"name": "b", "size": [1.0, 1.0],
                                              "blocks": [{"x": 0.5, "y": 0.3, "w": 0.08, "h": 0.08}]}),
                           DEFAULT_ROBOT_RADIUS, 0.01)
    path = np.array([[0.2, 0.2], [0.6, 0.2], [0.6, 0.6]])
    assert blocked.segments_free(path[:-1], path[1:]).all()
    got, refused = round_corners(blocked, path, 2)
    assert refused == 2 and np.array_equal(got, path)
    info = get_planner("fm2").solve(open_space, np.array([0.2, 0.2]), np.array([0.8, 0.8]),
                                    get_planner("fm2").validate_params({"round": 2}), 0)[1]
    assert info["round_refused"] == 0


# --- unreachable goals --------------------------------------------------------------------------------------

WALLED = parse_environment(
    {"name": "walled", "size": [1.0, 1.0], "blocks": [{"x": 0.5, "y": 0.5, "w": 0.06, "h": 1.0}]}
)


@pytest.mark.parametrize("kind", ["unit", "fm2"])
def test_an_unreachable_goal_is_still_detected(kind):
    space = config_space(WALLED, DEFAULT_ROBOT_RADIUS, 0.01)
    s, g = np.array([0.2, 0.5]), np.array([0.8, 0.5])
    speed = speeds(space, kind)
    with pytest.raises(NoPathFound, match="cannot be reached from the start"):
        full_path(space, s, g, speed)
    with pytest.raises(NoPathFound, match="cannot be reached from the start"):
        plan(space, s, g, speed)
    fm = FrontMarch(space, g, speed)
    with pytest.raises(NoPathFound, match="cannot be reached from the start"):
        fm.path(s, g)
    assert fm.complete  # it marched the goal's whole side, and no further
    assert np.isinf(fm.field()[:, :45]).all()
    # the planners themselves (plan_path refuses the query before planning: test_planners.py)
    for name in ("fmm", "fm2"):
        impl = get_planner(name)
        with pytest.raises(NoPathFound, match="cannot be reached from the start"):
            impl.solve(space, s.copy(), g.copy(), impl.validate_params({}), 0)
        with pytest.raises(NoPathFound, match="separate free regions"):
            plan_path(WALLED, s, g, name)


def test_a_start_in_a_blocked_cell_is_unreachable():
    space = config_space(WALLED, DEFAULT_ROBOT_RADIUS, 0.01)
    with pytest.raises(NoPathFound, match="cannot be reached from the start"):
        plan(space, np.array([0.5, 0.5]), np.array([0.8, 0.5]))


def test_the_cell_states_agree_with_the_kernels():
    from planners import _marching, fast_marching

    assert (fast_marching._FROZEN, fast_marching._MASK) == (_marching.FROZEN, _marching.MASK)
