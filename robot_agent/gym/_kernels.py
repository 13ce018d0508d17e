"""The navigation task's compiled per-step work for all robots at once: observations, rewards, ends.

Units: m, rad.  ``occupied`` ``(M, ny, nx)`` uint8 holds each map's occupied cells (:func:`occupied_cells`)
at ``res`` m per cell.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from robot_agent.engine.compiled import kernel

__all__ = ["observe", "observe_parallel", "occupied_cells", "window_pad"]


@kernel
def _wrap(a: float) -> float:
    if -math.pi <= a < math.pi:
        return a
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True, error_model="numpy", inline="always")  # inlined in both loops: no call per robot
def _observe_one(i: int, belief: np.ndarray, pose: np.ndarray, goal: np.ndarray, map_of: np.ndarray,
                 occupied: np.ndarray, res: float, pad: int, width: float, height: float, cell: float,
                 failed: np.ndarray, goal_tol: float, progress_gain: float, step_cost: float, goal_reward: float,
                 collision_cost: float, last_dist: np.ndarray, out_pose: np.ndarray, out_goal: np.ndarray,
                 out_occ: np.ndarray, reward: np.ndarray, reached: np.ndarray, colx: np.ndarray,
                 coly: np.ndarray) -> None:
    """Robot ``i``'s row of :func:`observe` (``colx``, ``coly``: scratch of the window's size)."""
    k = out_occ.shape[1]
    inv = 1.0 / res
    half = 0.5 * k
    nx = np.uint64(occupied.shape[2])
    bx = min(max(belief[i, 0], 0.0), width)
    by = min(max(belief[i, 1], 0.0), height)
    bth = min(max(_wrap(belief[i, 2]), -math.pi), math.pi)
    out_pose[i, 0], out_pose[i, 1], out_pose[i, 2] = bx, by, bth
    out_goal[i, 0], out_goal[i, 1], out_goal[i, 2] = goal[i, 0], goal[i, 1], goal[i, 2]
    c, s = math.cos(bth) * cell * inv, math.sin(bth) * cell * inv
    gx0, gy0 = bx * inv + pad, by * inv + pad  # the robot in grid cells (padded: every index is >= 0)
    for b in range(k):  # the window's axes in grid cells: ahead (a) and to the left (b)
        fb = b + 0.5 - half
        colx[b], coly[b] = -s * fb, c * fb
    grid = occupied[map_of[i]].ravel()
    cells = out_occ[i].ravel()
    j = 0
    for a in range(k):
        fa = a + 0.5 - half
        px, py = gx0 + c * fa, gy0 + s * fa
        for b in range(k):
            cells[j] = grid[np.uint64(py + coly[b]) * nx + np.uint64(px + colx[b])]
            j += 1
    d = math.hypot(goal[i, 0] - pose[i, 0], goal[i, 1] - pose[i, 1])
    rw = progress_gain * (last_dist[i] - d) - step_cost
    reached[i] = d <= goal_tol and not failed[i]
    if reached[i]:
        rw += goal_reward
    if failed[i]:
        rw -= collision_cost
    reward[i] = rw
    last_dist[i] = d


@kernel
def observe(belief: np.ndarray, pose: np.ndarray, goal: np.ndarray, map_of: np.ndarray, occupied: np.ndarray,
            res: float, pad: int, width: float, height: float, cell: float, failed: np.ndarray, goal_tol: float,
            progress_gain: float, step_cost: float, goal_reward: float, collision_cost: float,
            last_dist: np.ndarray, rows: np.ndarray, out_pose: np.ndarray, out_goal: np.ndarray,
            out_occ: np.ndarray, reward: np.ndarray, reached: np.ndarray) -> None:
    """Observations, rewards and goal arrivals of robots ``rows``, in place.

    ``belief`` ``(N, 3)``: the robot's localisation (what it observes of its pose); ``pose`` ``(N, 3)``:
    its actual pose (what reaching the goal and the reward are judged by); ``goal`` ``(N, 3)``; ``failed``
    ``(N,)``: it collided.  ``occupied`` ``(M, ny, nx)`` uint8 marks, per map, the cells of ``res`` m whose
    centre has a block or wall within ``cell / sqrt(2)``, and ``pad`` cells around the field (see
    :func:`occupied_cells`).  ``out_occ[i, a, b]``
    is 1 when the window cell ``a`` cells of ``cell`` m ahead of the robot and ``b`` to its left (both
    counted from the window's back right corner, the robot at its centre) lies outside the field or its
    centre is in such a cell.  ``reward`` = ``progress_gain`` x (``last_dist`` - distance to the goal) -
    ``step_cost``, plus ``goal_reward`` on arrival (within ``goal_tol``), minus ``collision_cost`` on a
    collision; ``last_dist`` becomes the new distance.
    """
    colx, coly = np.empty(out_occ.shape[1]), np.empty(out_occ.shape[1])
    for r in range(len(rows)):
        _observe_one(rows[r], belief, pose, goal, map_of, occupied, res, pad, width, height, cell, failed, goal_tol,
                     progress_gain, step_cost, goal_reward, collision_cost, last_dist, out_pose, out_goal, out_occ,
                     reward, reached, colx, coly)


@njit(cache=True, error_model="numpy", parallel=True)
def observe_parallel(belief: np.ndarray, pose: np.ndarray, goal: np.ndarray, map_of: np.ndarray,
                     occupied: np.ndarray, res: float, pad: int, width: float, height: float, cell: float,
                     failed: np.ndarray, goal_tol: float, progress_gain: float, step_cost: float,
                     goal_reward: float, collision_cost: float, last_dist: np.ndarray, rows: np.ndarray,
                     out_pose: np.ndarray, out_goal: np.ndarray, out_occ: np.ndarray, reward: np.ndarray,
                     reached: np.ndarray) -> None:
    """:func:`observe` with the robots shared among numba's threads (``NUMBA_NUM_THREADS``, default every
    core): each robot's row depends on its own state only, so the result is the same."""
    for r in prange(len(rows)):
        colx, coly = np.empty(out_occ.shape[1]), np.empty(out_occ.shape[1])
        _observe_one(rows[r], belief, pose, goal, map_of, occupied, res, pad, width, height, cell, failed, goal_tol,
                     progress_gain, step_cost, goal_reward, collision_cost, last_dist, out_pose, out_goal, out_occ,
                     reward, reached, colx, coly)


def occupied_cells(clearance: np.ndarray, cell: float, pad: int) -> np.ndarray:
    """uint8 mask of the cells of a clearance field (m) with a block or wall within ``cell / sqrt(2)`` (m)
    of their centre (a window cell of size ``cell`` centred there touches an obstacle), with ``pad`` cells
    of 1 (outside the field) around it."""
    inner = clearance < cell * math.sqrt(0.5)
    return np.ascontiguousarray(np.pad(inner, pad, constant_values=True), dtype=np.uint8)


def window_pad(cells: int, cell: float, res: float) -> int:
    """Cells of ``res`` m around the field that a window of ``cells x cells`` cells of ``cell`` m, centred
    anywhere on the field and turned any way, can reach (with one to spare)."""
    return math.ceil(0.5 * cells * cell * math.sqrt(2.0) / res) + 2
