"""Planner benchmark: every planner on a 3.6 m field, and FMM / FM² per problem against scikit-fmm.

Baseline, measured in the same run on the same grid: one raw
``skfmm.travel_time`` call (unit speed, obstacles masked, phi built as the
planners build it).  Timings are interleaved (one call of every task per
round), medians of ``--runs`` rounds after a warm-up round; ``ratio`` is the
median over rounds of task / baseline.  Grids are built once per environment
and resolution (neither figure includes rasterisation).

Part 1 (``field``), every planner on the 3.6 m field (room and blocks tiled)
from (0.3, 0.3) to (3.3, 3.3) on ``--sizes`` grids:

- ``solve``: the planner proper (``Planner.solve``: FMM = march + descent;
  FM² = speed map + march + descent; PRM = roadmap + query);
- ``plan_path``: what a user waits for, end to end: validation, ``solve``,
  the collision check of the raw path, post-processing and the final check.

PRM is timed with its roadmap rebuilt every call (``prm``) and reused
(``prm_query``).

Part 2 (``problems``), FMM and FM² per problem on ``--problem-sizes`` cells a
side: the paper's four (``room`` and ``blocks``, plans A and B) and harder
generated ones (``maze``: a serpentine through the whole field; ``clutter``:
40 seeded random blocks, corner to corner; ``field``: the tiled 3.6 m field
corner to corner; ``near``: a short query inside one room).  ``fmm`` and
``fm2`` are ``Planner.solve`` (the march stops once the start and the band the
descent reads are accepted); ``fmm_full`` / ``fm2_full`` are the same
planners on the whole field (``skfmm.travel_time`` + the same descent), as
before early termination; ``accepted`` is the fraction of the free cells the
march accepted (its cost: docs/performance.md).  The issue's targets: median
over the paper's four problems on 360 cells a side, FMM <= 0.25x and FM² <=
0.5x the baseline.

Part 3 (``baselines``, issue 31), on the problem set of ``planners.problems`` (the paper's four, ``narrow``,
``clutter``, ``zigzag``; 1 cm grid, 0.065 m clearance, each problem's visibility-graph optimum stored) against
the same-run baseline on that grid: ``fmm``, ``fm2``, ``fm2_no_shortcut`` (``shortcut`` false: the smoothed descent,
FM² before its band shortcut), ``astar``, ``prm`` (grown until connected, its defaults), ``prm_fixed`` (the paper's
500 samples, ``grow`` false), ``prm_star`` and ``theta_star`` as ratios to the baseline (``Planner.solve``,
PRM with a fresh roadmap and its own seed every call: a seed per round), with success and length / optimum
over ``--seeds`` seeds; and every OMPL planner (when the ``ompl`` package is installed) over ``--seeds``
seeds with a ``--ompl-budget`` time budget: success, time to the first solution and to within 1 % of the
optimum (from its progress), length / optimum at the end, each time also as a ratio to the baseline's median.
For every planner also the smallest exact clearance (m) and the median total turning (rad) of the sent paths.
The issue's target: PRM's median ratio over the paper's four <= 0.6.

Prints JSON.

    python bench/planners.py [--runs 5] [--sizes 180,360,1800] [--problem-sizes 360,1800]
                             [--only field|problems|baselines] [--seeds 10] [--ompl-budget 1.0]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the planners package
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402
import skfmm  # noqa: E402

from bench._common import interleaved, report  # noqa: E402
from planners import (  # noqa: E402
    Environment, PlanningError, check_query, config_space, get_planner, load_environment, plan_path,
)
from planners.fast_marching import descend, travel_time  # noqa: E402
from planners.fm2 import speed_map  # noqa: E402

TARGETS = {"fmm": 1.3, "fm2": 1.5}
PRM_TARGET_OF_360 = 0.6
#: issue 35: median over the paper's four problems on 360 cells a side, as a fraction of the baseline
EARLY_TARGETS = {"fmm": 0.25, "fm2": 0.5}
PAPER = [("room", "A"), ("room", "B"), ("blocks", "A"), ("blocks", "B")]


def full_field() -> Environment:
    """The 3.6 m field: room and blocks environments on the four 1.8 m sub-fields."""
    blocks = []
    layout = {(0, 0): "room", (1, 0): "blocks", (0, 1): "blocks", (1, 1): "room"}
    for (i, j), name in layout.items():
        for b in load_environment(name).blocks:
            blocks.append({"x": b.x + 1.8 * i, "y": b.y + 1.8 * j, "w": b.w, "h": b.h, "angle": b.angle})
    return load_environment({"name": "field", "size": [3.6, 3.6], "blocks": blocks})


def baseline(space, goal) -> None:  # type: ignore[no-untyped-def]
    h = space.resolution
    ny, nx = space.free.shape
    xs = (np.arange(nx) + 0.5) * h - goal[0]
    ys = (np.arange(ny) + 0.5) * h - goal[1]
    phi = np.ma.MaskedArray(np.hypot(xs[None, :], ys[:, None]) - h, mask=~space.free)
    skfmm.travel_time(phi, np.ones((ny, nx)), dx=h)


def maze() -> Environment:
    """A serpentine: five walls from alternate sides, the path winds through the whole 1.8 m field."""
    blocks = []
    for n, x in enumerate((0.3, 0.6, 0.9, 1.2, 1.5)):
        blocks.append({"x": x, "y": 0.75 if n % 2 == 0 else 1.05, "w": 0.06, "h": 1.5, "angle": 0.0})
    return load_environment({"name": "maze", "size": [1.8, 1.8], "blocks": blocks})


def clutter(seed: int = 0) -> Environment:
    """40 random blocks (seeded) on the 1.8 m field, with (0.1, 0.1) and (1.7, 1.7) free and connected."""
    while True:
        rng = np.random.default_rng(seed)
        blocks = []
        for _ in range(40):
            w, h = rng.uniform(0.04, 0.2, 2)
            r = math.hypot(w, h) / 2 + 0.002
            blocks.append({"x": rng.uniform(r, 1.8 - r), "y": rng.uniform(r, 1.8 - r), "w": w, "h": h,
                           "angle": rng.uniform(0, math.pi)})
        env = load_environment({"name": f"clutter-{seed}", "size": [1.8, 1.8], "blocks": blocks})
        try:
            check_query(env, (0.1, 0.1), (1.7, 1.7), robot_radius=0.045, resolution=0.01)
            return env
        except PlanningError:  # blocked or separated: the next seed
            seed += 1


def problems() -> list[tuple[str, bool, Environment, tuple[float, float], tuple[float, float]]]:
    """(name, one of the paper's, environment, start, goal): the paper's four, then harder generated ones."""
    out = []
    for env_name, plan_name in PAPER:
        env = load_environment(env_name)
        p = env.plan(plan_name)
        out.append((f"{env_name} {plan_name}", True, env, tuple(p.start[:2]), tuple(p.goal[:2])))
    out.append(("maze", False, maze(), (0.15, 0.15), (1.65, 1.65)))
    out.append(("clutter", False, clutter(), (0.1, 0.1), (1.7, 1.7)))
    out.append(("field", False, full_field(), (0.3, 0.3), (3.3, 3.3)))
    out.append(("near", False, load_environment("room"), (1.2, 1.3), (1.5, 1.5)))
    return out


def run_problems(sizes: list[int], runs: int) -> tuple[list[dict], dict[str, dict], dict[str, bool]]:
    """Part 2: FMM and FM² per problem, early-terminated and on the whole field, against the baseline.

    Returns the rows, the medians over the paper's four per grid, and the issue's targets (360 cells).
    """
    rows, medians, checks = [], {}, {}
    fmm, fm2 = get_planner("fmm"), get_planner("fm2")
    p_fmm, p_fm2 = fmm.validate_params({}), fm2.validate_params({})
    for n in sizes:
        ratios: dict[str, list[float]] = {"fmm": [], "fm2": []}
        for name, paper, env, start, goal in problems():
            space = config_space(env, 0.045, env.width / n)
            s, g = np.array(start), np.array(goal)
            info: dict[str, dict] = {}

            def early(impl, params, key):  # type: ignore[no-untyped-def]
                def run() -> None:
                    info[key] = impl.solve(space, s.copy(), g.copy(), params, 0)[1]
                return run

            def full_fmm() -> None:
                descend(space, travel_time(space, g), s, g)

            def full_fm2() -> None:
                descend(space, travel_time(space, g, speed_map(space, p_fm2["saturation"], p_fm2["min_speed"])), s, g)

            tasks = {"baseline": lambda: baseline(space, g), "fmm": early(fmm, p_fmm, "fmm"),
                     "fm2": early(fm2, p_fm2, "fm2"), "fmm_full": full_fmm, "fm2_full": full_fm2}
            timed = interleaved(tasks, "baseline", runs)
            free = int(space.free.sum())
            row = {"problem": name, "paper": paper, "grid": f"{space.free.shape[1]}x{space.free.shape[0]}",
                   "resolution_m": space.resolution, "free_cells": free,
                   "baseline_travel_time_s": timed["baseline"]["median_s"]}
            for key in ("fmm", "fm2", "fmm_full", "fm2_full"):
                row[key] = {"s": timed[key]["median_s"], "ratio": timed[key]["ratio"]}
            for key in ("fmm", "fm2"):
                row[key]["cells_accepted"] = info[key]["cells_accepted"]
                row[key]["accepted"] = info[key]["cells_accepted"] / free
                row[key]["descents"] = info[key]["descents"]
            rows.append(row)
            print(f"{name} {row['grid']}: baseline {row['baseline_travel_time_s'] * 1e3:.1f} ms, "
                  + ", ".join(f"{k} {row[k]['ratio']:.3f}x" for k in ("fmm", "fm2", "fmm_full", "fm2_full")),
                  file=sys.stderr)
            if paper:
                for key in ratios:
                    ratios[key].append(row[key]["ratio"])
        medians[f"{n}x{n}"] = {key: statistics.median(r) for key, r in ratios.items()}
        if n == 360:
            for key, limit in EARLY_TARGETS.items():
                checks[f"{key}: median over the paper's four at 360x360 <= {limit}x baseline"] = \
                    medians["360x360"][key] <= limit
    return rows, medians, checks


def run_baselines(runs: int, seeds: int, ompl_budget: float) -> tuple[list[dict], dict[str, bool]]:
    """Part 3: the new PRM, Theta* and OMPL's planners on the problem set against the same-run baseline."""
    from planners.ompl_planners import OMPL_PLANNERS
    from planners.problems import PROBLEM_CLEARANCE, problems as problem_set

    try:
        import ompl.geometric  # noqa: F401
        ompl_names = list(OMPL_PLANNERS)
    except ImportError:
        ompl_names = []
    from planners.geometry import polyline_min_clearance

    ours = {"fmm": ("fmm", {}), "fm2": ("fm2", {}), "fm2_no_shortcut": ("fm2", {"shortcut": False}),
            "astar": ("astar", {}), "prm": ("prm", {}),
            "prm_fixed": ("prm", {"grow": False}), "prm_star": ("prm", {"prm_star": True}),
            "theta_star": ("theta_star", {})}

    def shape(path: np.ndarray) -> tuple[float, float]:
        """Exact minimum clearance (m) and total turning (rad) of a sent path."""
        d = np.diff(path[:, :2], axis=0)
        d = d[np.hypot(*d.T) > 1e-9]
        a = np.arctan2(d[:, 1], d[:, 0])
        turn = float(np.abs((np.diff(a) + np.pi) % (2 * np.pi) - np.pi).sum())
        return polyline_min_clearance(pb.env, path), turn
    rows, paper_prm = [], []
    for pb in problem_set():
        space = config_space(pb.env, PROBLEM_CLEARANCE)
        s, g = np.array(pb.start[:2]), np.array(pb.goal[:2])
        tasks = {"baseline": lambda space=space, g=g: baseline(space, g)}
        for label, (name, extra) in ours.items():
            impl = get_planner(name)
            params = impl.validate_params(extra)
            counter = iter(range(10**9))

            def solve(impl=impl, params=params, counter=counter, space=space, s=s, g=g) -> None:  # type: ignore[no-untyped-def]
                impl.forget()
                try:
                    impl.solve(space, s.copy(), g.copy(), params, next(counter))
                except PlanningError:
                    pass  # a failed PRM run is timed as well: its time was spent

            tasks[label] = solve
        timed = interleaved(tasks, "baseline", runs)
        base = timed["baseline"]["median_s"]
        row: dict = {"problem": pb.name, "optimum_m": pb.optimum_m, "baseline_travel_time_s": base, "planners": {}}
        for label, (name, extra) in ours.items():
            lengths, clear, turns, fails = [], [], [], 0
            for seed in range(seeds if get_planner(name).stochastic else 1):
                get_planner(name).forget()
                try:
                    r = plan_path(pb.env, pb.start, pb.goal, name, robot_radius=0.045, planning_margin=0.02,
                                  params=extra, seed=seed)
                except PlanningError:
                    fails += 1
                    continue
                lengths.append(r.length_m)
                c, t = shape(r.path)
                clear.append(c)
                turns.append(t)
            row["planners"][label] = {"solve_s": timed[label]["median_s"], "ratio": timed[label]["ratio"],
                                      "success": f"{len(lengths)}/{len(lengths) + fails}",
                                      "length_over_optimum": statistics.median(lengths) / pb.optimum_m
                                      if lengths else None,
                                      "clearance_min_m": min(clear) if clear else None,
                                      "turning_rad": statistics.median(turns) if turns else None}
        for name in ompl_names:
            first, within, ratio, clear, turns, ok = [], [], [], [], [], 0
            for seed in range(seeds):
                try:
                    r = plan_path(pb.env, pb.start, pb.goal, name, robot_radius=0.045, planning_margin=0.02,
                                  params={"time_budget_s": ompl_budget}, seed=seed)
                except PlanningError:
                    continue
                ok += 1
                prog = r.info["progress"]
                if r.info["time_to_first_solution_s"] is not None:
                    first.append(r.info["time_to_first_solution_s"])
                near = [t for t, c in prog if c <= 1.01 * pb.optimum_m]
                if near and r.info["time_to_first_solution_s"] is not None:
                    within.append(near[0])
                ratio.append(r.length_m / pb.optimum_m)
                c, t = shape(r.path)
                clear.append(c)
                turns.append(t)

            def med(xs: list[float]) -> float | None:
                return statistics.median(xs) if xs else None

            row["planners"][name] = {
                "success": f"{ok}/{seeds}", "budget_s": ompl_budget,
                "first_solution_s": med(first), "first_solution_ratio": med(first) / base if first else None,
                "within_1pct_s": med(within), "within_1pct_runs": f"{len(within)}/{seeds}",
                "within_1pct_ratio": med(within) / base if within else None,
                "length_over_optimum": med(ratio), "clearance_min_m": min(clear) if clear else None,
                "turning_rad": med(turns)}
        rows.append(row)
        print(f"{pb.name}: baseline {base * 1e3:.1f} ms, " + ", ".join(
            f"{k} {v.get('ratio', v.get('first_solution_ratio')) or float('nan'):.2f}x {v['success']}"
            for k, v in row["planners"].items()), file=sys.stderr)
        if pb.name in ("room-A", "room-B", "blocks-A", "blocks-B"):
            paper_prm.append(row["planners"]["prm"]["ratio"])
    checks = {f"prm: median over the paper's four <= {PRM_TARGET_OF_360}x baseline (1 cm grid)":
              statistics.median(paper_prm) <= PRM_TARGET_OF_360}
    return rows, checks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--sizes", default="180,360,1800", help="part 1: cells a side of the 3.6 m field")
    ap.add_argument("--problem-sizes", default="360,1800", help="part 2: cells a side of each problem's field")
    ap.add_argument("--only", choices=("field", "problems", "baselines"), help="run one part")
    ap.add_argument("--seeds", type=int, default=10, help="part 3: seeds per stochastic planner and problem")
    ap.add_argument("--ompl-budget", type=float, default=1.0, help="part 3: OMPL's time budget (s)")
    args = ap.parse_args()
    results, checks, rows, medians = [], {}, [], {}
    if args.only == "baselines":
        rows, checks = run_baselines(args.runs, args.seeds, args.ompl_budget)
        report("planners", [], clearance_m=0.065, resolution_m=0.01, runs=args.runs, seeds=args.seeds,
               targets_met=checks, baselines=rows)
        return
    if args.only != "field":
        rows, medians, checks = run_problems([int(n) for n in args.problem_sizes.split(",")], args.runs)
    if args.only == "problems":
        report("planners", [], robot_radius_m=0.045, runs=args.runs, targets_met=checks,
               paper_medians=medians, problems=rows)
        return
    env = full_field()
    start, goal = (0.3, 0.3, 0.0), (3.3, 3.3, 0.0)
    s_arr, g_arr = np.array(start[:2]), np.array(goal[:2])
    prm = get_planner("prm")
    for n in (int(s) for s in args.sizes.split(",")):
        res = 3.6 / n
        space = config_space(env, 0.045, res)
        tasks = {"baseline": lambda: baseline(space, g_arr)}

        def add(label: str, name: str, fresh_roadmap: bool = False) -> None:
            impl = get_planner(name)
            params = impl.validate_params({})

            def solve() -> None:
                if fresh_roadmap:
                    prm._cache.clear()
                impl.solve(space, s_arr, g_arr, params, 0)

            def full() -> None:
                if fresh_roadmap:
                    prm._cache.clear()
                plan_path(env, start, goal, name, resolution=res)

            tasks[f"{label}.solve"] = solve
            tasks[f"{label}.plan_path"] = full

        for name in ("fmm", "fm2", "astar"):
            add(name, name)
        add("prm", "prm", fresh_roadmap=True)
        add("prm_query", "prm")
        timed = interleaved(tasks, "baseline", args.runs)
        row = {"grid": f"{n}x{n}", "resolution_m": res, "baseline_travel_time_s": timed["baseline"]["median_s"],
               "planners": {}}
        for key, val in timed.items():
            if key == "baseline":
                continue
            label, kind = key.split(".")
            row["planners"].setdefault(label, {})[f"{kind}_s"] = val["median_s"]
            row["planners"][label][f"{kind}_ratio"] = val["ratio"]
        results.append(row)
        for name, limit in TARGETS.items():
            checks[f"{name}@{row['grid']} solve <= {limit}x baseline"] = row["planners"][name]["solve_ratio"] <= limit
        if n == 360:
            ratio = row["planners"]["prm"]["solve_ratio"]
            checks[f"prm(500)@360x360 solve <= {PRM_TARGET_OF_360}x baseline"] = ratio <= PRM_TARGET_OF_360
    report("planners", results, environment="field 3.6 m (room/blocks tiled)", start=start, goal=goal,
           robot_radius_m=0.045, runs=args.runs, targets_met=checks, paper_medians=medians, problems=rows)


if __name__ == "__main__":
    main()
