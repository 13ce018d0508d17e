"""The localisation stream of closed-loop programs: what `PO` lines at the tracker's 30 Hz cost an agent host.

An agent host process runs ``--robots`` emulated field robots (a world each, the whole field, time
scale 1, as on the real testbed); this process connects once to every robot, places it and sends it a
long zig-zag path, and drains every line the robots send.  The host's CPU (user + system, from
/proc) is measured over ``--seconds`` of driving twice per round: with every connection subscribed to
`PO` lines (`T,T,O,1`) and without (the baseline: the same robots driving, tracked, unsubscribed),
interleaved over ``--rounds`` rounds.  Prints JSON: the host's share of one core in each case (median)
and the difference, the cost of the stream (target for 64 robots: at most 10% of a core).

    python bench/closed_loop.py [--robots 64] [--seconds 8] [--rounds 2]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = str(ROOT)

from bench._common import report  # noqa: E402

#: a path across the field and back, long enough to drive for the whole window at 0.2 m/s (m)
ZIGZAG = [(0.3 + 3.0 * (k % 2), 0.3 + 0.15 * k, 0.0) for k in range(20)]

_HOST = """
import asyncio, sys
from robot_agent.host import AgentHost

async def main():
    host = AgentHost(robots=int(sys.argv[1]), backend="field", world="separate", area=(3.6, 3.6),
                     time_scale=1.0, port=0, max_connections=1024, max_connections_per_peer=1024,
                     max_probation_connections=1024)
    await host.start()
    print("ports", " ".join(str(p) for p in host.ports), flush=True)
    await asyncio.Event().wait()

asyncio.run(main())
"""


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def _drive(ports: list[int], subscribe: bool, seconds: float, pid: int) -> dict[str, float]:
    """Every robot placed and driving (and subscribed when ``subscribe``); the host's CPU share over the window."""
    from robot_agent.protocol import encode_path, encode_place

    conns = [await asyncio.open_connection("127.0.0.1", p) for p in ports]
    po = 0

    async def drain(reader: asyncio.StreamReader) -> None:
        nonlocal po
        while line := await reader.readline():
            po += line.startswith(b"PO,")

    for reader, writer in conns:
        await reader.readline()  # HELLO
        writer.write((encode_place(ZIGZAG[0]) + "\n").encode())
        await reader.readline()  # OK,I
        if subscribe:
            writer.write(b"T,T,O,1\n")
            await reader.readline()
        writer.write((encode_path(ZIGZAG) + "\n").encode())
    tasks = [asyncio.create_task(drain(r)) for r, _ in conns]
    await asyncio.sleep(1.0)  # every robot under way
    po0, c0, t0 = po, _cpu_s(pid), time.monotonic()
    await asyncio.sleep(seconds)
    share = (_cpu_s(pid) - c0) / (time.monotonic() - t0)
    lines_per_s = (po - po0) / (time.monotonic() - t0)
    for _, w in conns:
        w.write(b"T,T,S\n")
        w.close()
    for t in tasks:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    return {"core_share": share, "po_lines_per_s": lines_per_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    host = subprocess.Popen([sys.executable, "-c", _HOST, str(args.robots)], stdout=subprocess.PIPE, text=True,
                            cwd=ROOT)
    try:
        line = host.stdout.readline()
        ports = [int(p) for p in re.findall(r"\d+", line)]
        if len(ports) != args.robots:
            raise SystemExit(f"the agent host did not start: {line!r}")
        runs: dict[str, list[dict[str, float]]] = {"unsubscribed": [], "subscribed": []}
        for _ in range(args.rounds):
            for name in runs:
                runs[name].append(asyncio.run(_drive(ports, name == "subscribed", args.seconds, host.pid)))
    finally:
        host.kill()
        host.wait()
    base = statistics.median(r["core_share"] for r in runs["unsubscribed"])
    sub = statistics.median(r["core_share"] for r in runs["subscribed"])
    results = [{"name": name, "robots": args.robots,
                "host_core_share": round(statistics.median(r["core_share"] for r in rs), 4),
                "po_lines_per_s": round(statistics.median(r["po_lines_per_s"] for r in rs), 1)}
               for name, rs in runs.items()]
    results.append({"name": "po_stream_cost", "robots": args.robots, "core_share": round(sub - base, 4),
                    "target": 0.10, "met": sub - base <= 0.10})
    report("closed_loop", results, seconds=args.seconds, rounds=args.rounds)


if __name__ == "__main__":
    main()
