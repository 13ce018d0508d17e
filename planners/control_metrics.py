"""Metrics that judge how a controller tracked its path (docs/metrics.md, "Controller metrics").

Pure numpy/scipy, vectorised, no I/O.  Inputs: the planned path P0 ``(M, 2+)``
(m), the performed poses ``(N, 3)`` x, y, theta (m, rad) with their times
``t`` ``(N,)`` (s).  Quantities that differentiate the motion (jerk, velocity
smoothness, stops) are taken on the poses interpolated to a uniform grid of
``rate_hz`` (default 10 Hz): finite differences of tracker poses at 30-50 Hz
would measure the tracker's jitter more than the robot (a 0.3 mm jitter at
30 Hz alone gives jerks of tens of m/s^3).

Keys (:data:`CONTROL_KEYS`): ``cross_track_error_mean_m``,
``cross_track_error_max_m``, ``heading_error_rms_rad``, ``time_to_goal_s``,
``jerk_linear_rms_m_s3``, ``jerk_angular_rms_rad_s3``,
``velocity_smoothness_m_s2``, ``stop_count``, ``collision_count``, ``spl``,
``barn_score``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .environment import Environment
from .geometry import distance_to_obstacles

__all__ = ["CONTROL_KEYS", "ControlSettings", "barn_score", "control_metrics", "cross_track", "rising_edges", "spl"]

CONTROL_KEYS = ("cross_track_error_mean_m", "cross_track_error_max_m", "heading_error_rms_rad", "time_to_goal_s",
                "jerk_linear_rms_m_s3", "jerk_angular_rms_rad_s3", "velocity_smoothness_m_s2", "stop_count",
                "collision_count", "spl", "barn_score")
_SPACING = 0.002  # m between the samples of P0 that the nearest-point search uses


@dataclass(frozen=True)
class ControlSettings:
    """How the controller metrics are taken (SI units): the distance from the robot's centre to an obstacle
    below which a collision is counted (the robot's collision radius), the goal tolerance, the robot's top
    speed (BARN's optimal time), the uniform grid's rate and the stop thresholds."""

    collision_radius: float = 0.0
    goal_tolerance: float = 0.05
    max_speed: float = 0.2
    rate_hz: float = 10.0
    stop_speed: float = 0.01
    stop_turn_rate: float = 0.05

    def to_dict(self) -> dict[str, float]:
        """JSON form, units in the keys."""
        return {"collision_radius_m": self.collision_radius, "goal_tolerance_m": self.goal_tolerance,
                "max_speed_m_s": self.max_speed, "rate_hz": self.rate_hz, "stop_speed_m_s": self.stop_speed,
                "stop_turn_rate_rad_s": self.stop_turn_rate}


def _dense(path: np.ndarray) -> np.ndarray:
    """P0 ``(M, 2)`` resampled every ``_SPACING`` m of arc length or closer (both ends kept)."""
    seg = np.hypot(*np.diff(path, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return path[:1].copy()
    u = np.linspace(0.0, s[-1], max(2, int(math.ceil(s[-1] / _SPACING)) + 1))
    return np.column_stack([np.interp(u, s, path[:, 0]), np.interp(u, s, path[:, 1])])


def cross_track(planned: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m) of each point ``xy`` ``(N, 2)`` to the polyline ``planned``, and the direction (rad) of the
    polyline there.  Exact on the two pieces of the densely resampled P0 next to the nearest sample."""
    d = _dense(np.asarray(planned, dtype=float)[:, :2])
    if len(d) < 2:
        return np.hypot(*(xy - d[0]).T), np.zeros(len(xy))
    _, k = cKDTree(d).query(xy)
    best = np.full(len(xy), np.inf)
    heading = np.zeros(len(xy))
    for j in (np.clip(k - 1, 0, len(d) - 2), np.clip(k, 0, len(d) - 2)):  # the pieces before and after
        a, ab = d[j], d[j + 1] - d[j]
        ll = np.maximum((ab ** 2).sum(1), 1e-18)
        t = np.clip(((xy - a) * ab).sum(1) / ll, 0.0, 1.0)
        dist = np.hypot(*(a + t[:, None] * ab - xy).T)
        closer = dist < best
        best[closer] = dist[closer]
        heading[closer] = np.arctan2(ab[closer, 1], ab[closer, 0])
    return best, heading


def _time_mean(values: np.ndarray, t: np.ndarray) -> float:
    """Time-weighted mean (trapezoids) of ``values`` sampled at ``t``; the plain mean without duration."""
    span = t[-1] - t[0]
    if len(t) < 2 or span <= 0:
        return float(values.mean())
    return float((0.5 * (values[1:] + values[:-1]) * np.diff(t)).sum() / span)


def rising_edges(flags: np.ndarray) -> int:
    """How often ``flags`` turns from False to True (a True first element counts)."""
    f = np.asarray(flags, dtype=bool)
    return int(f[:1].sum() + (f[1:] & ~f[:-1]).sum())


def spl(success: bool, shortest_m: float, taken_m: float) -> float:
    """Success weighted by path length (Anderson et al. 2018): ``S l / max(p, l)``."""
    if not success or shortest_m <= 0:
        return 0.0
    return float(shortest_m / max(taken_m, shortest_m))


def barn_score(success: bool, shortest_m: float, time_s: float | None, max_speed: float) -> float:
    """The BARN Challenge's score (Xiao et al. 2022): ``S OT / clip(AT, 2 OT, 8 OT)`` with the optimal time
    ``OT = l / max_speed`` and the actual time ``AT``; in ``{0} u [0.125, 0.5]``."""
    if not success or time_s is None or shortest_m <= 0:
        return 0.0
    ot = shortest_m / max_speed
    return float(ot / min(max(time_s, 2.0 * ot), 8.0 * ot))


def _grid(t: np.ndarray, poses: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Forward speed (m/s), turn rate (rad/s) and grid times on a uniform grid of ``rate_hz``; step (s)."""
    h = 1.0 / rate_hz
    tg = np.arange(t[0], t[-1] + 1e-9, h)
    if len(tg) < 4:
        return np.zeros(0), np.zeros(0), tg, h
    x, y = np.interp(tg, t, poses[:, 0]), np.interp(tg, t, poses[:, 1])
    th = np.interp(tg, t, np.unwrap(poses[:, 2]))
    v = np.gradient(x, h) * np.cos(th) + np.gradient(y, h) * np.sin(th)
    return v, np.gradient(th, h), tg, h


def _rms(a: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(a ** 2))) if len(a) else None


def control_metrics(planned: np.ndarray, poses: np.ndarray, t: np.ndarray, *, goal: np.ndarray,
                    env: Environment | None = None, performed_length_m: float | None = None,
                    execution_time_s: float | None = None,
                    settings: ControlSettings = ControlSettings()) -> dict[str, Any]:
    """The :data:`CONTROL_KEYS` of one run (docs/metrics.md): ``planned`` P0 ``(M, 2+)``, ``poses`` ``(N, 3)``
    at times ``t`` ``(N,)`` from the path's start to its end, the ``goal`` (x, y), the environment for the
    collision count (None without it), the performed length and execution time as the run's metrics have
    them (computed here when not given).  Counts are ints, the rest floats or None."""
    p0 = np.asarray(planned, dtype=float)[:, :2]
    pr = np.asarray(poses, dtype=float).reshape(-1, 3)
    t = np.asarray(t, dtype=float)
    xy = pr[:, :2]
    xte, tangent = cross_track(p0, xy)
    at_goal = np.hypot(*(xy - np.asarray(goal, dtype=float)[:2]).T) <= settings.goal_tolerance
    k_goal = int(np.argmax(at_goal)) if at_goal.any() else len(t)
    time_to_goal = float(t[k_goal] - t[0]) if at_goal.any() else None
    before = slice(0, max(k_goal, 2))  # the heading error while tracking, not the final turn to the goal angle
    err = np.abs((pr[before, 2] - tangent[before] + np.pi) % (2 * np.pi) - np.pi)
    v, w, tg, h = _grid(t, pr, settings.rate_hz)
    a_lin, a_ang = np.gradient(v, h) if len(v) else v, np.gradient(w, h) if len(w) else w
    moving = (np.abs(v) > settings.stop_speed) | (np.abs(w) > settings.stop_turn_rate)
    if moving.any():  # halts after the first motion and before the goal
        first = int(np.argmax(moving))
        end = len(tg) if time_to_goal is None else int(np.searchsorted(tg, t[0] + time_to_goal))
        stops = rising_edges(~moving[first:end])
    else:
        stops = 0
    collisions = None
    if env is not None:
        collisions = rising_edges(distance_to_obstacles(env, xy) < settings.collision_radius)
    length = float(np.hypot(*np.diff(xy, axis=0).T).sum()) if performed_length_m is None else performed_length_m
    duration = float(t[-1] - t[0]) if execution_time_s is None else execution_time_s
    shortest = float(np.hypot(*np.diff(p0, axis=0).T).sum())
    success = bool(at_goal[-1])  # a robot that touches anything stops there: FAIL, not at the goal
    return {
        "cross_track_error_mean_m": _time_mean(xte, t),
        "cross_track_error_max_m": float(xte.max()),
        "heading_error_rms_rad": float(math.sqrt(_time_mean(err ** 2, t[before]))),
        "time_to_goal_s": time_to_goal,
        "jerk_linear_rms_m_s3": _rms(np.gradient(a_lin, h)) if len(v) else None,
        "jerk_angular_rms_rad_s3": _rms(np.gradient(a_ang, h)) if len(w) else None,
        "velocity_smoothness_m_s2": float(np.abs(np.diff(v)).mean() / h) if len(v) else None,
        "stop_count": stops,
        "collision_count": collisions,
        "spl": spl(success, shortest, length),
        "barn_score": barn_score(success, shortest, duration, settings.max_speed),
    }
