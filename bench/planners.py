"""Planner benchmark: every planner on 180², 360² and 1800² grids of a 3.6 m field.

Baseline, measured in the same run on the same grid: one raw
``skfmm.travel_time`` call (unit speed, obstacles masked).  Two figures per
planner, each the median of ``--runs`` (default 5) calls with the grid
already built (grids are cached per environment and resolution):

- ``solve``: the planner proper (``Planner.solve``: FMM = travel time +
  descent; FM² = speed map + travel time + descent; PRM = roadmap + query);
  the issue's targets apply to this figure;
- ``plan_path``: what a user waits for, end to end: validation, ``solve``,
  the collision check of the raw path, post-processing and the final check.

PRM is timed with its roadmap rebuilt every call (``prm``) and reused
(``prm_query``).  Prints JSON; ``ratio`` = time / baseline.

    python bench/planners.py [--runs 5] [--sizes 180,360,1800]
"""

from __future__ import annotations

import argparse
import os
import sys

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the planners package
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402
import skfmm  # noqa: E402

from bench._common import interleaved, report  # noqa: E402
from planners import Environment, config_space, get_planner, load_environment, plan_path  # noqa: E402

TARGETS = {"fmm": 1.3, "fm2": 1.5}
PRM_TARGET_OF_360 = 0.6


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--sizes", default="180,360,1800")
    args = ap.parse_args()
    env = full_field()
    start, goal = (0.3, 0.3, 0.0), (3.3, 3.3, 0.0)
    s_arr, g_arr = np.array(start[:2]), np.array(goal[:2])
    prm = get_planner("prm")
    results, checks = [], {}
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
           robot_radius_m=0.045, runs=args.runs, targets_met=checks)


if __name__ == "__main__":
    main()
