"""Execution of a multi-robot plan by its order of passage: an action dependency graph.

docs/planners.md, "Several robots: prioritized planning" (execution by dependencies), has the overview.

A prioritized plan (:mod:`planners.prioritized`) is a set of timed paths that
keep the robots apart *if* every robot keeps to its timing.  Robots do not:
they turn on the spot, start up, round corners and, on the field, drive slower
than planned.  Hönig, Kiesel, Tinka, Durham and Ayanian (2019, "Persistent
and robust execution of MAPF schedules in warehouses", IEEE RA-L) keep
instead the plan's *order* of passage at every shared place: whenever robot
``i``'s plan is at a place before robot ``j``'s plan comes within the
conflict distance of it, robot ``j`` may not start the move into its
conflicting waypoint until robot ``i`` has reached the waypoint after its
own (it has left the place).  Released by these precedences instead of the
clock, delays change when robots move but not in which order they pass, so
they cannot make robots meet (unless a robot strays from its path by more
than the margin).

Waypoints are occupied over intervals ``[arrive, leave]`` (s, the plan's; a
robot stands at its goal for good, ``leave = inf``); of two conflicting
occupations the one with the earlier midpoint goes first (they do not
overlap in a collision-free plan).  The computation is vectorised per robot
``j``: all robots' waypoints against ``j``'s, one distance matrix.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["NONE", "fleet_dependencies", "waiting_for"]

#: no requirement on a robot (its reached index is always at least 0)
NONE = -1


def fleet_dependencies(xy: Sequence[np.ndarray], arrive: Sequence[np.ndarray], leave: Sequence[np.ndarray],
                       distance: float) -> list[np.ndarray]:
    """The precedences of robots at waypoints ``xy[i]`` ``(K_i, 2+)`` (m) that the plan occupies from
    ``arrive[i]`` to ``leave[i]`` ``(K_i,)`` (s), for places closer than ``distance`` (m, centre to centre).

    Returns per robot ``j`` an int array ``(R, K_j)``: entry ``[i, k]`` is the waypoint index robot ``i``
    must have reached before robot ``j`` may leave its waypoint ``k`` (:data:`NONE`: no requirement).  Each
    row is non-decreasing along ``k`` (a later departure needs at least what an earlier one needed).  A
    requirement on a robot's last waypoint (it stands there for good) is capped at that index."""
    n = len(xy)
    pts = np.concatenate([np.asarray(p, dtype=float)[:, :2] for p in xy])
    mid = np.concatenate([_midpoints(a, b) for a, b in zip(arrive, leave)])
    sizes = np.array([len(p) for p in xy])
    offsets = np.r_[0, np.cumsum(sizes)[:-1]]
    robot = np.repeat(np.arange(n), sizes)
    nxt = np.minimum(np.arange(len(pts)) - offsets[robot] + 1, sizes[robot] - 1)  # the waypoint after each
    out = []
    for j in range(n):
        cols = slice(offsets[j], offsets[j] + sizes[j])
        near = np.hypot(pts[:, None, 0] - pts[None, cols, 0], pts[:, None, 1] - pts[None, cols, 1]) < distance
        before = (mid[:, None] < mid[None, cols]) | ((mid[:, None] == mid[None, cols]) & (robot[:, None] < j))
        must = np.where(near & before & (robot[:, None] != j), nxt[:, None], NONE)  # (all waypoints, K_j)
        need = np.maximum.reduceat(must, offsets, axis=0)  # (R, K_j): to enter j's waypoint b
        req = np.full((n, sizes[j]), NONE, dtype=np.int64)
        req[:, :-1] = need[:, 1:]  # entering b means leaving b - 1
        out.append(np.maximum.accumulate(req, axis=1))
    return out


def _midpoints(arrive: np.ndarray, leave: np.ndarray) -> np.ndarray:
    """The middle of each occupation (s); ``inf`` for one that never ends."""
    a, b = np.asarray(arrive, dtype=float), np.asarray(leave, dtype=float)
    return np.where(np.isfinite(b), (a + b) / 2, np.inf)


def waiting_for(req: np.ndarray, reached: np.ndarray) -> np.ndarray:
    """The robots (indices) whose progress ``reached`` ``(R,)`` (waypoint indices) does not yet meet ``req``
    ``(R,)``, one column of :func:`fleet_dependencies`' result."""
    return np.flatnonzero(reached < req)
