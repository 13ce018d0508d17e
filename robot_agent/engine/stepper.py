"""The simulation loop in compiled code: many control steps of a whole fleet per call.

:func:`run` advances every robot of an :class:`~robot_agent.engine.backends.Emulated`
backend up to ``max_steps`` control steps without returning to Python.  A
step is: sense (:mod:`robot_agent.engine.physics`), :func:`control_fleet` (the
follower), actuate, collisions once all robots moved
(:func:`robot_agent.engine.contact.collide`), :func:`settle_fleet` (path states and
event rows).  It stops early when nothing moves any more or when its output
buffers could not hold another step.  Events and logged poses go to those
buffers as rows; :class:`robot_agent.engine.sim.SimCore` turns them into records.
Backends that are stepped through Python run the same two fleet kernels
around their own methods.

Array groups (each passed as a tuple, modified in place):

- ``ctrl`` = ``(state, aligning, wp, k, timeout, cmd, anchor, anchor_k,
  points, offset, count, cid, cpar, cmem, want)``: the path follower's state
  and each robot's controller (id, parameters, memory, a plug-in's
  commands; see ``SimCore`` and :mod:`robot_agent.engine.controllers`);
- ``phys`` = :attr:`.backends.Emulated.arrays`; ``world`` = :attr:`.world.World.arrays`;
- ``out`` = ``(events (E, 5) int64: step, robot, old wp, new wp, flags;
  pose_rows (P, 2) int64: step, robot; pose_xyt (P, 3); and per-robot
  scratch: flags, old wp, moving, check, hit, measurement (3,))``.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

from .compiled import kernel
from .contact import block_distance, collide, obstacle_xy, wall_distance
from .controllers import RPP
from .follower import DONE, STALLED, TIMED_OUT, Gains, control
from .movers import MoverGains, drive_movers
from .physics import FIELD, IDEAL, FieldGains, field_actuate, field_sense, ideal_actuate

__all__ = ["COLLIDED", "ENDED", "FIELD", "IDEAL", "State", "clearance", "control_fleet", "run", "settle_fleet"]

COLLIDED = 32  #: flag bit: the robot touched a wall, a block, a robot or a moving obstacle this step
ENDED = DONE | STALLED | TIMED_OUT


class State(IntEnum):
    """Per-robot path state (the ``ST`` reply's names)."""

    IDLE = 0
    MOVING = 1
    DONE = 2
    FAILED = 3


@kernel
def clearance(i: int, x: float, y: float, t: float, believed: np.ndarray, world: tuple, radius: float) -> float:
    """Distance (m) from the edge of robot ``i`` believed at ``(x, y)`` (its frame) to the nearest wall, block,
    moving obstacle (at its time ``t``, s since the path began) or other robot of its world (where those
    robots believe they are, ``believed`` ``(N, 3)`` in their frames); ``radius`` is the robots' collision
    radius (m).  What regulated pure pursuit slows down by, as nav2's reads its costmap."""
    origin, world_of, sizes, centre, half, cs, nblocks, shared = world[0], world[1], world[2], world[3], \
        world[4], world[5], world[6], world[7]
    mo_first, mo_par, mo_pts, mo_cum, mo_n = world[9], world[10], world[11], world[12], world[13]
    mv_on, mv_pose = world[15], world[16]
    wx, wy = x + origin[i, 0], y + origin[i, 1]
    w = world_of[i]
    d = min(wall_distance(wx, wy, sizes[w, 0], sizes[w, 1]), block_distance(wx, wy, w, centre, half, cs, nblocks))
    for m in range(mo_first[i], mo_first[i + 1]):
        ox, oy = obstacle_xy(m, t, mo_par, mo_pts, mo_cum, mo_n, mv_on, mv_pose, origin[i, 0], origin[i, 1])
        d = min(d, math.hypot(wx - ox, wy - oy) - mo_par[m, 0])
    n = len(mo_first) - 2
    if w == 0:
        for m in range(mo_first[n], mo_first[n + 1]):  # a fleet's obstacle robots
            d = min(d, math.hypot(wx - mv_pose[m, 0], wy - mv_pose[m, 1]) - mo_par[m, 0])
    for j in shared:
        if j != i and world_of[j] == w:
            d = min(d, math.hypot(wx - believed[j, 0] - origin[j, 0], wy - believed[j, 1] - origin[j, 1]) - radius)
    return d - radius


@kernel
def control_fleet(belief: np.ndarray, moving: np.ndarray, ctrl: tuple, g: Gains, flags: np.ndarray,
                  old: np.ndarray, world: tuple, radius: float) -> None:
    """The follower's step for every robot: its flags, its waypoint before the step in ``old``;
    robots not ``moving`` get zero commands.  ``world`` (:attr:`.world.World.arrays`) and the collision
    ``radius`` (m) give the clearance that regulated pure pursuit slows down by."""
    state, aligning, wp, k, timeout, cmd, anchor, anchor_k, points, offset, count, cid, cpar, cmem, want = ctrl
    for i in range(len(belief)):
        old[i] = wp[i]
        if moving[i]:
            near = clearance(i, belief[i, 0], belief[i, 1], k[i] * g.dt, belief, world, radius) if cid[i] == RPP \
                else np.inf
            flags[i] = control(i, belief[i, 0], belief[i, 1], belief[i, 2], points, offset, count, wp, aligning,
                               cmd, anchor, anchor_k, k, timeout, g, cid, cpar, cmem, want, near)
        else:
            flags[i] = 0
            cmd[i, 0] = cmd[i, 1] = 0.0


@kernel
def settle_fleet(step: int, hit: np.ndarray, flags: np.ndarray, old: np.ndarray, ctrl: tuple,
                 events: np.ndarray, n_ev: int) -> int:
    """End every robot's step after the collision check: a hit stops its commands (and fails its
    path), its path state follows its flags, and an event row goes to ``events`` from row
    ``n_ev`` on when anything happened; returns the new row count."""
    state, aligning, wp, k, timeout, cmd, anchor, anchor_k, points, offset, count, _, _, _, _ = ctrl
    for i in range(len(hit)):
        if hit[i]:
            cmd[i, 0] = cmd[i, 1] = 0.0
            if state[i] == State.MOVING and not flags[i] & ENDED:
                flags[i] |= COLLIDED
        k[i] += 1
        f = flags[i]
        if f & DONE:
            state[i] = State.DONE
        elif f & (STALLED | TIMED_OUT | COLLIDED):
            state[i] = State.FAILED
        if f != 0 or wp[i] != old[i]:
            events[n_ev, 0], events[n_ev, 1], events[n_ev, 2] = step, i, old[i]
            events[n_ev, 3], events[n_ev, 4] = wp[i], f
            n_ev += 1
    return n_ev


@kernel
def _busy(kind: int, state: np.ndarray, tracks: np.ndarray) -> bool:
    for i in range(len(state)):
        if state[i] == State.MOVING or (kind == FIELD and (tracks[i, 0] != 0.0 or tracks[i, 1] != 0.0)):
            return True
    return False


@kernel
def run(kind: int, max_steps: int, step0: int, log_poses: bool, ctrl: tuple, phys: tuple, world: tuple,
        radius: float, step_travel: float, out: tuple, g: Gains, fg: FieldGains, movers: tuple,
        mg: MoverGains) -> tuple[int, int, int]:
    """Advance the fleet up to ``max_steps`` steps from simulation step ``step0``; on the field the obstacle
    robots (``movers`` = ``(tables, phys)`` of :mod:`robot_agent.engine.movers`) step after the robots moved.

    Returns ``(steps done, event rows, pose rows)``.
    """
    state, aligning, wp, k, timeout, cmd, anchor, anchor_k, points, offset, count, _, _, _, _ = ctrl
    pose, belief, ctl, tracks, gain, keys, ring, ring_ok, ring_pos, noise, odo, odo_ring, bias = phys
    events, pose_rows, pose_xyt, flags, old, moving, check, hit, meas = out
    n = len(state)
    n_ev = n_pose = 0
    s = 0
    while s < max_steps and n_ev + n <= len(events) and n_pose + n <= len(pose_rows) and _busy(kind, state, tracks):
        step = step0 + s
        for i in range(n):
            moving[i] = state[i] == State.MOVING
            if kind == FIELD:
                seen = field_sense(i, k[i], keys[i], pose, belief, ctl, ring, ring_ok, ring_pos, noise, meas, odo,
                                   odo_ring, bias, fg)
            else:
                meas[:] = pose[i]
                seen = True
            if seen and moving[i] and log_poses:
                pose_rows[n_pose, 0], pose_rows[n_pose, 1] = step, i
                pose_xyt[n_pose, :] = meas
                n_pose += 1
        control_fleet(ctl, moving, ctrl, g, flags, old, world, radius)
        for i in range(n):
            if kind == FIELD:
                field_actuate(i, cmd[i, 0], cmd[i, 1], pose, tracks, gain, noise, ring_pos, odo, odo_ring, fg)
                check[i] = (moving[i] and not flags[i] & ENDED) or tracks[i, 0] != 0.0 or tracks[i, 1] != 0.0
            else:
                ideal_actuate(i, cmd[i, 0], cmd[i, 1], pose, g.dt)
                check[i] = moving[i] and not flags[i] & ENDED
        if kind == FIELD:
            drive_movers(k, world, movers[0], movers[1], meas, fg, mg, False)
        collide(pose, check, step, k, hit, world, radius, step_travel, g.dt)
        if kind == FIELD:
            for i in range(n):
                if hit[i]:
                    tracks[i, 0] = tracks[i, 1] = 0.0
        n_ev = settle_fleet(step, hit, flags, old, ctrl, events, n_ev)
        s += 1
    return s, n_ev, n_pose
