"""A multi-robot run played out live by the server (docs/performance.md, "Many robots live"): its CPU while it shows
64 robots at time scale 1.

A fleet run is computed as one task, then played out at the time scale (``server/pipeline/playback.py``):
every 0.1 s the server releases each robot's poses that came due, publishes them as live events and logs
the protocol lines at their time.  This starts ``twb up --time-scale 1`` with one dashboard-like listener
on ``GET /api/v1/events``, submits a ``twb`` job of ``--robots`` robots on the whole field (lanes of
explicit back-and-forth paths, no planner), and measures the server process's CPU (user + system, from
/proc) over ``--seconds`` windows, interleaved over ``--rounds`` rounds:

- ``idle``: the same server and listener, no run (the baseline);
- ``playing``: a window inside the run's playback (the computation itself is before it, in a worker).

Prints JSON: the server's share of one core per phase (medians), the ratio playing / idle (median over
rounds), and the live pose events received per second while playing.

    python bench/fleet_playback.py [--robots 64] [--seconds 5] [--rounds 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import httpx  # noqa: E402

from bench._common import report  # noqa: E402
from contract.vocabulary import TERMINAL  # noqa: E402


def lanes(robots: int) -> list[dict[str, Any]]:
    """``robots`` robots in lanes 0.2 m apart across the whole field, four columns, each driving 0.7 m along +x
    and back three times (explicit paths, m)."""
    out = []
    for k in range(robots):
        col, row = divmod(k, 16)
        x0, y = 0.2 + 0.85 * col, 0.3 + 0.2 * row
        out.append({"start": [x0, y, 0.0], "goal": [x0 + 0.7, y, 0.0],
                    "path": [[x0, y], [x0 + 0.7, y], [x0, y], [x0 + 0.7, y], [x0, y], [x0 + 0.7, y]]})
    return out


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) of process ``pid``, threads included."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def share(pid: int, seconds: float) -> float:
    """The process's share of one core over the next ``seconds`` of wall time."""
    c0, t0 = cpu_s(pid), time.perf_counter()
    time.sleep(seconds)
    return (cpu_s(pid) - c0) / (time.perf_counter() - t0)


class Listener(threading.Thread):
    """``GET /api/v1/events`` read as the dashboard reads it; counts the pose events of multi-robot runs."""

    def __init__(self, url: str, token: str) -> None:
        super().__init__(daemon=True)
        self.url, self.token, self.poses, self.stop = url, token, 0, threading.Event()

    def run(self) -> None:
        try:
            with httpx.Client(base_url=self.url, headers={"Authorization": f"Bearer {self.token}"}, timeout=None) as c:
                with c.stream("GET", "/api/v1/events") as resp:
                    for line in resp.iter_lines():
                        if self.stop.is_set():
                            return
                        if line.startswith("data: ") and '"robot":' in line and '"pose"' in line:
                            self.poses += 1
        except httpx.HTTPError:  # the testbed stopped under it
            return


def playing_window(c: httpx.Client, listener: Listener, pid: int, robots: int, seconds: float) -> dict[str, float]:
    """Submit the lanes job, wait for its run's playback (running, poses arriving), measure one window."""
    job = {"environment": "fleet-bench", "field": "full", "modes": ["twb"], "robots": lanes(robots)}
    url = f"/api/v1/experiments/{c.post('/api/v1/experiments', json=job).raise_for_status().json()['id']}"
    deadline = time.monotonic() + 120
    before = listener.poses
    while listener.poses - before < robots:  # the playback has begun: every robot shown once
        if time.monotonic() > deadline:
            raise RuntimeError(f"the run did not start playing: {c.get(url).text}")
        time.sleep(0.05)
    p0 = listener.poses
    got = share(pid, seconds)
    events = (listener.poses - p0) / seconds
    run = c.get(url).json()["runs"][0]
    if run["status"] not in ("running",):
        raise RuntimeError(f"the window outlasted the playback ({run['status']}): lower --seconds")
    while c.get(url).json()["status"] not in TERMINAL:
        time.sleep(0.2)
    return {"share": got, "events_per_s": events}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    from twb.launch import LocalTestbed

    idle, playing, ratios, events = [], [], [], []
    with tempfile.TemporaryDirectory(prefix="twb-fleet-playback-") as tmp:
        with LocalTestbed(Path(tmp), "--time-scale", "1", "--sim-robots", "1", timeout=180) as tb:
            pid = tb.proc.pid
            with httpx.Client(base_url=tb.url, headers={"Authorization": f"Bearer {tb.token}"}, timeout=60) as c:
                env = {"name": "fleet-bench", "size": [3.6, 3.6], "blocks": []}
                c.post("/api/v1/environments", json=env).raise_for_status()
                listener = Listener(tb.url, tb.token)
                listener.start()
                time.sleep(1.0)
                for _ in range(args.rounds):
                    base = share(pid, args.seconds)
                    w = playing_window(c, listener, pid, args.robots, args.seconds)
                    idle.append(base)
                    playing.append(w["share"])
                    ratios.append(w["share"] / base if base > 0 else float("inf"))
                    events.append(w["events_per_s"])
                listener.stop.set()
    report("fleet_playback", [
        {"phase": "idle", "core_share_median": round(statistics.median(idle), 4), "rounds": [round(v, 4) for v in idle]},
        {"phase": "playing", "core_share_median": round(statistics.median(playing), 4),
         "rounds": [round(v, 4) for v in playing], "ratio_to_idle_median": round(statistics.median(ratios), 2),
         "pose_events_per_s_median": round(statistics.median(events), 1)},
    ], robots=args.robots, seconds=args.seconds, note="server process only; the computation runs before the window")


if __name__ == "__main__":
    main()
