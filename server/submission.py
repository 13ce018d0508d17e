"""Accepting a job: the checks a submission passes before its runs are queued."""

from __future__ import annotations

import dataclasses
import math
import threading
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from planners.compared import job_configuration, problem_label

from .access import environment_named
from .core.security import Principal
from .core.settings import Settings
from .errors import Forbidden, Invalid, QuotaExceeded
from .models import Experiment, Program, User
from .schemas import ExperimentCreate
from .store.experiments import count_queued, create_experiment
from .validation import Preflight, preflight

__all__ = ["UPLOADS_DISABLED", "UserLocks", "job_names", "submit"]

UPLOADS_DISABLED = "uploads are disabled on this testbed"


class UserLocks:
    """One lock per user: a user's submissions are counted against the quota one at a time (any thread)."""

    def __init__(self) -> None:
        self._locks: dict[int, threading.Lock] = {}
        self._guard = threading.Lock()

    def __call__(self, user_id: int) -> threading.Lock:
        with self._guard:
            return self._locks.setdefault(user_id, threading.Lock())


def submit(session: Session, *, user: Principal, body: ExperimentCreate, settings: Settings) -> Experiment:
    """Check the job and add it with its queued runs (flushes, no commit).

    Hold the user's :class:`UserLocks` lock until the transaction commits:
    the quota is a count, then an insert.  (On PostgreSQL the user's row is
    locked as well, for several server processes.)

    Raises :class:`Invalid` (too many repetitions, unknown environment or
    program, a job that cannot run: :class:`~server.errors.PreflightError`),
    :class:`Forbidden` (a program while uploads are disabled) or
    :class:`QuotaExceeded` (too many queued experiments).
    """
    if body.repetitions > settings.max_repetitions:
        raise Invalid(f"repetitions must be at most {settings.max_repetitions}")
    stochastic = False
    if body.program is not None:
        stochastic = _check_program(session, user, body.program, settings)
    if body.controller_program is not None:
        if math.isinf(settings.time_scale) and settings.clock == "free":
            raise Invalid("controller_program: with the free-running clock a controller program closes the loop "
                          "against the robot's 0.5 s watchdog in wall time, which needs a finite time scale; this "
                          "testbed runs as fast as possible (start it with --clock lockstep, or --time-scale 1)")
        _check_program(session, user, body.controller_program, settings, field="controller_program")
    env_row = environment_named(session, user, body.environment)
    if env_row is None:
        raise Invalid(f"unknown environment {body.environment!r}")
    session.execute(select(User.id).where(User.id == user.id).with_for_update())
    queued = count_queued(session, owner_id=user.id)
    if queued >= settings.max_queued_per_user:
        raise QuotaExceeded(f"you already have {queued} queued experiments (limit {settings.max_queued_per_user})")
    checked = preflight(body, env_row.data, settings.robot_radius_m, settings.planning_margin_m)
    if body.program is not None:  # the program declared at its upload whether it is randomised
        checked = dataclasses.replace(checked, stochastic=stochastic)
    label, problem = job_names(body, checked, env_row.data)
    return create_experiment(session, owner=user, body=body, checked=checked, robot_radius=settings.robot_radius_m,
                             planning_margin=settings.planning_margin_m, label=label, problem=problem)


def job_names(body: ExperimentCreate, checked: Preflight, env_data: dict[str, Any]) -> tuple[str, str]:
    """The job's configuration label and problem name: its own ``label`` and ``problem``, else derived as a
    study derives them (:func:`planners.compared.job_configuration`: the planner with the parameters *given*;
    :func:`planners.compared.problem_label`: a plan of the environment, or the start and goal)."""
    label = body.label or job_configuration(
        planner=body.planner, planner_params=body.planner_params, program=body.program, controller=body.controller,
        controller_params=body.controller_params, controller_program=body.controller_program,
        profile_overrides=body.profile_overrides)
    problem = body.problem or problem_label(checked.env.name, plans=env_data.get("plans") or [],
                                            start=checked.start, goal=checked.goal, robots=checked.robots)
    return label, problem


def _check_program(session: Session, user: Principal, program_id: int, settings: Settings,
                   field: str = "program") -> bool:
    """A job naming a program (in ``field``): uploads enabled (403) and the program the user's (422); whether
    the program declared itself stochastic."""
    if not settings.uploads_enabled:
        raise Forbidden(UPLOADS_DISABLED)
    row = session.execute(select(Program.owner_id, Program.stochastic).where(Program.id == program_id)).first()
    if row is None or (row.owner_id != user.id and not user.is_admin):
        raise Invalid(f"unknown program {program_id}" if field == "program"
                      else f"{field}: unknown program {program_id}")
    return bool(row.stochastic)
