"""What ``wait()`` shows while an experiment runs, without any I/O of its own.

On a terminal a rich progress bar; elsewhere (logs, CI) plain status lines on
stderr, every :data:`REPORT_EVERY_S` seconds and whenever the experiment's
status, its finished runs or its gripper work change.  While a field run's
gripper builds the environment — minutes at live speed — both say so, with an
estimate: the robot profile's ``seconds_per_block`` for every block removed and
every block placed, divided by the testbed's time scale.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Any, Optional, TextIO

from contract.vocabulary import Mode

from ._models import Experiment, Run

__all__ = ["REPORT_EVERY_S", "BuildEstimate", "LineReporter", "ProgressBar", "format_seconds", "gripper_seconds_per_block"]

#: seconds between two status lines when nothing changes
REPORT_EVERY_S = 10.0


def format_seconds(seconds: float) -> str:
    """``"45 s"``, ``"2 min 24 s"`` or ``"1 h 05 min"`` for a duration in seconds."""
    s = max(0, round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def gripper_seconds_per_block(profile: str) -> Optional[float]:
    """Experiment seconds the gripper of robot profile ``profile`` takes per block, or None if unknown here."""
    try:
        from contract.robot_profile import load_profile

        return float(load_profile(profile)["gripper"]["seconds_per_block"])
    except Exception:  # noqa: BLE001 - an unknown or unreadable profile means no estimate, nothing worse
        return None


@dataclass(frozen=True)
class BuildEstimate:
    """How long the gripper needs to build a run's environment.

    ``placed`` blocks of the new environment; ``removed`` blocks of the one the
    sub-field had (None: unknown); ``seconds_per_block`` of the robot's gripper
    (None: profile unknown); ``time_scale`` experiment seconds per wall second
    (None: as fast as the machine goes, ``max``); ``known_scale`` whether the
    testbed told its time scale at all.
    """

    placed: int
    removed: Optional[int] = None
    seconds_per_block: Optional[float] = None
    time_scale: Optional[float] = None
    known_scale: bool = False

    @property
    def wall_seconds(self) -> Optional[float]:
        """Estimated wall seconds of the whole build (None when the profile or time scale is unknown)."""
        if self.seconds_per_block is None or not self.known_scale:
            return None
        if self.time_scale is None:
            return 0.0
        return self.seconds_per_block * (self.placed + (self.removed or 0)) / self.time_scale

    def describe(self) -> str:
        """``"building the environment (9 blocks placed, 9 removed): about 2 min 24 s at time scale 1"``."""
        blocks = f"{self.placed} blocks" if not self.removed else f"{self.placed} blocks placed, {self.removed} removed"
        text = f"building the environment ({blocks})"
        wall = self.wall_seconds
        if wall is None:
            return text
        if self.time_scale is None:
            return f"{text}: moments at time scale max"
        return f"{text}: about {format_seconds(wall)} at time scale {self.time_scale:g}"


def _building(exp: Experiment) -> list[Run]:
    return [r for r in exp.runs if r.status == "building" and r.mode == Mode.TWB]


def status_text(exp: Experiment, builds: dict[int, BuildEstimate]) -> str:
    """One line about ``exp``: status, runs done / total, when a queued one starts, what the gripper does."""
    parts = [f"experiment {exp.id}: {exp.status}", f"{exp.runs_done}/{exp.runs_total} runs done"]
    if exp.status == "queued" and exp.estimated_start_s is not None:
        parts.append(f"estimated start in {format_seconds(exp.estimated_start_s)}")
    for run in _building(exp):
        where = f"sub-field {run.subfield}" if run.subfield else "the field"
        est = builds.get(run.id)
        parts.append(f"run {run.id} on {where}: " + (est.describe() if est else "building the environment"))
    if exp.finished and exp.error:
        parts.append(exp.error)
    return ", ".join(parts[:2]) + "".join(f"; {p}" for p in parts[2:])


class LineReporter:
    """Plain status lines (no terminal control codes) on ``stream``: at the first update, on every
    change of status, finished runs or gripper work, and every ``every`` seconds otherwise."""

    def __init__(self, stream: Optional[TextIO] = None, every: Optional[float] = None) -> None:
        self._stream = stream
        self._every = REPORT_EVERY_S if every is None else every
        self._t0 = time.monotonic()
        self._last_key: Any = None
        self._last_t = 0.0

    def update(self, exp: Experiment, builds: dict[int, BuildEstimate]) -> None:
        key = (exp.status, exp.runs_done, exp.runs_total, tuple(r.id for r in _building(exp)))
        now = time.monotonic()
        if key == self._last_key and now - self._last_t < self._every:
            return
        self._last_key, self._last_t = key, now
        stream = self._stream or sys.stderr
        stream.write(f"[{format_seconds(now - self._t0)}] {status_text(exp, builds)}\n")
        stream.flush()

    def close(self) -> None:
        """Nothing to undo for plain lines."""


class ProgressBar:
    """A rich progress bar on stderr: runs done / total, the experiment's status, the gripper's work."""

    def __init__(self, label: str) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self._progress = Progress(
            TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("runs"),
            TextColumn("[bold]{task.fields[status]}"), TimeElapsedColumn(),
            console=Console(stderr=True), transient=False,
        )
        self._task = self._progress.add_task(label, total=None, status="")
        self._progress.start()

    def update(self, exp: Experiment, builds: dict[int, BuildEstimate]) -> None:
        status = exp.status
        if exp.status == "queued" and exp.estimated_start_s is not None:
            status += f" (start in {format_seconds(exp.estimated_start_s)})"
        for run in _building(exp):
            est = builds.get(run.id)
            status += f" · run {run.id}: " + (est.describe() if est else "building the environment")
        self._progress.update(self._task, completed=exp.runs_done, total=exp.runs_total or None, status=status)

    def close(self) -> None:
        self._progress.stop()
