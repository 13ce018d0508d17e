"""Agent benchmark: simulation core steps per second, and the CPU share of a live agent.

Core figures: :meth:`SimCore.advance` (the compiled loop, as the host runs
it when ahead of schedule) for 1 ideal, 1 field, 64 field and 1000 ideal
robots, every robot following a long path in its own copy of the ``room``
environment (9 blocks), collisions checked, tracker poses logged.  Each
figure is the median of ``--runs`` (default 5) timings of about
``--robot-steps`` robot-steps (default 20000: 20000 steps of 1 robot, 312 of
64, 50 of 1000), interleaved with the same-run baseline: one numpy
unicycle integration step (the midpoint rule the robots use) on arrays of
the same size.  ``ratio`` = step time / baseline time; ``realtime_factor`` =
experiment seconds simulated per wall second at the 50 Hz control rate.
``step_call_s`` is the time of one :meth:`SimCore.step` call (one step per
call, as at time scale 1), which is dominated by the call into compiled code.

Live figure: the CPU share (process CPU time / wall time) of one agent
serving 64 field robots at time scale 1 over TCP, tracking at 30 Hz into CSV
files, for ``--live-seconds`` (default 5).

    python bench/sim.py [--runs 5] [--robot-steps 20000] [--live-seconds 5]
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
from contract.params import robot_params  # noqa: E402
from contract.protocol import encode_path  # noqa: E402
from planners import load_environment  # noqa: E402
from robot_agent.engine.cores import layout_core  # noqa: E402
from robot_agent.engine.noise import path_key  # noqa: E402
from robot_agent.engine.sim import SimCore, State  # noqa: E402
from robot_agent.host import AgentHost  # noqa: E402
from robot_agent.host.sinks import CsvTrackerSink  # noqa: E402

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


def numpy_unicycle_step(pose: np.ndarray, vw: np.ndarray, dt: float) -> None:
    """The baseline: the robots' midpoint-rule pose update, numpy on ``(N, 3)`` poses, in place."""
    mid = pose[:, 2] + 0.5 * dt * vw[:, 1]
    pose[:, 0] += vw[:, 0] * dt * np.cos(mid)
    pose[:, 1] += vw[:, 0] * dt * np.sin(mid)
    pose[:, 2] = (pose[:, 2] + vw[:, 1] * dt + np.pi) % (2 * np.pi) - np.pi


def busy_core(n: int, backend: str, steps: int = 0) -> SimCore:
    """``n`` robots each in its own room, all following a loop long enough for ``steps`` steps."""
    params = robot_params("bebot")
    core = layout_core(params, backend, n)
    path = loop_path(max(50, steps // 300))  # one loop takes about 450 steps
    blocks = room_blocks()
    for i in range(n):
        core.world.set_blocks(i, blocks)
        core.place(i, tuple(path[0]))
        core.set_path(i, path, path_key(i))
    return core


def core_figures(runs: int, robot_steps: int) -> list[dict]:
    results = []
    for n, backend in CONFIGS:
        steps = max(50, robot_steps // n)
        core = busy_core(n, backend, steps * (runs + 2) + 100)
        pose = np.random.default_rng(0).random((n, 3))
        vw = np.full((n, 2), 0.1)

        def sim() -> None:
            core.advance(steps)

        def baseline() -> None:
            for _ in range(steps):
                numpy_unicycle_step(pose, vw, 0.02)

        s0 = core.step_count
        timed = interleaved({"baseline": baseline, "step": sim}, "baseline", runs)
        assert core.step_count - s0 == steps * (runs + 1), "robots stopped during the timing"
        moving = int((core.state == State.MOVING).sum())
        calls = interleaved({"step": core.step}, "step", runs)["step"]["median_s"]
        step_s = timed["step"]["median_s"] / steps
        results.append({
            "robots": n,
            "backend": backend,
            "steps_per_run": steps,
            "still_moving": moving,
            "step_s": step_s,
            "steps_per_s": 1.0 / step_s,
            "realtime_factor": core.dt / step_s,
            "step_call_s": calls,
            "baseline_numpy_unicycle_step_s": timed["baseline"]["median_s"] / steps,
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
    ap.add_argument("--robot-steps", type=int, default=20000)
    ap.add_argument("--live-seconds", type=float, default=5.0)
    args = ap.parse_args()
    results = core_figures(args.runs, args.robot_steps)
    live = asyncio.run(live_cpu_share(args.live_seconds)) if args.live_seconds > 0 else None
    checks = {}
    for label, (n, backend, target) in TARGETS.items():
        row = next(r for r in results if r["robots"] == n and r["backend"] == backend)
        checks[label] = row["realtime_factor"] >= target
    if live is not None:
        checks[f"64 field robots live: cpu share <= {CPU_TARGET}"] = live["cpu_share_of_one_core"] <= CPU_TARGET
    report("agent", results, control_rate_hz=robot_params("bebot").controller.control_rate_hz, runs=args.runs,
           robot_steps_per_run=args.robot_steps, environment="room (9 blocks) per robot", live=live, targets_met=checks)


if __name__ == "__main__":
    main()
