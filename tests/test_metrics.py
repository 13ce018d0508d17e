"""Path metrics (docs/design.md, "Metrics"): hand-computed values, edge cases, and brute-force references."""

import doctest
import json
import math

import numpy as np
import pytest

import planners.metrics as pm
from planners import parse_environment
from planners.geometry import (
    distance_to_obstacles,
    polyline_clearance,
    polyline_min_clearance,
    segment_clearance,
    segment_distance_to_obstacles,
)
from planners.metrics import (
    COMPARISON_KEYS,
    PATH_KEYS,
    RATIO_KEYS,
    MetricSettings,
    angle_over_length,
    average_speed,
    clearance,
    collided,
    comparison_metrics,
    deviation,
    direct_comparison,
    discrete_frechet,
    execution_time,
    frechet_distance,
    goal_reached,
    hausdorff_distance,
    max_curvature,
    min_clearance,
    path_length,
    path_metrics,
    point_to_polyline_distance,
    ratio_metrics,
    resample,
    run_metrics,
    smoothness,
    turning_angles,
)

SQUARE = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float)


def heading_path(*degrees: float, step: float = 1.0) -> np.ndarray:
    """A polyline whose consecutive segments have the given headings (degrees), each ``step`` long."""
    a = np.radians(degrees)
    return np.vstack([[0.0, 0.0], np.cumsum(np.c_[np.cos(a), np.sin(a)] * step, axis=0)])


def brute_point_to_polyline(q: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance of every point to every segment, the smallest kept (chunked to bound memory)."""
    a, d = line[:-1], np.diff(line, axis=0)
    len2 = (d**2).sum(1)
    out = []
    for part in np.array_split(q, max(1, len(q) // 500)):
        r = part[:, None, :] - a[None]
        t = np.clip((r * d).sum(-1) / np.where(len2 > 0, len2, 1), 0, 1)
        out.append(np.hypot(*(r - t[..., None] * d).transpose(2, 0, 1)).min(1))
    return np.concatenate(out)


def brute_frechet(a: np.ndarray, b: np.ndarray) -> float:
    """Eiter & Mannila's table, filled cell by cell (the reference, for small inputs)."""
    n, m = len(a), len(b)
    c = np.full((n, m), np.inf)
    for i in range(n):
        for j in range(m):
            d = math.dist(a[i], b[j])
            if i == 0 and j == 0:
                c[i, j] = d
            else:
                prev = min(
                    c[i - 1, j] if i else np.inf, c[i, j - 1] if j else np.inf, c[i - 1, j - 1] if i and j else np.inf
                )
                c[i, j] = max(d, prev)
    return float(c[-1, -1])


def test_docstring_examples():
    assert doctest.testmod(pm).failed == 0


# ---------------------------------------------------------------- length and resampling


def test_unit_square_length_and_heading_column_ignored():
    assert path_length(SQUARE) == 4.0
    with_theta = np.c_[SQUARE, [9, 9, 9, 9, 9]]
    assert path_length(with_theta) == 4.0


def test_resample_is_even_in_arc_length_with_both_ends():
    out = resample(SQUARE, 9)
    expect = [[0, 0], [0.5, 0], [1, 0], [1, 0.5], [1, 1], [0.5, 1], [0, 1], [0, 0.5], [0, 0]]
    np.testing.assert_allclose(out, expect, atol=1e-15)
    rng = np.random.default_rng(0)
    path = np.cumsum(rng.normal(size=(30, 2)), axis=0)
    r = resample(path, 57)
    assert np.array_equal(r[0], path[0]) and np.array_equal(r[-1], path[-1])
    # every resampled point lies on the path at arc length k L / (n - 1)
    s_path = np.r_[0, np.cumsum(np.hypot(*np.diff(path, axis=0).T))]
    s_want = np.linspace(0, s_path[-1], 57)
    x = np.interp(s_want, s_path, path[:, 0])
    y = np.interp(s_want, s_path, path[:, 1])
    np.testing.assert_allclose(r, np.c_[x, y], atol=1e-12)


def test_resample_handles_zero_length_segments_and_paths():
    dup = np.array([[0, 0], [0, 0], [1, 0], [1, 0], [1, 0], [1, 2], [1, 2]], dtype=float)
    np.testing.assert_allclose(resample(dup, 4), [[0, 0], [1, 0], [1, 1], [1, 2]], atol=1e-15)
    still = np.zeros((5, 2)) + 0.3
    assert np.array_equal(resample(still, 3), np.full((3, 2), 0.3))


# ---------------------------------------------------------------- turning angles and smoothness


def test_unit_square_smoothness_for_given_segment_counts():
    # 4 segments: the corners, three right angles: sqrt(3 (pi/2)^2 / 3)
    assert smoothness(SQUARE, segments=4) == pytest.approx(math.pi / 2, abs=1e-12)
    # 8 segments of 0.5 m: 7 vertices, 3 of them corners
    assert smoothness(SQUARE, segments=8) == pytest.approx(math.pi / 2 * math.sqrt(3 / 7), abs=1e-12)
    # default: segments of 0.05 m -> m = 80, 79 vertices, 3 corners
    assert smoothness(SQUARE) == pytest.approx(math.pi / 2 * math.sqrt(3 / 79), abs=1e-12)
    # AOL: total turning 3 pi/2 over 4 m; curvature: pi/2 over 0.05 m
    assert angle_over_length(SQUARE) == pytest.approx(3 * math.pi / 2 / 4, abs=1e-12)
    assert max_curvature(SQUARE) == pytest.approx(math.pi / 2 / 0.05, rel=1e-9)


def test_heading_change_from_170_to_minus_170_degrees_is_a_20_degree_turn():
    alpha = turning_angles(heading_path(170, -170))
    assert alpha == pytest.approx([math.radians(20)], abs=1e-12)
    assert turning_angles(heading_path(-170, 170)) == pytest.approx([math.radians(20)], abs=1e-12)
    assert turning_angles(heading_path(10, -10, 350)) == pytest.approx([math.radians(20), 0], abs=1e-12)


def test_a_reversal_is_pi():
    back = np.array([[0, 0], [1, 0], [0.5, 0]], dtype=float)
    assert turning_angles(back) == pytest.approx([math.pi], abs=0)
    assert smoothness(back, segments=2) == pytest.approx(math.pi, abs=1e-12)


def test_collinear_points_with_rounding_noise_give_zero_not_nan():
    t = np.arange(50) * 0.1
    line = np.c_[0.3 + t * 0.7, 1.1 - t * 0.3]  # rounding makes u.v/(|u||v|) stray from 1 either way
    alpha = turning_angles(line)
    assert np.isfinite(alpha).all() and alpha.max() < 1e-12
    assert smoothness(line) < 1e-12
    assert angle_over_length(line) < 1e-12 and max_curvature(line) < 1e-9
    # a cosine just above 1 would be NaN without clipping
    u, v = np.diff(line[:3], axis=0)
    naive = np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v))
    assert abs(naive - 1) < 1e-15


def test_turning_angles_match_the_clipped_arccos_definition():
    rng = np.random.default_rng(2)
    path = np.cumsum(rng.normal(size=(500, 2)), axis=0)
    d = np.diff(path, axis=0)
    u, v = d[:-1], d[1:]
    cos = (u * v).sum(1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
    np.testing.assert_allclose(turning_angles(path), np.arccos(np.clip(cos, -1, 1)), atol=1e-7)


def test_zero_length_segments_are_dropped_before_turning():
    path = heading_path(0, 90, 180)
    dup = np.repeat(path, [1, 3, 2, 1], axis=0)
    np.testing.assert_array_equal(turning_angles(dup), turning_angles(path))
    assert smoothness(dup, segments=3) == pytest.approx(math.pi / 2, abs=1e-12)


def test_degenerate_paths_have_no_turning():
    still = np.zeros((4, 2))
    assert smoothness(still) == 0 and angle_over_length(still) == 0 and max_curvature(still) == 0
    assert turning_angles(np.array([[0, 0], [1, 1]])).size == 0
    assert smoothness(np.array([[0, 0], [2, 0]])) == 0


# ---------------------------------------------------------------- deviation and distances between paths


def test_constant_10_mm_offset_with_staggered_samples_is_10_mm():
    planned = np.c_[np.linspace(0, 1.5, 16), np.zeros(16)]
    x = np.r_[0, np.arange(0.05, 1.5, 0.1), 1.5]  # halfway between the planned points
    performed = np.c_[x, np.full(len(x), 0.01)]
    dev = deviation(planned, performed)
    assert dev.shape == (200,)
    np.testing.assert_allclose(dev, 0.01, rtol=0, atol=1e-12)
    m = comparison_metrics(planned, performed)
    assert m["deviation_mean_m"] == pytest.approx(0.01, abs=1e-12)
    assert m["deviation_max_m"] == pytest.approx(0.01, abs=1e-12)
    # turned by 30 degrees and with a different sample count: still 10 mm
    c, s = math.cos(0.5236), math.sin(0.5236)
    rot = np.array([[c, -s], [s, c]])
    assert deviation(planned @ rot.T, performed @ rot.T, n=37) == pytest.approx(np.full(37, 0.01), abs=1e-12)


def test_point_to_polyline_matches_brute_force():
    rng = np.random.default_rng(3)
    for trial in range(30):
        n = int(rng.integers(2, 60))
        line = np.cumsum(rng.normal(scale=rng.choice([0.01, 0.3]), size=(n, 2)), axis=0)
        if n > 8 and trial % 3 == 0:
            line[4:7] = line[4]  # zero-length segments
        if trial % 4 == 0:
            line = np.vstack([line, line[-1] + [5.0, 0.0]])  # one segment far longer than the rest
        q = line.mean(0) + rng.normal(scale=rng.choice([0.05, 2.0]), size=(200, 2))
        np.testing.assert_allclose(point_to_polyline_distance(q, line), brute_point_to_polyline(q, line), atol=1e-12)


def test_point_to_polyline_many_points_on_a_dense_line_matches_brute_force():
    # far more points than 8192 (the strided pilot chooses the first k) and a
    # polyline much denser than the distances measured
    rng = np.random.default_rng(4)
    s = np.linspace(0, 1, 2000)
    line = np.c_[s * 3, np.sin(9 * s)]
    q = np.repeat(line, 6, axis=0)[: 12000] + rng.normal(scale=0.02, size=(12000, 2))
    np.testing.assert_allclose(point_to_polyline_distance(q, line), brute_point_to_polyline(q, line), atol=1e-12)


def test_point_to_polyline_degenerate_inputs():
    assert point_to_polyline_distance(np.zeros((0, 2)), SQUARE).shape == (0,)
    assert point_to_polyline_distance([[3.0, 4.0]], [[0.0, 0.0]]) == pytest.approx([5.0])
    assert point_to_polyline_distance([[3.0, 4.0]], np.zeros((3, 2))) == pytest.approx([5.0])


def test_hausdorff_against_dense_sampling_and_deviation():
    rng = np.random.default_rng(5)
    a = np.cumsum(rng.normal(scale=0.1, size=(20, 2)), axis=0)
    b = a + rng.normal(scale=0.02, size=a.shape)
    h = hausdorff_distance(a, b, n=400)
    assert h == pytest.approx(hausdorff_distance(b, a, n=400), abs=1e-15)
    dense_a, dense_b = resample(a, 20000), resample(b, 20000)
    ref = max(brute_point_to_polyline(dense_a, b).max(), brute_point_to_polyline(dense_b, a).max())
    spacing = max(path_length(a), path_length(b)) / 399
    assert ref - spacing / 2 - 1e-12 <= h <= ref + 1e-12
    assert h >= deviation(a, b, n=400).max() - 1e-15
    assert comparison_metrics(a, b, samples=400)["hausdorff_m"] == pytest.approx(h, abs=1e-15)


def test_discrete_frechet_matches_the_cell_by_cell_table():
    rng = np.random.default_rng(6)
    for _ in range(25):
        a = rng.normal(size=(int(rng.integers(1, 25)), 2))
        b = rng.normal(size=(int(rng.integers(1, 25)), 2))
        assert discrete_frechet(a, b) == pytest.approx(brute_frechet(a, b), abs=1e-12)


def test_frechet_known_values():
    line = np.c_[np.linspace(0, 1, 11), np.zeros(11)]
    assert discrete_frechet(line, line) == 0
    assert frechet_distance(line, line + [0, 0.01]) == pytest.approx(0.01, abs=1e-12)
    # the same points walked the other way: Hausdorff 0, Fréchet the whole length
    assert hausdorff_distance(line, line[::-1]) < 1e-12
    assert frechet_distance(line, line[::-1]) == pytest.approx(1.0, abs=1e-12)


def test_direct_comparison_is_sim_in_the_role_of_p0():
    rng = np.random.default_rng(7)
    sim = np.cumsum(rng.normal(scale=0.1, size=(30, 2)), axis=0)
    twb = sim + rng.normal(scale=0.01, size=sim.shape)
    assert direct_comparison(sim, twb) == comparison_metrics(sim, twb)
    assert direct_comparison(sim, twb)["deviation_mean_m"] == pytest.approx(deviation(sim, twb).mean())


# ---------------------------------------------------------------- clearance


def env_with(*blocks, size=(2.0, 2.0)):
    return parse_environment({"name": "t", "size": list(size), "blocks": list(blocks)})


def test_straight_path_passing_a_turned_block_gets_the_analytic_clearance():
    # a square turned 45 degrees: its top corner is at (1, 1 + 0.1 sqrt 2)
    env = env_with({"x": 1, "y": 1, "w": 0.2, "h": 0.2, "angle": math.pi / 4})
    path = np.array([[0.3, 1.3], [1.7, 1.3]])
    exact = 1.3 - (1 + 0.1 * math.sqrt(2))
    assert min_clearance(env, path) == pytest.approx(exact, abs=1e-12)
    # the two vertices are far away, and even 200 samples miss the corner
    assert distance_to_obstacles(env, path).min() > exact + 0.1
    assert clearance(env, path).min() > exact + 1e-6
    m = path_metrics(path, env=env)
    assert m["clearance_min_m"] == pytest.approx(exact, abs=1e-12)
    assert m["clearance_mean_m"] == pytest.approx(clearance(env, path).mean(), abs=1e-15)


def test_clearance_of_a_path_along_a_face_and_walls():
    env = env_with({"x": 1.0, "y": 0.8, "w": 0.4, "h": 0.2})
    path = np.array([[0.5, 0.5], [1.5, 0.5]])  # 0.2 below the block's face at y = 0.7, x in 0.8..1.2
    assert min_clearance(env, path) == pytest.approx(0.2, abs=1e-12)
    np.testing.assert_allclose(clearance(env, path, n=5), [math.hypot(0.3, 0.2), math.hypot(0.05, 0.2), 0.2,
                                                           math.hypot(0.05, 0.2), math.hypot(0.3, 0.2)], atol=1e-12)
    near_wall = np.array([[0.05, 1.5], [0.5, 1.9]])
    assert min_clearance(env, near_wall) == pytest.approx(0.05, abs=1e-12)


def test_clearance_is_zero_inside_blocks_and_outside_the_field():
    env = env_with({"x": 1.0, "y": 1.0, "w": 0.2, "h": 0.2})
    through = np.array([[0.5, 1.0], [1.5, 1.0]])  # crosses the block, both ends free
    assert min_clearance(env, through) == 0
    assert collided(env, through)
    out = np.array([[0.5, 0.5], [2.5, 0.5]])
    assert min_clearance(env, out) == 0


def test_collided_uses_the_robot_radius():
    env = env_with({"x": 1.0, "y": 0.8, "w": 0.4, "h": 0.2})
    path = np.array([[0.5, 0.5], [1.5, 0.5]])  # 0.2 m from the block
    assert not collided(env, path, robot_radius=0.19)
    assert collided(env, path, robot_radius=0.21)
    assert path_metrics(path, env=env, settings=MetricSettings(robot_radius=0.21))["collided"] is True


@pytest.mark.parametrize("name", ["room", "blocks"])
def test_exact_segment_clearance_against_dense_sampling(name):
    from planners import load_environment

    env = load_environment(name)
    rng = np.random.default_rng(8)
    a = rng.random((400, 2)) * 1.8
    b = np.clip(a + rng.normal(scale=0.2, size=a.shape), 0, 1.8)
    exact = segment_clearance(env, a, b)
    spacing = 5e-4
    sampled = segment_distance_to_obstacles(env, a, b, spacing=spacing)
    # sampling can only miss the minimum, by at most half a spacing (1-Lipschitz)
    assert np.all(exact <= sampled + 1e-12)
    assert np.all(sampled - exact <= spacing / 2 + 1e-12)
    # a polyline: per segment, and the pruned exact minimum
    path = np.clip(np.cumsum(rng.normal(scale=0.03, size=(300, 2)), axis=0) + 0.9, 0, 1.8)
    per = polyline_clearance(env, path)
    np.testing.assert_array_equal(per, segment_clearance(env, path[:-1], path[1:]))
    for chunk in (1, 7, 32, 1000):
        assert polyline_min_clearance(env, path, chunk=chunk) == per.min()


def test_clearance_metrics_need_an_environment():
    m = path_metrics(SQUARE)
    assert m["clearance_min_m"] is None and m["clearance_mean_m"] is None and m["collided"] is None


# ---------------------------------------------------------------- time, speed, goal


def test_average_speed_uses_path_length_not_displacement():
    out_and_back = np.array([[0.2, 0.2], [1.2, 0.2], [0.2, 0.2]])
    t = np.array([3.0, 8.0, 13.0])
    m = path_metrics(out_and_back, t=t)
    assert m["execution_time_s"] == 10.0
    assert m["average_speed_m_s"] == pytest.approx(0.2)
    assert average_speed(out_and_back, 10.0) == pytest.approx(0.2)
    assert math.isnan(average_speed(out_and_back, 0.0))
    assert path_metrics(out_and_back, t=[1.0, 1.0, 1.0])["average_speed_m_s"] is None


def test_execution_time_from_events_or_from_the_log():
    t = np.array([0.5, 1.0, 4.5])
    assert execution_time(t) == 4.0
    assert execution_time(t, start=0.7, done=4.2) == pytest.approx(3.5)
    m = path_metrics(SQUARE, t=np.arange(5.0), start_time=0.5, done_time=3.0)
    assert m["execution_time_s"] == 2.5 and m["average_speed_m_s"] == pytest.approx(4 / 2.5)
    with pytest.raises(ValueError, match="both `start` and `done`"):
        execution_time(t, start=1.0)
    with pytest.raises(ValueError, match="`done`"):
        execution_time(t, start=2.0, done=1.0)


def test_goal_reached_within_the_tolerance():
    path = np.array([[0, 0], [1.0, 0.03]])
    assert goal_reached(path, [1.0, 0.0, 3.0], tolerance=0.03)
    assert not goal_reached(path, [1.0, 0.0], tolerance=0.029)
    assert path_metrics(path, goal=[1.0, 0.0])["goal_reached"] is True  # default 0.05 m
    assert path_metrics(path)["goal_reached"] is None


# ---------------------------------------------------------------- dictionaries


def test_run_metrics_keys_values_and_json():
    env = env_with({"x": 1.0, "y": 1.0, "w": 0.2, "h": 0.2})
    planned = np.array([[0.2, 0.2, 0.0], [1.6, 0.2, 0.0], [1.6, 1.6, 1.57]])
    performed = np.array([[0.2, 0.21], [1.0, 0.21], [1.59, 0.25], [1.59, 1.0], [1.58, 1.6]])
    t = np.linspace(0, 20, len(performed))
    m = run_metrics(planned, performed, env=env, t=t, planning_time_s=0.25)
    assert set(m) == set(PATH_KEYS) | set(COMPARISON_KEYS) | set(RATIO_KEYS) | {"planning_time_s", "planned"}
    assert set(m["planned"]) == set(PATH_KEYS)
    json.dumps(m, allow_nan=False)
    assert m["planned"]["length_m"] == pytest.approx(2.8)
    assert m["length_m"] == pytest.approx(path_length(performed))
    assert m["length_ratio"] == pytest.approx(path_length(performed) / 2.8)
    assert m["smoothness_ratio"] == pytest.approx(m["smoothness_rad"] / m["planned"]["smoothness_rad"])
    assert m["clearance_ratio"] == pytest.approx(m["clearance_min_m"] / m["planned"]["clearance_min_m"])
    assert m["execution_time_s"] == 20 and m["planning_time_s"] == 0.25
    assert m["goal_reached"] is True and m["planned"]["goal_reached"] is True
    assert m["planned"]["execution_time_s"] is None


def test_ratios_are_none_when_undefined():
    straight = np.array([[0.0, 0.0], [1.0, 0.0]])
    m = run_metrics(straight, np.array([[0.0, 0.0], [0.5, 0.1], [1.0, 0.0]]))
    assert m["smoothness_ratio"] is None  # the planned path does not turn
    assert m["clearance_ratio"] is None  # no environment
    assert ratio_metrics({"length_m": 2.0}, {"length_m": 0.0})["length_ratio"] is None


def test_settings_are_validated_and_serialised():
    s = MetricSettings(samples=50, segments=10)
    assert s.to_dict()["samples"] == 50 and s.to_dict()["segments"] == 10
    with pytest.raises(ValueError, match="`samples` must be an integer >= 2"):
        MetricSettings(samples=1)
    with pytest.raises(ValueError, match="`segments` must be an integer >= 2"):
        MetricSettings(segments=1)
    with pytest.raises(ValueError, match="`robot_radius` must be a finite number >= 0"):
        MetricSettings(robot_radius=-0.1)
    with pytest.raises(ValueError, match="`segment_length` must be a finite number > 0"):
        MetricSettings(segment_length=0)


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "bad, match",
    [
        (np.array([[0.0, 0.0], [np.nan, 1.0]]), r"`path` must be finite: point 1"),
        (np.array([[0.0, 0.0], [np.inf, 1.0]]), r"`path` must be finite"),
        (np.array([[0.0, 0.0]]), r"`path` must have at least 2 points, got 1"),
        (np.zeros((0, 2)), r"`path` must have at least 2 points, got 0"),
        (np.zeros(4), r"`path` must have shape \(N, 2\) or \(N, 3\), got \(4,\)"),
        (np.zeros((3, 4)), r"`path` must have shape \(N, 2\) or \(N, 3\)"),
        ([["a", "b"], ["c", "d"]], r"`path` must be an array of numbers"),
    ],
)
def test_bad_paths_are_refused(bad, match):
    for fn in (path_length, smoothness, turning_angles, lambda p: resample(p, 5)):
        with pytest.raises(ValueError, match=match):
            fn(bad)


def test_bad_arguments_are_refused_naming_the_parameter():
    with pytest.raises(ValueError, match="`planned` must be finite"):
        deviation([[0, 0], [np.nan, 0]], SQUARE)
    with pytest.raises(ValueError, match="`performed` must have at least 2 points"):
        deviation(SQUARE, [[0, 0]])
    with pytest.raises(ValueError, match="`n` must be an integer >= 2"):
        resample(SQUARE, 1)
    with pytest.raises(ValueError, match="`n` must be an integer >= 2"):
        deviation(SQUARE, SQUARE, n=2.5)
    with pytest.raises(ValueError, match="`segments` must be an integer >= 2"):
        smoothness(SQUARE, segments=1)
    with pytest.raises(ValueError, match="`t` must be non-decreasing"):
        path_metrics(SQUARE, t=[0, 1, 3, 2, 4])
    with pytest.raises(ValueError, match="`t` must have one time per point"):
        path_metrics(SQUARE, t=[0, 1, 2])
    with pytest.raises(ValueError, match="`t` must be finite"):
        execution_time([0, np.nan, 2])
    with pytest.raises(ValueError, match="`goal` must be finite"):
        goal_reached(SQUARE, [np.nan, 0])
    with pytest.raises(ValueError, match="`robot_radius` must be a finite number >= 0"):
        collided(env_with(), SQUARE * 0.5, robot_radius=-1)


# ---------------------------------------------------------------- moving obstacles
# (docs/metrics.md, "Moving obstacles and collisions by kind")


def test_obstacle_distance_and_time_within_a_safety_radius():
    from planners import parse_environment
    from planners.metrics import OBSTACLE_KEYS, obstacle_gaps, obstacle_metrics

    # a disc of 0.05 m standing at (1.0, 0.5) until t = 10 s, then leaving upwards at 0.1 m/s
    env = parse_environment({"name": "m", "size": [1.8, 1.8], "moving_obstacles": [
        {"radius": 0.05, "waypoints": [[1.0, 0.5], [1.0, 1.5]], "speed": 0.1, "delay_s": 10.0}]})
    t = np.arange(0.0, 20.01, 0.5)
    path = np.column_stack([0.2 + 0.08 * t, np.full_like(t, 0.3)])  # along y = 0.3, at x = 1.0 at t = 10
    gaps = obstacle_gaps(env, path, t, robot_radius=0.04)
    centre = np.column_stack([np.full_like(t, 1.0), 0.5 + 0.1 * np.maximum(t - 10, 0)])
    np.testing.assert_allclose(gaps, np.hypot(*(path - centre).T) - 0.09, atol=1e-12)
    # obstacle time counts from the start time: the same samples logged 5 s later, with start_time 5
    s = MetricSettings(robot_radius=0.04, obstacle_safety=0.15)
    m = obstacle_metrics(env, path, t + 5.0, start_time=5.0, settings=s)
    assert m["obstacle_distance_min_m"] == pytest.approx(gaps.min()) and gaps.min() == pytest.approx(0.2 - 0.09)
    assert m["obstacle_time_within_s"] == pytest.approx(0.5 * (gaps[:-1] < 0.15).sum())
    assert m["obstacle_time_within_s"] > 0
    assert obstacle_metrics(env, path, t, settings=MetricSettings(obstacle_safety=0.0))["obstacle_time_within_s"] == 0
    full = run_metrics(path, path, env=env, t=t, start_time=0.0, done_time=20.0, settings=s)
    assert {k: full[k] for k in OBSTACLE_KEYS} == obstacle_metrics(env, path, t, start_time=0.0, settings=s)
    static = parse_environment({"name": "s", "size": [1.8, 1.8]})
    assert not set(OBSTACLE_KEYS) & set(run_metrics(path, path, env=static, t=t))
    assert obstacle_metrics(static, path, t) == {k: None for k in OBSTACLE_KEYS}
