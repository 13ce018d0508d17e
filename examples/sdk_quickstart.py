"""Submit a job with the SDK, wait for it, print its metrics and save the logged poses.

Start a testbed first (`twb up`, or `twb up --time-scale max` for a fast one),
then run this script from the same directory: the SDK finds the token in
./twb-data/token (or set TWB_URL and TWB_TOKEN).

    python examples/sdk_quickstart.py --planner fm2 --out poses
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from client_sdk import Client, TwbError


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="room", help="environment (room, blocks, or yours)")
    ap.add_argument("--plan", default="A", help="the environment's start/goal pair")
    ap.add_argument("--planner", default="fm2", help="fmm, fm2, prm, astar or a plug-in")
    ap.add_argument("--repetitions", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("poses"), help="directory for the poses CSV files")
    ap.add_argument("--url", default=None, help="testbed URL (default $TWB_URL or http://127.0.0.1:8000)")
    ap.add_argument("--token", default=None, help="token (default $TWB_TOKEN or ./twb-data/token)")
    args = ap.parse_args()

    try:
        with Client(args.url, args.token) as twb:
            plan = twb.get_environment(args.env).plan(args.plan)
            exp = twb.submit(args.env, plan.start, plan.goal, args.planner, repetitions=args.repetitions)
            print(f"submitted experiment {exp.id}")
            exp = twb.wait(exp.id, timeout=600, progress=True)
            print(f"experiment {exp.id}: {exp.status}")
            if exp.status != "completed":
                print(exp.error, file=sys.stderr)
                return 1

            metrics = twb.get_metrics(exp.id)
            print(f"planned path: {metrics.planned['length_m']:.3f} m, κ' {metrics.planned['smoothness_rad']:.3f} rad")
            for mode, agg in metrics.aggregates.items():
                length, dev = agg.metrics["length_m"], agg.metrics["deviation_mean_m"]
                print(f"{mode}: {agg.runs} runs, length {length.mean:.3f} ± {length.std or 0:.3f} m, "
                      f"mean deviation {dev.mean * 1000:.1f} mm")
            for d in metrics.direct:
                print(f"repetition {d.repetition}: field vs simulation, mean deviation "
                      f"{d.metrics['deviation_mean_m'] * 1000:.1f} mm")

            args.out.mkdir(parents=True, exist_ok=True)
            for run in exp.runs:
                poses = twb.get_poses(run.id)                       # (N, 4): t, x, y, theta
                path = args.out / f"run-{run.id}-{run.mode}-{run.repetition}.csv"
                np.savetxt(path, poses, delimiter=",", header="t,x,y,theta", comments="", fmt="%.5f")
                print(f"{path}: {len(poses)} poses")
    except (TwbError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
