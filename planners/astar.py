"""A* baseline: the shortest path on the 8-connected grid of free cells.

The classic grid planner: moves to the 8 neighbouring cells (cost ``h`` or
``h*sqrt(2)``), no corner cutting.  A* with the octile heuristic returns a
shortest path of this graph; we compute one with SciPy's compiled Dijkstra
(``scipy.sparse.csgraph``) on the graph built in one vectorised pass, which
yields a path of the same (optimal) length as A* without a Python heap loop
over cells.  The heuristic only prunes the search; it does not change the
cost of the result.  Among equally short grid paths the one returned is
deterministic.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from .base import Planner
from .errors import NoPathFound
from .grid import ConfigSpace

__all__ = ["AStarPlanner", "grid_graph"]


def _shift(d: int, n: int) -> tuple[slice, slice]:
    """Slices selecting index ``k`` and ``k + d`` along an axis of length ``n``."""
    return (slice(0, n - d), slice(d, n)) if d >= 0 else (slice(-d, n), slice(0, n + d))


def grid_graph(free: np.ndarray, h: float) -> tuple[Any, np.ndarray]:
    """Sparse undirected 8-connected graph over ``free`` cells; returns (graph, node id per cell).

    Diagonal edges exist only when both cells they cut past are free.
    """
    ny, nx = free.shape
    n = int(free.sum())
    ids = np.full(free.shape, -1, dtype=np.int64)
    ids[free] = np.arange(n)
    rows, cols, weights = [], [], []
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        (ra, rb), (ca, cb) = _shift(dy, ny), _shift(dx, nx)
        ok = free[ra, ca] & free[rb, cb]
        if dy and dx:  # no corner cutting: both orthogonal neighbours free
            ok &= free[rb, ca] & free[ra, cb]
        rows.append(ids[ra, ca][ok])
        cols.append(ids[rb, cb][ok])
        weights.append(np.full(int(ok.sum()), h * (math.sqrt(2) if dy and dx else 1.0)))
    graph = coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    return graph.tocsr(), ids


class AStarPlanner(Planner):
    """Shortest path on the 8-connected occupancy grid (classic A* baseline)."""

    name = "astar"
    description = "A* on the 8-connected grid (optimal grid path; SciPy csgraph search)"
    parameters = ()

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        graph, ids = grid_graph(space.free, space.resolution)
        (sy, gy), (sx, gx) = space.grid.cell_of(np.array([start, goal]))
        s, g = int(ids[sy, sx]), int(ids[gy, gx])
        dist, pred = dijkstra(graph, directed=False, indices=s, return_predecessors=True)
        if not math.isfinite(dist[g]):
            raise NoPathFound("the goal cannot be reached from the start on the 8-connected grid")
        order = [g]
        # walking predecessors is a loop over the path's cells only
        while order[-1] != s:
            order.append(int(pred[order[-1]]))
        nodes = np.array(order[::-1])
        cells = np.argwhere(space.free)[nodes]  # argwhere order == id order (row-major)
        pts = space.grid.cell_centres(cells[:, 0], cells[:, 1])
        pts[0], pts[-1] = start, goal
        if len(pts) == 1:
            pts = np.array([start, goal])
        return pts, {"grid_nodes": int(graph.shape[0]), "grid_cells_on_path": int(len(nodes))}
