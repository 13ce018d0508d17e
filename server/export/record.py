"""What an export is made of: a run's stored data as plain values (no database, no I/O).

Units are SI throughout (docs/design.md, "Units and frames"): times ``t`` are
seconds of experiment time on the run's clock; positions metres and angles
radians in the frame of the experiment's field (a sub-field's lower-left
corner is its origin).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

__all__ = ["LogLine", "ObstacleTrack", "RobotTrack", "RunRecord"]


@dataclass(frozen=True)
class RobotTrack:
    """One robot of a run: ``index`` (its place in a multi-robot job's ``robots``; 0 for a single robot),
    ``poses`` ``(N, 4)`` t, x, y, theta (s, m, m, rad), oldest first, and ``planned`` ``(M, 3)`` x, y, theta
    (m, m, rad), the path it was given, or None when not stored."""

    index: int
    poses: np.ndarray
    planned: Optional[np.ndarray] = None


@dataclass(frozen=True)
class ObstacleTrack:
    """One moving obstacle of the environment: ``index`` in its ``moving_obstacles``, ``radius`` (m) and
    ``poses`` ``(T, 4)`` t, x, y, theta (s, m, m, rad), oldest first."""

    index: int
    radius: float
    poses: np.ndarray


@dataclass(frozen=True)
class LogLine:
    """A protocol line of the run's log at experiment time ``t`` (s): ``direction`` ``>`` sent to the robot,
    ``<`` received from it; ``o``/``e`` an uploaded program's stdout/stderr, ``s`` its sandbox's robot port."""

    t: float
    direction: str
    line: str


@dataclass(frozen=True)
class RunRecord:
    """A run as stored: identity, clock span (``t_start``, ``t_end``, s; None when it never drove), the
    environment (``size`` m, ``blocks`` ``(B, 5)`` x, y, w, h, angle in m and rad), the robot radius (m), its
    robots (one, or a fleet's), its moving obstacles (``obstacles_exact``: exact tracks rather than the
    tracker's), its log and its metrics (docs/metrics.md)."""

    run_id: int
    experiment_id: int
    mode: str
    repetition: int
    status: str
    environment: str
    size: tuple[float, float]
    blocks: np.ndarray
    robot_radius: float
    robots: tuple[RobotTrack, ...]
    fleet: bool = False
    t_start: Optional[float] = None
    t_end: Optional[float] = None
    obstacles: tuple[ObstacleTrack, ...] = ()
    obstacles_exact: bool = True
    log: tuple[LogLine, ...] = ()
    metrics: dict[str, Any] = field(default_factory=dict)

    @property
    def t0(self) -> float:
        """When the export's scene and plans appear (s): the run's start, else its first pose, else 0."""
        if self.t_start is not None:
            return float(self.t_start)
        firsts = [float(r.poses[0, 0]) for r in self.robots if len(r.poses)]
        return min(firsts) if firsts else 0.0

    @property
    def t1(self) -> float:
        """When the export's driven paths and metrics appear (s): the run's end, else its last pose, else
        :attr:`t0`."""
        if self.t_end is not None:
            return max(float(self.t_end), self.t0)
        lasts = [float(r.poses[-1, 0]) for r in self.robots if len(r.poses)]
        return max(lasts) if lasts else self.t0
