"""The closed loop's cost (docs/performance.md, "Many robots live"): ``PO`` lines at the tracker's 30 Hz and ``T,T,V``
back, for 64 field robots.

One ``twb agent`` process runs ``--robots`` emulated field robots (a world each, the whole field, time
scale 1, as on the real testbed).  This process connects once to every robot, has the gripper place
them all at once (each placement takes 5 s of experiment time, so they must run side by side: placed
one after the other, 64 robots take 320 s before the first window opens, which is what made the
first version of this benchmark look hung).  The host's CPU (user + system, from /proc) is measured over
``--seconds`` of wall time in three phases per round, interleaved over ``--rounds`` rounds:

- ``idle``: nothing moves (the baseline the issue names: the same host, robots and connections);
- ``paths``: every robot follows a path around a 0.6 m square (``T,T,P``), no connection subscribed to
  ``PO`` lines: the cost of the moving robots and their tracker, with hardly a line on the wire;
- ``closed_loop``: every connection subscribed (``T,T,O,1``) and the loop closed: on every ``PO`` line a
  P-controller sends ``T,T,V`` towards the next corner of the square, so velocity commands arrive at
  the tracker's rate too.

Prints JSON: the host's share of one core per phase (medians), ratios to the baselines (medians over
rounds), the closed loop's cost over idle (target for 64 robots: at most 10% of a core) and the machine's
speed (``machine_reference``: the CPU seconds of a fixed workload, measured in every round while nothing moves;
the cost divided by it, ``reference_workloads_per_s``, compares between days and machines).

    python bench/closed_loop.py [--robots 64] [--seconds 8] [--rounds 3] [--clock lockstep|free]

``--clock``: the agent's clock for the subscribed connections (``twb agent --clock``; lockstep, the default since
issue 32, holds each robot's clock until its controller answered every pose).
"""

from __future__ import annotations

import asyncio
import math
import statistics
import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from bench._agent_proc import AgentProcess  # noqa: E402
from bench._clients import (  # noqa: E402
    Counts, Phases, RobotClient, ask_all, close_all, connect_all, cpu_window, live_arguments)
from bench._common import machine_reference_s, report  # noqa: E402

CENTRE_MM = (1800.0, 1800.0)  #: where the gripper puts every robot (mm, its frame: the middle of the field)
SQUARE_MM = 300.0  #: half the side of the square the robots drive around (mm)
SWITCH_MM = 50.0  #: distance at which a robot heads for the next corner (mm)
TARGET = 0.10  #: the issue's target: share of one core
CORNERS_MM = [(CENTRE_MM[0] + sx * SQUARE_MM, CENTRE_MM[1] + sy * SQUARE_MM)
              for sx, sy in ((1, -1), (1, 1), (-1, 1), (-1, -1))]


def velocity_mm_deg(x: float, y: float, a_deg: float, goal: tuple[float, float]) -> tuple[float, float]:
    """The P-controller of ``tests/test_closed_loop.py``: body velocities (mm/s, deg/s) from the pose
    ``(x, y)`` (mm), heading ``a_deg`` (deg) towards ``goal`` (mm)."""
    dx, dy = goal[0] - x, goal[1] - y
    err = math.remainder(math.atan2(dy, dx) - math.radians(a_deg), math.tau)
    v = min(150.0, 1.5 * math.hypot(dx, dy)) * max(math.cos(err), 0.0)
    return v, math.degrees(max(-2.5, min(2.5, 4.0 * err)))


class Steering(RobotClient):
    """Answers every ``PO`` line with a ``T,T,V`` towards the next corner of the square while :attr:`driving`."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, counts: Counts) -> None:
        super().__init__(reader, writer, counts)
        self.driving = False
        self.corner = 0

    def on_pose(self, line: bytes) -> None:
        if not self.driving:
            return
        _, xs, ys, a, _ = line.split(b",")
        x, y = float(xs), float(ys)
        goal = CORNERS_MM[self.corner]
        if math.hypot(goal[0] - x, goal[1] - y) < SWITCH_MM:
            self.corner = (self.corner + 1) % len(CORNERS_MM)
            goal = CORNERS_MM[self.corner]
        v, w = velocity_mm_deg(x, y, float(a), goal)
        self.writer.write(f"T,T,V,{v:.1f},{w:.1f}\n".encode())
        self.counts.v += 1


async def _measure(host: AgentProcess, seconds: float, rounds: int) -> Phases:
    """``rounds`` rounds of the three phases (see the module docstring); per phase, each round's window."""
    counts = Counts()
    clients = await connect_all(host.ports, counts, (*CENTRE_MM, 0.0), Steering)
    steering = [c for c in clients if isinstance(c, Steering)]
    square = ";".join(f"{x:.0f},{y:.0f},0" for x, y in CORNERS_MM * 3)
    phases = Phases(["idle", "paths", "closed_loop"])
    runs = phases.runs
    reference = phases.reference
    try:
        for _ in range(rounds):
            await asyncio.sleep(1.0)  # the robots coast to a stop
            runs["idle"].append(await cpu_window(host, counts, seconds))
            reference.append(machine_reference_s())  # nothing moves meanwhile
            await ask_all(clients, f"T,T,P,{square}", "OK,P")
            await asyncio.sleep(1.0)  # every robot under way
            runs["paths"].append(await cpu_window(host, counts, seconds))
            await ask_all(clients, "T,T,S", "OK,S")
            await ask_all(clients, "T,T,O,1", "OK,O")
            for c in steering:
                c.driving = True
                c.writer.write(b"T,T,V,0,0\n")  # velocity mode; from now on every PO line gets a T,T,V
            await asyncio.sleep(1.0)
            runs["closed_loop"].append(await cpu_window(host, counts, seconds))
            for c in steering:
                c.driving = False
            await ask_all(clients, "T,T,S", "OK,S")
            await ask_all(clients, "T,T,O,0", "OK,O")
    finally:
        await close_all(clients)
    return phases


def main() -> None:
    ap = live_arguments(__doc__, seconds=8.0)
    ap.add_argument("--clock", choices=("lockstep", "free"), default="lockstep")
    args = ap.parse_args()
    with AgentProcess(["--robots", str(args.robots), "--backend", "field", "--area", "3.6,3.6",
                       "--time-scale", "1", "--clock", args.clock]) as host:
        phases = asyncio.run(_measure(host, args.seconds, args.rounds))
    results = phases.rows("idle", robots=args.robots)
    results[-1]["ratio_to_paths"] = phases.ratio("closed_loop", "paths")
    cost = phases.diff("closed_loop", "idle")
    ref = statistics.median(phases.reference)
    results.append({"name": "machine_reference", "cpu_s": round(ref, 4),
                    "per_round": [round(r, 4) for r in phases.reference]})
    results.append({"name": "closed_loop_cost", "robots": args.robots, "core_share": round(cost, 4),
                    "over_paths": round(phases.diff("closed_loop", "paths"), 4), "target": TARGET,
                    "met": cost <= TARGET, "reference_workloads_per_s": round(cost / ref, 3)})
    report("closed_loop", results, seconds=args.seconds, rounds=args.rounds, time_scale=1.0, backend="field",
           clock=args.clock)


if __name__ == "__main__":
    main()
