"""A run's stored data as a :class:`~server.export.record.RunRecord`: the database read, nothing converted."""

from __future__ import annotations

from typing import Any, Optional

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from ..models import Experiment, Message, Run
from ..obstacles import run_obstacles
from ..store.poses import run_poses
from .record import LogLine, ObstacleTrack, RobotTrack, RunRecord

__all__ = ["experiment_records", "run_record"]


def run_record(session: Session, run: Run) -> RunRecord:
    """Everything an export shows of ``run``: its poses (per robot), plans, environment, moving obstacles (as
    ``GET /runs/{id}/obstacles`` gives them), protocol log and metrics (SI units, the run's clock)."""
    exp = run.experiment
    env = exp.environment_data or {}
    fleet = exp.robots is not None
    rows = np.asarray(run_poses(session, run.id, fleet=fleet), dtype=float).reshape(-1, 5 if fleet else 4)
    plans = _plans(run, exp)
    if fleet:
        robots = tuple(RobotTrack(k, np.ascontiguousarray(rows[rows[:, 4] == k, :4]), plans[k])
                       for k in range(len(exp.robots or [])))
    else:
        robots = (RobotTrack(0, rows, plans[0]),)
    moving = run_obstacles(session, run)
    obstacles = tuple(ObstacleTrack(o["index"], float(o["radius"]), np.asarray(o["poses"], dtype=float).reshape(-1, 4))
                      for o in moving["obstacles"])
    blocks = np.asarray([[b["x"], b["y"], b["w"], b["h"], b.get("angle", 0.0)] for b in env.get("blocks") or []],
                        dtype=float).reshape(-1, 5)
    size = env.get("size") or [1.8, 1.8]
    return RunRecord(run_id=run.id, experiment_id=exp.id, mode=run.mode, repetition=run.repetition, status=run.status,
                     environment=exp.environment, size=(float(size[0]), float(size[1])), blocks=blocks,
                     robot_radius=float(exp.robot_radius), robots=robots, fleet=fleet, t_start=run.t_start,
                     t_end=run.t_end, obstacles=obstacles, obstacles_exact=bool(moving["exact"]),
                     log=_log(session, run), metrics=dict(run.metrics or {}))


def experiment_records(session: Session, exp: Experiment) -> list[RunRecord]:
    """:func:`run_record` of each of the experiment's runs, in order."""
    return [run_record(session, run) for run in exp.runs]


def _plans(run: Run, exp: Experiment) -> list[Optional[np.ndarray]]:
    """Each robot's planned path ``(M, 3)`` (m, m, rad), None where not stored: the run's own (robot 0's);
    a fleet's others from the experiment's plan when it is the run's (a deterministic planner's, or
    repetition 1's)."""
    own = None if run.planned_path is None else np.asarray(run.planned_path, dtype=float).reshape(-1, 3)
    if exp.robots is None:
        return [own]
    out: list[Optional[np.ndarray]] = [own] + [None] * (len(exp.robots) - 1)
    stored: list[Any] = (exp.planning_info or {}).get("robots") or []
    if own is not None and (run.repetition == 1 or not exp.planner_stochastic) and len(stored) == len(exp.robots):
        for k in range(1, len(stored)):
            path = stored[k].get("path")
            out[k] = None if path is None else np.asarray(path, dtype=float).reshape(-1, 3)
    return out


def _log(session: Session, run: Run) -> tuple[LogLine, ...]:
    """The run's protocol lines in order; a line without a time gets the one before it, lines before the first
    timed one that line's time (the run's start, or 0, when none has a time)."""
    rows = session.execute(select(Message.t, Message.direction, Message.line)
                           .where(Message.run_id == run.id).order_by(Message.id)).all()
    first = next((float(t) for t, _, _ in rows if t is not None), None)
    last = first if first is not None else (float(run.t_start) if run.t_start is not None else 0.0)
    out = []
    for t, direction, line in rows:
        last = float(t) if t is not None else last
        out.append(LogLine(last, direction, line))
    return tuple(out)
