"""Comparisons of a selection of experiments: which configuration is better, on which problems, how sure."""

from __future__ import annotations

from typing import Annotated, Literal, Optional

import anyio
from fastapi import APIRouter, Query

from planners.compared import FLEET_METHOD, METHOD, comparisons_job
from planners.stats import MIN_PROBLEMS

from ...comparisons import MAX_EXPERIMENTS, MAX_METRICS, comparison_input, parse_ids, parse_metrics
from ...schemas import ComparisonsPublic
from ..deps import CurrentUser, TestbedDep
from ..responses import AUTHENTICATED, errors

router = APIRouter(prefix="/comparisons", tags=["comparisons"], responses=AUTHENTICATED)

#: the bootstrap's resamples and seed: a study's defaults (client_sdk.study.compare), so the numbers agree
N_RESAMPLES = 9999
SEED = 0


@router.get("", response_model=ComparisonsPublic, responses=errors(404))
async def get_comparisons(
    user: CurrentUser,
    testbed: TestbedDep,
    experiments: Annotated[list[str], Query(
        description=f"Experiment ids, comma-separated (`experiments=1,2,3`) or repeated: 2 to {MAX_EXPERIMENTS}; "
                    "configurations in this order.")],
    metrics: Annotated[Optional[str], Query(
        description=f"Metrics to compare after the success rate, comma-separated (at most {MAX_METRICS}); "
                    "default: a study's (docs/study.md, \"Comparisons\").")] = None,
    test: Annotated[Literal["t", "rank"], Query(
        description="t tests (per problem paired t or Welch, over problems one-sample t) or rank tests.")] = "t",
    family: Annotated[Literal["metric", "all"], Query(
        description="Holm's family: each metric's comparisons (pooled and per-problem apart), or all.")] = "metric",
    confidence: Annotated[float, Query(gt=0, lt=1, description="Level of the intervals.")] = 0.95,
) -> ComparisonsPublic:
    """Compare the configurations of these experiments (their labels) on each problem and, with 3 or more
    problems, over the problems: the success rate and each metric, per mode and pair, with intervals, tests
    and Holm's correction; and how each configuration's runs ended.  The same numbers as a study's
    ``comparisons.csv`` for its experiments given in study order.  404 if one is not yours."""
    ids = parse_ids(experiments)
    names = parse_metrics(metrics)

    def load():  # type: ignore[no-untyped-def]
        with testbed.sessions() as session:
            return comparison_input(session, user, ids, names)

    given = await anyio.to_thread.run_sync(load)
    fleet = any(e["robots"] > 1 for e in given.experiments)
    options = {"confidence": confidence, "family": family, "test": test, "n_resamples": N_RESAMPLES, "seed": SEED}
    done = await testbed.pool.run(comparisons_job, given.rows, given.metrics, options)
    members: dict[str, list[int]] = {}
    for e in given.experiments:
        members.setdefault(e["configuration"], []).append(e["id"])
    return ComparisonsPublic(
        experiments=given.experiments, configurations=list(members), problems=done["problems"],
        metrics=given.metrics, test=test, family=family, confidence=confidence, n_resamples=N_RESAMPLES, seed=SEED,
        min_problems=MIN_PROBLEMS,
        outcomes=[{**o, "experiments": members[o["configuration"]]} for o in done["outcomes"]], rows=done["rows"],
        method=METHOD + (FLEET_METHOD if fleet else ""))
