"""Generated world sets: BARN-like worlds on a sub-field, each solvable by FMM, with difficulty metrics.

After BARN (Perille, Truong, Xiao and Stone, *Benchmarking Metric Ground Navigation*, SSRR 2020): a
world is an occupancy grid of ``cells x cells`` square cells over the field (30 x 30 on a 1.8 m
sub-field: 0.06 m cells), made either by a cellular automaton (``cave``: cells filled at random with
probability ``fill``, then smoothed ``smooth`` times by the 4-5 rule: a cell is filled when at least five
of its eight neighbours are, emptied when at most three are) or by random rectangles (``blocks``).
The grid becomes the environment's blocks (rectangles of cells, runs merged), the start and goal areas
are kept clear, and the world is kept only if FMM (:func:`planners.api.plan_path`, the testbed's robot
radius and planning margin) finds a path from start to goal; otherwise the generator draws again.

The difficulty metrics are BARN's, computed along that FMM path (points every ``spacing`` m) and
averaged over its points, in metres where they are lengths:

- ``distance_to_obstacle_m``: the distance from the point to the nearest block or wall (exact);
- ``visibility_m``: the mean, over ``rays`` directions, of how far a ray from the point travels before it
  meets an obstacle, at most ``ray_range`` m;
- ``dispersion``: how many times, going round the ``rays`` directions, a ray's reaching ``ray_range``
  changes (an opening begins or ends): twice the number of openings around the point;
- ``characteristic_dimension_m``: the narrowest width through the point, the least over directions of
  the visibility forward plus backward (both capped at ``ray_range``);
- ``tortuosity``: the path's length over the straight distance from start to goal (1: straight).

Rays march in steps of ``resolution`` m over the occupancy grid of that resolution
(:class:`planners.grid.GridMap`), so their lengths are within a step (plus a cell) of the exact ones.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy import ndimage

from .api import plan_path
from .environment import Environment, parse_environment
from .errors import PlanningError
from .geometry import distance_to_obstacles
from .grid import grid_map

__all__ = [
    "KINDS",
    "Difficulty",
    "GeneratedWorld",
    "block_grid",
    "cave_grid",
    "difficulty",
    "generate_world",
    "generate_worlds",
    "grid_blocks",
    "point_metrics",
]

KINDS = ("cave", "blocks")
START = (0.9, 0.15, math.pi / 2)  #: where every generated world's robot starts (m, m, rad): bottom centre
GOAL = (0.9, 1.65, math.pi / 2)  #: and where it goes: top centre
ROBOT_RADIUS, PLANNING_MARGIN = 0.045, 0.02  # the testbed's (BeBot profile; planners.api)
MAX_ATTEMPTS = 200


@dataclass(frozen=True)
class Difficulty:
    """BARN's difficulty metrics of a world along a path (see the module docstring; lengths in m)."""

    distance_to_obstacle_m: float
    visibility_m: float
    dispersion: float
    characteristic_dimension_m: float
    tortuosity: float

    def to_dict(self) -> dict[str, float]:
        """The metrics by name."""
        return {k: float(v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class GeneratedWorld:
    """One generated world: its ``environment`` (with plan ``A`` from :data:`START` to :data:`GOAL`), the
    ``path`` FMM found ``(N, 3)``, its ``difficulty``, the ``seed`` it was drawn from, its ``kind`` and
    ``params`` (fill and smoothing of a cave, rectangle count of blocks) and ``attempts`` (draws until one
    was solvable)."""

    environment: Environment
    path: np.ndarray
    difficulty: Difficulty
    seed: int
    kind: str
    params: dict[str, float]
    attempts: int


# ------------------------------------------------------------------------------------------------ grids


def _cells_iv(cells: int) -> None:
    if not (isinstance(cells, (int, np.integer)) and cells >= 8):
        raise ValueError(f"`cells` must be an integer >= 8, got {cells!r}")


def cave_grid(rng: np.random.Generator, cells: int, fill: float, smooth: int) -> np.ndarray:
    """A ``(cells, cells)`` bool grid (True: obstacle; row 0 at the bottom) grown by the cellular automaton:
    random ``fill`` (0..1), then ``smooth`` rounds of the 4-5 rule (cells off the grid count as free)."""
    _cells_iv(cells)
    if not 0.0 <= fill <= 1.0:
        raise ValueError(f"`fill` must be in [0, 1], got {fill!r}")
    if not (isinstance(smooth, (int, np.integer)) and smooth >= 0):
        raise ValueError(f"`smooth` must be an integer >= 0, got {smooth!r}")
    grid = rng.random((cells, cells)) < fill
    kernel = np.ones((3, 3), dtype=np.int64)
    kernel[1, 1] = 0
    for _ in range(int(smooth)):
        around = ndimage.convolve(grid.astype(np.int64), kernel, mode="constant", cval=0)
        grid = np.where(around >= 5, True, np.where(around <= 3, False, grid))
    return grid


def block_grid(rng: np.random.Generator, cells: int, count: int, max_side: int = 6) -> np.ndarray:
    """A ``(cells, cells)`` bool grid of ``count`` random rectangles of 1 to ``max_side`` cells a side."""
    _cells_iv(cells)
    grid = np.zeros((cells, cells), dtype=bool)
    for _ in range(int(count)):
        w, h = rng.integers(1, max_side + 1, size=2)
        x, y = rng.integers(0, cells - w + 1), rng.integers(0, cells - h + 1)
        grid[y:y + h, x:x + w] = True
    return grid


def grid_blocks(grid: np.ndarray, cell: float) -> list[dict[str, float]]:
    """The obstacle cells of ``grid`` as environment blocks (centre, size; m) of ``cell`` m cells: each row's
    runs, merged with the same run of the rows above."""
    rows = grid.shape[0]
    open_runs: dict[tuple[int, int], int] = {}  # (x0, x1) -> first row
    out: list[tuple[int, int, int, int]] = []
    for y in range(rows + 1):
        runs: set[tuple[int, int]] = set()
        if y < rows:
            row = np.concatenate([[False], grid[y], [False]])
            edges = np.flatnonzero(row[1:] != row[:-1])
            runs = {(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])}
        for run in list(open_runs):
            if run not in runs:
                out.append((run[0], run[1], open_runs.pop(run), y))
        for run in runs:
            open_runs.setdefault(run, y)
    return [{"x": (x0 + x1) / 2 * cell, "y": (y0 + y1) / 2 * cell, "w": (x1 - x0) * cell, "h": (y1 - y0) * cell,
             "angle": 0.0} for x0, x1, y0, y1 in sorted(out, key=lambda r: (r[2], r[0]))]


def _clear(grid: np.ndarray, cell: float, centre: Sequence[float], radius: float) -> None:
    """Empty the cells within ``radius`` (m) of ``centre`` (m), in place."""
    n = grid.shape[0]
    c = (np.arange(n) + 0.5) * cell
    near = (c[None, :] - centre[0]) ** 2 + (c[:, None] - centre[1]) ** 2 <= radius ** 2
    grid[near] = False


# ------------------------------------------------------------------------------------------------ metrics


def point_metrics(env: Environment, points: np.ndarray, *, rays: int = 32, ray_range: float = 0.6,
                  resolution: float = 0.01) -> dict[str, np.ndarray]:
    """Per point ``(P, 2)`` (m): ``distance_to_obstacle_m``, ``visibility_m``, ``dispersion`` and
    ``characteristic_dimension_m`` (see the module docstring), each ``(P,)``."""
    if not (isinstance(rays, (int, np.integer)) and rays >= 4 and rays % 2 == 0):
        raise ValueError(f"`rays` must be an even integer >= 4, got {rays!r}")
    if not (math.isfinite(ray_range) and ray_range > 0):
        raise ValueError(f"`ray_range` must be > 0 (m), got {ray_range!r}")
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    gm = grid_map(env, resolution)
    ny, nx = gm.shape
    steps = max(1, math.ceil(ray_range / resolution))
    ang = 2.0 * math.pi * np.arange(rays) / rays
    dist = resolution * np.arange(1, steps + 1)
    xs = p[:, None, None, 0] + np.cos(ang)[None, :, None] * dist[None, None, :]  # (P, D, S)
    ys = p[:, None, None, 1] + np.sin(ang)[None, :, None] * dist[None, None, :]
    ix, iy = np.floor(xs / resolution).astype(np.int64), np.floor(ys / resolution).astype(np.int64)
    inside = (ix >= 0) & (iy >= 0) & (ix < nx) & (iy < ny)
    blocked = ~inside
    blocked[inside] = gm.obstacle[iy[inside], ix[inside]]
    hit = blocked.any(axis=2)
    first = np.argmax(blocked, axis=2)  # the first blocked step (0 if none: masked by hit)
    vis = np.where(hit, first * resolution, ray_range).clip(max=ray_range)  # (P, D): free run before the hit
    long = vis >= ray_range
    dispersion = (long != np.roll(long, -1, axis=1)).sum(axis=1).astype(float)
    half = rays // 2
    width = (vis[:, :half] + vis[:, half:]).min(axis=1)
    return {"distance_to_obstacle_m": distance_to_obstacles(env, p), "visibility_m": vis.mean(axis=1),
            "dispersion": dispersion, "characteristic_dimension_m": width}


def _resample(path: np.ndarray, spacing: float) -> np.ndarray:
    xy = np.asarray(path, dtype=float)[:, :2]
    seg = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    at = np.linspace(0.0, s[-1], max(2, math.ceil(s[-1] / spacing) + 1))
    return np.column_stack([np.interp(at, s, xy[:, 0]), np.interp(at, s, xy[:, 1])])


def difficulty(env: Environment, path: np.ndarray, *, spacing: float = 0.02, rays: int = 32,
               ray_range: float = 0.6, resolution: float = 0.01) -> Difficulty:
    """BARN's metrics of ``env`` along ``path`` ``(N, 2+)`` (m), its points every ``spacing`` m averaged."""
    if not (math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"`spacing` must be > 0 (m), got {spacing!r}")
    xy = np.asarray(path, dtype=float)
    if xy.ndim != 2 or len(xy) < 2 or xy.shape[1] < 2:
        raise ValueError("`path` must have at least two points (N, 2+)")
    pts = _resample(xy, spacing)
    m = point_metrics(env, pts, rays=rays, ray_range=ray_range, resolution=resolution)
    length = float(np.hypot(*np.diff(xy[:, :2], axis=0).T).sum())
    chord = float(math.hypot(*(xy[-1, :2] - xy[0, :2])))
    return Difficulty(float(m["distance_to_obstacle_m"].mean()), float(m["visibility_m"].mean()),
                      float(m["dispersion"].mean()), float(m["characteristic_dimension_m"].mean()),
                      length / chord if chord > 0 else 1.0)


# ------------------------------------------------------------------------------------------------ worlds


def generate_world(seed: int, *, kind: str = "cave", name: str | None = None, size: float = 1.8, cells: int = 30,
                   max_attempts: int = MAX_ATTEMPTS) -> GeneratedWorld:
    """One world from ``seed`` (see the module docstring): a ``kind`` world of ``cells x cells`` cells on a
    ``size`` m square field, redrawn until FMM solves plan ``A``.  Raises ``ValueError`` for bad
    arguments, ``RuntimeError`` when ``max_attempts`` draws gave no solvable world."""
    if kind not in KINDS:
        raise ValueError(f"`kind` must be one of {', '.join(KINDS)}, got {kind!r}")
    if not (math.isfinite(size) and size >= 1.0):
        raise ValueError(f"`size` must be >= 1.0 (m), got {size!r}")
    _cells_iv(cells)
    rng = np.random.default_rng(seed)
    cell = size / cells
    start = (START[0] * size / 1.8, START[1] * size / 1.8, START[2])
    goal = (GOAL[0] * size / 1.8, GOAL[1] * size / 1.8, GOAL[2])
    name = name or f"{kind}-{seed}"
    for attempt in range(1, max_attempts + 1):
        if kind == "cave":
            params = {"fill": float(rng.uniform(0.35, 0.55)), "smooth": int(rng.integers(1, 5))}
            grid = cave_grid(rng, cells, params["fill"], params["smooth"])
        else:
            params = {"count": int(rng.integers(8, 40))}
            grid = block_grid(rng, cells, params["count"])
        for point in (start, goal):
            _clear(grid, cell, point, 0.15)
        env = parse_environment({
            "name": name, "size": [size, size], "blocks": grid_blocks(grid, cell),
            "plans": [{"name": "A", "start": list(start), "goal": list(goal)}],
            "description": f"generated {kind} world (seed {seed}, {', '.join(f'{k} {v:.3g}' for k, v in params.items())})"})
        try:
            plan = plan_path(env, start, goal, "fmm", robot_radius=ROBOT_RADIUS, planning_margin=PLANNING_MARGIN)
        except PlanningError:
            continue
        return GeneratedWorld(env, plan.path, difficulty(env, plan.path), int(seed), kind,
                              {k: float(v) for k, v in params.items()}, attempt)
    raise RuntimeError(f"no solvable {kind} world in {max_attempts} draws from seed {seed}")


def generate_worlds(count: int, seed: int, *, kind: str = "cave", prefix: str | None = None,
                    cells: int = 30) -> list[GeneratedWorld]:
    """``count`` worlds, world ``i`` from seed ``seed + i`` and named ``<prefix>-<i>`` (default prefix
    ``<kind>-<seed>``); the same arguments give the same worlds."""
    if not (isinstance(count, (int, np.integer)) and 1 <= count <= 10_000):
        raise ValueError(f"`count` must be an integer in [1, 10000], got {count!r}")
    prefix = prefix or f"{kind}-{seed}"
    return [generate_world(seed + i, kind=kind, name=f"{prefix}-{i:03d}", cells=cells) for i in range(count)]
