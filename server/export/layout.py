"""Where an export puts things, whatever its format: topic and frame names, times, orientations, log levels.

A run exported alone has the topics ``/tf``, ``/robot/pose``,
``/robot/planned_path``, ``/robot/driven_path``, ``/scene``, ``/metrics`` and
the log (``/log`` in MCAP, ``/rosout`` in a ROS 2 bag); a fleet's robots each
have their own ``/robot_<k>/...`` topics and ``robot_<k>/base_link`` frame.
An experiment's runs each get the prefix ``run_<id>`` (``/run_12/robot/pose``,
frame ``run_12/base_link``); ``/tf`` and the log stay shared, as ROS tools
expect.  Every pose is in the ``map`` frame: the experiment's field (origin at
its lower-left corner, metres).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any, Iterator

import numpy as np

from .record import RunRecord

__all__ = ["MAP_FRAME", "Names", "flat_metrics", "log_level", "log_times", "ns", "yaw_quaternion"]

#: the frame every pose, path and obstacle is given in: the experiment's field
MAP_FRAME = "map"
#: a block's height (m) in the exported scene: the testbed's blocks are low walls
BLOCK_HEIGHT_M = 0.05


def ns(t: float) -> int:
    """Experiment time ``t`` (s) as integer nanoseconds (a message's log time); negative times clamp to 0."""
    return max(0, int(round(float(t) * 1e9)))


def ns_array(t: np.ndarray) -> np.ndarray:
    """:func:`ns` of an array of times (s): int64 nanoseconds."""
    return np.maximum(0, np.rint(np.asarray(t, dtype=float) * 1e9)).astype(np.int64)


def yaw_quaternion(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The quaternions ``(z, w)`` of rotations by ``theta`` (rad) about +z (x = y = 0)."""
    half = np.asarray(theta, dtype=float) * 0.5
    return np.sin(half), np.cos(half)


def quaternion_yaw(z: float, w: float) -> float:
    """The rotation (rad, in (-pi, pi]) about +z of the quaternion ``(0, 0, z, w)``."""
    return math.atan2(2.0 * w * z, 1.0 - 2.0 * z * z)


@dataclass(frozen=True)
class Names:
    """The topic and frame names of one run in an export: ``prefix`` ``""`` for a run exported alone,
    ``"run_<id>"`` for a run of an exported experiment."""

    prefix: str
    fleet: bool

    @classmethod
    def of(cls, record: RunRecord, in_experiment: bool) -> "Names":
        return cls(f"run_{record.run_id}" if in_experiment else "", record.fleet)

    def topic(self, *parts: str) -> str:
        """``/<prefix>/<parts...>`` (no prefix for a run alone)."""
        return "/" + "/".join(p for p in (self.prefix, *parts) if p)

    def robot(self, index: int) -> str:
        """A robot's namespace: ``robot`` for a single robot, ``robot_<k>`` for a fleet's."""
        return f"robot_{index}" if self.fleet else "robot"

    def robot_topic(self, index: int, name: str) -> str:
        return self.topic(self.robot(index), name)

    def base_frame(self, index: int) -> str:
        """The robot's body frame: ``base_link`` (``robot_<k>/base_link`` in a fleet), under the prefix."""
        return "/".join(p for p in (self.prefix, f"robot_{index}" if self.fleet else "", "base_link") if p)

    @property
    def log_name(self) -> str:
        """Who a log line is from: ``run_<id>`` in an experiment, else ``robot``."""
        return self.prefix or "robot"


def log_level(direction: str, line: str) -> str:
    """How serious a protocol line is: ``error`` (the robot's ``EV,FAIL``), ``warning`` (an ``ERR`` reply,
    a program's stderr), else ``info``."""
    if line.startswith("EV,FAIL") or line.startswith("robot ") and ": EV,FAIL" in line:
        return "error"
    if direction == "e" or line.startswith("ERR") or (line.startswith("robot ") and ": ERR" in line):
        return "warning"
    return "info"


def log_times(record: RunRecord) -> Iterator[tuple[int, str, str]]:
    """The run's log as ``(log time ns, level, text)``, the text ``"<direction> <line>"`` (``"> T,T,P,..."``)."""
    for entry in record.log:
        yield ns(entry.t), log_level(entry.direction, entry.line), f"{entry.direction} {entry.line}"


def flat_metrics(metrics: dict[str, Any], prefix: str = "") -> list[tuple[str, str]]:
    """The run's metrics as ``(key, value)`` text pairs, nested keys joined with ``.`` (``planned.length_m``,
    ``robots.0.length_m``); numbers as ``repr`` (exact), lists as JSON."""
    out: list[tuple[str, str]] = []
    for k, v in metrics.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out += flat_metrics(v, key + ".")
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for i, x in enumerate(v):
                out += flat_metrics(x, f"{key}.{i}.")
        elif isinstance(v, (list, tuple)):
            out.append((key, json.dumps(v)))
        elif isinstance(v, bool) or v is None:
            out.append((key, json.dumps(v)))
        else:
            out.append((key, repr(v) if isinstance(v, float) else str(v)))
    return out
