"""Statistics of run metrics: aggregation across repetitions, rates, and comparisons of two configurations.

Pure numpy/scipy, no I/O.  Records are mappings such as the dictionaries of
:func:`planners.metrics.run_metrics` plus the keys that identify a group
(by default ``planner`` and ``mode``)::

    >>> rows = [{"planner": "fmm", "mode": "sim", "length_m": v} for v in (1.0, 1.2, 1.1)]
    >>> g = aggregate(rows)[0]
    >>> g["planner"], g["mode"], g["runs"], round(g["metrics"]["length_m"]["mean"], 3)
    ('fmm', 'sim', 3, 1.1)

Conventions (see ``docs/metrics.md``):

- ``std`` is the sample standard deviation (``ddof = 1``);
- the confidence interval is Student's t: ``mean ± t_{(1+c)/2, n-1} std / sqrt(n)``;
- None, NaN and infinite values are left out, so ``n`` can differ between
  metrics of one group; booleans count as 0/1 (the mean of ``collided`` is a
  collision rate);
- with ``n = 1`` there is no spread: ``std`` and the interval are None;
- nested mappings (such as ``"planned"``) and strings are not aggregated.

Comparisons (:func:`compare_means`, :func:`compare_rates`, :func:`holm`)
return result objects after SciPy's: ``statistic``, ``pvalue`` and a
``confidence_interval()`` method; every test and the bootstrap are
``scipy.stats``'s, this module only pairs, corrects and labels.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, NamedTuple, Optional, Sequence

import numpy as np
from scipy import stats as _st

__all__ = ["MIN_BOOTSTRAP", "ConfidenceInterval", "Heterogeneity", "MeanComparison", "ProblemComparison",
           "RateComparison", "aggregate", "compare_means", "compare_problems", "compare_rates", "holm", "proportion",
           "sample_size_mean", "sample_size_rate", "summarize", "table_rows"]


def _confidence_iv(confidence: Any) -> float:
    try:
        c = float(confidence)
    except (TypeError, ValueError):
        raise ValueError(f"`confidence` must be a number in (0, 1), got {confidence!r}") from None
    if not 0 < c < 1:
        raise ValueError(f"`confidence` must be in (0, 1), got {confidence!r}")
    return c


def _number(v: Any) -> float | None:
    """``v`` as a float if it is a finite number or a bool, else None."""
    if isinstance(v, (bool, np.bool_)):
        return float(v)
    if isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(float(v)):
        return float(v)
    return None


def summarize(values: Iterable[Any], confidence: float = 0.95) -> dict[str, Any]:
    """Mean, sample standard deviation and Student-t confidence interval of ``values``.

    Parameters
    ----------
    values : iterable of numbers (None, NaN and inf are skipped; bools are 0/1)
    confidence : float
        Two-sided level of the interval, in (0, 1); default 0.95.

    Returns
    -------
    dict
        ``n``, ``mean``, ``std``, ``ci_low``, ``ci_high`` (same unit as the
        values) and ``confidence``; floats or None (n = 0: all None; n = 1:
        ``std`` and the interval None).
    """
    c = _confidence_iv(confidence)
    xs = np.array([x for x in (_number(v) for v in values) if x is not None], dtype=float)
    out: dict[str, Any] = {"n": int(xs.size), "mean": None, "std": None, "ci_low": None, "ci_high": None,
                           "confidence": c}
    if xs.size == 0:
        return out
    mean = float(xs.mean())
    out["mean"] = mean
    if xs.size >= 2:
        std = float(xs.std(ddof=1))
        half = float(_st.t.ppf(0.5 + c / 2, xs.size - 1)) * std / math.sqrt(xs.size)
        out.update(std=std, ci_low=mean - half, ci_high=mean + half)
    return out


def proportion(successes: int, n: int, confidence: float = 0.95) -> dict[str, Any]:
    """A rate ``successes / n`` with its Wilson score interval (SciPy's ``binomtest``).

    Returns ``n``, ``k`` (successes), ``rate`` and ``ci_low``, ``ci_high`` in
    [0, 1], and ``confidence``; with ``n = 0`` the rate and interval are None.
    Wilson's interval keeps its coverage for small ``n`` and rates near 0 or 1,
    where the normal approximation fails (0/5 has the interval [0, 0.43]).
    """
    c = _confidence_iv(confidence)
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"`successes` must be in 0..n and `n` >= 0, got {successes} of {n}")
    out: dict[str, Any] = {"n": int(n), "k": int(successes), "rate": None, "ci_low": None, "ci_high": None,
                           "confidence": c}
    if n == 0:
        return out
    ci = _st.binomtest(int(successes), int(n)).proportion_ci(confidence_level=c, method="wilson")
    out.update(rate=successes / n, ci_low=float(ci.low), ci_high=float(ci.high))
    return out


def aggregate(
    records: Iterable[Mapping[str, Any]],
    by: Sequence[str] = ("planner", "mode"),
    metrics: Sequence[str] | None = None,
    confidence: float = 0.95,
) -> list[dict[str, Any]]:
    """Group ``records`` by the keys ``by`` and summarise every metric of each group.

    Parameters
    ----------
    records : iterable of mappings
        One per run: the group keys and the metric values.
    by : sequence of str
        Keys identifying a group (default ``("planner", "mode")``); a record
        without one of them is grouped under None.
    metrics : sequence of str, optional
        The metrics to summarise; default: every key not in ``by`` holding a
        number or bool in some record of the group, in the order keys are
        first seen (so columns keep the records' order).
    confidence : float
        Level of the confidence interval (default 0.95).

    Returns
    -------
    list of dict
        One per group, in first-seen order: the ``by`` keys, ``runs`` (records
        in the group) and ``metrics``: ``{name: summarize(...)}``.
    """
    c = _confidence_iv(confidence)
    if isinstance(by, str):
        raise ValueError("`by` must be a sequence of key names, e.g. ('planner', 'mode'), not a string")
    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    for i, rec in enumerate(records):
        if not isinstance(rec, Mapping):
            raise ValueError(f"`records[{i}]` must be a mapping, got {type(rec).__name__}")
        groups.setdefault(tuple(rec.get(k) for k in by), []).append(rec)
    out = []
    for key, recs in groups.items():
        names = list(metrics) if metrics is not None else _numeric_keys(recs, by)
        out.append({
            **dict(zip(by, key)),
            "runs": len(recs),
            "metrics": {name: summarize((r.get(name) for r in recs), c) for name in names},
        })
    return out


def _numeric_keys(records: Sequence[Mapping[str, Any]], skip: Sequence[str]) -> list[str]:
    """Keys in first-seen order that hold a number or bool in at least one record."""
    numeric = (bool, int, float, np.bool_, np.integer, np.floating)
    seen: dict[str, bool] = {}
    for rec in records:
        for k, v in rec.items():
            if k not in skip:
                seen[k] = seen.get(k, False) or isinstance(v, numeric)
    return [k for k, ok in seen.items() if ok]


def table_rows(groups: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Long format of :func:`aggregate`'s result: one flat row per group and metric.

    Each row has the group keys, ``runs``, ``metric`` and the summary fields
    (``n``, ``mean``, ``std``, ``ci_low``, ``ci_high``, ``confidence``):
    ready for a CSV table or a plotting library.
    """
    rows = []
    for g in groups:
        keys = {k: v for k, v in g.items() if k != "metrics"}
        for name, summary in g["metrics"].items():
            rows.append({**keys, "metric": name, **summary})
    return rows


# ----------------------------------------------------------------------------- comparing two configurations

_ALTERNATIVES = ("two-sided", "less", "greater")


class ConfidenceInterval(NamedTuple):
    """A confidence interval ``[low, high]`` (NaN when undefined), as SciPy's result objects return it."""

    low: float
    high: float


def _alternative_iv(alternative: Any) -> str:
    if alternative not in _ALTERNATIVES:
        raise ValueError(f"`alternative` must be one of {', '.join(_ALTERNATIVES)}, got {alternative!r}")
    return str(alternative)


def _sample_iv(x: Any, name: str) -> np.ndarray:
    """A 1-d array of the finite numbers of ``x`` (None, NaN and inf dropped; bools are 0/1)."""
    if isinstance(x, np.ndarray) and x.ndim != 1:
        raise ValueError(f"`{name}` must be one-dimensional, got shape {x.shape}")
    vals = [_number(v) for v in x]
    return np.array([v for v in vals if v is not None], dtype=float)


def _constant(x: np.ndarray) -> bool:
    """All values equal, up to rounding (1e-12 relative): such a sample has no spread to test with."""
    return x.size > 0 and float(np.ptp(x)) <= 1e-12 * max(1.0, float(np.abs(x).max()))


def _rng(seed: Any) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


#: fewer values a side (or pairs) than this: no bootstrap interval (the studentized bootstrap needs spread in
#: nearly every resample; with 4 values there are only 35 distinct resamples)
MIN_BOOTSTRAP = 5


def _studentized(samples: tuple[np.ndarray, ...]) -> tuple[float, float, Any]:
    """The estimate (difference of means, or mean of paired differences), its standard error and the statistic
    ``t* = (estimate* - estimate) / se*`` of a resample, vectorised along ``axis``.  A resample whose values
    are all equal up to rounding (the :func:`_constant` rule) has ``se* = 0`` exactly, not the rounding noise
    of a few 1e-13 that would make ``t*`` a huge finite number (quantised metrics, such as times in control
    steps, produce many such resamples); a numerator within rounding of 0 is 0."""
    def flat(x: np.ndarray, axis: int) -> np.ndarray:
        scale = np.maximum(1.0, np.abs(x).max(axis=axis))
        return np.ptp(x, axis=axis) <= 1e-12 * scale

    def ratio(num: np.ndarray, se: np.ndarray, scale: float) -> np.ndarray:
        num = np.where(np.abs(num) <= 1e-12 * scale, 0.0, num)
        return num / se

    if len(samples) == 1:
        (d,) = samples
        est, se = float(d.mean()), float(d.std(ddof=1) / math.sqrt(d.size))
        scale_d = max(1.0, float(np.abs(d).max()))

        def t_one(x: np.ndarray, axis: int = -1) -> np.ndarray:
            s = np.where(flat(x, axis), 0.0, x.std(axis=axis, ddof=1) / math.sqrt(x.shape[axis]))
            return ratio(x.mean(axis) - est, s, scale_d)
        return est, se, t_one
    a, b = samples
    est = float(a.mean() - b.mean())
    se = math.sqrt(a.var(ddof=1) / a.size + b.var(ddof=1) / b.size)
    scale_ab = max(1.0, float(np.abs(a).max()), float(np.abs(b).max()))

    def t_two(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
        vx = np.where(flat(x, axis), 0.0, x.var(axis=axis, ddof=1))
        vy = np.where(flat(y, axis), 0.0, y.var(axis=axis, ddof=1))
        return ratio(x.mean(axis) - y.mean(axis) - est, np.sqrt(vx / x.shape[axis] + vy / y.shape[axis]), scale_ab)
    return est, se, t_two


#: the note of an interval that is Student's t instead of the bootstrap's (see :func:`_bootstrap_ci`)
COARSE = ("the values are too coarse (quantised: many resamples without spread) for a bootstrap interval: "
          "Student's t interval")


def _t_fallback(samples: tuple[np.ndarray, ...], confidence: float, alternative: str) -> ConfidenceInterval:
    """Student's (paired) or Welch's t interval of the same difference."""
    if len(samples) == 1:
        r = _st.ttest_1samp(samples[0], 0.0, alternative=alternative)
    else:
        r = _st.ttest_ind(samples[0], samples[1], equal_var=False, alternative=alternative)
    ci = r.confidence_interval(confidence_level=confidence)
    return ConfidenceInterval(float(ci.low), float(ci.high))


def _bootstrap_ci(samples: tuple[np.ndarray, ...], confidence: float, alternative: str, n_resamples: int,
                  seed: Any) -> tuple[ConfidenceInterval, bool]:
    """Studentized ("bootstrap-t") interval of mean(a) - mean(b), or of mean(d) for paired differences ``d``;
    and whether it fell back to Student's t.

    ``scipy.stats.bootstrap`` resamples (each sample on its own; the paired
    differences as one sample) and returns the distribution of ``t*``; the
    interval is ``estimate - q * se`` at the quantiles ``q`` of ``t*``
    (Efron & Tibshirani 1993, ch. 12.5).  A resample without spread (``se* =
    0``) counts as an infinite ``t*`` of its sign (0 when its mean is the
    estimate), so tiny samples get wide intervals, not narrow ones.  Where so
    many resamples have no spread that a quantile the interval reads is
    infinite (quantised values: a third of the resamples of ``[0.1, 0.05,
    0.05, 0.05, 0.05]`` are all 0.05), the bootstrap has nothing to say about
    that side; the interval is then Student's t (paired) or Welch's, the
    interval of the test reported beside it.
    """
    import inspect

    est, se, statistic = _studentized(samples)
    kw = {"rng" if "rng" in inspect.signature(_st.bootstrap).parameters else "random_state": _rng(seed)}
    with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy's own percentile interval of t* is not used (infinite t*)
        res = _st.bootstrap(samples, statistic, vectorized=True, paired=False, n_resamples=n_resamples,
                            method="percentile", **kw)
    t = np.asarray(res.bootstrap_distribution, dtype=float)
    t = np.where(np.isnan(t), 0.0, t)  # 0/0: a resample without spread whose mean is the estimate

    def q(level: float) -> float:  # an order statistic: no interpolation between infinite values
        return float(np.quantile(t, level, method="inverted_cdf"))

    levels = {"two-sided": ((1 + confidence) / 2, (1 - confidence) / 2), "greater": (confidence,),
              "less": (1 - confidence,)}[alternative]
    if not all(math.isfinite(q(level)) for level in levels):
        return _t_fallback(samples, confidence, alternative), True
    if alternative == "two-sided":
        return ConfidenceInterval(est - q((1 + confidence) / 2) * se, est - q((1 - confidence) / 2) * se), False
    if alternative == "greater":  # a lower bound for the difference
        return ConfidenceInterval(est - q(confidence) * se, math.inf), False
    return ConfidenceInterval(-math.inf, est - q(1 - confidence) * se), False


@dataclass(frozen=True)
class MeanComparison:
    """The difference of means ``mean_a - mean_b`` of two samples, its test and effect size.

    ``statistic`` and ``pvalue`` come from the test named in ``test``
    (``"welch-t"``, ``"paired-t"``, ``"mann-whitney-u"``, ``"wilcoxon"``; empty
    when no test is defined, then both are NaN and ``note`` says why).
    ``difference`` is in the metric's unit; ``effect_size`` is Hedges' g
    (unpaired) or Cohen's d_z (paired: mean difference / std of the
    differences), unit-free.  With ``paired``, ``n_a == n_b`` is the number of
    pairs.
    """

    statistic: float
    pvalue: float
    test: str
    paired: bool
    n_a: int
    n_b: int
    mean_a: float
    mean_b: float
    difference: float
    effect: str
    effect_size: float
    confidence_level: float
    alternative: str = "two-sided"
    note: str = ""
    _ci: ConfidenceInterval = field(default=ConfidenceInterval(math.nan, math.nan), repr=False, compare=False)
    _samples: tuple = field(default=(), repr=False, compare=False)
    _seed: Any = field(default=None, repr=False, compare=False)
    _n_resamples: int = field(default=9999, repr=False, compare=False)

    def confidence_interval(self, confidence_level: Optional[float] = None) -> ConfidenceInterval:
        """Studentized bootstrap interval of the difference (resampled by ``scipy.stats.bootstrap``: the pairs'
        differences when ``paired``, else each sample on its own); NaN where the comparison has too few values
        or no spread (see ``note``).  Another ``confidence_level`` resamples again with the same seed."""
        if confidence_level is None or confidence_level == self.confidence_level or not self._samples:
            return self._ci
        c = _confidence_iv(confidence_level)
        return _bootstrap_ci(self._samples, c, self.alternative, self._n_resamples, self._seed)[0]


def compare_means(
    a: Iterable[Any],
    b: Iterable[Any],
    *,
    paired: bool = False,
    test: str = "t",
    alternative: str = "two-sided",
    confidence: float = 0.95,
    n_resamples: int = 9999,
    seed: Any = 0,
) -> MeanComparison:
    """Compare the means of two samples: difference, studentized bootstrap interval, test, effect size.

    Parameters
    ----------
    a, b : iterables of numbers (same unit)
        The metric's values of configurations a and b (None, NaN, inf are
        dropped).  With ``paired`` they are aligned: ``a[i]`` and ``b[i]`` ran
        the same problem and repetition, and a pair with a missing value is
        dropped whole.
    paired : bool
        Pairs are resampled together and the test is the paired one.
    test : {"t", "rank"}
        ``"t"`` (default): Welch's t (``ttest_ind(equal_var=False)``) or the
        paired t (``ttest_rel``), which test the same quantity the interval
        estimates, the difference of means.  ``"rank"``: Mann-Whitney U or the
        Wilcoxon signed-rank test, for heavy-tailed metrics; they test a shift
        in distribution, not the means.
    alternative : {"two-sided", "less", "greater"}
        The alternative hypothesis about ``mean_a - mean_b`` (for both the
        test and the interval).
    confidence : float
        Level of the interval, in (0, 1).
    n_resamples : int
        Bootstrap resamples (default 9999, as SciPy).
    seed : int or numpy Generator
        Seed of the bootstrap, so the interval is reproducible.

    Returns
    -------
    MeanComparison
        With no spread to test with (both samples constant, or every pair
        differing by the same amount, or fewer than two values a side) the
        difference is still given, but ``pvalue``, ``statistic`` and the interval
        are NaN and ``note`` says why: a zero-width interval would claim a
        certainty the data do not have.  With 2 to 4 values a side (pairs) the
        test is given but no interval (:data:`MIN_BOOTSTRAP`).

    Notes
    -----
    The interval is the studentized bootstrap ("bootstrap-t"), not BCa or
    the percentile interval: with the 4-10 repetitions of a testbed study
    those cover a 95% target only 82-89% of the time (normal and skewed
    data, see tests/test_stats.py), the studentized one 93-97%.

    References
    ----------
    Welch (1947); Efron & Tibshirani, *An Introduction to the Bootstrap* (1993),
    ch. 12.5 (bootstrap-t); Hedges & Olkin (1985) for g.
    """
    c = _confidence_iv(confidence)
    alt = _alternative_iv(alternative)
    if test not in ("t", "rank"):
        raise ValueError(f"`test` must be 't' or 'rank', got {test!r}")
    if not isinstance(n_resamples, int) or n_resamples < 100:
        raise ValueError(f"`n_resamples` must be an integer >= 100, got {n_resamples!r}")
    if paired:
        pa, pb = list(a), list(b)
        if len(pa) != len(pb):
            raise ValueError(f"paired samples must have the same length, got {len(pa)} and {len(pb)}")
        keep = [(x, y) for x, y in ((_number(x), _number(y)) for x, y in zip(pa, pb)) if x is not None and y is not None]
        xa = np.array([x for x, _ in keep], dtype=float)
        xb = np.array([y for _, y in keep], dtype=float)
    else:
        xa, xb = _sample_iv(a, "a"), _sample_iv(b, "b")
    nan = math.nan
    base = dict(paired=bool(paired), n_a=int(xa.size), n_b=int(xb.size), confidence_level=c, alternative=alt,
                mean_a=float(xa.mean()) if xa.size else nan, mean_b=float(xb.mean()) if xb.size else nan,
                effect="cohen-dz" if paired else "hedges-g")
    base["difference"] = base["mean_a"] - base["mean_b"]
    undefined = dict(statistic=nan, pvalue=nan, test="", effect_size=nan)
    with warnings.catch_warnings():
        # SciPy warns of precision loss when one sample is (nearly) constant; Welch's t is still right then
        warnings.simplefilter("ignore", RuntimeWarning)
        return _compare_means(xa, xb, base, undefined, paired, test, alt, c, n_resamples, seed)


def _compare_means(xa: np.ndarray, xb: np.ndarray, base: dict[str, Any], undefined: dict[str, Any], paired: bool,
                   test: str, alt: str, c: float, n_resamples: int, seed: Any) -> MeanComparison:
    nan = math.nan
    if paired:
        d = xa - xb
        if d.size < 2:
            return MeanComparison(**base, **undefined, note=f"{d.size} pair(s): too few for an interval or a test")
        if _constant(d):
            return MeanComparison(**base, **undefined,
                                  note="every pair differs by the same amount: no spread, so no interval or test")
        if test == "t":
            r = _st.ttest_rel(xa, xb, alternative=alt)
            name = "paired-t"
        else:
            r = _st.wilcoxon(d, alternative=alt)
            name = "wilcoxon"
        samples: tuple = (d,)
        effect = float(d.mean() / d.std(ddof=1))
        few = d.size < MIN_BOOTSTRAP
    else:
        if xa.size < 2 or xb.size < 2:
            return MeanComparison(**base, **undefined,
                                  note=f"n = {xa.size} and {xb.size}: at least two values a side are needed")
        if _constant(xa) and _constant(xb):
            return MeanComparison(**base, **undefined,
                                  note="both samples are constant: no spread, so no interval or test")
        if test == "t":
            r = _st.ttest_ind(xa, xb, equal_var=False, alternative=alt)
            name = "welch-t"
        else:
            r = _st.mannwhitneyu(xa, xb, alternative=alt)
            name = "mann-whitney-u"
        samples = (xa, xb)
        na, nb = xa.size, xb.size
        pooled = math.sqrt(((na - 1) * xa.var(ddof=1) + (nb - 1) * xb.var(ddof=1)) / (na + nb - 2))
        j = 1 - 3 / (4 * (na + nb) - 9)  # Hedges' small-sample correction
        effect = j * base["difference"] / pooled if pooled > 0 else nan
        few = min(na, nb) < MIN_BOOTSTRAP
    tested = dict(statistic=float(r.statistic), pvalue=float(r.pvalue), test=name, effect_size=effect)
    if few:
        return MeanComparison(**base, **tested, note=f"fewer than {MIN_BOOTSTRAP} values a side: too few to "
                                                     "bootstrap an interval")
    ci, coarse = _bootstrap_ci(samples, c, alt, n_resamples, seed)
    return MeanComparison(**base, **tested, note=COARSE if coarse else "", _ci=ci, _samples=samples, _seed=seed,
                          _n_resamples=n_resamples)


@dataclass(frozen=True)
class RateComparison:
    """Two success rates ``k_a / n_a`` and ``k_b / n_b``: Fisher's exact test and the risk difference.

    ``statistic`` is the sample odds ratio and ``pvalue`` Fisher's exact
    p-value (``scipy.stats.fisher_exact``); ``difference`` (= ``effect_size``,
    the risk difference) is ``rate_a - rate_b`` in [-1, 1].
    """

    statistic: float
    pvalue: float
    test: str
    k_a: int
    n_a: int
    k_b: int
    n_b: int
    rate_a: float
    rate_b: float
    difference: float
    effect: str
    effect_size: float
    confidence_level: float
    alternative: str = "two-sided"
    note: str = ""
    paired: bool = False

    @property
    def mean_a(self) -> float:
        """The rate of a (so a rate row reads like a mean row)."""
        return self.rate_a

    @property
    def mean_b(self) -> float:
        return self.rate_b

    def confidence_interval(self, confidence_level: Optional[float] = None) -> ConfidenceInterval:
        """Newcombe's hybrid score interval of the risk difference, from the two Wilson intervals
        (:func:`proportion`); NaN when a side has no runs."""
        c = self.confidence_level if confidence_level is None else _confidence_iv(confidence_level)
        if self.n_a == 0 or self.n_b == 0:
            return ConfidenceInterval(math.nan, math.nan)
        pa, pb = proportion(self.k_a, self.n_a, c), proportion(self.k_b, self.n_b, c)
        d = pa["rate"] - pb["rate"]
        low = d - math.sqrt((pa["rate"] - pa["ci_low"]) ** 2 + (pb["ci_high"] - pb["rate"]) ** 2)
        high = d + math.sqrt((pa["ci_high"] - pa["rate"]) ** 2 + (pb["rate"] - pb["ci_low"]) ** 2)
        return ConfidenceInterval(max(-1.0, low), min(1.0, high))


def compare_rates(k_a: int, n_a: int, k_b: int, n_b: int, *, alternative: str = "two-sided",
                  confidence: float = 0.95) -> RateComparison:
    """Compare two success rates with Fisher's exact test (``scipy.stats.fisher_exact``).

    Parameters
    ----------
    k_a, n_a, k_b, n_b : int
        Successes and runs of a and of b.
    alternative : {"two-sided", "less", "greater"}
        About ``rate_a - rate_b``.
    confidence : float
        Level of :meth:`RateComparison.confidence_interval` (Newcombe's hybrid
        score interval of the difference, which keeps its coverage at 0/n and n/n).

    Example: 0 of 5 against 5 of 5 has the two-sided p = 2 / 252 = 0.0079.

    References
    ----------
    Fisher (1935); Newcombe, *Statistics in Medicine* 17 (1998), method 10.
    """
    c = _confidence_iv(confidence)
    alt = _alternative_iv(alternative)
    for name, k, n in (("a", k_a, n_a), ("b", k_b, n_b)):
        if not (isinstance(k, (int, np.integer)) and isinstance(n, (int, np.integer)) and 0 <= k <= n):
            raise ValueError(f"`k_{name}` must be in 0..n_{name} (integers), got {k!r} of {n!r}")
    nan = math.nan
    ra = k_a / n_a if n_a else nan
    rb = k_b / n_b if n_b else nan
    base = dict(test="", k_a=int(k_a), n_a=int(n_a), k_b=int(k_b), n_b=int(n_b), rate_a=ra, rate_b=rb,
                difference=ra - rb, effect="risk-difference", effect_size=ra - rb, confidence_level=c,
                alternative=alt)
    if n_a == 0 or n_b == 0:
        return RateComparison(statistic=nan, pvalue=nan, **base, note="a side without runs: no rate to compare")
    r = _st.fisher_exact([[k_a, n_a - k_a], [k_b, n_b - k_b]], alternative=alt)
    base["test"] = "fisher-exact"
    return RateComparison(statistic=float(r.statistic), pvalue=float(r.pvalue), **base)


def holm(pvalues: Iterable[Any]) -> np.ndarray:
    """Holm's step-down adjusted p-values of a family of tests (NaN entries are not part of the family).

    Sort the ``m`` p-values ascending, multiply the i-th smallest (i = 0 ...)
    by ``m - i``, make the sequence non-decreasing (running maximum) and clip
    at 1.  Rejecting every hypothesis whose adjusted p-value is at most alpha
    is exactly Holm's procedure at family-wise error rate alpha: it controls
    the chance of *any* false "significant" in the family, without assuming
    independence, and is uniformly more powerful than Bonferroni.
    (``scipy.stats.false_discovery_control`` is Benjamini-Hochberg, which
    controls a different quantity, the false discovery rate.)

    >>> [round(float(v), 12) for v in holm([0.01, 0.04, 0.03, 0.005])]
    [0.03, 0.06, 0.06, 0.02]

    Reference: Holm, *Scand. J. Statist.* 6 (1979) 65-70.
    """
    p = np.array([math.nan if v is None else float(v) for v in pvalues], dtype=float)
    if np.any((p < 0) | (p > 1)):
        raise ValueError("`pvalues` must be in [0, 1] (or NaN/None for no test)")
    out = np.full(p.shape, math.nan)
    idx = np.flatnonzero(np.isfinite(p))
    m = idx.size
    if m:
        order = idx[np.argsort(p[idx], kind="stable")]
        adjusted = np.maximum.accumulate((m - np.arange(m)) * p[order])
        out[order] = np.minimum(adjusted, 1.0)
    # full precision, never below the unadjusted value (a product of floats can round just under it)
    return np.where(np.isfinite(out), np.maximum(out, p), out)


# ----------------------------------------------------------------------------- over problems: the unit of inference


class Heterogeneity(NamedTuple):
    """How much the per-problem differences disagree beyond their own uncertainty (a configuration x problem
    interaction): Cochran's ``q`` on ``df`` degrees of freedom with its ``pvalue`` (chi-squared), and
    ``i2`` = max(0, (q - df) / q), the share of the spread between problems that is real rather than noise
    (Higgins & Thompson 2002).  Where the repetitions of every problem agree exactly (a deterministic
    simulation), the per-problem differences have no noise: ``i2`` is 1 when they differ and 0 when they do
    not, and ``q``/``pvalue`` are NaN.  NaN throughout when some problems have a standard error and others
    none."""

    q: float
    df: int
    pvalue: float
    i2: float


def heterogeneity(differences: Sequence[float], standard_errors: Sequence[float]) -> Heterogeneity:
    """Cochran's Q and I² of per-problem ``differences`` with their ``standard_errors`` (same unit)."""
    d = np.asarray(differences, dtype=float)
    se = np.asarray(standard_errors, dtype=float)
    k = int(d.size)
    nan = math.nan
    if k < 2:
        return Heterogeneity(nan, max(k - 1, 0), nan, nan)
    if np.all(se == 0):
        return Heterogeneity(nan, k - 1, nan, 0.0 if _constant(d) else 1.0)
    if not np.all(np.isfinite(se) & (se > 0)):
        return Heterogeneity(nan, k - 1, nan, nan)
    w = 1.0 / se ** 2
    mean = float((w * d).sum() / w.sum())
    q = float((w * (d - mean) ** 2).sum())
    i2 = max(0.0, (q - (k - 1)) / q) if q > 0 else 0.0
    return Heterogeneity(q, k - 1, float(_st.chi2.sf(q, k - 1)), i2)


@dataclass(frozen=True)
class ProblemComparison:
    """Configuration a against b pooled over problems, the problem being the unit of inference.

    Each problem (environment, start/goal plan) contributes one difference ``a - b`` of its own means (over
    its runs: its repetitions estimate the within-problem noise, they are not independent evidence about
    other problems).  ``difference`` is the mean of the ``differences`` (every problem weighs the same),
    ``mean_a``/``mean_b`` the means of the per-problem means.  The test is over the problems: a one-sample
    t on the differences (``problem-t``; with its Student-t interval on ``n_problems - 1`` degrees of
    freedom — for a balanced design the same inference as a mixed model with a random problem effect) or
    the Wilcoxon signed-rank test (``problem-wilcoxon``, with the same t interval); where every problem
    differs by the same amount (a success rate of 100 % against 0 % on each) there is no spread for either,
    and the test is the exact sign test over the problems (``problem-sign``, no interval).  ``effect_size`` is the
    mean difference over their standard deviation (a problem-level d_z).  ``favour_a``/``favour_b`` count
    the problems whose difference is positive/negative (``ties`` none); ``heterogeneity``: see
    :class:`Heterogeneity`.  ``n_a``/``n_b`` are the runs behind the problems' means.
    """

    statistic: float
    pvalue: float
    test: str
    n_problems: int
    n_a: int
    n_b: int
    mean_a: float
    mean_b: float
    difference: float
    effect_size: float
    confidence_level: float
    problems: tuple
    differences: tuple
    favour_a: int
    favour_b: int
    ties: int
    heterogeneity: Heterogeneity
    alternative: str = "two-sided"
    note: str = ""
    effect: str = "problem-dz"
    paired: bool = True
    _ci: ConfidenceInterval = field(default=ConfidenceInterval(math.nan, math.nan), repr=False, compare=False)

    def confidence_interval(self, confidence_level: Optional[float] = None) -> ConfidenceInterval:
        """Student-t interval of the mean per-problem difference over the ``n_problems`` problems."""
        c = self.confidence_level if confidence_level is None else _confidence_iv(confidence_level)
        if c == self.confidence_level:
            return self._ci
        return _t_interval(np.asarray(self.differences, dtype=float), c, self.alternative)


def _t_interval(d: np.ndarray, c: float, alternative: str) -> ConfidenceInterval:
    if d.size < 2 or _constant(d):
        return ConfidenceInterval(math.nan, math.nan)
    ci = _st.ttest_1samp(d, 0.0, alternative=alternative).confidence_interval(confidence_level=c)
    return ConfidenceInterval(float(ci.low), float(ci.high))


_SIGN_ALTERNATIVE = {"two-sided": "two-sided", "greater": "greater", "less": "less"}

#: fewer problems than this: no pooled verdict, per-problem results only (a test over two problems has one
#: degree of freedom and no check of its assumptions; its interval spans most of the line)
MIN_PROBLEMS = 3


def compare_problems(
    mean_a: Sequence[float],
    mean_b: Sequence[float],
    *,
    problems: Sequence[Any],
    standard_errors: Optional[Sequence[float]] = None,
    runs_a: int = 0,
    runs_b: int = 0,
    test: str = "t",
    alternative: str = "two-sided",
    confidence: float = 0.95,
    min_problems: int = MIN_PROBLEMS,
) -> ProblemComparison:
    """Pool a comparison over problems: one difference per problem, the test and interval over problems.

    Parameters
    ----------
    mean_a, mean_b : sequences of float
        Per problem, a's and b's mean of the metric (same unit; a rate as a fraction).
    problems : sequence
        The problems' names, in the same order.
    standard_errors : sequence of float, optional
        Per problem, the standard error of ``mean_a - mean_b`` from its repetitions (0 where they agree
        exactly, NaN where there are too few): the heterogeneity needs them.
    runs_a, runs_b : int
        How many runs are behind the means (reported, not used).
    test : {"t", "rank"}
        One-sample t over the problems' differences, or the Wilcoxon signed-rank test.
    min_problems : int
        Below this many problems no test and no interval (the ``note`` says so); default 3.

    Returns
    -------
    ProblemComparison

    References
    ----------
    The "summary statistics" approach to clustered data (e.g. Holmes & Friston 1998): inference at the
    level of the unit that was sampled; Cochran (1954), Higgins & Thompson (2002) for Q and I².
    """
    c = _confidence_iv(confidence)
    alt = _alternative_iv(alternative)
    if test not in ("t", "rank"):
        raise ValueError(f"`test` must be 't' or 'rank', got {test!r}")
    a = np.asarray(mean_a, dtype=float)
    b = np.asarray(mean_b, dtype=float)
    if a.shape != b.shape or a.ndim != 1 or len(problems) != a.size:
        raise ValueError("`mean_a`, `mean_b` and `problems` must be one value per problem")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("per-problem means must be finite (leave out a problem without a value)")
    d = a - b
    se = np.full(d.size, math.nan) if standard_errors is None else np.asarray(standard_errors, dtype=float)
    nan = math.nan
    k = int(d.size)
    base = dict(n_problems=k, n_a=int(runs_a), n_b=int(runs_b), mean_a=float(a.mean()) if k else nan,
                mean_b=float(b.mean()) if k else nan, difference=float(d.mean()) if k else nan,
                confidence_level=c, alternative=alt, problems=tuple(problems), differences=tuple(float(x) for x in d),
                favour_a=int((d > 0).sum()), favour_b=int((d < 0).sum()), ties=int((d == 0).sum()),
                heterogeneity=heterogeneity(d, se))
    undefined = dict(statistic=nan, pvalue=nan, test="", effect_size=nan)
    if k < min_problems:
        return ProblemComparison(**base, **undefined, note=f"{k} problem(s): at least {min_problems} are needed for "
                                                           "a verdict over problems; see each problem's result")
    if _constant(d):
        if d[0] == 0:
            return ProblemComparison(**base, **undefined,
                                     note="no difference on any problem: nothing to test")
        # the same difference on every problem (e.g. 100 % against 0 % everywhere): no spread for a t interval,
        # but k problems all on one side are evidence over problems — the exact sign test says how much
        r = _st.binomtest(int((d > 0).sum()), k, 0.5, alternative=_SIGN_ALTERNATIVE[alt])
        return ProblemComparison(**base, statistic=float((d > 0).sum()), pvalue=float(r.pvalue), test="problem-sign",
                                 effect_size=nan,
                                 note="every problem differs by the same amount: no spread for an interval; the exact "
                                      "sign test over problems")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        if test == "t":
            r = _st.ttest_1samp(d, 0.0, alternative=alt)
            name = "problem-t"
        else:
            r = _st.wilcoxon(d, alternative=alt)
            name = "problem-wilcoxon"
    effect = float(d.mean() / d.std(ddof=1))
    return ProblemComparison(**base, statistic=float(r.statistic), pvalue=float(r.pvalue), test=name,
                             effect_size=effect, _ci=_t_interval(d, c, alt))


def sample_size_mean(effect_size: float, *, paired: bool = True, power: float = 0.8, alpha: float = 0.05,
                     alternative: str = "two-sided", limit: int = 100_000) -> Optional[int]:
    """Units needed to detect a standardised difference ``effect_size`` with a t-test.

    ``paired``: a one-sample t on the differences (problems, or pairs of repetitions), ``effect_size`` =
    mean / sd of the differences; else Welch's t with two equal groups of the returned size each,
    ``effect_size`` = difference / pooled sd.  The power is exact (noncentral t: ``scipy.stats.nct``).
    None when ``effect_size`` is 0 or not finite, or more than ``limit`` would be needed.

    Reference: Cohen, *Statistical Power Analysis for the Behavioral Sciences* (1988), ch. 2.
    """
    _alternative_iv(alternative)
    if not (0 < power < 1) or not (0 < alpha < 1):
        raise ValueError("`power` and `alpha` must be in (0, 1)")
    if not (isinstance(effect_size, (int, float)) and math.isfinite(effect_size)) or effect_size == 0:
        return None
    es = abs(float(effect_size))
    tails = 2 if alternative == "two-sided" else 1

    def achieved(n: int) -> float:
        df = n - 1 if paired else 2 * n - 2
        nc = es * math.sqrt(n if paired else n / 2)
        crit = float(_st.t.ppf(1 - alpha / tails, df))
        return float(_st.nct.sf(crit, df, nc) + (_st.nct.cdf(-crit, df, nc) if tails == 2 else 0.0))

    lo, hi = 2, 2
    while achieved(hi) < power:
        lo, hi = hi, hi * 2
        if hi > limit:
            return None
    while lo < hi:  # the smallest n reaching the power
        mid = (lo + hi) // 2
        lo, hi = (mid + 1, hi) if achieved(mid) < power else (lo, mid)
    return hi


def sample_size_rate(rate_a: float, rate_b: float, *, power: float = 0.8, alpha: float = 0.05,
                     limit: int = 100_000) -> Optional[int]:
    """Runs per configuration needed to tell success rates ``rate_a`` and ``rate_b`` apart (two-sided, normal
    approximation to the two-proportion test; Fleiss, *Statistical Methods for Rates and Proportions*, 1981);
    None when the rates are equal or more than ``limit`` would be needed."""
    if not (0 < power < 1) or not (0 < alpha < 1):
        raise ValueError("`power` and `alpha` must be in (0, 1)")
    p1, p2 = float(rate_a), float(rate_b)
    if not (0 <= p1 <= 1 and 0 <= p2 <= 1) or p1 == p2:
        return None
    za, zb = float(_st.norm.ppf(1 - alpha / 2)), float(_st.norm.ppf(power))
    pbar = (p1 + p2) / 2
    n = (za * math.sqrt(2 * pbar * (1 - pbar)) + zb * math.sqrt(p1 * (1 - p1) + p2 * (1 - p2))) ** 2 / (p1 - p2) ** 2
    n = max(2, math.ceil(n))
    return n if n <= limit else None
