"""The motor-schema path follower of one robot (compiled scalar functions).

As on the Teleworkbench robots, a path is a list of waypoints.  Each control
step (all quantities SI: m, rad, s):

1. :func:`advance_waypoint` moves the robot's current waypoint on while the
   robot (its *believed* position) is within ``switch_radius_m`` of it; the
   last waypoint counts as reached within ``goal_tolerance_m``, and then the
   robot only aligns to the last point's angle.
2. :func:`move_to_waypoint` is the move-to-goal motor schema: a velocity
   vector towards the current waypoint, of magnitude ``max speed`` (on the
   approach to the last point ``arrive_gain x distance``, at least
   ``min_speed``; :func:`approach_speed`).
3. :func:`heading_control` turns that vector into body velocities: a
   P-controller on the heading error for the turn rate; the forward speed is
   the vector's magnitude times ``cos(error)``, zero above
   ``turn_in_place_rad`` (turn on the spot first).
4. :func:`align_control` turns on the spot to the final angle.
5. :func:`rate_limit` applies the acceleration limits to the commands.

:func:`control` chains 1-5 with stall and timeout detection for one robot
of a fleet; the simulation's kernels (:mod:`robot_agent.engine.stepper`) call it
for every moving robot.  The functions are compiled with numba (the issue's
single-robot target of 5000x real time leaves 4 microseconds per step) and
can be called from Python with floats.  :class:`Gains` carries the
controller's parameters into compiled code.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from contract.params import RobotParams

from .compiled import kernel
from .controllers import DIRECT, SCHEMA, project, steer
from .kinematics import wrap_angle

__all__ = [
    "ARRIVED", "DONE", "STALLED", "STARTED", "TIMED_OUT",
    "Gains", "advance_waypoint", "align_control", "approach_speed", "control", "gains",
    "heading_control", "move_to_waypoint", "path_length", "rate_limit", "timeout_steps",
]

# Bits of the flags :func:`control` returns (the stepper adds COLLIDED).
STARTED, ARRIVED, DONE, STALLED, TIMED_OUT = 1, 2, 4, 8, 16
MAX_SKIP = 64  # waypoints a robot may pass in one step


class Gains(NamedTuple):
    """The follower's parameters in compiled code (SI units; see the profile notes)."""

    heading_gain: float
    switch_radius: float
    goal_tolerance: float
    angle_tolerance: float
    arrive_gain: float
    min_speed: float
    min_turn_rate: float
    turn_in_place: float
    max_speed: float
    max_turn: float
    dv_max: float  #: forward speed change per step (m/s), acceleration limit x dt
    dw_max: float  #: turn rate change per step (rad/s)
    stall_time: float
    stall_distance: float
    stall_angle: float
    dt: float


def gains(p: RobotParams) -> Gains:
    """The :class:`Gains` of robot parameters ``p``."""
    c = p.controller
    return Gains(c.heading_gain_1_s, c.switch_radius_m, c.goal_tolerance_m, c.angle_tolerance_rad,
                 c.arrive_gain_1_s, c.min_speed_m_s, c.min_turn_rate_rad_s, c.turn_in_place_rad,
                 p.max_speed_m_s, p.max_angular_speed_rad_s, c.accel_limit_m_s2 * p.dt,
                 c.angular_accel_limit_rad_s2 * p.dt, c.stall_time_s, c.stall_distance_m,
                 c.stall_angle_rad, p.dt)


@kernel
def _clip(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


@kernel
def move_to_waypoint(x: float, y: float, tx: float, ty: float, speed: float) -> tuple[float, float]:
    """Move-to-goal schema: the velocity vector (m/s) of magnitude ``speed`` from ``(x, y)``
    towards ``(tx, ty)``; the zero vector at the target."""
    dx, dy = tx - x, ty - y
    dist = math.hypot(dx, dy)
    scale = speed / dist if dist > 1e-12 else 0.0
    return dx * scale, dy * scale


@kernel
def approach_speed(dist: float, is_last: bool, g: Gains) -> float:
    """Schema magnitude (m/s): ``max_speed``, or on the approach to the last point
    ``arrive_gain x dist`` clipped to ``[min_speed, max_speed]``."""
    if is_last:
        return _clip(g.arrive_gain * dist, g.min_speed, g.max_speed)
    return g.max_speed


@kernel
def heading_control(theta: float, vx: float, vy: float, g: Gains) -> tuple[float, float]:
    """Body velocity commands ``(v m/s, w rad/s)`` that follow the velocity vector ``(vx, vy)``.

    ``w = clip(heading_gain x error, +-max_turn)``; ``v = |vec| cos(error)``,
    0 when the error exceeds ``turn_in_place`` or 90 degrees.
    """
    mag = math.hypot(vx, vy)
    err = wrap_angle(math.atan2(vy, vx) - theta) if mag > 0 else 0.0
    w = _clip(g.heading_gain * err, -g.max_turn, g.max_turn)
    v = 0.0 if abs(err) > g.turn_in_place else mag * max(math.cos(err), 0.0)
    return v, w


@kernel
def align_control(theta: float, goal_angle: float, g: Gains) -> tuple[float, bool]:
    """Turn rate (rad/s) that aligns ``theta`` to ``goal_angle``, and whether it is aligned.

    The rate is the P-control ``heading_gain x error``, at least
    ``min_turn_rate`` (so the tracks overcome their dead band) and at most
    ``max_turn``; an aligned robot (error below ``angle_tolerance``) gets 0.
    """
    err = wrap_angle(goal_angle - theta)
    if abs(err) < g.angle_tolerance:
        return 0.0, True
    return math.copysign(_clip(abs(g.heading_gain * err), g.min_turn_rate, g.max_turn), err), False


@kernel
def rate_limit(prev: float, desired: float, max_step: float) -> float:
    """``desired`` changed from ``prev`` by at most ``max_step`` (acceleration x dt)."""
    return prev + _clip(desired - prev, -max_step, max_step)


@kernel
def advance_waypoint(x: float, y: float, path: np.ndarray, wp: int, g: Gains) -> tuple[int, bool]:
    """The current waypoint index after this step, and whether the last point was reached.

    ``path`` ``(P, 2+)`` is the robot's path, ``wp`` its current waypoint.
    The robot passes every waypoint within ``switch_radius`` (several close
    ones in one step, at most ``MAX_SKIP``); the last one is reached within
    ``goal_tolerance``.
    """
    last = len(path) - 1
    for _ in range(MAX_SKIP):
        radius = g.goal_tolerance if wp == last else g.switch_radius
        if math.hypot(path[wp, 0] - x, path[wp, 1] - y) >= radius:
            return wp, False
        if wp == last:
            return wp, True
        wp += 1
    return wp, False


@kernel
def control(i: int, bx: float, by: float, bth: float, points: np.ndarray, offset: np.ndarray,
            count: np.ndarray, wp: np.ndarray, aligning: np.ndarray, cmd: np.ndarray, anchor: np.ndarray,
            anchor_k: np.ndarray, k: np.ndarray, timeout: np.ndarray, g: Gains, cid: np.ndarray,
            cpar: np.ndarray, cmem: np.ndarray, want: np.ndarray, clearance: float) -> int:
    """One control step of moving robot ``i`` believed at ``(bx, by, bth)``; returns its flags.

    Updates in place the fleet arrays at ``i``: waypoint ``wp``, ``aligning``,
    commands ``cmd`` ``(N, 2)`` (zero once the path ended) and the stall
    anchor (``anchor`` ``(N, 3)``, ``anchor_k``).  ``points``, ``offset`` and
    ``count`` hold every robot's path back to back; ``k`` counts control
    steps since the path began, ``timeout`` is its limit.  ``cid[i]`` is the
    robot's controller (:mod:`robot_agent.engine.controllers`; the schema's steps
    are 1-5 above), ``cpar[i]`` its parameters, ``cmem[i]`` its memory,
    ``want[i]`` a plug-in's commands and ``clearance`` (m) the believed
    distance from the robot's edge to the nearest obstacle (regulated pure
    pursuit's proximity term; ``inf`` when no controller needs it).  Other
    controllers pass waypoints when the robot's projection on the path has
    passed them, too.  A ``DIRECT`` robot (``T,T,V``) drives by ``want`` and
    never arrives or stalls; its ``timeout`` is the watchdog.
    """
    flags = 0
    if k[i] == 0:
        flags |= STARTED
        anchor[i, 0], anchor[i, 1], anchor[i, 2] = bx, by, bth
        anchor_k[i] = 0
    path = points[offset[i]:offset[i] + count[i]]
    if not aligning[i] and count[i] > 0 and cid[i] != DIRECT:
        if cid[i] != SCHEMA:
            seg, frac = project(bx, by, path, int(cmem[i, 0]), cmem[i, 1])
            cmem[i, 0], cmem[i, 1] = seg, frac
            wp[i] = max(wp[i], min(seg + (1 if frac > 0.0 else 0), count[i] - 1))
        wp[i], arrived = advance_waypoint(bx, by, path, wp[i], g)
        if arrived:
            flags |= ARRIVED
            aligning[i] = True
    row = offset[i] + wp[i]
    tx, ty, tth = points[row, 0], points[row, 1], points[row, 2]
    if aligning[i]:
        v = 0.0
        w, aligned = align_control(bth, tth, g)
    elif cid[i] == SCHEMA:
        speed = approach_speed(math.hypot(tx - bx, ty - by), wp[i] == count[i] - 1, g)
        vx, vy = move_to_waypoint(bx, by, tx, ty, speed)
        v, w = heading_control(bth, vx, vy, g)
        aligned = False
    elif cid[i] == DIRECT:
        v, w = want[i, 0], want[i, 1]
        aligned = False
    else:
        v, w = steer(cid[i], bx, by, bth, cmd[i, 0], clearance, path, cmem[i], cpar[i], want[i], g.max_speed,
                     g.max_turn, g.arrive_gain, g.min_speed, g.heading_gain, g.min_turn_rate, g.dt)
        aligned = False
    if aligned:
        flags |= DONE
    if (math.hypot(bx - anchor[i, 0], by - anchor[i, 1]) > g.stall_distance
            or abs(wrap_angle(bth - anchor[i, 2])) > g.stall_angle):
        anchor[i, 0], anchor[i, 1], anchor[i, 2] = bx, by, bth
        anchor_k[i] = k[i]
    if not aligned:
        if (k[i] - anchor_k[i]) * g.dt > g.stall_time and cid[i] != DIRECT:
            flags |= STALLED
        elif k[i] >= timeout[i]:
            flags |= TIMED_OUT
    if flags & (DONE | STALLED | TIMED_OUT):
        cmd[i, 0] = cmd[i, 1] = 0.0
    else:
        cmd[i, 0] = rate_limit(cmd[i, 0], v, g.dv_max)
        cmd[i, 1] = rate_limit(cmd[i, 1], w, g.dw_max)
    return flags


def path_length(xy: np.ndarray) -> float:
    """Length (m) of a polyline ``(N, 2+)``."""
    if len(xy) < 2:
        return 0.0
    d = np.diff(np.asarray(xy)[:, :2], axis=0)
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def timeout_steps(path: np.ndarray, start_xy: np.ndarray, p: RobotParams) -> int:
    """Control steps a path may take: ``timeout_base + factor x (length / max_speed)`` seconds.

    The length includes the way from ``start_xy`` to the first point.
    """
    c = p.controller
    length = path_length(np.vstack([np.asarray(start_xy, dtype=float)[None, :2], path[:, :2]]))
    return int(np.ceil((c.timeout_base_s + c.timeout_factor * length / p.max_speed_m_s) / p.dt))
