"""How the runs of each configuration x mode ended: outcome counts and the success rate with its Wilson interval.

Outcomes of a run (``runs.csv``'s ``outcome``): ``success`` (completed), why a
failed run failed (``collision``, ``timeout``, ``controller_timeout``,
``stalled``, ``planning``, ``program``, ``other``), or the testbed's
``error``, ``cancelled``, ``interrupted``.  The success rate counts the runs
that ended in the job's own outcomes (success or a failure); a testbed error is
not the planner's and is left out, as the server does.

Identical repetitions: the ideal simulation is deterministic, so without
start-pose jitter every repetition of a problem is the same run again.  A group
(configuration, mode, problem) whose counted runs all ended the same way with
bit-identical metrics counts **once** in the rate's interval and in the
comparisons: five copies of one observation are one observation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Iterable, Optional

from contract.vocabulary import NOT_COUNTED
from planners.comparisons import IDENTITY_METRICS, counted, distinct_runs, identical_repetitions

from ._records import StudyRecords

__all__ = ["COUNTED", "IDENTITY_METRICS", "NOT_COUNTED", "OutcomeSummary", "counted", "distinct_runs",
           "identical_repetitions", "outcome_table"]

#: the outcome columns of the tables: success, the two common failures, everything else
COUNTED = ("success", "collision", "timeout", "other")


def _proportion(k: int, n: int) -> dict[str, Any]:
    from planners.stats import proportion

    return proportion(k, n)


@dataclass(frozen=True)
class OutcomeSummary:
    """How the runs of one configuration in one mode ended.

    ``counts``: runs per outcome (every outcome that occurred); ``runs``: runs
    the testbed created; ``not_submitted``: runs of jobs it refused;
    ``success``: :func:`planners.stats.proportion` of successes over the
    counted runs (``n``, ``k``, ``rate``, ``ci_low``, ``ci_high``: a Wilson 95%
    interval) — over the *distinct* runs when repetitions were identical
    (``identical``), so the interval is not narrowed by copies.
    """

    #: the outcomes with a column of their own; every other failure is ``other``
    NAMED: ClassVar[tuple[str, ...]] = ("success", "collision", "timeout")

    configuration: str
    mode: str
    runs: int
    not_submitted: int
    counts: dict[str, int]
    success: dict[str, Any]
    identical: bool = False

    @classmethod
    def ordered(cls, counts: dict[str, int]) -> dict[str, int]:
        """``counts`` in the order of the tables: the :attr:`NAMED` outcomes, other failures, then the runs not
        counted."""
        def rank(item: tuple[str, int]) -> tuple[int, str]:
            o = item[0]
            return (cls.NAMED.index(o) if o in cls.NAMED else len(cls.NAMED) + (o in NOT_COUNTED)), o

        return dict(sorted(counts.items(), key=rank))

    @property
    def counted(self) -> int:
        """Runs that ended in the job's own outcome (success or a failure)."""
        return sum(n for o, n in self.counts.items() if o not in NOT_COUNTED)

    @property
    def successes(self) -> int:
        return self.counts.get("success", 0)

    def count(self, column: str) -> int:
        """Runs in one of the :attr:`NAMED` columns or ``other`` (every failure not named: for a single robot's
        runs every failure but collision and timeout)."""
        if column == "other":
            return sum(n for o, n in self.counts.items() if o not in NOT_COUNTED + self.NAMED)
        return self.counts.get(column, 0)

    @property
    def other_detail(self) -> str:
        """The failures in the ``other`` column by name, e.g. ``stalled 1, planning 1``."""
        return ", ".join(f"{o} {n}" for o, n in sorted(self.counts.items()) if o not in NOT_COUNTED + self.NAMED)

    @property
    def not_counted(self) -> int:
        """Runs not counted in the rate: testbed errors, cancelled, interrupted, and jobs refused."""
        return sum(n for o, n in self.counts.items() if o in NOT_COUNTED) + self.not_submitted

    def rate_text(self, percent: bool = True) -> str:
        """``5/5 (95% CI 57–100 %)``, or ``no counted run``."""
        s = self.success
        if not self.counted:
            return "no counted run"
        k, n = self.successes, self.counted
        if s.get("rate") is None:
            return f"{k}/{n}"
        ci = f"{100 * s['ci_low']:.0f}–{100 * s['ci_high']:.0f} %"
        extra = f"; identical repetitions counted once: {s['k']}/{s['n']}" if self.identical else ""
        return f"{k}/{n} (95% CI {ci}{extra})"

    def row(self) -> dict[str, Any]:
        """One row of ``outcomes.csv``."""
        s = self.success
        return {"configuration": self.configuration, "mode": self.mode, "runs": self.runs,
                "not_submitted": self.not_submitted, "counted": self.counted, "success": self.successes,
                "collision": self.count("collision"), "timeout": self.count("timeout"),
                "other": self.count("other"), "other_detail": self.other_detail,
                "testbed_error": self.counts.get("error", 0), "cancelled": self.counts.get("cancelled", 0),
                "interrupted": self.counts.get("interrupted", 0), "success_rate": s.get("rate"),
                "ci_low": s.get("ci_low"), "ci_high": s.get("ci_high"), "identical_repetitions": self.identical,
                "distinct_runs": s.get("n")}


def outcome_table(data: StudyRecords, modes: Optional[Iterable[str]] = None, *,
                  summary: type[OutcomeSummary] = OutcomeSummary, key: str = "outcome") -> list[OutcomeSummary]:
    """One :class:`OutcomeSummary` per configuration x mode, in study order; a configuration whose jobs were all
    refused still appears (every run ``not_submitted``).  ``summary`` and ``key``: the class and the runs.csv
    column the runs are counted by (a fleet study's ``fleet_outcome``, by kind)."""
    modes = list(modes) if modes is not None else data.modes
    out = []
    for c in data.configurations:
        for m in modes:
            rows = [r for r in data.rows if r["configuration"] == c and r["mode"] == m]
            counts: dict[str, int] = {}
            for r in rows:
                kind = r.get(key) or r["outcome"]
                counts[kind] = counts.get(kind, 0) + 1
            refused = sum(e.get("repetitions", data.spec.repetitions) for e in data.experiments
                          if e["configuration"] == c and e["status"] == "rejected" and m in e.get("modes", [m]))
            distinct, merged = distinct_runs(rows)
            k = sum(r["outcome"] == "success" for r in distinct)
            out.append(summary(c, m, len(rows), refused, summary.ordered(counts), _proportion(k, len(distinct)),
                               merged))
    return out
