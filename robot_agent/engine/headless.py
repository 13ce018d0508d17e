"""One robot's run as a function call: build, place, follow a path to its end, with no socket and no clock.

The agent's own simulation core (:class:`~robot_agent.engine.sim.SimCore`) stepped as fast as it goes, in a
world of its own, exactly as an agent's simulation-pool robot would run it: the path, the placement and
the blocks go through the wire codec's rounding (0.01 mm, 0.01 deg) as they would over TCP, the noise
key comes from the run's seed, and the tracker log is the core's.  So a run here gives the same poses
and events as the same run sent to an agent (times counted from the path's start).  The testbed's
simulation pool on Ray runs this (:mod:`robot_agent.engine.jobs`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from contract.controller_specs import select
from contract.frames import FIELD_SIZE
from contract.params import robot_params
from contract.protocol import (
    BuildCommand,
    MovingCommand,
    PathCommand,
    PlaceCommand,
    encode_build,
    encode_moving,
    encode_path,
    encode_place,
    parse_command,
)
from contract.robot_profile import DEFAULT_PROFILE

from .cores import layout_core
from .movers import mover_tracks
from .noise import path_key
from .sim import SimEvent

__all__ = ["HeadlessRun", "PlacementRefused", "simulate_run"]


class PlacementRefused(ValueError):
    """The gripper cannot put the robot at the start (a wall or a block within the collision radius), as an
    agent answers ``ERR,RANGE`` to ``T,T,I`` there."""

_CHUNK = 4096  # control steps per compiled call


@dataclass
class HeadlessRun:
    """What one run gave: tracker ``poses`` ``(N, 4)`` (t s, x m, y m, theta rad; the robot's frame),
    its ``events`` in order, the experiment times (s) of its start and end (None if none) and, on the
    field, the tracker's poses of its obstacle robots (``obstacles``: per moving obstacle ``(T, 4)`` on the
    run's clock, as ``poses``; None: exact discs, :mod:`robot_agent.engine.movers`)."""

    poses: np.ndarray
    events: list[SimEvent] = field(default_factory=list)
    t_start: float | None = None
    t_end: float | None = None
    obstacles: list[np.ndarray] | None = None

    @property
    def outcome(self) -> str:
        """``DONE``, the ``FAIL`` reason (``COLLISION`` ...), or ``TIMEOUT_SIM`` when ``max_s`` ran out first."""
        last = self.events[-1] if self.events else None
        if last is not None and last.kind == "DONE":
            return "DONE"
        if last is not None and last.kind == "FAIL":
            return str(last.reason)
        return "TIMEOUT_SIM"

    @property
    def obstacle(self) -> int | None:
        """The moving obstacle the robot collided with (its index in the environment), else None."""
        last = self.events[-1] if self.events else None
        return last.index if last is not None and last.kind == "FAIL" and last.reason == "COLLISION" else None


def simulate_run(path: Sequence[Sequence[float]] | np.ndarray, start: Sequence[float], *, seed: int,
                 blocks: Sequence[Sequence[float]] = (), moving: Sequence[tuple] = (), backend: str = "ideal",
                 profile: str | dict = DEFAULT_PROFILE, area: tuple[float, float] = FIELD_SIZE,
                 max_s: float = 3600.0, track_gains: tuple[float, float] | None = None, controller: str | None = None,
                 controller_params: dict[str, float] | None = None) -> HeadlessRun:
    """Run ``path`` ``(N, 3)`` (m, m, rad) from ``start`` (x, y, theta) among ``blocks`` (cx, cy, w, h,
    angle: m, rad) and ``moving`` obstacles (params, waypoints: as :func:`~contract.protocol.encode_moving`
    takes them) in a world of ``area`` (m), with the run's ``seed``, until the robot ends the path or
    ``max_s`` of experiment time passed (on the ``field`` backend the moving obstacles are robots the
    testbed drives, :mod:`robot_agent.engine.movers`), with ``controller`` (a name of
    :mod:`contract.controller_specs`, default the motor schema) and its ``controller_params`` (SI
    units; defaults filled in).  ``track_gains`` (left, right; field backend) replaces the run's drawn
    track gains (calibration re-simulates runs with fitted ones).  Raises :class:`PlacementRefused`
    when the start is not free and :class:`~contract.controller_specs.ControllerError` for a bad
    controller choice."""
    chosen = select(controller, controller_params)
    params = robot_params(profile)
    core = layout_core(params, backend, 1, "separate", area)
    world = core.world
    size = (float(world.area[0, 0]), float(world.area[0, 1]))
    built = parse_command(encode_build(blocks), field_size=size)
    placed = parse_command(encode_place(start), field_size=size)
    sent = parse_command(encode_path(path), field_size=size)
    movers = parse_command(encode_moving(moving), field_size=size)
    assert isinstance(built, BuildCommand) and isinstance(placed, PlaceCommand) and isinstance(sent, PathCommand)
    assert isinstance(movers, MovingCommand)
    world.set_blocks(0, built.blocks)
    world.set_moving(0, list(movers.obstacles))
    why = world.place_conflict(0, placed.pose, core.backend.pose)
    if why:
        raise PlacementRefused(f"cannot place the robot: {why}")
    core.place(0, placed.pose)
    core.poses.drain()
    core.set_path(0, sent.points, path_key(seed), chosen)
    if track_gains is not None:
        core.backend.gain[0] = track_gains
    events: list[SimEvent] = []
    left = math.ceil(max_s / core.dt)
    while left > 0 and core.busy():
        n = min(_CHUNK, left)
        events += core.advance(n)
        left -= n
    poses = core.poses.drain().get(0, np.zeros((0, 4)))
    t_start = next((e.t for e in events if e.kind == "START"), None)
    t_end = next((e.t for e in events if e.kind in ("DONE", "FAIL")), None)
    tracks = None
    if world.driven is not None and movers.obstacles:
        tracks = [tr + [t_start or 0.0, 0.0, 0.0, 0.0] for tr in mover_tracks(
            list(movers.obstacles), path_key(seed), params, int(core.k[0]) * core.dt, world.halted(0))]
    return HeadlessRun(poses, events, t_start, t_end, tracks)
