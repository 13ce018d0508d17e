"""An experiment's results: metrics per run, aggregates per mode, the direct sim-vs-field comparison."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from planners.stats import aggregate

from .models import Experiment, Run
from .pipeline.compute import compare_runs
from .status import RunStatus
from .store.poses import run_poses

__all__ = ["experiment_metrics"]


def experiment_metrics(session: Session, exp: Experiment) -> dict[str, Any]:
    """``{experiment_id, status, planned, runs, aggregates, direct}`` (docs/metrics.md; SI units).

    ``aggregates``: mean, std and 95% CI per mode over the completed runs.
    ``direct`` is the paper's "ST": for each repetition with both a completed
    ``sim`` and ``twb`` run, the deviation (and Hausdorff / Fréchet distances)
    of the field path from the simulated one.
    """
    runs = list(exp.runs)
    per_run = [{"run_id": r.id, "mode": r.mode, "repetition": r.repetition, "status": r.status,
                "metrics": r.metrics or {}} for r in runs]
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
        if "sim" in modes and "twb" in modes:
            sim, twb = modes["sim"], modes["twb"]
            direct.append({"repetition": rep, "sim_run_id": sim.id, "twb_run_id": twb.id,
                           **compare_runs(_driven(session, sim), _driven(session, twb))})
    planned = next((r.metrics.get("planned") for r in done if r.metrics.get("planned")), None)
    return {"experiment_id": exp.id, "status": exp.status, "planned": planned, "runs": per_run,
            "aggregates": aggregates, "direct": direct}


def _driven(session: Session, run: Run) -> list[list[float]]:
    return run_poses(session, run.id, between=(run.t_start, run.t_end))
