"""The running testbed: store, scheduler loop, run tasks, tracker routing, live events.

One :class:`Testbed` lives in the FastAPI lifespan and is reached through a
dependency (``request.app.state.testbed``).  The scheduler's state is only
touched on the event loop; request handlers running in worker threads hand
work over with ``call_soon_threadsafe``.  Database work from the loop runs in
threads; planning and metrics in worker processes.
"""

from __future__ import annotations

import asyncio
import logging
import math
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Awaitable, Callable, Optional

from sqlalchemy import delete, select

from robot_agent.frames import SUBFIELD_SIZE

from . import planning
from .bootstrap import bootstrap_store
from .broker import EventBroker
from .core.db import make_engine, make_session_factory, migrate
from .core.security import AuthCache, Principal
from .core.settings import Settings
from .jobs import finish_if_done, public_dict, run_public
from .models import Experiment, Pose, Robot, Run, Subfield, User, utcnow
from .runner import RunContext, RunFailed, execute_run, plan_experiment
from .sandbox import Sandbox
from .scheduler import SUBFIELD_ORIGINS, Pending, RobotSlot, Scheduler
from .schemas import TERMINAL_STATES, RobotPublic, RobotRegister, SubfieldPublic
from .tracking import PoseRouter

__all__ = ["Testbed"]

log = logging.getLogger("twb.server")


class Testbed:
    """Everything the server runs besides HTTP handling."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        if settings.uploads_enabled:  # uploaded programs must not read the database or the token file
            settings.data_dir.chmod(0o700)
        #: runs uploaded planner programs (docs/uploads.md)
        self.sandbox = Sandbox(settings)
        self.engine = make_engine(settings.database_url)
        self.sessions = make_session_factory(self.engine)
        self.broker = EventBroker()
        self.scheduler = Scheduler()
        self.router = PoseRouter(self.sessions, self.broker, self._origin_of)
        self.auth = AuthCache(self._principal)
        self.admin_token = ""
        self.stopping = False
        #: environment key built by each robot's gripper (None: nothing)
        self.built: dict[str, Optional[str]] = {}
        #: hooks of agents embedded in this process: robot_id -> fn(seed) seeding its next path
        self.seed_hooks: dict[str, Callable[[int], None]] = {}
        #: hooks of embedded agents: robot_id -> coroutine function delivering pending tracker poses now
        self.flush_hooks: dict[str, Callable[[], Awaitable[None]]] = {}
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._wake = asyncio.Event()
        self._tasks: dict[int, asyncio.Task] = {}
        self._loop_task: Optional[asyncio.Task] = None
        self._probe_task: Optional[asyncio.Task] = None
        self._pool: Optional[ProcessPoolExecutor] = None
        self._plan_locks: dict[int, asyncio.Lock] = {}
        self._plan_failures: dict[int, str] = {}  # experiment id -> why planning failed
        self._estimates: dict[int, float] = {}
        #: serialized views of finished experiments (they no longer change): id -> (owner id, JSON)
        self.finished_views: dict[int, tuple[int, bytes]] = {}
        self._expected: dict[int, float] = {}

    # ------------------------------------------------------------------ life cycle

    def prepare(self) -> str:
        """Migrate and bootstrap the store (blocking); returns the admin token."""
        migrate(self.engine)
        self.admin_token = bootstrap_store(self.settings, self.sessions)
        return self.admin_token

    def _principal(self, token_hash: str) -> Optional[Principal]:
        from .models import Token

        with self.sessions() as s:
            row = s.execute(select(Token.kind, User.id, User.name, User.is_admin).join(User)
                            .where(Token.token_hash == token_hash)).first()
        return None if row is None else Principal(id=row[1], name=row[2], is_admin=row[3], kind=row[0])

    def issue_agent_token(self) -> str:
        """A fresh agent token (tracker ingestion, registration) for agents started with the server."""
        from .core.security import hash_token, new_token
        from .models import Token

        token = new_token()
        with self.sessions.begin() as s:
            admin = s.scalar(select(User).where(User.name == "admin"))
            s.add(Token(user_id=admin.id, token_hash=hash_token(token), kind="agent", label="embedded agents"))
        return token

    async def start(self) -> None:
        """Start the scheduler (after :meth:`prepare`)."""
        self._loop = asyncio.get_running_loop()
        self.broker.bind(self._loop)
        self._wake = asyncio.Event()
        # spawn, not fork: this process has threads and an event loop; workers
        # ignore SIGINT so that Ctrl-C in a terminal reaches only the server
        self._pool = ProcessPoolExecutor(max_workers=self.settings.planning_workers,
                                         mp_context=multiprocessing.get_context("spawn"),
                                         initializer=planning.worker_init)
        for _ in range(self.settings.planning_workers):
            self._pool.submit(planning.warm_up)
        await asyncio.to_thread(self._load_state)
        self._loop_task = asyncio.create_task(self._schedule_loop(), name="twb-scheduler")
        self._probe_task = asyncio.create_task(self._probe_loop(), name="twb-robot-probe")
        self.wake()

    async def stop(self) -> None:
        """Stop scheduling; runs in progress end ``interrupted``; queued runs stay queued."""
        self.stopping = True
        for t in (self._loop_task, self._probe_task):
            if t:
                t.cancel()
        tasks = list(self._tasks.values())
        for t in tasks:
            t.cancel()
        if tasks:
            await asyncio.wait(tasks, timeout=10)
        if self._pool:
            self._pool.shutdown(wait=False, cancel_futures=True)
        self.engine.dispose()

    def _load_state(self) -> None:
        with self.sessions() as s:
            for r in s.scalars(select(Robot)).all():
                # known from an earlier start: offline until it registers again or answers a probe
                self.scheduler.robots[r.robot_id] = RobotSlot(
                    r.robot_id, r.host, r.port, r.backend, r.profile, r.platform,
                    tuple(r.origin), tuple(r.area), healthy=False)
            rows = s.execute(select(Run, Experiment).join(Experiment).where(Run.status == "queued")
                             .order_by(Run.id)).all()
            for run, exp in rows:
                self.scheduler.add(self._pending(run, exp))

    def _pending(self, run: Run, exp: Experiment, exclude: frozenset[str] = frozenset()) -> Pending:
        n_blocks = len(exp.environment_data.get("blocks", []))
        length = math.dist(exp.start[:2], exp.goal[:2]) * 1.4
        if exp.planned_path:
            length = sum(math.dist(a[:2], b[:2]) for a, b in zip(exp.planned_path[:-1], exp.planned_path[1:]))
        expected = planning.expected_duration_s(length, n_blocks)
        self._expected[run.id] = expected
        return Pending(run.id, exp.id, run.mode, exp.field, exp.environment, expected, exclude)

    # ------------------------------------------------------------------ scheduling

    def wake(self) -> None:
        """Ask the scheduler to look at the queue (thread-safe)."""
        loop = self._loop
        if loop is None:
            return
        if _on_loop(loop):
            self._wake.set()
        else:
            loop.call_soon_threadsafe(self._wake.set)

    async def _schedule_loop(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            try:
                for a in self.scheduler.assign():
                    task = asyncio.create_task(execute_run(self, a), name=f"twb-run-{a.run_id}")
                    self._tasks[a.run_id] = task
                    task.add_done_callback(lambda _t, rid=a.run_id: self._tasks.pop(rid, None))
                self._refresh_estimates()
            except Exception:  # noqa: BLE001 - the scheduler must survive any single bad state
                log.exception("scheduler step failed")

    async def _probe_loop(self, interval_s: float = 3.0) -> None:
        """Robots marked offline (a failed run, or known from an earlier start) are tried again."""
        while True:
            await asyncio.sleep(interval_s)
            for r in [r for r in self.scheduler.robots.values() if not r.healthy and r.run_id is None]:
                if await _answers(r.host, r.port):
                    log.info("robot %s answers again", r.robot_id)
                    r.healthy = True
                    self.built.pop(r.robot_id, None)
                    self.broker.publish({"type": "robot", "robot_id": r.robot_id})
                    self.wake()

    def _refresh_estimates(self) -> None:
        remaining = {rid: self._expected.get(rid, 60.0) / 2 for rid in self._tasks}
        starts = self.scheduler.estimate_starts(remaining)
        scale = self.settings.time_scale
        per_exp: dict[int, float] = {}
        for p in self.scheduler.queue:
            if p.run_id in starts:
                wall = 0.0 if math.isinf(scale) else starts[p.run_id] / scale
                per_exp[p.experiment_id] = min(per_exp.get(p.experiment_id, math.inf), wall)
        self._estimates = per_exp

    def estimate_start(self, experiment_id: int) -> Optional[float]:
        """Estimated wall seconds until the experiment's next run starts (queued ones only)."""
        v = self._estimates.get(experiment_id)
        return None if v is None or math.isinf(v) else round(v, 1)

    def submitted(self, experiment_id: int) -> None:
        """A new experiment was committed: queue its runs (thread-safe)."""
        with self.sessions() as s:
            exp = s.get(Experiment, experiment_id)
            pend = [self._pending(r, exp) for r in exp.runs if r.status == "queued"]
            owner = exp.owner_id
            payload = public_dict(exp, s.get(User, owner).name)

        def add() -> None:
            for p in pend:
                self.scheduler.add(p)
            self._refresh_estimates()
            self._wake.set()

        self._call_on_loop(add)
        self.broker.publish({"type": "experiment", "owner_id": owner, "experiment": _brief(payload)})

    def _call_on_loop(self, fn: Callable[[], None]) -> None:
        loop = self._loop
        if loop is None:
            return
        if _on_loop(loop):
            fn()
        else:
            loop.call_soon_threadsafe(fn)

    async def cancel(self, experiment_id: int) -> None:
        """Cancel an experiment's queued runs and stop its running ones."""

        def queued_ids() -> list[int]:
            with self.sessions() as s:
                return list(s.scalars(select(Run.id).where(Run.experiment_id == experiment_id,
                                                           Run.status == "queued")))

        for rid in await asyncio.to_thread(queued_ids):
            if self.scheduler.drop(rid):
                await self.update_run(rid, status="cancelled", error="cancelled by its owner", finished_at=utcnow())
        running = [t for rid, t in self._tasks.items() if self._run_experiment.get(rid) == experiment_id]
        for t in running:
            t.cancel()
        if running:
            await asyncio.wait(running, timeout=10)
        self._refresh_estimates()

    @property
    def _run_experiment(self) -> dict[int, int]:
        with self.sessions() as s:
            ids = list(self._tasks)
            return dict(s.execute(select(Run.id, Run.experiment_id).where(Run.id.in_(ids))).all()) if ids else {}

    async def retry_run(self, run_id: int, robot_id: str, error: str) -> bool:
        """Requeue a run that hit a testbed fault, once, avoiding ``robot_id``. True if requeued."""

        def requeue() -> Optional[Pending]:
            with self.sessions.begin() as s:
                run = s.get(Run, run_id)
                if run.attempt >= 2:
                    return None
                run.attempt += 1
                run.status = "queued"
                run.error = f"attempt 1: {error}"
                run.robot_id = None
                run.subfield = None
                run.t_start = run.t_end = None
                s.execute(delete(Pose).where(Pose.run_id == run_id))
                return self._pending(run, run.experiment, frozenset({robot_id}))

        p = await asyncio.to_thread(requeue)
        if p is None:
            return False
        log.warning("run %d: %s; retrying on another robot", run_id, error)
        self.scheduler.add(p)
        await self.update_run(run_id)  # publish the queued state
        return True

    # ------------------------------------------------------------------ runs

    async def load_run(self, run_id: int) -> tuple[dict[str, Any], dict[str, Any]]:
        def load() -> tuple[dict[str, Any], dict[str, Any]]:
            with self.sessions() as s:
                run = s.get(Run, run_id)
                e = run.experiment
                exp = {k: getattr(e, k) for k in ("id", "owner_id", "environment", "environment_data", "start",
                                                  "goal", "field", "robot_radius", "planning_time_s")}
                return {"id": run.id, "seed": run.seed, "mode": run.mode}, exp

        return await asyncio.to_thread(load)

    async def update_run(self, run_id: int, **fields: Any) -> None:
        """Write run fields, roll the experiment's status up, publish both."""

        def write() -> tuple[dict[str, Any], Optional[dict[str, Any]], int]:
            with self.sessions.begin() as s:
                run = s.get(Run, run_id)
                for k, v in fields.items():
                    setattr(run, k, v)
                exp = run.experiment
                changed = finish_if_done(exp)
                owner = s.get(User, exp.owner_id)
                exp_view = public_dict(exp, owner.name) if changed or exp.status in TERMINAL_STATES else None
                return run_public(run).model_dump(mode="json"), exp_view, exp.owner_id

        run_view, exp_view, owner_id = await asyncio.to_thread(write)
        self.finished_views.pop(run_view["experiment_id"], None)
        self.broker.publish({"type": "run", "owner_id": owner_id, "run": run_view})
        if exp_view is not None:
            self.broker.publish({"type": "experiment", "owner_id": owner_id, "experiment": _brief(exp_view)})
            if exp_view["status"] in TERMINAL_STATES:
                self._estimates.pop(exp_view["id"], None)

    async def planned_path(self, experiment_id: int, ctx: Optional[RunContext] = None) -> list[list[float]]:
        """The experiment's path, planned once even when several runs ask at the same time.

        A planning failure fails the whole experiment: its queued runs end
        ``failed`` with the same reason, and a run already past its queue
        (another mode running in parallel) gets that reason too instead of
        planning — or running an uploaded program — a second time.
        """
        lock = self._plan_locks.setdefault(experiment_id, asyncio.Lock())
        async with lock:
            if experiment_id in self._plan_failures:
                raise RunFailed(self._plan_failures[experiment_id])
            try:
                return await plan_experiment(self, experiment_id, ctx)
            except RunFailed as exc:
                self._plan_failures[experiment_id] = str(exc)
                await self._fail_queued(experiment_id, str(exc))
                raise

    async def _fail_queued(self, experiment_id: int, reason: str) -> None:
        def ids() -> list[int]:
            with self.sessions.begin() as s:
                e = s.get(Experiment, experiment_id)
                e.error = reason
                return [r.id for r in e.runs if r.status == "queued"]

        for rid in await asyncio.to_thread(ids):
            if self.scheduler.drop(rid):
                await self.update_run(rid, status="failed", error=reason, finished_at=utcnow())

    async def in_pool(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Run CPU work in the worker processes."""
        return await asyncio.get_running_loop().run_in_executor(self._pool, fn, *args)

    async def collect_poses(self, robot_id: str, t_end: float) -> None:
        """Make sure the tracker poses up to ``t_end`` are stored before the window closes.

        Agents embedded in this process are flushed directly; remote ones are
        waited for, up to ``tracker_grace_s`` plus a second.
        """
        hook = self.flush_hooks.get(robot_id)
        if hook is not None:
            await hook()
            return
        await self.router.wait_for_time(robot_id, t_end, self.settings.tracker_grace_s + 1.0)

    def seed_next_path(self, robot_id: str, seed: int) -> None:
        """Seed the robot's next path when its agent runs in this process (exact replay)."""
        hook = self.seed_hooks.get(robot_id)
        if hook is not None:
            hook(seed)

    # ------------------------------------------------------------------ field state

    def set_subfield(self, k: int, **fields: Any) -> None:
        slot = self.scheduler.subfields[k]
        for key, v in fields.items():
            setattr(slot, key, v)

        def write() -> None:
            with self.sessions.begin() as s:
                row = s.get(Subfield, k)
                row.state, row.environment, row.run_id = slot.state, slot.environment, slot.run_id
                robot = self.scheduler.field_robot(k)
                row.robot_id = robot.robot_id if robot else None
                row.updated_at = utcnow()

        self._call_on_loop(lambda: asyncio.ensure_future(asyncio.to_thread(write)))
        self.broker.publish({"type": "subfield", "subfield": self.subfield_view(k).model_dump(mode="json")})

    def subfield_view(self, k: int) -> SubfieldPublic:
        slot = self.scheduler.subfields[k]
        robot = self.scheduler.field_robot(k)
        state = slot.state if slot.run_id is not None or slot.state == "building" else "idle"
        if robot is None:
            state = "offline"
        return SubfieldPublic(id=k, state=state, environment=slot.environment,
                              robot_id=robot.robot_id if robot else None, run_id=slot.run_id,
                              origin=list(SUBFIELD_ORIGINS[k]), size=list(SUBFIELD_SIZE))

    def subfields(self) -> list[SubfieldPublic]:
        return [self.subfield_view(k) for k in sorted(self.scheduler.subfields)]

    def robots(self) -> list[RobotPublic]:
        return [self._robot_view(r) for r in sorted(self.scheduler.robots.values(), key=lambda r: (r.pool, r.robot_id))]

    def register_robot(self, body: RobotRegister) -> RobotPublic:
        """Add or refresh a robot (blocking DB write; call from a worker thread)."""
        with self.sessions.begin() as s:
            row = s.scalar(select(Robot).where(Robot.robot_id == body.robot_id))
            if row is None:
                row = Robot(robot_id=body.robot_id)
                s.add(row)
            for k in ("host", "port", "platform", "backend", "profile", "origin", "area"):
                setattr(row, k, getattr(body, k))
            row.status = "idle"
            row.last_seen = utcnow()
        slot = RobotSlot(body.robot_id, body.host, body.port, body.backend, body.profile, body.platform,
                         (float(body.origin[0]), float(body.origin[1])), (float(body.area[0]), float(body.area[1])))

        def install() -> None:
            old = self.scheduler.robots.get(body.robot_id)
            if old is not None:
                slot.run_id = old.run_id
            self.scheduler.robots[body.robot_id] = slot
            self.built.pop(body.robot_id, None)  # a (re)started agent has an empty world
            self._wake.set()

        self._call_on_loop(install)
        self.broker.publish({"type": "robot", "robot_id": body.robot_id})
        return self._robot_view(slot)

    def _robot_view(self, slot: RobotSlot) -> RobotPublic:
        status = "offline" if not slot.healthy else ("busy" if slot.run_id is not None else "idle")
        return RobotPublic(robot_id=slot.robot_id, host=slot.host, port=slot.port, platform=slot.platform,
                           backend=slot.backend, profile=slot.profile, origin=list(slot.origin),
                           area=list(slot.area), subfield=slot.subfield, pool=slot.pool, status=status,
                           last_seen=utcnow(), last_pose=self.router.last_pose(slot.robot_id))

    def _origin_of(self, robot_id: str) -> tuple[float, float]:
        r = self.scheduler.robots.get(robot_id)
        return r.origin if r else (0.0, 0.0)

    def summary(self) -> dict[str, Any]:
        robots = self.scheduler.robots.values()
        return {
            "queued_runs": len(self.scheduler.queue),
            "running_runs": len(self._tasks),
            "field_robots": sum(1 for r in robots if r.pool == "field"),
            "sim_robots": sum(1 for r in robots if r.pool == "sim"),
            "time_scale": None if math.isinf(self.settings.time_scale) else self.settings.time_scale,
        }


async def _answers(host: str, port: int, timeout_s: float = 2.0) -> bool:
    """Whether a robot agent greets on host:port."""
    try:
        reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout_s)
    except (OSError, asyncio.TimeoutError):
        return False
    try:
        line = await asyncio.wait_for(reader.readline(), timeout_s)
        return line.startswith(b"HELLO,")
    except (OSError, asyncio.TimeoutError):
        return False
    finally:
        writer.close()


def _on_loop(loop: asyncio.AbstractEventLoop) -> bool:
    try:
        return asyncio.get_running_loop() is loop
    except RuntimeError:
        return False


def _brief(view: dict[str, Any]) -> dict[str, Any]:
    """An experiment event without the bulky path and runs."""
    return {k: v for k, v in view.items() if k not in ("planned_path", "runs")}
