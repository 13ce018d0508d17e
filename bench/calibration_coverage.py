"""Does `twb calibrate`'s interval cover the truth?  Known profiles (each field variant of the noise study),
runs emulated with them (seeded), fitted back; per parameter the share of cases whose reported interval
contains the true value, and the replay error (the fitted profile re-simulated against the runs, cm RMS).

    python bench/calibration_coverage.py --seeds 1-5            # JSON on stdout

A case is one variant and one emulation seed: six runs of about 10 s on three-corner paths
(tests/test_calibration.py's :func:`emulated_runs`), each with its own seed.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from typing import Any

if __package__ in (None, ""):
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np

from contract.overrides import apply_overrides
from contract.robot_profile import load_profile
from robot_agent.engine.calibration import FITTED, RecordedRun, calibrate
from robot_agent.engine.headless import simulate_run

#: the noise study's variants (docs/fidelity.md, "twb study noise") and the shipped robot
VARIANTS: dict[str, dict[str, float]] = {
    "shipped": {},
    "tracker 3 mm": {"tracker_noise_xy_m": 0.003},
    "motor lag 0.4 s": {"motor_time_constant_s": 0.4},
    "wheel slip x4": {"wheel_noise_rel": 0.32, "wheel_noise_abs_m_s": 0.016},
}


def emulated_runs(profile: dict[str, Any], seed: int, n: int = 6) -> list[RecordedRun]:
    """``n`` runs of about 10 s on a sub-field: three-corner paths, each with its own seed (its own track gains)."""
    rng = np.random.default_rng(seed)
    runs = []
    for k in range(n):
        start = np.array([0.3, 0.3 + 0.2 * k])
        corners = [start + [0.5, rng.uniform(-0.2, 0.2)], start + [0.9, rng.uniform(0.2, 0.5)],
                   start + [1.2, rng.uniform(-0.1, 0.3)]]
        path = np.clip(np.array([[*start, 0.0], *[[*p, 0.0] for p in corners]]), 0.15, 1.65)
        path[:, 2] = 0.0
        out = simulate_run(path, (*path[0, :2], 0.0), seed=seed * 100 + k, backend="field", profile=profile,
                           area=(1.8, 1.8))
        if out.outcome != "DONE":
            continue
        poses = out.poses.copy()
        poses[:, 0] -= out.t_start
        runs.append(RecordedRun(path, (*path[0, :2], 0.0), poses[poses[:, 0] >= 0], (), (1.8, 1.8), f"run {k}"))
    return runs


def case(job: tuple[str, int]) -> dict[str, Any]:
    """One variant and seed: the true values, the fitted values and intervals, which intervals cover."""
    variant, seed = job
    truth = apply_overrides(load_profile("bebot"), VARIANTS[variant])
    cal = calibrate(emulated_runs(truth, seed), "bebot", seed=seed)
    true = {k: float(truth["field"][k]) for k in FITTED}
    out: dict[str, Any] = {"variant": variant, "seed": seed, "replay_cm_rms": round(cal.rms_m * 100, 3), "params": {}}
    for k in FITTED:
        lo, hi = cal.interval.get(k, (None, None))
        covered = None if lo is None else bool(lo <= true[k] <= hi)
        out["params"][k] = {"true": true[k], "fitted": cal.values[k], "interval": [lo, hi], "covered": covered}
    return out


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="1-5")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    jobs = [(v, s) for v in VARIANTS for s in _seeds(a.seeds)]
    with ProcessPoolExecutor(a.workers) as ex:
        cases = list(ex.map(case, jobs))
    coverage = {}
    for k in FITTED:
        flags = [c["params"][k]["covered"] for c in cases if c["params"][k]["covered"] is not None]
        coverage[k] = {"covered": sum(flags), "cases": len(flags),
                       "without_interval": sum(c["params"][k]["covered"] is None for c in cases)}
    reported = [c["params"][k]["covered"] for c in cases for k in FITTED if c["params"][k]["covered"] is not None]
    print(json.dumps({"coverage": coverage, "intervals_covering": f"{sum(reported)}/{len(reported)}",
                      "replay_cm_rms": {v: [c["replay_cm_rms"] for c in cases if c["variant"] == v] for v in VARIANTS},
                      "cases": cases}, indent=1))


if __name__ == "__main__":
    main()
