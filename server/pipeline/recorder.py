"""What the run pipeline records, off the event loop: run states, plans, retries, protocol lines.

Every change of a run rolls its experiment's status up in the same
transaction, forgets the experiment's cached view, and is published as a
live event (``run``, and ``experiment`` when the experiment's status
changed or it is finished).  Database work runs in threads; the loop never
blocks on it.
"""

from __future__ import annotations

import asyncio
from typing import Any, Callable, Iterable, Optional, Sequence

import numpy as np
from sqlalchemy.orm import Session, sessionmaker

from ..broker import EventBroker
from ..models import Experiment, Run, utcnow
from ..schemas import ExperimentPublic, RunPublic
from ..status import TERMINAL, RunStatus
from ..store import experiments as exp_store
from ..store import poses as pose_store
from ..store import runs as run_store
from ..store.runs import RunJob
from ..views import FinishedViews

__all__ = ["RunRecorder"]


class RunRecorder:
    """Persistence and live events of runs, for the pipeline and the dispatcher."""

    def __init__(self, sessions: sessionmaker[Session], broker: EventBroker, views: FinishedViews) -> None:
        self._sessions = sessions
        self._broker = broker
        self._views = views

    async def start(self, run_id: int, *, status: RunStatus | Callable[[RunJob], RunStatus],
                    **fields: Any) -> RunJob:
        """A try of the run starts, in one transaction: what an interrupted earlier try left goes, ``status``
        (or ``status(job)``, decided on the run's job) and ``fields`` are written as by :meth:`update`;
        returns what the pipeline needs of the run and its experiment."""

        def write() -> tuple[RunJob, list[dict[str, Any]]]:
            with self._sessions.begin() as s:
                job, written = run_store.start_try(s, run_id, status, fields)
                return job, self._written(written)

        job, events = await asyncio.to_thread(write)
        self._publish(events)
        return job

    async def update(self, run_id: int, **fields: Any) -> None:
        """Write run fields (``status``, ``t_start``, ``metrics`` …), roll the experiment up, publish."""

        def write() -> list[dict[str, Any]]:
            with self._sessions.begin() as s:
                return self._written(run_store.update_run(s, run_id, fields))

        self._publish(await asyncio.to_thread(write))

    async def end(self, run_ids: Iterable[int], status: RunStatus, error: str, *, failure: Optional[str] = None) -> None:
        """End several runs at once (queued runs cancelled, or failed with their experiment: ``failure`` why)."""
        ids = list(run_ids)
        if not ids:
            return

        def write() -> list[dict[str, Any]]:
            with self._sessions.begin() as s:
                runs = run_store.end_runs(s, ids, status, error, failure=failure)
                return self._events(runs, {r.experiment_id: True for r in runs})

        self._publish(await asyncio.to_thread(write))

    async def finish(self, run_id: int, status: RunStatus, error: str, *, failure: Optional[str] = None,
                     fields: Optional[dict[str, Any]] = None, poses: Optional[np.ndarray] = None,
                     messages: Sequence[dict[str, Any]] = (), retry: bool = False,
                     resume: bool = False,
                     obstacles: Optional[Sequence[np.ndarray]] = None) -> Optional[tuple[Run, Experiment]]:
        """Store a run's end in one transaction: the rest of its protocol log, then

        - ``resume``: the run is queued again, through nobody's fault (not counted as a retry);
        - ``retry`` (a testbed fault): the run is queued again once, its poses go;
        - otherwise (or when the retry was had already): its ``poses`` ``(N, 4)`` (s, m, m, rad), its
          ``obstacles`` (a field run's obstacle robots' poses, per moving obstacle ``(T, 4)``), ``fields``
          (``metrics``, ``t_start`` …), ``status``, ``finished_at``, ``error`` (kept when empty: a completed
          second attempt keeps the note about the first) and ``failure``.

        Returns the run and experiment rows when the run is queued again, else None.  All or nothing:
        when the database is away nothing is written and the call can be repeated.
        """

        def write() -> tuple[Optional[tuple[Run, Experiment]], list[dict[str, Any]]]:
            with self._sessions.begin() as s:
                run_store.add_messages(s, list(messages))
                again = (run_store.resume_run(s, run_id, error) if resume
                         else run_store.requeue_run(s, run_id, error) if retry else None)
                if again is not None:
                    return (again, again.experiment), self._events([again], {again.experiment_id: resume})
                if poses is not None:
                    pose_store.add_poses(s, run_id, poses)
                if obstacles is not None:
                    pose_store.add_obstacle_poses(s, run_id, obstacles)
                end: dict[str, Any] = dict(fields or {}, status=status, finished_at=utcnow())
                if error:
                    end["error"] = error
                if failure is not None:
                    end["failure"] = failure
                return None, self._written(run_store.update_run(s, run_id, end))

        rows, events = await asyncio.to_thread(write)
        self._publish(events)
        return rows

    async def fail_experiment(self, experiment_id: int, error: str) -> None:
        """The experiment's error text (its path could not be had)."""

        def write() -> None:
            with self._sessions.begin() as s:
                exp_store.set_error(s, experiment_id=experiment_id, error=error)

        await asyncio.to_thread(write)
        self._views.forget(experiment_id)

    async def store_plan(self, experiment_id: int, path: list[list[float]], planning_time_s: Optional[float],
                         info: dict[str, Any]) -> None:
        """Keep the experiment's planned path (m, m, rad) and planning time (s)."""

        def write() -> None:
            with self._sessions.begin() as s:
                exp_store.store_plan(s, experiment_id=experiment_id, path=path, planning_time_s=planning_time_s,
                                     info=info)

        await asyncio.to_thread(write)
        self._views.forget(experiment_id)

    async def store_planning_info(self, experiment_id: int, info: dict[str, Any]) -> None:
        """Keep what is known of a planning attempt that gave no path."""

        def write() -> None:
            with self._sessions.begin() as s:
                exp_store.store_planning_info(s, experiment_id=experiment_id, info=info)

        await asyncio.to_thread(write)
        self._views.forget(experiment_id)

    async def planned_path(self, experiment_id: int) -> tuple[Optional[list[list[float]]], Optional[float]]:
        """The experiment's stored planned path and planning time, if planned already."""

        def load() -> tuple[Optional[list[list[float]]], Optional[float]]:
            with self._sessions() as s:
                exp = s.get(Experiment, experiment_id)
                return exp.planned_path, exp.planning_time_s

        return await asyncio.to_thread(load)

    async def driven(self, run_id: int) -> tuple[list[list[float]], Optional[float], Optional[float]]:
        """Every logged pose ``[t, x, y, theta]`` of the run (oldest first), its ``t_start`` and ``t_end`` (s)."""

        def load() -> tuple[list[list[float]], Optional[float], Optional[float]]:
            with self._sessions() as s:
                run = s.get(Run, run_id)
                return pose_store.run_poses(s, run_id), run.t_start, run.t_end

        return await asyncio.to_thread(load)

    async def add_messages(self, batch: list[dict[str, Any]]) -> None:
        """Store protocol-log rows ``{run_id, t, t_estimated, direction, line}``."""
        if not batch:
            return

        def write() -> None:
            with self._sessions.begin() as s:
                run_store.add_messages(s, batch)

        await asyncio.to_thread(write)

    # ------------------------------------------------------------------ events

    def _written(self, w: run_store.RunWrite) -> list[dict[str, Any]]:
        """The live events of one run's write (built inside the transaction, published after it)."""
        out = [self._run_event(w.run, w.owner_id)]
        if w.experiment is not None:
            out.append(self._experiment_event(w.experiment))
        return out

    @staticmethod
    def _run_event(run: Run | dict[str, Any], owner_id: int) -> dict[str, Any]:
        """A run's live event, from its ORM row or its columns by name (without its planned path: the run's JSON
        has it)."""
        view = RunPublic.model_validate(run).model_dump(mode="json", exclude={"planned_path"})
        return {"type": "run", "owner_id": owner_id, "run": view}

    @staticmethod
    def _experiment_event(exp: Experiment) -> dict[str, Any]:
        view = ExperimentPublic.model_validate(exp).model_dump(mode="json", exclude={"planned_path", "runs"})
        return {"type": "experiment", "owner_id": exp.owner_id, "experiment": view}

    def _events(self, runs: list[Run], exp_changed: dict[int, bool]) -> list[dict[str, Any]]:
        """The live events for changed runs (built inside the transaction, published after it)."""
        out: list[dict[str, Any]] = []
        exps: dict[int, Experiment] = {}
        for run in runs:
            out.append(self._run_event(run, run.experiment.owner_id))
            exps[run.experiment_id] = run.experiment
        for exp_id, exp in exps.items():
            if exp_changed.get(exp_id) or exp.status in TERMINAL:
                out.append(self._experiment_event(exp))
        return out

    def _publish(self, events: list[dict[str, Any]]) -> None:
        for ev in events:
            if ev["type"] == "run":
                self._views.forget(ev["run"]["experiment_id"])
        for ev in events:
            self._broker.publish(ev)
