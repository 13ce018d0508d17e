"""Which configuration is better, over which problems, and how sure: the comparisons every surface shows.

One implementation for the study report (``comparisons.csv``), ``twb results``, the SDK and the
dashboard's compare page (through ``GET /api/v1/comparisons``): rows of runs in, :class:`Comparisons`
out.  Pure computation on :mod:`planners.stats` (``scipy.stats`` underneath).

**The problem is the unit of inference.**  A problem is an environment with a start/goal plan (or a
fleet).  Its repetitions estimate how a configuration's runs vary on *that* problem; they are not
independent evidence about other problems, and pooling them as independent pairs (pseudo-replication)
makes a difference that one problem drives look certain.  So every comparison of two configurations a
and b on a metric in a mode has

- **one row per problem** (``problem`` set): a's and b's means over that problem's runs, the difference
  with its studentized-bootstrap interval and its test — paired by repetition when both ran the same
  repetitions (the study gives them common random numbers: the same noise and start jitter per
  repetition), else Welch's; identical repetitions (a deterministic simulation) count once, and then
  there is nothing to test;
- **one pooled row** (``problem`` None) when at least :data:`~planners.stats.MIN_PROBLEMS` problems have
  both: the mean of the per-problem differences, its interval and test over the problems
  (:func:`planners.stats.compare_problems`), how many problems favour each side and how much the
  problems disagree (:class:`~planners.stats.Heterogeneity`).  With fewer problems there is no pooled
  row: the per-problem results are the answer, and the words say so.

The success rate works the same way: Fisher's exact test per problem, and over problems the mean of
the per-problem differences of rates.

Holm's correction runs within a family: by default each metric's pooled rows form one family and each
metric's per-problem rows another; ``family="all"`` makes one family of all pooled rows and one of all
per-problem rows.  p-values keep full precision (an adjusted p-value is never below its own).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations
from typing import Any, Callable, Hashable, Iterable, Mapping, Optional, Sequence

import numpy as np

from contract.vocabulary import NOT_COUNTED, SUCCESS, Mode, RunStatus

from .stats import (MIN_PROBLEMS, MeanComparison, ProblemComparison, RateComparison, compare_means, compare_problems,
                    compare_rates, holm, sample_size_mean, sample_size_rate)

__all__ = ["COLUMNS", "DIRECTION", "IDENTITY_METRICS", "Comparison", "Comparisons", "compare", "counted",
           "distinct_runs", "identical_repetitions", "problem_of", "problem_name"]

#: +1: higher is better, -1: lower is better (metrics not listed: reported, not judged)
DIRECTION: dict[str, int] = {
    "success_rate": 1, "length_m": -1, "execution_time_s": -1, "average_speed_m_s": 0, "deviation_mean_m": -1,
    "smoothness_rad": -1, "clearance_min_m": 1, "cross_track_error_mean_m": -1, "heading_error_rms_rad": -1,
    "time_to_goal_s": -1, "jerk_linear_rms_m_s3": -1, "planning_time_s": -1, "planned_length_m": -1,
    "hausdorff_m": -1, "frechet_m": -1, "aol_rad_per_m": -1,
}
#: metrics compared to decide that repetitions are identical (a single robot's, then a fleet's: a row has one set)
IDENTITY_METRICS = ("length_m", "execution_time_s", "deviation_mean_m", "smoothness_rad", "clearance_min_m",
                    "path_length_sum_m", "robot_distance_min_m", "safety_time_s", "makespan_s")
#: the columns of a comparison's row (``comparisons.csv``, the API), in this order
COLUMNS = ("metric", "mode", "a", "b", "n_a", "n_b", "mean_a", "mean_b", "diff", "ci_low", "ci_high", "test", "p",
           "p_holm", "effect", "effect_size", "paired", "runs_a", "runs_b", "family_size", "problem", "n_problems",
           "favour_a", "favour_b", "heterogeneity_i2", "heterogeneity_p", "n_needed", "needed_unit", "note")
IDENTICAL = "identical repetitions"

Row = Mapping[str, Any]


def problem_of(row: Row) -> tuple[Any, Any]:
    """A run's problem: its (environment, plan)."""
    return row.get("environment"), row.get("plan")


def problem_name(problem: Hashable) -> str:
    """``room A`` for ``("room", "A")``; any other problem as its string."""
    if isinstance(problem, tuple):
        return " ".join(str(p) for p in problem if p not in (None, ""))
    return str(problem)


def counted(row: Row) -> bool:
    """The run ended in the job's own outcome (success or a failure), not a testbed fault."""
    return row.get("outcome") not in NOT_COUNTED


def _same(values: list[Any]) -> bool:
    """All None, or all numbers equal up to rounding (1e-9 relative: times are differences of clock readings)."""
    if all(v is None for v in values):
        return True
    if any(not isinstance(v, (int, float)) or isinstance(v, bool) for v in values):
        return len(set(values)) == 1
    hi = max(abs(v) for v in values)
    return max(values) - min(values) <= 1e-9 * max(1.0, hi)


def identical_repetitions(rows: Sequence[Row]) -> bool:
    """At least two counted runs, all with the same outcome and the same metrics (up to rounding)."""
    mine = [r for r in rows if counted(r)]
    return (len(mine) >= 2 and len({r.get("outcome") for r in mine}) == 1
            and all(_same([r.get(k) for r in mine]) for k in IDENTITY_METRICS))


def distinct_runs(rows: Iterable[Row], problem: Callable[[Row], Hashable] = problem_of) -> tuple[list[Row], bool]:
    """The counted runs with identical repetitions of one problem kept once; and whether any were merged
    (``rows``: one configuration's runs in one mode)."""
    by_problem: dict[Hashable, list[Row]] = {}
    for r in rows:
        if counted(r):
            by_problem.setdefault(problem(r), []).append(r)
    out: list[Row] = []
    merged = False
    for group in by_problem.values():
        if identical_repetitions(group):
            out.append(group[0])
            merged = True
        else:
            out.extend(group)
    return out, merged


@dataclass(frozen=True)
class Comparison:
    """Configuration ``a`` against ``b`` on one ``metric`` in one ``mode``, on one ``problem`` or pooled over
    problems (``problem`` None).

    ``result``: a :class:`~planners.stats.MeanComparison` or :class:`~planners.stats.RateComparison` (one
    problem), a :class:`~planners.stats.ProblemComparison` (pooled).  ``statistic``, ``pvalue`` and
    ``confidence_interval()`` are the result's, after SciPy; ``pvalue_holm`` is adjusted within a family of
    ``family_size`` tests.  ``runs_a``/``runs_b``: the runs behind it before identical repetitions were
    merged.  ``direction``: +1 higher is better, -1 lower, 0 not judged.
    """

    metric: str
    mode: str
    a: str
    b: str
    problem: Optional[Hashable]
    result: Any
    pvalue_holm: float
    family_size: int
    runs_a: int
    runs_b: int
    direction: int = 0
    note: str = ""

    @property
    def pooled(self) -> bool:
        """Over problems (True) or on one problem."""
        return self.problem is None

    @property
    def statistic(self) -> float:
        return self.result.statistic

    @property
    def pvalue(self) -> float:
        return self.result.pvalue

    @property
    def difference(self) -> float:
        """``a - b`` in the metric's unit (a rate: a fraction); pooled: the mean of the problems' differences."""
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
        """The configuration the difference favours (by :attr:`direction`), or None."""
        sign = self.direction * np.sign(self.difference) if math.isfinite(self.difference) else 0
        return self.a if sign > 0 else self.b if sign < 0 else None

    def favouring(self) -> tuple[int, int, int]:
        """Pooled: how many problems favour a, favour b, neither (by :attr:`direction`; undirected metrics: by
        the sign of a - b)."""
        r = self.result
        if not isinstance(r, ProblemComparison):
            raise ValueError("only a pooled comparison counts problems")
        up, down = r.favour_a, r.favour_b
        return (down, up, r.ties) if self.direction < 0 else (up, down, r.ties)

    def needed(self, *, power: float = 0.8, alpha: float = 0.05, effect: Optional[float] = None) -> Optional[int]:
        """How many units a test at ``alpha`` needs to detect a difference of ``effect`` (the metric's unit;
        default: the observed difference) with ``power``: problems for a pooled comparison, repetitions per
        configuration on one problem (paired: pairs).  None where it cannot say (no spread, no difference).
        Method: the noncentral t (:func:`planners.stats.sample_size_mean`) at the observed spread, or for a
        success rate the two-proportion normal approximation (:func:`planners.stats.sample_size_rate`).  A
        planning figure for the next study, not a verdict: at the observed difference it says how much more
        data would settle *that* difference."""
        r = self.result
        diff = self.difference if effect is None else float(effect)
        if not math.isfinite(diff) or diff == 0:
            return None
        if isinstance(r, RateComparison):
            if not (r.n_a and r.n_b):
                return None
            rb = r.rate_b
            return sample_size_rate(min(1.0, max(0.0, rb + diff)), rb, power=power, alpha=alpha)
        if isinstance(r, ProblemComparison):
            d = np.asarray(r.differences, dtype=float)
            sd = float(d.std(ddof=1)) if d.size >= 2 else math.nan
            return sample_size_mean(diff / sd, paired=True, power=power, alpha=alpha) if sd > 0 else None
        samples = r._samples
        if not samples:
            return None
        if len(samples) == 1:
            sd = float(samples[0].std(ddof=1))
            return sample_size_mean(diff / sd, paired=True, power=power, alpha=alpha) if sd > 0 else None
        xa, xb = samples
        pooled = math.sqrt((xa.var(ddof=1) + xb.var(ddof=1)) / 2)
        return sample_size_mean(diff / pooled, paired=False, power=power, alpha=alpha) if pooled > 0 else None

    def row(self) -> dict[str, Any]:
        """The comparison as a flat row (``comparisons.csv``; the API's ``rows``), keys :data:`COLUMNS`."""
        r, ci = self.result, self.confidence_interval()
        pooled = isinstance(r, ProblemComparison)
        het = r.heterogeneity if pooled else None
        favour = self.favouring() if pooled else (None, None, None)
        return {"metric": self.metric, "mode": self.mode, "a": self.a, "b": self.b, "n_a": r.n_a, "n_b": r.n_b, "mean_a": r.mean_a, "mean_b": r.mean_b, "diff": r.difference,
                "ci_low": ci.low, "ci_high": ci.high, "test": r.test, "p": r.pvalue, "p_holm": self.pvalue_holm,
                "effect": r.effect, "effect_size": r.effect_size, "paired": r.paired, "runs_a": self.runs_a,
                "runs_b": self.runs_b, "family_size": self.family_size,
                "problem": "" if self.problem is None else problem_name(self.problem), "n_problems": r.n_problems if pooled else 1, "favour_a": favour[0], "favour_b": favour[1],
                "heterogeneity_i2": het.i2 if het else None, "heterogeneity_p": het.pvalue if het else None,
                "n_needed": self.needed(),
                "needed_unit": "problems" if pooled else ("runs" if isinstance(r, RateComparison) or not r.paired
                                                          else "pairs"),
                "note": self.note}


class Comparisons(list):
    """The :class:`Comparison` list of a study or of a set of experiments, with look-ups and rows."""

    def rows(self) -> list[dict[str, Any]]:
        return [c.row() for c in self]

    def get(self, metric: str, mode: str, a: str, b: str, problem: Optional[Hashable] = None) -> Optional[Comparison]:
        """The comparison of ``a`` and ``b`` (either order: then the signs are as stored) on ``problem``, or
        without one the answer over problems: the pooled comparison, or where the two share a single problem,
        that problem's.  None where there is none (two problems have per-problem answers only)."""
        mine = [c for c in self if c.metric == metric and c.mode == mode and {c.a, c.b} == {a, b}]
        if problem is not None:
            return next((c for c in mine if c.problem == problem), None)
        pooled = next((c for c in mine if c.pooled), None)
        if pooled is not None:
            return pooled
        return mine[0] if len(mine) == 1 else None

    def pooled(self) -> "Comparisons":
        """The comparisons over problems."""
        return Comparisons(c for c in self if c.pooled)

    def per_problem(self, problem: Optional[Hashable] = None) -> "Comparisons":
        """The comparisons on one problem each (all problems, or ``problem``'s)."""
        return Comparisons(c for c in self if not c.pooled and (problem is None or c.problem == problem))

    def of(self, metric: str, mode: str, a: str, b: str) -> "Comparisons":
        """Every problem's comparison of ``a`` and ``b`` on ``metric`` in ``mode`` (the pooled one excluded)."""
        return Comparisons(c for c in self if not c.pooled and c.metric == metric and c.mode == mode
                           and {c.a, c.b} == {a, b})

    def significant(self, alpha: float = 0.05) -> "Comparisons":
        return Comparisons(c for c in self if c.significant(alpha))


def _enters_completed(row: Row, metric: str) -> bool:
    return row.get("status") == RunStatus.COMPLETED


def _note_identical(mode: str) -> str:
    return IDENTICAL + (" (deterministic simulation)" if mode == Mode.SIM else "")


def _per_problem_mean(metric: str, mode: str, ra: list[Row], rb: list[Row], *, enters: Callable[[Row, str], bool],
                      names: tuple[str, str], **kw: Any) -> tuple[MeanComparison, int, int, str, float]:
    """One problem's comparison of a metric; with the standard error of its difference (for the
    heterogeneity: 0 where both sides repeat themselves exactly, NaN where it cannot be had)."""
    done_a = [r for r in ra if enters(r, metric)]
    done_b = [r for r in rb if enters(r, metric)]
    note = ""
    by_rep: dict[Any, list] = {}
    for side, rows in ((0, done_a), (1, done_b)):
        for r in rows:
            by_rep.setdefault(r.get("repetition"), [None, None])[side] = r
    same_reps = bool(done_a) and {r.get("repetition") for r in ra} == {r.get("repetition") for r in rb}
    ident_a = len(done_a) >= 2 and identical_repetitions(done_a)
    ident_b = len(done_b) >= 2 and identical_repetitions(done_b)
    if ident_a or ident_b:
        note = _note_identical(mode)
    if same_reps and not (ident_a and ident_b):
        pairs = [(x, y) for x, y in by_rep.values() if x is not None and y is not None]
        res = compare_means([x.get(metric) for x, _ in pairs], [y.get(metric) for _, y in pairs], paired=True, **kw)
        runs_a = runs_b = len(pairs)
    else:
        xa = [r.get(metric) for r in (done_a[:1] if ident_a else done_a)]
        xb = [r.get(metric) for r in (done_b[:1] if ident_b else done_b)]
        res = compare_means(xa, xb, paired=False, **kw)
        runs_a, runs_b = len(done_a), len(done_b)
    se = _standard_error(res, ident_a and ident_b)
    if not done_a or not done_b:
        note = "no completed run of " + " and ".join(n for n, d in zip(names, (done_a, done_b)) if not d)
    else:
        parts = []
        if note:
            parts.append(f"{note}: counted once" + ("" if math.isfinite(res.pvalue) else
                                                    ", nothing left to vary — no interval or test"))
        if res.note and (math.isfinite(res.pvalue) or not note):
            parts.append(res.note)
        note = "; ".join(parts)
    return res, runs_a, runs_b, note, se


def _standard_error(res: MeanComparison, exact: bool) -> float:
    """The standard error of a problem's difference of means: 0 where both sides are exact (identical
    repetitions), NaN where there are too few values."""
    if exact:
        return 0.0
    if res.paired:
        if res.n_a < 2:
            return math.nan
        d = res._samples[0] if res._samples else None
        return float(d.std(ddof=1) / math.sqrt(d.size)) if d is not None else math.nan
    if res._samples:
        xa, xb = res._samples
        return math.sqrt(xa.var(ddof=1) / xa.size + xb.var(ddof=1) / xb.size)
    return math.nan


def _per_problem_rate(mode: str, ra: list[Row], rb: list[Row], confidence: float) \
        -> tuple[RateComparison, int, int, str, float]:
    da, ma = distinct_runs(ra, lambda r: 0)
    db, mb = distinct_runs(rb, lambda r: 0)
    ka = sum(r.get("outcome") == SUCCESS for r in da)
    kb = sum(r.get("outcome") == SUCCESS for r in db)
    res = compare_rates(ka, len(da), kb, len(db), confidence=confidence)
    note = f"{_note_identical(mode)}: counted once" if ma or mb else ""
    if res.note:
        note = f"{note}; {res.note}" if note else res.note
    se = math.nan
    if da and db:
        if ma and mb:
            se = 0.0
        else:  # the binomial standard error, with half a success added to each side (never exactly 0)
            pa, pb = (ka + 0.5) / (len(da) + 1), (kb + 0.5) / (len(db) + 1)
            se = math.sqrt(pa * (1 - pa) / len(da) + pb * (1 - pb) / len(db))
    return res, sum(counted(r) for r in ra), sum(counted(r) for r in rb), note, se


def _pooled(results: list[tuple[Hashable, Any, int, int, str, float]], test: str, confidence: float,
            metric: str) -> tuple[ProblemComparison, int, int, str]:
    """The problems' results pooled: only problems where both sides have a value enter."""
    usable = [(p, r, na, nb, se) for p, r, na, nb, _note, se in results
              if math.isfinite(r.mean_a) and math.isfinite(r.mean_b)]
    left = len(results) - len(usable)
    res = compare_problems([r.mean_a for _, r, *_ in usable], [r.mean_b for _, r, *_ in usable],
                           problems=[problem_name(p) for p, *_ in usable], standard_errors=[u[4] for u in usable],
                           runs_a=sum(u[2] for u in usable), runs_b=sum(u[3] for u in usable), test=test,
                           confidence=confidence)
    what = "counted runs" if metric == "success_rate" else "completed runs"
    if not usable:
        return res, 0, 0, f"no problem has {what} of both"
    notes = [res.note] if res.note else []
    if left:
        notes.append(f"{left} problem(s) left out: no {what} of one side")
    return res, res.n_a, res.n_b, "; ".join(notes)


def compare(
    rows: Sequence[Row],
    metrics: Iterable[str],
    *,
    modes: Optional[Iterable[str]] = None,
    pairs: Optional[Iterable[tuple[str, str]]] = None,
    problem: Callable[[Row], Hashable] = problem_of,
    problems: Optional[Iterable[Hashable]] = None,
    enters: Callable[[Row, str], bool] = _enters_completed,
    direction: Optional[Mapping[str, int]] = None,
    confidence: float = 0.95,
    family: str = "metric",
    test: str = "t",
    n_resamples: int = 9999,
    seed: int = 0,
    min_problems: int = MIN_PROBLEMS,
) -> Comparisons:
    """Compare every pair of configurations, per mode, on the success rate and each metric: per problem, and
    pooled over problems where there are enough.

    Parameters
    ----------
    rows : sequence of mappings
        One per run: ``configuration``, ``mode``, ``repetition``, ``status``, ``outcome`` (the contract's
        :func:`~contract.vocabulary.run_outcome`), the problem's keys and the metrics.
    metrics : iterable of str
        Metrics to compare after ``success_rate`` (which always comes first).
    modes, pairs : optional
        Default: the modes in the rows' order; every pair of configurations in the rows' order (a before b).
    problem : callable
        A run's problem (default ``(environment, plan)``).
    problems : iterable, optional
        The problems' order (their rows', and so which bootstrap stream each comparison gets); problems not
        listed follow in the order first seen.  Default: the order first seen in ``rows``.
    enters : callable
        Whether a run enters a metric's comparison (default: completed runs).
    direction : mapping, optional
        Metric -> +1 (higher is better), -1 (lower), 0; default :data:`DIRECTION`.
    confidence, test, n_resamples, seed :
        Level of the intervals; ``"t"`` or ``"rank"`` tests (per problem: paired t / Welch or Wilcoxon /
        Mann-Whitney; over problems: one-sample t or Wilcoxon signed-rank); bootstrap resamples; the seed of
        the first comparison's bootstrap (each has its own stream, so results do not depend on the order).
    family : {"metric", "all"}
        Holm's families: per metric (pooled rows, and per-problem rows apart), or all metrics together.
    min_problems : int
        Problems needed for a pooled comparison (default 3).

    Returns
    -------
    Comparisons
        Per metric, mode and pair: the pooled comparison (if any) followed by one per problem; differences
        are ``a - b``.
    """
    if family not in ("metric", "all"):
        raise ValueError(f"`family` must be 'metric' or 'all', got {family!r}")
    if test not in ("t", "rank"):
        raise ValueError(f"`test` must be 't' or 'rank', got {test!r}")
    rows = list(rows)
    direction = dict(DIRECTION if direction is None else direction)
    names = ["success_rate", *[m for m in metrics if m != "success_rate"]]
    modes = list(modes) if modes is not None else list(dict.fromkeys(r["mode"] for r in rows))
    configs = list(dict.fromkeys(r["configuration"] for r in rows))
    pairs = list(pairs) if pairs is not None else list(combinations(configs, 2))
    index: dict[tuple, list[Row]] = {}
    for r in rows:
        index.setdefault((r["configuration"], r["mode"], problem(r)), []).append(r)
    problems = list(dict.fromkeys([*(problems or ()), *(problem(r) for r in rows)]))
    raw: list[tuple] = []  # (metric, mode, a, b, problem, result, runs_a, runs_b, note)
    stream = 0
    for metric in names:
        for mode in modes:
            for a, b in pairs:
                results = []
                for p in problems:
                    ra, rb = index.get((a, mode, p), []), index.get((b, mode, p), [])
                    if not ra or not rb:
                        continue
                    if metric == "success_rate":
                        res, na, nb, note, se = _per_problem_rate(mode, ra, rb, confidence)
                    else:
                        res, na, nb, note, se = _per_problem_mean(
                            metric, mode, ra, rb, enters=enters, names=(a, b), confidence=confidence, test=test,
                            n_resamples=n_resamples, seed=[seed, stream])
                        stream += 1
                    results.append((p, res, na, nb, note, se))
                if not results:
                    continue
                if len(results) >= min_problems:
                    res, na, nb, note = _pooled(results, test, confidence, metric)
                    raw.append((metric, mode, a, b, None, res, na, nb, note))
                raw += [(metric, mode, a, b, p, res, na, nb, note) for p, res, na, nb, note, _se in results]
    groups: dict[Any, list[int]] = {}
    for i, (metric, _mode, _a, _b, p, *_rest) in enumerate(raw):
        groups.setdefault((metric if family == "metric" else None, p is None), []).append(i)
    adjusted = [math.nan] * len(raw)
    sizes = [0] * len(raw)
    for idx in groups.values():
        ps = [raw[i][5].pvalue for i in idx]
        size = sum(math.isfinite(p) for p in ps)
        for i, p in zip(idx, holm(ps)):
            adjusted[i], sizes[i] = float(p), size
    return Comparisons(Comparison(m, mode, a, b, p, res, adjusted[i], sizes[i], na, nb, direction.get(m, 0), note)
                       for i, (m, mode, a, b, p, res, na, nb, note) in enumerate(raw))
