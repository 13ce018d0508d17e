"""Running a study against a testbed: submit every experiment, follow them, collect the results."""

from __future__ import annotations

import hashlib
import sys
import tempfile
import time
from collections import Counter
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Optional

from contract.vocabulary import JUDGED, Mode, TERMINAL
from planners.compared import LABEL_LENGTH, PROBLEM_LENGTH, flat_metrics, shorten
from planners.comparisons import problem_name

from .._client import Client
from .._exceptions import Conflict, NotFound, RateLimited, TwbError, ValidationError
from .._models import Environment, Experiment, ExperimentMetrics
from ._data import StudyData
from ._fleet_results import fleet_row
from ._limits import StudyRefused, check_study, refusal
from ._spec import ControllerChoice, PlannerSpec, PlanSpec, ProfileSpec, StudySpec, StudySpecError
from ._stream import StudySink

__all__ = ["StudyJob", "StudyRefused", "configuration", "flat_metrics", "plan_jobs", "run_study", "study_planner_seed"]


class StudyJob(dict):
    """One experiment of a study: environment, plan, planner, configuration and the job body sent to the server."""


def study_planner_seed(seed: int, configuration: str, environment: str, plan: str) -> int:
    """The planner seed of a study's experiment: a stable hash of the study's ``seed``, the ``configuration`` (its
    full name, controller and profile variant included), the ``environment`` and the ``plan`` (docs/study.md,
    "Seeds").  Every experiment keeps the study's ``seed`` for its noise (common random numbers: repetition k
    of every configuration and problem gets the same noise stream and start jitter), while a randomised
    planner's draws are distinct per configuration, problem and repetition (the testbed derives each
    repetition's planner seed from this one, the same for both modes)."""
    digest = hashlib.sha256(f"study-planner:{seed}:{configuration}:{environment}:{plan}".encode()).digest()
    return int.from_bytes(digest[:8], "big") >> 1


def _body(name: str, problem: dict[str, Any], planner: PlannerSpec, controller: Optional[ControllerChoice],
          spec: StudySpec, profile: Optional[ProfileSpec] = None, *, label: str = "", plan: str = "") -> dict[str, Any]:
    """The job sent to the server for one problem (``{"start", "goal"}``, or a fleet's ``{"robots"}``; m, rad) and
    configuration (an explicit path: start, waypoints, goal), with the robots' ``controller`` and the field
    robot's ``profile`` variant; named on the server as in runs.csv: the configuration's ``label`` and the
    problem ``<environment> <plan>`` (so ``GET /api/v1/comparisons`` of the study's experiments groups them as
    the study does)."""
    body: dict[str, Any] = {"environment": name, **problem}
    if label:
        body["label"] = shorten(label, LABEL_LENGTH)
    if plan:
        body["problem"] = shorten(problem_name((name, plan)), PROBLEM_LENGTH)
    if planner.waypoints is not None:
        body["path"] = [list(problem["start"]), *[list(w) for w in planner.waypoints], list(problem["goal"])]
    else:
        body.update(planner=planner.name, planner_params=dict(planner.params))
    body.update(modes=list(spec.modes), repetitions=spec.repetitions, seed=spec.seed, field=spec.field)
    if spec.jitter is not None:
        body["jitter"] = dict(spec.jitter)
    if profile is not None and profile.overrides:
        body["profile_overrides"] = dict(profile.overrides)
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
            problem = _problem(plan, env)
            for planner, controller, config in spec.configurations():
                for profile in spec.profiles or [None]:
                    label = configuration(config, profile)
                    body = _body(name, problem, planner, controller, spec, profile, label=label, plan=plan.name)
                    if planner.waypoints is None:  # its planner's own seed: distinct per configuration and problem
                        body["planner_seed"] = study_planner_seed(spec.seed, label, name, plan.name)
                    job = StudyJob(environment=name, plan=plan.name,
                                   planner=planner.name if planner.waypoints is None else "path",
                                   controller=controller.name if controller is not None else "schema",
                                   configuration=label, profile=profile.label if profile else "", body=body)
                    if plan.fleet:
                        job["robots"] = plan.robot_count
                    jobs.append(job)
    return jobs


def _problem(plan: PlanSpec, env: Environment) -> dict[str, Any]:
    """A plan's poses in ``env``: ``{"start", "goal"}`` (a plan of the environment's, or explicit), or a fleet's
    ``{"robots": [{"start", "goal"}, ...]}`` (a circle around the environment's centre); m, rad."""
    if plan.circle is not None:
        return {"robots": plan.circle.robots_in(env.size)}
    if plan.robots is not None:
        return {"robots": [dict(r) for r in plan.robots]}
    if plan.start is not None:
        return {"start": list(plan.start), "goal": list(plan.goal or [])}
    try:
        p = env.plan(plan.name)
    except KeyError as exc:
        raise ValueError(str(exc.args[0])) from None
    return {"start": list(p.start), "goal": list(p.goal)}


def configuration(name: str, profile: Optional[ProfileSpec]) -> str:
    """A compared configuration's name: the planner's (and controller's, ``fmm/pure_pursuit``), with the field
    robot's variant if any (``fmm · tracker 3 mm``)."""
    return name if profile is None else f"{name} · {profile.label}"


#: how many of the oldest unfinished experiments are looked at per poll (the queue runs them about in order)
_WINDOW = 16


class _StudyProgress:
    """Runs done of the total, runs/s over the last half minute and the time left: a bar on a terminal, a line
    every ``every_s`` otherwise (logs)."""

    def __init__(self, name: str, total: int, enabled: bool, *, every_s: float = 10.0) -> None:
        self._name, self._total, self._enabled, self._every_s = name, total, enabled, every_s
        self._samples: list[tuple[float, int]] = []
        self._printed = time.monotonic()
        self._p = None
        if not enabled or not sys.stderr.isatty():
            return
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self._p = Progress(TextColumn(f"study {name}"), BarColumn(), MofNCompleteColumn(), TextColumn("runs"),
                           TimeElapsedColumn(), TextColumn("{task.fields[rate]}"), TextColumn("{task.fields[states]}"),
                           console=Console(stderr=True))
        self._task = self._p.add_task("", total=total, rate="", states="submitting")
        self._p.start()

    def rate(self, done: int, now: float) -> tuple[Optional[float], Optional[float]]:
        """Runs per second over the last 30 s of samples and the seconds left at that rate (None: unknown)."""
        self._samples.append((now, done))
        while len(self._samples) > 2 and now - self._samples[1][0] >= 30.0:
            self._samples.pop(0)
        (t0, d0), (t1, d1) = self._samples[0], self._samples[-1]
        if t1 - t0 < 1.0 or d1 <= d0:
            return None, None
        per_s = (d1 - d0) / (t1 - t0)
        return per_s, (self._total - done) / per_s

    def update(self, done: int, states: str) -> None:
        if not self._enabled:
            return
        now = time.monotonic()
        per_s, left = self.rate(done, now)
        rate = "" if per_s is None else f"{per_s:.1f} runs/s, ETA {_duration(left)}"
        if self._p is not None:
            self._p.update(self._task, completed=done, rate=rate, states=states)
        elif now - self._printed >= self._every_s or done == self._total:
            self._printed = now
            print(f"study {self._name}: {done}/{self._total} runs{', ' + rate if rate else ''}; {states}",
                  file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._p is not None:
            self._p.stop()


def _duration(seconds: Optional[float]) -> str:
    if seconds is None:
        return "?"
    m, s = divmod(int(round(seconds)), 60)
    h, m = divmod(m, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def run_study(client: Client, spec: StudySpec, *, progress: Optional[bool] = None, timeout: Optional[float] = None,
              interval: float = 0.5, out: Optional[str | Path] = None) -> StudyData:
    """Submit every experiment of ``spec``, follow them and collect runs, metrics and poses (and the field runs'
    tracked obstacle robots) into ``out``.

    Before submitting, the study is checked against the testbed
    (:func:`~client_sdk.study._limits.check_study`: planners, environments,
    the limits the server states); :class:`StudyRefused` lists every problem
    and nothing is submitted.  A refusal that dooms the whole study (too many
    repetitions, the queue quota) also raises :class:`StudyRefused`, after
    cancelling what was submitted.  A job the server refuses for its own
    reason (422, e.g. a start inside an obstacle) is kept as an experiment
    with status ``rejected`` and the server's reason; the others go on.

    Results are written to ``out`` (default: a new temporary directory) as
    each experiment finishes (:class:`~client_sdk.study._stream.StudySink`),
    so a study of thousands of runs keeps no poses in memory; the returned
    data reads them from there.  ``progress`` (default: when stderr is a
    terminal) shows runs done / total, runs/s and the time left (a line every
    10 s when stderr is not a terminal).  On Ctrl-C or a timeout the
    unfinished experiments are cancelled.
    """
    t0 = time.monotonic()
    started = datetime.now(timezone.utc)
    reasons = check_study(client, spec)
    if reasons:
        raise StudyRefused(reasons)
    envs = _environments(client, spec)
    jobs = plan_jobs(spec, envs)
    total = len(jobs) * spec.runs_per_experiment
    sink = StudySink(Path(out) if out is not None else Path(tempfile.mkdtemp(prefix="twb-study-")))
    bar = _StudyProgress(spec.name, total, sys.stderr.isatty() if progress is None else progress)
    submitted: dict[int, StudyJob] = {}
    final: dict[int, dict[str, Any]] = {}  # experiment id -> its entry in study.json
    ended: Counter[str] = Counter()  # run statuses of the finished experiments
    waiting = list(enumerate(jobs))  # not submitted yet
    pending: list[int] = []  # submitted, not finished, oldest first
    try:
        while waiting or pending:
            waiting = _submit(client, spec, jobs, waiting, submitted, pending, final)
            states: Counter[str] = Counter()
            for eid in pending[:_WINDOW]:
                exp = client.get_experiment(eid)
                if exp.finished:
                    final[eid] = _collect_experiment(client, spec, submitted[eid], exp, sink,
                                                     bool(envs[submitted[eid]["environment"]].moving_obstacles))
                    ended.update(r.status for r in exp.runs)
                else:
                    states.update(r.status for r in exp.runs)
            pending[:] = [eid for eid in pending if eid not in final]
            states.update(ended)
            states["queued"] += sum(_runs(submitted[eid]) for eid in pending[_WINDOW:]) + \
                sum(_runs(job) for _, job in waiting)
            done = sum(n for st, n in states.items() if st in TERMINAL)
            bar.update(done, " ".join(f"{st} {n}" for st, n in sorted(states.items()) if n))
            if not (waiting or pending):
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
    experiments = [final.get(job.get("experiment_id"), None) or _experiment_entry(job, None) for job in jobs]
    meta = {"server": client.url, "started_at": started.isoformat(timespec="seconds"),
            "wall_s": round(time.monotonic() - t0, 3), "runs": total}
    return sink.close(spec, {n: e.to_json() for n, e in envs.items()}, experiments, meta)


def _runs(job: StudyJob) -> int:
    return job["body"]["repetitions"] * len(job["body"]["modes"])


def _submit(client: Client, spec: StudySpec, jobs: list[StudyJob], waiting: list[tuple[int, StudyJob]],
            submitted: dict[int, StudyJob], pending: list[int], final: dict[int, Any]) -> list[tuple[int, StudyJob]]:
    """Submit waiting jobs until the testbed's queue quota says wait (429 while experiments of this study are
    still unfinished: a large study is paced, the rest goes in as they finish); the jobs still waiting.

    A refusal that dooms the study (:func:`refusal`: the repetitions limit, or the quota with nothing of this
    study left to finish) cancels what was submitted and raises :class:`StudyRefused`; a job refused for its
    own reason is recorded as ``rejected``.
    """
    while waiting:
        i, job = waiting[0]
        try:
            exp = client.submit(job["body"])
            job["experiment_id"] = exp.id
            submitted[exp.id] = job
            pending.append(exp.id)
        except (ValidationError, RateLimited) as exc:
            if exc.status == 429 and pending:
                return waiting  # the quota: go on when some of the study's experiments have finished
            doom = refusal(exc, spec, i, len(jobs))
            if doom is not None:
                _cancel(client, submitted, final)
                raise StudyRefused([doom + (f"; the {len(pending)} unfinished experiment(s) it had submitted were "
                                            "cancelled" if pending else "")]) from None
            job["experiment_id"], job["rejected"] = None, exc.detail if isinstance(exc.detail, str) else str(exc)
        waiting = waiting[1:]
    return waiting


def _collect_experiment(client: Client, spec: StudySpec, job: StudyJob, exp: Experiment, sink: StudySink,
                        moving: bool) -> dict[str, Any]:
    """A finished experiment's rows, poses and (``moving``: its environment has moving obstacles) its field runs'
    tracked obstacle robots to the sink; its entry in study.json."""
    rows, direct = _rows(spec, job, exp, client.get_metrics(exp.id))
    poses, obstacles = {}, {}
    for run in exp.runs:
        # a failed run's driving is data too: Fig. 8 draws it up to where it stopped
        if run.status not in JUDGED or run.t_start is None:
            continue
        try:
            poses[run.id] = client.get_poses(run.id)
            # only a field run can have obstacle robots: a simulation's would be the exact tracks, not fetched
            if moving and run.mode == Mode.TWB:
                tracked = client.get_obstacles(run.id)
                if not tracked.exact:
                    obstacles[run.id] = tracked
        except NotFound:
            pass
    sink.add(rows, direct, poses, obstacles)
    return _experiment_entry(job, exp)


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


def _experiment_entry(job: StudyJob, exp: Optional[Experiment]) -> dict[str, Any]:
    """An experiment's entry in study.json: its job, how it ended and its runs (``rejected``: never submitted)."""
    body = job["body"]
    robots = body.get("robots")
    entry = {
        "experiment_id": job.get("experiment_id"), "environment": job["environment"], "plan": job["plan"],
        "planner": job["planner"], "controller": job["controller"],
        "controller_params": body.get("controller_params", {}), "configuration": job["configuration"],
        "profile": job.get("profile", ""),
        "profile_overrides": body.get("profile_overrides", {}), "planner_params": body.get("planner_params", {}),
        "path": body.get("path"), "start": robots[0]["start"] if robots else body["start"],
        "goal": robots[0]["goal"] if robots else body["goal"], "repetitions": body["repetitions"],
        "modes": body["modes"],
        "status": exp.status if exp else "rejected", "error": exp.error if exp else job.get("rejected", ""),
        "planned_path": exp.planned_path.tolist() if exp is not None and exp.planned_path is not None else None,
        "planning_time_s": exp.planning_time_s if exp else None,
        "planner_seed": body.get("planner_seed"),
        "planner_stochastic": bool(exp.planner_stochastic) if exp else False,
        "runs": [r.id for r in exp.runs] if exp else [],
    }
    if exp is not None and exp.planner_stochastic and not robots:
        # a randomised planner: every repetition's own plan (``planned_path`` is repetition 1's)
        entry["repetition_paths"] = {str(r.repetition): r.planned_path.tolist() for r in exp.runs
                                     if r.planned_path is not None and len(r.planned_path)}
    progress = {str(r.repetition): r.planning_progress.tolist() for r in (exp.runs if exp is not None else [])
                if r.planning_progress is not None and len(r.planning_progress)}
    if progress:
        # an anytime planner's best length over its planning time, each repetition's ([[t_s, length_m], ...])
        entry["repetition_progress"] = progress
    if robots:
        # a fleet: every robot's start and goal, and the path planned for each (None where planning failed)
        entry["robots"] = robots
        planned = (exp.planning_info or {}).get("robots") or [] if exp is not None else []
        entry["planned_paths"] = [r.get("path") for r in planned] or None
    return entry


def _rows(spec: StudySpec, job: StudyJob, exp: Experiment,
          metrics: ExperimentMetrics) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """A finished experiment's rows of runs.csv and direct.csv."""
    rows, direct = [], []
    st = {d.repetition: d for d in metrics.direct}
    ident = {"study": spec.name, "experiment_id": exp.id, "environment": job["environment"], "plan": job["plan"],
             "planner": job["planner"], "controller": job["controller"], "configuration": job["configuration"],
             "profile": job.get("profile", "")}
    for run in exp.runs:
        stop = run.stopped_at or [None, None]
        row = {**ident, "run_id": run.id, "mode": run.mode, "repetition": run.repetition, "seed": run.seed,
               "planner_seed": run.planner_seed,
               "status": run.status, "outcome": run.outcome, "failure": run.failure, "error": run.error,
               "stopped_at_x": stop[0], "stopped_at_y": stop[1], "subfield": run.subfield,
               "robot_id": run.robot_id, "t_start": run.t_start, "t_end": run.t_end}
        if "robots" in job:
            row.update(fleet_row(job["robots"], run.outcome, run.metrics))
        else:
            row.update(flat_metrics(run.metrics))
        # the run's own planning (its repetition's); planned_* above are its own planned path's
        row.update(planning_time_s=run.planning_time_s if run.planning_time_s is not None
                   else row.get("planning_time_s"), planning_cpu_s=run.planning_cpu_s,
                   planning_repeats=run.planning_repeats, planning_load=run.planning_load)
        d = st.get(run.repetition)
        if d is not None:
            row.update({f"st_{k}": v for k, v in d.metrics.items()})
        rows.append(row)
    for d in metrics.direct:
        direct.append({**ident, "repetition": d.repetition, "sim_run_id": d.sim_run_id,
                       "twb_run_id": d.twb_run_id, **d.metrics})
    return rows, direct
