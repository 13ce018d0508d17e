"""The steps of a run on its robot: connect, build, place, drive, analyze (see :mod:`server.pipeline.runner`)."""

from __future__ import annotations

import asyncio
import math
from typing import Optional

from contract.controller_specs import DEFAULT_CONTROLLER
from contract.protocol import encode_build, encode_controller, encode_moving, encode_path, encode_place
from contract.vocabulary import Mode
from robot_agent.engine import run_data, tasks

from ..agent_link import AgentLink
from ..errors import AgentRefused, AgentUnavailable, AgentUnreachable, FailureKind, RunFailed, TestbedFault
from ..status import SubfieldState
from ..store.runs import RunJob
from .context import RunContext, RunServices
from .paths import Plan

__all__ = ["PARK", "analyze", "build", "collect_poses", "connect", "drive", "fail_fields", "failure_of", "place", "run_timeout_s", "start_pose",
           "timeout_for_length_s"]

#: park positions (robot frame) of sub-field robots 2-4 during full-field runs: their outer corners
PARK = {2: (1.7, 0.1, 0.0), 3: (0.1, 1.7, 0.0), 4: (1.7, 1.7, 0.0)}

#: what the robot's ``EV,FAIL,<reason>`` means for the run
_FAILURES = {
    "COLLISION": (FailureKind.COLLISION, "collision: the robot hit an obstacle"),
    "TIMEOUT": (FailureKind.CONTROLLER_TIMEOUT, "timeout: the robot's controller gave up on the path"),
    "STALLED": (FailureKind.STALLED, "stalled: the robot could not make progress"),
}


def failure_of(reason: str, obstacle: Optional[int] = None) -> RunFailed | TestbedFault:
    """What the robot's ``EV,FAIL,<reason>`` means for the run: the job's failure, or the testbed's fault
    (``STOPPED``: someone else stopped the robot); ``obstacle``: the moving obstacle of a collision
    (``EV,FAIL,COLLISION,OBSTACLE,<k>``), kept on the failure as ``obstacle``."""
    if reason == "STOPPED":
        return TestbedFault("the robot was stopped by someone else during the run")
    fkind, message = _FAILURES.get(reason, (FailureKind.OTHER, reason.lower()))
    if reason == "COLLISION" and obstacle is not None:
        message = f"collision: the robot hit moving obstacle {obstacle} (the environment's moving_obstacles[{obstacle}])"
    failure = RunFailed(message, fkind)
    failure.obstacle = obstacle if reason == "COLLISION" else None
    return failure


def fail_fields(fields: tuple[str, ...]) -> tuple[str, Optional[int]]:
    """The reason and the moving obstacle (or None) of an ``EV,FAIL`` line's fields (time last)."""
    reason = fields[1] if len(fields) > 1 else "UNKNOWN"
    if len(fields) == 5 and fields[2] == "OBSTACLE" and fields[3].isdigit():
        return reason, int(fields[3])
    return reason, None


def run_timeout_s(svc: RunServices, path: list[list[float]]) -> float:
    """Experiment seconds a run along ``path`` may take before it is stopped (``failed``, timeout)."""
    return timeout_for_length_s(svc, sum(math.dist(a[:2], b[:2]) for a, b in zip(path[:-1], path[1:])))


def timeout_for_length_s(svc: RunServices, length_m: float) -> float:
    """Experiment seconds a run driving ``length_m`` (m) may take before it is stopped: the testbed's factor
    times the expected duration, at least its minimum."""
    settings = svc.settings
    return max(settings.run_timeout_min_s, settings.run_timeout_factor * run_data.expected_duration_s(length_m, 0))


def start_pose(job: RunJob) -> list[float]:
    """Where the gripper puts the robot (x, y, theta; m, rad): the start, facing the goal when it has no
    heading (before any jitter)."""
    start = list(job.start)
    if len(start) < 3:
        start = [*start[:2], math.atan2(job.goal[1] - start[1], job.goal[0] - start[0])]
    return start


async def connect(ctx: RunContext, svc: RunServices, robot_id: Optional[str] = None) -> AgentLink:
    """An authenticated protocol connection to the run's robot (or ``robot_id``), logged to the run."""
    rid = robot_id or ctx.robot.robot_id
    r = svc.field.robots[rid]
    try:
        return await AgentLink.connect(r.host, r.port, time_scale=ctx.time_scale, on_line=ctx.on_line,
                                       control_key=svc.field.keys.get(rid))
    except AgentUnreachable as exc:
        if rid == ctx.robot.robot_id:
            raise
        # another robot than the run's (one to park): the run's robot is not the one to avoid
        raise AgentUnavailable(f"robot {rid}: {exc}") from None


async def build(ctx: RunContext, svc: RunServices, link: AgentLink, job: RunJob) -> None:
    """Have the gripper build the environment, unless the robot already has it built.

    A full-field run first clears the other sub-fields and parks their robots
    at their outer corners.
    """
    field = svc.field
    key = job.environment + (":full" if job.field == "full" else "")
    if job.mode == Mode.TWB and job.environment_data.get("moving_obstacles"):
        ctx.on_line("s", await svc.pool.run(tasks.OBSTACLE_NOTE, job.environment_data,
                                            ctx.robot.platform or "BeBot"), None, False)
    if len(ctx.subfields) == 4:
        for k in (2, 3, 4):
            other = field.field_robot(k)
            if other is not None:
                await _park(ctx, svc, other.robot_id, k)
    if field.built.get(ctx.robot.robot_id) == key:
        return
    blocks = run_data.block_tuples(job.environment_data)
    for k in ctx.subfields:
        await field.set_subfield(k, state=SubfieldState.BUILDING)
    await link.request(encode_build(blocks), ctx.wall(60 * (len(blocks) + 10)))
    rid = ctx.robot.robot_id
    if job.environment_data.get("moving_obstacles") or rid in field.moving:  # set them, or clear the last ones
        moving = await svc.pool.run(tasks.MOVING, job.environment_data)
        await link.request(encode_moving(moving), ctx.wall(0))
        if moving:
            field.moving.add(rid)
        else:
            field.moving.discard(rid)
    field.built[ctx.robot.robot_id] = key
    shown = job.environment if len(ctx.subfields) == 1 else f"{job.environment} (full)"
    for k in ctx.subfields:
        await field.set_subfield(k, environment=shown)


async def _park(ctx: RunContext, svc: RunServices, robot_id: str, k: int) -> None:
    """Clear sub-field ``k`` and park its robot in its outer corner (a refusal is the testbed's fault)."""
    field = svc.field
    async with await connect(ctx, svc, robot_id) as other:
        # always cleared, whatever we believe was built: removing nothing costs the gripper nothing
        await other.request("T,T,B", ctx.wall(60 * 10))
        if field.built.get(robot_id) is not None:
            await field.set_subfield(k, environment=None)
        field.built[robot_id] = None
        try:
            await other.request(encode_place(PARK[k]), ctx.wall(30))
        except AgentRefused as exc:
            here = (await other.request("T,T,Q", ctx.wall(0))).fields
            if not (len(here) >= 3 and abs(float(here[1]) - PARK[k][0] * 1000) < 1 and
                    abs(float(here[2]) - PARK[k][1] * 1000) < 1):  # not already standing there
                raise TestbedFault(f"robot {robot_id} could not be parked for a full-field run: {exc.message}") \
                    from None


async def place(ctx: RunContext, link: AgentLink, job: RunJob) -> None:
    """The gripper puts the robot at the start (facing the goal when the start has no heading), moved by the
    job's seeded jitter if it has one (where the jittered pose is not free, at the start itself)."""
    start = start_pose(job)
    pose = run_data.jittered(start, job.jitter, job.seed)
    try:
        await link.request(encode_place(pose), ctx.wall(30))
        return
    except AgentRefused as exc:
        if pose == start:
            raise TestbedFault(f"the gripper could not place the robot at the start: {exc.message}") from None
        ctx.on_line("s", f"the jittered start is not free ({exc.message}); placing at the start itself", None, False)
    try:
        await link.request(encode_place(start), ctx.wall(30))
    except AgentRefused as exc:
        raise TestbedFault(f"the gripper could not place the robot at the start: {exc.message}") from None


async def drive(ctx: RunContext, svc: RunServices, link: AgentLink, job: RunJob, path: list[list[float]]) -> None:
    """Send the path and follow the events until ``DONE`` (returns) or ``FAIL`` / the timeout (:class:`RunFailed`).

    The timeout counts experiment time on the robot's own clock: a testbed
    that falls behind the time scale (a busy machine, a long queue) never
    fails a run that the robot is still driving within its time.
    """
    rec, robot_id = svc.recorder, ctx.robot.robot_id
    for k in ctx.subfields:
        await svc.field.set_subfield(k, state=SubfieldState.RUNNING, run_id=ctx.run_id, owner_id=job.owner_id)
    timeout_exp = run_timeout_s(svc, path)
    ctx.seeded = svc.hooks.seed_next_path(robot_id, job.seed)
    svc.tracker.open(robot_id, ctx.run_id, job.owner_id)
    t_sent = (await link.request("T,T,Q", ctx.wall(0))).time or 0.0  # the robot's clock, not ours
    if job.controller != DEFAULT_CONTROLLER:  # the default needs no line: robots without T,T,C run it
        await link.request(encode_controller(job.controller, job.controller_params), ctx.wall(0))
    await link.request(encode_path(path), ctx.wall(0))
    await rec.add_messages(ctx.take_messages())  # the log up to the path, kept even if the server dies now
    t_start: Optional[float] = None
    replans: list[tuple[int, float]] = []  # (points, planning s) of each EV,REPLAN,<points>,<ms>,<t>
    if run_data.replanning(job.controller_params):
        ctx.end_metrics.update(run_data.replan_metrics(replans))
    loop = asyncio.get_running_loop()
    deadline = loop.time() + ctx.wall(timeout_exp)
    while True:
        left = deadline - loop.time()
        ev = await link.next_event(left) if left > 0 else None
        if ev is None:  # the wall-clock budget is spent: did the robot's own time run out too?
            elapsed = ((await link.request("T,T,Q", ctx.wall(0))).time or 0.0) - t_sent
            if elapsed < timeout_exp:  # the testbed was slower than the time scale, not the robot
                deadline = loop.time() + ctx.wall(timeout_exp - elapsed)
                continue
            try:
                await link.request("T,T,S", ctx.wall(0))
            finally:
                await rec.update(ctx.run_id, t_start=t_start, t_end=link.now())
            raise RunFailed(f"timeout: the robot did not finish within {timeout_exp:.0f} s of experiment time",
                            FailureKind.TIMEOUT)
        if ctx.messages_due():
            await rec.add_messages(ctx.take_messages())
        kind = ev.fields[0] if ev.fields else ""
        if kind == "START":
            t_start = ev.time
            await rec.update(ctx.run_id, t_start=t_start)
        elif kind == "REPLAN" and len(ev.fields) == 4:
            replans.append((int(float(ev.fields[1])), float(ev.fields[2]) / 1000.0))
            ctx.end_metrics.update(run_data.replan_metrics(replans))
        elif kind in ("DONE", "FAIL"):
            await rec.update(ctx.run_id, t_start=t_start, t_end=ev.time)
            await collect_poses(svc, robot_id, ev.time or 0.0)
            if kind == "DONE":
                return
            raise failure_of(*fail_fields(ev.fields))


async def collect_poses(svc: RunServices, robot_id: str, t_end: float) -> None:
    """Make sure the tracker poses up to ``t_end`` are stored before the window closes.

    Robots in this process are flushed directly; remote ones are waited for,
    up to ``tracker_grace_s`` plus a second.
    """
    if not await svc.hooks.flush_tracker(robot_id):
        await svc.tracker.wait_for_time(robot_id, t_end, svc.settings.tracker_grace_s + 1.0)


async def analyze(ctx: RunContext, svc: RunServices, job: RunJob, plan: Plan, *, collided: bool,
                  failed: bool = False, obstacle: Optional[int] = None) -> None:
    """The run's metrics (docs/metrics.md), in a worker process.

    ``collided`` is what the robot itself detected (it stops with
    ``EV,FAIL,COLLISION``); the tracker's view of how close it came is
    ``clearance_min_m``, which can dip below the robot radius by the
    tracker's noise without a contact.  Too few logged poses is the
    testbed's fault (:class:`TestbedFault`).  A ``failed`` run also records
    where it stopped (its last logged pose); ``obstacle`` the moving
    obstacle a collision was with (None: a block, the wall or a robot).
    """
    rec = svc.recorder
    poses, t0, t1 = await rec.driven(ctx.run_id)
    obstacles = None
    if job.mode == Mode.TWB and job.environment_data.get("moving_obstacles") and t0 is not None and t1 is not None:
        if ctx.seeded:  # the obstacle robots' trajectories, replayed as the agent drove them
            obstacles = await svc.pool.run(tasks.FIELD_OBSTACLE_TRACKS, job.environment_data, job.seed,
                                           ctx.robot.platform or "BeBot", t0, t1)
            ctx.end_obstacles = obstacles  # stored with the run's end
        else:
            ctx.on_line("s", "the obstacle metrics measure against the moving obstacles' exact tracks: this robot's "
                             "agent keys its noise itself, so its obstacle robots cannot be replayed here", None,
                        False)
    try:
        metrics = await svc.pool.run(tasks.MEASURE, job.environment_data, plan.path, poses, t0, t1, job.goal,
                                     job.robot_radius, plan.planning_time_s, obstacles)
    except run_data.TooFewPoses as exc:
        raise TestbedFault(f"cannot compute metrics: {exc}") from None
    metrics["collided"] = collided
    metrics.update(run_data.collision_counts(collided, obstacle))
    metrics.update(ctx.end_metrics)
    ctx.end_fields["metrics"] = metrics  # stored with the run's end
    if failed and poses:
        ctx.end_fields["stopped_at"] = [round(poses[-1][1], 4), round(poses[-1][2], 4)]

