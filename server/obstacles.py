"""Where a run's moving obstacles were: a field run's obstacle robots as the tracker saw them, else the exact
tracks (docs/protocol.md, "Moving obstacles")."""

from __future__ import annotations

from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from robot_agent.engine.run_data import exact_obstacle_tracks

from .models import Run
from .store.poses import obstacle_poses

__all__ = ["EXACT_STEP_S", "run_obstacles"]

#: the exact tracks are sampled this often (s): at 0.1 m/s a corner is cut by at most 2.5 mm
EXACT_STEP_S = 0.05


def run_obstacles(session: Session, run: Run) -> dict[str, Any]:
    """``{"exact", "obstacles": [{"index", "radius", "count", "poses"}]}``, one entry per moving obstacle of the
    run's environment, poses ``[t, x, y, theta]`` (s on the run's clock, m, m, rad in its frame), oldest first.

    ``exact`` False: the stored tracker poses of a field run's obstacle robots, each a robot of the run's
    radius (m). True: the exact tracks over the run's ``t_start`` to ``t_end`` every :data:`EXACT_STEP_S`
    (obstacle time 0 at ``t_start``; a multi-robot run's obstacles keep the fleet's clock), each disc of the
    environment's radius: a simulation's obstacles, and a field run's whose obstacle robots could not be
    replayed (its log says why) or that ran before they were stored; empty before the run started.
    """
    exp = run.experiment
    stored = obstacle_poses(session, run.id)
    moving = exp.environment_data.get("moving_obstacles") or []
    if stored:
        return {"exact": False, "obstacles": [_entry(k, exp.robot_radius, stored.get(k, [])) for k in range(len(moving))]}
    tracks: list[Any] = [[] for _ in moving]
    if run.t_start is not None and run.t_end is not None:
        zero = 0.0 if exp.robots is not None else run.t_start
        tracks = [np.round(tr, 6).tolist()
                  for tr in exact_obstacle_tracks(exp.environment_data, run.t_start, run.t_end, zero, EXACT_STEP_S)]
    return {"exact": True, "obstacles": [_entry(k, float(o["radius"]), tr) for k, (o, tr) in enumerate(zip(moving, tracks))]}


def _entry(k: int, radius: float, poses: list[list[float]]) -> dict[str, Any]:
    return {"index": k, "radius": radius, "count": len(poses), "poses": poses}
