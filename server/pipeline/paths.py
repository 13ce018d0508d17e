"""An experiment's path, had once: its explicit path, a planner's in a worker process, or its program's.

The first run of an experiment that reaches ``planning`` gets the path and
stores it; runs after it (or waiting for it: another mode running in
parallel) read the stored one.  When no path can be had, the experiment
fails as a whole: every run that asks gets the same
:class:`~server.errors.RunFailed` (``whole_experiment``) and the planner or
program is not tried again.

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
from dataclasses import dataclass
from typing import Any, Callable, Optional

from sqlalchemy.orm import Session, sessionmaker

from planners import PlanningError
from robot_agent.engine import run_data, tasks

from ..core.settings import Settings
from ..errors import FailureKind, ProgramFailed, RunFailed
from ..models import Experiment, Program
from ..sandbox import ProgramSpec, Sandbox
from ..sandbox.outcome import robots_phrase
from ..validation import FIELD_SIZE, SUBFIELD_SIZE, check_program_paths
from .pool import ComputePool
from .recorder import RunRecorder

__all__ = ["LineLog", "PathService", "Plan", "placed"]

#: ``on_line(direction, line, t, t_estimated)``: one line for the run's protocol log
LineLog = Callable[[str, str, Optional[float], bool], None]


@dataclass(frozen=True)
class Plan:
    """A path ``[[x, y, theta], ...]`` (m, m, rad) and how long planning took (s; None for explicit paths);
    for a multi-robot job's program, every robot's path in ``robots`` (``path`` is robot 0's)."""

    path: list[list[float]]
    planning_time_s: Optional[float]
    robots: Optional[list[list[list[float]]]] = None


def placed(start: list[float], goal: list[float]) -> list[float]:
    """The pose the gripper places a robot at (m, m, rad): ``start`` with its heading, else facing the goal."""
    if len(start) > 2:
        return list(start[:3])
    return [*start[:2], math.atan2(goal[1] - start[1], goal[0] - start[0])]


class PathService:
    """Gets each experiment's path once (see the module docstring)."""

    def __init__(self, sessions: sessionmaker[Session], recorder: RunRecorder, pool: ComputePool, sandbox: Sandbox,
                 settings: Settings) -> None:
        self._sessions = sessions
        self._recorder = recorder
        self._pool = pool
        self._sandbox = sandbox
        self._settings = settings
        self._locks: weakref.WeakValueDictionary[int, asyncio.Lock] = weakref.WeakValueDictionary()
        self._failures: OrderedDict[int, RunFailed] = OrderedDict()
        self._plans: OrderedDict[int, Plan] = OrderedDict()  # recent experiments' paths (they never change)

    async def path_for(self, experiment_id: int, *, run_id: Optional[int] = None, robot_id: str = "robot",
                       platform: str = "BeBot", on_line: Optional[LineLog] = None) -> Plan:
        """The experiment's path; raises :class:`RunFailed` (``whole_experiment``) when there is none.

        ``run_id``, ``robot_id``, ``platform``, ``on_line``: the run asking, for
        an uploaded program (its environment, and the run's log of its output).
        """
        known = self.known(experiment_id)
        if known is not None:
            return known
        lock = self._locks.get(experiment_id)
        if lock is None:
            lock = self._locks[experiment_id] = asyncio.Lock()
        async with lock:
            if experiment_id in self._failures:
                raise self._failures[experiment_id]
            try:
                plan = await self._plan(experiment_id, run_id, robot_id, platform, on_line)
            except RunFailed as exc:
                self._failures[experiment_id] = exc
                while len(self._failures) > 10_000:
                    self._failures.popitem(last=False)
                raise
            self._plans[experiment_id] = plan
            while len(self._plans) > 1_000:
                self._plans.popitem(last=False)
            return plan

    async def program_spec(self, program_id: Optional[int]) -> Optional[ProgramSpec]:
        """An uploaded program as the sandbox runs it, or None if it no longer exists."""
        def load() -> Optional[ProgramSpec]:
            with self._sessions() as s:
                p = s.get(Program, program_id) if program_id is not None else None
                return None if p is None else ProgramSpec(p.id, p.name, p.kind, p.interpreter, list(p.args or []),
                                                          p.content)

        return await asyncio.to_thread(load)

    def known(self, experiment_id: int) -> Optional[Plan]:
        """The experiment's path if it was had recently (no database read), else None."""
        return self._plans.get(experiment_id)

    async def _plan(self, experiment_id: int, run_id: Optional[int], robot_id: str, platform: str,
                    on_line: Optional[LineLog]) -> Plan:
        def load() -> Experiment:
            with self._sessions() as s:
                return s.get(Experiment, experiment_id)

        exp = await asyncio.to_thread(load)
        if exp.planned_path is not None:
            robots = (exp.planning_info or {}).get("robots") if exp.robots is not None else None
            return Plan(exp.planned_path, exp.planning_time_s, [r["path"] for r in robots] if robots else None)
        if exp.robots is not None:
            paths, seconds, info = await self._from_program(exp, run_id, robot_id, platform, on_line)
            await self._recorder.store_plan(experiment_id, paths[0], seconds, info)
            return Plan(paths[0], seconds, paths)
        if exp.explicit_path is not None:
            path, seconds, info = run_data.explicit_path(exp.explicit_path, exp.goal), None, {"explicit": True}
        elif exp.program_id is not None or exp.planner is None:
            path, seconds, info = await self._from_program(exp, run_id, robot_id, platform, on_line)
        else:
            try:
                r = await self._pool.run(tasks.PLAN, exp.environment_data, exp.start, exp.goal, exp.planner,
                                         exp.planner_params or {}, exp.seed, exp.robot_radius + exp.planning_margin)
            except PlanningError as exc:
                raise RunFailed(f"planning failed: {exc}", FailureKind.PLANNING, whole_experiment=True) from None
            path, seconds, info = r["path"], r["planning_time_s"], r.get("info", {})
        await self._recorder.store_plan(experiment_id, path, seconds, info)
        return Plan(path, seconds)

    async def _from_program(self, exp: Experiment, run_id: Optional[int], robot_id: str, platform: str,
                            on_line: Optional[LineLog]) -> tuple[Any, Optional[float], dict[str, Any]]:
        """Run the experiment's uploaded program; its path (a multi-robot job's: every robot's, one per robot
        port, each checked as a single robot's; the info then has them in ``robots``), planning time and info,
        or :class:`ProgramFailed` (naming the robots without a usable path)."""
        try:
            return await self._run_program(exp, run_id, robot_id, platform, on_line)
        except ProgramFailed as exc:
            await self._recorder.store_planning_info(exp.id, exc.info)
            raise

    async def _run_program(self, exp: Experiment, run_id: Optional[int], robot_id: str, platform: str,
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
                      seed=exp.seed, robot_radius=exp.robot_radius, planning_margin=exp.planning_margin,
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
