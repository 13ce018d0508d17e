"""The path-tracking controllers besides the motor schema (compiled scalar functions).

:func:`robot_agent.engine.follower.control` runs one of these for a robot whose
controller id (:mod:`contract.controller_specs`) is not the schema's.  Each
returns the desired body velocities ``(v m/s, w rad/s)`` of one control
step; the follower then applies the same arrival, final alignment, stall,
timeout and acceleration limits as for the schema.  All three share the
path geometry below: the robot's *projection* on the path (the nearest
point, searched forward from the last one over a short window so that a
path passing close to itself is never skipped) and points a given arc
length further on (the follower updates the projection before it steers).  ``params`` is the robot's row of the controller
parameter table, in the order of its :class:`~contract.controller_specs.ControllerSpec`; ``mem`` its
row of controller memory (projection segment and fraction, Kanayama's
reference segment and fraction).  Equations and sources: docs/controllers.md.
Units: m, rad, s.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import kernel
from .kinematics import wrap_angle

__all__ = ["DIRECT", "KANAYAMA", "MEMORY", "PARAM_SLOTS", "PLUGIN", "PURE_PURSUIT", "RPP", "SCHEMA", "along", "kanayama",
           "project", "pure_pursuit", "regulated_pure_pursuit", "rotate_to", "steer"]

SCHEMA, PURE_PURSUIT, RPP, KANAYAMA = 0, 1, 2, 3  #: ids of the built-in controllers
DIRECT = 4  #: a client's body velocities (``T,T,V``, held in ``want``): no path, a watchdog instead of arrival
PLUGIN = 100  #: the id of a plug-in controller: its commands come from Python (``want``)
PARAM_SLOTS = 8  #: columns of the parameter table
MEMORY = 4  #: columns of the controller memory: projection segment, fraction; reference segment, fraction
_SEARCH_M = 0.3  # how far along the path (m) beyond the last projection the nearest point is searched


@kernel
def _seg_len(path: np.ndarray, j: int) -> float:
    return math.hypot(path[j + 1, 0] - path[j, 0], path[j + 1, 1] - path[j, 1])


@kernel
def project(x: float, y: float, path: np.ndarray, seg: int, frac: float) -> tuple[int, float]:
    """The nearest point of ``path`` ``(P, 2+)`` to ``(x, y)`` at or after segment ``seg`` at fraction
    ``frac``, searched over the next ``_SEARCH_M`` of arc length: ``(segment, fraction in [0, 1])``."""
    if len(path) < 2:
        return 0, 0.0
    best_d, best_j, best_t = math.inf, seg, frac
    walked = 0.0
    j = seg
    while j < len(path) - 1:
        ax, ay = path[j, 0], path[j, 1]
        dx, dy = path[j + 1, 0] - ax, path[j + 1, 1] - ay
        ll = dx * dx + dy * dy
        t = ((x - ax) * dx + (y - ay) * dy) / ll if ll > 0.0 else 0.0
        t = min(max(t, frac if j == seg else 0.0), 1.0)
        ex, ey = ax + t * dx - x, ay + t * dy - y
        d = ex * ex + ey * ey  # squared: only compared
        if d < best_d:
            best_d, best_j, best_t = d, j, t
        walked += math.sqrt(ll) * ((1.0 - frac) if j == seg else 1.0)
        if walked > _SEARCH_M:
            break
        j += 1
    return best_j, best_t


@kernel
def along(path: np.ndarray, seg: int, frac: float, dist: float) -> tuple[int, float, float, float, bool]:
    """The point ``dist`` (m) of arc length after segment ``seg`` at ``frac``: ``(segment, fraction, x, y,
    at the end)``; the last point when the path ends sooner."""
    last = len(path) - 1
    if last < 1:
        return 0, 0.0, path[0, 0], path[0, 1], True
    left = dist
    j, t = seg, frac
    while j < last:
        ll = _seg_len(path, j)
        rest = ll * (1.0 - t)
        if rest >= left and ll > 0.0:
            t += left / ll
            return j, t, path[j, 0] + t * (path[j + 1, 0] - path[j, 0]), path[j, 1] + t * (path[j + 1, 1] - path[j, 1]), False
        left -= rest
        j += 1
        t = 0.0
    return last - 1, 1.0, path[last, 0], path[last, 1], True


@kernel
def _heading(path: np.ndarray, seg: int) -> float:
    """Direction (rad) of segment ``seg`` (the last point's angle on a one-point path)."""
    if len(path) < 2:
        return path[0, 2]
    return math.atan2(path[seg + 1, 1] - path[seg, 1], path[seg + 1, 0] - path[seg, 0])


@kernel
def rotate_to(err: float, gain: float, min_rate: float, max_rate: float) -> tuple[float, float]:
    """Turn on the spot towards a heading error ``err`` (rad): ``(0, w)`` with ``|w|`` = ``gain x |err|``
    clipped to ``[min_rate, max_rate]`` (rad/s)."""
    return 0.0, math.copysign(min(max(abs(gain * err), min_rate), max_rate), err)


@kernel
def _pursue(x: float, y: float, th: float, gx: float, gy: float, speed: float, max_turn: float) -> tuple[float, float]:
    """Pure pursuit's arc through the goal point ``(gx, gy)``: ``w = v kappa``, ``kappa = 2 y_r / L^2``
    (``y_r`` the point's lateral offset in the robot frame, ``L`` its distance); at the turn-rate limit
    the speed drops so that the arc keeps its curvature."""
    dx, dy = gx - x, gy - y
    ly = -math.sin(th) * dx + math.cos(th) * dy
    l2 = dx * dx + dy * dy
    kappa = 2.0 * ly / l2 if l2 > 1e-12 else 0.0
    v = speed
    if abs(v * kappa) > max_turn:
        v = max_turn / abs(kappa)
    return v, v * kappa


@kernel
def pure_pursuit(x: float, y: float, th: float, path: np.ndarray, mem: np.ndarray, params: np.ndarray,
                 max_speed: float, max_turn: float, arrive_gain: float, min_speed: float, heading_gain: float,
                 min_turn: float) -> tuple[float, float]:
    """Pure pursuit (Coulter 1992): steer along the arc through the path point ``lookahead_m`` ahead of the
    robot's projection; params ``lookahead_m, speed_m_s, rotate_to_heading_rad``."""
    lookahead, speed, rotate = params[0], min(params[1], max_speed), params[2]
    seg, frac = int(mem[0]), mem[1]
    _, _, gx, gy, end = along(path, seg, frac, lookahead)
    err = wrap_angle(math.atan2(gy - y, gx - x) - th)
    if abs(err) > rotate:
        return rotate_to(err, heading_gain, min_turn, max_turn)
    if end:
        speed = min(speed, max(arrive_gain * math.hypot(gx - x, gy - y), min_speed))
    return _pursue(x, y, th, gx, gy, speed, max_turn)


@kernel
def regulated_pure_pursuit(x: float, y: float, th: float, v_now: float, clearance: float, path: np.ndarray,
                           mem: np.ndarray, params: np.ndarray, max_speed: float, max_turn: float,
                           heading_gain: float, min_turn: float) -> tuple[float, float]:
    """Regulated pure pursuit (Macenski et al. 2023, nav2): pure pursuit with a lookahead that grows with
    the speed, and a speed regulated down in curves, near obstacles (``clearance`` m from the robot's
    edge) and on the approach to the goal.  Params ``speed_m_s, lookahead_time_s, min_lookahead_m,
    max_lookahead_m, min_radius_m, proximity_m, approach_m, min_speed_m_s``; rotation to the path's
    heading beyond 0.785 rad as nav2's default."""
    speed = min(params[0], max_speed)
    lookahead = min(max(abs(v_now) * params[1], params[2]), params[3])
    seg, frac = int(mem[0]), mem[1]
    _, _, gx, gy, end = along(path, seg, frac, lookahead)
    err = wrap_angle(math.atan2(gy - y, gx - x) - th)
    if abs(err) > 0.785:
        return rotate_to(err, heading_gain, min_turn, max_turn)
    dx, dy = gx - x, gy - y
    l2 = dx * dx + dy * dy
    kappa = 2.0 * (-math.sin(th) * dx + math.cos(th) * dy) / l2 if l2 > 1e-12 else 0.0
    v = speed
    if abs(kappa) > 1e-9 and 1.0 / abs(kappa) < params[4]:  # curvature: v x r / r_min
        v *= (1.0 / abs(kappa)) / params[4]
    if params[5] > 0.0 and clearance < params[5]:  # proximity: v x d / d_prox
        v *= max(clearance, 0.0) / params[5]
    v = max(v, params[7])  # regulated speeds keep a floor
    if end:  # approach: v x d_goal / d_approach, at least the floor
        d_goal = math.sqrt(l2)
        if d_goal < params[6]:
            v = max(v * d_goal / params[6], params[7])
    v = min(v, speed)
    return _pursue(x, y, th, gx, gy, v, max_turn)


@kernel
def kanayama(x: float, y: float, th: float, dt: float, path: np.ndarray, mem: np.ndarray, params: np.ndarray,
             max_speed: float, max_turn: float, arrive_gain: float, min_speed: float, heading_gain: float,
             min_turn: float) -> tuple[float, float]:
    """Kanayama et al. (1990): a reference pose moves along the path at ``speed_m_s`` (waiting while it is
    ``max_lead_m`` ahead of the robot's projection); with the reference's error ``(e_x, e_y, e_th)`` in the
    robot frame, ``v = v_r cos e_th + K_x e_x`` and ``w = w_r + v_r (K_y e_y + K_th sin e_th)``.  Params
    ``speed_m_s, k_x_1_s, k_y_1_m2, k_theta_1_m, max_lead_m, rotate_to_heading_rad`` (beyond that heading
    error it turns on the spot first).  Once the reference has reached the end the
    robot drives to the last point (a pursuit of it), where the follower's arrival takes over."""
    v_r, kx, ky, kth, lead = min(params[0], max_speed), params[1], params[2], params[3], params[4]
    last = len(path) - 1
    seg, frac = int(mem[0]), mem[1]
    # the reference slows on the approach as the other followers do (arrival: gain x distance to the last point,
    # once the path ends within v_r / gain of the projection), or lagging motors carry the robot past the goal
    if arrive_gain > 0.0 and along(path, seg, frac, v_r / arrive_gain)[4]:
        v_r = min(v_r, max(arrive_gain * math.hypot(path[last, 0] - x, path[last, 1] - y), min_speed))
    rseg, rfrac = int(mem[2]), mem[3]
    if rseg < seg or (rseg == seg and rfrac < frac):
        rseg, rfrac = seg, frac
    # the reference moves on by v_r dt, but never more than `lead` beyond the projection
    lseg, lfrac, _, _, _ = along(path, seg, frac, lead)
    nseg, nfrac, rx, ry, end = along(path, rseg, rfrac, v_r * dt)
    if nseg > lseg or (nseg == lseg and nfrac > lfrac):
        nseg, nfrac, rx, ry, end = along(path, seg, frac, lead)
    mem[2], mem[3] = nseg, nfrac
    if end and math.hypot(path[last, 0] - rx, path[last, 1] - ry) < 1e-9:
        gx, gy = path[last, 0], path[last, 1]
        err = wrap_angle(math.atan2(gy - y, gx - x) - th)
        if abs(err) > 1.2:
            return rotate_to(err, heading_gain, min_turn, max_turn)
        speed = min(v_r, max(arrive_gain * math.hypot(gx - x, gy - y), min_speed))
        return _pursue(x, y, th, gx, gy, speed, max_turn)
    th_r = _heading(path, nseg)
    h = 0.02  # the reference's turn rate: heading change over +-2 cm of arc length, times v_r
    s0, _, _, _, _ = along(path, nseg, nfrac, h)
    th_ahead = _heading(path, s0)
    w_r = v_r * wrap_angle(th_ahead - th_r) / h
    c, s = math.cos(th), math.sin(th)
    ex = c * (rx - x) + s * (ry - y)
    ey = -s * (rx - x) + c * (ry - y)
    eth = wrap_angle(th_r - th)
    if abs(eth) > params[5]:
        return rotate_to(eth, heading_gain, min_turn, max_turn)
    v = min(max(v_r * math.cos(eth) + kx * ex, 0.0), max_speed)
    w = min(max(w_r + v_r * (ky * ey + kth * math.sin(eth)), -max_turn), max_turn)
    return v, w


@kernel
def steer(cid: int, x: float, y: float, th: float, v_now: float, clearance: float, path: np.ndarray,
          mem: np.ndarray, params: np.ndarray, want: np.ndarray, max_speed: float, max_turn: float,
          arrive_gain: float, min_speed: float, heading_gain: float, min_turn: float,
          dt: float) -> tuple[float, float]:
    """The desired ``(v, w)`` of controller ``cid`` (not the schema) for a robot at ``(x, y, th)``;
    a plug-in's are ``want`` (computed in Python before the step)."""
    if cid == PURE_PURSUIT:
        return pure_pursuit(x, y, th, path, mem, params, max_speed, max_turn, arrive_gain, min_speed, heading_gain,
                            min_turn)
    if cid == RPP:
        return regulated_pure_pursuit(x, y, th, v_now, clearance, path, mem, params, max_speed, max_turn,
                                      heading_gain, min_turn)
    if cid == KANAYAMA:
        return kanayama(x, y, th, dt, path, mem, params, max_speed, max_turn, arrive_gain, min_speed,
                        heading_gain, min_turn)
    return want[0], want[1]
