"""One robot as its clients see it: the protocol verbs, events and the disconnect rule.

:class:`Robot` turns parsed commands into calls on the host's simulation core
(one method per verb, after aiosmtpd's ``smtp_<VERB>``) and routes the core's
events to the connection that sent the path.

Rules (documented in ``docs/protocol.md``):

- A new ``T,T,P`` replaces the path in progress; the replaced path ends with
  ``EV,FAIL,STOPPED`` to its sender, before the new path's ``OK,P,<n>``.
- ``T,T,S`` stops the path in progress (``EV,FAIL,STOPPED`` to its sender,
  then ``OK,S``); with no path in progress it only answers ``OK,S``.
- ``T,T,I`` and ``T,T,B`` are refused with ``ERR,STATE`` while a path is in
  progress or the gripper is busy; ``T,T,P`` is refused while the gripper is
  busy.  The gripper takes experiment time per block / placement, and the
  ``OK`` comes when it is done.
- **Disconnect rule**: when the connection that sent the path in progress
  closes, the robot stops at once (the path ends as ``FAIL,STOPPED``, logged
  by the agent since nobody is left to tell): nothing drives unattended.
- **Authentication** (only when the robot has a ``control_key``): ``T,T,P``,
  ``T,T,S``, ``T,T,I`` and ``T,T,B`` need a connection authenticated with
  ``T,T,A,<secret>``, the secret being the control key or the current lease;
  ``T,T,L,<lease>`` (control key only) grants the one lease, ``T,T,L`` alone
  revokes it, and so does the granting connection closing.  Connections
  authenticated with a revoked lease lose their authentication.
"""

from __future__ import annotations

import asyncio
import hmac
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Awaitable, Callable

from contract.controller_specs import ControllerError, select
from contract.params import RobotParams
from contract.protocol import (AuthCommand, BuildCommand, Command, ControllerCommand, ErrorCode, LeaseCommand,
                               LocalisationCommand, MovingCommand, PathCommand, PlaceCommand, ProtocolError, QueryCommand, RobotState, StopCommand,
                               VelocityCommand, format_event, format_hello, format_ok, format_status, parse_arguments, split_command)
from robot_agent.engine.noise import path_key
from robot_agent.engine.sim import SimCore, SimEvent, State
from robot_agent.engine.world import World

from .connection import MAX_AUTH_FAILURES

if TYPE_CHECKING:
    from .connection import Connection

__all__ = ["GUARDED_VERBS", "Robot", "RobotServices"]

log = logging.getLogger("robot_agent.host.robot")

GUARDED_VERBS = frozenset("PSIBMV")  #: verbs that need an authenticated connection when there is a control key
WATCHDOG_S = 0.5  #: experiment seconds a robot in velocity mode drives on without a new T,T,V


@dataclass(frozen=True)
class RobotServices:
    """What a robot uses of the host that runs it, handed in: the robot never sees the host itself."""

    core: SimCore  #: the simulation core all robots of the host share
    world: World
    params: RobotParams
    seed: int  #: the host's seed, from which each path's noise key derives
    backend_name: str  #: ``ideal`` or ``field``
    advertise_host: str  #: the address clients reach the robot's port at
    sync_clock: Callable[[], None]  #: bring experiment time up to date before a command applies
    wake: Callable[[], None]  #: something changed: the simulation loop plans its next step now
    sleep: Callable[[float], Awaitable[None]]  #: wait this many seconds of experiment time
    event_hook: Callable[["Robot", str], None]  #: an ``EV`` line of this robot, for the host's listeners
    localisation_changed: Callable[[], None]  #: a connection subscribed to ``PO`` lines or left
    #: a ``T,T,V`` of a connection driving the robot: True when it answers a pose its lockstep controller was sent
    #: (the host applies it in its control step), False: apply it now
    answer: Callable[["Robot", "Connection", VelocityCommand], bool] = lambda robot, conn, cmd: False
    #: a path or velocity mode starts: the tracker's stream of the robot restarts with it (frames in flight dropped)
    path_started: Callable[["Robot"], None] = lambda robot: None


class Robot:
    """Robot ``index`` of a host, called ``robot_id``; ``services`` are what it uses of that host."""

    def __init__(self, services: RobotServices, index: int, robot_id: str, *,
                 control_key: str | None = None) -> None:
        self.services, self.index, self.robot_id = services, index, robot_id
        self.control_key = control_key
        self.lease: str | None = None  # the second secret, granted by a key holder
        self.lease_grant = 0  # number of the current (or last) grant
        self.lease_holder: "Connection | None" = None
        self.port = 0
        self.connections: set["Connection"] = set()
        self.owner: "Connection | None" = None  # sender of the path in progress
        self.gripper_busy = False
        self.path_count = 0
        self.next_seed: int | None = None  # one-shot seed for the next path
        self.last_seed: int | None = None

    # ------------------------------------------------------------------ frames

    @property
    def origin(self) -> tuple[float, float]:
        """The robot frame's origin in its world (m)."""
        o = self.services.world.origin[self.index]
        return float(o[0]), float(o[1])

    @property
    def area(self) -> tuple[float, float]:
        """The working area (w, h) in m: protocol points must lie in [0, w] x [0, h]."""
        a = self.services.world.area[self.index]
        return float(a[0]), float(a[1])

    def hello(self) -> str:
        """The greeting line."""
        return format_hello(self.robot_id, self.services.params.platform)

    def state(self) -> RobotState:
        """The path state (ST names)."""
        return RobotState(State(int(self.services.core.state[self.index])).name)

    # ------------------------------------------------------------------ dispatch

    async def handle(self, conn: "Connection", line: bytes, *, in_thread: bool = False) -> list[str]:
        """Reply lines for one client line (``ERR`` for anything refused).

        The verb is checked against the connection's authentication before its
        arguments are parsed; with ``in_thread`` (long lines) both parsing
        steps run in a worker thread.
        """
        try:
            if in_thread:
                verb, rest = await asyncio.to_thread(split_command, line)
            else:
                verb, rest = split_command(line)
            self._admit(conn, verb)
            if in_thread:
                cmd = await asyncio.to_thread(parse_arguments, verb, rest, field_size=self.area)
            else:
                cmd = parse_arguments(verb, rest, field_size=self.area)
            return await self._dispatch(conn, cmd)
        except ProtocolError as exc:
            return [exc.line()]

    async def _dispatch(self, conn: "Connection", cmd: Command) -> list[str]:
        """One method per verb."""
        verb = _VERBS.get(type(cmd))
        if verb is None:
            raise ProtocolError(ErrorCode.UNSUPPORTED, "unsupported command")
        replies = verb(self, conn, cmd)
        return replies if isinstance(replies, list) else await replies

    def cmd_localisation(self, conn: "Connection", cmd: LocalisationCommand) -> list[str]:
        """``T,T,O``: send (or stop sending) this connection ``PO`` lines; with a clock, how the robot's clock
        treats it while it drives the robot (``lockstep``/``free``; none named: the host's default)."""
        conn.localisation = cmd.on
        conn.clock = cmd.clock if cmd.on else None
        self.services.localisation_changed()
        return [format_ok("O")]

    # ------------------------------------------------------------------ authentication

    def authorized(self, conn: "Connection") -> bool:
        """Whether ``conn`` may move the robot or change the world (always, without a control key)."""
        if self.control_key is None or conn.auth == "key":
            return True
        return conn.auth == "lease" and self.lease is not None and conn.lease_grant == self.lease_grant

    def _admit(self, conn: "Connection", verb: str) -> None:
        """Refuse a verb this connection may not use now."""
        if conn.probation and verb != "A":
            raise ProtocolError(ErrorCode.STATE, "too many connections")
        if verb in GUARDED_VERBS and not self.authorized(conn):
            raise ProtocolError(ErrorCode.AUTH,
                                f"T,T,{verb} needs an authenticated connection: send T,T,A,<secret> first")

    def cmd_auth(self, conn: "Connection", cmd: AuthCommand) -> list[str]:
        """``T,T,A``: authenticate with the control key or the current lease (any secret without a key)."""
        key, lease = self.control_key, self.lease
        if key is None:
            conn.auth = "open"
        elif hmac.compare_digest(cmd.secret, key):
            conn.auth = "key"
        elif lease is not None and hmac.compare_digest(cmd.secret, lease):
            conn.auth, conn.lease_grant = "lease", self.lease_grant
        else:
            conn.auth_failures += 1
            log.info("%s: wrong secret from %s (%d)", self.robot_id, conn.peer, conn.auth_failures)
            left = MAX_AUTH_FAILURES - conn.auth_failures
            why = (f"wrong secret ({left} attempt{'s' if left != 1 else ''} left)" if left > 0
                   else "wrong secret; closing")
            raise ProtocolError(ErrorCode.AUTH, why)
        conn.probation = False
        return [format_ok("A")]

    def cmd_lease(self, conn: "Connection", cmd: LeaseCommand) -> list[str]:
        """``T,T,L``: grant (or with no lease, revoke) the robot's one lease; control key only."""
        if self.control_key is None:
            return [format_ok("L")]  # an open robot: nothing to grant
        if conn.auth != "key":
            raise ProtocolError(ErrorCode.AUTH, "only a connection authenticated with the control key grants leases")
        if cmd.lease is None:
            self.revoke_lease()
        elif hmac.compare_digest(cmd.lease, self.control_key):
            raise ProtocolError(ErrorCode.RANGE, "a lease must differ from the control key")
        else:
            self.lease, self.lease_holder = cmd.lease, conn
            self.lease_grant += 1
            log.info("%s: lease granted by %s", self.robot_id, conn.peer)
        return [format_ok("L")]

    def revoke_lease(self) -> None:
        """End the current lease: connections authenticated with it lose their authentication."""
        if self.lease is not None:
            log.info("%s: lease revoked", self.robot_id)
        self.lease, self.lease_holder = None, None

    def _noise_key(self) -> int:
        if self.next_seed is not None:
            seed, self.next_seed = self.next_seed, None
            self.last_seed = seed
            return path_key(seed)
        self.last_seed = None
        return path_key(self.services.seed, self.robot_id, self.path_count)

    def cmd_path(self, conn: "Connection", cmd: PathCommand) -> list[str]:
        """``T,T,P``: follow a path from the next control step."""
        if self.gripper_busy:
            raise ProtocolError(ErrorCode.STATE, "the gripper is busy with this robot")
        self.services.sync_clock()
        replaced = self.services.core.set_path(self.index, cmd.points, self._noise_key(), conn.controller)
        self.services.path_started(self)
        self.path_count += 1
        if replaced is not None:
            self._deliver(replaced)
        self.owner = conn
        self.services.wake()
        log.info("%s: path of %d points from %s", self.robot_id, len(cmd.points), conn.peer)
        return [format_ok("P", len(cmd.points))]

    def cmd_controller(self, conn: "Connection", cmd: ControllerCommand) -> list[str]:
        """``T,T,C``: the controller of the paths this connection sends from now on (alone: the default)."""
        try:
            chosen = select(cmd.name, cmd.params)
        except ControllerError as exc:
            code = ErrorCode.UNSUPPORTED if exc.field == "controller" else ErrorCode.RANGE
            raise ProtocolError(code, str(exc)) from None
        conn.controller = None if cmd.name is None else chosen
        return [format_ok("C")]

    def cmd_velocity(self, conn: "Connection", cmd: VelocityCommand) -> list[str]:
        """``T,T,V``: drive with body velocities until the next one, ``T,T,S`` or the watchdog (no path)."""
        core = self.services.core
        if self.gripper_busy:
            raise ProtocolError(ErrorCode.STATE, "the gripper is busy with this robot")
        started = not core.driving(self.index)
        if started:  # (a robot in velocity mode keeps the clock running: nothing to bring up to date)
            self.services.sync_clock()
        if started and core.moving(self.index):
            raise ProtocolError(ErrorCode.STATE, "a path is in progress: T,T,V drives a robot without one (T,T,S first)")
        if not started and self.owner is not conn:
            raise ProtocolError(ErrorCode.STATE, "another connection drives this robot")
        if not started and self.services.answer(self, conn, cmd):
            return [format_ok("V")]  # a lockstep controller's answer: it applies in its control step
        core.drive(self.index, cmd.v, cmd.w, self._noise_key() if started else 0, WATCHDOG_S)
        if started:
            self.services.path_started(self)
            self.path_count += 1
            self.owner = conn
            self.services.wake()
            log.info("%s: velocity mode from %s", self.robot_id, conn.peer)
        return [format_ok("V")]

    def cmd_stop(self, conn: "Connection", cmd: StopCommand) -> list[str]:
        """``T,T,S``: stop now."""
        self.services.sync_clock()
        ev = self.services.core.stop(self.index)
        if ev is not None:
            self._deliver(ev)
        return [format_ok("S")]

    def cmd_query(self, conn: "Connection", cmd: QueryCommand) -> list[str]:
        """``T,T,Q``: state, believed pose (robot frame) and experiment time."""
        self.services.sync_clock()
        return [format_status(self.state(), self.services.core.belief(self.index), self.services.core.t)]

    def _check_gripper(self) -> None:
        core = self.services.core
        if core.driving(self.index):
            raise ProtocolError(ErrorCode.STATE, "the robot is driving in velocity mode (send T,T,S first)")
        if core.moving(self.index):
            raise ProtocolError(ErrorCode.STATE, "the robot is following a path (send T,T,S first)")
        if self.gripper_busy:
            raise ProtocolError(ErrorCode.STATE, "the gripper is busy with this robot")

    def gripper_seconds(self, *, blocks: int = 0, placements: int = 0) -> float:
        """Experiment seconds the gripper takes; none in the ``ideal`` simulator, where worlds appear at once."""
        if self.services.backend_name == "ideal":
            return 0.0
        g = self.services.params.gripper
        return blocks * g.seconds_per_block + placements * g.seconds_per_placement

    async def cmd_place(self, conn: "Connection", cmd: PlaceCommand) -> list[str]:
        """``T,T,I``: the gripper places the robot (takes ``seconds_per_placement``)."""
        self._check_gripper()
        why = self.services.world.place_conflict(self.index, cmd.pose, self.services.core.backend.pose)
        if why:
            raise ProtocolError(ErrorCode.RANGE, f"cannot place the robot: {why}")
        self.gripper_busy = True
        try:
            await self.services.sleep(self.gripper_seconds(placements=1))
            if self.services.core.moving(self.index):  # a path arrived meanwhile: impossible, but safe
                raise ProtocolError(ErrorCode.STATE, "the robot started moving")
            self.services.core.place(self.index, cmd.pose)
        finally:
            self.gripper_busy = False
        return [format_ok("I")]

    async def cmd_build(self, conn: "Connection", cmd: BuildCommand) -> list[str]:
        """``T,T,B``: the gripper replaces this robot's blocks (time per block removed and placed)."""
        self._check_gripper()
        removed = len(self.services.world.blocks_local(self.index))
        self.gripper_busy = True
        try:
            await self.services.sleep(self.gripper_seconds(blocks=removed + len(cmd.blocks)))
            self.services.world.set_blocks(self.index, cmd.blocks)
        finally:
            self.gripper_busy = False
        return [format_ok("B", len(cmd.blocks))]

    def cmd_moving(self, conn: "Connection", cmd: MovingCommand) -> list[str]:
        """``T,T,M``: replace this robot's moving obstacles (their time starts with its next path)."""
        self._check_gripper()
        self.services.world.set_moving(self.index, list(cmd.obstacles))
        return [format_ok("M", len(cmd.obstacles))]

    # ------------------------------------------------------------------ events

    def _deliver(self, ev: SimEvent) -> None:
        """Send a core event to the path's sender (log it when nobody is left)."""
        line = ev.line
        if ev.kind in ("DONE", "FAIL", "REPLAN"):
            log.info("%s: %s", self.robot_id, line)
        owner = self.owner
        if ev.kind in ("DONE", "FAIL"):
            self.owner = None
        if owner is not None:
            owner.send(line)
        self.services.event_hook(self, line)

    def on_event(self, ev: SimEvent) -> None:
        """An event of this robot from the simulation core."""
        self._deliver(ev)

    def connected(self, conn: "Connection") -> None:
        """A client connected to this robot's port."""
        self.connections.add(conn)

    def disconnected(self, conn: "Connection") -> None:
        """The disconnect rule: the path of a closing sender stops at once; its lease ends."""
        self.connections.discard(conn)
        if conn.localisation:
            conn.localisation = False
            self.services.localisation_changed()
        if self.lease_holder is conn:
            self.revoke_lease()
        if self.owner is conn:
            self.owner = None
            ev = self.services.core.stop(self.index)
            if ev is not None:
                log.warning("%s: client %s left mid-path; robot stopped (FAIL,STOPPED)", self.robot_id, conn.peer)
                self.services.event_hook(self, format_event("FAIL", ev.t, reason="STOPPED"))

    def info(self) -> dict[str, object]:
        """The registration record of this robot (see ``docs/protocol.md``)."""
        return {
            "robot_id": self.robot_id,
            "host": self.services.advertise_host,
            "port": self.port,
            "platform": self.services.params.platform,
            "backend": self.services.backend_name,
            "profile": self.services.params.name,
            "origin": list(self.origin),
            "area": list(self.area),
        }


#: the method of each command (every one takes the connection and the command; some are coroutines)
_VERBS: dict[type, Callable[..., "list[str] | Awaitable[list[str]]"]] = {
    PathCommand: Robot.cmd_path,
    StopCommand: Robot.cmd_stop,
    QueryCommand: Robot.cmd_query,
    PlaceCommand: Robot.cmd_place,
    BuildCommand: Robot.cmd_build,
    MovingCommand: Robot.cmd_moving,
    AuthCommand: Robot.cmd_auth,
    LeaseCommand: Robot.cmd_lease,
    ControllerCommand: Robot.cmd_controller,
    VelocityCommand: Robot.cmd_velocity,
    LocalisationCommand: Robot.cmd_localisation,
}
