"""Raw-socket clients of many robots for the live benchmarks: one connection per robot, all driven at once.

Every client drains its robot's lines in a task of its own (``PO`` lines go to :meth:`RobotClient.on_pose`,
events are counted, replies queued for :meth:`RobotClient.ask`), so that the agent never waits for a reader.
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import time
from dataclasses import dataclass, field
from typing import Callable

from bench._agent_proc import AgentProcess

__all__ = ["Counts", "Phases", "RobotClient", "ask_all", "close_all", "connect_all", "cpu_window",
           "live_arguments"]


@dataclass
class Counts:
    """Lines seen by every client together since the last :meth:`reset`."""

    po: int = 0  #: ``PO`` lines received
    v: int = 0  #: ``T,T,V`` lines sent
    fails: dict[str, int] = field(default_factory=dict)  #: ``EV,FAIL`` lines by reason

    def reset(self) -> None:
        self.po = self.v = 0
        self.fails = {}


class RobotClient:
    """One connection to one robot; subclasses answer ``PO`` lines in :meth:`on_pose`."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, counts: Counts) -> None:
        self.reader, self.writer, self.counts = reader, writer, counts
        self.replies: asyncio.Queue[str] = asyncio.Queue()
        self.task: asyncio.Task | None = None

    async def ask(self, line: str) -> str:
        """Send ``line``; its reply (``EV`` and ``PO`` lines and ``OK,V`` are not replies here)."""
        self.writer.write(line.encode() + b"\n")
        return await self.replies.get()

    def on_pose(self, line: bytes) -> None:
        """A ``PO`` line (without terminator) arrived; nothing by default."""

    async def read_loop(self) -> None:
        """Every line the robot sends, until it closes the connection."""
        while line := await self.reader.readline():
            if line.startswith(b"PO,"):
                self.counts.po += 1
                self.on_pose(line.rstrip())
            elif line.startswith(b"EV,"):
                if line.startswith(b"EV,FAIL"):
                    why = line.split(b",")[2].decode()
                    self.counts.fails[why] = self.counts.fails.get(why, 0) + 1
            elif not line.startswith(b"OK,V"):
                self.replies.put_nowait(line.decode().rstrip())


async def ask_all(clients: list[RobotClient], line: str, reply: str) -> None:
    """Send ``line`` on every connection at once and check that each reply starts with ``reply``."""
    answers = await asyncio.gather(*(c.ask(line) for c in clients))
    assert all(a.startswith(reply) for a in answers), answers


async def connect_all(ports: list[int], counts: Counts, place_mm: tuple[float, float, float],
                      client: Callable[[asyncio.StreamReader, asyncio.StreamWriter, Counts], RobotClient] = RobotClient,
                      ) -> list[RobotClient]:
    """A client per robot, greeted, and every robot placed at ``place_mm`` (mm, mm, deg) by its gripper.

    The placements run side by side: each takes the gripper's ``seconds_per_placement`` of experiment
    time (5 s on a BeBot), so at time scale 1 one after the other they would take 5 s per robot."""
    clients = []
    for port in ports:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        c = client(reader, writer, counts)
        c.task = asyncio.create_task(c.read_loop())
        clients.append(c)
    hellos = await asyncio.gather(*(c.replies.get() for c in clients))
    assert all(h.startswith("HELLO,") for h in hellos), hellos
    await ask_all(clients, "T,T,I,{:.0f},{:.0f},{:.0f}".format(*place_mm), "OK,I")
    return clients


async def close_all(clients: list[RobotClient]) -> None:
    """Close every connection and end its reader."""
    for c in clients:
        c.writer.close()
    tasks = [c.task for c in clients if c.task is not None]
    for t in tasks:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)


async def cpu_window(host: AgentProcess, counts: Counts, seconds: float) -> dict[str, object]:
    """The host's share of one core and the clients' line rates (per s) over ``seconds`` of wall time from
    now, with the ``EV,FAIL`` lines seen meanwhile."""
    counts.reset()
    c0, t0 = host.cpu(), time.monotonic()
    await asyncio.sleep(seconds)
    wall = time.monotonic() - t0
    return {"core_share": (host.cpu() - c0) / wall, "po_lines_per_s": counts.po / wall,
            "v_lines_per_s": counts.v / wall, "fails": dict(counts.fails)}


class Phases:
    """Each phase's windows (:func:`cpu_window`), measured round by round; summaries over the rounds."""

    def __init__(self, names: list[str]) -> None:
        self.runs: dict[str, list[dict]] = {name: [] for name in names}
        #: the machine's speed, once per round (:func:`bench._common.machine_reference_s`, s)
        self.reference: list[float] = []

    def share(self, name: str) -> list[float]:
        """Phase ``name``'s share of one core, per round."""
        return [r["core_share"] for r in self.runs[name]]

    def median(self, name: str) -> float:
        """Median over rounds of phase ``name``'s share of one core."""
        return statistics.median(self.share(name))

    def ratio(self, a: str, b: str) -> float:
        """Median over rounds of phase ``a``'s share over phase ``b``'s (an idle ``b`` near 0 gives a large
        number: 1e-3 at least)."""
        return round(statistics.median(x / max(y, 1e-3) for x, y in zip(self.share(a), self.share(b))), 2)

    def diff(self, a: str, b: str) -> float:
        """Median over rounds of phase ``a``'s share minus phase ``b``'s."""
        return statistics.median(x - y for x, y in zip(self.share(a), self.share(b)))

    def rows(self, baseline: str, **fields: object) -> list[dict[str, object]]:
        """A JSON row per phase: ``fields``, the share (median and per round), line rates and, but for the
        ``baseline``, the ratio to it and the ``EV,FAIL`` lines seen."""
        out = []
        for name, rs in self.runs.items():
            row = {"name": name, **fields, "host_core_share": round(self.median(name), 4),
                   "per_round": [round(s, 4) for s in self.share(name)],
                   "po_lines_per_s": round(statistics.median(r["po_lines_per_s"] for r in rs), 1),
                   "v_lines_per_s": round(statistics.median(r["v_lines_per_s"] for r in rs), 1)}
            if name != baseline:
                row[f"ratio_to_{baseline}"] = self.ratio(name, baseline)
                row["fails"] = [r["fails"] for r in rs]
            out.append(row)
        return out


def live_arguments(doc: str, seconds: float) -> argparse.ArgumentParser:
    """The options every live benchmark has: ``--robots`` (64), ``--seconds`` per window (wall s), ``--rounds``."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--robots", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=seconds, help="wall seconds per measurement window")
    ap.add_argument("--rounds", type=int, default=3)
    return ap
