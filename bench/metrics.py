"""Metrics benchmark: deviation, clearance and smoothness on 10⁵-point paths.

The planned path P0 is a smooth curve across the 3.6 m field (room/blocks
tiled, 36 blocks); the performed path Pr is P0 shifted by 5 mm with 1 mm
tracker-like noise; both have ``--points`` points (default 10⁵).
Baseline, measured in the same run: a ``cKDTree`` built on Pr and queried
with the points of P0 (the same size), the usual building block of
nearest-point metrics.  Each figure is the median of ``--runs`` (default 5)
interleaved rounds; ``ratio`` = time / baseline.

Metrics timed, as docs/design.md, "Metrics" defines them (``n`` = 200 samples, segments
of 0.05 m) — the targets (<= 0.1 s and <= 5x baseline) apply to these:

- ``deviation``: P0 resampled to 200 points, exact distance to the polyline Pr;
- ``clearance``: Pr's exact minimum clearance over all its segments plus the
  mean over 200 samples;
- ``smoothness``: κ' of Pr.

Stress variants with every point used (reported, no target):
``deviation_all`` (10⁵ samples of P0 against Pr), ``clearance_all``
(10⁵ samples), ``smoothness_all`` (10⁵ - 1 segments).

    python bench/metrics.py [--runs 5] [--points 100000]
"""

from __future__ import annotations

import argparse
import os
import sys

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the planners package
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from bench._common import interleaved, report  # noqa: E402
from bench.planners import full_field  # noqa: E402
from planners.metrics import clearance, deviation, min_clearance, smoothness  # noqa: E402

TARGET_S = 0.1
TARGET_RATIO = 5.0


def paths(points: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """P0: a smooth wave across the field; Pr: P0 + 5 mm offset + 1 mm noise (m)."""
    s = np.linspace(0.0, 1.0, points)
    planned = np.c_[0.2 + 3.2 * s, 1.8 + 1.4 * np.sin(4 * np.pi * s)]
    rng = np.random.default_rng(seed)
    performed = planned + [0.0, 0.005] + rng.normal(scale=0.001, size=planned.shape)
    return planned, performed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--points", type=int, default=100_000)
    args = ap.parse_args()
    env = full_field()
    p0, pr = paths(args.points)
    n_all = args.points
    tasks = {
        "baseline": lambda: cKDTree(pr).query(p0),
        "deviation": lambda: deviation(p0, pr),
        "clearance": lambda: (min_clearance(env, pr), clearance(env, pr).mean()),
        "smoothness": lambda: smoothness(pr),
        "deviation_all": lambda: deviation(p0, pr, n=n_all),
        "clearance_all": lambda: (min_clearance(env, pr), clearance(env, pr, n=n_all).mean()),
        "smoothness_all": lambda: smoothness(pr, segments=n_all - 1),
    }
    timed = interleaved(tasks, "baseline", args.runs)
    results = [{"task": name, **val} for name, val in timed.items()]
    checks = {}
    for name in ("deviation", "clearance", "smoothness"):
        checks[f"{name} <= {TARGET_S} s"] = timed[name]["median_s"] <= TARGET_S
        checks[f"{name} <= {TARGET_RATIO}x baseline"] = timed[name]["ratio"] <= TARGET_RATIO
    report("metrics", results, points=args.points, runs=args.runs, blocks=len(env.blocks),
           baseline="cKDTree(performed).query(planned)", targets_met=checks)


if __name__ == "__main__":
    main()
