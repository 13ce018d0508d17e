"""Experiments: submit (202), list, inspect, cancel, metrics."""

from __future__ import annotations

from typing import Optional

import anyio
from fastapi import APIRouter, HTTPException, Query, Response
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from ...core.security import Principal

from ...jobs import create_experiment, experiment_public, experiment_summary
from ...models import Environment, Experiment, User
from ...schemas import TERMINAL_STATES, ExperimentCreate, ExperimentPublic, ExperimentSummary, Page
from ...validation import PreflightError, preflight
from ..deps import CurrentUser, SessionDep, TestbedDep, owned_row
from .environments import visible
from .programs import check_usable

router = APIRouter(prefix="/experiments", tags=["experiments"])


def owned_experiment(session: Session, user: Principal, experiment_id: int) -> tuple[Experiment, str]:
    """The experiment and its owner's name; 404 when it does not exist or is not the user's."""
    return owned_row(session, user, Experiment, experiment_id, "Experiment")


@router.post("", response_model=ExperimentPublic, status_code=202)
def submit_experiment(body: ExperimentCreate, session: SessionDep, user: CurrentUser, testbed: TestbedDep) -> ExperimentPublic:
    """Validate a job and queue its runs; 422 with the reason if it cannot run."""
    settings = testbed.settings
    if body.repetitions > settings.max_repetitions:
        raise HTTPException(422, f"repetitions must be at most {settings.max_repetitions}")
    if body.program is not None:
        check_usable(session, user, body.program, settings)
    env_row = session.scalar(select(Environment).where(Environment.name == body.environment, visible(user)))
    if env_row is None:
        raise HTTPException(422, f"unknown environment {body.environment!r}")
    queued = session.scalar(
        select(func.count(Experiment.id)).where(Experiment.owner_id == user.id, Experiment.status == "queued")
    ) or 0
    if queued >= settings.max_queued_per_user:
        raise HTTPException(429, f"you already have {queued} queued experiments (limit {settings.max_queued_per_user})")
    try:
        checked = preflight(body, env_row.data, settings.robot_radius_m, settings.planning_margin_m)
    except PreflightError as exc:
        raise HTTPException(422, str(exc)) from None
    exp = create_experiment(session, owner=user, body=body, checked=checked, robot_radius=settings.robot_radius_m,
                            planning_margin=settings.planning_margin_m)
    session.commit()
    testbed.submitted(exp.id)
    session.refresh(exp)
    return experiment_public(exp, user.name, testbed.estimate_start(exp.id))


@router.get("", response_model=Page[ExperimentSummary])
def list_experiments(
    session: SessionDep,
    user: CurrentUser,
    testbed: TestbedDep,
    status: Optional[str] = Query(default=None, description="Only experiments in this state."),
    offset: int = Query(default=0, ge=0),
    limit: int = Query(default=50, ge=1, le=500),
) -> Page[ExperimentSummary]:
    """Your experiments, newest first (admins see everyone's)."""
    cond = [] if user.is_admin else [Experiment.owner_id == user.id]
    if status:
        cond.append(Experiment.status == status)
    rows = session.execute(
        select(Experiment, User.name).join(User, Experiment.owner_id == User.id).where(*cond)
        .order_by(Experiment.id.desc()).offset(offset).limit(limit)
    ).all()
    count = session.scalar(select(func.count(Experiment.id)).where(*cond)) or 0
    return Page(data=[experiment_summary(e, owner, testbed.estimate_start(e.id)) for e, owner in rows], count=count)


@router.get("/{experiment_id}", response_model=ExperimentPublic)
async def get_experiment(experiment_id: int, user: CurrentUser, testbed: TestbedDep) -> Response:
    """Status, planned path and runs (mode, repetition, status, sub-field, metrics) of one experiment."""
    hit = testbed.finished_views.get(experiment_id)
    if hit is not None and (hit[0] == user.id or user.is_admin):
        return Response(hit[1], media_type="application/json")

    def load() -> bytes:
        with testbed.sessions() as session:
            exp, owner = owned_experiment(session, user, experiment_id)
            body = experiment_public(exp, owner, testbed.estimate_start(exp.id)).model_dump_json().encode()
            if exp.status in TERMINAL_STATES:  # finished experiments no longer change
                testbed.finished_views[exp.id] = (exp.owner_id, body)
            return body

    return Response(await anyio.to_thread.run_sync(load), media_type="application/json")


@router.post("/{experiment_id}/cancel", response_model=ExperimentPublic)
async def cancel_experiment(experiment_id: int, user: CurrentUser, testbed: TestbedDep) -> ExperimentPublic:
    """Cancel queued runs and stop running ones; 409 if the experiment has already finished."""

    def check() -> None:
        with testbed.sessions() as s:
            exp, _ = owned_experiment(s, user, experiment_id)
            if exp.status in TERMINAL_STATES:
                raise HTTPException(409, f"Experiment already {exp.status}")

    await anyio.to_thread.run_sync(check)
    await testbed.cancel(experiment_id)

    def load() -> ExperimentPublic:
        with testbed.sessions() as s:
            exp, owner = owned_experiment(s, user, experiment_id)
            return experiment_public(exp, owner)

    return await anyio.to_thread.run_sync(load)


@router.get("/{experiment_id}/metrics")
def experiment_metrics(experiment_id: int, session: SessionDep, user: CurrentUser) -> dict:
    """Metrics per run, mean/std/95% CI per mode, and the direct sim-vs-twb comparison per repetition.

    ``direct`` is the paper's "ST": for each repetition with both a completed
    ``sim`` and ``twb`` run, the deviation (and Hausdorff / Fréchet distances)
    of the field path from the simulated one.
    """
    from planners.stats import aggregate

    from ...models import Pose, Run
    from ...planning import compare_runs

    exp, _ = owned_experiment(session, user, experiment_id)
    runs = [r for r in exp.runs]
    per_run = [{"run_id": r.id, "mode": r.mode, "repetition": r.repetition, "status": r.status,
                "metrics": r.metrics or {}} for r in runs]
    done = [r for r in runs if r.status == "completed" and r.metrics]
    records = [{"mode": r.mode, **{k: v for k, v in r.metrics.items() if not isinstance(v, dict) and k != "poses"}}
               for r in done]
    aggregates = {g["mode"]: {"runs": g["runs"], "metrics": g["metrics"]}
                  for g in aggregate(records, by=("mode",))} if records else {}
    direct = []
    by_rep: dict[int, dict[str, Run]] = {}
    for r in done:
        by_rep.setdefault(r.repetition, {})[r.mode] = r
    for rep, modes in sorted(by_rep.items()):
        if "sim" in modes and "twb" in modes:
            def poses(run: Run) -> list[list[float]]:
                rows = session.execute(select(Pose.t, Pose.x, Pose.y, Pose.theta).where(Pose.run_id == run.id)
                                       .order_by(Pose.t)).all()
                lo, hi = run.t_start, run.t_end
                return [list(p) for p in rows if lo is None or hi is None or lo - 1e-9 <= p[0] <= hi + 1e-9]

            direct.append({"repetition": rep, "sim_run_id": modes["sim"].id, "twb_run_id": modes["twb"].id,
                           **compare_runs(poses(modes["sim"]), poses(modes["twb"]))})
    planned = next((r.metrics.get("planned") for r in done if r.metrics.get("planned")), None)
    return {"experiment_id": exp.id, "status": exp.status, "planned": planned, "runs": per_run,
            "aggregates": aggregates, "direct": direct}
