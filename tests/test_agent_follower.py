"""The follower, kinematics, noise, world and simulation core as pure computation (no sockets)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robot_agent import follower as fl
from robot_agent.backends import make_backend
from robot_agent.kinematics import body_to_tracks, tracks_to_body, unicycle_step, wrap_angle
from robot_agent.noise import normals, path_key, uniforms
from robot_agent.params import robot_params
from robot_agent.robot_profile import load_profile, profile_names
from robot_agent.sim import SimCore, State
from robot_agent.world import SUBFIELD_ORIGINS, World, field_layout

P = robot_params("bebot")
C = P.controller


def test_every_profile_value_has_a_note():
    for name in profile_names():
        prof = load_profile(name)
        robot_params(prof)  # complete and valid
        notes = prof["notes"]
        for key, value in prof.items():
            if key in ("name", "platform", "notes"):
                continue
            if isinstance(value, dict):
                for sub in value:
                    assert f"{key}.{sub}" in notes, f"{name}: {key}.{sub} has no note"
            else:
                assert key in notes, f"{name}: {key} has no note"


def test_bad_profile_names_the_key():
    prof = load_profile("bebot")
    prof["controller"] = {**prof["controller"], "heading_gain_1_s": float("nan")}
    with pytest.raises(ValueError, match="heading_gain_1_s"):
        robot_params(prof)


def test_move_to_waypoint_points_at_target_with_given_speed():
    xy = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    tgt = np.array([[3.0, 4.0], [1.0, 0.0], [2.0, 2.0]])
    v = fl.move_to_waypoint(xy, tgt, np.array([0.5, 0.2, 0.3]))
    np.testing.assert_allclose(v, [[0.3, 0.4], [0.0, -0.2], [0.0, 0.0]], atol=1e-12)


def test_heading_control_turns_towards_and_slows_with_error():
    theta = np.array([0.0, 0.0, 0.0])
    vec = np.array([[0.2, 0.0], [0.0, 0.2], [-0.2, 0.0]])
    v, w = fl.heading_control(theta, vec, C, P.max_angular_speed_rad_s)
    assert v[0] == pytest.approx(0.2) and w[0] == 0.0
    assert v[1] == 0.0 and w[1] == pytest.approx(min(C.heading_gain_1_s * math.pi / 2, P.max_angular_speed_rad_s))
    assert v[2] == 0.0 and abs(w[2]) == pytest.approx(P.max_angular_speed_rad_s)
    small = fl.heading_control(np.array([0.3]), np.array([[0.2, 0.0]]), C, 3.0)
    assert small[0][0] == pytest.approx(0.2 * math.cos(0.3)) and small[1][0] == pytest.approx(-C.heading_gain_1_s * 0.3)


def test_align_control_has_minimum_rate_and_stops_inside_tolerance():
    w, aligned = fl.align_control(np.array([0.0, 0.0, 0.0]), np.array([0.01, 0.1, -2.0]), C, 3.0)
    assert aligned.tolist() == [True, False, False]
    assert w[0] == 0.0
    assert w[1] == pytest.approx(max(C.min_turn_rate_rad_s, C.heading_gain_1_s * 0.1))
    assert w[2] == pytest.approx(-3.0)


def test_rate_limit():
    out = fl.rate_limit(np.array([0.0, 0.1, 0.2]), np.array([1.0, 0.12, -1.0]), 0.05)
    np.testing.assert_allclose(out, [0.05, 0.12, 0.15])


def test_advance_waypoints_skips_several_close_points_and_detects_arrival():
    points = np.array([[0, 0, 0], [0.01, 0, 0], [0.02, 0, 0], [1, 0, 0], [5, 5, 0], [5.001, 5, 0]], float)
    offset, count = np.array([0, 4]), np.array([4, 2])
    wp, arrived = fl.advance_waypoints(np.array([[0.0, 0.0], [5.0, 5.0]]), points, offset, count,
                                       np.array([0, 0]), np.array([True, True]), C)
    assert wp.tolist() == [3, 1]
    assert arrived.tolist() == [False, True]
    wp2, arrived2 = fl.advance_waypoints(np.array([[0.0, 0.0], [5.0, 5.0]]), points, offset, count,
                                         np.array([0, 0]), np.array([False, False]), C)
    assert wp2.tolist() == [0, 0] and not arrived2.any()


def test_stall_and_timeout():
    belief = np.zeros((2, 3))
    anchor = np.zeros((2, 3))
    anchor_k = np.zeros(2, dtype=np.int64)
    steps = int(C.stall_time_s / P.dt) + 1
    belief[1, 0] = 0.5  # robot 1 made progress
    stalled = fl.stall_update(belief, anchor, anchor_k, np.array([steps, steps]), np.array([True, True]), C, P.dt)
    assert stalled.tolist() == [True, False]
    assert anchor_k.tolist() == [0, steps]
    n = fl.timeout_steps(np.array([[1.0, 0, 0], [1.0, 1.0, 0]]), np.zeros(2), C, 0.2, 0.02)
    assert n == math.ceil((C.timeout_base_s + C.timeout_factor * 2.0 / 0.2) / 0.02)


def test_kinematics():
    pose = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2]])
    out = unicycle_step(pose, np.array([[0.1, 0.0], [0.0, 1.0]]), 0.5)
    np.testing.assert_allclose(out, [[0.05, 0, 0], [1, 1, math.pi / 2 + 0.5]])
    vw = np.array([[0.2, 1.0], [-0.1, -2.0]])
    np.testing.assert_allclose(tracks_to_body(body_to_tracks(vw, 0.07), 0.07), vw)
    assert wrap_angle(np.array([3 * math.pi]))[0] == pytest.approx(-math.pi)


def test_noise_is_a_pure_function_of_key_and_counter():
    keys = np.array([path_key(1), path_key(1), path_key(2)], dtype=np.uint64)
    u = uniforms(keys, np.array([5, 5, 5]), 4)
    assert (u[0] == u[1]).all() and not (u[0] == u[2]).any()
    assert ((u > 0) & (u < 1)).all()
    z = normals(np.full(20000, path_key(3), dtype=np.uint64), np.arange(20000), 3)
    assert abs(z.mean()) < 0.03 and abs(z.std() - 1) < 0.03
    assert path_key(7, "robot-1", 0) != path_key(7, "robot-2", 0) != path_key(7, "robot-1", 1)


def test_field_layout():
    sizes, world_of, origin, area = field_layout(4)
    assert sizes.tolist() == [[3.6, 3.6]] and world_of.tolist() == [0, 0, 0, 0]
    assert [tuple(o) for o in origin.tolist()] == list(SUBFIELD_ORIGINS)
    _, _, origin, area = field_layout(1, area=(3.6, 3.6))
    assert origin.tolist() == [[0, 0]] and area.tolist() == [[3.6, 3.6]]
    sizes, world_of, _, _ = field_layout(10)
    assert len(sizes) == 10 and world_of.tolist() == list(range(10))
    _, _, origin, area = field_layout(4, "shared", area=[(3.6, 3.6)] + [(1.8, 1.8)] * 3)
    assert origin.tolist() == [[0, 0], [1.8, 0], [0, 1.8], [1.8, 1.8]] and area[0].tolist() == [3.6, 3.6]
    with pytest.raises(ValueError, match="once per robot"):
        field_layout(2, area=[(1.0, 1.0)] * 3)
    with pytest.raises(ValueError, match="4 sub-fields"):
        field_layout(5, "shared")
    with pytest.raises(ValueError, match="inside"):
        field_layout(2, area=(3.6, 3.7))


def test_world_collisions_blocks_walls_robots_and_frames():
    sizes, world_of, origin, area = field_layout(2)
    w = World(sizes, world_of, origin, area, 0.04)
    w.set_blocks(0, np.array([[0.9, 0.9, 0.2, 0.2, math.pi / 4]]))
    poses = np.array([[0.9, 0.9 + 0.14 + 0.035, 0], [0.5, 0.5, 0]])  # robot 1 is at (2.3, 0.5) in the world
    hit = w.collisions(poses, np.array([True, True]))
    assert hit.tolist() == [True, False]  # the rotated block's corner reaches y = 0.9 + 0.1414
    assert w.place_conflict(0, (0.02, 0.5, 0), poses) is not None  # the wall
    poses2 = np.array([[1.78, 0.5, 0], [0.0 + 0.03, 0.5, 0]])  # 5 cm apart across the sub-field border
    assert w.collisions(poses2, np.array([True, False])).tolist() == [True, False]
    np.testing.assert_allclose(w.blocks_local(0)[:, :2], [[0.9, 0.9]])


def _core(backend: str, n: int = 1) -> SimCore:
    sizes, world_of, origin, area = field_layout(n, "separate")
    return SimCore(P, make_backend(backend, n, P), World(sizes, world_of, origin, area, P.collision_radius_m))


def _drive(core: SimCore, steps: int = 20000) -> list:
    events = []
    for _ in range(steps):
        events += core.step()
        if not (core.state == State.MOVING).any():
            break
    return events


@pytest.mark.parametrize("backend", ["ideal", "field"])
def test_core_follows_a_path_to_the_goal(backend):
    core = _core(backend)
    core.place(0, (0.3, 0.3, 0.0))
    path = np.array([[0.3, 0.3, 0], [1.0, 0.3, 0], [1.0, 1.0, math.pi]])
    core.set_path(0, path, path_key(1))
    events = _drive(core)
    kinds = [(e.kind, e.index) for e in events]
    assert kinds[0] == ("START", None) and kinds[-1] == ("DONE", None)
    assert [i for k, i in kinds if k == "WP"] == [0, 1, 2]
    tol = C.goal_tolerance_m + (0.0 if backend == "ideal" else 0.02)
    assert math.hypot(*(core.backend.pose[0, :2] - path[-1, :2])) < tol
    assert abs(wrap_angle(np.array([core.backend.pose[0, 2] - math.pi]))[0]) < C.angle_tolerance_rad + 0.1
