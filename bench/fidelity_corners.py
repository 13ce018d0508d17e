"""Where a driven path's κ' comes from: near the plan's corners or along its straights (docs/fidelity.md,
"What does not hold yet").

For the varied environments' random problems of ``--seeds`` (``bench/fidelity.py``'s), every planner's
path is driven by the simulated (S) and the field (T) robot; the squared turning angles of each driven
path's 5 cm resampling (what κ' is the root mean of) are pooled per planner and mode and split into
those within ``--near`` metres of a corner of the plan (a turn above 15° on the plan's own resampling)
and the rest, each divided by the number of all angles.  Their sum is the pooled κ'².

    python bench/fidelity_corners.py [--seeds 0-3] [--near 0.15] [--set field.wheel_noise_rel=0 ...]

Prints JSON: per planner and mode, ``near`` and ``elsewhere`` (rad²), the mean driven κ' and the mean
planned κ' (rad), and the runs counted (completed ones only).
"""

from __future__ import annotations

import argparse
import math
import os
import sys

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

from bench import fidelity  # noqa: E402
from bench._common import key_values, report, seed_list  # noqa: E402
from contract.params import robot_params  # noqa: E402
from contract.protocol import decode_path, encode_path  # noqa: E402
from planners import PlanningError, parse_environment, plan_path  # noqa: E402
from planners.metrics import smoothness_polyline, turning_angles  # noqa: E402

CORNER_RAD = np.radians(15.0)  #: a plan's turn above this is a corner


def split_turning(driven: np.ndarray, corners: np.ndarray, near_m: float) -> tuple[float, float, int]:
    """Sums of squared turning angles (rad²) of ``driven``'s κ' resampling within ``near_m`` of any of
    ``corners`` ``(K, 2)`` (m) and elsewhere, and how many angles there are (κ' is the root of the two sums
    over it)."""
    poly = smoothness_polyline(driven)
    a = turning_angles(poly)
    pts = poly[1:1 + len(a)]
    if len(corners):
        d = np.min(np.hypot(pts[:, None, 0] - corners[None, :, 0], pts[:, None, 1] - corners[None, :, 1]), axis=1)
    else:
        d = np.full(len(a), np.inf)
    near = d < near_m
    return float(np.sum(a[near] ** 2)), float(np.sum(a[~near] ** 2)), len(a)


def measure(seeds: list[int], near_m: float, overrides: dict[str, float]) -> list[dict[str, object]]:
    """The split of every planner and mode over the varied problems of ``seeds``."""
    params = robot_params(fidelity.profile_with(overrides))
    acc: dict[tuple[str, str], list[tuple[float, float, int, float, float]]] = {}
    for seed in seeds:
        for env_data in fidelity.varied_environments():
            env = parse_environment(env_data)
            for prob in fidelity.random_plans(env_data, 3, seed):
                for planner in ("fmm", "fm2", "prm"):
                    try:
                        r = plan_path(env, prob["start"], prob["goal"], planner, seed=seed,
                                      robot_radius=fidelity.ROBOT_RADIUS + fidelity.PLANNING_MARGIN)
                    except PlanningError:
                        continue
                    plan = np.round(r.path, 6)
                    wire = decode_path(encode_path(plan))
                    pv = smoothness_polyline(plan[:, :2])
                    pa = turning_angles(pv)
                    corners = pv[1:-1][pa > CORNER_RAD]
                    planned_kappa = float(np.sqrt(np.mean(pa * pa))) if len(pa) else 0.0  # smoothness(plan)
                    for mode, backend in fidelity.BACKEND.items():
                        poses, t0, t1, end, _ = fidelity.drive(env_data, wire, prob["start"], backend, 1000 + seed,
                                                               params)
                        if end != "DONE":
                            continue
                        q = poses[(poses[:, 0] >= t0) & (poses[:, 0] <= t1), 1:3]
                        near, elsewhere, n = split_turning(q, corners, near_m)
                        kappa = math.sqrt((near + elsewhere) / n) if n else 0.0  # smoothness(q), from its angles
                        acc.setdefault((planner, mode), []).append((near, elsewhere, n, kappa, planned_kappa))
    rows = []
    for (planner, mode), v in sorted(acc.items()):
        a = np.array(v)
        n = a[:, 2].sum()
        rows.append({"name": f"{planner}/{mode}", "near_rad2": round(a[:, 0].sum() / n, 5),
                     "elsewhere_rad2": round(a[:, 1].sum() / n, 5), "kappa_rad": round(a[:, 3].mean(), 4),
                     "planned_kappa_rad": round(a[:, 4].mean(), 4), "runs": len(a)})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--near", type=float, default=0.15, help="distance (m) from a corner that counts as near it")
    ap.add_argument("--set", action="append", default=[], help="profile change section.key=value")
    args = ap.parse_args()
    overrides = key_values(args.set)
    try:
        fidelity.profile_with(overrides)
    except ValueError as exc:
        ap.error(str(exc))
    report("fidelity_corners", measure(seed_list(args.seeds), args.near, overrides), seeds=args.seeds,
           near_m=args.near, overrides=overrides)


if __name__ == "__main__":
    main()
