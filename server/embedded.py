"""The robots of ``twb up``, in the server's own process: the field and the simulation pool.

Four emulated field robots, one per sub-field (sub-field 1's robot covers the
whole field, for full-field jobs), share one world; ``sim_robots`` ideal
robots have a whole-field world each.  They listen on free ports of
127.0.0.1 like any agent and the run pipeline drives them over TCP, but
they register and deliver their tracker poses directly (no HTTP), and the
pipeline seeds their next path and flushes their tracker through
:class:`EmbeddedField`'s :class:`~server.pipeline.context.RobotHooks`.
"""

from __future__ import annotations

import asyncio
import logging
import secrets
from typing import TYPE_CHECKING, Optional

import numpy as np
from sqlalchemy.exc import DBAPIError

from contract.frames import FIELD_SIZE, SUBFIELD_ORIGINS, SUBFIELD_SIZE

from .field import FieldState
from .schemas import RobotRegister
from .tracking import PoseRouter

if TYPE_CHECKING:
    from robot_agent.host import AgentHost

__all__ = ["EmbeddedField"]

log = logging.getLogger("twb.server")


class _RouterSink:
    """A tracker sink storing pose batches through the server's pose router (in a thread).

    While the database is unreachable the batches are dropped (a run in progress then ends and is queued
    again: its poses would be incomplete anyway), with one log line per outage.
    """

    def __init__(self, router: PoseRouter) -> None:
        self._router = router
        self._failing = False

    async def send(self, robot_id: str, poses: np.ndarray) -> None:
        try:
            await asyncio.to_thread(self._router.ingest, robot_id, np.asarray(poses, dtype=float))
        except DBAPIError as exc:
            if not self._failing:
                log.warning("tracker poses are dropped while the database is unreachable: %s", exc.orig)
            self._failing = True
        else:
            self._failing = False

    async def aclose(self) -> None:
        return None


class EmbeddedField:
    """Four field robots and ``sim_robots`` simulated ones at ``time_scale``, seeded with ``seed``; ``clock``
    their closed-loop clock (``lockstep`` or ``free``, :mod:`robot_agent.host.lockstep`)."""

    def __init__(self, *, sim_robots: int = 4, seed: int = 0, time_scale: float = 1.0,
                 clock: str = "lockstep", lockstep_wait_s: float = 3.0) -> None:
        self.sim_robots, self.seed, self.time_scale, self.clock = sim_robots, seed, time_scale, clock
        self.lockstep_wait_s = lockstep_wait_s
        self._hosts: list["AgentHost"] = []
        self._host_of: dict[str, "AgentHost"] = {}

    def descriptors(self) -> int:
        """File descriptors the robots may hold at most: each robot port's own connection budget (its
        regular connections and those on probation, :class:`robot_agent.host.connection.Limits`), the
        testbed's side of its own connections to them, and the listening sockets."""
        from robot_agent.host.connection import Limits

        limits = Limits()
        robots = 4 + self.sim_robots
        return robots * (limits.max_connections + limits.max_probation + 2 + 1)

    async def start(self, field: FieldState, router: PoseRouter) -> None:
        """Start the robots and register them with ``field``; their poses go to ``router``."""
        from robot_agent.host import AgentHost  # the simulation core (numba) only where robots run

        sink = _RouterSink(router)
        # their ports listen on 127.0.0.1 like any agent's: only the testbed (which knows the key) drives them
        key = secrets.token_hex(32)
        common = {"time_scale": self.time_scale, "clock": self.clock, "lockstep_wait_s": self.lockstep_wait_s,
                  "seed": self.seed, "tracker_sink": sink,
                  "advertise_host": "127.0.0.1", "control_key": key}
        self._hosts = [
            AgentHost(robots=4, backend="field", world="shared", robot_ids=[f"field-{k}" for k in range(1, 5)],
                      area=[FIELD_SIZE, SUBFIELD_SIZE, SUBFIELD_SIZE, SUBFIELD_SIZE], origins=list(SUBFIELD_ORIGINS),
                      **common),
        ]
        if self.sim_robots:  # none when simulation runs go to Ray
            self._hosts.append(AgentHost(robots=self.sim_robots, backend="ideal", world="separate", area=FIELD_SIZE,
                                         robot_ids=[f"sim-{i}" for i in range(1, self.sim_robots + 1)], **common))
        for host in self._hosts:
            await host.start()
            for r in host.robots:
                self._host_of[r.robot_id] = host
                await field.register(RobotRegister(**r.info()), control_key=key)

    async def stop(self) -> None:
        """Stop every robot (their connections close; pending tracker poses are delivered)."""
        for host in self._hosts:
            await host.stop()
        self._hosts, self._host_of = [], {}

    # ------------------------------------------------------------------ RobotHooks

    def seed_next_path(self, robot_id: str, seed: int) -> bool:
        host = self._host_of.get(robot_id)
        if host is not None:
            host.set_path_seed(robot_id, seed)
        return host is not None

    async def flush_tracker(self, robot_id: str) -> bool:
        host: Optional["AgentHost"] = self._host_of.get(robot_id)
        if host is None:
            return False
        await host.flush_tracker()
        return True
