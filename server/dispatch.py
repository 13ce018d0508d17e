"""The dispatcher: queued runs to robots, each run's end to the store, retries, cancels, estimates.

It owns the queue (a :class:`~server.scheduler.Scheduler` deciding on the
field's robots and sub-fields) and one task per run under way
(:func:`server.pipeline.runner.execute_run`).  When a run ends it writes the
outcome, frees the robot and sub-fields, and looks at the queue again:

- ``error`` (the testbed's fault): the robot goes offline and the run is
  queued again once, avoiding that robot (while the testbed stops, such
  runs end ``interrupted`` instead);
- ``failed`` for the whole experiment (no path): its queued runs fail too.

Offline robots are probed every few seconds.  Everything here runs on the
event loop; database work goes through the recorder's threads.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from dataclasses import replace
from typing import Any, Iterable, Optional

from sqlalchemy.exc import DBAPIError

from contract.vocabulary import Mode
from robot_agent.engine import run_data

from .field import FieldState
from .models import Experiment, Run
from .pipeline.context import RunServices
from .pipeline.runner import RunEnd, execute_run, failure_text, store_end
from .scheduler import Assignment, Pending, Scheduler
from .status import RunStatus, SubfieldState

__all__ = ["Dispatcher", "pending_of"]

log = logging.getLogger("twb.server")


def pending_of(run: Run, exp: Experiment, exclude: frozenset[str] = frozenset()) -> Pending:
    """A queued run as the scheduler sees it, with its expected experiment duration (s)."""
    n_blocks = len(exp.environment_data.get("blocks", []))
    length = math.dist(exp.start[:2], exp.goal[:2]) * 1.4
    if exp.planned_path:
        length = sum(math.dist(a[:2], b[:2]) for a, b in zip(exp.planned_path[:-1], exp.planned_path[1:]))
    return Pending(run.id, exp.id, run.mode, exp.field, exp.environment,
                   run_data.expected_duration_s(length, n_blocks), exclude)


CANCELLED = "cancelled by its owner"
_ESTIMATE_EVERY_S = 0.5


class Dispatcher:
    """Runs queued runs on the field (see the module docstring)."""

    def __init__(self, services: RunServices, *, probe_interval_s: float = 3.0) -> None:
        self._svc = services
        self._field: FieldState = services.field
        self.scheduler = Scheduler(robots=self._field.robots, subfields=self._field.subfields)
        self.stopping = False
        self._probe_interval_s = probe_interval_s
        self._wake = asyncio.Event()
        self._tasks: dict[int, asyncio.Task] = {}
        self._experiment: dict[int, int] = {}  # queued or running run -> its experiment
        self._expected: dict[int, float] = {}  # queued or running run -> expected duration (s), for estimates
        self._estimates: dict[int, float] = {}  # experiment -> wall seconds until its next run starts
        self._background: list[asyncio.Task] = []
        self._unsaved: list[tuple[int, int, RunEnd]] = []  # run ends that wait for the database
        # experiments cancelled since the start: a run of one that ends now is not queued again
        self._cancelled: set[int] = set()
        self._estimated_at = -math.inf
        self._estimate_later: Optional[asyncio.TimerHandle] = None

    # ------------------------------------------------------------------ life cycle

    def start(self, queued: Iterable[Pending] = ()) -> None:
        """Start dispatching (on the loop), with the runs queued in the store."""
        self.add(queued)
        self._background = [asyncio.create_task(self._dispatch_loop(), name="twb-dispatch"),
                            asyncio.create_task(self._probe_loop(), name="twb-robot-probe")]

    async def stop(self) -> None:
        """Stop dispatching; runs under way end ``interrupted``; queued runs stay queued."""
        self.stopping = True
        if self._estimate_later is not None:
            self._estimate_later.cancel()
        for t in self._background:
            t.cancel()
        tasks = list(self._tasks.values())
        for t in tasks:
            t.cancel()
        if tasks:
            await asyncio.wait(tasks, timeout=10)

    def wake(self) -> None:
        """Look at the queue again (something was queued or freed)."""
        self._wake.set()

    # ------------------------------------------------------------------ queue

    def add(self, pending: Iterable[Pending]) -> None:
        """Queue runs (in order)."""
        for p in pending:
            self._expected[p.run_id] = p.expected_s
            self._experiment[p.run_id] = p.experiment_id
            self.scheduler.add(p)
        self._refresh_estimates(now=True)
        self.wake()

    async def cancel(self, experiment_ids: Iterable[int]) -> None:
        """Cancel experiments: their queued runs end ``cancelled`` (in one write), running ones are stopped."""
        ids = set(experiment_ids)
        self._cancelled |= ids
        await self._svc.recorder.end(self._drop(ids), RunStatus.CANCELLED, CANCELLED)
        running = [t for rid, t in self._tasks.items() if self._experiment.get(rid) in ids]
        for t in running:
            t.cancel()
        if running:
            await asyncio.wait(running, timeout=10)
        self._refresh_estimates()

    async def _fail_experiment(self, experiment_id: int, reason: str, kind: Optional[str]) -> None:
        """The experiment's path cannot be had: its queued runs fail with the reason."""
        await self._svc.recorder.fail_experiment(experiment_id, reason)
        await self._svc.recorder.end(self._drop({experiment_id}), RunStatus.FAILED, reason, failure=kind)

    def _drop(self, experiment_ids: set[int]) -> list[int]:
        """Take the experiments' queued runs off the queue; their ids."""
        ids = [p.run_id for p in self.scheduler.queue if p.experiment_id in experiment_ids]
        dropped = [rid for rid in ids if self.scheduler.drop(rid)]
        for rid in dropped:
            self._forget(rid)
        return dropped

    def _forget(self, run_id: int) -> None:
        self._experiment.pop(run_id, None)
        self._expected.pop(run_id, None)

    # ------------------------------------------------------------------ runs

    async def _dispatch_loop(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            try:
                for a in self.scheduler.assign():
                    self._start(a)
                self._refresh_estimates()
            except Exception:  # noqa: BLE001 - the dispatcher must survive any single bad state
                log.exception("dispatching failed")

    def _start(self, a: Assignment) -> None:
        task = asyncio.create_task(self._run(a), name=f"twb-run-{a.run_id}")
        self._tasks[a.run_id] = task
        task.add_done_callback(lambda _t, rid=a.run_id: self._tasks.pop(rid, None))

    async def _run(self, a: Assignment) -> None:
        end = await execute_run(a, self._svc, stopping=lambda: self.stopping)
        try:
            await asyncio.shield(self._finish(a, end))
        except asyncio.CancelledError:
            pass

    async def _finish(self, a: Assignment, end: RunEnd) -> None:
        """Store how the run ended, free its robot and sub-fields, look at the queue.

        The robot and sub-fields are freed whatever happens; when the database
        is unreachable the end is kept and stored once it answers again
        (:meth:`_store_ends`), so nothing a run produced is lost.
        """
        experiment_id = self._experiment.get(a.run_id, -1)
        self._forget(a.run_id)
        if end.status is RunStatus.ERROR and self.stopping:
            # the testbed stopping under the run is not the robot's fault
            end = RunEnd(RunStatus.INTERRUPTED, end.error)
        if end.status is RunStatus.ERROR and end.robot_fault is not None:
            self._field.set_offline(end.robot_fault, end.error)
        try:
            await self._store_end(a.run_id, experiment_id, end)
        except DBAPIError as exc:
            log.warning("run %d: its end waits for the database (%s)", a.run_id, exc.orig)
            self._unsaved.append((a.run_id, experiment_id, end))
        finally:
            self.scheduler.release(a.run_id)
            for k in a.subfields:  # tell the dashboards the sub-field is free again
                await self._field.set_subfield(k, state=SubfieldState.IDLE, run_id=None)
            self.wake()

    async def _store_end(self, run_id: int, experiment_id: int, end: RunEnd) -> None:
        """The database work of a run's end (one transaction: repeatable until it is stored), then what it queues."""
        if (end.resume or end.status is RunStatus.ERROR) and experiment_id in self._cancelled:
            # its owner cancelled it while it ended: no retry (what it produced is kept)
            end = replace(end, status=RunStatus.CANCELLED, error=CANCELLED, resume=False)
        rows = await store_end(self._svc.recorder, run_id, end)
        if rows is not None:
            retry = end.status is RunStatus.ERROR
            if retry:
                log.warning("run %d: %s; retrying on another robot", run_id, end.error)
            await self._queue_again(rows, experiment_id,
                                    frozenset({end.robot_fault} if retry and end.robot_fault else ()))
            return
        if end.status is RunStatus.FAILED and end.whole_experiment:
            await self._fail_experiment(experiment_id, end.error, failure_text(end))

    async def _queue_again(self, rows: tuple[Run, Experiment], experiment_id: int,
                           exclude: frozenset[str] = frozenset()) -> None:
        """Queue a run the store has queued again; one its owner cancelled meanwhile ends ``cancelled``."""
        if experiment_id in self._cancelled:
            await self._svc.recorder.end([rows[0].id], RunStatus.CANCELLED, CANCELLED)
            return
        self.add([pending_of(*rows, exclude)])

    async def _store_ends(self) -> None:
        """Store the run ends that waited for the database, in order; stop at the first that still waits."""
        while self._unsaved:
            run_id, experiment_id, end = self._unsaved[0]
            try:
                await self._store_end(run_id, experiment_id, end)
            except DBAPIError:
                return
            self._unsaved.pop(0)
            log.info("run %d: its end is stored", run_id)

    async def _probe_loop(self) -> None:
        """Every few seconds: robots marked offline (a failed run, or known from an earlier start) are tried
        again, and run ends that waited for the database are stored."""
        while True:
            await asyncio.sleep(self._probe_interval_s)
            if await self._field.probe_offline():
                self.wake()
            await self._store_ends()

    # ------------------------------------------------------------------ estimates and summary

    def _refresh_estimates(self, *, now: bool = False) -> None:
        """Recompute the queue's estimated starts; unless ``now`` (a submission: its estimate is asked for at
        once) at most every ``_ESTIMATE_EVERY_S``, as a long queue makes this a few milliseconds and runs end
        many times a second at full speed; a skipped refresh is done later."""
        wait = 0.0 if now else self._estimated_at + _ESTIMATE_EVERY_S - time.monotonic()
        if wait > 0:
            if self._estimate_later is None:
                self._estimate_later = asyncio.get_running_loop().call_later(wait, self._estimate_now)
            return
        self._estimate_now()

    def _estimate_now(self) -> None:
        if self._estimate_later is not None:  # a refresh asked for now makes the one waiting needless
            self._estimate_later.cancel()
            self._estimate_later = None
        self._estimated_at = time.monotonic()
        remaining = {rid: self._expected.get(rid, 60.0) / 2 for rid in self._tasks}
        starts = self.scheduler.estimate_starts(remaining)
        scale = self._svc.settings.time_scale
        per_exp: dict[int, float] = {}
        for p in self.scheduler.queue:
            if p.run_id in starts:
                wall = 0.0 if math.isinf(scale) else starts[p.run_id] / scale
                per_exp[p.experiment_id] = min(per_exp.get(p.experiment_id, math.inf), wall)
        self._estimates = per_exp

    def estimate_start(self, experiment_id: int) -> Optional[float]:
        """Estimated wall seconds until the experiment's next run starts (queued ones only; any thread: a snapshot)."""
        v = self._estimates.get(experiment_id)
        return None if v is None or math.isinf(v) else round(v, 1)

    def summary(self) -> dict[str, Any]:
        """Queue and fleet counts (``GET /health``)."""
        robots = self._field.robots.values()
        scale = self._svc.settings.time_scale
        return {
            "queued_runs": len(self.scheduler.queue),
            "running_runs": len(self._tasks),
            "field_robots": sum(1 for r in robots if r.pool == "field"),
            "sim_robots": sum(1 for r in robots if r.pool == Mode.SIM),
            "time_scale": None if math.isinf(scale) else scale,
        }

