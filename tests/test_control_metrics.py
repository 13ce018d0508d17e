"""Controller metrics (planners.control_metrics) on motions whose values are known by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners import parse_environment
from planners.control_metrics import CONTROL_KEYS, ControlSettings, barn_score, control_metrics, rising_edges, spl

LINE = np.array([[0.0, 0.0], [1.0, 0.0]])
GOAL = np.array([1.0, 0.0])


def _drive(x: np.ndarray, t: np.ndarray, y: float = 0.0, theta: float = 0.0) -> np.ndarray:
    return np.column_stack([x, np.full_like(x, y), np.full_like(x, theta)])


def test_a_steady_offset_drive_along_a_line():
    t = np.linspace(0.0, 5.0, 251)
    poses = _drive(0.2 * t, t, y=0.01, theta=0.1)
    m = control_metrics(LINE, poses, t, goal=GOAL, settings=ControlSettings(max_speed=0.2))
    assert set(m) == set(CONTROL_KEYS)
    assert m["cross_track_error_mean_m"] == pytest.approx(0.01) and m["cross_track_error_max_m"] == pytest.approx(0.01)
    assert m["heading_error_rms_rad"] == pytest.approx(0.1)
    assert m["time_to_goal_s"] == pytest.approx(4.76, abs=0.021)  # within 5 cm of the goal at x = 0.95 m
    assert m["jerk_linear_rms_m_s3"] == pytest.approx(0.0, abs=1e-9)
    assert m["velocity_smoothness_m_s2"] == pytest.approx(0.0, abs=1e-9)
    assert m["stop_count"] == 0 and m["collision_count"] is None
    assert m["spl"] == pytest.approx(1.0) and m["barn_score"] == 0.5  # 5 s = OT: at most 2 OT scores 0.5


def test_the_cross_track_error_is_a_mean_over_time():
    t = np.array([0.0, 1.0, 2.0, 10.0])  # 8 of 10 s at 2 cm, 2 s near 0
    poses = np.array([[0.1, 0.0, 0.0], [0.2, 0.0, 0.0], [0.3, 0.02, 0.0], [1.0, 0.02, 0.0]])
    m = control_metrics(LINE, poses, t, goal=GOAL)
    assert m["cross_track_error_mean_m"] == pytest.approx((0.5 * 0.02 + 8 * 0.02) / 10)


def test_a_halt_on_the_way_is_a_stop_and_jerk_shows_the_changes():
    t = np.linspace(0.0, 9.0, 901)
    v = np.where((t > 3.0) & (t < 5.0), 0.0, 0.15)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    m = control_metrics(LINE, _drive(x, t), t, goal=GOAL)
    assert m["stop_count"] == 1 and m["time_to_goal_s"] is not None
    assert m["jerk_linear_rms_m_s3"] > 0.5 and m["velocity_smoothness_m_s2"] > 0.0
    never = control_metrics(LINE, _drive(0.5 * x, t), t, goal=GOAL)
    assert never["time_to_goal_s"] is None and never["spl"] == 0.0 and never["barn_score"] == 0.0


def test_collisions_count_each_contact_once():
    env = parse_environment({"name": "b", "size": [1.0, 0.5], "blocks": [{"x": 0.5, "y": 0.3, "w": 0.1, "h": 0.1}]})
    t = np.linspace(0.0, 10.0, 1001)
    y = 0.2 + 0.04 * np.cos(2 * math.pi * t / 5)  # comes within 1 cm of the block at t = 0, 5 and 10 s
    poses = np.column_stack([np.full_like(t, 0.5), y, np.zeros_like(t)])
    m = control_metrics(np.array([[0.5, 0.2], [0.5, 0.16]]), poses, t, goal=np.array([0.5, 0.16]), env=env,
                        settings=ControlSettings(collision_radius=0.04))
    assert m["collision_count"] == 3  # t = 0, 5 and 10 s: the block's edge is at y = 0.25
    assert rising_edges(np.array([False, True, True, False, True])) == 2


def test_spl_and_barn_follow_their_definitions():
    assert spl(True, 1.0, 1.25) == pytest.approx(0.8) and spl(True, 1.0, 0.9) == 1.0 and spl(False, 1.0, 1.0) == 0
    assert barn_score(True, 1.0, 10.0, 0.2) == 0.5  # OT = 5 s; AT = 2 OT
    assert barn_score(True, 1.0, 20.0, 0.2) == pytest.approx(0.25)
    assert barn_score(True, 1.0, 100.0, 0.2) == pytest.approx(0.125)  # clipped at 8 OT
    assert barn_score(False, 1.0, 10.0, 0.2) == 0.0
