"""The emulated robots' physics, one robot at a time (compiled scalar functions).

What the two emulated backends (:mod:`robot_agent.engine.backends`) do to robot
``i`` of a fleet in one control step, written once and called both by the
backends' array methods and by the fused simulation loop
(:mod:`robot_agent.engine.stepper`):

- ideal (Player/Stage-like): the commands move the robot exactly
  (:func:`ideal_actuate`); it knows its pose.
- field (the emulated physical robot): :func:`field_sense` is the overhead
  tracker (a frame at ``camera_rate_hz`` timed from the path start; a
  position error that varies smoothly over the field, :func:`tracker_bias`,
  plus per-frame jitter; dropped frames; ``tracker_latency_s`` delay) and the
  robot's localisation, which turns those late fixes into its belief
  (:func:`localise`: each fix is projected forward over the latency with the
  robot's odometry, and the belief is dead-reckoned between fixes);
  :func:`field_actuate` the tracks (per-run gain, speed noise, dead band,
  first-order lag, acceleration limit) and the odometry model of them
  (:func:`odometry`); :func:`field_begin` the per-run draws.

All noise comes from :mod:`robot_agent.engine.noise`, keyed per run, so runs replay
exactly.  Units: m, rad, s.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from contract.params import RobotParams

from .compiled import kernel
from .kinematics import body_to_tracks, tracks_to_body, unicycle_step, wrap_angle
from .noise import box_muller, uniform

__all__ = ["BIAS_FEATURES", "FIELD", "IDEAL", "FieldGains", "RUN_COUNTER", "field_actuate", "field_begin", "field_gains", "field_sense",
           "ideal_actuate", "localise", "odometry", "tracker_bias"]

#: noise counter reserved for per-run draws (a path never runs 2**40 steps); the tracker's bias
#: field draws from the counters after it
RUN_COUNTER = 1 << 40
_SENSE_CHANNELS = 8  # normals 0-2 tracker noise, 3-4 track noise, (5 unused), uniform 6 dropout
#: random Fourier features per axis of the tracker's position bias (:func:`tracker_bias`)
BIAS_FEATURES = 8


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
    bias_xy: float  #: standard deviation of the tracker's smooth position error (m)
    bias_wavenumber: float  #: 1 / its correlation length (1/m)
    predict: int  #: steps over which the localisation projects each fix forward (latency compensation)
    lead: float  #: how far ahead (s) of its belief the controller's pose is predicted
    slip_rho: float  #: per-step autocorrelation of the track slip (exp(-dt / wheel_noise_corr_s); 0: white)
    turn_base: float  #: the track width the robot really turns with (m): wheel_base x track_width_factor (skid)


def field_gains(p: RobotParams) -> FieldGains:
    """The :class:`FieldGains` of robot parameters ``p``."""
    f = p.field
    alpha = 1.0 - math.exp(-p.dt / f.motor_time_constant_s) if f.motor_time_constant_s > 0 else 1.0
    k = 1.0 / f.tracker_bias_length_m if f.tracker_bias_length_m > 0 else 0.0
    return FieldGains(int(p.controller.control_rate_hz), int(f.camera_rate_hz), int(round(f.tracker_latency_s / p.dt)),
                      f.tracker_dropout_prob, f.tracker_noise_xy_m, f.tracker_noise_theta_rad, p.wheel_base_m,
                      f.wheel_noise_rel, f.wheel_noise_abs_m_s, f.wheel_gain_mean, f.wheel_bias_sigma,
                      f.dead_band_m_s, p.max_accel_m_s2 * p.dt, alpha, p.dt, f.tracker_bias_xy_m, k,
                      int(round(f.latency_compensation_s / p.dt)), f.control_lead_s,
                      math.exp(-p.dt / f.wheel_noise_corr_s) if f.wheel_noise_corr_s > 0 else 0.0,
                      p.wheel_base_m * f.track_width_factor)


IDEAL, FIELD = 0, 1  #: which physics the compiled loop applies to a fleet (``Emulated.kind``)


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
def field_begin(i: int, key: np.uint64, from_rest: bool, pose: np.ndarray, belief: np.ndarray, ctl: np.ndarray,
                gain: np.ndarray, ring_ok: np.ndarray, odo: np.ndarray, odo_ring: np.ndarray, bias: np.ndarray,
                noise: np.ndarray, fg: FieldGains) -> None:
    """A path with noise ``key`` starts for robot ``i``: draw its track gains and the tracker's
    bias field (``bias`` ``(N, 2 * BIAS_FEATURES, 3)``), start its track slip (``noise[i]``) at 0 (a
    run replays from its own seed alone); a robot that was at rest gets a fresh tracker measurement
    as its belief (the tracker was watching it) and odometry at rest."""
    noise[i, 0] = noise[i, 1] = 0.0
    z0, z1, z2, z3, z4, _ = _six_normals(key, RUN_COUNTER, np.empty(6))
    gain[i, 0] = fg.gain_mean + fg.bias_sigma * z0
    gain[i, 1] = fg.gain_mean + fg.bias_sigma * z1
    for j in range(bias.shape[1]):  # features of x (first half) and y: wave vector ~ N(0, k^2 I), phase
        c = RUN_COUNTER + 1 + j
        kx, ky = box_muller(uniform(key, c, 4, 0), uniform(key, c, 4, 1))
        bias[i, j, 0] = kx * fg.bias_wavenumber
        bias[i, j, 1] = ky * fg.bias_wavenumber
        bias[i, j, 2] = 2.0 * math.pi * uniform(key, c, 4, 2)
    if from_rest:
        bx, by = tracker_bias(i, pose[i, 0], pose[i, 1], bias, fg)
        belief[i, 0] = pose[i, 0] + bx + z2 * fg.sigma_xy
        belief[i, 1] = pose[i, 1] + by + z3 * fg.sigma_xy
        belief[i, 2] = wrap_angle(pose[i, 2] + z4 * fg.sigma_theta)
        ctl[i, :] = belief[i]
        ring_ok[i, :] = False
        odo[i, :] = 0.0
        odo_ring[i, :, :] = 0.0


@kernel
def tracker_bias(i: int, x: float, y: float, bias: np.ndarray, fg: FieldGains) -> tuple[float, float]:
    """The tracker's position error (m) at ``(x, y)`` in robot ``i``'s run: a smooth random field.

    Random Fourier features (Rahimi and Recht 2007): per axis ``sigma sqrt(2/F) sum_j cos(k_j . p +
    phi_j)`` over ``F`` features drawn in :func:`field_begin`; a Gaussian-like field of standard
    deviation ``bias_xy`` whose correlation falls as ``exp(-d^2 / (2 l^2))`` with distance ``d``
    (``l`` = ``tracker_bias_length_m``): the lens-distortion and calibration residue of the
    cameras, the same wherever the robot passes the same spot.
    """
    if fg.bias_xy == 0.0:
        return 0.0, 0.0
    f = bias.shape[1] // 2
    sx = sy = 0.0
    for j in range(f):
        sx += math.cos(bias[i, j, 0] * x + bias[i, j, 1] * y + bias[i, j, 2])
        sy += math.cos(bias[i, f + j, 0] * x + bias[i, f + j, 1] * y + bias[i, f + j, 2])
    scale = fg.bias_xy * math.sqrt(2.0 / f)
    return scale * sx, scale * sy


@kernel
def field_sense(i: int, step: int, key: np.uint64, pose: np.ndarray, belief: np.ndarray, ctl: np.ndarray,
                ring: np.ndarray, ring_ok: np.ndarray, ring_pos: np.ndarray, noise: np.ndarray, meas: np.ndarray,
                odo: np.ndarray, odo_ring: np.ndarray, bias: np.ndarray, fg: FieldGains) -> bool:
    """The tracker at control step ``step`` of robot ``i``'s run; returns whether it saw the robot.

    Writes the measurement (pose plus the tracker's bias and jitter, ``meas``
    ``(3,)``), puts it in flight (``ring`` ``(N, delay + 1, 3)``), updates
    ``belief[i]`` (:func:`localise`) with the measurement that arrives now, and
    keeps this step's track slip in ``noise[i]`` for :func:`field_actuate`: standard normal, white
    from step to step or, with ``wheel_noise_corr_s``, a first-order autoregressive process of that
    correlation time (slip changes with the surface patch a track is on, not every 20 ms).
    """
    u = np.empty(_SENSE_CHANNELS)
    z0, z1, z2, z3, z4, _ = _six_normals(key, step, u)
    if fg.slip_rho > 0.0:
        keep = math.sqrt(1.0 - fg.slip_rho * fg.slip_rho)
        noise[i, 0] = fg.slip_rho * noise[i, 0] + keep * z3
        noise[i, 1] = fg.slip_rho * noise[i, 1] + keep * z4
    else:
        noise[i, 0], noise[i, 1] = z3, z4
    frame = (step * fg.camera_rate) // fg.control_rate != ((step - 1) * fg.camera_rate) // fg.control_rate
    ok = frame and u[6] >= fg.dropout
    bx, by = tracker_bias(i, pose[i, 0], pose[i, 1], bias, fg)
    meas[0] = pose[i, 0] + bx + z0 * fg.sigma_xy
    meas[1] = pose[i, 1] + by + z1 * fg.sigma_xy
    meas[2] = wrap_angle(pose[i, 2] + z2 * fg.sigma_theta)
    slots = fg.delay + 1
    slot = ring_pos[i] % slots
    ring[i, slot, :] = meas
    ring_ok[i, slot] = ok
    ready = (ring_pos[i] + 1) % slots
    localise(i, ring_pos[i], ring_ok[i, ready], ring[i, ready], belief, ctl, odo, odo_ring, fg)
    ring_pos[i] += 1
    return ok


@kernel
def localise(i: int, pos: int, arrived: bool, fix: np.ndarray, belief: np.ndarray, ctl: np.ndarray, odo: np.ndarray,
             odo_ring: np.ndarray, fg: FieldGains) -> None:
    """Robot ``i``'s belief at the start of its step number ``pos`` (its ``ring_pos``).

    Without latency compensation (``predict`` = 0) the belief is the latest
    fix that arrived, held until the next one.  With it, as robot software
    that knows its tracker's latency does: a fix that arrives now (taken
    ``predict`` steps ago) is moved forward by the odometry of those steps
    (``odo_ring`` ``(N, predict + 1, 2)``: the modelled track speeds of each
    step, :func:`odometry`); between fixes the belief moves on by the last
    step's odometry (dead reckoning).
    """
    p = fg.predict
    if p == 0:
        if arrived:
            belief[i, :] = fix
    elif arrived:
        slots = p + 1
        x, y, th = fix[0], fix[1], fix[2]
        for j in range(pos - p, pos):
            s = (j + slots) % slots
            v, w = tracks_to_body(odo_ring[i, s, 0], odo_ring[i, s, 1], fg.wheel_base)
            x, y, th = unicycle_step(x, y, th, v, w, fg.dt)
        belief[i, 0], belief[i, 1], belief[i, 2] = x, y, th
    else:
        v, w = tracks_to_body(odo[i, 0], odo[i, 1], fg.wheel_base)
        belief[i, 0], belief[i, 1], belief[i, 2] = unicycle_step(belief[i, 0], belief[i, 1], belief[i, 2], v, w, fg.dt)
    if fg.lead > 0.0:
        v, w = tracks_to_body(odo[i, 0], odo[i, 1], fg.wheel_base)
        ctl[i, 0], ctl[i, 1], ctl[i, 2] = unicycle_step(belief[i, 0], belief[i, 1], belief[i, 2], v, w, fg.lead)
    else:
        ctl[i, :] = belief[i]


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
def odometry(i: int, v: float, w: float, pos: int, odo: np.ndarray, odo_ring: np.ndarray, fg: FieldGains) -> None:
    """The robot's model of its own tracks after commands ``(v, w)`` in its step ``pos``.

    The same track model as the physics (:func:`_track`: dead band, lag,
    acceleration limit) with what the robot knows of itself, the nominal
    unit gain and no noise; what the per-run gains, the slip noise and the
    tracker reveal later is not in it.  Kept in ``odo[i]`` and, for
    :func:`localise`, in ``odo_ring[i]`` at slot ``pos % (predict + 1)``.
    """
    if fg.predict == 0 and fg.lead == 0.0:
        return
    left, right = body_to_tracks(v, w, fg.wheel_base)
    odo[i, 0] = _track(odo[i, 0], left, 1.0, 0.0, fg)
    odo[i, 1] = _track(odo[i, 1], right, 1.0, 0.0, fg)
    s = pos % (fg.predict + 1)
    odo_ring[i, s, 0], odo_ring[i, s, 1] = odo[i, 0], odo[i, 1]


@kernel
def field_actuate(i: int, v: float, w: float, pose: np.ndarray, tracks: np.ndarray, gain: np.ndarray,
                  noise: np.ndarray, ring_pos: np.ndarray, odo: np.ndarray, odo_ring: np.ndarray,
                  fg: FieldGains) -> None:
    """Robot ``i``'s tracks follow commands ``(v, w)`` for one step and move it (in place); its
    odometry model follows the same commands (:func:`odometry`).  The commands become track speeds over
    the nominal ``wheel_base`` (what the robot's software knows); the tracks turn the robot over
    ``turn_base``: a skid-steered robot turns slower than its track speeds say (``track_width_factor``)."""
    left, right = body_to_tracks(v, w, fg.wheel_base)
    tracks[i, 0] = _track(tracks[i, 0], left, gain[i, 0], noise[i, 0], fg)
    tracks[i, 1] = _track(tracks[i, 1], right, gain[i, 1], noise[i, 1], fg)
    bv, bw = tracks_to_body(tracks[i, 0], tracks[i, 1], fg.turn_base)
    pose[i, 0], pose[i, 1], pose[i, 2] = unicycle_step(pose[i, 0], pose[i, 1], pose[i, 2], bv, bw, fg.dt)
    odometry(i, v, w, ring_pos[i] - 1, odo, odo_ring, fg)
