"""Prioritized space-time planning benchmark (docs/planners.md, "Several robots: prioritized planning"): 16 robots on
the 3.6 m field's 360² grid.

The field of ``bench/planners.py`` (room and blocks on the four sub-fields,
a 360 x 360 grid at 1 cm).  Sixteen robots stand at the start and goal poses
of the four sub-fields' plans A and B; each drives to the same pose of the
diagonally opposite sub-field, so every robot crosses the field's centre.
Times :func:`planners.prioritized.plan_prioritized` end to end (the
configuration space built once, as the testbed caches it; ``cold`` times the
first call, grid included) and checks the plan: the smallest distance
between two robots' centres over time.  Target: at most 2 s.

    python bench/prioritized.py [--runs 5] [--robots 16]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the planners package
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from bench._common import interleaved, report  # noqa: E402
from bench.planners import full_field  # noqa: E402
from planners import DEFAULT_PLANNING_MARGIN, load_environment  # noqa: E402
from planners.prioritized import min_separation, plan_prioritized  # noqa: E402

TARGET_S = 2.0
_SUBFIELDS = [((0, 0), "room"), ((1, 0), "blocks"), ((0, 1), "blocks"), ((1, 1), "room")]


def fleet(robots: int) -> tuple[list[list[float]], list[list[float]]]:
    """Starts and goals (m) of up to 16 robots: the plans' poses, each going to its opposite sub-field."""
    poses = []
    for (i, j), name in _SUBFIELDS:
        env = load_environment(name)
        for p in env.plans:
            for x, y, _ in (p.start, p.goal):
                poses.append([x + 1.8 * i, y + 1.8 * j])
    per = len(poses) // 4
    goals = [poses[(k + 3 * per) % len(poses)] if k < per else poses[(3 - k // per) * per + k % per]
             for k in range(len(poses))]
    return poses[:robots], goals[:robots]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--robots", type=int, default=16)
    args = ap.parse_args()
    env = full_field()
    starts, goals = fleet(args.robots)
    t0 = time.perf_counter()
    plan = plan_prioritized(env, starts, goals, planning_margin=DEFAULT_PLANNING_MARGIN)
    cold = time.perf_counter() - t0
    timing = interleaved({"prioritized": lambda: plan_prioritized(env, starts, goals,
                                                                  planning_margin=DEFAULT_PLANNING_MARGIN)},
                         "prioritized", args.runs)
    report("prioritized", [{
        "robots": args.robots, "grid": "360x360", "cold_s": round(cold, 3),
        "median_s": round(timing["prioritized"]["median_s"], 3), "target_s": TARGET_S,
        "makespan_s": round(plan.makespan_s, 2), "min_separation_m": round(min_separation(plan.paths), 4),
        "expanded": [i["expanded"] for i in plan.info], "waits": [i["waits"] for i in plan.info],
    }])


if __name__ == "__main__":
    main()
