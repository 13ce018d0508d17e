"""Probabilistic RoadMap (Kavraki et al.), compiled.

Build: sample ``samples`` free configurations in vectorised batches, join each
to its ``k`` nearest neighbours (PRM*'s ``e (1 + 1/2) ln n`` with
``prm_star``), collision-check the candidate edges with the exact segment test
and keep the free ones.  Query: join start and goal the same way and take the
shortest path with Dijkstra.  Neighbours, edge checks and the query are numba
kernels (:mod:`planners._roadmap`): at the paper's 180 x 180 grids the former
``cKDTree`` / ``np.unique`` / ``scipy.sparse.csgraph.dijkstra`` pipeline spent
most of its time in per-call overhead, and the kernels give the same roadmap
and path for a seed.  With ``grow`` (the default) a roadmap
that does not connect start and goal doubles (new samples from the same
seeded stream, each joined to its nearest among all nodes) until it does or
``max_samples`` or ``time_budget_s`` runs out; without it the roadmap has
``samples`` nodes, the paper's fixed-sample PRM.  A roadmap depends only on
the configuration space, the parameters and the seed, so it is built once
and reused by every query with the same inputs (a grown roadmap is read back
at the stage each query needs: the path does not depend on earlier queries).
"""

from __future__ import annotations

import math
import time
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from .base import Param, Planner
from .errors import NoPathFound
from .grid import ConfigSpace

__all__ = ["PRMPlanner", "Roadmap", "build_roadmap", "prm_star_k"]


@dataclass(frozen=True, eq=False)
class Roadmap:
    """Roadmap nodes ``(M, 2)`` (m) and their free edges ``(E, 2)`` (node indices, i < j)."""

    nodes: np.ndarray
    edges: np.ndarray


class _Kernels:
    """The compiled kernels of :mod:`planners._roadmap` bound to one configuration space (made once per space)."""

    def __init__(self, space: ConfigSpace) -> None:
        import planners._roadmap as _roadmap  # numba loads with it

        _roadmap.warm()
        ny, nx = space.free.shape
        self.mod = _roadmap
        self.args = (np.ascontiguousarray(space.free.ravel(), dtype=np.uint8), nx, ny, 1.0 / space.resolution,
                     float(space.env.width), float(space.env.height))
        self.free_fraction = max(float(space.free.mean()), 1e-3)
        # per cell, a lower bound (cells) on the distance from its centre to any non-free cell (outside the
        # field counts as non-free): the centre-to-centre distance less a half-diagonal
        centres = ndimage.distance_transform_edt(np.pad(space.free, 1, constant_values=False))[1:-1, 1:-1]
        # (float32: half the memory; the 1e-3 cell margin exceeds its rounding below 8000 cells)
        self.reach = np.ascontiguousarray((centres - (math.sqrt(0.5) + 1e-3)).ravel(), dtype=np.float32)
        self.size = np.array([space.env.width, space.env.height])

    def is_free(self, pts: np.ndarray) -> np.ndarray:
        """``ConfigSpace.is_free`` of ``(N, 2)`` points (m), compiled: ``(N,)`` bool."""
        return self.mod.points_free(*self.args, pts)

    def knn_edges(self, nodes: np.ndarray, first: int, k: int) -> np.ndarray:
        """Free edges ``(E, 2)`` (i < j) joining ``nodes[first:]`` to their ``k`` nearest among all ``nodes``
        (themselves excepted)."""
        nodes = np.ascontiguousarray(nodes, dtype=float)
        nb = self.mod.knn(nodes, len(nodes), nodes[first:], k + 1, *self.args[4:])  # +1: a node's nearest is itself
        return self.mod.free_knn_edges(*self.args, self.reach, nodes, nb, first)

    def query(self, nodes: np.ndarray, edges: np.ndarray, start: np.ndarray, goal: np.ndarray,
              k: int) -> np.ndarray | None:
        """The shortest roadmap path start -> goal ``(N, 2)`` (m), start and goal joined to their ``k`` nearest
        nodes and each other; None when they do not connect."""
        nodes = np.ascontiguousarray(nodes, dtype=float)
        order = self.mod.query_path(*self.args, self.reach, nodes, np.ascontiguousarray(edges, dtype=np.int64),
                                    float(start[0]), float(start[1]), float(goal[0]), float(goal[1]), k)
        if len(order) == 0:
            return None
        return np.vstack([nodes, np.array([start[:2], goal[:2]], dtype=float)])[order]


def _kernels(space: ConfigSpace) -> _Kernels:
    """The space's :class:`_Kernels`, made once per space."""
    kern = space.__dict__.get("_prm_kernels")
    if kern is None:
        kern = _Kernels(space)
        object.__setattr__(space, "_prm_kernels", kern)
    return kern


def sample_free(space: ConfigSpace, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` uniformly distributed free points (m), drawn in vectorised batches."""
    kern = _kernels(space)
    out: list[np.ndarray] = []
    have = 0
    for _ in range(100):
        batch = rng.random((int(1.3 * (n - have) / kern.free_fraction) + 16, 2)) * kern.size
        batch = batch[kern.is_free(batch)]
        out.append(batch)
        have += len(batch)
        if have >= n:
            return np.concatenate(out)[:n]
    raise NoPathFound("could not sample free configurations: the free space is almost empty")


def build_roadmap(space: ConfigSpace, samples: int, k: int, seed: int) -> Roadmap:
    """Sample ``samples`` free nodes and connect each to its ``k`` nearest free-edge neighbours."""
    rng = np.random.default_rng(seed)
    nodes = sample_free(space, samples, rng)
    return Roadmap(nodes, _kernels(space).knn_edges(nodes, 0, k))


def prm_star_k(n: int) -> int:
    """PRM*'s neighbour count for ``n`` nodes in the plane: ``ceil(e (1 + 1/2) ln n)`` (Karaman and Frazzoli 2011)."""
    return max(1, math.ceil(math.e * 1.5 * math.log(max(n, 2))))


@dataclass
class _Growing:
    """A roadmap grown in stages from one seed: stage ``s`` holds the first ``sizes[s]`` nodes and exactly the
    edges among them (each node was joined to its neighbours among the nodes before it and itself), so any
    stage can be read back from a larger roadmap: a query's path does not depend on what earlier queries grew."""

    rng: np.random.Generator
    nodes: np.ndarray
    edges: np.ndarray
    sizes: list[int]

    def grow(self, space: ConfigSpace, n: int, k: int, star: bool) -> None:
        """Add free samples up to ``n`` nodes, each joined to its k (or PRM*'s k) nearest among all."""
        have = len(self.nodes)
        new = sample_free(space, n - have, self.rng)
        nodes = np.vstack([self.nodes, new]) if have else new
        kk = prm_star_k(n) if star else k
        self.nodes = nodes
        self.edges = np.vstack([self.edges, _kernels(space).knn_edges(nodes, have, kk)])
        self.sizes.append(n)

    def stage(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """Nodes and edges of stage ``s``."""
        n = self.sizes[s]
        return self.nodes[:n], self.edges[self.edges[:, 1] < n]


class PRMPlanner(Planner):
    """Probabilistic RoadMap, grown until start and goal connect; roadmaps cached per configuration space."""

    name = "prm"
    description = "Probabilistic RoadMap: seeded samples grown until start and goal connect, k-nearest edges, Dijkstra"
    parameters = (
        Param("samples", "", 500, 2, 200_000, "free samples of the first roadmap (all of it unless grow)",
              type="integer"),
        Param("k", "", 10, 1, 100, "nearest neighbours each sample is joined to (unless prm_star)", type="integer"),
        Param("grow", "", True, None, None, "double the roadmap until start and goal connect (false: the paper's "
              "fixed sample count)", type="boolean"),
        Param("max_samples", "", 50_000, 2, 1_000_000, "the sample budget of a growing roadmap (it grows no further; "
              "the first roadmap has samples nodes in any case)", type="integer"),
        Param("time_budget_s", "s", 0.5, 0.0, 600.0, "stop growing after this planning time", low_exclusive=True),
        Param("prm_star", "", False, None, None, "join each sample to PRM*'s e(1 + 1/2) ln n nearest instead of k",
              type="boolean"),
    )
    stochastic = True  # the roadmap is a random sample: each seed gives its own path

    def __init__(self) -> None:
        self._cache: weakref.WeakKeyDictionary[ConfigSpace, dict[tuple[Any, ...], Any]]
        self._cache = weakref.WeakKeyDictionary()

    def forget(self) -> None:
        """Drop the cached roadmaps: the next query builds its roadmap, as a single-query PRM does."""
        self._cache = weakref.WeakKeyDictionary()

    def roadmap(self, space: ConfigSpace, samples: int, k: int, seed: int) -> tuple[Roadmap, bool]:
        """The fixed-size roadmap for these inputs and whether it came from the cache."""
        per_space = self._cache.setdefault(space, {})
        key = (samples, k, seed)
        if key in per_space:
            return per_space[key], True
        rm = build_roadmap(space, samples, k, seed)
        per_space[key] = rm
        return rm, False

    def _growing(self, space: ConfigSpace, samples: int, k: int, star: bool, seed: int) -> tuple[_Growing, bool]:
        per_space = self._cache.setdefault(space, {})
        key = ("grow", samples, k, star, seed)
        cached = key in per_space
        if not cached:
            g = _Growing(np.random.default_rng(seed), np.zeros((0, 2)), np.zeros((0, 2), dtype=np.int64), [])
            g.grow(space, samples, k, star)
            per_space[key] = g
        return per_space[key], cached

    @staticmethod
    def _query(space: ConfigSpace, nodes: np.ndarray, edges: np.ndarray, start: np.ndarray, goal: np.ndarray,
               k: int) -> np.ndarray | None:
        """The shortest roadmap path start -> goal ``(N, 2)`` (m), or None when they do not connect."""
        return _kernels(space).query(nodes, edges, start, goal, k)

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        params = {**(self.defaults or {}), **params}  # direct callers may give only some
        samples, k, star = params["samples"], params["k"], params["prm_star"]
        if not params["grow"]:
            if star:
                k = prm_star_k(samples)
            rm, cached = self.roadmap(space, samples, k, seed)
            path = self._query(space, rm.nodes, rm.edges, start, goal, k)
            if path is None:
                raise NoPathFound(
                    f"PRM found no path with {samples} samples and k={k}; "
                    "try more samples (planner_params {\"samples\": ...}), a larger k or grow"
                )
            info = {"roadmap_nodes": len(rm.nodes), "roadmap_edges": len(rm.edges), "roadmap_cached": cached}
            return path, info
        _kernels(space)  # made (and numba loaded) once per space: not part of the time budget
        t0 = time.perf_counter()
        g, cached = self._growing(space, samples, k, star, seed)
        s = 0
        while True:
            nodes, edges = g.stage(s)
            kq = prm_star_k(len(nodes)) if star else k
            path = self._query(space, nodes, edges, start, goal, kq)
            if path is not None:
                info = {"roadmap_nodes": len(nodes), "roadmap_edges": len(edges), "roadmap_cached": cached,
                        "roadmap_stages": s + 1}
                return path, info
            n = min(2 * len(nodes), params["max_samples"])
            if n <= len(nodes):
                raise NoPathFound(f"PRM found no path with its sample budget of {len(nodes)} samples "
                                  f"(max_samples); try a larger max_samples")
            if time.perf_counter() - t0 > params["time_budget_s"]:
                raise NoPathFound(f"PRM found no path within its time budget of {params['time_budget_s']:g} s "
                                  f"({len(nodes)} samples; time_budget_s)")
            s += 1
            if s >= len(g.sizes):
                g.grow(space, n, k, star)
