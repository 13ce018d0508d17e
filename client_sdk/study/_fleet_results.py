"""A fleet study's results: each run's row, how it ended by kind, and the fleet metrics per configuration x
environment x robot count x mode with their uncertainty.

A fleet's run succeeds when every robot reached its goal.  A failed run is
counted under the kind of its failure (:func:`fleet_outcome`): a robot-robot
collision, a collision with a moving obstacle, with a block or the wall
(the gravest present, in that order), a deadlock (a timeout while no robot
under way moved: the fleet metrics' ``deadlock``), a timeout, or the server's
failure otherwise (``planning``: the planner found no way for some robot).

The metrics (docs/metrics.md, "Several robots") are summarised with
:func:`planners.stats.summarize` (mean, std, Student-t 95% interval) over
the runs each one is defined for (:data:`FLEET_METRICS`' ``over``):
``completed`` runs (makespan, flowtime, the sum of path lengths, the time
within the safety radius: a fleet that crashed early drove less and for a
shorter time) or every ``measured`` run, failed ones included (the closest
approach, the share of robots that arrived, collisions by kind: how unsafe a
failed fleet was is the point).  Identical repetitions (the deterministic simulation) count once,
as everywhere in a study (:func:`~client_sdk.study._outcomes.distinct_runs`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from planners.compared import (FLEET_COMPARED, FLEET_KINDS, FLEET_METRICS, FleetMetric, fleet_outcome, fleet_row,
                               measured)

from ._outcomes import OutcomeSummary, distinct_runs, outcome_table
from ._records import StudyRecords

__all__ = ["FLEET_COMPARED", "FLEET_KINDS", "FLEET_METRICS", "FleetGroup", "FleetMetric", "FleetOutcomes",
           "fleet_groups", "fleet_outcome", "fleet_outcomes", "fleet_row", "measured"]

# FleetMetric, FLEET_METRICS, FLEET_COMPARED, FLEET_KINDS, fleet_outcome, fleet_row and measured live in
# planners.compared: the server's GET /api/v1/comparisons flattens and compares a fleet's runs with them too.


def _runs_over(rows: list[dict[str, Any]], over: str) -> list[dict[str, Any]]:
    return [r for r in rows if (r.get("status") == "completed" if over == "completed" else measured(r))]


@dataclass(frozen=True)
class FleetOutcomes(OutcomeSummary):
    """How a configuration's fleet runs ended in one mode, by :func:`fleet_outcome` (columns :data:`FLEET_KINDS`,
    then ``other``); success: every robot arrived."""

    NAMED: ClassVar[tuple[str, ...]] = FLEET_KINDS


def fleet_outcomes(data: StudyRecords) -> list[OutcomeSummary]:
    """One :class:`FleetOutcomes` per configuration x mode, pooled over the problems (the outcomes figure)."""
    return outcome_table(data, summary=FleetOutcomes, key="fleet_outcome")


@dataclass(frozen=True, kw_only=True)
class FleetGroup(FleetOutcomes):
    """One configuration's runs on one fleet problem (environment, plan of ``robots`` robots) in one mode: an
    :class:`~client_sdk.study._outcomes.OutcomeSummary` whose ``counts`` are runs per :func:`fleet_outcome`
    (columns :data:`FLEET_KINDS`) and whose ``success`` is the share of runs in which every robot arrived, over
    the distinct counted runs (Wilson 95% interval), with ``metrics``: :func:`planners.stats.summarize` of each
    of :data:`FLEET_METRICS` over its distinct runs (``n`` says how many).
    """

    environment: str
    plan: str
    robots: int
    metrics: dict[str, dict[str, Any]]

    def keys(self) -> dict[str, Any]:
        return {"configuration": self.configuration, "environment": self.environment, "plan": self.plan,
                "robots": self.robots, "mode": self.mode}

    def row(self) -> dict[str, Any]:
        """The group's row of ``fleet_outcomes.csv``."""
        s = self.success
        return {**self.keys(), "runs": self.runs, "not_submitted": self.not_submitted,
                **{kind: self.count(kind) for kind in FLEET_KINDS}, "other": self.count("other"),
                "other_detail": self.other_detail, "not_counted": self.not_counted, "success_rate": s.get("rate"),
                "ci_low": s.get("ci_low"), "ci_high": s.get("ci_high"), "distinct_runs": s.get("n"),
                "identical_repetitions": self.identical}

    def aggregate(self) -> dict[str, Any]:
        """As :func:`planners.stats.aggregate` gives a group (for :func:`planners.stats.table_rows`), each
        summary with the runs it is ``over``."""
        return {**self.keys(), "runs": self.runs,
                "metrics": {m: {**s, "over": FLEET_METRICS[m].over} for m, s in self.metrics.items()}}


def fleet_groups(data: StudyRecords) -> list[FleetGroup]:
    """One :class:`FleetGroup` per configuration x environment x plan x mode, in study order (a refused job's
    group too, with its runs ``not_submitted``)."""
    from planners.stats import proportion, summarize

    out = []
    for config in data.configurations:
        for env, plan in data.problems:
            exps = [e for e in data.experiments if (e["configuration"], e["environment"], e["plan"]) ==
                    (config, env, plan)]
            if not exps:
                continue
            robots = len(exps[0].get("robots") or []) or 1
            for mode in data.modes:
                rows = [r for r in data.rows if (r["configuration"], r["environment"], r["plan"], r["mode"]) ==
                        (config, env, plan, mode)]
                counts: dict[str, int] = {}
                for r in rows:
                    kind = r.get("fleet_outcome") or r.get("outcome") or "pending"
                    counts[kind] = counts.get(kind, 0) + 1
                refused = sum(e.get("repetitions", data.spec.repetitions) for e in exps
                              if e["status"] == "rejected" and mode in e.get("modes", [mode]))
                distinct, merged = distinct_runs(rows)
                success = proportion(sum(r["outcome"] == "success" for r in distinct), len(distinct))
                metrics = {m: summarize(r.get(m) for r in _runs_over(distinct, spec.over))
                           for m, spec in FLEET_METRICS.items()}
                out.append(FleetGroup(configuration=config, mode=mode, runs=len(rows), not_submitted=refused,
                                      counts=FleetGroup.ordered(counts), success=success,
                                      identical=merged, environment=env, plan=plan, robots=robots, metrics=metrics))
    return out
