"""Runs: what the pipeline needs of one, state changes with the experiment's roll-up, retries, messages."""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import field as dc_field
from typing import Any, Callable, Iterable, Optional

from sqlalchemy import bindparam, delete, insert, select, update
from sqlalchemy.orm import Session

from ..models import Experiment, Message, Pose, Run, utcnow
from ..status import ACTIVE, TERMINAL, RunStatus, roll_up
from .driver import as_sqlalchemy_errors
from .experiments import finish_if_done, lock_experiments, lock_run, lock_run_row

__all__ = ["RunJob", "RunWrite", "add_messages", "end_runs", "interrupt_active", "queued_runs", "requeue_interrupted",
           "requeue_run", "resume_run", "start_try", "update_run"]


@dataclass(frozen=True)
class RunJob:
    """What the run pipeline needs to know of a run and its experiment (SI units)."""

    run_id: int
    seed: int
    mode: str
    experiment_id: int
    owner_id: int
    environment: str
    environment_data: dict[str, Any]
    start: list[float]
    goal: list[float]
    field: str
    robot_radius: float
    jitter: Optional[dict[str, float]] = None
    #: field parameters replacing the robot profile's in field runs (SI units), or None
    profile_overrides: Optional[dict[str, float]] = None
    controller: str = "schema"
    controller_params: dict[str, float] = dc_field(default_factory=dict)
    #: an uploaded program that drives the robot along the planned path (docs/controllers.md), or None
    controller_program: Optional[int] = None
    #: a multi-robot job's robots ``[{"start", "goal", "path"?}]`` (m, rad), or None; they are planned with
    #: the run (``planner``, ``planner_params``, ``seed`` of the experiment, ``planning_margin`` m)
    robots: Optional[list[dict[str, Any]]] = None
    planner: Optional[str] = None
    planner_params: dict[str, Any] = dc_field(default_factory=dict)
    experiment_seed: int = 0
    planning_margin: float = 0.0
    #: the uploaded planner program of the experiment (a multi-robot job's sends every robot's path), or None
    program: Optional[int] = None
    repetition: int = 1
    #: the seed the run's repetition plans with (None: a run from before planner seeds, planned with the job's seed)
    planner_seed: Optional[int] = None
    #: the experiment's planner is randomised: planned once per repetition (a failure fails that repetition only)
    planner_stochastic: bool = False


def _job(run: dict[str, Any], e: dict[str, Any]) -> RunJob:
    """The :class:`RunJob` of a run and its experiment (their columns by name)."""
    return RunJob(run["id"], run["seed"], run["mode"], e["id"], e["owner_id"], e["environment"], e["environment_data"],
                  list(e["start"]), list(e["goal"]), e["field"], e["robot_radius"], e["jitter"], e["profile_overrides"],
                  e["controller"] or "schema", dict(e["controller_params"] or {}), e["controller_program_id"],
                  e["robots"], e["planner"], dict(e["planner_params"] or {}), e["seed"], e["planning_margin"] or 0.0,
                  e["program_id"], run["repetition"], run["planner_seed"], bool(e["planner_stochastic"]))


@dataclass(frozen=True)
class RunWrite:
    """A run as a write left it: its columns by name (what :class:`~server.schemas.RunPublic` reads), its
    experiment's owner, and the experiment (an ORM row, for its live event) when the write changed the
    experiment's status or the experiment has ended, else None."""

    run: dict[str, Any]
    owner_id: int
    experiment: Optional[Experiment] = None


#: what a run's write reads of its experiment: the owner, and what tells whether the roll-up changes it
_ROLL_UP = ("id", "owner_id", "status", "started_at")
_ALL = tuple(c.name for c in Experiment.__table__.c)
_RUNS = Run.__table__
_POSES = Pose.__table__
# built once (building a statement and its cache key costs about as much as running it); an update's SET
# clause is the keys of its parameters
_UPDATE_RUN = update(_RUNS).where(_RUNS.c.id == bindparam("where_run_id"))
_STATUSES = select(_RUNS.c.status).where(_RUNS.c.experiment_id == bindparam("experiment_id"))
_CLEAR_POSES = delete(_POSES).where(_POSES.c.run_id == bindparam("run_id"))


def start_try(session: Session, run_id: int, status: RunStatus | Callable[[RunJob], RunStatus],
              fields: dict[str, Any]) -> tuple[RunJob, RunWrite]:
    """A try of the run starts: what an interrupted earlier try left goes (poses, metrics, end), ``status`` (or
    ``status(job)``, decided on the run's job) and ``fields`` are written and the experiment rolled up."""
    run, exp = lock_run_row(session, run_id, _ALL)
    job = _job(run, exp)
    if run["started_at"] is not None:  # a run that never started has no poses
        session.execute(_CLEAR_POSES, {"run_id": run_id})
    cleared = dict(t_start=None, t_end=None, metrics={}, failure=None, stopped_at=None)
    values = {k: v for k, v in cleared.items() if run[k] != v}  # a first try has nothing to clear: a narrower update
    values.update(fields, status=status(job) if callable(status) else status)
    return job, _write(session, run, exp, values)


def update_run(session: Session, run_id: int, fields: dict[str, Any]) -> RunWrite:
    """Write ``fields`` on the run and roll the experiment's status up."""
    run, exp = lock_run_row(session, run_id, _ROLL_UP)
    return _write(session, run, exp, fields)


def _write(session: Session, run: dict[str, Any], exp: dict[str, Any], values: dict[str, Any]) -> RunWrite:
    """Core statements, not the ORM's unit of work: the run's update, its siblings' statuses for the roll-up;
    the experiment is loaded (and stamped, and given its error text) only when its status changes."""
    session.execute(_UPDATE_RUN, {**values, "where_run_id": run["id"]})
    run.update(values)
    new = roll_up(session.scalars(_STATUSES, {"experiment_id": exp["id"]}).all())
    if new == exp["status"] and new not in TERMINAL and (new not in ACTIVE or exp["started_at"] is not None):
        return RunWrite(run, exp["owner_id"])
    orm = session.get(Experiment, exp["id"])
    assert orm is not None
    finish_if_done(orm)
    return RunWrite(run, orm.owner_id, orm)


def resume_run(session: Session, run_id: int, why: str) -> Run:
    """Queue again a run that ended through nobody's fault (not a retry); its poses stay until it runs."""
    run = lock_run(session, run_id)
    run.status, run.error, run.finished_at = RunStatus.QUEUED, f"resumed: {why}", None
    finish_if_done(run.experiment)
    return run


def requeue_run(session: Session, run_id: int, error: str) -> Optional[Run]:
    """Queue a run that hit a testbed fault again, once; its poses go. None if it was retried already.
    (Asking again for a run already queued changes nothing.)"""
    run = lock_run(session, run_id)
    if run.status == RunStatus.QUEUED:
        return run
    if run.attempt >= 2:
        return None
    run.attempt += 1
    run.status = RunStatus.QUEUED
    run.error = f"attempt 1: {error}"
    run.robot_id = None
    run.subfield = None
    run.t_start = run.t_end = None
    run.failure = run.stopped_at = None
    session.execute(delete(Pose).where(Pose.run_id == run_id))
    finish_if_done(run.experiment)
    return run


def end_runs(session: Session, run_ids: Iterable[int], status: RunStatus, error: str, *,
             failure: Optional[str] = None) -> list[Run]:
    """End the given runs (queued ones: cancelled, failed with their experiment) in one go; returns them."""
    ids = list(run_ids)
    if not ids:
        return []
    lock_experiments(session, run_ids=ids)
    runs = list(session.scalars(select(Run).where(Run.id.in_(ids))))
    now = utcnow()
    for run in runs:
        run.status, run.error, run.finished_at, run.failure = status, error, now, failure
    for exp in {run.experiment for run in runs}:
        finish_if_done(exp)
    return runs


def queued_runs(session: Session, *, experiment_ids: Optional[Iterable[int]] = None) -> list[tuple[Run, Experiment]]:
    """Queued runs with their experiments, oldest first (of the given experiments, or all)."""
    q = select(Run, Experiment).join(Experiment).where(Run.status == RunStatus.QUEUED)
    if experiment_ids is not None:
        q = q.where(Run.experiment_id.in_(list(experiment_ids)))
    return [(r, e) for r, e in session.execute(q.order_by(Run.id))]


def add_messages(session: Session, batch: list[dict[str, Any]]) -> None:
    """Insert protocol-log rows ``{run_id, t, t_estimated, direction, line}``."""
    if not batch:
        return
    conn = session.connection()
    if conn.dialect.name == "postgresql":  # COPY: half the CPU of an executemany for a run's few dozen lines
        with as_sqlalchemy_errors(conn.dialect, "COPY messages"), conn.connection.driver_connection.cursor() as cur:
            with cur.copy("COPY messages (run_id, t, t_estimated, direction, line) FROM STDIN") as copy:
                for m in batch:
                    copy.write_row((m["run_id"], m["t"], m.get("t_estimated", False), m["direction"], m["line"]))
    else:  # Core's executemany: the ORM's bulk insert costs a third more CPU for nothing here
        session.execute(insert(Message.__table__), batch)


def interrupt_active(session: Session, reason: str) -> int:
    """Runs left active by a server that stopped end ``interrupted``; returns how many.

    Their experiments wait ``queued`` when runs of theirs are still queued,
    else roll up.
    """
    cut = list(session.scalars(select(Run).where(Run.status.in_(ACTIVE))))
    now = utcnow()
    for run in cut:
        run.status, run.error, run.finished_at = RunStatus.INTERRUPTED, reason, now
    for exp in session.scalars(select(Experiment).where(Experiment.status.in_(ACTIVE))):
        if any(r.status == RunStatus.QUEUED for r in exp.runs):
            exp.status = RunStatus.QUEUED
        else:
            finish_if_done(exp)
    return len(cut)


def requeue_interrupted(session: Session) -> int:
    """Queue again every run a testbed stop interrupted; returns how many.  Its poses stay until it
    starts again and its messages for good (a record of the try); not counted as a retry: the robot
    was not at fault."""
    runs = list(session.scalars(select(Run).where(Run.status == RunStatus.INTERRUPTED)))
    for run in runs:
        run.status = RunStatus.QUEUED
        run.error = "resumed: the testbed stopped during an earlier try"
        run.finished_at = None
    for exp in {run.experiment for run in runs}:
        exp.finished_at = None
        exp.error = ""
        finish_if_done(exp)
    return len(runs)
