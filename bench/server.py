"""Server benchmark: tracker ingestion, REST latency under load, experiments per minute.

1. Tracker ingestion over HTTP into SQLite (poses/s): batches of 1000 poses
   posted by 4 concurrent clients into a run in progress, against a same-run
   baseline: raw ``sqlite3`` ``executemany`` of the same rows into a table of
   the same schema (WAL, one transaction per batch, as the server does).
   Targets: >= 50,000 poses/s and >= 0.3x the baseline.  The same into
   PostgreSQL (``twb up --database-url``, a server started from the machine's
   binaries as the tests do) against psycopg's own ``COPY`` of the same rows
   (target >= 0.3x).
2. REST ``GET /api/v1/experiments/{id}`` latency with 32 concurrent clients while one
   experiment is submitted per second: p50 / p99 (target p99 <= 50 ms).
3. Experiments per minute end to end (sim + twb run each) at maximum time scale.
4. A big queue: ``POST /api/v1/experiments`` and ``GET /health`` latency (p50 / p99) with
   5,000 runs queued, against the same requests on the empty queue of the same testbed
   (targets: POST p99 <= 100 ms, /health p99 <= 50 ms), and one cancel of all of them.

Each part starts its own ``twb up`` on a free port with a temporary data dir.
Prints JSON.

    python bench/server.py [--batches 200] [--requests 50] [--experiments 20]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import httpx  # noqa: E402
import numpy as np  # noqa: E402

from bench._common import postgres, report  # noqa: E402
from contract.vocabulary import TERMINAL  # noqa: E402
from twb.launch import LocalTestbed  # noqa: E402

TOKEN = "bench-token"
SLOW_ENV = {"name": "bench-open", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.1, "h": 0.1}]}


class Testbed(LocalTestbed):
    """`twb up` in a subprocess with the benchmark's token."""

    def __init__(self, data_dir: Path, *args: str) -> None:
        super().__init__(data_dir, *args, token=TOKEN)

    def client(self) -> httpx.Client:
        return httpx.Client(base_url=self.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=60)


def wait_status(c: httpx.Client, eid: int, wanted: set[str], timeout: float = 120) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        e = c.get(f"/api/v1/experiments/{eid}").json()
        if e["status"] in wanted:
            return e
        time.sleep(0.05)
    raise RuntimeError(f"experiment {eid} stuck in {e['status']}")


def rows(n: int, t0: float = 1e6) -> list[list[float]]:
    rng = np.random.default_rng(0)
    a = np.column_stack([t0 + np.arange(n) / 30.0, rng.random((n, 3))])
    return a.tolist()


class RawSqlite:
    """The baseline: raw ``executemany`` into a table of the poses schema (WAL, a transaction per batch)."""

    def __init__(self, path: Path) -> None:
        self.con = sqlite3.connect(path)
        self.con.execute("PRAGMA journal_mode=WAL")
        self.con.execute("PRAGMA synchronous=NORMAL")
        self.con.execute("CREATE TABLE poses (id INTEGER PRIMARY KEY, run_id INTEGER, t REAL, x REAL, y REAL, "
                         "theta REAL)")
        self.con.execute("CREATE INDEX ix_poses_run_t ON poses (run_id, t)")

    def insert(self, batches: list[list[list[float]]]) -> float:
        """Seconds to store ``batches``."""
        t0 = time.perf_counter()
        for b in batches:
            with self.con:
                self.con.executemany("INSERT INTO poses (run_id, t, x, y, theta) VALUES (1, ?, ?, ?, ?)", b)
        return time.perf_counter() - t0


class RawCopy:
    """The PostgreSQL baseline: psycopg's own ``COPY ... FROM STDIN`` (``write_row`` per row, as its docs show)
    of the same rows into a table of the poses schema, a transaction per batch."""

    def __init__(self, url: str) -> None:
        import psycopg

        self.con = psycopg.connect(url.replace("postgresql+psycopg://", "postgresql://"))
        with self.con.transaction():
            self.con.execute("DROP TABLE IF EXISTS baseline_poses")
            self.con.execute("CREATE TABLE baseline_poses (id BIGSERIAL PRIMARY KEY, run_id INTEGER, t DOUBLE "
                             "PRECISION, x DOUBLE PRECISION, y DOUBLE PRECISION, theta DOUBLE PRECISION)")
            self.con.execute("CREATE INDEX ix_baseline_poses_run_t ON baseline_poses (run_id, t)")

    def insert(self, batches: list[list[list[float]]]) -> float:
        """Seconds to store ``batches``."""
        t0 = time.perf_counter()
        for b in batches:
            with self.con.transaction(), self.con.cursor() as cur:
                with cur.copy("COPY baseline_poses (run_id, t, x, y, theta) FROM STDIN") as copy:
                    for t, x, y, a in b:
                        copy.write_row((1, t, x, y, a))
        return time.perf_counter() - t0

    def close(self) -> None:
        self.con.close()


async def post_batches(client: httpx.AsyncClient, robot: str, batches: list[list[list[float]]],
                       workers: int) -> float:
    """Seconds to post ``batches`` with ``workers`` concurrent requests; checks they were stored."""
    queue: asyncio.Queue = asyncio.Queue()
    for b in batches:  # encoded beforehand: the client's JSON work is not the server's
        queue.put_nowait(json.dumps({"robot_id": robot, "poses": b}).encode())
    stored = 0
    headers = {"content-type": "application/json"}

    async def worker() -> None:
        nonlocal stored
        while not queue.empty():
            b = queue.get_nowait()
            r = await client.post("/api/v1/tracker/poses", content=b, headers=headers)
            r.raise_for_status()
            stored += r.json()["stored"]

    t0 = time.perf_counter()
    await asyncio.gather(*(worker() for _ in range(workers)))
    dt = time.perf_counter() - t0
    if stored != sum(len(b) for b in batches):
        raise RuntimeError(f"only {stored} poses stored: the run window closed during the benchmark")
    return dt


def ingestion(tmp: Path, n_batches: int, rounds: int = 10, database_url: str = "") -> dict:
    """Server and baseline timed in alternating rounds, so both see the same machine load; on
    ``database_url`` (PostgreSQL, against a raw psycopg COPY), else on SQLite (against raw executemany)."""
    extra = ["--database-url", database_url] if database_url else []
    tb = Testbed(tmp / ("ingest-pg" if database_url else "ingest"), "--time-scale", "0.2", "--sim-robots", "1",
                 *extra)
    base: RawSqlite | RawCopy = RawCopy(database_url) if database_url else RawSqlite(tmp / "baseline.db")
    per_round = max(n_batches // rounds, 1)
    t_server = t_base = 0.0
    try:
        with tb.client() as c:
            c.post("/api/v1/environments", json=SLOW_ENV).raise_for_status()
            job = {"environment": "bench-open", "start": [0.2, 0.2, 0.0], "goal": [1.6, 1.6, 0.0],
                   "planner": "fmm", "modes": ["sim"]}
            e = c.post("/api/v1/experiments", json=job).json()
            e = wait_status(c, e["id"], {"running"})
            robot = e["runs"][0]["robot_id"]

            async def run_rounds() -> tuple[float, float]:
                ts = tb_ = 0.0
                async with httpx.AsyncClient(base_url=tb.url, headers={"Authorization": f"Bearer {TOKEN}"},
                                             timeout=60) as ac:
                    for r in range(rounds):
                        batches = [rows(1000, 1e6 + 1000 * (r * per_round + i)) for i in range(per_round)]
                        ts += await post_batches(ac, robot, batches, workers=4)
                        tb_ += base.insert(batches)
                return ts, tb_

            t_server, t_base = asyncio.run(run_rounds())
            c.post(f"/api/v1/experiments/{e['id']}/cancel")
    finally:
        tb.stop()
        if isinstance(base, RawCopy):
            base.close()
    n = rounds * per_round * 1000
    baseline = "baseline_psycopg_copy_poses_per_s" if database_url else "baseline_sqlite_poses_per_s"
    return {"poses": n, "batch": 1000, "clients": 4, "server_poses_per_s": n / t_server,
            baseline: n / t_base, "ratio": t_base / t_server}


async def latency(url: str, path: str, clients: int, per_client: int) -> list[float]:
    times: list[float] = []

    async def one(c: httpx.AsyncClient) -> None:
        for _ in range(per_client):
            t0 = time.perf_counter()
            r = await c.get(path)
            r.raise_for_status()
            times.append(time.perf_counter() - t0)

    limits = httpx.Limits(max_connections=clients)
    async with httpx.AsyncClient(base_url=url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=60,
                                 limits=limits) as c:
        await c.get(path)
        await asyncio.gather(*(one(c) for _ in range(clients)))
    return times


def wrk_latency(url: str, connections: int, seconds: int = 5) -> dict | None:
    """Latency percentiles measured by wrk (a C load generator, so the client costs little CPU)."""
    import shutil

    if shutil.which("wrk") is None:
        return None
    out = subprocess.run(["wrk", "-t", "2", "-c", str(connections), "-d", f"{seconds}s", "--latency",
                          "-H", f"Authorization: Bearer {TOKEN}", url], capture_output=True, text=True).stdout

    def ms(label: str) -> float:
        m = re.search(rf"^\s+{label}%\s+([\d.]+)(us|ms|s)\s*$", out, re.M)
        v, unit = float(m.group(1)), m.group(2)
        return v / 1000 if unit == "us" else v * 1000 if unit == "s" else v

    rps = re.search(r"Requests/sec:\s+([\d.]+)", out)
    return {"p50_ms": ms("50"), "p99_ms": ms("99"), "requests_per_s": float(rps.group(1)) if rps else None,
            "connections": connections, "seconds": seconds}


def rest_and_throughput(tmp: Path, requests: int, experiments: int) -> tuple[dict, dict]:
    tb = Testbed(tmp / "rest", "--time-scale", "max", "--sim-robots", "4")
    try:
        with tb.client() as c:
            job = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708],
                   "planner": "fm2", "modes": ["sim", "twb"], "repetitions": 2}
            e = wait_status(c, c.post("/api/v1/experiments", json=job).json()["id"], {"completed"})
            path = f"/api/v1/experiments/{e['id']}"
            stop = threading.Event()

            def submit_every_second() -> None:  # steady submissions while the pollers poll
                with tb.client() as s:
                    while not stop.wait(1.0):
                        s.post("/api/v1/experiments", json={**job, "repetitions": 1})

            submitter = threading.Thread(target=submit_every_second, daemon=True)
            submitter.start()
            try:
                times = asyncio.run(latency(tb.url, path, 32, requests))
                by_wrk = wrk_latency(tb.url + path, 32)
            finally:
                stop.set()
                submitter.join(30)
            q = np.percentile(np.array(times) * 1000, [50, 99])
            rest = {"endpoint": "GET /api/v1/experiments/{id} (4 runs with metrics)", "clients": 32,
                    "while": "one submission per second",
                    "httpx_client": {"requests": len(times), "p50_ms": float(q[0]), "p99_ms": float(q[1])},
                    "wrk": by_wrk}
            best = rest["wrk"] or rest["httpx_client"]
            rest["p50_ms"], rest["p99_ms"] = best["p50_ms"], best["p99_ms"]
            t0 = time.perf_counter()
            ids = [c.post("/api/v1/experiments", json={**job, "repetitions": 1, "seed": i}).json()["id"]
                   for i in range(experiments)]
            done = [wait_status(c, i, TERMINAL, timeout=600) for i in ids]
            wall = time.perf_counter() - t0
            ok = sum(d["status"] == "completed" for d in done)
            thr = {"experiments": experiments, "completed": ok, "runs_each": 2, "wall_s": wall,
                   "experiments_per_minute": 60 * experiments / wall}
    finally:
        tb.stop()
    return rest, thr


def timed(c: httpx.Client, n: int, call) -> dict:  # type: ignore[no-untyped-def]
    """p50 / p99 (ms) of ``n`` calls ``call(c)`` (after one untimed call)."""
    call(c).raise_for_status()
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        call(c).raise_for_status()
        times.append(time.perf_counter() - t0)
    q = np.percentile(np.array(times) * 1000, [50, 99])
    return {"requests": n, "p50_ms": float(q[0]), "p99_ms": float(q[1])}


def big_queue(tmp: Path, queued_runs: int, probes: int = 60) -> dict:
    """Submission and /health latency with ``queued_runs`` waiting, against the empty queue (ratios)."""
    tb = LocalTestbed(tmp / "queue", "--time-scale", "1", "--sim-robots", "1", token=TOKEN,
                      env={"TWB_MAX_QUEUED_PER_USER": "100000"})
    job = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fmm",
           "modes": ["sim", "twb"], "repetitions": 10}  # 20 runs each
    try:
        with httpx.Client(base_url=tb.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=120) as c:
            submit = lambda c: c.post("/api/v1/experiments", json=job)  # noqa: E731
            health = lambda c: c.get("/health")  # noqa: E731
            empty = {"post": timed(c, probes, submit), "health": timed(c, probes, health)}
            t0 = time.perf_counter()
            while c.get("/health").json()["queued_runs"] < queued_runs:
                submit(c).raise_for_status()
            fill_s = time.perf_counter() - t0
            full = {"post": timed(c, probes, submit), "health": timed(c, probes, health)}
            queued = c.get("/health").json()["queued_runs"]
            page = c.get("/api/v1/experiments", params={"status": "queued", "limit": 500}).json()["data"]
            ids = [e["id"] for e in page]
            t1 = time.perf_counter()
            cancelled = c.post("/api/v1/experiments/cancel", json={"ids": ids}).json()["cancelled"]
            cancel_s = time.perf_counter() - t1
    finally:
        tb.stop()
    return {"queued_runs": queued, "fill_s": fill_s, "empty_queue": empty, "full_queue": full,
            "post_p99_ratio": full["post"]["p99_ms"] / empty["post"]["p99_ms"],
            "health_p99_ratio": full["health"]["p99_ms"] / empty["health"]["p99_ms"],
            "cancel_one_request": {"experiments": len(cancelled), "seconds": cancel_s}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batches", type=int, default=200, help="tracker batches of 1000 poses")
    ap.add_argument("--requests", type=int, default=50, help="GET requests per client (32 clients)")
    ap.add_argument("--experiments", type=int, default=20)
    ap.add_argument("--queued-runs", type=int, default=5000)
    ap.add_argument("--only", choices=["ingestion", "ingestion-postgresql", "rest", "queue"],
                    help="run one part only")
    args = ap.parse_args()
    parts: list[dict] = []
    targets: dict[str, bool] = {}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if args.only in (None, "ingestion"):
            ing = ingestion(tmp, args.batches)
            parts.append({"tracker_ingestion": ing})
            targets["ingestion >= 50000 poses/s"] = ing["server_poses_per_s"] >= 50_000
            targets["ingestion >= 0.3x raw sqlite executemany"] = ing["ratio"] >= 0.3
        if args.only in (None, "ingestion-postgresql"):
            pg = postgres(tmp)
            if pg is None:
                parts.append({"tracker_ingestion_postgresql": {"skipped": "PostgreSQL's binaries are not installed"}})
            else:
                try:
                    ing = ingestion(tmp, args.batches, database_url=pg.database())
                finally:
                    pg.stop()
                parts.append({"tracker_ingestion_postgresql": ing})
                targets["PostgreSQL ingestion >= 0.3x a raw psycopg COPY"] = ing["ratio"] >= 0.3
        if args.only in (None, "rest"):
            rest, thr = rest_and_throughput(tmp, args.requests, args.experiments)
            parts += [{"rest_latency": rest}, {"throughput": thr}]
            targets["GET p99 <= 50 ms with 32 clients"] = rest["p99_ms"] <= 50
        if args.only in (None, "queue"):
            q = big_queue(tmp, args.queued_runs)
            parts.append({"big_queue": q})
            targets[f"POST p99 <= 100 ms with {args.queued_runs} runs queued"] = q["full_queue"]["post"]["p99_ms"] <= 100
            targets[f"/health p99 <= 50 ms with {args.queued_runs} runs queued"] = \
                q["full_queue"]["health"]["p99_ms"] <= 50
    report("server", parts, targets_met=targets)


if __name__ == "__main__":
    main()
