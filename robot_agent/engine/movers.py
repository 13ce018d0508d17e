"""Moving obstacles on the emulated field: robots the testbed drives itself along their tracks.

docs/protocol.md, "Moving obstacles", describes them from the outside.

In a simulation (ideal backend) a moving obstacle is a disc that moves
exactly as :mod:`planners.moving` says.  On the emulated field (field
backend) it is an emulated field robot of the run's profile, the same
physics as the run's robots (:mod:`robot_agent.engine.physics`: the tracker with its
latency, noise and dropouts, motor lag, acceleration limit, per-run track
gains and speed noise), driven by the testbed with :func:`pursue`: pure
pursuit of the exact track's point ``lookahead_s`` ahead in the obstacle's
time, so it keeps to the track's timing (``speed``, ``repeat``, ``delay_s``)
as well as a lagging robot can.  Its actual path deviates from the exact
track (it cuts corners, lags, overshoots at a ``pingpong`` turn) by a few
centimetres.  It is a robot: the run's robots touch it when their centres
come closer than two collision radii (whatever radius the environment gave
the disc), and once it is hit it stops where it is, as a robot does.

Each obstacle robot's noise comes from its own key, :func:`mover_key` of the
run's key and its index, and its motion does not depend on the run's robots
until one hits it; so its trajectory is replayed off line
(:func:`mover_tracks`) exactly as it was driven live, which is how the
server measures a run against where the obstacle robots really were.

State: a :class:`~robot_agent.engine.backends.FieldBackend`'s arrays, one row per
obstacle (its ``arrays`` tuple is ``phys`` below); poses are in the owner
robot's frame (m, rad); ``pts`` ``(M, K, 2)`` / ``cum`` ``(M, K)`` /
``count`` ``(M,)`` the tracks in that frame (:mod:`robot_agent.engine.contact`'s
layout), ``par`` ``(M, 4)`` radius, speed, repeat code, delay.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np

from contract.params import RobotParams

from .backends import FieldBackend
from .compiled import kernel
from .contact import LOOP, obstacle_position
from .kinematics import wrap_angle
from .noise import mix64
from .physics import FieldGains, field_actuate, field_begin, field_gains, field_sense

__all__ = ["MoverGains", "drive_movers", "drive_shared", "mover_gains", "mover_key", "mover_step", "mover_tracks", "pursue",
           "reset_mover", "start_pose"]

_SALT = 0x0B57AC1E  # separates obstacle keys from robot keys


class MoverGains(NamedTuple):
    """The testbed's obstacle driver (SI units): look ``lookahead_s`` (s) ahead on the track, turn at
    ``heading_gain`` (1/s) times the heading error up to ``max_turn`` (rad/s), drive at most ``max_speed``
    (m/s), turn in place beyond ``turn_in_place`` (rad) of error, stand within ``stop_m`` (m) of the point."""

    lookahead_s: float
    heading_gain: float
    max_speed: float
    max_turn: float
    turn_in_place: float
    stop_m: float
    dt: float


def mover_gains(p: RobotParams) -> MoverGains:
    """The obstacle driver of robots of parameters ``p`` (its speed and turn limits, its control step)."""
    return MoverGains(0.5, p.controller.heading_gain_1_s, p.max_speed_m_s, p.max_angular_speed_rad_s,
                      p.controller.turn_in_place_rad, 0.005, p.dt)


def mover_key(key: int, j: int) -> int:
    """The noise key of obstacle robot ``j`` of a run of noise key ``key`` (uint64 as int)."""
    salted = np.uint64((int(key) ^ int(mix64(np.uint64(j + _SALT)))) & ((1 << 64) - 1))
    return int(mix64(salted))


@kernel
def start_pose(m: int, pts: np.ndarray, count: np.ndarray) -> tuple[float, float, float]:
    """Where obstacle robot ``m`` stands before its track begins: its first waypoint, facing the first
    waypoint that differs from it (m, m, rad)."""
    x, y = pts[m, 0, 0], pts[m, 0, 1]
    for j in range(1, count[m]):
        dx, dy = pts[m, j, 0] - x, pts[m, j, 1] - y
        if dx != 0.0 or dy != 0.0:
            return x, y, math.atan2(dy, dx)
    return x, y, 0.0


@kernel
def pursue(m: int, t: float, x: float, y: float, th: float, par: np.ndarray, pts: np.ndarray, cum: np.ndarray,
           count: np.ndarray, mg: MoverGains) -> tuple[float, float]:
    """Body commands (v m/s, w rad/s) for obstacle robot ``m`` believed at ``(x, y, th)`` at its time ``t`` (s):
    towards the exact track's position ``lookahead_s`` later, at the speed that reaches it in that time."""
    tx, ty = obstacle_position(m, t + mg.lookahead_s, par, pts, cum, count)
    dx, dy = tx - x, ty - y
    d = math.hypot(dx, dy)
    if d < mg.stop_m:
        return 0.0, 0.0
    err = wrap_angle(math.atan2(dy, dx) - th)
    w = min(max(mg.heading_gain * err, -mg.max_turn), mg.max_turn)
    if abs(err) > mg.turn_in_place:
        return 0.0, w
    return min(mg.max_speed, d / mg.lookahead_s) * math.cos(err), w


@kernel
def reset_mover(m: int, key: np.uint64, par: np.ndarray, pts: np.ndarray, count: np.ndarray, phys: tuple,
                fg: FieldGains) -> None:
    """Put obstacle robot ``m`` at rest at its :func:`start_pose` and begin its run with noise ``key``."""
    pose, belief, ctl, tracks, gain, keys, ring, ring_ok, ring_pos, noise, odo, odo_ring, bias = phys
    pose[m, 0], pose[m, 1], pose[m, 2] = start_pose(m, pts, count)
    tracks[m, 0] = tracks[m, 1] = 0.0
    ring_pos[m] = 0
    keys[m] = key
    field_begin(m, key, True, pose, belief, ctl, gain, ring_ok, odo, odo_ring, bias, noise, fg)


@kernel
def mover_step(m: int, c: int, par: np.ndarray, pts: np.ndarray, cum: np.ndarray, count: np.ndarray, phys: tuple,
               meas: np.ndarray, fg: FieldGains, mg: MoverGains) -> bool:
    """Step ``c`` (control steps since its track began) of obstacle robot ``m``: the tracker, the driver,
    the tracks.  Returns whether the tracker saw it (its measurement in ``meas`` ``(3,)``)."""
    pose, belief, ctl, tracks, gain, keys, ring, ring_ok, ring_pos, noise, odo, odo_ring, bias = phys
    seen = field_sense(m, c, keys[m], pose, belief, ctl, ring, ring_ok, ring_pos, noise, meas, odo, odo_ring, bias,
                       fg)
    v, w = pursue(m, c * mg.dt, ctl[m, 0], ctl[m, 1], ctl[m, 2], par, pts, cum, count, mg)
    field_actuate(m, v, w, pose, tracks, gain, noise, ring_pos, odo, odo_ring, fg)
    return seen


@kernel
def drive_movers(k: np.ndarray, world: tuple, tables: tuple, phys: tuple, meas: np.ndarray, fg: FieldGains,
                 mg: MoverGains, only_shared: bool) -> None:
    """One control step of every driven obstacle robot of a world (:attr:`robot_agent.engine.world.World.arrays`)
    that was not hit: a robot's own at its time ``k[i]`` (steps since its path began), the shared ones
    (a fleet's) at their own clock, which this advances; ``only_shared``: those alone (the robots stand)."""
    mo_first, mo_par, mo_n, mv_on, mv_halt, mv_clock = world[9], world[10], world[13], world[15], world[17], \
        world[18]
    pts, cum = tables
    n = len(mo_first) - 2
    for g in range(0 if not only_shared else n, n + 1):
        for m in range(mo_first[g], mo_first[g + 1]):
            if not mv_on[m] or mv_halt[m] >= 0:
                continue
            c = k[g] if g < n else mv_clock[m]
            mover_step(m, c, mo_par, pts, cum, mo_n, phys, meas, fg, mg)
            if g == n:
                mv_clock[m] += 1


@kernel
def drive_shared(steps: int, k: np.ndarray, world: tuple, tables: tuple, phys: tuple, fg: FieldGains,
                 mg: MoverGains) -> None:
    """``steps`` control steps of a world's shared obstacle robots alone (:func:`drive_movers`)."""
    meas = np.empty(3)
    for _ in range(steps):
        drive_movers(k, world, tables, phys, meas, fg, mg, True)


@kernel
def _replay(steps: int, halt: np.ndarray, par: np.ndarray, pts: np.ndarray, cum: np.ndarray, count: np.ndarray,
            phys: tuple, fg: FieldGains, mg: MoverGains, rows: np.ndarray, xyt: np.ndarray) -> int:
    """``steps`` steps of every obstacle robot, each one standing after its ``halt`` step (-1: never);
    the tracker's measurements go to ``rows`` (step, obstacle) and ``xyt``; returns how many."""
    meas = np.empty(3)
    pose, belief, ctl, tracks, gain, keys, ring, ring_ok, ring_pos, noise, odo, odo_ring, bias = phys
    got = 0
    for c in range(steps):
        for m in range(len(count)):
            if halt[m] < 0 or c <= halt[m]:
                seen = mover_step(m, c, par, pts, cum, count, phys, meas, fg, mg)
            else:  # it stands where it was hit; the tracker still sees it
                seen = field_sense(m, c, keys[m], pose, belief, ctl, ring, ring_ok, ring_pos, noise, meas, odo,
                                   odo_ring, bias, fg)
            if seen:
                rows[got, 0], rows[got, 1] = c, m
                xyt[got, :] = meas
                got += 1
    return got


def mover_tracks(obstacles: Sequence[tuple[Sequence[float], Sequence[Sequence[float]]]], key: int,
                 params: RobotParams, duration_s: float, halt: Sequence[int] | None = None) -> list[np.ndarray]:
    """What the tracker logged of obstacle robots driven for ``duration_s`` (s) from their track's start in a
    run of noise ``key``: per obstacle ``(T, 4)`` t s (since the track began), x m, y m, theta rad, in the
    frame of their waypoints.  ``obstacles`` as the agent got them (:class:`~contract.protocol.MovingCommand`,
    after the wire's rounding); ``halt[j]`` the step obstacle ``j`` was hit in (it stands after it; -1:
    never).  The same numbers as the live obstacle robots' (:func:`drive_movers`)."""
    m = len(obstacles)
    if m == 0:
        return []
    steps = max(0, int(math.ceil(duration_s / params.dt - 1e-9)))
    par, pts, cum, count = track_tables(obstacles)
    state = FieldBackend(m, params)
    fg = field_gains(params)
    for j in range(m):
        reset_mover(j, np.uint64(mover_key(key, j)), par, pts, count, state.arrays, fg)
    h = np.full(m, -1, dtype=np.int64) if halt is None else np.asarray(halt, dtype=np.int64).reshape(m)
    rows = np.zeros((steps * m, 2), dtype=np.int64)
    xyt = np.zeros((steps * m, 3))
    got = _replay(steps, h, par, pts, cum, count, state.arrays, fg, mover_gains(params), rows, xyt)
    rows, xyt = rows[:got], xyt[:got]
    return [np.column_stack([rows[rows[:, 1] == j, 0] * params.dt, xyt[rows[:, 1] == j]]) for j in range(m)]


def track_tables(obstacles: Sequence[tuple[Sequence[float], Sequence[Sequence[float]]]]) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(par (M, 4), pts (M, K, 2), cum (M, K), count (M,))`` of obstacles given as (params, waypoints), a
    ``loop`` closed (:mod:`robot_agent.engine.contact`'s layout)."""
    tracks = []
    for p, w in obstacles:
        w = np.asarray(w, dtype=float).reshape(-1, 2)
        if int(p[2]) == LOOP and len(w) > 1:
            w = np.vstack([w, w[:1]])
        tracks.append((np.asarray(p, dtype=float).reshape(4), w))
    k = max((len(w) for _, w in tracks), default=1)
    par = np.zeros((max(len(tracks), 1), 4))
    pts = np.zeros((len(par), k, 2))
    cum = np.zeros((len(par), k))
    count = np.ones(len(par), dtype=np.int64)
    for m, (p, w) in enumerate(tracks):
        par[m] = p
        pts[m, : len(w)] = w
        cum[m, 1: len(w)] = np.cumsum(np.hypot(*np.diff(w, axis=0).T))
        count[m] = len(w)
    return par, pts, cum, count
