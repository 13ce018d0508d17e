"""The motor-schema path follower: pure functions on arrays, vectorised over robots.

As on the Teleworkbench robots, a path is a list of waypoints.  Each control
step (all quantities SI: m, rad, s):

1. :func:`advance_waypoints` moves every robot's current waypoint on while
   the robot (its *believed* position) is within ``switch_radius_m`` of it;
   the last waypoint counts as reached within ``goal_tolerance_m``, and then
   the robot only aligns to the last point's angle.
2. :func:`move_to_waypoint` is the move-to-goal motor schema: a velocity
   vector towards the current waypoint, of magnitude ``max speed`` (on the
   approach to the last point ``arrive_gain x distance``, at least
   ``min_speed``).
3. :func:`heading_control` turns that vector into body velocities: a
   P-controller on the heading error for the turn rate; the forward speed is
   the vector's magnitude times ``cos(error)``, zero above
   ``turn_in_place_rad`` (turn on the spot first).
4. :func:`align_control` turns on the spot to the final angle.
5. :func:`rate_limit` applies the acceleration limits to the commands.

:func:`stall_update` and :func:`timeout_steps` detect stalls and timeouts.
:func:`control_step` chains 2-5 for a whole fleet.
"""

from __future__ import annotations

import numpy as np

from .kinematics import wrap_angle
from .params import ControllerParams

__all__ = [
    "advance_waypoints",
    "align_control",
    "control_step",
    "heading_control",
    "move_to_waypoint",
    "path_length",
    "rate_limit",
    "stall_update",
    "timeout_steps",
]


def _clip(x: np.ndarray, lo: float | np.ndarray, hi: float | np.ndarray) -> np.ndarray:
    """``np.clip`` without its wrapper overhead (this runs every control step)."""
    return np.minimum(np.maximum(x, lo), hi)


def move_to_waypoint(xy: np.ndarray, target: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Move-to-goal schema: ``(N, 2)`` velocity vectors (m/s) from ``xy`` towards ``target``.

    ``speed`` ``(N,)`` (m/s) is each vector's magnitude; a robot already at its
    target gets the zero vector.
    """
    d = target - xy
    dist = np.hypot(d[:, 0], d[:, 1])
    scale = np.divide(speed, dist, out=np.zeros_like(dist), where=dist > 1e-12)
    return d * scale[:, None]


def approach_speed(dist: np.ndarray, is_last: np.ndarray, max_speed: float, p: ControllerParams) -> np.ndarray:
    """Schema magnitude (m/s): ``max_speed``, or on the approach to the last point
    ``arrive_gain x dist`` clipped to ``[min_speed, max_speed]``."""
    slow = _clip(p.arrive_gain_1_s * dist, p.min_speed_m_s, max_speed)
    return np.where(is_last, slow, max_speed)


def heading_control(
    theta: np.ndarray, vec: np.ndarray, p: ControllerParams, max_turn: float
) -> tuple[np.ndarray, np.ndarray]:
    """Body velocity commands ``(v m/s, w rad/s)`` that follow velocity vectors ``vec`` ``(N, 2)``.

    ``w = clip(heading_gain x error, +-max_turn)``; ``v = |vec| cos(error)``,
    0 when the error exceeds ``turn_in_place_rad`` or 90 degrees.
    """
    mag = np.hypot(vec[:, 0], vec[:, 1])
    err = wrap_angle(np.arctan2(vec[:, 1], vec[:, 0]) - theta)
    err = np.where(mag > 0, err, 0.0)
    w = _clip(p.heading_gain_1_s * err, -max_turn, max_turn)
    v = mag * np.maximum(np.cos(err), 0.0)
    v = np.where(np.abs(err) > p.turn_in_place_rad, 0.0, v)
    return v, w


def align_control(
    theta: np.ndarray, goal_angle: np.ndarray, p: ControllerParams, max_turn: float
) -> tuple[np.ndarray, np.ndarray]:
    """Turn rate (rad/s) that aligns ``theta`` to ``goal_angle``, and the mask of aligned robots.

    The rate is the P-control ``heading_gain x error``, at least
    ``min_turn_rate`` (so the tracks overcome their dead band) and at most
    ``max_turn``; aligned robots (error below ``angle_tolerance_rad``) get 0.
    """
    err = wrap_angle(goal_angle - theta)
    aligned = np.abs(err) < p.angle_tolerance_rad
    rate = _clip(np.abs(p.heading_gain_1_s * err), p.min_turn_rate_rad_s, max_turn)
    return np.where(aligned, 0.0, np.copysign(rate, err)), aligned


def rate_limit(prev: np.ndarray, desired: np.ndarray, max_step: float) -> np.ndarray:
    """``desired`` changed from ``prev`` by at most ``max_step`` (acceleration x dt) per element."""
    return prev + _clip(desired - prev, -max_step, max_step)


def advance_waypoints(
    xy: np.ndarray,
    points: np.ndarray,
    offset: np.ndarray,
    count: np.ndarray,
    wp: np.ndarray,
    active: np.ndarray,
    p: ControllerParams,
    max_iter: int = 64,
) -> tuple[np.ndarray, np.ndarray]:
    """Advance current waypoints; returns the new ``wp`` ``(N,)`` and the mask of robots that
    reached their last point (within ``goal_tolerance_m``).

    ``points`` ``(M, 3)`` holds every robot's path back to back: robot ``i``'s
    path is ``points[offset[i]:offset[i] + count[i]]`` and its current
    waypoint index is ``wp[i]``.  Only ``active`` robots move on.  A robot
    may pass several close waypoints in one step (at most ``max_iter``);
    every index in ``[old wp, new wp)`` was reached, and so was the last one
    when the returned mask is set.
    """
    arrived = np.zeros(len(wp), dtype=bool)
    radius = np.where(wp == count - 1, p.goal_tolerance_m, p.switch_radius_m)
    tgt = points[offset + wp]
    near = active & (count > 0) & (np.hypot(tgt[:, 0] - xy[:, 0], tgt[:, 1] - xy[:, 1]) < radius)
    if not near.any():  # the common case: nobody reached a waypoint this step
        return wp, arrived
    wp = wp.copy()
    idx = np.flatnonzero(near)
    for _ in range(max_iter):
        last = wp[idx] == count[idx] - 1
        arrived[idx[last]] = True
        idx = idx[~last]
        wp[idx] += 1
        if not len(idx):
            break
        tgt = points[offset[idx] + wp[idx], :2]
        dist = np.hypot(tgt[:, 0] - xy[idx, 0], tgt[:, 1] - xy[idx, 1])
        last = wp[idx] == count[idx] - 1
        idx = idx[dist < np.where(last, p.goal_tolerance_m, p.switch_radius_m)]
    return wp, arrived


def control_step(
    belief: np.ndarray,
    target: np.ndarray,
    is_last: np.ndarray,
    aligning: np.ndarray,
    prev_cmd: np.ndarray,
    p: ControllerParams,
    max_speed: float,
    max_turn: float,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """One control step for a fleet: body velocity commands ``(N, 2)`` and the aligned mask.

    ``belief`` ``(N, 3)`` is each robot's believed pose, ``target`` ``(N, 3)``
    its current waypoint (x, y, final angle), ``is_last`` whether that is the
    path's last point, ``aligning`` whether the robot reached it and only
    turns to its angle; ``prev_cmd`` ``(N, 2)`` the last commands, for the
    acceleration limits.
    """
    d = target[:, :2] - belief[:, :2]
    dist = np.hypot(d[:, 0], d[:, 1])
    vec = move_to_waypoint(belief[:, :2], target[:, :2], approach_speed(dist, is_last, max_speed, p))
    v, w = heading_control(belief[:, 2], vec, p, max_turn)
    w_align, aligned = align_control(belief[:, 2], target[:, 2], p, max_turn)
    v = np.where(aligning, 0.0, v)
    w = np.where(aligning, w_align, w)
    cmd = np.empty_like(prev_cmd)
    cmd[:, 0] = rate_limit(prev_cmd[:, 0], v, p.accel_limit_m_s2 * dt)
    cmd[:, 1] = rate_limit(prev_cmd[:, 1], w, p.angular_accel_limit_rad_s2 * dt)
    return cmd, aligning & aligned


def stall_update(
    belief: np.ndarray,
    anchor: np.ndarray,
    anchor_step: np.ndarray,
    step: np.ndarray,
    active: np.ndarray,
    p: ControllerParams,
    dt: float,
) -> np.ndarray:
    """Stall detection; updates ``anchor`` (poses) and ``anchor_step`` in place, returns the stalled mask.

    A robot makes progress when its believed pose is more than
    ``stall_distance_m`` or ``stall_angle_rad`` away from its anchor; then
    the anchor moves to the current pose.  ``active`` robots without
    progress for ``stall_time_s`` are stalled.
    """
    moved = np.hypot(belief[:, 0] - anchor[:, 0], belief[:, 1] - anchor[:, 1]) > p.stall_distance_m
    turned = np.abs(wrap_angle(belief[:, 2] - anchor[:, 2])) > p.stall_angle_rad
    progress = moved | turned
    anchor[progress] = belief[progress]
    anchor_step[progress] = step[progress]
    return active & ((step - anchor_step) * dt > p.stall_time_s)


def path_length(xy: np.ndarray) -> float:
    """Length (m) of a polyline ``(N, 2+)``."""
    if len(xy) < 2:
        return 0.0
    d = np.diff(np.asarray(xy)[:, :2], axis=0)
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def timeout_steps(path: np.ndarray, start_xy: np.ndarray, p: ControllerParams, max_speed: float, dt: float) -> int:
    """Control steps a path may take: ``timeout_base + factor x (length / max_speed)`` seconds.

    The length includes the way from ``start_xy`` to the first point.
    """
    length = path_length(np.vstack([np.asarray(start_xy, dtype=float)[None, :2], path[:, :2]]))
    return int(np.ceil((p.timeout_base_s + p.timeout_factor * length / max_speed) / dt))
