"""LaCAM on the field (docs/planners.md, "Several robots: LaCAM"; docs/performance.md): planning time against
prioritized planning, measured in the same run, and the fleets driven to the end.

Three fleets (:func:`fleet`):

* ``dense-16``: 16 robots in two blocks of 2 x 4 (0.15 m apart) on the sub-field exchanging sides;
* ``circle-32``: 32 robots on a circle of 1.5 m round the full field's centre, each bound for the antipodal
  point (prioritized planning gives up on it: "robot 28 (of 32, planned in order)");
* ``random-64``: 64 robots with random starts and goals on the full field (seeded; every two at least
  0.15 m apart).

Planning: :func:`planners.lacam.plan_lacam` with its schedule (:func:`planners.lacam.lacam_schedule`, what a
fleet job computes) and :func:`planners.prioritized.plan_prioritized`, both warm (the grid and the compiled
search loaded; ``cold`` is the first call in the process), interleaved rounds, medians; prioritized's
failures are reported as such.  Targets: circle-32 < 0.1 s, random-64 < 1 s.  ``--drive``: each fleet as a
fleet job (``robot_agent.engine.jobs.fleet_job``) for seeds 0..N-1 in simulation and on the emulated field,
counting collisions and robots that arrived.

    python bench/lacam.py [--runs 5] [--drive 10]
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

RADIUS = 0.065  # the testbed's robot radius with the planning margin (m)
SUB = {"name": "swap", "size": [1.8, 1.8]}
FULL = {"name": "field", "size": [3.6, 3.6]}
TARGETS_S = {"circle-32": 0.1, "random-64": 1.0}


def dense_swap() -> list[dict[str, list[float]]]:
    """16 robots: columns x = 0.3, 0.45 m and x = 1.35, 1.5 m, rows y = 0.45 ... 1.35 m (0.3 m apart) of the
    sub-field; each goes to the mirror image across x = 0.9 m (facing where it goes)."""
    out = []
    for x in (0.3, 0.45):
        for y in (0.45, 0.75, 1.05, 1.35):
            out.append({"start": [x, y, 0.0], "goal": [1.8 - x, y, 0.0]})
            out.append({"start": [1.8 - x, y, float(np.pi)], "goal": [x, y, float(np.pi)]})
    return out


def random_fleet(n: int, seed: int, size: float = 3.6, gap: float = 0.15, margin: float = 0.1) -> list[dict]:
    """``n`` robots with starts and goals drawn uniformly in the field less ``margin`` (m), every two starts and
    every two goals at least ``gap`` (m) apart (seeded)."""
    rng = np.random.default_rng(seed)

    def draw() -> np.ndarray:
        pts: list[np.ndarray] = []
        while len(pts) < n:
            p = rng.uniform(margin, size - margin, 2)
            if all(np.hypot(*(p - q)) >= gap for q in pts):
                pts.append(p)
        return np.array(pts)

    s, g = draw(), draw()
    return [{"start": np.round(a, 4).tolist(), "goal": np.round(b, 4).tolist()} for a, b in zip(s, g)]


def fleet(name: str, seed: int = 0) -> tuple[dict[str, Any], list[dict[str, list[float]]]]:
    """The environment and robots of fleet ``name`` (``dense-16``, ``circle-32``, ``random-64``)."""
    from client_sdk.study._fleet import circle_robots

    if name == "dense-16":
        return SUB, dense_swap()
    if name == "circle-32":
        return FULL, circle_robots(32, 1.5, (1.8, 1.8))
    if name == "random-64":
        return FULL, random_fleet(64, seed)
    raise ValueError(name)


def _time(fn: Any) -> tuple[float, Any]:
    t0 = time.perf_counter()
    try:
        out = fn()
    except Exception as exc:  # noqa: BLE001 - a planner's failure is a result here
        out = exc
    return time.perf_counter() - t0, out


def planning(names: list[str], runs: int) -> list[dict[str, Any]]:
    from planners import parse_environment
    from planners.lacam import lacam_schedule, plan_lacam
    from planners.prioritized import min_separation, plan_prioritized

    rows = []
    for name in names:
        env_data, robots = fleet(name)
        env = parse_environment(env_data)
        s, g = [r["start"] for r in robots], [r["goal"] for r in robots]
        heads = [r["goal"][2] if len(r["goal"]) > 2 else None for r in robots]

        def lacam() -> Any:
            plan = plan_lacam(env, s, g, robot_radius=RADIUS)
            lacam_schedule(plan, heads)
            return plan

        def prioritized() -> Any:
            return plan_prioritized(env, s, g, robot_radius=RADIUS)

        cold, plan = _time(lacam)
        times: dict[str, list[float]] = {"lacam": [], "prioritized": []}
        result: dict[str, Any] = {}
        for _ in range(runs):
            for key, fn in (("lacam", lacam), ("prioritized", prioritized)):
                t, out = _time(fn)
                times[key].append(t)
                result[key] = out
        lac = result["lacam"]
        pri = result["prioritized"]
        row: dict[str, Any] = {
            "fleet": name, "robots": len(robots), "lacam_cold_s": round(cold, 3),
            "lacam_median_s": round(statistics.median(times["lacam"]), 4), "target_s": TARGETS_S.get(name),
            "lacam_makespan_steps": lac.grid.makespan, "lacam_sum_of_costs_steps": lac.grid.sum_of_costs,
            "lacam_lower_bound_steps": lac.grid.stats["lower_bound"], "lacam_plan_makespan_s": round(lac.makespan_s, 2),
            "lacam_min_separation_m": round(min_separation(lac.paths), 4),
            "prioritized_median_s": round(statistics.median(times["prioritized"]), 4),
            "prioritized": "solved" if not isinstance(pri, Exception) else f"failed: {pri}",
        }
        if not isinstance(pri, Exception):
            row["prioritized_plan_makespan_s"] = round(pri.makespan_s, 2)
            row["ratio_lacam_to_prioritized"] = round(statistics.median(
                a / b for a, b in zip(times["lacam"], times["prioritized"])), 3)
        rows.append(row)
    return rows


def drive(names: list[str], seeds: int) -> list[dict[str, Any]]:
    from robot_agent.engine.jobs import fleet_job

    rows = []
    for name in names:
        for backend in ("ideal", "field"):
            done = collided = 0
            closest, makespan, wall = [], [], []
            for seed in range(seeds):
                env, robots = fleet(name, seed)
                t0 = time.perf_counter()
                out = fleet_job(env, robots, "lacam", {}, seed, 600.0, RADIUS, backend)
                wall.append(time.perf_counter() - t0)
                m = out["metrics"]
                done += all(r["outcome"] == "DONE" for r in out["robots"])
                collided += m["collisions_robot"] > 0
                closest.append(m["robot_distance_min_m"])
                makespan.append(m["makespan_s"] if m["makespan_s"] is not None else float("nan"))
            rows.append({"fleet": name, "backend": backend, "seeds": seeds, "all_arrived": done,
                         "runs_with_collision": collided, "closest_approach_min_m": round(min(closest), 4),
                         "makespan_median_s": round(float(np.nanmedian(makespan)), 2),
                         "wall_median_s": round(statistics.median(wall), 2)})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--drive", type=int, default=0, help="seeds to drive each fleet for (0: planning only)")
    ap.add_argument("--fleets", default="dense-16,circle-32,random-64")
    args = ap.parse_args()
    names = args.fleets.split(",")
    out = planning(names, args.runs)
    extra = {"drive": drive(names, args.drive)} if args.drive else {}
    report("lacam", out, **extra)


if __name__ == "__main__":
    main()
