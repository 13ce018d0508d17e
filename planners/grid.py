"""Occupancy grids and the robot's configuration space.

:class:`GridMap` rasterises an :class:`~planners.environment.Environment` at a
resolution ``h`` (metres per cell) and keeps, for every cell centre, an
approximate clearance (metres to the nearest obstacle, within about one cell)
from SciPy's Euclidean distance transform.  :class:`ConfigSpace` dilates the
obstacles by a robot radius: a cell is free when the exact distance from its
centre to every obstacle is at least the radius (the transform decides far
from the boundary, exact geometry in the band of cells where its error could
flip the decision).  Every
planner works in a ``ConfigSpace`` and every path it returns is checked
against it.

Array layout follows images with ``origin="lower"``: ``grid[iy, ix]`` is the
cell whose centre is ``((ix + 0.5) h, (iy + 0.5) h)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy import ndimage

from .environment import Environment
from .geometry import block_arrays, distance_to_obstacles

__all__ = ["ConfigSpace", "GridMap", "config_space", "grid_map"]

MAX_CELLS = 4000 * 4000


def _resolution_iv(env: Environment, resolution: float) -> tuple[int, int]:
    if not (isinstance(resolution, (int, float)) and math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"`resolution` must be a finite number > 0 (metres per cell), got {resolution!r}")
    nx = max(1, math.ceil(env.width / resolution - 1e-9))
    ny = max(1, math.ceil(env.height / resolution - 1e-9))
    if nx * ny > MAX_CELLS:
        raise ValueError(
            f"`resolution` {resolution} m gives a {nx} x {ny} grid; at most {MAX_CELLS} cells are allowed"
        )
    if nx < 4 or ny < 4:
        raise ValueError(f"`resolution` {resolution} m is too coarse for a {env.width} x {env.height} m field")
    return nx, ny


def _rasterise(env: Environment, resolution: float, nx: int, ny: int) -> np.ndarray:
    """Cells whose centre lies inside a block (one bounding box per block, vectorised inside)."""
    occ = np.zeros((ny, nx), dtype=bool)
    centres, half, angles = block_arrays(env)
    for (cx, cy), (hw, hh), a in zip(centres, half, angles):
        c, s = math.cos(a), math.sin(a)
        ex, ey = abs(c) * hw + abs(s) * hh, abs(s) * hw + abs(c) * hh  # bounding box half extents
        ix0, ix1 = max(0, math.floor((cx - ex) / resolution)), min(nx, math.ceil((cx + ex) / resolution) + 1)
        iy0, iy1 = max(0, math.floor((cy - ey) / resolution)), min(ny, math.ceil((cy + ey) / resolution) + 1)
        if ix0 >= ix1 or iy0 >= iy1:
            continue
        xs = (np.arange(ix0, ix1) + 0.5) * resolution - cx
        ys = (np.arange(iy0, iy1) + 0.5) * resolution - cy
        dx, dy = xs[None, :], ys[:, None]
        inside = (np.abs(c * dx + s * dy) <= hw) & (np.abs(-s * dx + c * dy) <= hh)
        occ[iy0:iy1, ix0:ix1] |= inside
    return occ


@dataclass(frozen=True, eq=False)
class GridMap:
    """An environment rasterised at ``resolution`` metres per cell.

    Attributes
    ----------
    env : Environment
    resolution : float, metres per cell
    obstacle : (ny, nx) bool array, cell centre inside a block
    clearance : (ny, nx) float array, metres from the cell centre to the nearest
        obstacle (blocks and walls), from the Euclidean distance transform (within
        about one cell of the exact distance); 0 in blocks.
    """

    env: Environment
    resolution: float
    obstacle: np.ndarray
    clearance: np.ndarray
    _spaces: dict = field(default_factory=dict, repr=False)

    @classmethod
    def build(cls, env: Environment, resolution: float = 0.01) -> "GridMap":
        """Rasterise ``env`` and compute the clearance field (prefer :func:`grid_map`, cached)."""
        nx, ny = _resolution_iv(env, resolution)
        obstacle = _rasterise(env, resolution, nx, ny)
        # A ring of obstacle cells outside the field makes the walls obstacles.
        # The EDT measures centre-to-centre; subtracting h/2 turns that into the
        # distance to the obstacle cell's edge, which is exact for walls and
        # grid-aligned blocks and within about one cell otherwise.
        padded = np.pad(~obstacle, 1, constant_values=False)
        edt = ndimage.distance_transform_edt(padded, sampling=resolution)[1:-1, 1:-1]
        clearance = np.maximum(edt - resolution / 2, 0.0)
        clearance[obstacle] = 0.0
        obstacle.flags.writeable = False
        clearance.flags.writeable = False
        return cls(env, float(resolution), obstacle, clearance)

    @property
    def shape(self) -> tuple[int, int]:
        return self.obstacle.shape  # type: ignore[return-value]

    def cell_of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row and column indices ``(iy, ix)`` of the cells containing ``points`` (clipped to the grid)."""
        p = np.asarray(points, dtype=float)
        ny, nx = self.shape
        ix = np.clip(np.floor(p[..., 0] / self.resolution).astype(np.int64), 0, nx - 1)
        iy = np.clip(np.floor(p[..., 1] / self.resolution).astype(np.int64), 0, ny - 1)
        return iy, ix

    def cell_centres(self, iy: np.ndarray, ix: np.ndarray) -> np.ndarray:
        """World coordinates (m) of cell centres, ``(N, 2)``."""
        return np.stack([(np.asarray(ix) + 0.5) * self.resolution, (np.asarray(iy) + 0.5) * self.resolution], -1)

    def space(self, robot_radius: float) -> "ConfigSpace":
        """The configuration space for a disc robot of ``robot_radius`` metres (cached)."""
        if not (math.isfinite(robot_radius) and robot_radius >= 0):
            raise ValueError(f"`robot_radius` must be a finite number >= 0 (metres), got {robot_radius!r}")
        key = round(float(robot_radius), 9)
        if key not in self._spaces:
            free = (self.clearance >= robot_radius) & ~self.obstacle
            # The EDT clearance is within about one cell of the exact distance; in
            # the band where that could flip the decision, decide exactly.
            band = np.abs(self.clearance - robot_radius) <= 1.5 * self.resolution
            iy, ix = np.nonzero(band)
            exact = distance_to_obstacles(self.env, self.cell_centres(iy, ix))
            free[iy, ix] = (exact >= robot_radius) & ~self.obstacle[iy, ix]
            free.flags.writeable = False
            self._spaces[key] = ConfigSpace(self, float(robot_radius), free)
        return self._spaces[key]


@dataclass(frozen=True, eq=False)
class ConfigSpace:
    """Free cells for a disc robot of ``radius`` metres: ``free[iy, ix]`` is True where it fits."""

    grid: GridMap
    radius: float
    free: np.ndarray

    @property
    def env(self) -> Environment:
        return self.grid.env

    @property
    def resolution(self) -> float:
        return self.grid.resolution

    def _free_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Free-cell lookup for coordinates in metres; outside the field or NaN is not free."""
        h = self.resolution
        ny, nx = self.free.shape
        fx, fy = np.floor(x * (1.0 / h)), np.floor(y * (1.0 / h))
        # a point exactly on the far wall belongs to the last cell
        fx = np.where(x == self.env.width, nx - 1, fx)
        fy = np.where(y == self.env.height, ny - 1, fy)
        inside = (fx >= 0) & (fx < nx) & (fy >= 0) & (fy < ny)  # NaN compares False
        flat = np.where(inside, fy * nx + fx, 0).astype(np.intp)
        return inside & self.free.ravel()[flat]

    def is_free(self, points: np.ndarray) -> np.ndarray:
        """True for each point inside the field whose cell is free, ``(N,)`` bool."""
        p = np.asarray(points, dtype=float).reshape(-1, np.shape(points)[-1])
        return self._free_at(p[:, 0], p[:, 1])

    def segments_free(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """True for each segment ``a[i] -> b[i]`` that crosses only free cells (exact).

        The cells a segment crosses are the cells of its two ends and, at every
        grid line it crosses, the cells on both sides; all segments are handled
        at once.  A cell touched only at a corner is not crossed.  Because the
        test is exact, every piece of a free segment is free too.  A segment
        with an end outside the field (or NaN) is not free.
        """
        a = np.asarray(a, dtype=float)[:, :2]
        b = np.asarray(b, dtype=float)[:, :2]
        n = len(a)
        if n == 0:
            return np.zeros(0, dtype=bool)
        ok = self.is_free(a) & self.is_free(b)
        inv_h = 1.0 / self.resolution
        # cell units from here; segments with a bad end are collapsed and already False
        A = np.where(ok[:, None], a, 0.0) * inv_h
        D = np.where(ok[:, None], b, 0.0) * inv_h - A
        ny, nx = self.free.shape
        free = self.free.ravel()
        bad = np.zeros(n, dtype=bool)
        for axis in (0, 1):  # crossings of vertical (x = k) then horizontal (y = k) grid lines
            lo = np.floor(np.minimum(A[:, axis], A[:, axis] + D[:, axis])) + 1
            hi = np.ceil(np.maximum(A[:, axis], A[:, axis] + D[:, axis])) - 1
            count = np.maximum(hi - lo + 1, 0).astype(np.intp)
            total = int(count.sum())
            if total == 0:
                continue
            owner = np.repeat(np.arange(n), count)
            first = np.cumsum(count) - count
            k = np.repeat(lo, count) + (np.arange(total) - np.repeat(first, count))
            t = (k - A[owner, axis]) / D[owner, axis]
            other = 1 - axis
            along = A[owner, other] + D[owner, other] * t
            # at a grid vertex the segment passes diagonally: tilt the other
            # coordinate towards each side's real cell so corner-touched cells are skipped
            tilt = 1e-9 * np.sign(D[owner, 0] * D[owner, 1])
            for side, shift in ((k - 1, -tilt), (k, tilt)):
                c_axis = np.clip(side, 0, (nx, ny)[axis] - 1).astype(np.intp)
                c_other = np.clip(np.floor(along + shift), 0, (nx, ny)[other] - 1).astype(np.intp)
                idx = c_other * nx + c_axis if axis == 0 else c_axis * nx + c_other
                bad[owner[~free[idx]]] = True
        return ok & ~bad

    def first_blocked_segment(self, path: np.ndarray) -> int | None:
        """Index of the first segment of the polyline ``path`` ``(N >= 2, >=2)`` that is not free, or None."""
        p = np.asarray(path, dtype=float)
        bad = np.flatnonzero(~self.segments_free(p[:-1], p[1:]))
        return int(bad[0]) if len(bad) else None

    def path_free(self, path: np.ndarray) -> bool:
        """True when every segment of the polyline ``path`` ``(N, >=2)`` is free."""
        p = np.asarray(path, dtype=float)
        if len(p) == 1:
            return bool(self.is_free(p[:, :2])[0])
        return self.first_blocked_segment(p) is None


@lru_cache(maxsize=16)
def grid_map(env: Environment, resolution: float = 0.01) -> GridMap:
    """Cached :meth:`GridMap.build`: environments are immutable, so grids are shared."""
    return GridMap.build(env, resolution)


def config_space(env: Environment, robot_radius: float, resolution: float = 0.01) -> ConfigSpace:
    """The cached configuration space of ``env`` for a robot of ``robot_radius`` metres."""
    return grid_map(env, float(resolution)).space(robot_radius)
