"""Agent benchmark: simulation core steps per second, and the CPU share of a live agent.

Core figures: :meth:`SimCore.step` for 1 ideal, 1 field, 64 field and 1000
ideal robots, every robot following a long path in its own copy of the
``room`` environment (9 blocks), collisions checked.  Each figure is the
median of ``--runs`` (default 5) timings of ``--steps`` steps, interleaved
with the same-run baseline: one vectorised unicycle integration step
(:func:`robot_agent.kinematics.unicycle_step`) on arrays of the same size.
``ratio`` = step time / baseline time; ``realtime_factor`` = experiment
seconds simulated per wall second at the 50 Hz control rate.

Live figure: the CPU share (process CPU time / wall time) of one agent
serving 64 field robots at time scale 1 over TCP, tracking at 30 Hz into CSV
files, for ``--live-seconds`` (default 5).

    python bench/sim.py [--runs 5] [--steps 200] [--live-seconds 5]
"""

from __future__ import annotations

import argparse
import asyncio
import math
import os
import sys
import tempfile
import time

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

from bench._common import interleaved, report  # noqa: E402
from planners import load_environment  # noqa: E402
from robot_agent.backends import make_backend  # noqa: E402
from robot_agent.host import AgentHost  # noqa: E402
from robot_agent.kinematics import unicycle_step  # noqa: E402
from robot_agent.noise import path_key  # noqa: E402
from robot_agent.params import robot_params  # noqa: E402
from robot_agent.protocol import encode_path  # noqa: E402
from robot_agent.sim import SimCore, State  # noqa: E402
from robot_agent.sinks import CsvTrackerSink  # noqa: E402
from robot_agent.world import World, field_layout  # noqa: E402

CONFIGS = [(1, "ideal"), (1, "field"), (64, "field"), (1000, "ideal")]
TARGETS = {"1 robot realtime_factor >= 5000": (1, "ideal", 5000.0), "1000 robots realtime_factor >= 20": (1000, "ideal", 20.0)}
CPU_TARGET = 0.25

# A loop through the room environment's doorways (robot frame, m); repeated to stay busy.
LOOP = [(0.3, 0.3), (0.75, 0.3), (0.75, 0.75), (0.3, 0.75), (0.3, 0.3)]


def loop_path(repeats: int, spacing: float = 0.1) -> np.ndarray:
    """The room loop ``repeats`` times, points every ``spacing`` m, headings along the way."""
    pts = []
    for (ax, ay), (bx, by) in zip(LOOP[:-1], LOOP[1:]):
        n = math.ceil(math.hypot(bx - ax, by - ay) / spacing)
        pts += [(ax + (bx - ax) * j / n, ay + (by - ay) * j / n, math.atan2(by - ay, bx - ax)) for j in range(n)]
    return np.array(pts * repeats + [(*LOOP[-1], 0.0)])


def room_blocks() -> np.ndarray:
    env = load_environment("room")
    return np.array([(b.x, b.y, b.w, b.h, b.angle) for b in env.blocks])


def busy_core(n: int, backend: str) -> SimCore:
    """``n`` robots each in its own room, all following a long loop."""
    params = robot_params("bebot")
    sizes, world_of, origin, area = field_layout(n, "separate")
    core = SimCore(params, make_backend(backend, n, params), World(sizes, world_of, origin, area,
                                                                 params.collision_radius_m))
    path = loop_path(50)
    blocks = room_blocks()
    for i in range(n):
        core.world.set_blocks(i, blocks)
        core.place(i, tuple(path[0]))
        core.set_path(i, path, path_key(i))
    return core


def core_figures(runs: int, steps: int) -> list[dict]:
    results = []
    for n, backend in CONFIGS:
        core = busy_core(n, backend)
        pose = np.random.default_rng(0).random((n, 3))
        vw = np.full((n, 2), 0.1)

        def sim() -> None:
            for _ in range(steps):
                core.step()

        def baseline() -> None:
            for _ in range(steps):
                unicycle_step(pose, vw, 0.02, out=pose)

        timed = interleaved({"baseline": baseline, "step": sim}, "baseline", runs)
        moving = int((core.state == State.MOVING).sum())
        step_s = timed["step"]["median_s"] / steps
        results.append({
            "robots": n,
            "backend": backend,
            "still_moving": moving,
            "step_s": step_s,
            "steps_per_s": 1.0 / step_s,
            "realtime_factor": core.dt / step_s,
            "baseline_unicycle_step_s": timed["baseline"]["median_s"] / steps,
            "ratio": timed["step"]["ratio"],
        })
    return results


async def live_cpu_share(seconds: float) -> dict:
    """CPU share of one process serving 64 field robots live (time scale 1) with CSV tracking."""
    with tempfile.TemporaryDirectory() as tmp:
        sink = CsvTrackerSink(os.path.join(tmp, "poses.csv"), many=True)
        async with AgentHost(robots=64, backend="field", time_scale=1.0, tracker_sink=sink) as agents:
            blocks = room_blocks()
            for i in range(64):
                agents.world.set_blocks(i, blocks)
                agents.core.place(i, (0.3, 0.3, 0.0))
            line = (encode_path(loop_path(20)) + "\n").encode()
            conns = [await asyncio.open_connection("127.0.0.1", p) for p in agents.ports]
            for reader, writer in conns:
                await reader.readline()
                writer.write(line)

            async def drain(reader: asyncio.StreamReader) -> None:
                while await reader.readline():
                    pass

            readers = [asyncio.create_task(drain(r)) for r, _ in conns]
            await asyncio.sleep(0.5)  # everybody started
            w0, c0 = time.perf_counter(), time.process_time()
            await asyncio.sleep(seconds)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            moving = int((agents.core.state == State.MOVING).sum())
            for _, writer in conns:
                writer.close()
            for t in readers:
                t.cancel()
            await asyncio.gather(*readers, return_exceptions=True)
    return {"robots": 64, "backend": "field", "time_scale": 1.0, "tracking_hz": 30, "sink": "csv",
            "wall_s": wall, "cpu_s": cpu, "cpu_share_of_one_core": cpu / wall, "still_moving": moving}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--live-seconds", type=float, default=5.0)
    args = ap.parse_args()
    results = core_figures(args.runs, args.steps)
    live = asyncio.run(live_cpu_share(args.live_seconds)) if args.live_seconds > 0 else None
    checks = {}
    for label, (n, backend, target) in TARGETS.items():
        row = next(r for r in results if r["robots"] == n and r["backend"] == backend)
        checks[label] = row["realtime_factor"] >= target
    if live is not None:
        checks[f"64 field robots live: cpu share <= {CPU_TARGET}"] = live["cpu_share_of_one_core"] <= CPU_TARGET
    report("agent", results, control_rate_hz=robot_params("bebot").controller.control_rate_hz, runs=args.runs,
           steps_per_run=args.steps, environment="room (9 blocks) per robot", live=live, targets_met=checks)


if __name__ == "__main__":
    main()
