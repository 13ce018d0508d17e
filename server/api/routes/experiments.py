"""Experiments: submit (202), list, inspect, cancel (one or many), metrics, export."""

from __future__ import annotations

from typing import Any, Optional

import anyio
from fastapi import APIRouter, Query, Response
from fastapi.responses import StreamingResponse
from sqlalchemy import func, select

from ...access import owned
from ...dispatch import pending_of
from ...errors import Conflict
from ...export import ExportFormat
from ...export.load import experiment_records
from ...export.serve import download_headers, export_chunks, require_format
from ...models import Experiment
from ...results import experiment_metrics
from ...schemas import (CancelledMany, CancelMany, ExperimentCreate, ExperimentMetricsPublic, ExperimentPublic,
                        ExperimentSummary, NotCancelled, Page)
from ...status import TERMINAL, RunStatus
from ...submission import submit
from ..deps import MAX_OFFSET, CurrentUser, IdPath, SessionDep, TestbedDep
from ..responses import AUTHENTICATED, EXPORTED, errors

router = APIRouter(prefix="/experiments", tags=["experiments"], responses=AUTHENTICATED)


@router.post("", response_model=ExperimentPublic, status_code=202, responses=errors(413))
async def submit_experiment(body: ExperimentCreate, user: CurrentUser, testbed: TestbedDep) -> ExperimentPublic:
    """Validate a job and queue its runs; 422 with the reason if it cannot run."""

    def add() -> tuple[ExperimentPublic, list[Any]]:
        with testbed.submit_locks(user.id), testbed.sessions.begin() as s:
            exp = submit(s, user=user, body=body, settings=testbed.settings)
            return ExperimentPublic.model_validate(exp), [pending_of(r, exp) for r in exp.runs]

    view, pending = await anyio.to_thread.run_sync(add)
    testbed.dispatcher.add(pending)
    testbed.broker.publish({"type": "experiment", "owner_id": user.id,
                            "experiment": view.model_dump(mode="json", exclude={"planned_path", "runs"})})
    view.estimated_start_s = testbed.dispatcher.estimate_start(view.id)
    return view


@router.post("/cancel", response_model=CancelledMany, responses=errors(413))
async def cancel_experiments(body: CancelMany, user: CurrentUser, testbed: TestbedDep) -> CancelledMany:
    """Cancel many experiments in one request: their queued runs end in one write, running ones are stopped."""

    def check() -> tuple[list[int], list[NotCancelled]]:
        with testbed.sessions() as s:
            q = select(Experiment.id, Experiment.status).where(Experiment.id.in_(set(body.ids)))
            if not user.is_admin:
                q = q.where(Experiment.owner_id == user.id)
            found = dict(s.execute(q).all())
        ok = [i for i in dict.fromkeys(body.ids) if i in found and found[i] not in TERMINAL]
        refused = [NotCancelled(id=i, reason="not found" if i not in found else f"already {found[i]}")
                   for i in dict.fromkeys(body.ids) if i not in ok]
        return ok, refused

    ok, refused = await anyio.to_thread.run_sync(check)
    await testbed.dispatcher.cancel(ok)
    return CancelledMany(cancelled=ok, not_cancelled=refused)


@router.get("", response_model=Page[ExperimentSummary])
def list_experiments(
    session: SessionDep,
    user: CurrentUser,
    testbed: TestbedDep,
    status: Optional[RunStatus] = Query(default=None, description="Only experiments in this state."),
    offset: int = Query(default=0, ge=0, le=MAX_OFFSET),
    limit: int = Query(default=50, ge=1, le=500),
) -> Page[ExperimentSummary]:
    """Your experiments, newest first (admins see everyone's)."""
    cond = [] if user.is_admin else [Experiment.owner_id == user.id]
    if status:
        cond.append(Experiment.status == status)
    rows = session.scalars(select(Experiment).where(*cond).order_by(Experiment.id.desc()).offset(offset).limit(limit))
    count = session.scalar(select(func.count(Experiment.id)).where(*cond)) or 0
    data = []
    for e in rows:
        view = ExperimentSummary.model_validate(e)
        view.estimated_start_s = testbed.dispatcher.estimate_start(e.id)
        data.append(view)
    return Page(data=data, count=count)


@router.get("/{experiment_id:int}", response_model=ExperimentPublic, responses=errors(404))
async def get_experiment(experiment_id: IdPath, user: CurrentUser, testbed: TestbedDep) -> Response:
    """Status, planned path and runs (mode, repetition, status, sub-field, metrics) of one experiment."""
    views = testbed.views
    hit = views.get(experiment_id)
    if hit is not None and (hit[0] == user.id or user.is_admin):
        return Response(hit[1], media_type="application/json")
    generation = views.generation(experiment_id)

    def load() -> bytes:
        with testbed.sessions() as session:
            exp = owned(session, user, Experiment, experiment_id, "Experiment")
            view = ExperimentPublic.model_validate(exp)
            view.estimated_start_s = testbed.dispatcher.estimate_start(exp.id)
            body = view.model_dump_json().encode()
            if exp.status in TERMINAL:  # finished experiments no longer change
                views.put(exp.id, exp.owner_id, body, generation)
            return body

    return Response(await anyio.to_thread.run_sync(load), media_type="application/json")


@router.post("/{experiment_id:int}/cancel", response_model=ExperimentPublic, responses=errors(404, 409))
async def cancel_experiment(experiment_id: IdPath, user: CurrentUser, testbed: TestbedDep) -> ExperimentPublic:
    """Cancel queued runs and stop running ones; 409 if the experiment has already finished."""

    def check() -> None:
        with testbed.sessions() as s:
            exp = owned(s, user, Experiment, experiment_id, "Experiment")
            if exp.status in TERMINAL:
                raise Conflict(f"Experiment already {exp.status}")

    await anyio.to_thread.run_sync(check)
    await testbed.dispatcher.cancel([experiment_id])

    def load() -> ExperimentPublic:
        with testbed.sessions() as s:
            return ExperimentPublic.model_validate(owned(s, user, Experiment, experiment_id, "Experiment"))

    return await anyio.to_thread.run_sync(load)


@router.get("/{experiment_id:int}/metrics", response_model=ExperimentMetricsPublic, responses=errors(404))
def get_experiment_metrics(experiment_id: IdPath, session: SessionDep, user: CurrentUser) -> ExperimentMetricsPublic:
    """Metrics per run, mean/std/95% CI per mode, and the direct sim-vs-twb comparison per repetition.

    ``direct`` is the paper's "ST": for each repetition with both a completed
    ``sim`` and ``twb`` run, the deviation (and Hausdorff / Fréchet distances)
    of the field path from the simulated one.
    """
    exp = owned(session, user, Experiment, experiment_id, "Experiment")
    return ExperimentMetricsPublic.model_validate(experiment_metrics(session, exp))


@router.get("/{experiment_id:int}/export", response_class=StreamingResponse, responses={**EXPORTED, **errors(404, 501)})
def export_experiment(
    experiment_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    format: ExportFormat = Query(default=ExportFormat.MCAP, description=(
        "mcap (Foxglove's well-known schemas) or rosbag2 (a ROS 2 bag directory, zipped).")),
) -> StreamingResponse:
    """Every run of the experiment in one MCAP file or ROS 2 bag, each run's topics under ``/run_<id>``.

    As ``GET /runs/{id}/export`` per run (docs/exports.md), with each run's
    topics and frames prefixed ``run_<id>``; ``/tf`` and the log are shared.
    Each run keeps its own clock.  501 when the server lacks the ``export`` extra.
    """
    require_format(format)
    exp = owned(session, user, Experiment, experiment_id, "Experiment")
    name = f"experiment-{experiment_id}"
    chunks, size = export_chunks(experiment_records(session, exp), format, name, experiment=True)
    return StreamingResponse(chunks, media_type=format.media_type,
                             headers=download_headers(format.filename(name), size))
