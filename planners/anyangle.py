"""Any-angle A*: Theta* (Nash, Daniel, Koenig and Felner, AAAI 2007) on the free cells of a configuration space.

A* over the 8-connected grid of free cells whose vertices are the cell centres (the start and goal cells'
vertices are the start and goal themselves), except that a cell reached from ``u`` takes ``u``'s parent as its
own parent whenever the segment between them is free (line of sight): paths bend only where an obstacle makes
them, in any direction, instead of at multiples of 45°.  Line of sight is the configuration space's exact
segment test (:func:`planners._segment.segment_free`, the same test as
:meth:`~planners.grid.ConfigSpace.segments_free`), so every segment of the result is free.  Theta* is not
guaranteed optimal (its parents are restricted to the vertices it expanded), but on grids it is usually within
about 1 % of the true shortest path (docs/planners.md has the measurements).  The search is compiled (numba),
loaded with the first plan.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Planner
from .errors import NoPathFound
from .grid import ConfigSpace

__all__ = ["ThetaStarPlanner", "theta_star"]




def theta_star(space: ConfigSpace, start: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, int]:
    """Theta*'s path ``(N, 2)`` (m) from ``start`` to ``goal`` (m) in ``space`` and the number of cells it
    expanded; an empty path when the goal cannot be reached."""
    ny, nx = space.free.shape
    (sy, gy), (sx, gx) = space.grid.cell_of(np.array([start[:2], goal[:2]]))
    s_idx, g_idx = int(sy) * nx + int(sx), int(gy) * nx + int(gx)
    free = np.ascontiguousarray(space.free.ravel(), dtype=np.uint8)
    if s_idx == g_idx:
        pts = np.array([start[:2], goal[:2]], dtype=float)
        return (pts if space.segments_free(pts[:1], pts[1:])[0] else np.zeros((0, 2))), 1
    from ._thetastar import search  # numba loads with it

    return search(free, nx, ny, space.resolution, float(space.env.width), float(space.env.height),
                     float(start[0]), float(start[1]), float(goal[0]), float(goal[1]), s_idx, g_idx)


class ThetaStarPlanner(Planner):
    """Theta*: any-angle A* on the free cells, line of sight by the exact segment test."""

    name = "theta_star"
    description = "Theta*: any-angle A* on the occupancy grid (line of sight by the exact segment test)"
    parameters = ()

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        path, expanded = theta_star(space, start, goal)
        if len(path) == 0:
            raise NoPathFound("Theta* found no path: the goal cannot be reached from the start on the grid")
        return path, {"expanded": int(expanded)}
