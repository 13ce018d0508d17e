"""The closed loop's cost (issue 16): ``PO`` lines at the tracker's 30 Hz and ``T,T,V`` back, for 64 field robots.

One ``twb agent`` process runs ``--robots`` emulated field robots (a world each, the whole field, time
scale 1, as on the real testbed).  This process connects once to every robot, has the gripper place
them all at once (each placement takes 5 s of experiment time, so they must run side by side: placed
one after the other, 64 robots take 320 s before the first window opens, which is what made the
first version of this benchmark look hung) and subscribes every connection to ``PO`` lines
(``T,T,O,1``) except during ``paths``.  The host's CPU (user + system, from /proc) is measured over
``--seconds`` of wall time in three phases per round, interleaved over ``--rounds`` rounds:

- ``idle``: nothing moves (the baseline the issue names: the same host, robots and connections);
- ``paths``: every robot follows a path around a 0.6 m square (``T,T,P``), unsubscribed (``T,T,O,0``):
  the cost of the moving robots and their tracker without any line on the wire;
- ``closed_loop``: the loop closed: on every ``PO`` line a P-controller sends ``T,T,V`` towards the
  next corner of the square, so velocity commands arrive at the tracker's rate too.

Prints JSON: the host's share of one core per phase (medians), ratios to the baselines (medians over
rounds) and the closed loop's cost over idle (target for 64 robots: at most 10% of a core).

    python bench/closed_loop.py [--robots 64] [--seconds 8] [--rounds 3]
"""

from __future__ import annotations

import argparse
import asyncio
import math
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from bench._agent_proc import AgentProcess  # noqa: E402
from bench._common import report  # noqa: E402

CENTRE_MM = (1800.0, 1800.0)  #: where the gripper puts every robot (mm, its frame: the middle of the field)
SQUARE_MM = 300.0  #: half the side of the square the robots drive around (mm)
SWITCH_MM = 50.0  #: distance at which a robot heads for the next corner (mm)
CORNERS_MM = [(CENTRE_MM[0] + sx * SQUARE_MM, CENTRE_MM[1] + sy * SQUARE_MM)
              for sx, sy in ((1, -1), (1, 1), (-1, 1), (-1, -1))]


def velocity_mm_deg(x: float, y: float, a_deg: float, goal: tuple[float, float]) -> tuple[float, float]:
    """The P-controller of ``tests/test_closed_loop.py``: body velocities (mm/s, deg/s) from the pose
    ``(x, y)`` (mm), heading ``a_deg`` (deg) towards ``goal`` (mm)."""
    dx, dy = goal[0] - x, goal[1] - y
    err = math.remainder(math.atan2(dy, dx) - math.radians(a_deg), math.tau)
    v = min(150.0, 1.5 * math.hypot(dx, dy)) * max(math.cos(err), 0.0)
    return v, math.degrees(max(-2.5, min(2.5, 4.0 * err)))


@dataclass
class Counts:
    """Lines seen by every client together since the last :meth:`reset`."""

    po: int = 0
    v: int = 0
    fails: dict[str, int] = field(default_factory=dict)

    def reset(self) -> None:
        self.po = self.v = 0
        self.fails = {}


class RobotClient:
    """One connection: answers every ``PO`` line with a ``T,T,V`` while :attr:`driving`."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, counts: Counts) -> None:
        self.reader, self.writer, self.counts = reader, writer, counts
        self.replies: asyncio.Queue[str] = asyncio.Queue()
        self.driving = False
        self.corner = 0
        self.task: asyncio.Task | None = None

    async def ask(self, line: str) -> str:
        """Send ``line``; its reply (events and ``OK,V`` are not replies here)."""
        self.writer.write(line.encode() + b"\n")
        return await self.replies.get()

    def _on_pose(self, line: bytes) -> None:
        _, xs, ys, a, _ = line.split(b",")
        x, y = float(xs), float(ys)
        goal = CORNERS_MM[self.corner]
        if math.hypot(goal[0] - x, goal[1] - y) < SWITCH_MM:
            self.corner = (self.corner + 1) % len(CORNERS_MM)
            goal = CORNERS_MM[self.corner]
        v, w = velocity_mm_deg(x, y, float(a), goal)
        self.writer.write(f"T,T,V,{v:.1f},{w:.1f}\n".encode())
        self.counts.v += 1

    async def read_loop(self) -> None:
        """Every line the robot sends, until it closes the connection."""
        while line := await self.reader.readline():
            if line.startswith(b"PO,"):
                self.counts.po += 1
                if self.driving:
                    self._on_pose(line.rstrip())
            elif line.startswith(b"OK,V"):
                pass
            elif line.startswith(b"EV,"):
                if line.startswith(b"EV,FAIL"):
                    why = line.split(b",")[2].decode()
                    self.counts.fails[why] = self.counts.fails.get(why, 0) + 1
            else:
                self.replies.put_nowait(line.decode().rstrip())


async def _connect(ports: list[int], counts: Counts) -> list[RobotClient]:
    """A client per robot, greeted, placed in the middle of the field (all at once) and subscribed."""
    clients = []
    for port in ports:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        c = RobotClient(reader, writer, counts)
        c.task = asyncio.create_task(c.read_loop())
        clients.append(c)
    hellos = await asyncio.gather(*(c.replies.get() for c in clients))
    assert all(h.startswith("HELLO,") for h in hellos), hellos
    placed = await asyncio.gather(*(c.ask(f"T,T,I,{CENTRE_MM[0]:.0f},{CENTRE_MM[1]:.0f},0") for c in clients))
    assert all(r == "OK,I" for r in placed), placed
    subscribed = await asyncio.gather(*(c.ask("T,T,O,1") for c in clients))
    assert all(r == "OK,O" for r in subscribed), subscribed
    return clients


async def _window(host: AgentProcess, counts: Counts, seconds: float) -> dict[str, float]:
    """The host's share of one core and the line rates (per s) over ``seconds`` of wall time from now."""
    counts.reset()
    c0, t0 = host.cpu(), time.monotonic()
    await asyncio.sleep(seconds)
    wall = time.monotonic() - t0
    return {"core_share": (host.cpu() - c0) / wall, "po_lines_per_s": counts.po / wall,
            "v_lines_per_s": counts.v / wall, "fails": dict(counts.fails)}


async def _all(clients: list[RobotClient], line: str, reply: str) -> None:
    """Send ``line`` on every connection and check each reply starts with ``reply``."""
    answers = await asyncio.gather(*(c.ask(line) for c in clients))
    assert all(a.startswith(reply) for a in answers), answers


async def _measure(host: AgentProcess, seconds: float, rounds: int) -> dict[str, list[dict]]:
    """``rounds`` rounds of the three phases (see the module docstring); per phase, each round's window."""
    counts = Counts()
    clients = await _connect(host.ports, counts)
    square = ";".join(f"{x:.0f},{y:.0f},0" for x, y in CORNERS_MM * 3)
    runs: dict[str, list[dict]] = {"idle": [], "paths": [], "closed_loop": []}
    try:
        for _ in range(rounds):
            await asyncio.sleep(1.0)  # the robots coast to a stop
            runs["idle"].append(await _window(host, counts, seconds))
            await _all(clients, "T,T,O,0", "OK,O")
            await _all(clients, f"T,T,P,{square}", "OK,P")
            await asyncio.sleep(1.0)  # every robot under way
            runs["paths"].append(await _window(host, counts, seconds))
            await _all(clients, "T,T,S", "OK,S")
            await _all(clients, "T,T,O,1", "OK,O")
            for c in clients:
                c.driving = True
                c.writer.write(b"T,T,V,0,0\n")  # velocity mode; from now on every PO line gets a T,T,V
            await asyncio.sleep(1.0)
            runs["closed_loop"].append(await _window(host, counts, seconds))
            for c in clients:
                c.driving = False
            await _all(clients, "T,T,S", "OK,S")
    finally:
        for c in clients:
            c.writer.close()
        for c in clients:
            assert c.task is not None
            c.task.cancel()
        await asyncio.gather(*(c.task for c in clients if c.task), return_exceptions=True)
    return runs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=8.0, help="wall seconds per measurement window")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    with AgentProcess(["--robots", str(args.robots), "--backend", "field", "--area", "3.6,3.6",
                       "--time-scale", "1"]) as host:
        runs = asyncio.run(_measure(host, args.seconds, args.rounds))
    share = {name: [r["core_share"] for r in rs] for name, rs in runs.items()}

    def ratio(a: str, b: str) -> float:
        """Median over rounds of phase ``a``'s share over phase ``b``'s (idle near 0 gives a large number)."""
        return round(statistics.median(x / max(y, 1e-3) for x, y in zip(share[a], share[b])), 2)

    results = []
    for name, rs in runs.items():
        row = {"name": name, "robots": args.robots, "host_core_share": round(statistics.median(share[name]), 4),
               "per_round": [round(s, 4) for s in share[name]],
               "po_lines_per_s": round(statistics.median(r["po_lines_per_s"] for r in rs), 1),
               "v_lines_per_s": round(statistics.median(r["v_lines_per_s"] for r in rs), 1)}
        if name != "idle":
            row["ratio_to_idle"] = ratio(name, "idle")
            row["fails"] = [r["fails"] for r in rs]
        results.append(row)
    results[-1]["ratio_to_paths"] = ratio("closed_loop", "paths")
    cost = statistics.median(b - a for a, b in zip(share["idle"], share["closed_loop"]))
    results.append({"name": "closed_loop_cost", "robots": args.robots, "core_share": round(cost, 4),
                    "over_paths": round(statistics.median(b - a for a, b in zip(share["paths"],
                                                                                 share["closed_loop"])), 4),
                    "target": 0.10, "met": cost <= 0.10})
    report("closed_loop", results, seconds=args.seconds, rounds=args.rounds, time_scale=1.0, backend="field")


if __name__ == "__main__":
    main()
