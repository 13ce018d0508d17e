"""Replanning benchmark (docs/controllers.md, "Replanning"): what a replan costs, and what checking the path ahead
costs.

- ``replans``: regulated pure pursuit with ``replan`` = 1 drives fmm's path of each plan of the built-in
  ``crossing`` on both backends for ``--seeds`` seeds (headless); every ``REPLAN`` event's planning wall
  time (the space-time planner from the robot's pose, post-processing included) is collected: median,
  90th percentile and maximum in ms, with the first replan of the process (it builds the grid of the
  static map, cached afterwards) reported alone.
- ``fleet``: the uncoordinated ``swap`` (four robots, fmm's straight paths) replanning around each other
  where they stand, ``--seeds`` seeds: planning times of the replans that found a path and of those that
  did not (they search the whole space-time horizon).
- ``checks``: the same controller along fmm's path of ``room`` plan A, where nothing crosses: with
  ``replan`` = 1 it checks 5 times a second and never replans; ``ratio`` is its run time over the run
  without replanning (medians of ``--runs`` interleaved rounds).

    python bench/replan.py [--seeds 10] [--runs 5]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from bench._common import interleaved, report  # noqa: E402
from planners import DEFAULT_PLANNING_MARGIN, load_environment, plan_path  # noqa: E402
from robot_agent.engine.headless import simulate_run  # noqa: E402
from robot_agent.engine.run_data import block_tuples, moving_tuples  # noqa: E402

RPP = "regulated_pure_pursuit"


def replans(seeds: int) -> dict:
    """Planning times of every replan on `crossing` (fmm's paths, both plans, both backends)."""
    env = load_environment("crossing")
    data = env.to_dict()
    blocks, moving = block_tuples(data), moving_tuples(data)
    times: list[float] = []
    first = None
    outcomes: dict[str, int] = {}
    for plan in env.plans:
        path = plan_path(env, plan.start, plan.goal, "fmm", planning_margin=DEFAULT_PLANNING_MARGIN).path
        for backend in ("ideal", "field"):
            for seed in range(seeds):
                run = simulate_run(path, plan.start, seed=seed, blocks=blocks, moving=moving, area=env.size,
                                   backend=backend, controller=RPP, controller_params={"replan": 1})
                outcomes[run.outcome] = outcomes.get(run.outcome, 0) + 1
                got = [e.seconds for e in run.events if e.kind == "REPLAN"]
                if first is None and got:
                    first, got = got[0], got[1:]
                times += got
    ms = np.array(times) * 1000.0
    return {"replans_timed": len(ms), "median_ms": round(float(np.median(ms)), 2),
            "p90_ms": round(float(np.percentile(ms, 90)), 2), "max_ms": round(float(ms.max()), 2),
            "first_ms": round(first * 1000.0, 2) if first is not None else None, "runs": outcomes}


def fleet(seeds: int) -> dict:
    """Replanning times in the uncoordinated four-robot swap, found and not found."""
    from contract.controller_specs import select
    from robot_agent.engine.jobs import fleet_job

    env = load_environment("swap")
    robots = [{"start": list(p.start), "goal": list(p.goal)} for p in env.plans]
    params = select(RPP, {"replan": 1}).params
    found: list[float] = []
    failed: list[float] = []
    success = []
    for seed in range(seeds):
        out = fleet_job(env.to_dict(), robots, "fmm", {}, seed, 120.0, 0.045, controller=RPP,
                        controller_params=params)
        success.append(out["metrics"]["success_rate"])
        for r in out["robots"]:
            for _, line, _ in r["lines"]:
                if line.startswith("EV,REPLAN,"):
                    _, _, n, ms, _ = line.split(",")
                    (found if int(n) else failed).append(float(ms))

    def stats(ms: list[float]) -> dict:
        return {"n": len(ms), "median_ms": round(float(np.median(ms)), 2) if ms else None,
                "max_ms": round(float(max(ms)), 2) if ms else None}

    return {"found": stats(found), "not_found": stats(failed), "success_rate_mean": float(np.mean(success))}


def checks(runs: int) -> dict:
    """The cost of checking (nothing to replan around) relative to not replanning."""
    env = load_environment("room")
    p = env.plan("A")
    path = plan_path(env, p.start, p.goal, "fmm", planning_margin=DEFAULT_PLANNING_MARGIN).path
    blocks = block_tuples(env.to_dict())

    def drive(on: int):  # noqa: ANN202
        return lambda: simulate_run(path, p.start, seed=1, blocks=blocks, area=env.size, backend="field",
                                    controller=RPP, controller_params={"replan": on})

    t0 = time.perf_counter()
    run = drive(1)()
    once = time.perf_counter() - t0
    timing = interleaved({"off": drive(0), "on": drive(1)}, "off", runs)
    return {"experiment_s": run.t_end, "checks": int(run.t_end / 0.2), "first_run_s": round(once, 4),
            "timing": timing}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--runs", type=int, default=5)
    a = ap.parse_args()
    report("replan", [{"replans": replans(a.seeds)}, {"fleet": fleet(a.seeds)}, {"checks": checks(a.runs)}])


if __name__ == "__main__":
    main()
