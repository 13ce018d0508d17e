"""Moving obstacles benchmark (docs/planners.md, "Space-time A*"): st_astar's planning time and the simulation's speed
with discs.

Per plan of the built-in ``crossing``: ``st_astar`` and ``fmm`` end to end
(``plan_path``, the testbed's planning margin), and the headless run of the
st_astar path in the world with its moving discs against the same run with
the discs removed (the collision check's cost per step).  Medians of
``--runs`` interleaved rounds; ``ratio`` is time / the baseline of each
group (``fmm`` for planning, the run without discs for the simulation).

    python bench/dynamic.py [--runs 5]
"""

from __future__ import annotations

import argparse
import os
import sys

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the planners package
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from bench._common import interleaved, report  # noqa: E402
from planners import DEFAULT_PLANNING_MARGIN, load_environment, plan_path  # noqa: E402
from robot_agent.engine.headless import simulate_run  # noqa: E402
from robot_agent.engine.run_data import block_tuples, moving_tuples  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    env = load_environment("crossing")
    data = env.to_dict()
    blocks, moving = block_tuples(data), moving_tuples(data)
    results = []
    for plan in env.plans:
        def planner(name: str):  # noqa: ANN202 - a closure per planner
            return lambda: plan_path(env, plan.start, plan.goal, name, planning_margin=DEFAULT_PLANNING_MARGIN)

        timing = interleaved({"fmm": planner("fmm"), "st_astar": planner("st_astar")}, "fmm", args.runs)
        st = planner("st_astar")()
        run = simulate_run(st.path, plan.start, seed=1, blocks=blocks, moving=moving, area=env.size)
        sim = interleaved({
            "without_discs": lambda: simulate_run(st.path, plan.start, seed=1, blocks=blocks, area=env.size),
            "with_discs": lambda: simulate_run(st.path, plan.start, seed=1, blocks=blocks, moving=moving,
                                               area=env.size),
        }, "without_discs", args.runs)
        results.append({"plan": plan.name, "planning": timing, "simulation": sim,
                        "st_astar_expanded": st.info["expanded"], "st_astar_length_m": round(st.length_m, 3),
                        "run_outcome": run.outcome, "run_experiment_s": run.t_end,
                        "real_time_factor": round(run.t_end / sim["with_discs"]["median_s"])})
    report("dynamic", results)


if __name__ == "__main__":
    main()
