"""The engine's jobs by name: picklable references that load the compiled core only where they run.

A worker pool runs ``task(*args)`` in another process (or as a Ray task); pickling a
:class:`Task` sends its name, not the function, so the server that submits it never
imports :mod:`.jobs` (numba and the simulation core load in the workers alone)::

    await pool.run(tasks.SIMULATE, env_data, path, ...)   # robot_agent.engine.jobs.simulate_job
"""

from __future__ import annotations

import importlib
from typing import Any, Callable

__all__ = ["COMPARE", "CONFIGURE_WORKER", "FIELD_OBSTACLE_TRACKS", "FLEET", "MEASURE", "MOVING", "OBSTACLE_NOTE", "PLAN", "SIMULATE",
           "Task", "WARM_UP", "run_task"]

_JOBS = "robot_agent.engine.jobs"


class Task:
    """The job ``name`` of :mod:`robot_agent.engine.jobs` (or of ``module``), called where it runs."""

    __slots__ = ("module", "name")

    def __init__(self, name: str, module: str = _JOBS) -> None:
        self.module, self.name = module, name

    def __call__(self, *args: Any) -> Any:
        # the one deferred import of the engine: it happens in the worker, never in the submitting server
        return getattr(importlib.import_module(self.module), self.name)(*args)

    def __reduce__(self) -> tuple[Any, ...]:
        return Task, (self.name, self.module)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Task) and (other.module, other.name) == (self.module, self.name)

    def __hash__(self) -> int:
        return hash((self.module, self.name))

    def __repr__(self) -> str:
        return f"Task({self.module}.{self.name})"


def run_task(task: Callable[..., Any], *args: Any) -> Any:
    """``task(*args)``: a plain function for engines that take functions only (Ray's ``remote``)."""
    return task(*args)


WARM_UP = Task("warm_up")  #: ready a fresh worker (imports, the compiled core)
PLAN = Task("plan_job")  #: one experiment's path
SIMULATE = Task("simulate_job")  #: one run without a robot agent, measured
FLEET = Task("fleet_job")  #: a multi-robot run: planned, driven in one world, measured
MEASURE = Task("measure_run")  #: a run's metrics from its planned path and logged poses
COMPARE = Task("compare_runs", "robot_agent.engine.run_data")  #: the paper's direct sim-vs-field comparison
FIELD_OBSTACLE_TRACKS = Task("field_obstacle_tracks")  #: a field run's obstacle robots, replayed
OBSTACLE_NOTE = Task("obstacle_robots_note")  #: the run log's line on a field run's obstacle robots
MOVING = Task("moving_tuples", "robot_agent.engine.run_data")
CONFIGURE_WORKER = Task("configure_worker", "robot_agent.engine.limits")  #: a worker's planning limits  #: moving obstacles as ``T,T,M`` takes them
