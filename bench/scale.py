"""A sim-only sweep through the whole testbed: runs per second on each path, against the in-process limit.

The sweep: ``--runs`` simulation runs as experiments of 20 repetitions (seeded)
over the four built-in planners and the built-in environments' plans.  Timed,
from the first submission to the last run's end:

- ``local-sqlite``: ``twb up`` (local agents, ``--sim-robots`` of them) on SQLite;
- ``local-postgresql``: the same on PostgreSQL;
- ``ray-postgresql``: ``twb up --sim-engine ray`` on PostgreSQL (a local Ray cluster);

beside ``in-process``, the same runs in one Python loop with no server (plan
once per experiment, then simulate and measure each run: the functions a Ray
task runs), the limit.  PostgreSQL is started from the machine's binaries as
the tests do (tests/pg_support.py).  Prints JSON; ``ratio`` is runs/s over the
in-process loop's runs/s, measured in the same invocation.

    python bench/scale.py [--runs 2000] [--only ray-postgresql] [--sim-robots 4]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = str(ROOT)
from bench._common import postgres, report  # noqa: E402

PLANNERS = ["fmm", "fm2", "astar", "prm"]
REPETITIONS = 20


def sweep(runs: int) -> list[dict[str, Any]]:
    """The sweep's experiments (sim only, ``REPETITIONS`` each, ``runs`` runs in all)."""
    envs = {name: json.loads((ROOT / "planners" / "data" / f"{name}.json").read_text()) for name in ("room", "blocks")}
    problems = [(name, plan) for name, env in envs.items() for plan in env["plans"]]
    jobs = []
    for i, (planner, (env, plan)) in enumerate(itertools.islice(itertools.cycle(itertools.product(PLANNERS, problems)),
                                                                 max(1, runs // REPETITIONS))):
        jobs.append({"environment": env, "start": plan["start"], "goal": plan["goal"], "planner": planner,
                     "modes": ["sim"], "repetitions": REPETITIONS, "seed": i})
    return jobs


def in_process(jobs: list[dict[str, Any]]) -> dict[str, Any]:
    """The limit: plan each experiment, simulate and measure each run, in this process."""
    from planners import load_environment  # noqa: F401 - import cost outside the timing
    from robot_agent.engine import jobs as engine

    envs = {n: json.loads((ROOT / "planners" / "data" / f"{n}.json").read_text()) for n in ("room", "blocks")}
    engine.simulate_job(envs["room"], [[0.3, 0.3, 0.0], [0.6, 0.3, 0.0]], [[0.3, 0.3, 0.0]], 0, 60,
                         [0.6, 0.3, 0.0], 0.045, 0.0)  # compile the simulation core first
    t0, c0 = time.perf_counter(), time.process_time()
    n = 0
    for job in jobs:
        env = envs[job["environment"]]
        plan = engine.plan_job(env, job["start"], job["goal"], job["planner"], {}, job["seed"], 0.065)
        for rep in range(job["repetitions"]):
            engine.simulate_job(env, plan["path"], [job["start"]], job["seed"] + rep, 600, job["goal"], 0.045,
                                 plan["planning_time_s"])
            n += 1
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"name": "in-process", "runs": n, "wall_s": round(wall, 2), "runs_per_s": round(n / wall, 1),
            "cpu_ms_per_run": {"this_process": round(cpu * 1000 / n, 2)}}


def _processes() -> dict[int, tuple[int, str, float]]:
    """Every process: pid -> (parent pid, command line, CPU seconds: user + system, threads included)."""
    tick = os.sysconf("SC_CLK_TCK")
    out = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[int(d.name)] = (int(fields[1]), cmd, (int(fields[11]) + int(fields[12])) / tick)
    return out


def _cpu_by_part(server_pid: int, pg_port: int | None) -> dict[str, float]:
    """CPU seconds so far of the server, of the Ray workers it started (its descendants: other Ray clusters on
    the machine do not count) and of this bench's PostgreSQL (the postmaster on ``pg_port`` and its children)."""
    procs = _processes()

    def under(pid: int, root: int) -> bool:
        while pid > 1:
            if pid == root:
                return True
            pid = procs[pid][0] if pid in procs else 0
        return False

    postmaster = next((pid for pid, (_, cmd, _) in procs.items()
                       if pg_port is not None and cmd.startswith("/") and "postgres" in cmd and f"-p {pg_port}" in cmd),
                      None)
    return {
        "server": procs.get(server_pid, (0, "", 0.0))[2],
        "ray_workers": sum(c for pid, (_, cmd, c) in procs.items() if cmd.startswith("ray::") and under(pid, server_pid)),
        "postgresql": sum(c for pid, (_, cmd, c) in procs.items()
                          if postmaster is not None and pid != postmaster and under(pid, postmaster)),
    }


def through_testbed(name: str, args: list[str], jobs: list[dict[str, Any]], data_dir: Path) -> dict[str, Any]:
    """Submit the sweep to a fresh testbed and time it to the last run's end."""
    from twb.launch import LocalTestbed

    env = {"TWB_MAX_QUEUED_PER_USER": "100000"}
    url = args[args.index("--database-url") + 1] if "--database-url" in args else ""
    m = re.search(r":(\d+)/", url)
    pg_port = int(m.group(1)) if m else None
    with LocalTestbed(data_dir, "--time-scale", "max", *args, timeout=180, env=env) as tb:
        import httpx

        with httpx.Client(base_url=tb.url, headers={"Authorization": f"Bearer {tb.token}"}, timeout=60) as c:
            cpu0 = _cpu_by_part(tb.proc.pid, pg_port)
            t0 = time.perf_counter()
            ids = [c.post("/api/v1/experiments", json=job).raise_for_status().json()["id"] for job in jobs]
            submitted = time.perf_counter() - t0
            samples = []
            while True:
                h = c.get("/health").json()
                samples.append((time.perf_counter() - t0, h["queued_runs"] + h["running_runs"]))
                if h["queued_runs"] + h["running_runs"] == 0:
                    break
                time.sleep(0.25)
            wall = time.perf_counter() - t0
            cpu1 = _cpu_by_part(tb.proc.pid, pg_port)
            statuses: dict[str, int] = {}
            for i in ids:
                for r in c.get(f"/api/v1/experiments/{i}").json()["runs"]:
                    statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    n = sum(statuses.values())
    # steady rate: runs ended between 10 % and 90 % of the sweep, over the time that took
    total = samples[0][1] if samples else n
    t10 = next((t for t, left in samples if left <= 0.9 * total), None)
    t90 = next((t for t, left in samples if left <= 0.1 * total), None)
    steady = round(0.8 * total / (t90 - t10), 1) if t10 is not None and t90 is not None and t90 > t10 else None
    cpu_ms = {k: round((cpu1[k] - cpu0[k]) * 1000 / max(n, 1), 2) for k in cpu0}  # per run
    return {"name": name, "runs": n, "statuses": statuses, "submit_s": round(submitted, 2), "wall_s": round(wall, 2),
            "runs_per_s": round(n / wall, 1), "steady_runs_per_s": steady, "cpu_ms_per_run": cpu_ms}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2000)
    ap.add_argument("--sim-robots", type=int, default=4)
    ap.add_argument("--only", action="append", choices=["local-sqlite", "local-postgresql", "ray-postgresql"])
    args = ap.parse_args()
    jobs = sweep(args.runs)
    limit = in_process(jobs)
    results = [limit]
    work = Path(tempfile.mkdtemp(prefix="twb-scale-"))
    pg = None
    wanted = args.only or ["local-sqlite", "local-postgresql", "ray-postgresql"]
    try:
        for name in wanted:
            extra: list[str] = []
            if name.endswith("postgresql"):
                pg = pg or postgres(work)
                if pg is None:
                    results.append({"name": name, "skipped": "PostgreSQL's binaries are not installed"})
                    continue
                extra += ["--database-url", pg.database()]
            extra += ["--sim-engine", "ray"] if name.startswith("ray") else ["--sim-robots", str(args.sim_robots)]
            r = through_testbed(name, extra, jobs, work / name)
            r["ratio"] = round(r["runs_per_s"] / limit["runs_per_s"], 3)
            results.append(r)
    finally:
        if pg is not None:
            pg.stop()
    report("scale", results, runs=args.runs, sim_robots=args.sim_robots,
           median_in_process_run_ms=round(1000 / limit["runs_per_s"], 2) if limit["runs_per_s"] else None,
           note="ratio: runs/s over the in-process loop's runs/s (one process, no server), same invocation")


if __name__ == "__main__":
    main()
