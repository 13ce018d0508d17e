"""Experiments and their runs: creation, per-run seeds, status roll-up, public views.

Store functions take keyword-only arguments and a session; they never commit
unless they say so.
"""

from __future__ import annotations

import hashlib
from typing import Any, Iterable, Optional

from sqlalchemy.orm import Session

from .models import Experiment, Run, User, utcnow
from .schemas import TERMINAL_STATES, ExperimentCreate, ExperimentPublic, ExperimentSummary, RunPublic
from .validation import Preflight

__all__ = [
    "ACTIVE_STATES",
    "create_experiment",
    "experiment_public",
    "experiment_summary",
    "roll_up",
    "run_public",
    "run_seed",
]

ACTIVE_STATES = ("building", "placing", "planning", "running", "analyzing")


def run_seed(experiment_seed: int, mode: str, repetition: int) -> int:
    """Seed of one run's random elements (noise, dropouts), derived stably from the job's seed.

    The same repetition gets different seeds in sim and twb (independent noise),
    and replaying a job with the same seed replays every run exactly.
    """
    digest = hashlib.sha256(f"{experiment_seed}:{mode}:{repetition}".encode()).digest()
    return int.from_bytes(digest[:8], "big") >> 1


def create_experiment(
    session: Session, *, owner: User, body: ExperimentCreate, checked: Preflight, robot_radius: float,
    planning_margin: float = 0.0,
) -> Experiment:
    """Add the experiment and one queued run per repetition and mode (flushes, no commit)."""
    exp = Experiment(
        owner_id=owner.id,
        status="queued",
        environment=checked.env.name,
        environment_data=checked.env.to_dict(),
        start=checked.start,
        goal=checked.goal,
        planner=body.planner,
        planner_params=checked.planner_params,
        explicit_path=checked.path,
        program_id=body.program,
        modes=list(body.modes),
        repetitions=body.repetitions,
        seed=body.seed,
        field=body.field,
        robot_radius=robot_radius,
        planning_margin=planning_margin if body.path is None else 0.0,
    )
    session.add(exp)
    session.flush()
    for rep in range(1, body.repetitions + 1):
        for mode in body.modes:
            session.add(Run(experiment_id=exp.id, mode=mode, repetition=rep, seed=run_seed(body.seed, mode, rep)))
    session.flush()
    return exp


def roll_up(statuses: Iterable[str]) -> str:
    """The experiment's status from its runs' statuses.

    Unfinished: ``queued`` until a run starts, then the state of the most
    advanced active run.  Finished: ``cancelled`` > ``error`` > ``failed`` >
    ``interrupted`` > ``completed`` (the first that any run has).
    """
    sts = list(statuses)
    if not sts:
        return "queued"
    if all(s in TERMINAL_STATES for s in sts):
        for s in ("cancelled", "error", "failed", "interrupted"):
            if s in sts:
                return s
        return "completed"
    active = [s for s in sts if s in ACTIVE_STATES]
    if active:
        return max(active, key=ACTIVE_STATES.index)
    return "running" if any(s in TERMINAL_STATES for s in sts) else "queued"


def run_public(run: Run) -> RunPublic:
    return RunPublic(
        id=run.id, experiment_id=run.experiment_id, mode=run.mode, repetition=run.repetition,
        status=run.status, seed=run.seed, attempt=run.attempt, subfield=run.subfield, robot_id=run.robot_id,
        t_start=run.t_start, t_end=run.t_end, metrics=run.metrics or {}, error=run.error,
        created_at=run.created_at, started_at=run.started_at, finished_at=run.finished_at,
    )


def experiment_summary(exp: Experiment, owner: str, estimated_start_s: Optional[float] = None) -> ExperimentSummary:
    return ExperimentSummary(
        id=exp.id, owner=owner, status=exp.status, environment=exp.environment, planner=exp.planner,
        program=exp.program_id, modes=exp.modes, repetitions=exp.repetitions, field=exp.field, error=exp.error,
        created_at=exp.created_at, finished_at=exp.finished_at, estimated_start_s=estimated_start_s,
    )


def experiment_public(exp: Experiment, owner: str, estimated_start_s: Optional[float] = None) -> ExperimentPublic:
    base = experiment_summary(exp, owner, estimated_start_s).model_dump()
    return ExperimentPublic(
        **base,
        start=exp.start, goal=exp.goal, planner_params=exp.planner_params or {}, seed=exp.seed,
        robot_radius=exp.robot_radius, planning_margin=exp.planning_margin, planned_path=exp.planned_path, planning_time_s=exp.planning_time_s,
        planning_info=exp.planning_info or {}, started_at=exp.started_at,
        runs=[run_public(r) for r in exp.runs],
    )


def finish_if_done(exp: Experiment) -> bool:
    """Update ``exp.status`` from its runs; set ``finished_at`` when all are done. True if changed."""
    new = roll_up(r.status for r in exp.runs)
    changed = new != exp.status
    exp.status = new
    if new in TERMINAL_STATES and exp.finished_at is None:
        exp.finished_at = utcnow()
    if new in ACTIVE_STATES and exp.started_at is None:
        exp.started_at = utcnow()
    return changed


def public_dict(exp: Experiment, owner: str) -> dict[str, Any]:
    return experiment_public(exp, owner).model_dump(mode="json")
