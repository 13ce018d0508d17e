"""A fleet live (docs/performance.md, "Many robots live"): 64 field robots on the full field with moving obstacles, at
time scale 1.

One ``twb agent`` process runs ``--robots`` emulated field robots, each with the whole field (3.6 m x
3.6 m) as a world of its own, live (time scale 1), tracking at 30 Hz into CSV files.  This process
connects once to every robot and has the gripper place them all at once in the middle of the field.
The host's CPU (user + system, from /proc) is measured over ``--seconds`` of wall time in three phases
per round, interleaved over ``--rounds`` rounds:

- ``idle``: nothing moves (the baseline: the same host, robots and connections);
- ``paths``: every robot follows a path around a 0.6 m square (``T,T,P``), no moving obstacles;
- ``moving``: the same with ``--obstacles`` moving obstacles per robot (``T,T,M``): discs of 5 cm
  shuttling at 0.2 m/s along tracks across the field, clear of the square, so that every robot meets
  them in every step (collision checks) and drives on.

The live phases run ``--obstacles`` per robot (default 16, the protocol's most, ``MAX_MOVING``: 1,024
in all), and ``step_cost`` times the simulation step of the same fleet in this process with 0, 8 and 16
per robot (set in the world directly), one step per call as the host runs it live, interleaved; with
fewer than 16 live, the live share plus 50 steps/s x the step's extra cost up to 16 (from the ratios to
the step without obstacles) is the estimate for 16 per robot.  Prints JSON: the
host's share of one core per phase (medians), ratios to the baselines (medians over rounds), the step
costs; target: at most 25% of a core with 16 moving obstacles per robot.

    python bench/fleet_live.py [--robots 64] [--obstacles 16] [--seconds 20] [--rounds 3]
"""

from __future__ import annotations

import asyncio
import sys
import tempfile
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from bench._agent_proc import AgentProcess  # noqa: E402
from bench._clients import Counts, Phases, ask_all, close_all, connect_all, cpu_window, live_arguments  # noqa: E402
from bench._common import interleaved, report  # noqa: E402
from contract.params import robot_params  # noqa: E402
from contract.protocol import MAX_MOVING, encode_moving  # noqa: E402

FIELD_M = 3.6  #: the whole field (m), every robot's world
CENTRE_M = (1.8, 1.8)  #: where the gripper puts every robot (m)
SQUARE_M = 0.3  #: half the side of the square the robots drive around (m)
TARGET = 0.25  #: the issue's target: share of one core


def square_path(laps: int = 4) -> list[tuple[float, float, float]]:
    """``laps`` laps around the square about the centre (m, m, rad): a minute of driving at a BeBot's speeds."""
    cx, cy = CENTRE_M
    corners = [(cx + sx * SQUARE_M, cy + sy * SQUARE_M, 0.0) for sx, sy in ((1, -1), (1, 1), (-1, 1), (-1, -1))]
    return corners * laps


def obstacles(count: int) -> list[tuple[tuple[float, float, float, float], list[tuple[float, float]]]]:
    """``count`` moving obstacles as ``encode_moving`` takes them: (radius m, speed m/s, repeat code 2 =
    pingpong, delay s) and two waypoints (m) on a track across the field, horizontal and vertical ones
    alternating, at least 0.8 m from the robots' square."""
    lanes = [0.3, 0.7, FIELD_M - 0.7, FIELD_M - 0.3]
    out = []
    for k in range(count):
        lane = lanes[(k // 2) % len(lanes)]
        ends = [(0.3, lane), (FIELD_M - 0.3, lane)] if k % 2 == 0 else [(lane, 0.3), (lane, FIELD_M - 0.3)]
        out.append(((0.05, 0.2, 2.0, 0.25 * k), ends))
    return out


def step_costs(robots: int, counts: tuple[int, ...], steps: int = 50, runs: int = 9) -> dict[int, dict[str, float]]:
    """The simulation's cost per control step (s) of ``robots`` field robots driving the square, each with
    ``n`` moving obstacles for every ``n`` in ``counts`` (set in the world directly: the protocol stops at
    8), one step per call as at time scale 1, tracker poses logged; interleaved, ``counts[0]`` the baseline."""
    from contract.params import robot_params
    from robot_agent.engine.cores import layout_core
    from robot_agent.engine.noise import path_key
    from robot_agent.engine.sim import SimCore

    p = robot_params()
    path = np.array(square_path(laps=8 + steps * (runs + 1) * len(counts) // 300))
    tasks = {}
    for n in counts:
        core = layout_core(p, "field", robots, "separate", (FIELD_M, FIELD_M))
        discs = [(np.array(par), np.array(ends)) for par, ends in obstacles(n)]
        for i in range(robots):
            core.place(i, (*CENTRE_M, 0.0))
            core.world.set_moving(i, discs)
            core.set_path(i, path, path_key(0, f"robot-{i + 1}", 0))

        def run(core: SimCore = core) -> None:
            for _ in range(steps):
                core.step()
            core.poses.clear()

        tasks[n] = run
    timing = interleaved({str(n): fn for n, fn in tasks.items()}, str(counts[0]), runs)
    return {n: {"step_s": timing[str(n)]["median_s"] / steps, "ratio": timing[str(n)]["ratio"]} for n in counts}


async def _measure(host: AgentProcess, n_obstacles: int, seconds: float, rounds: int) -> Phases:
    """``rounds`` rounds of the three phases (see the module docstring); per phase, each round's window."""
    from contract.protocol import encode_path

    counts = Counts()
    clients = await connect_all(host.ports, counts, (CENTRE_M[0] * 1000, CENTRE_M[1] * 1000, 0.0))
    path = encode_path(square_path())
    with_discs = encode_moving(obstacles(n_obstacles))
    phases = Phases(["idle", "paths", "moving"])
    runs = phases.runs
    try:
        for _ in range(rounds):
            await asyncio.sleep(1.0)  # the robots coast to a stop
            runs["idle"].append(await cpu_window(host, counts, seconds))
            for phase, discs in (("paths", "T,T,M"), ("moving", with_discs)):
                await ask_all(clients, discs, "OK,M")
                await ask_all(clients, path, "OK,P")
                await asyncio.sleep(1.0)  # every robot under way
                runs[phase].append(await cpu_window(host, counts, seconds))
                await ask_all(clients, "T,T,S", "OK,S")
    finally:
        await close_all(clients)
    return phases


def main() -> None:
    ap = live_arguments(__doc__, seconds=20.0)
    ap.add_argument("--obstacles", type=int, default=MAX_MOVING, help=f"per robot, at most {MAX_MOVING}")
    args = ap.parse_args()
    if not 1 <= args.obstacles <= MAX_MOVING:
        ap.error(f"--obstacles must be 1..{MAX_MOVING} (the protocol's moving obstacles per robot)")
    with tempfile.TemporaryDirectory(prefix="twb-fleet-live-") as tmp:
        with AgentProcess(["--robots", str(args.robots), "--backend", "field", "--area", f"{FIELD_M},{FIELD_M}",
                           "--time-scale", "1", "--tracker-csv", str(Path(tmp) / "track-{robot_id}.csv")]) as host:
            phases = asyncio.run(_measure(host, args.obstacles, args.seconds, args.rounds))
    results = phases.rows("idle", robots=args.robots)
    for row in results:
        row["obstacles_per_robot"] = args.obstacles if row["name"] == "moving" else 0
    results[-1]["ratio_to_paths"] = phases.ratio("moving", "paths")
    moving = phases.median("moving")
    over_paths = phases.diff("moving", "paths")
    steps = step_costs(args.robots, tuple(sorted({0, 8, args.obstacles, 16})))
    rate = 1.0 / robot_params().dt  # control steps per wall second at time scale 1
    # from the ratios to the same round's step without obstacles, robust where the medians wander
    extra_16 = max(0.0, steps[16]["ratio"] - steps[args.obstacles]["ratio"]) * steps[0]["step_s"] * rate
    results.append({"name": "step_cost", "robots": args.robots, "per_robot_obstacles": {
        str(n): {"step_s": round(c["step_s"], 7), "ratio": round(c["ratio"], 3),
                 "core_share_at_50_hz": round(c["step_s"] * rate, 4)} for n, c in steps.items()}})
    results.append({"name": "fleet_live", "robots": args.robots, "obstacles_per_robot": args.obstacles,
                    "core_share": round(moving, 4), "over_paths": round(over_paths, 4),
                    "estimate_16_obstacles_per_robot": round(moving + extra_16, 4),
                    "target": TARGET, "met": moving + extra_16 <= TARGET})
    report("fleet_live", results, seconds=args.seconds, rounds=args.rounds, time_scale=1.0, backend="field",
           tracker="csv")


if __name__ == "__main__":
    main()
