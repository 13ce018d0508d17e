"""Export benchmark: a 60 s run written as MCAP (Foxglove's schemas) and as a zipped ROS 2 bag.

The run: 60 s of poses at the robot's 50 Hz control rate (3,000 poses, the
simulation's ground truth; a field run's 30 Hz tracker gives fewer) along a
smooth curve through ``crossing`` (9 blocks), its two moving discs' exact
tracks every 0.05 s (``robot_agent.engine.run_data.exact_obstacle_tracks``,
as ``GET /runs/{id}/obstacles`` serves them: 2 x 1,200 poses), a 200-line
protocol log, a 120-point plan and the metrics.  The conversion alone is
timed (:func:`server.export.convert.write_export` into memory): loading from the
database and sending are not.

Baseline, measured in the same run: ``json.dumps`` of the same poses as the
poses endpoint's body (``{"poses": [[t, x, y, theta], ...]}``), the cheapest
way to ship them at all.  Each figure is the median of ``--runs`` (default 5)
interleaved rounds after a warm-up; ``ratio`` = time / baseline.  ``cold_s``
is the first MCAP export of the process (its imports included), what a
server's first export costs.  Target: the MCAP export < 0.5 s.

    python bench/export.py [--runs 5] [--seconds 60]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
from importlib import resources

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the planners package
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

from bench._common import interleaved, report, time_once  # noqa: E402
from robot_agent.engine.run_data import exact_obstacle_tracks  # noqa: E402
from server.export import ExportFormat, LogLine, ObstacleTrack, RobotTrack, RunRecord  # noqa: E402
from server.export.convert import write_export  # noqa: E402

TARGET_S = 0.5
RATE_HZ = 50.0


def run_record(seconds: float = 60.0) -> RunRecord:
    """The benchmark's run: ``seconds`` of poses at 50 Hz in ``crossing``, its discs, log, plan and metrics."""
    env = json.loads(resources.files("planners").joinpath("data", "crossing.json").read_text("utf-8"))
    t0 = 12.5
    t = t0 + np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    s = (t - t0) / seconds
    x, y = 0.3 + 1.2 * s, 0.3 + 1.2 * s ** 2 + 0.05 * np.sin(12 * np.pi * s)
    theta = np.arctan2(np.gradient(y), np.gradient(x))
    poses = np.column_stack([t, x, y, theta])
    plan = poses[:: len(poses) // 120, 1:4]
    tracks = exact_obstacle_tracks(env, t0, float(t[-1]), t0, 0.05)
    obstacles = tuple(ObstacleTrack(k, 0.04, np.asarray(tr)) for k, tr in enumerate(tracks))
    log = tuple(LogLine(t0 + k * seconds / 200, "<" if k % 2 else ">", f"EV,WP,{k}" if k % 2 else f"T,T,Q,{k}")
                for k in range(200))
    blocks = np.asarray([[b["x"], b["y"], b["w"], b["h"], b.get("angle", 0.0)] for b in env["blocks"]])
    return RunRecord(run_id=1, experiment_id=1, mode="sim", repetition=1, status="completed", environment="crossing",
                     size=(1.8, 1.8), blocks=blocks, robot_radius=0.045, robots=(RobotTrack(0, poses, plan),),
                     t_start=t0, t_end=float(t[-1]), obstacles=obstacles, log=log,
                     metrics={"length_m": 2.2, "execution_time_s": seconds, "goal_reached": True,
                              "planned": {"length_m": 2.1}})


def export_bytes(record: RunRecord, fmt: ExportFormat) -> int:
    buf = io.BytesIO()
    write_export([record], fmt, buf, name="run-1")
    return buf.tell()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=60.0)
    args = ap.parse_args()
    record = run_record(args.seconds)
    poses = record.robots[0].poses
    cold = time_once(lambda: export_bytes(record, ExportFormat.MCAP))
    tasks = {
        "baseline": lambda: json.dumps({"poses": poses.tolist()}),
        "mcap": lambda: export_bytes(record, ExportFormat.MCAP),
        "rosbag2": lambda: export_bytes(record, ExportFormat.ROSBAG2),
    }
    timed = interleaved(tasks, "baseline", args.runs)
    sizes = {"mcap": export_bytes(record, ExportFormat.MCAP), "rosbag2": export_bytes(record, ExportFormat.ROSBAG2)}
    results = [{"task": name, **val, **({"bytes": sizes[name]} if name in sizes else {})}
               for name, val in timed.items()]
    report("export", results, seconds=args.seconds, poses=len(poses),
           obstacle_poses=sum(len(o.poses) for o in record.obstacles), log_lines=len(record.log), runs=args.runs,
           cold_s=cold, load_avg_1m=os.getloadavg()[0], cpus=os.cpu_count(), baseline='json.dumps({"poses": poses.tolist()})',
           targets_met={f"mcap < {TARGET_S} s": timed["mcap"]["median_s"] < TARGET_S,
                        f"mcap cold (imports included) < {TARGET_S} s": cold < TARGET_S})


if __name__ == "__main__":
    main()
