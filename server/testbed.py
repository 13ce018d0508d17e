"""The running testbed: builds the server's services, starts them in order and stops them in reverse.

One :class:`Testbed` lives in the FastAPI lifespan (``app.state.testbed``);
API routes reach its services through dependencies (``server.api.deps``).
It holds no logic of its own beyond wiring, start-up and shutdown::

    store (SQLAlchemy) ── broker (live events) ── finished views (response cache)
    field (robots, sub-fields) ── tracker (pose windows) ── locator ── worker pool or Ray ── sandbox
    recorder ── paths ── run services ── dispatcher (queue → runs)
    embedded robots (``twb up`` only)

Shutdown: the dispatcher stops first (runs under way end ``interrupted``,
with their partial poses and messages kept), then the embedded robots,
then the workers and the store.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Optional

from .bootstrap import bootstrap_store
from .broker import EventBroker
from .core.db import make_engine, make_session_factory, migrate, private_sqlite_file
from .core.security import AuthCache, FailedTokens, Principal
from .core.settings import Settings
from .dispatch import Dispatcher, pending_of
from .embedded import EmbeddedField
from .field import FieldState
from .locate import Locator
from .pipeline.paths import PathService
from .pipeline.pool import WorkerPool
from .pipeline.ray_pool import RayPool
from .pipeline.recorder import RunRecorder
from .pipeline.context import NoHooks, RunServices
from .sandbox import Sandbox
from .scheduler import Pending
from .store.runs import queued_runs
from .submission import UserLocks
from .store.users import principal_of
from .tracking import PoseRouter
from .views import FinishedViews

__all__ = ["Testbed"]

log = logging.getLogger("twb.server")


class Testbed:
    """Every service of one testbed server; ``embedded``: robots run in this process (``twb up``)."""

    __test__ = False  # not a test class, whatever pytest thinks of the name

    def __init__(self, settings: Settings, *, embedded: Optional[EmbeddedField] = None) -> None:
        self.settings = settings
        # the database and the token file are for the server alone (and uploaded programs must not read them)
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        settings.data_dir.chmod(0o700)
        private_sqlite_file(settings.database_url)
        self.engine = make_engine(settings.database_url)
        self.sessions = make_session_factory(self.engine)
        self.auth = AuthCache(self._principal)
        self.failed_tokens = FailedTokens(settings.auth_failures_per_minute)
        self.submit_locks = UserLocks()
        self.broker = EventBroker()
        self.views = FinishedViews()
        self.field = FieldState(self.sessions, self.broker)
        self.tracker = PoseRouter(self.sessions, self.broker, self.field.origin_of)
        #: where a field robot stands when it joins, asked of its tracker (not the last session's logs)
        self.locator = Locator(self.tracker.place)
        self.field.on_join = self.locator.locate
        #: planning and metrics, off the loop: worker processes, or Ray tasks (then simulation runs too)
        self.pool: WorkerPool | RayPool = (
            RayPool(address=settings.ray_address, cpus=settings.ray_cpus, slots=settings.ray_slots,
                    log_dir=settings.data_dir) if settings.sim_engine == "ray" else WorkerPool(
                        settings.planning_workers, memory_mb=settings.planning_memory_mb,
                        deadline_s=settings.planning_timeout_s))
        #: runs uploaded planner programs (docs/uploads.md)
        self.sandbox = Sandbox(settings)
        self.recorder = RunRecorder(self.sessions, self.broker, self.views)
        self.embedded = embedded
        #: what each run uses (the pipeline's only view of the testbed)
        self.services = RunServices(
            settings=settings, recorder=self.recorder,
            paths=PathService(self.sessions, self.recorder, self.pool, self.sandbox, settings),
            pool=self.pool, field=self.field, tracker=self.tracker, hooks=embedded or NoHooks(), sandbox=self.sandbox)
        self.dispatcher = Dispatcher(self.services)
        self.admin_token = ""

    def prepare(self) -> str:
        """Migrate and bootstrap the store (blocking); returns the admin token."""
        migrate(self.engine)
        self.admin_token = bootstrap_store(self.settings, self.sessions)
        if isinstance(self.pool, RayPool):
            self.pool.start()  # the cluster is reached (or started) before the server listens: EngineUnavailable
        return self.admin_token

    def _principal(self, token_hash: str) -> Optional[Principal]:
        with self.sessions() as s:
            return principal_of(s, token_hash)

    async def start(self) -> None:
        """Start the services (after :meth:`prepare`): workers, known robots, the queue, embedded robots."""
        self.broker.bind(asyncio.get_running_loop())
        if isinstance(self.pool, RayPool):
            self.field.add_engine_slots(self.pool.engine, self.pool.slots)
        else:
            self.pool.start()
        await self.field.load()
        self.dispatcher.start(await asyncio.to_thread(self._queued))
        if self.embedded is not None:
            await self.embedded.start(self.field, self.tracker)
            self.dispatcher.wake()

    def _queued(self) -> list[Pending]:
        with self.sessions() as s:
            return [pending_of(run, exp) for run, exp in queued_runs(s)]

    async def stop(self) -> None:
        """Stop: runs under way end ``interrupted``; queued runs stay queued for the next start."""
        await self.dispatcher.stop()
        await self.locator.stop()
        if self.embedded is not None:
            await self.embedded.stop()
        await asyncio.to_thread(self.pool.stop)
        self.engine.dispose()
