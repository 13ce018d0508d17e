"""Running a study against a testbed: submit every experiment, follow them, collect the results."""

from __future__ import annotations

import sys
import time
from collections import Counter
from datetime import datetime, timezone
from typing import Any, Optional

from .._client import Client
from .._exceptions import Conflict, NotFound, RateLimited, TwbError, ValidationError
from .._models import Environment, Experiment, ExperimentMetrics
from ._data import StudyData
from ._limits import StudyRefused, check_study, refusal
from ._spec import ControllerChoice, PlannerSpec, PlanSpec, StudySpec, StudySpecError

__all__ = ["StudyJob", "StudyRefused", "flat_metrics", "plan_jobs", "run_study"]


class StudyJob(dict):
    """One experiment of a study: environment, plan, planner, configuration and the job body sent to the server."""


def _body(name: str, start: list[float], goal: list[float], planner: PlannerSpec, controller: Optional[ControllerChoice],
          spec: StudySpec) -> dict[str, Any]:
    """The job sent to the server for one problem and configuration (an explicit path: start, waypoints, goal)."""
    body: dict[str, Any] = {"environment": name, "start": list(start), "goal": list(goal)}
    if planner.waypoints is not None:
        body["path"] = [list(start), *[list(w) for w in planner.waypoints], list(goal)]
    else:
        body.update(planner=planner.name, planner_params=dict(planner.params))
    body.update(modes=list(spec.modes), repetitions=spec.repetitions, seed=spec.seed, field=spec.field)
    if spec.jitter is not None:
        body["jitter"] = dict(spec.jitter)
    if controller is not None:
        body.update(controller=controller.name, controller_params=dict(controller.params))
    return body


def _environments(client: Client, spec: StudySpec) -> dict[str, Environment]:
    """The study's environments, creating those given as files that the server does not have yet."""
    out = {}
    for e in spec.environments:
        name = e if isinstance(e, str) else e["name"]
        try:
            out[name] = client.get_environment(name)
        except NotFound:
            if isinstance(e, str):
                raise StudySpecError(f"unknown environment {name!r}: create it first or give its file in "
                                     "the study's `environments`") from None
            out[name] = client.create_environment(e)
    return out


def plan_jobs(spec: StudySpec, environments: dict[str, Environment]) -> list[StudyJob]:
    """The experiments of the study, environment x plan x planner (x controller), in that order."""
    jobs = []
    for name in spec.environment_names():
        env = environments[name]
        plans = spec.plans if spec.plans is not None else [PlanSpec(p.name) for p in env.plans]
        if not plans:
            raise ValueError(f"environment {name!r} has no plans: give explicit start/goal pairs in the study's `plans`")
        for plan in plans:
            if plan.start is None:
                try:
                    p = env.plan(plan.name)
                except KeyError as exc:
                    raise ValueError(str(exc.args[0])) from None
                start, goal = p.start, p.goal
            else:
                start, goal = plan.start, plan.goal
            for planner, controller, configuration in spec.configurations():
                jobs.append(StudyJob(environment=name, plan=plan.name,
                                     planner=planner.name if planner.waypoints is None else "path",
                                     controller=controller.name if controller is not None else "schema",
                                     configuration=configuration,
                                     body=_body(name, start, goal, planner, controller, spec)))
    return jobs


class _StudyProgress:
    def __init__(self, name: str, total: int, enabled: bool) -> None:
        self._p = None
        if not enabled:
            return
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self._p = Progress(TextColumn(f"study {name}"), BarColumn(), MofNCompleteColumn(), TextColumn("runs"),
                           TimeElapsedColumn(), TextColumn("{task.fields[states]}"), console=Console(stderr=True))
        self._task = self._p.add_task("", total=total, states="submitting")
        self._p.start()

    def update(self, done: int, states: str) -> None:
        if self._p is not None:
            self._p.update(self._task, completed=done, states=states)

    def close(self) -> None:
        if self._p is not None:
            self._p.stop()


def run_study(client: Client, spec: StudySpec, *, progress: Optional[bool] = None, timeout: Optional[float] = None,
              interval: float = 0.5) -> StudyData:
    """Submit every experiment of ``spec``, wait for all of them and collect runs, metrics and poses.

    Before submitting, the study is checked against the testbed
    (:func:`~client_sdk.study._limits.check_study`: planners, environments,
    the limits the server states); :class:`StudyRefused` lists every problem
    and nothing is submitted.  A refusal that dooms the whole study (too many
    repetitions, the queue quota) also raises :class:`StudyRefused`, after
    cancelling what was submitted.  A job the server refuses for its own
    reason (422, e.g. a start inside an obstacle) is kept as an experiment
    with status ``rejected`` and the server's reason; the others go on.
    ``progress`` (default: when stderr is a terminal) shows runs done / total
    and the run states.  On Ctrl-C or a timeout the unfinished experiments are
    cancelled.
    """
    t0 = time.monotonic()
    started = datetime.now(timezone.utc)
    reasons = check_study(client, spec)
    if reasons:
        raise StudyRefused(reasons)
    envs = _environments(client, spec)
    jobs = plan_jobs(spec, envs)
    total = len(jobs) * spec.runs_per_experiment
    bar = _StudyProgress(spec.name, total, sys.stderr.isatty() if progress is None else progress)
    submitted: dict[int, StudyJob] = {}
    final: dict[int, Experiment] = {}
    try:
        for i, job in enumerate(jobs):
            try:
                exp = client.submit(job["body"])
                job["experiment_id"] = exp.id
                submitted[exp.id] = job
            except (ValidationError, RateLimited) as exc:
                doom = refusal(exc, spec, i, len(jobs))
                if doom is not None:
                    _cancel(client, submitted, final)
                    raise StudyRefused([doom + (f"; the {len(submitted)} experiment(s) already submitted were "
                                                "cancelled" if submitted else "")]) from None
                job["experiment_id"], job["rejected"] = None, exc.detail if isinstance(exc.detail, str) else str(exc)
        while True:
            states: Counter[str] = Counter()
            for eid in submitted:
                if eid in final:
                    states.update(r.status for r in final[eid].runs)
                    continue
                exp = client.get_experiment(eid)
                states.update(r.status for r in exp.runs)
                if exp.finished:
                    final[eid] = exp
            done = sum(n for s, n in states.items() if s in ("completed", "failed", "error", "cancelled", "interrupted"))
            bar.update(done, " ".join(f"{s} {n}" for s, n in sorted(states.items())))
            if len(final) == len(submitted):
                break
            if timeout is not None and time.monotonic() - t0 > timeout:
                raise TimeoutError(f"study {spec.name!r} not finished after {timeout:g} s "
                                   f"({done}/{total} runs done); its unfinished experiments were cancelled")
            time.sleep(interval)
    except (KeyboardInterrupt, TimeoutError):
        _cancel(client, submitted, final)
        raise
    finally:
        bar.close()
    metrics = {eid: client.get_metrics(eid) for eid in final}
    data = _assemble(spec, envs, jobs, final, metrics)
    for exp in final.values():
        for run in exp.runs:
            # a failed run's driving is data too: Fig. 8 draws it up to where it stopped
            if run.status in ("completed", "failed") and run.t_start is not None:
                try:
                    data.add_poses(run.id, client.get_poses(run.id))
                except NotFound:
                    pass
    data.meta.update(server=client.url, started_at=started.isoformat(timespec="seconds"),
                     wall_s=round(time.monotonic() - t0, 3), runs=total)
    return data


def _cancel(client: Client, submitted: dict[int, StudyJob], final: dict[int, Experiment]) -> None:
    """Cancel the study's unfinished experiments (best effort: a testbed gone away ends the attempt)."""
    for eid in submitted:
        if eid not in final:
            try:
                client.cancel(eid)
            except (Conflict, NotFound):
                pass
            except TwbError:
                break


def flat_metrics(metrics: dict[str, Any]) -> dict[str, Any]:
    """A run's metrics as one flat row: the planned path's become ``planned_<name>``; settings are left out."""
    out: dict[str, Any] = {}
    for k, v in metrics.items():
        if k == "planned" and isinstance(v, dict):
            out.update({f"planned_{pk}": pv for pk, pv in v.items() if not isinstance(pv, (dict, list))})
        elif not isinstance(v, (dict, list)):
            out[k] = v
    return out


def _assemble(spec: StudySpec, envs: dict[str, Environment], jobs: list[StudyJob], final: dict[int, Experiment],
              metrics: dict[int, ExperimentMetrics]) -> StudyData:
    experiments, rows, direct = [], [], []
    for job in jobs:
        eid = job.get("experiment_id")
        exp = final.get(eid) if eid is not None else None
        body = job["body"]
        experiments.append({
            "experiment_id": eid, "environment": job["environment"], "plan": job["plan"], "planner": job["planner"],
            "controller": job["controller"], "controller_params": body.get("controller_params", {}),
            "configuration": job["configuration"], "planner_params": body.get("planner_params", {}),
            "path": body.get("path"), "start": body["start"], "goal": body["goal"],
            "repetitions": body["repetitions"], "modes": body["modes"],
            "status": exp.status if exp else "rejected", "error": exp.error if exp else job.get("rejected", ""),
            "planned_path": exp.planned_path.tolist() if exp is not None and exp.planned_path is not None else None,
            "planning_time_s": exp.planning_time_s if exp else None,
            "runs": [r.id for r in exp.runs] if exp else [],
        })
        if exp is None:
            continue
        st = {d.repetition: d for d in metrics[exp.id].direct}
        ident = {"study": spec.name, "experiment_id": exp.id, "environment": job["environment"], "plan": job["plan"],
                 "planner": job["planner"], "controller": job["controller"], "configuration": job["configuration"]}
        for run in exp.runs:
            stop = run.stopped_at or [None, None]
            row = {**ident, "run_id": run.id, "mode": run.mode, "repetition": run.repetition, "seed": run.seed,
                   "status": run.status, "outcome": run.outcome, "failure": run.failure, "error": run.error,
                   "stopped_at_x": stop[0], "stopped_at_y": stop[1], "subfield": run.subfield,
                   "robot_id": run.robot_id, "t_start": run.t_start, "t_end": run.t_end, **flat_metrics(run.metrics)}
            d = st.get(run.repetition)
            if d is not None:
                row.update({f"st_{k}": v for k, v in d.metrics.items()})
            rows.append(row)
        for d in metrics[exp.id].direct:
            direct.append({**ident, "repetition": d.repetition, "sim_run_id": d.sim_run_id,
                           "twb_run_id": d.twb_run_id, **d.metrics})
    return StudyData(spec, {n: e.to_json() for n, e in envs.items()}, experiments, rows, direct)
