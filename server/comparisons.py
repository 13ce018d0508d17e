"""Comparisons of a selection of experiments: their runs as rows, compared as a study compares them.

``GET /api/v1/comparisons`` loads the experiments (the owner's only) with :func:`comparison_input` and runs
:func:`planners.compared.comparisons_job` on the worker pool (the bootstrap is CPU work).  Each run is a row
as a study's ``runs.csv`` has it: ``configuration`` the experiment's label (``#<id> <label>`` where two selected
experiments share the label and the problem, so they stay apart), ``problem`` its problem, ``outcome`` by
:func:`contract.vocabulary.run_outcome`, the metrics flattened by :func:`planners.compared.flat_metrics` (a
fleet's by :func:`planners.compared.fleet_row`).  Configurations come in the order of the ids given, problems
and modes in the order first seen, so a study's experiments given in study order give the rows of its
``comparisons.csv``.  Repetitions pair (common random numbers) only between experiments with the same seed.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any, Sequence

from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from contract.vocabulary import run_outcome
from planners.compared import (COMPARED_METRICS, CONTROLLER_METRICS, DEFAULT_CONTROLLER, DIRECTION,
                               FLEET_COMPARED, FLEET_METRICS, default_metrics, flat_metrics, fleet_row,
                               job_configuration, problem_label)

from .core.security import Principal
from .errors import Invalid, NotFound
from .models import Experiment

__all__ = ["MAX_EXPERIMENTS", "MAX_METRICS", "ComparisonInput", "comparison_input", "parse_ids", "parse_metrics"]

#: the most experiments one comparison takes
MAX_EXPERIMENTS = 200
#: the most metrics one comparison takes (besides the success rate)
MAX_METRICS = 40


def parse_ids(values: Sequence[str]) -> list[int]:
    """Experiment ids from ``experiments=1,2,3`` (or the parameter repeated), in order, each once; Invalid
    (422) for anything else, fewer than 2 or more than :data:`MAX_EXPERIMENTS`."""
    ids: list[int] = []
    for text in values:
        for part in text.split(","):
            part = part.strip()
            if not part:
                continue
            if not part.isdigit() or not 1 <= int(part) <= 2**63 - 1:
                raise Invalid(f"experiments: {part!r} is not an experiment id (give ids such as experiments=1,2,3)")
            ids.append(int(part))
    ids = list(dict.fromkeys(ids))
    if len(ids) < 2:
        raise Invalid("experiments: give at least 2 experiments to compare (experiments=1,2,...)")
    if len(ids) > MAX_EXPERIMENTS:
        raise Invalid(f"experiments: at most {MAX_EXPERIMENTS} experiments in one comparison, got {len(ids)}")
    return ids


def parse_metrics(text: str | None) -> list[str] | None:
    """Metric names from ``metrics=length_m,execution_time_s`` (None: the defaults); Invalid (422) for a name
    that is no metric's or more than :data:`MAX_METRICS`."""
    if text is None:
        return None
    names = list(dict.fromkeys(m.strip() for m in text.split(",") if m.strip()))
    if not names:
        raise Invalid("metrics: give metric names such as metrics=length_m,execution_time_s (or leave it out)")
    if len(names) > MAX_METRICS:
        raise Invalid(f"metrics: at most {MAX_METRICS} metrics in one comparison, got {len(names)}")
    bad = next((m for m in names if not (m.replace("_", "").isalnum() and m.isascii())), None)
    if bad is not None:
        raise Invalid(f"metrics: {bad!r} is not a metric name")
    return names


#: the keys of a run's row that are not metrics
_NOT_METRICS = {"configuration", "mode", "repetition", "status", "outcome", "problem", "experiment_id", "robots",
                "fleet_outcome", "robot_ends"}


@dataclass(frozen=True)
class ComparisonInput:
    """What the comparison is of: the experiments' entries (in the order given), the runs' rows and the
    metrics to compare after the success rate."""

    experiments: list[dict[str, Any]]
    rows: list[dict[str, Any]]
    metrics: list[str]


def _label(exp: Experiment) -> str:
    """The experiment's label; derived for one stored without (cannot happen after migration 0014)."""
    return exp.label or job_configuration(planner=exp.planner, program=exp.program_id, controller=exp.controller,
                                          controller_program=exp.controller_program_id,
                                          profile_overrides=exp.profile_overrides)


def _problem(exp: Experiment) -> str:
    return exp.problem or problem_label(exp.environment, plans=(exp.environment_data or {}).get("plans") or [],
                                        start=exp.start, goal=exp.goal, robots=exp.robots)


def comparison_input(session: Session, user: Principal, ids: Sequence[int],
                     metrics: list[str] | None) -> ComparisonInput:
    """The experiments ``ids`` (the user's, or anyone's for an admin: NotFound naming the first that is not)
    with their runs as rows, and the metrics to compare (``metrics``, checked against the metrics the runs
    have and the known ones: Invalid otherwise; None: :func:`planners.compared.default_metrics`)."""
    q = select(Experiment).where(Experiment.id.in_(ids)).options(selectinload(Experiment.runs))
    if not user.is_admin:
        q = q.where(Experiment.owner_id == user.id)
    found = {e.id: e for e in session.scalars(q)}
    missing = next((i for i in ids if i not in found), None)
    if missing is not None:
        raise NotFound(f"Experiment {missing} not found")
    exps = [found[i] for i in ids]
    names = {e.id: (_label(e), _problem(e)) for e in exps}
    twins = Counter(names.values())
    entries, rows = [], []
    for e in exps:
        label, problem = names[e.id]
        config = f"#{e.id} {label}" if twins[label, problem] > 1 else label
        entries.append({"id": e.id, "label": label, "problem": problem, "configuration": config, "status": e.status,
                        "environment": e.environment, "planner": e.planner, "modes": list(e.modes),
                        "repetitions": e.repetitions, "seed": e.seed, "robots": len(e.robots) if e.robots else 1})
        for run in sorted(e.runs, key=lambda r: r.id):
            outcome = run_outcome(run.status, run.failure)
            row = {"configuration": config, "mode": run.mode, "repetition": (e.seed, run.repetition),
                   "status": run.status, "outcome": outcome, "problem": problem, "experiment_id": e.id}
            metrics_of = run.metrics or {}
            row.update(fleet_row(len(e.robots), outcome, metrics_of) if e.robots else flat_metrics(metrics_of))
            rows.append(row)
    if metrics is None:
        fleets = [bool(e.robots) for e in exps]
        controllers = {(e.controller or DEFAULT_CONTROLLER, e.controller_program_id) for e in exps}
        compared = len(controllers) > 1 or controllers != {(DEFAULT_CONTROLLER, None)}
        metrics = list(default_metrics(single=not all(fleets), fleet=any(fleets), controllers=compared))
    else:
        known = ({k for r in rows for k in r} - _NOT_METRICS) | set(DIRECTION) | set(FLEET_METRICS) | \
            {"success_rate"} | set(COMPARED_METRICS) | set(CONTROLLER_METRICS) | set(FLEET_COMPARED)
        unknown = [m for m in metrics if m not in known]
        if unknown:
            raise Invalid(f"metrics: unknown metric {unknown[0]!r}: no run of these experiments has it "
                          "(docs/metrics.md lists them)")
    return ComparisonInput(entries, rows, metrics)
