"""Comparisons between a study's configurations: per problem and pooled over problems (the unit of inference).

The statistics are :mod:`planners.comparisons`' — the one implementation the
server's ``GET /api/v1/comparisons``, ``twb results`` and the dashboard use too
(docs/study.md, "Comparisons"); this module adds what a study knows: its
default metrics, a fleet's safety metrics compared over every measured run, and
the fleet metrics' directions.

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

from planners.comparisons import COLUMNS as COMPARISON_COLUMNS
from planners.comparisons import DIRECTION as _BASE_DIRECTION
from planners.comparisons import Comparison, Comparisons
from planners.comparisons import compare as _compare

from ._fleet_results import FLEET_COMPARED, FLEET_METRICS, measured
from ._records import StudyRecords

__all__ = ["COMPARISON_COLUMNS", "COMPARED_METRICS", "CONTROLLER_METRICS", "Comparison", "Comparisons", "DIRECTION",
           "compare", "compared_over"]

#: metrics compared by default (the paper's Fig. 6), after the success rate
COMPARED_METRICS = ("length_m", "execution_time_s", "average_speed_m_s", "deviation_mean_m", "smoothness_rad",
                    "clearance_min_m")
#: compared too when a study has controllers (docs/metrics.md, "Controller metrics")
CONTROLLER_METRICS = ("cross_track_error_mean_m", "heading_error_rms_rad", "time_to_goal_s", "jerk_linear_rms_m_s3")
#: +1: higher is better, -1: lower is better, 0: neither (reported, not judged)
DIRECTION = {**_BASE_DIRECTION, **{m: spec.direction for m, spec in FLEET_METRICS.items()}}


def compared_over(metric: str) -> str:
    """The runs a metric is compared over: ``completed`` (a single robot's metrics, a fleet's times and lengths)
    or ``measured`` (a fleet's safety metrics: failed runs included; :data:`FLEET_METRICS`)."""
    spec = FLEET_METRICS.get(metric)
    return spec.over if spec is not None else "completed"


def _enters(row: dict, metric: str) -> bool:
    return row.get("status") == "completed" if compared_over(metric) == "completed" else measured(row)


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
        comparison has its own stream, so results do not depend on the order).

    Returns
    -------
    Comparisons
        A list of :class:`Comparison`; differences are ``a - b``; ``problem`` None for the pooled ones.
    """
    if metrics is None and data.spec.fleet:
        metrics = FLEET_COMPARED
    elif metrics is None:
        metrics = COMPARED_METRICS + (CONTROLLER_METRICS if data.spec.controllers is not None else ())
    return _compare(data.rows, metrics, modes=modes if modes is not None else data.modes,
                    pairs=pairs if pairs is not None else list(combinations(data.configurations, 2)), enters=_enters, direction=DIRECTION, confidence=confidence, family=family,
                    test=test, n_resamples=n_resamples, seed=seed)
