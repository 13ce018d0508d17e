"""The planner benchmark's problem set and its optima (issue 31).

A *problem* is an environment, a start and a goal (m).  :func:`problems` returns the paper's four (``room``
and ``blocks``, plans A and B) and three harder ones shipped in ``planners/data/problems/`` (not built-in
environments of the testbed):

- ``narrow``: a wall across the field with one 0.15 m gap (0.02 m of free width at 0.065 m clearance);
- ``clutter``: 30 seeded random blocks, corner to corner;
- ``zigzag``: a serpentine corridor through five walls.

Each has plan A corner to corner and plan B back (the same optimum), so that a study's plans A and B exist in
every environment (``twb study planners``).

Each carries its **optimum**: the length (m) of the shortest path keeping :data:`PROBLEM_CLEARANCE` from every
block and wall by the exact distance, computed on the visibility graph of the inflated blocks
(:func:`visibility_optimum`) and stored with the problem, so that a study reports length / optimum without
recomputing it.
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from .environment import Environment, load_environment
from .geometry import block_corners, distance_to_obstacles, segment_clearance
from .grid import config_space

__all__ = ["HARD", "PAPER", "PROBLEM_CLEARANCE", "Problem", "generate_environments", "problems", "stored_optimum",
           "visibility_optimum"]

#: the clearance (m) the problems are posed for: the BeBot's radius plus the planning margin
PROBLEM_CLEARANCE = 0.065
PAPER = (("room", "A"), ("room", "B"), ("blocks", "A"), ("blocks", "B"))
HARD = ("narrow", "clutter", "zigzag")


@dataclass(frozen=True)
class Problem:
    """One benchmark problem: ``env``, ``start`` and ``goal`` (x, y, theta; m, rad) and the stored ``optimum_m``."""

    name: str
    env: Environment
    start: tuple[float, float, float]
    goal: tuple[float, float, float]
    optimum_m: float


def _arc_vertices(corners: np.ndarray, clearance: float, per_turn: int) -> np.ndarray:
    """Vertices of a regular ``per_turn``-gon circumscribing the circle of ``clearance`` (m) round every corner."""
    ang = (np.arange(per_turn) + 0.5) * (2 * math.pi / per_turn)
    rad = clearance / math.cos(math.pi / per_turn) * (1 + 1e-9)
    ring = rad * np.column_stack([np.cos(ang), np.sin(ang)])
    return (corners.reshape(-1, 1, 2) + ring[None]).reshape(-1, 2)


def visibility_optimum(env: Environment, start: np.ndarray, goal: np.ndarray, clearance: float = PROBLEM_CLEARANCE,
                       *, per_turn: int = 64, chunk: int = 200_000) -> tuple[float, np.ndarray]:
    """The shortest path (m) from ``start`` to ``goal`` keeping ``clearance`` (m) from blocks and walls.

    The blocks inflated by ``clearance`` have rounded corners; each corner's circle is replaced by the
    circumscribed ``per_turn``-gon (a path round it is feasible and at most ``clearance * angle * (sec(pi /
    per_turn) - 1)`` longer than round the arc: under 0.1 mm a quarter turn at 0.065 m and 64).  Nodes: the
    polygon vertices outside every inflated block and wall band, the start and the goal; edges: every pair
    whose segment keeps ``clearance`` by the exact distance (:func:`~planners.geometry.segment_clearance`,
    ``chunk`` pairs at a time); Dijkstra.  Returns the length and the path ``(N, 2)``; ``inf`` and an empty
    path when no path exists.
    """
    s, g = np.asarray(start, dtype=float)[:2], np.asarray(goal, dtype=float)[:2]
    verts = _arc_vertices(block_corners(env).reshape(-1, 2), clearance, per_turn)
    verts = verts[distance_to_obstacles(env, verts) >= clearance]
    pts = np.vstack([s, g, verts])
    n = len(pts)
    i, j = np.triu_indices(n, 1)
    keep = np.zeros(len(i), dtype=bool)
    for lo in range(0, len(i), chunk):
        sl = slice(lo, lo + chunk)
        keep[sl] = segment_clearance(env, pts[i[sl]], pts[j[sl]]) >= clearance * (1 - 1e-7)
    i, j = i[keep], j[keep]
    w = np.maximum(np.hypot(*(pts[i] - pts[j]).T), 1e-15)
    graph = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
    dist, pred = dijkstra(graph, directed=False, indices=0, return_predecessors=True)
    if not math.isfinite(dist[1]):
        return math.inf, np.zeros((0, 2))
    order = [1]
    while order[-1] != 0:  # a loop over the path's vertices only
        order.append(int(pred[order[-1]]))
    return float(dist[1]), pts[order[::-1]]


def _load(name: str) -> dict:
    """The stored JSON ``planners/data/problems/<name>.json``: an environment file, or the optima."""
    return json.loads(resources.files("planners").joinpath("data", "problems", f"{name}.json").read_text("utf-8"))


def problems(names: tuple[str, ...] | None = None) -> list[Problem]:
    """The problem set (default: :data:`PAPER` then :data:`HARD`), each with its stored optimum (m)."""
    stored = _load("optima")
    out = []
    for key in names or tuple(f"{e}-{p}" for e, p in PAPER) + HARD:
        env_name, _, plan = key.partition("-")
        env = load_environment(env_name) if env_name in ("room", "blocks") else load_environment(_load(env_name))
        pl = env.plan(plan or "A")
        out.append(Problem(key, env, pl.start, pl.goal, float(stored[key])))
    return out


@functools.cache
def _every_problem() -> tuple[Problem, ...]:
    """Every problem whose optimum is stored (each environment's plan A and plan B)."""
    return tuple(problems(tuple(_load("optima"))))


def stored_optimum(env: Environment, start: Sequence[float], goal: Sequence[float]) -> float | None:
    """The stored optimum (m) of the problem posed by ``env`` (the same size and blocks as a problem of the set),
    ``start`` and ``goal`` (x, y within 1 mm of its own; m); None for any other problem."""
    for p in _every_problem():
        if (p.env.size == env.size and p.env.blocks == env.blocks
                and math.dist(p.start[:2], start[:2]) < 1e-3 and math.dist(p.goal[:2], goal[:2]) < 1e-3):
            return p.optimum_m
    return None


def _both_ways(a: list[float], b: list[float]) -> list[dict]:
    """Plan A from ``a`` to ``b`` and plan B back (m), so that a study's plans A and B exist in every environment."""
    return [{"name": "A", "start": [*a, 0.0], "goal": [*b, 0.0]}, {"name": "B", "start": [*b, 0.0], "goal": [*a, 0.0]}]


def _clutter(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    blocks: list[dict] = []
    while len(blocks) < 30:
        x, y = rng.uniform(0.15, 1.65, 2)
        w, h = rng.uniform(0.06, 0.2, 2)
        if min(math.hypot(x - 0.2, y - 0.2), math.hypot(x - 1.6, y - 1.6)) < 0.3:
            continue  # keep the corners free for the start and goal
        blocks.append({"x": round(float(x), 3), "y": round(float(y), 3), "w": round(float(w), 3),
                       "h": round(float(h), 3), "angle": round(float(rng.uniform(0, math.pi)), 4)})
    return {"name": "clutter", "size": [1.8, 1.8],
            "description": f"30 random blocks (numpy seed {seed}), 0.06-0.2 m a side, any angle.",
            "blocks": blocks, "plans": _both_ways([0.2, 0.2], [1.6, 1.6])}


def generate_environments() -> dict[str, dict]:
    """The three hard environments as environment-file dicts (how ``planners/data/problems/`` was written)."""
    narrow = {"name": "narrow", "size": [1.8, 1.8],
              "description": "A 0.1 m wall across the field at x = 0.9 m with one 0.15 m gap (y 0.8 to 0.95 m).",
              "blocks": [{"x": 0.9, "y": 0.4, "w": 0.1, "h": 0.8, "angle": 0.0},
                         {"x": 0.9, "y": 1.375, "w": 0.1, "h": 0.85, "angle": 0.0}],
              "plans": _both_ways([0.3, 0.3], [1.5, 1.5])}
    seed = 31
    while True:  # the first seed from 31 whose corners are connected at PROBLEM_CLEARANCE
        clutter = _clutter(seed)
        space = config_space(load_environment(clutter), PROBLEM_CLEARANCE)
        labels, _ = ndimage.label(space.free)
        (sy, gy), (sx, gx) = space.grid.cell_of(np.array([[0.2, 0.2], [1.6, 1.6]]))
        if labels[sy, sx] == labels[gy, gx] != 0:
            break
        seed += 1
    walls = []
    for k in range(5):
        x = 0.3 * (k + 1)
        y = 0.75 if k % 2 == 0 else 1.05  # a 0.3 m opening at the top, then at the bottom, ...
        walls.append({"x": x, "y": y, "w": 0.05, "h": 1.5, "angle": 0.0})
    zigzag = {"name": "zigzag", "size": [1.8, 1.8],
              "description": "Five 1.5 m walls 0.3 m apart, open alternately at the top and bottom: a serpentine.",
              "blocks": walls,
              "plans": _both_ways([0.15, 0.15], [1.65, 1.65])}
    return {"narrow": narrow, "clutter": clutter, "zigzag": zigzag}
