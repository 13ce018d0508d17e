"""Aggregation of run metrics across repetitions: mean, standard deviation, 95% confidence interval.

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
"""

from __future__ import annotations

import math
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
from scipy import stats as _st

__all__ = ["aggregate", "proportion", "summarize", "table_rows"]


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
