"""The navigation task's compiled per-step work for all robots at once: observations, rewards, ends.

Units: m, rad.  ``clearance`` ``(M, ny, nx)`` float32 holds each map's clearance field (m from a cell
centre to the nearest block or wall, :class:`planners.grid.GridMap`) at ``res`` m per cell.
"""

from __future__ import annotations

import math

import numpy as np

from robot_agent.engine.compiled import kernel

__all__ = ["observe"]


@kernel
def _wrap(a: float) -> float:
    if -math.pi <= a < math.pi:
        return a
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@kernel
def observe(belief: np.ndarray, pose: np.ndarray, goal: np.ndarray, map_of: np.ndarray, clearance: np.ndarray,
            res: float, width: float, height: float, cell: float, failed: np.ndarray, goal_tol: float,
            progress_gain: float, step_cost: float, goal_reward: float, collision_cost: float,
            last_dist: np.ndarray, rows: np.ndarray, out_pose: np.ndarray, out_goal: np.ndarray,
            out_occ: np.ndarray, reward: np.ndarray, reached: np.ndarray) -> None:
    """Observations, rewards and goal arrivals of robots ``rows``, in place.

    ``belief`` ``(N, 3)``: the robot's localisation (what it observes of its pose); ``pose`` ``(N, 3)``:
    its actual pose (what reaching the goal and the reward are judged by); ``goal`` ``(N, 3)``; ``failed``
    ``(N,)``: it collided.  ``out_occ[i, a, b]`` is 1 when the cell ``a`` steps of ``cell`` m ahead of the
    robot and ``b`` to its left (both counted from the window's back right corner, the robot at its
    centre) lies outside the field or has a block or wall within ``cell / sqrt(2)`` of its centre.
    ``reward`` = ``progress_gain`` x (``last_dist`` - distance to the goal) - ``step_cost``, plus
    ``goal_reward`` on arrival (within ``goal_tol``), minus ``collision_cost`` on a collision;
    ``last_dist`` becomes the new distance.
    """
    k = out_occ.shape[1]
    ny, nx = clearance.shape[1], clearance.shape[2]
    near = cell * 0.7071067811865476
    half = 0.5 * k
    for r in range(len(rows)):
        i = rows[r]
        bx, by, bth = belief[i, 0], belief[i, 1], _wrap(belief[i, 2])
        out_pose[i, 0] = min(max(bx, 0.0), width)
        out_pose[i, 1] = min(max(by, 0.0), height)
        out_pose[i, 2] = min(max(bth, -math.pi), math.pi)
        out_goal[i, 0], out_goal[i, 1], out_goal[i, 2] = goal[i, 0], goal[i, 1], goal[i, 2]
        c, s = math.cos(bth), math.sin(bth)
        m = map_of[i]
        for a in range(k):
            fx = (a + 0.5 - half) * cell
            for b in range(k):
                fy = (b + 0.5 - half) * cell
                wx = bx + c * fx - s * fy
                wy = by + s * fx + c * fy
                if wx < 0.0 or wy < 0.0 or wx >= width or wy >= height:
                    out_occ[i, a, b] = 1
                    continue
                ix = min(int(wx / res), nx - 1)
                iy = min(int(wy / res), ny - 1)
                out_occ[i, a, b] = 1 if clearance[m, iy, ix] < near else 0
        d = math.hypot(goal[i, 0] - pose[i, 0], goal[i, 1] - pose[i, 1])
        rw = progress_gain * (last_dist[i] - d) - step_cost
        reached[i] = d <= goal_tol and not failed[i]
        if reached[i]:
            rw += goal_reward
        if failed[i]:
            rw -= collision_cost
        reward[i] = rw
        last_dist[i] = d
