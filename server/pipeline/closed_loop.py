"""A run driven by an uploaded controller program: the planned path in, body velocities out, over TCP.

Instead of the server sending ``T,T,P``, the experiment's ``controller_program``
runs in the sandbox (:meth:`server.sandbox.Sandbox.run_controller`).  Its robot
port relays the closed-loop verbs (``T,T,O``, ``T,T,V``, ``T,T,S``, ``T,T,Q``)
to the run's robot over the run's own authenticated connection, and sends the
program the robot's ``PO`` and ``EV`` lines.  When the program connects, the
server subscribes with the testbed's clock (``T,T,O,1,<clock>``, settings
``clock``) and puts the robot in velocity mode (``T,T,V,0,0``): from then on the
robot's 0.5 s watchdog holds.  In lockstep (the default) the robot's clock waits for
the program's answer to every pose it is sent (docs/protocol.md, "Lockstep"): the
program gets the run's poses only — from the first after velocity mode started,
the newest one kept for it until it subscribes — so a run is the same at every
time scale.  The run ends when:

- the program stops the robot (``T,T,S``, or ``T,T,V,0,0`` within the goal
  tolerance: the server sends ``T,T,S`` instead, answered ``OK,V``) — ``completed`` within the goal tolerance,
  else ``failed`` (program);
- the program exits, crashes or hits a sandbox limit — the robot is stopped;
  ``completed`` only after a clean exit with the robot within the tolerance
  (how a program exits after the run has ended, e.g. on the
  ``ERR,STATE,the run has ended`` of a ``T,T,V`` sent too late, does not
  change the run's outcome);
- the robot ends velocity mode itself: ``EV,FAIL,WATCHDOG`` (no ``T,T,V`` for
  0.5 s of experiment time), ``EV,FAIL,COLLISION`` — ``failed``.
"""

from __future__ import annotations

import asyncio
import math
import time
from typing import Any, Callable, Optional

import numpy as np

from planners.metrics import DEFAULT_GOAL_TOLERANCE

from ..agent_link import AgentLink
from ..errors import FailureKind, RunFailed
from ..sandbox import ProgramSpec
from ..status import SubfieldState
from ..store.runs import RunJob
from ..validation import FIELD_SIZE, SUBFIELD_SIZE
from .context import RunContext, RunServices
from .paths import Plan
from .steps import collect_poses, fail_fields, failure_of, start_pose

__all__ = ["RELAY_LOGGED_LINES", "ControllerRelay", "drive_program", "program_metrics"]

#: a controller program's relayed lines (to its robot and back) logged at most, per run; the rest are counted,
#: so that the run's log keeps room for the program's own report (its robot port, stdout, stderr, its end)
RELAY_LOGGED_LINES = 10_000


class ControllerRelay:
    """The run's side of a controller program's robot port (:class:`server.sandbox.service.Relay`).

    ``goal`` (m) in the robot's frame; ``tolerance_m``: how near the goal the
    robot must stop.  ``ended`` resolves with the robot's ending ``EV,FAIL``
    fields (``STOPPED`` when the program or the server stopped it).  ``seed``
    gives the robot's velocity mode the job's noise seed (whether it could:
    :meth:`.context.RobotHooks.seed_next_path`), so that its obstacle robots replay.
    """

    def __init__(self, link: AgentLink, ctx: RunContext, goal: tuple[float, float], tolerance_m: float,
                 seed: Callable[[], bool] = lambda: False, clock: str = "lockstep") -> None:
        self.link, self.ctx, self._seed, self.clock = link, ctx, seed, clock
        self.goal, self.tolerance_m = goal, tolerance_m
        self.pose: Optional[tuple[float, float]] = None  # the last PO position, m
        self.t_start: Optional[float] = None
        self.t_end: Optional[float] = None
        self.ended: asyncio.Future[tuple[str, ...]] = asyncio.get_running_loop().create_future()
        self._subscribed = False
        self._arming = False  # T,T,V,0,0 sent: the robot's OK,V starts the run's poses
        self._run_poses = False  # PO lines from now on are the run's (velocity mode started)
        self._held: Optional[str] = None  # the run's newest PO line while the program has not subscribed
        self._lines: asyncio.Queue[Optional[str]] = asyncio.Queue()
        #: the program's T,T,V lines, and how long each answered the first PO line it had not answered yet (s)
        self.steps = 0
        self.responses_s: list[float] = []
        self._unanswered: Optional[float] = None
        #: the program connected and the robot is in velocity mode
        self.armed = False
        #: why the program broke the relay's rules (it flooded its robot port): the run fails with it
        self.fault: Optional[str] = None
        self._relay_logged = 0
        link.on_pose = self._on_pose
        link.on_line = self._log

    def _log(self, direction: str, line: str, t: Optional[float], estimated: bool) -> None:
        """The run's line between server and robot while the program drives: logged up to RELAY_LOGGED_LINES."""
        if self._arming and direction == "<" and line.startswith("OK,V"):
            self._arming, self._run_poses = False, True  # in the order the robot sent them: the next PO is the run's
        if self._relay_logged < RELAY_LOGGED_LINES:
            self._relay_logged += 1
            self.ctx.on_line(direction, line, t, estimated)
        else:
            self.ctx.not_logged(f"relayed lines of the controller program beyond its first {RELAY_LOGGED_LINES}")

    def abort(self, reason: str) -> None:
        """The program broke the relay's rules (:meth:`server.sandbox.service.Relay.abort`): the run fails
        with ``reason`` (program), whatever the robot does meanwhile; no more of its lines go to the robot."""
        if self.fault is None:
            self.fault = reason
            self.ctx.on_line("s", f"relay: {reason}", None, False)

    def distance_m(self) -> float:
        """How far the last localised position is from the goal (m; inf before any)."""
        return math.inf if self.pose is None else math.dist(self.pose, self.goal)

    def _on_pose(self, line: str, fields: tuple[str, ...]) -> None:
        try:
            self.pose = (float(fields[0]) / 1000.0, float(fields[1]) / 1000.0)
        except (IndexError, ValueError):
            return
        if not self._run_poses or self.ended.done():
            return
        if self._subscribed:
            self._lines.put_nowait(line)
        else:
            self._held = line

    async def connected(self) -> None:
        """The program is on its robot port: localise, and put the robot in velocity mode (the watchdog holds)."""
        if self.armed or self.ended.done():
            return
        self.armed = True
        self.ctx.seeded = self._seed()  # velocity mode draws the robot's noise as a path does
        await self.link.request(f"T,T,O,1,{self.clock}", self.ctx.wall(0))
        self._arming = True
        await self.link.request("T,T,V,0,0", self.ctx.wall(0))

    async def to_robot(self, line: str) -> str:
        """One valid closed-loop line of the program; the reply for it."""
        if line.startswith("T,T,O"):  # the server's own subscription stays; only what the program gets changes
            self._subscribed = line.split(",")[3:4] == ["1"]
            if self._subscribed and self._held is not None and not self.ended.done():
                self._lines.put_nowait(self._held)  # the pose a lockstep robot waits for an answer to
            self._held = None
            return "OK,O"
        if self.ended.done() or self.fault is not None:
            return "ERR,STATE,the run has ended"
        if line.startswith("T,T,V"):
            self.steps += 1
            if self._unanswered is not None:
                self.responses_s.append(time.perf_counter() - self._unanswered)
                self._unanswered = None
        if line.startswith("T,T,V") and self.armed and self._zero(line) and self.distance_m() <= self.tolerance_m:
            # arrived and told to stand: the run is over; the stop goes instead of the T,T,V, as the answer to the
            # pose, so that a lockstep robot stops in the same control step at every time scale
            reply = await self.link.forward("T,T,S", self.ctx.wall(0))
            return "OK,V" if reply.startswith("OK") else reply
        return await self.link.forward(line, self.ctx.wall(0))

    @staticmethod
    def _zero(line: str) -> bool:
        try:
            return all(float(v) == 0.0 for v in line.split(",")[3:5])
        except ValueError:
            return False

    async def from_robot(self) -> Optional[str]:
        """The next ``PO``/``EV`` line for the program; None once the run has ended."""
        line = await self._lines.get()
        if line is not None and line.startswith("PO") and self._unanswered is None:
            self._unanswered = time.perf_counter()
        return line

    async def follow_events(self) -> None:
        """Pass the robot's events to the program until velocity mode ends (``ended``)."""
        while not self.ended.done():
            ev = await self.link.next_event(3600.0)
            if ev is None:
                continue
            self._lines.put_nowait(",".join(("EV", *ev.fields)))
            kind = ev.fields[0] if ev.fields else ""
            if kind == "START" and self.t_start is None:
                self.t_start = ev.time
            elif kind == "FAIL":
                self.t_end = ev.time
                self.ended.set_result(ev.fields)

    def close(self) -> None:
        """No more lines for the program: its sandbox ends."""
        self._lines.put_nowait(None)


async def drive_program(ctx: RunContext, svc: RunServices, link: AgentLink, job: RunJob, plan: Plan) -> None:
    """Run the job's controller program against the robot (see the module docstring); returns when the run
    completed, else raises :class:`RunFailed`."""
    if svc.sandbox is None or not svc.settings.uploads_enabled:
        raise RunFailed("program could not start: uploads are disabled on this testbed", FailureKind.PROGRAM)
    spec: Optional[ProgramSpec] = await svc.paths.program_spec(job.controller_program)
    if spec is None:
        raise RunFailed("the experiment's controller program no longer exists", FailureKind.PROGRAM)
    rec, robot_id = svc.recorder, ctx.robot.robot_id
    for k in ctx.subfields:
        await svc.field.set_subfield(k, state=SubfieldState.RUNNING, run_id=ctx.run_id, owner_id=job.owner_id)
    svc.tracker.open(robot_id, ctx.run_id, job.owner_id)
    await rec.add_messages(ctx.take_messages())
    line_log = link.on_line  # the relay logs its lines itself while the program drives
    relay = ControllerRelay(link, ctx, (job.goal[0], job.goal[1]), DEFAULT_GOAL_TOLERANCE,
                            seed=lambda: svc.hooks.seed_next_path(robot_id, job.seed), clock=svc.settings.clock)
    s = svc.settings
    program = asyncio.create_task(svc.sandbox.run_controller(
        spec, relay, env_data=job.environment_data, start=start_pose(job), goal=list(job.goal), path=plan.path,
        field_size=SUBFIELD_SIZE if job.field == "sub" else FIELD_SIZE, seed=job.seed,
        robot_radius=job.robot_radius, planning_margin=s.planning_margin_m, robot_id=robot_id,
        platform=ctx.robot.platform or "BeBot"), name=f"twb-controller-{ctx.run_id}")
    events = asyncio.create_task(relay.follow_events(), name=f"twb-controller-events-{ctx.run_id}")
    try:
        await asyncio.wait({program, relay.ended}, return_when=asyncio.FIRST_COMPLETED)
        program_first = not relay.ended.done()
        if program_first and relay.armed:  # the program ended first: stop the robot
            await link.request("T,T,S", ctx.wall(0))
            await asyncio.wait({relay.ended}, timeout=ctx.wall(5))
        relay.close()
        outcome = await program
    finally:
        relay.close()
        events.cancel()
        program.cancel()
        link.on_pose = None
        link.on_line = line_log
    for direction, line in outcome.log:
        ctx.on_line(direction, line, None, False)
    ctx.end_metrics.update(program_metrics(relay.steps, relay.responses_s, outcome.info))
    t_end = relay.t_end if relay.t_end is not None else link.now()
    await rec.update(ctx.run_id, t_start=relay.t_start, t_end=t_end)
    await collect_poses(svc, robot_id, t_end or 0.0)
    _verdict(relay, outcome.reason if program_first else None)


def program_metrics(steps: int, responses_s: list[float], info: dict[str, Any]) -> dict[str, Any]:
    """A controller program's compute cost (docs/metrics.md): ``controller_steps`` (its ``T,T,V`` lines),
    ``controller_cpu_s`` (its CPU time, s), ``controller_cpu_per_step_ms`` (that per step, ms) and the wall
    time from a ``PO`` line handed to it to its next ``T,T,V`` (ms, median and 95th percentile; the sandbox's
    relay included), plus ``controller_program``: the sandbox's report (exit, wall and CPU s, memory KiB)."""
    cpu = info.get("cpu_s")
    r = np.asarray(responses_s, dtype=float) * 1000.0
    report = {k: info.get(k) for k in ("id", "name", "exit_code", "signal", "timed_out", "wall_s", "cpu_s",
                                       "max_rss_kib", "memory_peak_kib", "processes_max")}
    return {
        "controller_steps": int(steps), "controller_cpu_s": cpu,
        "controller_cpu_per_step_ms": None if cpu is None or steps == 0 else round(1000.0 * cpu / steps, 4),
        "controller_response_ms_median": round(float(np.median(r)), 4) if len(r) else None,
        "controller_response_ms_p95": round(float(np.percentile(r, 95)), 4) if len(r) else None,
        "controller_program": report,
    }


def _verdict(relay: ControllerRelay, program_reason: Optional[str]) -> None:
    """Raise why the run failed, if it did: the robot's ending first, then the program's (``program_reason``:
    None when the run had ended before the program), then where it stopped."""
    if relay.fault is not None:  # the program flooded its robot port: whatever the robot did after is its doing
        raise RunFailed(relay.fault, FailureKind.PROGRAM)
    fields = relay.ended.result() if relay.ended.done() else ()
    reason = fields[1] if len(fields) > 1 else ""
    if reason == "WATCHDOG":
        raise RunFailed("watchdog: the controller program sent no T,T,V for 0.5 s of experiment time "
                        "(the robot stopped)", FailureKind.PROGRAM)
    if reason and reason != "STOPPED":
        raise failure_of(*fail_fields(fields))
    if program_reason is not None:
        raise RunFailed(program_reason, FailureKind.PROGRAM)
    if not relay.armed:
        raise RunFailed("program ended without connecting to the robot port", FailureKind.PROGRAM)
    d = relay.distance_m()
    if d > relay.tolerance_m:
        raise RunFailed(f"program stopped the robot {d:.3f} m from the goal (tolerance {relay.tolerance_m} m)",
                        FailureKind.PROGRAM)
