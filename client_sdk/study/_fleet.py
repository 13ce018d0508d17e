"""Fleet problems of a study (docs/study.md, "Fleets: robot counts and obstacle scenarios"): several robots in one
world, given robot by robot or generated.

A ``plans`` entry of a study file is a fleet problem when it has ``robots``
(explicit: ``{"name": "swap4", "robots": [{"start": [x, y, theta], "goal":
[...]}, ...]}``, 2 to 16 robots on a sub-field, 64 on the whole field; m, rad) or ``circle`` (generated:
``{"name": "circle-8", "circle": {"robots": 8, "radius_m": 0.6}}``).  The
circle is the classic multi-robot benchmark: N robots evenly on a circle
around the environment's centre (or ``"centre": [x, y]``), each facing the
centre and bound for the antipodal point, so every robot crosses the centre
and a study crosses robot counts as problems (circle-2, circle-4, circle-8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Optional, Sequence

import numpy as np

from contract.frames import MAX_ROBOTS
from contract.frames import MAX_ROBOTS_SUBFIELD as MAX_ROBOTS_SUB

__all__ = ["MAX_ROBOTS", "MAX_ROBOTS_SUB", "MIN_ROBOTS", "SEPARATION_M", "Circle", "circle_robots", "finite", "is_pose", "parse_circle",
           "parse_robots"]

#: robots of a multi-robot job: at least 2; at most MAX_ROBOTS_SUB (16) on a sub-field, MAX_ROBOTS (64) in all
MIN_ROBOTS = 2
#: the closest two robots' starts (or goals) may stand, centre to centre (m): twice the robot radius with the
#: testbed's planning margin (the server's pre-flight rule; docs/server.md, "Multi-robot jobs")
#: (planners.api's DEFAULT_ROBOT_RADIUS and DEFAULT_PLANNING_MARGIN, written out: importing planners takes a second)
SEPARATION_M = 2 * (0.045 + 0.02)
_ROBOT_KEYS = {"start", "goal"}
_CIRCLE_KEYS = {"robots", "radius_m", "centre"}

Bad = Callable[[str], Exception]


@dataclass(frozen=True)
class Circle:
    """``robots`` robots evenly on a circle of ``radius_m`` (m) around ``centre`` (m; None: the environment's
    centre), each bound for the antipodal point."""

    robots: int
    radius_m: float
    centre: Optional[tuple[float, float]] = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"robots": self.robots, "radius_m": self.radius_m}
        if self.centre is not None:
            out["centre"] = list(self.centre)
        return out

    def robots_in(self, size: Sequence[float]) -> list[dict[str, list[float]]]:
        """The robots in an environment of ``size`` (m): :func:`circle_robots` around its centre unless the
        circle has its own."""
        centre = self.centre if self.centre is not None else (size[0] / 2, size[1] / 2)
        return circle_robots(self.robots, self.radius_m, centre)


def circle_robots(n: int, radius_m: float, centre: Sequence[float]) -> list[dict[str, list[float]]]:
    """``n`` robots evenly on a circle: robot k starts at ``centre + radius_m (cos a_k, sin a_k)``, ``a_k = 2πk/n``
    (rad, from +x, anticlockwise), facing the centre (heading ``a_k + π`` wrapped to (-π, π]), and is bound for
    the antipodal point ``centre - radius_m (cos a_k, sin a_k)``, arriving with the same heading (it drives
    straight through the centre).  Neighbours stand ``2 radius_m sin(π/n)`` apart (m).

    Returns ``[{"start": [x, y, theta], "goal": [x, y, theta]}, ...]`` (m, rad; positions rounded to 1e-9 m so
    that exact positions such as 0.3 stay 0.3), as a multi-robot job's ``robots``.
    """
    if n < 1 or not radius_m > 0:
        raise ValueError(f"a circle needs at least one robot and a radius > 0, got {n} and {radius_m!r}")
    a = 2 * np.pi * np.arange(n) / n
    offset = radius_m * np.column_stack([np.cos(a), np.sin(a)])
    c = np.asarray(centre[:2], dtype=float)
    heading = np.pi - np.mod(-a, 2 * np.pi)  # a + π wrapped to (-π, π]: towards the centre
    start = np.column_stack([np.round(c + offset, 9) + 0.0, heading])  # + 0.0: no -0.0
    goal = np.column_stack([np.round(c - offset, 9) + 0.0, heading])
    return [{"start": s.tolist(), "goal": g.tolist()} for s, g in zip(start, goal)]


def finite(v: Any) -> bool:
    """``v`` is a finite int or float (not a bool)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def is_pose(v: Any) -> bool:
    """``v`` is ``[x, y]`` or ``[x, y, theta]`` of finite numbers."""
    return isinstance(v, list) and len(v) in (2, 3) and all(finite(x) for x in v)


def _closest(points: np.ndarray) -> tuple[float, int, int]:
    """The smallest distance (m) between two of ``points`` ``(R, 2)`` and their indices."""
    d = np.hypot(*(points[:, None, :2] - points[None, :, :2]).transpose(2, 0, 1))
    d[np.diag_indices(len(points))] = np.inf
    i, j = np.unravel_index(int(np.argmin(d)), d.shape)
    return float(d[i, j]), int(min(i, j)), int(max(i, j))


def parse_robots(value: Any, where: str, bad: Bad) -> list[dict[str, list[float]]]:
    """A fleet problem's explicit ``robots``: 2 to 64 ``{"start", "goal"}`` poses ([x, y] or [x, y, theta]; m,
    rad), no two starts and no two goals closer than :data:`SEPARATION_M`."""
    if not isinstance(value, list) or not MIN_ROBOTS <= len(value) <= MAX_ROBOTS:
        raise bad(f"{where} must be a list of {MIN_ROBOTS} to {MAX_ROBOTS} {{\"start\", \"goal\"}} objects")
    out = []
    for k, r in enumerate(value):
        if not isinstance(r, Mapping):
            raise bad(f"{where}[{k}] must be an object {{\"start\": [x, y, theta], \"goal\": [x, y, theta]}}")
        unknown = sorted(set(r) - _ROBOT_KEYS)
        if unknown:
            raise bad(f"{where}[{k}]: unknown key(s) {', '.join(unknown)} (allowed: goal, start; a study's "
                      "configurations plan every robot)")
        for key in ("start", "goal"):
            if not is_pose(r.get(key)):
                raise bad(f"{where}[{k}].{key} must be [x, y] or [x, y, theta] (m, rad)")
        out.append({"start": [float(x) for x in r["start"]], "goal": [float(x) for x in r["goal"]]})
    for key in ("start", "goal"):
        gap, i, j = _closest(np.array([r[key][:2] for r in out]))
        if gap < SEPARATION_M:
            raise bad(f"{where}[{j}].{key} is {gap:.3f} m from {where}[{i}].{key}: two robots need "
                      f"{SEPARATION_M:.3f} m between their centres")
    return out


def parse_circle(value: Any, where: str, bad: Bad) -> Circle:
    """A fleet problem's ``circle``: ``{"robots": 2..64, "radius_m": > 0, "centre"?: [x, y]}`` (m), with
    neighbours at least :data:`SEPARATION_M` apart."""
    if not isinstance(value, Mapping):
        raise bad(f"{where} must be an object such as {{\"robots\": 8, \"radius_m\": 0.6}}")
    unknown = sorted(set(value) - _CIRCLE_KEYS)
    if unknown:
        raise bad(f"{where}: unknown key(s) {', '.join(unknown)} (allowed: {', '.join(sorted(_CIRCLE_KEYS))})")
    n = value.get("robots")
    if not isinstance(n, int) or isinstance(n, bool) or not MIN_ROBOTS <= n <= MAX_ROBOTS:
        raise bad(f"{where}.robots must be an integer from {MIN_ROBOTS} to {MAX_ROBOTS}, got {n!r}")
    r = value.get("radius_m")
    if not finite(r) or r <= 0:
        raise bad(f"{where}.radius_m must be a number > 0 (m), got {r!r}")
    centre = value.get("centre")
    if centre is not None and not (isinstance(centre, list) and len(centre) == 2 and all(finite(x) for x in centre)):
        raise bad(f"{where}.centre must be [x, y] (m), got {centre!r}")
    gap = 2 * r * math.sin(math.pi / n)
    if gap < SEPARATION_M:
        raise bad(f"{where}: {n} robots on a circle of radius {r:g} m stand {gap:.3f} m apart; two robots need "
                  f"{SEPARATION_M:.3f} m between their centres (a radius of at least "
                  f"{SEPARATION_M / (2 * math.sin(math.pi / n)):.3f} m)")
    return Circle(n, float(r), None if centre is None else (float(centre[0]), float(centre[1])))
