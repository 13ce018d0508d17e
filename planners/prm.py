"""Probabilistic RoadMap (Kavraki et al.), vectorised.

Build: sample ``samples`` free configurations in batches, join each to its
``k`` nearest neighbours (``scipy.spatial.cKDTree``), collision-check every
candidate edge at once against the configuration space, and keep the free
ones as a sparse graph.  Query: add start and goal the same way and take the
shortest path with ``scipy.sparse.csgraph.dijkstra``.  A roadmap depends only
on the configuration space, ``samples``, ``k`` and the seed, so it is built
once and reused by every query with the same inputs.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from .base import Param, Planner
from .errors import NoPathFound
from .grid import ConfigSpace

__all__ = ["PRMPlanner", "Roadmap", "build_roadmap"]


@dataclass(frozen=True, eq=False)
class Roadmap:
    """Roadmap nodes ``(M, 2)`` (m) and their free edges ``(E, 2)`` (node indices, i < j)."""

    nodes: np.ndarray
    edges: np.ndarray
    tree: cKDTree


def sample_free(space: ConfigSpace, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` uniformly distributed free points (m), drawn in vectorised batches."""
    free_fraction = max(float(space.free.mean()), 1e-3)
    out: list[np.ndarray] = []
    have = 0
    size = np.array([space.env.width, space.env.height])
    for _ in range(100):
        batch = rng.random((int(1.3 * (n - have) / free_fraction) + 16, 2)) * size
        batch = batch[space.is_free(batch)]
        out.append(batch)
        have += len(batch)
        if have >= n:
            return np.concatenate(out)[:n]
    raise NoPathFound("could not sample free configurations: the free space is almost empty")


def _free_edges(space: ConfigSpace, pts: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    if len(pairs) == 0:
        return pairs
    return pairs[space.segments_free(pts[pairs[:, 0]], pts[pairs[:, 1]])]


def _knn_pairs(tree: cKDTree, query: np.ndarray, k: int, offset: int = 0) -> np.ndarray:
    """Unique index pairs (i, j), i < j, joining ``query`` points (indexed from ``offset``) to k neighbours."""
    k = min(k, tree.n)
    _, nb = tree.query(query, k=k)
    nb = np.asarray(nb).reshape(len(query), k)
    src = np.repeat(np.arange(len(query)) + offset, k)
    pairs = np.column_stack([src, nb.ravel()])
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    pairs.sort(axis=1)
    n = int(pairs.max()) + 1 if len(pairs) else 1
    keys = np.unique(pairs[:, 0] * n + pairs[:, 1])  # 1-D keys: much faster than unique(axis=0)
    return np.column_stack([keys // n, keys % n])


def build_roadmap(space: ConfigSpace, samples: int, k: int, seed: int) -> Roadmap:
    """Sample ``samples`` free nodes and connect each to its ``k`` nearest free-edge neighbours."""
    rng = np.random.default_rng(seed)
    nodes = sample_free(space, samples, rng)
    tree = cKDTree(nodes)
    pairs = _knn_pairs(tree, nodes, k + 1)  # +1: the nearest of a node is itself
    return Roadmap(nodes, _free_edges(space, nodes, pairs), tree)


class PRMPlanner(Planner):
    """Probabilistic RoadMap with k-nearest connection; roadmaps cached per configuration space."""

    name = "prm"
    description = "Probabilistic RoadMap: seeded samples, k-nearest edges, Dijkstra query"
    parameters = (Param("samples", "", 500, 2, 200_000, "free samples of the roadmap", type="integer"),
                  Param("k", "", 10, 1, 100, "nearest neighbours each sample is joined to", type="integer"))
    stochastic = True  # the roadmap is a random sample: each seed gives its own path

    def __init__(self) -> None:
        self._cache: weakref.WeakKeyDictionary[ConfigSpace, dict[tuple[int, int, int], Roadmap]]
        self._cache = weakref.WeakKeyDictionary()

    def forget(self) -> None:
        """Drop the cached roadmaps: the next query builds its roadmap, as a single-query PRM does."""
        self._cache = weakref.WeakKeyDictionary()

    def roadmap(self, space: ConfigSpace, samples: int, k: int, seed: int) -> tuple[Roadmap, bool]:
        """The roadmap for these inputs and whether it came from the cache."""
        per_space = self._cache.setdefault(space, {})
        key = (samples, k, seed)
        if key in per_space:
            return per_space[key], True
        rm = build_roadmap(space, samples, k, seed)
        per_space[key] = rm
        return rm, False

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        samples, k = params["samples"], params["k"]
        rm, cached = self.roadmap(space, samples, k, seed)
        m = len(rm.nodes)
        ends = np.array([start[:2], goal[:2]])
        pts = np.vstack([rm.nodes, ends])
        # start/goal join their k nearest roadmap nodes, and each other directly
        query_pairs = np.vstack([_knn_pairs(rm.tree, ends, k, offset=m), [[m, m + 1]]])
        edges = np.vstack([rm.edges, _free_edges(space, pts, query_pairs)])
        w = np.hypot(*(pts[edges[:, 0]] - pts[edges[:, 1]]).T)
        # zero-length edges would vanish from a sparse matrix; keep them tiny instead
        w = np.maximum(w, 1e-12)
        graph = coo_matrix((w, (edges[:, 0], edges[:, 1])), shape=(m + 2, m + 2)).tocsr()
        dist, pred = dijkstra(graph, directed=False, indices=m, return_predecessors=True)
        if not math.isfinite(dist[m + 1]):
            raise NoPathFound(
                f"PRM found no path with {samples} samples and k={k}; "
                "try more samples (planner_params {\"samples\": ...}) or a larger k"
            )
        order = [m + 1]
        while order[-1] != m:  # a loop over the path's nodes only
            order.append(int(pred[order[-1]]))
        path = pts[order[::-1]]
        info = {"roadmap_nodes": m, "roadmap_edges": int(len(rm.edges)), "roadmap_cached": cached}
        return path, info
