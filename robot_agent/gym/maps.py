"""The navigation task's maps: an environment's blocks, clearance field and where episodes may start and end.

A :class:`NavMap` is built once per environment and shared by every robot that drives in it: the blocks
as the engine's world takes them (``(B, 5)``: cx, cy, w, h in m, angle in rad), the environment's
clearance field (:class:`planners.grid.GridMap`: metres from each cell centre to the nearest block or
wall) from which the local occupancy is sampled, and the free cells of the robot's configuration space
(clearance at least the collision radius plus a margin) in the largest connected region, from which
starts and goals are drawn: every drawn goal is reachable from its start.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from planners.environment import Environment, load_environment
from planners.grid import grid_map

__all__ = ["Environments", "NavMap", "build_map", "build_maps", "environment_list"]


@dataclass(frozen=True, eq=False)
class NavMap:
    """One environment prepared for the navigation task (see the module docstring).

    Attributes
    ----------
    env : Environment
    blocks : (B, 5) float array, cx, cy, w, h (m), angle (rad)
    clearance : (ny, nx) float32 array, m from each cell centre to the nearest block or wall
    resolution : float, m per cell of ``clearance`` and of the free cells
    free_xy : (F, 2) float array, centres (m) of the cells starts and goals are drawn from
    """

    env: Environment
    blocks: np.ndarray
    clearance: np.ndarray
    resolution: float
    free_xy: np.ndarray

    @property
    def size(self) -> tuple[float, float]:
        """Width and height (m)."""
        return self.env.size

    def sample_pair(self, rng: np.random.Generator, min_distance: float) -> tuple[np.ndarray, np.ndarray]:
        """A start and a goal pose ``(3,)`` each (m, m, rad), ``min_distance`` (m) apart or more when the
        region allows it (the first of 64 drawn goals that is; else the farthest), headings uniform in
        [-pi, pi)."""
        u = rng.random(67)  # one draw: the start, 64 candidate goals, two headings
        pick = (u[:65] * len(self.free_xy)).astype(np.int64)
        a, cand = self.free_xy[pick[0]], self.free_xy[pick[1:]]
        d = np.hypot(cand[:, 0] - a[0], cand[:, 1] - a[1])
        far = d >= min_distance
        b = cand[int(np.argmax(far))] if far.any() else cand[int(np.argmax(d))]
        th = (2.0 * u[65:] - 1.0) * math.pi
        return np.array([a[0], a[1], th[0]]), np.array([b[0], b[1], th[1]])


def _build_iv(resolution: float, clearance_m: float) -> None:
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"`resolution` must be > 0 (m), got {resolution!r}")
    if not (math.isfinite(clearance_m) and clearance_m > 0):
        raise ValueError(f"`clearance_m` must be > 0 (m), got {clearance_m!r}")


def build_map(env: Environment, *, clearance_m: float, resolution: float = 0.02) -> NavMap:
    """``env`` prepared for the task: starts and goals keep ``clearance_m`` (m) from blocks and walls, on a
    grid of ``resolution`` (m)."""
    _build_iv(resolution, clearance_m)
    if env.moving_obstacles:
        raise ValueError(f"environment {env.name!r} has moving obstacles: the navigation task has static worlds only")
    gm = grid_map(env, resolution)
    free = gm.space(clearance_m).free
    labels, count = ndimage.label(free)  # 4-connected: a diagonal squeeze between two cells is no way through
    if count == 0:
        raise ValueError(f"environment {env.name!r} has no free cell {clearance_m} m from every block and wall")
    biggest = 1 + int(np.argmax(np.bincount(labels.ravel())[1:]))
    iy, ix = np.nonzero(labels == biggest)
    blocks = np.array([(b.x, b.y, b.w, b.h, b.angle) for b in env.blocks], dtype=float).reshape(-1, 5)
    return NavMap(env, blocks, np.ascontiguousarray(gm.clearance, dtype=np.float32), float(resolution),
                  gm.cell_centres(iy, ix))


#: what an environment argument may be (:func:`environment_list`)
Environments = str | Path | Environment | Sequence[str | Path | Environment]


def environment_list(environments: Environments) -> list:
    """The environments one argument names: a built-in name, a JSON file, an :class:`Environment`, a
    directory (its ``*.json`` files but ``index.json``, sorted: a world set of ``twb worlds generate``), or
    a sequence of those."""
    items = [environments] if isinstance(environments, (str, Path, Environment)) else list(environments)
    out: list = []
    for item in items:
        if isinstance(item, (str, Path)) and Path(item).is_dir():
            out += sorted(str(p) for p in Path(item).glob("*.json") if p.name != "index.json")
        else:
            out.append(item)
    return out


def build_maps(environments: Environments, *, clearance_m: float,
               resolution: float = 0.02) -> list[NavMap]:
    """:func:`build_map` of each environment (:func:`environment_list`); all must have the same size (the
    engine's worlds are made once)."""
    environments = environment_list(environments)
    if not environments:
        raise ValueError("`environments` must name at least one environment")
    maps = [build_map(load_environment(e), clearance_m=clearance_m, resolution=resolution) for e in environments]
    sizes = {m.size for m in maps}
    if len(sizes) > 1:
        raise ValueError(f"`environments` must all have one size, got {sorted(sizes)}")
    return maps
