"""Comparisons between configurations: every pair, per mode and metric, with intervals, tests and Holm's correction.

The statistics are :mod:`planners.stats`'s (``scipy.stats`` underneath); this
module is the glue:

- **pairing**: a pair of configurations is compared *paired* when the design
  is paired — both ran the same problems (environment, plan) and repetitions
  in that mode; the study gives both the same seed, so repetition k of each
  starts with the same start-pose jitter and drives with the same noise
  stream.  A pair of runs enters a metric's comparison when both completed.
  Otherwise (a refused job, a testbed error) the comparison is unpaired.
- **identical repetitions** (the deterministic simulation without jitter) are
  counted once per problem (:func:`~client_sdk.study._outcomes.distinct_runs`);
  with nothing left to vary there is no interval and no test, and the note
  says so.
- **success rate**: Fisher's exact test on the counted runs (completed or
  failed); the difference is the risk difference with Newcombe's interval.
- **Holm**: p-values are adjusted within a family — by default each metric's
  comparisons (all pairs, all modes); ``family="all"`` makes the whole table one
  family.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations
from typing import Any, Iterable, Optional

import numpy as np

from contract.vocabulary import Mode

from ._fleet_results import FLEET_COMPARED, FLEET_METRICS, measured
from ._outcomes import counted, distinct_runs, identical_repetitions
from ._records import StudyRecords

__all__ = ["COMPARISON_COLUMNS", "COMPARED_METRICS", "CONTROLLER_METRICS", "Comparison", "Comparisons", "DIRECTION", "compare",
           "compared_over"]

#: metrics compared by default (the paper's Fig. 6), after the success rate
COMPARED_METRICS = ("length_m", "execution_time_s", "average_speed_m_s", "deviation_mean_m", "smoothness_rad",
                    "clearance_min_m")
#: compared too when a study has controllers (docs/metrics.md, "Controller metrics")
CONTROLLER_METRICS = ("cross_track_error_mean_m", "heading_error_rms_rad", "time_to_goal_s", "jerk_linear_rms_m_s3")
#: +1: higher is better, -1: lower is better, 0: neither (reported, not judged)
DIRECTION = {"success_rate": 1, "length_m": -1, "execution_time_s": -1, "average_speed_m_s": 0,
             "deviation_mean_m": -1, "smoothness_rad": -1, "clearance_min_m": 1, "cross_track_error_mean_m": -1,
             "heading_error_rms_rad": -1, "time_to_goal_s": -1, "jerk_linear_rms_m_s3": -1,
             **{m: spec.direction for m, spec in FLEET_METRICS.items()}}
#: comparisons.csv: these columns first, in this order
COMPARISON_COLUMNS = ("metric", "mode", "a", "b", "n_a", "n_b", "mean_a", "mean_b", "diff", "ci_low", "ci_high",
                      "test", "p", "p_holm", "effect", "effect_size", "paired", "runs_a", "runs_b", "family_size",
                      "note")
IDENTICAL = "identical repetitions (deterministic simulation)"


@dataclass(frozen=True)
class Comparison:
    """Configuration ``a`` against ``b`` on one ``metric`` in one ``mode``: ``result`` (a
    :class:`planners.stats.MeanComparison` or, for ``success_rate``, a :class:`planners.stats.RateComparison`)
    and ``pvalue_holm``, the p-value adjusted for the family of ``family_size`` tests.

    ``statistic``, ``pvalue`` and ``confidence_interval()`` are the result's, after SciPy.
    ``runs_a``/``runs_b`` are the completed runs used before identical repetitions were merged.
    """

    metric: str
    mode: str
    a: str
    b: str
    result: Any
    pvalue_holm: float
    family_size: int
    runs_a: int
    runs_b: int
    note: str = ""

    @property
    def statistic(self) -> float:
        return self.result.statistic

    @property
    def pvalue(self) -> float:
        return self.result.pvalue

    @property
    def difference(self) -> float:
        """``a - b`` in the metric's unit (a rate: a fraction)."""
        return self.result.difference

    @property
    def tested(self) -> bool:
        return math.isfinite(self.result.pvalue)

    def confidence_interval(self, confidence_level: Optional[float] = None) -> Any:
        return self.result.confidence_interval(confidence_level)

    def significant(self, alpha: float = 0.05) -> bool:
        """Holm-adjusted p-value at most ``alpha``."""
        return math.isfinite(self.pvalue_holm) and self.pvalue_holm <= alpha

    def better(self) -> Optional[str]:
        """The configuration the difference favours (by :data:`DIRECTION`), or None if it has no direction."""
        sign = DIRECTION.get(self.metric, 0) * np.sign(self.difference) if math.isfinite(self.difference) else 0
        return self.a if sign > 0 else self.b if sign < 0 else None

    def row(self) -> dict[str, Any]:
        """The row of ``comparisons.csv``."""
        r, ci = self.result, self.confidence_interval()
        return {"metric": self.metric, "mode": self.mode, "a": self.a, "b": self.b, "n_a": r.n_a, "n_b": r.n_b,
                "mean_a": r.mean_a, "mean_b": r.mean_b, "diff": r.difference, "ci_low": ci.low, "ci_high": ci.high,
                "test": r.test, "p": r.pvalue, "p_holm": self.pvalue_holm, "effect": r.effect,
                "effect_size": r.effect_size, "paired": r.paired, "runs_a": self.runs_a, "runs_b": self.runs_b,
                "family_size": self.family_size, "note": self.note}


class Comparisons(list):
    """The list of :class:`Comparison` of a study, with look-ups and the rows of ``comparisons.csv``."""

    def rows(self) -> list[dict[str, Any]]:
        return [c.row() for c in self]

    def get(self, metric: str, mode: str, a: str, b: str) -> Optional[Comparison]:
        """The comparison of ``a`` and ``b`` (either order: then the signs are as stored) or None."""
        for c in self:
            if c.metric == metric and c.mode == mode and {c.a, c.b} == {a, b}:
                return c
        return None

    def significant(self, alpha: float = 0.05) -> "Comparisons":
        return Comparisons(c for c in self if c.significant(alpha))


def _holm(pvalues: list[float]) -> np.ndarray:
    from planners.stats import holm

    return holm(pvalues)


def _problem_keys(rows: list[dict[str, Any]]) -> set[tuple]:
    return {(r.get("environment"), r.get("plan"), r.get("repetition")) for r in rows}


def _mean_comparison(metric: str, mode: str, ra: list[dict[str, Any]], rb: list[dict[str, Any]], paired: bool,
                     **kw: Any) -> tuple[Any, int, int, str]:
    from planners.stats import compare_means

    over = compared_over(metric)
    done_a = [r for r in ra if _enters(r, over)]
    done_b = [r for r in rb if _enters(r, over)]
    note = ""
    if paired:
        by_key: dict[tuple, list] = {}
        for side, rows in ((0, done_a), (1, done_b)):
            for r in rows:
                by_key.setdefault((r.get("environment"), r.get("plan"), r.get("repetition")), [None, None])[side] = r
        pairs = [(x, y) for x, y in by_key.values() if x is not None and y is not None]
        # identical repetitions: both sides repeat themselves within a problem -> one pair per problem
        problems: dict[tuple, list] = {}
        for x, y in pairs:
            problems.setdefault((x.get("environment"), x.get("plan")), []).append((x, y))
        kept = []
        for group in problems.values():
            if len(group) >= 2 and identical_repetitions([x for x, _ in group]) \
                    and identical_repetitions([y for _, y in group]):
                kept.append(group[0])
                note = IDENTICAL if mode == Mode.SIM else "identical repetitions"
            else:
                kept.extend(group)
        res = compare_means([x.get(metric) for x, _ in kept], [y.get(metric) for _, y in kept], paired=True, **kw)
        runs_a = runs_b = len(pairs)
    else:
        da, ma = distinct_runs(done_a)
        db, mb = distinct_runs(done_b)
        if ma or mb:
            note = IDENTICAL if mode == Mode.SIM else "identical repetitions"
        res = compare_means([r.get(metric) for r in da], [r.get(metric) for r in db], paired=False, **kw)
        runs_a, runs_b = len(done_a), len(done_b)
    if not done_a or not done_b:
        note = f"no {over} run of " + " and ".join(
            n for n, d in ((ra[0]["configuration"] if ra else "a", done_a),
                           (rb[0]["configuration"] if rb else "b", done_b)) if not d)
    else:
        parts = []
        if note:
            parts.append(f"{note}: counted once per problem" + (
                "" if math.isfinite(res.pvalue) else ", nothing left to vary — no interval or test"))
        if res.note and (math.isfinite(res.pvalue) or not note):
            parts.append(res.note)
        note = "; ".join(parts)
    return res, runs_a, runs_b, note


def compared_over(metric: str) -> str:
    """The runs a metric is compared over: ``completed`` (a single robot's metrics, a fleet's times and lengths)
    or ``measured`` (a fleet's safety metrics: failed runs included; :data:`FLEET_METRICS`)."""
    spec = FLEET_METRICS.get(metric)
    return spec.over if spec is not None else "completed"


def _enters(row: dict[str, Any], over: str) -> bool:
    return row.get("status") == "completed" if over == "completed" else measured(row)


def _rate_comparison(mode: str, ra: list[dict[str, Any]], rb: list[dict[str, Any]], confidence: float) \
        -> tuple[Any, int, int, str]:
    from planners.stats import compare_rates

    da, ma = distinct_runs(ra)
    db, mb = distinct_runs(rb)
    res = compare_rates(sum(r["outcome"] == "success" for r in da), len(da),
                        sum(r["outcome"] == "success" for r in db), len(db), confidence=confidence)
    note = ""
    if ma or mb:
        note = (IDENTICAL if mode == Mode.SIM else "identical repetitions") + ": counted once per problem"
    if res.note:
        note = f"{note}; {res.note}" if note else res.note
    return res, sum(counted(r) for r in ra), sum(counted(r) for r in rb), note


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
    """Compare every pair of the study's configurations, per mode, on the success rate and each metric.

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
        Holm's family: each metric's comparisons, or the whole table.
    test : {"t", "rank"}
        Welch / paired t (default) or Mann-Whitney U / Wilcoxon signed-rank.
    n_resamples, seed : int
        Bootstrap resamples and the seed of the first comparison (each
        comparison has its own stream, so results do not depend on the order).

    Returns
    -------
    Comparisons
        A list of :class:`Comparison`; differences are ``a - b``.
    """
    if family not in ("metric", "all"):
        raise ValueError(f"`family` must be 'metric' or 'all', got {family!r}")
    if metrics is None and data.spec.fleet:
        metrics = FLEET_COMPARED
    elif metrics is None:
        metrics = COMPARED_METRICS + (CONTROLLER_METRICS if data.spec.controllers is not None else ())
    names = ["success_rate", *[m for m in metrics if m != "success_rate"]]
    modes = list(modes) if modes is not None else data.modes
    pairs = list(pairs) if pairs is not None else list(combinations(data.configurations, 2))
    raw: list[tuple] = []
    for metric in names:
        for mode in modes:
            for a, b in pairs:
                ra = [r for r in data.rows if r["configuration"] == a and r["mode"] == mode]
                rb = [r for r in data.rows if r["configuration"] == b and r["mode"] == mode]
                if metric == "success_rate":
                    res, na, nb, note = _rate_comparison(mode, ra, rb, confidence)
                else:
                    paired = bool(ra) and _problem_keys(ra) == _problem_keys(rb)
                    res, na, nb, note = _mean_comparison(
                        metric, mode, ra, rb, paired, confidence=confidence, test=test, n_resamples=n_resamples,
                        seed=[seed, len(raw)])
                raw.append((metric, mode, a, b, res, na, nb, note))
    groups: dict[Any, list[int]] = {}
    for i, (metric, *_rest) in enumerate(raw):
        groups.setdefault(metric if family == "metric" else None, []).append(i)
    adjusted = [math.nan] * len(raw)
    sizes = [0] * len(raw)
    for idx in groups.values():
        ps = [raw[i][4].pvalue for i in idx]
        size = sum(math.isfinite(p) for p in ps)
        for i, p in zip(idx, _holm(ps)):
            adjusted[i], sizes[i] = float(p), size
    return Comparisons(Comparison(m, mode, a, b, res, adjusted[i], sizes[i], na, nb, note)
                       for i, (m, mode, a, b, res, na, nb, note) in enumerate(raw))

