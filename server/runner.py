"""The run pipeline: one run from its assignment to ``completed`` (or why not).

States (DESIGN §7): ``building`` (the gripper builds the environment unless
the sub-field already has it) -> ``placing`` (the gripper puts the robot at
the start) -> ``planning`` (once per experiment, in a worker process) ->
``running`` (the ``T,T,P`` line is sent, events followed, tracker poses
stored) -> ``analyzing`` (metrics, in a worker process) -> ``completed``.

Whose fault: ``failed`` is the job's (no path, collision, stall, timeout);
``error`` is the testbed's (agent unreachable, died, or refused a line the
pre-flight accepted) and is retried once on another robot; ``interrupted``
is a server stop; ``cancelled`` the owner's wish.  Every protocol line is
logged with experiment time.
"""

from __future__ import annotations

import asyncio
import logging
import math
from typing import TYPE_CHECKING, Any, Optional

from sqlalchemy import insert, select

from robot_agent.protocol import encode_build, encode_path, encode_place

from . import planning
from .agent_link import AgentLink, AgentRefused, AgentUnavailable
from .jobs import finish_if_done
from .models import Experiment, Message, Pose, Run, utcnow

if TYPE_CHECKING:
    from .scheduler import Assignment
    from .testbed import Testbed

__all__ = ["RunFailed", "execute_run"]

log = logging.getLogger("twb.runner")

# park positions (robot frame) of sub-field robots 2-4 during full-field runs: their outer corners
PARK = {2: (1.7, 0.1, 0.0), 3: (0.1, 1.7, 0.0), 4: (1.7, 1.7, 0.0)}


class RunFailed(Exception):
    """The job's own fault: the run ends ``failed`` with this reason."""


class _Cut(Exception):
    """The run ended for a testbed reason: status (error, interrupted) and message."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


class RunContext:
    """Everything one execution needs, and its protocol log."""

    def __init__(self, testbed: "Testbed", assignment: "Assignment") -> None:
        self.tb = testbed
        self.a = assignment
        self.run_id = assignment.run_id
        self.robot = testbed.scheduler.robots[assignment.robot_id]
        self.messages: list[dict[str, Any]] = []

    def on_line(self, direction: str, line: str, t: Optional[float], estimated: bool) -> None:
        self.messages.append({"run_id": self.run_id, "t": t, "t_estimated": estimated, "direction": direction,
                              "line": line[:10_000]})

    async def flush_messages(self) -> None:
        batch, self.messages = self.messages, []
        if batch:
            def write() -> None:
                with self.tb.sessions.begin() as s:
                    s.execute(insert(Message), batch)

            await asyncio.to_thread(write)

    def wall(self, experiment_s: float, slack_s: float = 10.0) -> float:
        """Wall seconds for ``experiment_s`` of experiment time, plus slack."""
        scale = self.tb.settings.time_scale
        return (0.0 if math.isinf(scale) else experiment_s / scale) + slack_s


async def execute_run(testbed: "Testbed", assignment: "Assignment") -> None:
    """Carry out one assigned run; never raises (every outcome is stored)."""
    ctx = RunContext(testbed, assignment)
    status, error = "completed", ""
    try:
        await _pipeline(ctx)
    except RunFailed as exc:
        status, error = "failed", str(exc)
    except _Cut as exc:
        status, error = exc.status, str(exc)
    except (AgentUnavailable, OSError) as exc:
        status, error = "error", f"robot {ctx.robot.robot_id}: {exc}"
    except AgentRefused as exc:
        status, error = "error", f"robot {ctx.robot.robot_id} refused a command: {exc}"
    except asyncio.CancelledError:
        status = "interrupted" if testbed.stopping else "cancelled"
        error = "the server stopped during this run" if testbed.stopping else "cancelled by its owner"
    except Exception as exc:  # noqa: BLE001 - a bug must end the run as an error, not kill the testbed
        log.exception("run %d crashed", ctx.run_id)
        status, error = "error", f"internal error: {type(exc).__name__}: {exc}"
    finally:
        testbed.router.close(ctx.robot.robot_id)
    try:
        await asyncio.shield(_finish(ctx, status, error))
    except asyncio.CancelledError:
        pass


async def _finish(ctx: RunContext, status: str, error: str) -> None:
    tb = ctx.tb
    await ctx.flush_messages()
    retry = False
    if status == "error":
        ctx.robot.healthy = False
        retry = await tb.retry_run(ctx.run_id, ctx.robot.robot_id, error)
    if not retry:
        # a completed second attempt keeps the note about the first one
        extra = {"error": error} if error else {}
        await tb.update_run(ctx.run_id, status=status, finished_at=utcnow(), **extra)
    tb.scheduler.release(ctx.run_id)
    for k in ctx.a.subfields:  # tell the dashboards the sub-field is free again
        tb.set_subfield(k, state="idle", run_id=None)
    tb.wake()


async def _pipeline(ctx: RunContext) -> None:
    tb = ctx.tb
    run, exp = await tb.load_run(ctx.run_id)
    env = exp["environment_data"]
    await tb.update_run(ctx.run_id, status="building", robot_id=ctx.robot.robot_id,
                        subfield=ctx.a.subfields[0] if len(ctx.a.subfields) == 1 else None,
                        started_at=utcnow())
    link = await AgentLink.connect(ctx.robot.host, ctx.robot.port, time_scale=tb.settings.time_scale,
                                   on_line=ctx.on_line)
    try:
        await link.request("T,T,Q", ctx.wall(0))  # anchors the agent's clock
        await _build(ctx, link, exp, env)
        await tb.update_run(ctx.run_id, status="placing")
        start = exp["start"]
        if len(start) < 3:
            start = [*start[:2], math.atan2(exp["goal"][1] - start[1], exp["goal"][0] - start[0])]
        try:
            await link.request(encode_place(start), ctx.wall(30))
        except AgentRefused as exc:
            raise _Cut("error", f"the gripper could not place the robot at the start: {exc.message}") from None
        await tb.update_run(ctx.run_id, status="planning")
        path = await tb.planned_path(exp["id"], ctx)
        await tb.update_run(ctx.run_id, status="running")
        try:
            await _drive(ctx, link, run, exp, path)
        except RunFailed as exc:
            failure: Optional[RunFailed] = exc
        else:
            failure = None
    finally:
        await link.close()
        await ctx.flush_messages()
    await tb.update_run(ctx.run_id, status="analyzing")
    # a run that failed on the field (collision, stall, timeout) is measured too: what it drove
    # until then is data; its `collided` is the robot's own verdict, as for completed runs
    try:
        await _analyze(ctx, exp, path, collided=failure is not None and str(failure).startswith("collision"))
    except _Cut:
        if failure is None:
            raise
    if failure is not None:
        raise failure


async def _build(ctx: RunContext, link: AgentLink, exp: dict[str, Any], env: dict[str, Any]) -> None:
    """Have the gripper build the environment, unless this sub-field / robot already has it."""
    tb = ctx.tb
    key = exp["environment"] + (":full" if exp["field"] == "full" else "")
    if len(ctx.a.subfields) == 4:  # full field: clear the other sub-fields, park their robots
        for k in (2, 3, 4):
            other = tb.scheduler.field_robot(k)
            if other is None:
                continue
            async with await AgentLink.connect(other.host, other.port, time_scale=tb.settings.time_scale,
                                               on_line=ctx.on_line) as olink:
                if tb.built.get(other.robot_id) is not None:
                    await olink.request("T,T,B", ctx.wall(60 * 10))
                    tb.built[other.robot_id] = None
                    tb.set_subfield(k, environment=None)
                try:
                    await olink.request(encode_place(PARK[k]), ctx.wall(30))
                except AgentRefused:
                    pass  # it may already stand there
    if tb.built.get(ctx.robot.robot_id) == key:
        return
    blocks = [(b["x"], b["y"], b["w"], b["h"], b.get("angle", 0.0)) for b in env.get("blocks", [])]
    for k in ctx.a.subfields:
        tb.set_subfield(k, state="building")
    await link.request(encode_build(blocks), ctx.wall(60 * (len(blocks) + 10)))
    tb.built[ctx.robot.robot_id] = key
    for k in ctx.a.subfields:
        tb.set_subfield(k, environment=exp["environment"] if len(ctx.a.subfields) == 1 else f"{exp['environment']} (full)")


async def _drive(ctx: RunContext, link: AgentLink, run: dict[str, Any], exp: dict[str, Any],
                 path: list[list[float]]) -> None:
    """Send the path, follow the events until DONE/FAIL or the timeout."""
    tb = ctx.tb
    for k in ctx.a.subfields:
        tb.set_subfield(k, state="running", run_id=ctx.run_id)
    length = sum(math.dist(a[:2], b[:2]) for a, b in zip(path[:-1], path[1:]))
    timeout_exp = max(tb.settings.run_timeout_min_s,
                      tb.settings.run_timeout_factor * planning.expected_duration_s(length, 0))
    tb.seed_next_path(ctx.robot.robot_id, run["seed"])
    tb.router.open(ctx.robot.robot_id, ctx.run_id, exp["owner_id"])
    await link.request(encode_path(path), ctx.wall(0))
    deadline = asyncio.get_running_loop().time() + ctx.wall(timeout_exp)
    t_start: Optional[float] = None
    while True:
        left = deadline - asyncio.get_running_loop().time()
        ev = await link.next_event(max(left, 0.0)) if left > 0 else None
        if ev is None:
            try:
                await link.request("T,T,S", ctx.wall(0))
            finally:
                await tb.update_run(ctx.run_id, t_start=t_start, t_end=link.now())
            raise RunFailed(f"timeout: the robot did not finish within {timeout_exp:.0f} s of experiment time")
        kind = ev.fields[0] if ev.fields else ""
        if kind == "START":
            t_start = ev.time
            await tb.update_run(ctx.run_id, t_start=t_start)
        elif kind == "DONE":
            await tb.update_run(ctx.run_id, t_start=t_start, t_end=ev.time)
            await tb.collect_poses(ctx.robot.robot_id, ev.time or 0.0)
            return
        elif kind == "FAIL":
            reason = ev.fields[1] if len(ev.fields) > 1 else "UNKNOWN"
            await tb.update_run(ctx.run_id, t_start=t_start, t_end=ev.time)
            await tb.collect_poses(ctx.robot.robot_id, ev.time or 0.0)
            if reason == "STOPPED":
                raise _Cut("error", "the robot was stopped by someone else during the run")
            raise RunFailed({"COLLISION": "collision: the robot hit an obstacle",
                             "TIMEOUT": "timeout: the robot's controller gave up on the path",
                             "STALLED": "stalled: the robot could not make progress"}.get(reason, reason.lower()))


async def _analyze(ctx: RunContext, exp: dict[str, Any], path: list[list[float]], *, collided: bool) -> None:
    """DESIGN §6 metrics of the run, in a worker process.

    ``collided`` is what the robot itself detected (it stops with
    ``EV,FAIL,COLLISION``); the tracker's view of how close it came is
    ``clearance_min_m``, which can dip below the robot radius by the
    tracker's noise without a contact.
    """
    tb = ctx.tb

    def load() -> tuple[list[list[float]], Optional[float], Optional[float]]:
        with tb.sessions() as s:
            r = s.get(Run, ctx.run_id)
            rows = s.execute(select(Pose.t, Pose.x, Pose.y, Pose.theta).where(Pose.run_id == ctx.run_id)
                             .order_by(Pose.t)).all()
            return [list(x) for x in rows], r.t_start, r.t_end

    poses, t0, t1 = await asyncio.to_thread(load)
    try:
        metrics = await tb.in_pool(planning.measure_run, exp["environment_data"], path, poses, t0, t1,
                                   exp["goal"], exp["robot_radius"], exp["planning_time_s"])
    except ValueError as exc:
        raise _Cut("error", f"cannot compute metrics: {exc}") from None
    metrics["collided"] = collided
    await tb.update_run(ctx.run_id, metrics=metrics)


async def plan_experiment(testbed: "Testbed", experiment_id: int, ctx: Optional[RunContext] = None) -> list[list[float]]:
    """The experiment's path: the explicit one, planned once in a worker process, or sent by the
    experiment's uploaded program run sandboxed (its output goes to the log of ``ctx``'s run); stored.
    """

    def load() -> Experiment:
        with testbed.sessions() as s:
            return s.get(Experiment, experiment_id)

    exp = await asyncio.to_thread(load)
    if exp.planned_path is not None:
        return exp.planned_path
    if exp.explicit_path is not None:
        result = {"path": planning.explicit_path(exp.explicit_path, exp.goal), "planning_time_s": None,
                  "info": {"explicit": True}}
    elif exp.program_id is not None or exp.planner is None:
        from .program_planning import ProgramFailed, plan_with_program

        try:
            result = await plan_with_program(
                testbed, exp, run_id=ctx.run_id if ctx else None, robot_id=ctx.robot.robot_id if ctx else "robot",
                platform=(ctx.robot.platform or "BeBot") if ctx else "BeBot", on_line=ctx.on_line if ctx else None)
        except ProgramFailed as exc:
            info, reason = exc.info, str(exc)

            def store_info() -> None:
                with testbed.sessions.begin() as s:
                    s.get(Experiment, experiment_id).planning_info = info

            await asyncio.to_thread(store_info)
            raise RunFailed(reason) from None
    else:
        from planners import PlanningError

        try:
            result = await testbed.in_pool(planning.plan_job, exp.environment_data, exp.start, exp.goal,
                                           exp.planner, exp.planner_params or {}, exp.seed,
                                           exp.robot_radius + exp.planning_margin)
        except PlanningError as exc:
            raise RunFailed(f"planning failed: {exc}") from None

    def store() -> None:
        with testbed.sessions.begin() as s:
            e = s.get(Experiment, experiment_id)
            e.planned_path = result["path"]
            e.planning_time_s = result["planning_time_s"]
            e.planning_info = result.get("info", {})
            finish_if_done(e)

    await asyncio.to_thread(store)
    return result["path"]
