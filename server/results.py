"""An experiment's results: metrics per run, aggregates per mode, the direct sim-vs-field comparison."""

from __future__ import annotations

from typing import Any, Sequence

from sqlalchemy.orm import Session

from contract.vocabulary import JOB_OUTCOMES, Mode, run_outcome
from planners.stats import aggregate, proportion
from robot_agent.engine.run_data import compare_runs

from .models import Experiment, Run
from .status import RunStatus
from .store.poses import run_poses

__all__ = ["experiment_metrics", "outcome_of", "outcomes"]


def experiment_metrics(session: Session, exp: Experiment) -> dict[str, Any]:
    """``{experiment_id, status, planned, runs, outcomes, aggregates, direct}`` (docs/metrics.md; SI units).

    ``outcomes``: per mode, how the runs ended and the success rate with its
    Wilson interval (:func:`outcomes`).  ``aggregates``: mean, std and 95% CI
    per mode over the completed runs (``runs`` says how many of them there
    were); failed runs keep their metrics in ``runs``, flagged by ``outcome``.
    ``direct`` is the paper's "ST": for each repetition with both a completed
    ``sim`` and ``twb`` run, the deviation (and Hausdorff / Fréchet distances)
    of the field path from the simulated one (not for multi-robot jobs: their
    runs' metrics are the fleet's, per robot under ``robots``).
    """
    runs = list(exp.runs)
    per_run = [{"run_id": r.id, "mode": r.mode, "repetition": r.repetition, "status": r.status,
                "outcome": outcome_of(r), "stopped_at": r.stopped_at, "metrics": r.metrics or {}} for r in runs]
    done = [r for r in runs if r.status == RunStatus.COMPLETED and r.metrics]
    records = [{"mode": r.mode, **{k: v for k, v in r.metrics.items() if not isinstance(v, dict) and k != "poses"}}
               for r in done]
    aggregates = {g["mode"]: {"runs": g["runs"], "metrics": g["metrics"]}
                  for g in aggregate(records, by=("mode",))} if records else {}
    by_rep: dict[int, dict[str, Run]] = {}
    for r in done:
        by_rep.setdefault(r.repetition, {})[r.mode] = r
    direct = []
    for rep, modes in sorted(by_rep.items()):
        if Mode.SIM in modes and Mode.TWB in modes and exp.robots is None:
            sim, twb = modes[Mode.SIM], modes[Mode.TWB]
            direct.append({"repetition": rep, "sim_run_id": sim.id, "twb_run_id": twb.id,
                           **compare_runs(_driven(session, sim), _driven(session, twb))})
    planned = next((r.metrics.get("planned") for r in done if r.metrics.get("planned")), None)
    return {"experiment_id": exp.id, "status": exp.status, "planned": planned, "runs": per_run,
            "outcomes": outcomes(runs), "aggregates": aggregates, "direct": direct}


def outcome_of(run: Run) -> str:
    """How a run ended (:func:`contract.vocabulary.run_outcome`)."""
    return run_outcome(run.status, run.failure)


def outcomes(runs: Sequence[Run]) -> dict[str, Any]:
    """Per mode: ``counts`` of each outcome, and ``success``: the rate over the runs that ended in one of the
    job's own outcomes (completed or failed; testbed errors, cancels and interruptions are counted apart)
    with its Wilson 95% interval."""
    out: dict[str, Any] = {}
    for mode in dict.fromkeys(r.mode for r in runs):
        mine = [outcome_of(r) for r in runs if r.mode == mode]
        counts = {k: mine.count(k) for k in dict.fromkeys(mine)}
        judged = sum(counts.get(k, 0) for k in JOB_OUTCOMES)
        out[mode] = {"runs": len(mine), "counts": counts, "success": proportion(counts.get("success", 0), judged)}
    return out


def _driven(session: Session, run: Run) -> list[list[float]]:
    return run_poses(session, run.id, between=(run.t_start, run.t_end))
