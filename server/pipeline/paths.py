"""Each repetition's path: an explicit path, a planner's in a worker process, or an uploaded program's.

A run gets its repetition's plan (:meth:`PathService.path_for`); the simulated
and the field run of one repetition share it: the first of them to reach
``planning`` has it made, the other waits on the repetition's lock and reuses
it (or, after a restart, reads it from its sibling run).

- A **randomised planner** (:attr:`planners.Planner.stochastic`, e.g. PRM;
  the experiment's ``planner_stochastic``) plans once per repetition with the
  repetition's planner seed (:func:`server.store.experiments.planner_seed`):
  every repetition drives its own draw.  When it finds no path, that
  repetition's runs fail (``planning``) and the others go on: another seed may
  find one, and the success rate counts it.
- A **deterministic planner** plans once per repetition too, in a warmed worker,
  so that every repetition has its own planning time; its path comes out the
  same every time, and the experiment's one path (the first one had, or the
  one stored on the experiment) is what every run drives.  When it finds no
  path the experiment fails as a whole: every run that asks gets the same
  :class:`~server.errors.RunFailed` (``whole_experiment``) and the planner is
  not tried again.
- An **uploaded program** runs once per experiment, its one path and timing
  reused by every run (its sandbox's start-up dominates any timing), unless it
  declared itself ``stochastic`` at upload: then it runs once per repetition
  with the repetition's planner seed, and fails per repetition as a randomised
  planner does.
- An **explicit path** is every run's path, with no planning time.

Repetition 1's plan is also kept on the experiment (``planned_path``,
``planning_time_s``, ``planning_info``), as before plans were per run.

An uploaded program runs sandboxed (:mod:`server.sandbox`); its output and
its robot-port conversation go to the log of the run that executed it, and
the path it sent must go from the start to the goal clear of obstacles by
the robot radius (:func:`server.validation.check_program_paths`), like an
explicit path.  A multi-robot job's program gets a robot port per robot and
sends each robot's path on its port; every path is checked so, and the plan
has them all (:attr:`Plan.robots`), which its runs then drive as explicit
per-robot paths (:mod:`server.pipeline.fleet`).
"""

from __future__ import annotations

import asyncio
import math
import weakref
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Any, Callable, Hashable, Optional

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from planners import PlanningError
from planners.api import machine_load
from robot_agent.engine import run_data, tasks

from ..core.settings import Settings
from ..errors import FailureKind, ProgramFailed, RunFailed
from ..models import Experiment, Program, Run
from ..sandbox import ProgramSpec, Sandbox
from ..sandbox.outcome import robots_phrase
from ..store.experiments import planner_seed
from ..validation import FIELD_SIZE, SUBFIELD_SIZE, check_program_paths
from .pool import ComputePool
from .recorder import RunRecorder

__all__ = ["LineLog", "PathService", "Plan", "placed"]

#: seconds past the planning deadline before the server ends a worker that did not stop the plan itself
_WATCHDOG_GRACE_S = 30.0

#: ``on_line(direction, line, t, t_estimated)``: one line for the run's protocol log
LineLog = Callable[[str, str, Optional[float], bool], None]

#: the plan columns of a run (:meth:`Plan.run_fields`)
_RUN_PLAN = ("planned_path", "planning_time_s", "planning_cpu_s", "planning_repeats", "planning_load",
             "planning_progress")


@dataclass(frozen=True)
class Plan:
    """A path ``[[x, y, theta], ...]`` (m, m, rad) and its planning: the median wall and CPU seconds of
    ``planning_repeats`` planner calls and the machine's load per CPU then (None for explicit paths; a
    program's wall time is its own, CPU unknown); for a multi-robot job's program, every robot's path in
    ``robots`` (``path`` is robot 0's).  ``note``: a line for the log of the run that had it made (None)."""

    path: list[list[float]]
    planning_time_s: Optional[float]
    robots: Optional[list[list[list[float]]]] = None
    planning_cpu_s: Optional[float] = None
    planning_repeats: Optional[int] = None
    planning_load: Optional[float] = None
    note: Optional[str] = None
    #: an anytime planner's best length so far against its planning time, ``[[t_s, length_m], ...]``
    planning_progress: Optional[list[list[float]]] = None

    def run_fields(self) -> dict[str, Any]:
        """The run's columns of this plan (stored with each run that drives it)."""
        return {k: getattr(self, "path" if k == "planned_path" else k) for k in _RUN_PLAN}


def placed(start: list[float], goal: list[float]) -> list[float]:
    """The pose the gripper places a robot at (m, m, rad): ``start`` with its heading, else facing the goal."""
    if len(start) > 2:
        return list(start[:3])
    return [*start[:2], math.atan2(goal[1] - start[1], goal[0] - start[0])]


def _trim(d: OrderedDict[Any, Any], most: int) -> None:
    while len(d) > most:
        d.popitem(last=False)


class PathService:
    """Gets each repetition's path once (see the module docstring)."""

    def __init__(self, sessions: sessionmaker[Session], recorder: RunRecorder, pool: ComputePool, sandbox: Sandbox,
                 settings: Settings) -> None:
        self._sessions = sessions
        self._recorder = recorder
        self._pool = pool
        self._sandbox = sandbox
        self._settings = settings
        #: a repetition's lock ``(experiment, repetition)``; an experiment's ``("experiment", id)``
        self._locks: weakref.WeakValueDictionary[Hashable, asyncio.Lock] = weakref.WeakValueDictionary()
        self._failures: OrderedDict[int, RunFailed] = OrderedDict()  # experiments that failed as a whole
        self._rep_failures: OrderedDict[tuple[int, int], RunFailed] = OrderedDict()  # repetitions that did
        self._plans: OrderedDict[tuple[int, int], Plan] = OrderedDict()  # recent repetitions' plans
        self._paths: OrderedDict[int, Plan] = OrderedDict()  # recent experiments' one path (deterministic)

    def _lock(self, key: Hashable) -> asyncio.Lock:
        lock = self._locks.get(key)
        if lock is None:
            lock = self._locks[key] = asyncio.Lock()
        return lock

    async def path_for(self, experiment_id: int, repetition: int = 1, *, run_id: Optional[int] = None,
                       robot_id: str = "robot", platform: str = "BeBot", on_line: Optional[LineLog] = None) -> Plan:
        """The repetition's plan; raises :class:`RunFailed` when there is none (``whole_experiment`` when no run of
        the experiment can have one).

        ``run_id``, ``robot_id``, ``platform``, ``on_line``: the run asking, for
        an uploaded program (its environment, and the run's log of its output)
        and a note on the plan.
        """
        key = (experiment_id, repetition)
        known = self._plans.get(key)
        if known is not None:
            return known
        async with self._lock(key):
            known = self._plans.get(key)
            if known is not None:
                return known
            failure = self._failures.get(experiment_id) or self._rep_failures.get(key)
            if failure is not None:
                raise failure
            try:
                plan = await self._plan(experiment_id, repetition, run_id, robot_id, platform, on_line)
            except RunFailed as exc:
                if exc.whole_experiment:
                    self._failures[experiment_id] = exc
                    _trim(self._failures, 10_000)
                else:
                    self._rep_failures[key] = exc
                    _trim(self._rep_failures, 10_000)
                raise
            if plan.note is not None:
                if on_line is not None:
                    on_line("s", plan.note, None, False)
                plan = replace(plan, note=None)
            self._plans[key] = plan
            _trim(self._plans, 4_096)
            return plan

    async def program_spec(self, program_id: Optional[int]) -> Optional[ProgramSpec]:
        """An uploaded program as the sandbox runs it, or None if it no longer exists."""
        def load() -> Optional[ProgramSpec]:
            with self._sessions() as s:
                p = s.get(Program, program_id) if program_id is not None else None
                return None if p is None else ProgramSpec(p.id, p.name, p.kind, p.interpreter, list(p.args or []),
                                                          p.content)

        return await asyncio.to_thread(load)

    def known(self, experiment_id: int, repetition: int = 1) -> Optional[Plan]:
        """The repetition's plan if it was had recently (no database read), else None."""
        return self._plans.get((experiment_id, repetition))

    async def _plan(self, experiment_id: int, repetition: int, run_id: Optional[int], robot_id: str, platform: str,
                    on_line: Optional[LineLog]) -> Plan:
        def load() -> tuple[Experiment, Optional[Plan]]:
            with self._sessions() as s:
                exp = s.get(Experiment, experiment_id)
                rows = s.execute(select(*(getattr(Run, k) for k in _RUN_PLAN)).where(
                    Run.experiment_id == experiment_id, Run.repetition == repetition)).all()
            # a run of the repetition that had it made before a restart: its sibling drives the same plan
            had = next((r for r in rows if r.planned_path is not None), None)
            return exp, None if had is None else Plan(had.planned_path, had.planning_time_s, None,
                                                      had.planning_cpu_s, had.planning_repeats, had.planning_load,
                                                      planning_progress=had.planning_progress)

        exp, had = await asyncio.to_thread(load)
        stochastic = bool(exp.planner_stochastic)
        if had is not None and exp.robots is None:
            return had
        seed = planner_seed(exp.seed if exp.planner_seed is None else exp.planner_seed, repetition)
        if exp.robots is not None or exp.explicit_path is not None or exp.program_id is not None or exp.planner is None:
            if stochastic:  # a stochastic program: once per repetition, with its planner seed
                plan, info = await self._program_plan(exp, seed, run_id, robot_id, platform, on_line, whole=False)
                if repetition == 1:
                    await self._recorder.store_plan(exp.id, plan.path, plan.planning_time_s, info)
                return plan
            return await self._experiment_plan(exp, run_id, robot_id, platform, on_line)
        try:
            r = await self._planned(tasks.PLAN, exp.environment_data, exp.start, exp.goal, exp.planner,
                                    exp.planner_params or {}, seed, exp.robot_radius + exp.planning_margin,
                                    self._settings.planning_timing_budget_s)
        except PlanningError as exc:
            raise RunFailed(f"planning failed: {exc}", FailureKind.PLANNING, whole_experiment=not stochastic) from None
        plan = Plan(r["path"], r["planning_time_s"], None, r.get("planning_cpu_s"), r.get("planning_repeats"),
                    r.get("planning_load"), planning_progress=(r.get("info") or {}).get("progress") or None)
        if not stochastic:  # the experiment's one path: the same every time, and the one every run drives
            one = self._paths.get(exp.id)
            if one is None and exp.planned_path is not None:
                one = Plan(exp.planned_path, exp.planning_time_s)
            if one is None:
                self._paths[exp.id] = plan
                _trim(self._paths, 1_000)
            elif one.path != plan.path:
                plan = replace(plan, path=one.path, note=(
                    f"planner {exp.planner!r} is deterministic but planned another path this time (it was "
                    "timed again for this repetition); the experiment's path is driven, as by every run of it "
                    "(a planner whose path depends on its seed declares itself stochastic: docs/planners.md)"))
        if repetition == 1:
            await self._recorder.store_plan(exp.id, plan.path, plan.planning_time_s,
                                            r.get("info", {}) if plan.note is None else exp.planning_info or {})
        return plan

    async def _planned(self, task: Any, *args: Any) -> Any:
        """``task(*args)`` on the pool, watched: the worker ends a plan past the planning deadline itself
        (:mod:`robot_agent.engine.limits`) unless it is stuck in compiled code; 30 s after the deadline the
        workers are ended (the pool replaces them) and the plan fails as having run out of time."""
        deadline = float(getattr(self._pool, "deadline_s", 0.0) or 0.0)
        if deadline <= 0:
            return await self._pool.run(task, *args)
        try:
            return await asyncio.wait_for(self._pool.run(task, *args), deadline + _WATCHDOG_GRACE_S)
        except TimeoutError:
            self._pool.kill()
            raise PlanningError(f"the planning time limit of {deadline:g} s was reached and the plan did not stop: "
                                "its worker was ended") from None

    async def _experiment_plan(self, exp: Experiment, run_id: Optional[int], robot_id: str, platform: str,
                               on_line: Optional[LineLog]) -> Plan:
        """The experiment's one path, had once for all its runs: explicit, or a deterministic program's."""
        async with self._lock(("experiment", exp.id)):
            if exp.id in self._failures:
                raise self._failures[exp.id]
            one = self._paths.get(exp.id)
            if one is not None:
                return one
            stored, seconds = await self._recorder.planned_path(exp.id)
            if stored is not None:
                robots = (exp.planning_info or {}).get("robots") if exp.robots is not None else None
                one = Plan(stored, seconds, [r["path"] for r in robots] if robots else None,
                           planning_repeats=None if seconds is None else 1)
            elif exp.robots is None and exp.explicit_path is not None:
                path = run_data.explicit_path(exp.explicit_path, exp.goal)
                await self._recorder.store_plan(exp.id, path, None, {"explicit": True})
                one = Plan(path, None)
            else:
                try:
                    one, info = await self._program_plan(exp, exp.seed, run_id, robot_id, platform, on_line,
                                                         whole=True)
                except RunFailed as exc:
                    self._failures[exp.id] = exc
                    raise
                await self._recorder.store_plan(exp.id, one.path, one.planning_time_s, info)
            self._paths[exp.id] = one
            _trim(self._paths, 1_000)
            return one

    async def _program_plan(self, exp: Experiment, seed: int, run_id: Optional[int], robot_id: str, platform: str,
                            on_line: Optional[LineLog], *, whole: bool) -> tuple[Plan, dict[str, Any]]:
        """The experiment's program run with ``seed``: its plan (a multi-robot job's: every robot's path) and
        info; :class:`ProgramFailed` (``whole``: for the whole experiment, else for the repetition)."""
        try:
            paths, seconds, info = await self._from_program(exp, seed, run_id, robot_id, platform, on_line)
        except ProgramFailed as exc:
            exc.whole_experiment = whole
            raise
        fleet = exp.robots is not None
        return Plan(paths[0] if fleet else paths, seconds, paths if fleet else None, None,
                    None if seconds is None else 1, machine_load()), info

    async def _from_program(self, exp: Experiment, seed: int, run_id: Optional[int], robot_id: str, platform: str,
                            on_line: Optional[LineLog]) -> tuple[Any, Optional[float], dict[str, Any]]:
        """Run the experiment's uploaded program; its path (a multi-robot job's: every robot's, one per robot
        port, each checked as a single robot's; the info then has them in ``robots``), planning time and info,
        or :class:`ProgramFailed` (naming the robots without a usable path)."""
        try:
            return await self._run_program(exp, seed, run_id, robot_id, platform, on_line)
        except ProgramFailed as exc:
            await self._recorder.store_planning_info(exp.id, exc.info)
            raise

    async def _run_program(self, exp: Experiment, seed: int, run_id: Optional[int], robot_id: str, platform: str,
                           on_line: Optional[LineLog]) -> tuple[Any, Optional[float], dict[str, Any]]:
        if not self._settings.uploads_enabled:
            raise ProgramFailed("uploads are disabled on this testbed")
        spec = await self.program_spec(exp.program_id)
        if spec is None:
            raise ProgramFailed("the experiment's program no longer exists")
        fleet = exp.robots is not None
        # each robot's start with the heading the gripper places it with (steps.place), and its goal
        robots = exp.robots if fleet else [{"start": exp.start, "goal": exp.goal}]
        starts = [placed(r["start"], r["goal"]) for r in robots]
        goals = [list(r["goal"]) for r in robots]
        common = dict(env_data=exp.environment_data, field_size=SUBFIELD_SIZE if exp.field == "sub" else FIELD_SIZE,
                      seed=seed, robot_radius=exp.robot_radius, planning_margin=exp.planning_margin,
                      robot_id=robot_id, platform=platform)
        outcome = await (self._sandbox.run_fleet(spec, starts=starts, goals=goals, **common) if fleet
                         else self._sandbox.run(spec, start=starts[0], goal=goals[0], **common))
        if on_line is not None:
            for direction, line in outcome.log:
                on_line(direction, line, None, False)
        info: dict[str, Any] = {"program": {**outcome.info, "run_id": run_id}}
        paths = outcome.paths if fleet else None if outcome.path is None else [outcome.path]
        if paths is None:
            raise ProgramFailed(outcome.reason or "program sent no path", info)
        problems = await self._pool.run(check_program_paths, exp.environment_data, starts, goals, paths,
                                        exp.robot_radius)
        bad = [k for k, why in enumerate(problems) if why is not None]
        if bad:
            reason = (f"program's path is unusable: {problems[0]}" if not fleet else
                      f"program's path for robot {bad[0]} is unusable: {problems[bad[0]]}" if len(bad) == 1 else
                      f"program's paths for {robots_phrase(bad)} are unusable: "
                      + "; ".join(f"robot {k}: {problems[k]}" for k in bad))
            if on_line is not None:
                on_line("s", reason, None, False)
            raise ProgramFailed(reason, info)
        if not fleet:
            return paths[0], outcome.planning_time_s, info
        info["robots"] = [{"path": p, "depart": None} for p in paths]
        return paths, outcome.planning_time_s, info
