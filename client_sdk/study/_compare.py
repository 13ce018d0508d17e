"""Comparisons between a study's configurations: per problem and pooled over problems (the unit of inference).

The statistics are :mod:`planners.comparisons`' — the one implementation the
server's ``GET /api/v1/comparisons``, ``twb results`` and the dashboard use too
(docs/study.md, "Comparisons"), called as every surface calls it
(:func:`planners.compared.compare_runs`: the default metrics, a fleet's safety
metrics compared over every measured run, the fleet metrics' directions); this
module adds what a study knows: its configurations, modes and problems in study
order.

- **The problem is the unit**: per (metric, mode, pair) one comparison per
  problem (environment, plan), and a pooled one over problems when there are at
  least three; its uncertainty comes from the problems, not from the runs.
- **Pairing within a problem**: the study gives every configuration the same
  noise seed per repetition (common random numbers), so repetition k of a and of
  b are paired when both ran the same repetitions.
- **Identical repetitions** (the deterministic simulation without jitter) count
  once per problem; with nothing left to vary there is no interval and no test.
- **Holm** within each metric's pooled rows, and apart within its per-problem rows
  (``family="all"``: all metrics together).
"""

from __future__ import annotations

from itertools import combinations
from typing import Iterable, Optional

from planners.compared import COMPARED_METRICS, CONTROLLER_METRICS, DIRECTION, compare_runs, compared_over
from planners.comparisons import COLUMNS as COMPARISON_COLUMNS
from planners.comparisons import Comparison, Comparisons

from ._records import StudyRecords

__all__ = ["COMPARISON_COLUMNS", "COMPARED_METRICS", "CONTROLLER_METRICS", "Comparison", "Comparisons", "DIRECTION",
           "compare", "compared_over"]

# COMPARED_METRICS, CONTROLLER_METRICS, DIRECTION and compared_over live in planners.compared, with
# compare_runs: GET /api/v1/comparisons compares a selection of experiments with the same defaults.


def compare(
    data: StudyRecords,
    metrics: Optional[Iterable[str]] = None,
    *,
    modes: Optional[Iterable[str]] = None,
    pairs: Optional[Iterable[tuple[str, str]]] = None,
    confidence: float = 0.95,
    family: str = "metric",
    test: str = "t",
    n_resamples: int = 9999,
    seed: int = 0,
) -> Comparisons:
    """Compare every pair of the study's configurations, per mode, on the success rate and each metric: on
    each problem, and pooled over the problems when there are at least three (:func:`planners.comparisons.compare`).

    Parameters
    ----------
    data : StudyRecords
    metrics : iterable of str, optional
        Metrics (runs.csv columns) to compare after ``success_rate``; default
        :data:`COMPARED_METRICS`, and :data:`CONTROLLER_METRICS` when the
        study compares controllers; a fleet study's
        :data:`~client_sdk.study._fleet_results.FLEET_COMPARED`.  A metric is
        compared over the completed runs, a fleet's safety metrics over every
        measured run (``FLEET_METRICS``' ``over``).
    modes : iterable of str, optional
        Default: the study's modes.
    pairs : iterable of (a, b), optional
        Default: every pair of configurations, in study order (a before b).
    confidence : float
        Level of the intervals (default 0.95).
    family : {"metric", "all"}
        Holm's family: each metric's comparisons (pooled and per-problem apart), or the whole table.
    test : {"t", "rank"}
        t tests (per problem paired t or Welch, over problems one-sample t) or rank tests (Wilcoxon /
        Mann-Whitney U, over problems Wilcoxon signed-rank).
    n_resamples, seed : int
        Bootstrap resamples and the seed of the first comparison (each
        comparison has its own stream, numbered in the order of the metrics,
        modes, pairs and problems, in study order: ``GET /api/v1/comparisons``
        of the study's experiments in study order gives the same numbers).

    Returns
    -------
    Comparisons
        A list of :class:`Comparison`; differences are ``a - b``; ``problem`` None for the pooled ones.
    """
    return compare_runs(data.rows, metrics, fleet=data.spec.fleet, controllers=data.spec.controllers is not None,
                        modes=modes if modes is not None else data.modes,
                        pairs=pairs if pairs is not None else list(combinations(data.configurations, 2)),
                        problems=data.problems, confidence=confidence, family=family, test=test,
                        n_resamples=n_resamples, seed=seed)
