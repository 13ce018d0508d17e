"""The simulation loop in compiled code: many control steps of a whole fleet per call.

:func:`run` advances every robot of an :class:`~robot_agent.backends.Emulated`
backend up to ``max_steps`` control steps without returning to Python:
sense, follow (:func:`robot_agent.follower.control`), actuate
(:mod:`robot_agent.physics`), then collisions (:func:`robot_agent.contact.collide`)
once all robots moved.  It stops early when nothing moves any more or when
its output buffers could not hold another step.  Events and logged poses go
to those buffers as rows; :class:`robot_agent.sim.SimCore` turns them into
records.  :func:`control_fleet` is the follower step alone, for backends
that are stepped through Python.

Array groups (each passed as a tuple, modified in place):

- ``ctrl`` = ``(state, aligning, wp, k, timeout, cmd, anchor, anchor_k,
  points, offset, count)``: the path follower's state (see ``SimCore``);
- ``phys`` = :attr:`Emulated.arrays`; ``world`` = :attr:`World.arrays`;
- ``out`` = ``(events (E, 5) int64: step, robot, old wp, new wp, flags;
  pose_rows (P, 2) int64: step, robot; pose_xyt (P, 3); and per-robot
  scratch: flags, old wp, check, hit, measurement (3,))``.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from .compiled import kernel
from .contact import collide
from .follower import DONE, STALLED, TIMED_OUT, Gains, control
from .physics import FieldGains, field_actuate, field_sense, ideal_actuate

__all__ = ["COLLIDED", "ENDED", "FIELD", "IDEAL", "State", "control_fleet", "run"]

COLLIDED = 32  #: flag bit: the robot touched a wall, a block or a robot this step
ENDED = DONE | STALLED | TIMED_OUT
IDEAL, FIELD = 0, 1  #: the physics :func:`run` applies (``Emulated.kind``)


class State(IntEnum):
    """Per-robot path state (the ``ST`` reply's names)."""

    IDLE = 0
    MOVING = 1
    DONE = 2
    FAILED = 3


@kernel
def control_fleet(belief: np.ndarray, moving: np.ndarray, ctrl: tuple, g: Gains, flags: np.ndarray) -> None:
    """The follower's step for every robot (commands of robots not ``moving`` become 0)."""
    state, aligning, wp, k, timeout, cmd, anchor, anchor_k, points, offset, count = ctrl
    for i in range(len(belief)):
        if moving[i]:
            flags[i] = control(i, belief[i, 0], belief[i, 1], belief[i, 2], points, offset, count, wp, aligning,
                               cmd, anchor, anchor_k, k, timeout, g)
        else:
            flags[i] = 0
            cmd[i, 0] = cmd[i, 1] = 0.0


@kernel
def _busy(kind: int, state: np.ndarray, tracks: np.ndarray) -> bool:
    for i in range(len(state)):
        if state[i] == State.MOVING or (kind == FIELD and (tracks[i, 0] != 0.0 or tracks[i, 1] != 0.0)):
            return True
    return False


@kernel
def run(kind: int, max_steps: int, step0: int, log_poses: bool, ctrl: tuple, phys: tuple, world: tuple,
        radius: float, step_travel: float, out: tuple, g: Gains, fg: FieldGains) -> tuple[int, int, int]:
    """Advance the fleet up to ``max_steps`` steps from simulation step ``step0``.

    Returns ``(steps done, event rows, pose rows)``.
    """
    state, aligning, wp, k, timeout, cmd, anchor, anchor_k, points, offset, count = ctrl
    pose, belief, tracks, gain, keys, ring, ring_ok, ring_pos, noise = phys
    origin, world_of, sizes, centre, half, cs, nblocks, shared, safe_until = world
    events, pose_rows, pose_xyt, flags, old, check, hit, meas = out
    n = len(state)
    n_ev = n_pose = 0
    s = 0
    while s < max_steps and n_ev + n <= len(events) and n_pose + n <= len(pose_rows) and _busy(kind, state, tracks):
        step = step0 + s
        for i in range(n):
            moving = state[i] == State.MOVING
            if kind == FIELD:
                seen = field_sense(i, k[i], keys[i], pose, belief, ring, ring_ok, ring_pos, noise, meas, fg)
                logged = seen and moving
            else:
                meas[:] = pose[i]
                logged = moving
            if logged and log_poses:
                pose_rows[n_pose, 0], pose_rows[n_pose, 1] = step, i
                pose_xyt[n_pose, :] = meas
                n_pose += 1
            old[i] = wp[i]
            if moving:
                flags[i] = control(i, belief[i, 0], belief[i, 1], belief[i, 2], points, offset, count, wp,
                                   aligning, cmd, anchor, anchor_k, k, timeout, g)
            else:
                flags[i] = 0
                cmd[i, 0] = cmd[i, 1] = 0.0
            if kind == FIELD:
                field_actuate(i, cmd[i, 0], cmd[i, 1], pose, tracks, gain, noise, fg)
                check[i] = (moving and not flags[i] & ENDED) or tracks[i, 0] != 0.0 or tracks[i, 1] != 0.0
            else:
                ideal_actuate(i, cmd[i, 0], cmd[i, 1], pose, g.dt)
                check[i] = moving and not flags[i] & ENDED
        collide(pose, check, step, hit, origin, world_of, sizes, centre, half, cs, nblocks, shared, safe_until,
                radius, step_travel)
        for i in range(n):
            if hit[i]:
                tracks[i, 0] = tracks[i, 1] = 0.0
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
        s += 1
    return s, n_ev, n_pose
