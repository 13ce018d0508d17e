"""What one run carries through its steps: its context (protocol log, time scale) and the services it uses."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Optional, Protocol

import numpy as np

from ..core.settings import Settings
from ..field import FieldState
from ..sandbox import Sandbox
from ..scheduler import Assignment, RobotSlot
from ..tracking import PoseRouter
from .paths import PathService
from .pool import ComputePool
from .recorder import RunRecorder

__all__ = ["NoHooks", "RobotHooks", "RunContext", "RunServices"]


class RobotHooks(Protocol):
    """What the server can do to robot agents that run in its own process (``twb up``)."""

    def seed_next_path(self, robot_id: str, seed: int) -> bool:
        """Seed the noise of the robot's next path (exact replay); whether it could (False: another process's
        robot, whose noise its agent keys)."""

    async def flush_tracker(self, robot_id: str) -> bool:
        """Deliver the robot's pending tracker poses now; False if the robot is not in this process."""


class NoHooks:
    """Robots elsewhere: nothing to seed or flush directly."""

    def seed_next_path(self, robot_id: str, seed: int) -> bool:
        return False

    async def flush_tracker(self, robot_id: str) -> bool:
        return False


@dataclass(frozen=True)
class RunServices:
    """Everything a run uses, handed in by the testbed (no back-pointer to it)."""

    settings: Settings
    recorder: RunRecorder
    paths: PathService
    pool: ComputePool
    field: FieldState
    tracker: PoseRouter
    hooks: RobotHooks = field(default_factory=NoHooks)
    #: runs uploaded controller programs (None: this testbed has none)
    sandbox: Optional[Sandbox] = None


class RunContext:
    """One execution: its assignment, robot, time scale and protocol log."""

    def __init__(self, assignment: Assignment, robot: RobotSlot, time_scale: float, slack_s: float = 10.0,
                 log_lines: int = 20_000) -> None:
        self.assignment = assignment
        self.run_id = assignment.run_id
        self.robot = robot
        self.time_scale = time_scale
        self.slack_s = slack_s
        #: the run is carried out as a task (an engine slot's, or a field-robot variant's), not by the robot
        self.as_task = bool(robot.engine)
        self.messages: list[dict[str, Any]] = []
        #: the log keeps its first ``log_lines`` lines; the rest are counted (``dropped``), and so are lines a
        #: step chose not to log (``dropped_by``: why -> how many), and said in one last line (:meth:`finish_log`)
        self.log_lines = log_lines
        self.logged = 0
        self.dropped = 0
        self.dropped_by: dict[str, int] = {}
        self._taken_at = time.monotonic()
        #: what is stored with the run's end, in its one transaction: run fields (metrics, t_start …) and the
        #: poses a compute engine's task returned (s, m, m, rad)
        self.end_fields: dict[str, Any] = {}
        self.end_poses: Optional[np.ndarray] = None
        #: a field run's obstacle robots' tracker poses, per moving obstacle (T, 4) (s, m, m, rad; the run's
        #: clock and frame), stored with the end too; None: none to store (a sim run's are exact)
        self.end_obstacles: Optional[list[np.ndarray]] = None
        #: metrics a step measured itself (a controller program's compute time), added to the run's metrics
        self.end_metrics: dict[str, Any] = {}
        #: the robot's path noise was keyed by the run's seed (then its field obstacle robots can be replayed)
        self.seeded = False

    @property
    def subfields(self) -> tuple[int, ...]:
        return self.assignment.subfields

    def on_line(self, direction: str, line: str, t: Optional[float], estimated: bool) -> None:
        """Log one protocol line (``>`` sent, ``<`` received; program lines ``o``/``e``/``s``), if the log has
        room (``log_lines``); else count it."""
        if self.logged >= self.log_lines:
            self.dropped += 1
            return
        self.logged += 1
        self.messages.append({"run_id": self.run_id, "t": t, "t_estimated": estimated, "direction": direction,
                              "line": line[:10_000]})

    def not_logged(self, why: str, count: int = 1) -> None:
        """``count`` lines a step did not log (``why``: what they were, e.g. ``relayed lines of the controller
        program beyond its first 10000``), for the log's last line."""
        self.dropped_by[why] = self.dropped_by.get(why, 0) + count

    def finish_log(self) -> None:
        """End the log with one line saying how many lines were dropped and why (nothing when none was);
        that line is kept whatever the cap."""
        total = self.dropped + sum(self.dropped_by.values())
        if not total:
            return
        parts = [f"{n} {why}" for why, n in self.dropped_by.items()]
        if self.dropped:
            parts.append(f"{self.dropped} lines beyond the {self.log_lines} a run's log keeps")
        self.messages.append({"run_id": self.run_id, "t": None, "t_estimated": False, "direction": "s",
                              "line": f"{total} lines dropped: {'; '.join(parts)}"})
        self.dropped, self.dropped_by = 0, {}

    def take_messages(self) -> list[dict[str, Any]]:
        batch, self.messages = self.messages, []
        self._taken_at = time.monotonic()
        return batch

    def messages_due(self, every_s: float = 1.0, lines: int = 500) -> bool:
        """Whether the log should be stored now (a second or many lines since): a killed server loses
        at most that much of a run's log."""
        return len(self.messages) >= lines or (bool(self.messages) and time.monotonic() - self._taken_at >= every_s)

    def wall(self, experiment_s: float) -> float:
        """Wall seconds for ``experiment_s`` of experiment time at the time scale, plus the slack."""
        return (0.0 if math.isinf(self.time_scale) else experiment_s / self.time_scale) + self.slack_s
