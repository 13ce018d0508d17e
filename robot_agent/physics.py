"""The emulated robots' physics, one robot at a time (compiled scalar functions).

What the two emulated backends (:mod:`robot_agent.backends`) do to robot
``i`` of a fleet in one control step, written once and called both by the
backends' array methods and by the fused simulation loop
(:mod:`robot_agent.stepper`):

- ideal (Player/Stage-like): the commands move the robot exactly
  (:func:`ideal_actuate`); it knows its pose.
- field (the emulated physical robot): :func:`field_sense` is the overhead
  tracker (a frame at ``camera_rate_hz`` timed from the path start, Gaussian
  noise, dropped frames, ``tracker_latency_s`` delay) and the belief it
  gives; :func:`field_actuate` the tracks (per-run gain, speed noise, dead
  band, first-order lag, acceleration limit); :func:`field_begin` the
  per-run draws.

All noise comes from :mod:`robot_agent.noise`, keyed per run, so runs replay
exactly.  Units: m, rad, s.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .compiled import kernel
from .kinematics import body_to_tracks, tracks_to_body, unicycle_step, wrap_angle
from .noise import box_muller, uniform
from .params import RobotParams

__all__ = ["FieldGains", "RUN_COUNTER", "field_actuate", "field_begin", "field_gains", "field_sense",
           "ideal_actuate"]

#: noise counter reserved for per-run draws (a path never runs 2**40 steps)
RUN_COUNTER = 1 << 40
_SENSE_CHANNELS = 8  # normals 0-2 tracker noise, 3-4 track noise, (5 unused), uniform 6 dropout


class FieldGains(NamedTuple):
    """The field emulation's parameters in compiled code (SI units; see the profile notes)."""

    control_rate: int
    camera_rate: int
    delay: int  #: tracker latency in control steps
    dropout: float
    sigma_xy: float
    sigma_theta: float
    wheel_base: float
    wheel_noise_rel: float
    wheel_noise_abs: float
    gain_mean: float
    bias_sigma: float
    dead_band: float
    accel_step: float  #: largest track speed change per step (m/s)
    alpha: float  #: first-order lag factor per step
    dt: float


def field_gains(p: RobotParams) -> FieldGains:
    """The :class:`FieldGains` of robot parameters ``p``."""
    f = p.field
    alpha = 1.0 - math.exp(-p.dt / f.motor_time_constant_s) if f.motor_time_constant_s > 0 else 1.0
    return FieldGains(int(p.controller.control_rate_hz), int(f.camera_rate_hz), int(round(f.tracker_latency_s / p.dt)),
                      f.tracker_dropout_prob, f.tracker_noise_xy_m, f.tracker_noise_theta_rad, p.wheel_base_m,
                      f.wheel_noise_rel, f.wheel_noise_abs_m_s, f.wheel_gain_mean, f.wheel_bias_sigma,
                      f.dead_band_m_s, p.max_accel_m_s2 * p.dt, alpha, p.dt)


@kernel
def _six_normals(key: np.uint64, counter: int, u: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """Fill ``u`` with the uniforms of ``counter`` (``len(u)`` channels, at least 6) and return six
    standard normals, Box-Muller on the pairs ``(u[j], u[j + 3])``."""
    for ch in range(len(u)):
        u[ch] = uniform(key, counter, len(u), ch)
    z0, z3 = box_muller(u[0], u[3])
    z1, z4 = box_muller(u[1], u[4])
    z2, z5 = box_muller(u[2], u[5])
    return z0, z1, z2, z3, z4, z5


@kernel
def ideal_actuate(i: int, v: float, w: float, pose: np.ndarray, dt: float) -> None:
    """Move robot ``i`` (``pose`` ``(N, 3)``, in place) exactly by commands ``(v, w)`` for ``dt``."""
    pose[i, 0], pose[i, 1], pose[i, 2] = unicycle_step(pose[i, 0], pose[i, 1], pose[i, 2], v, w, dt)


@kernel
def field_begin(i: int, key: np.uint64, from_rest: bool, pose: np.ndarray, belief: np.ndarray,
                gain: np.ndarray, ring_ok: np.ndarray, fg: FieldGains) -> None:
    """A path with noise ``key`` starts for robot ``i``: draw its track gains; a robot that was at
    rest gets a fresh tracker measurement as its belief (the tracker was watching it)."""
    z0, z1, z2, z3, z4, _ = _six_normals(key, RUN_COUNTER, np.empty(6))
    gain[i, 0] = fg.gain_mean + fg.bias_sigma * z0
    gain[i, 1] = fg.gain_mean + fg.bias_sigma * z1
    if from_rest:
        belief[i, 0] = pose[i, 0] + z2 * fg.sigma_xy
        belief[i, 1] = pose[i, 1] + z3 * fg.sigma_xy
        belief[i, 2] = wrap_angle(pose[i, 2] + z4 * fg.sigma_theta)
        ring_ok[i, :] = False


@kernel
def field_sense(i: int, step: int, key: np.uint64, pose: np.ndarray, belief: np.ndarray, ring: np.ndarray,
                ring_ok: np.ndarray, ring_pos: np.ndarray, noise: np.ndarray, meas: np.ndarray,
                fg: FieldGains) -> bool:
    """The tracker at control step ``step`` of robot ``i``'s run; returns whether it saw the robot.

    Writes the measurement (noisy pose, ``meas`` ``(3,)``), puts it in flight
    (``ring`` ``(N, delay + 1, 3)``), updates ``belief[i]`` with the
    measurement that arrives now, and keeps this step's track noise in
    ``noise[i]`` for :func:`field_actuate`.
    """
    u = np.empty(_SENSE_CHANNELS)
    z0, z1, z2, z3, z4, _ = _six_normals(key, step, u)
    noise[i, 0], noise[i, 1] = z3, z4
    frame = (step * fg.camera_rate) // fg.control_rate != ((step - 1) * fg.camera_rate) // fg.control_rate
    ok = frame and u[6] >= fg.dropout
    meas[0] = pose[i, 0] + z0 * fg.sigma_xy
    meas[1] = pose[i, 1] + z1 * fg.sigma_xy
    meas[2] = wrap_angle(pose[i, 2] + z2 * fg.sigma_theta)
    slots = fg.delay + 1
    slot = ring_pos[i] % slots
    ring[i, slot, :] = meas
    ring_ok[i, slot] = ok
    ready = (ring_pos[i] + 1) % slots
    if ring_ok[i, ready]:
        belief[i, :] = ring[i, ready, :]
    ring_pos[i] += 1
    return ok


@kernel
def _track(current: float, want: float, gain: float, z: float, fg: FieldGains) -> float:
    """A track's speed (m/s) after one step towards the commanded ``want``."""
    if abs(want) < fg.dead_band:
        target = 0.0
    else:
        target = want * gain + (fg.wheel_noise_rel * abs(want) + fg.wheel_noise_abs) * z
    step = (target - current) * fg.alpha
    out = current + min(max(step, -fg.accel_step), fg.accel_step)
    return 0.0 if abs(out) < 1e-5 else out


@kernel
def field_actuate(i: int, v: float, w: float, pose: np.ndarray, tracks: np.ndarray, gain: np.ndarray,
                  noise: np.ndarray, fg: FieldGains) -> None:
    """Robot ``i``'s tracks follow commands ``(v, w)`` for one step and move it (in place)."""
    left, right = body_to_tracks(v, w, fg.wheel_base)
    tracks[i, 0] = _track(tracks[i, 0], left, gain[i, 0], noise[i, 0], fg)
    tracks[i, 1] = _track(tracks[i, 1], right, gain[i, 1], noise[i, 1], fg)
    bv, bw = tracks_to_body(tracks[i, 0], tracks[i, 1], fg.wheel_base)
    pose[i, 0], pose[i, 1], pose[i, 2] = unicycle_step(pose[i, 0], pose[i, 1], pose[i, 2], bv, bw, fg.dt)
