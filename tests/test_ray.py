"""The simulation pool on Ray (docs/scale-out.md, "The simulation pool on Ray"): real Ray clusters started by real
testbed processes.

(Failed runs — a collision, where the robot stopped — are compared the same way in-process, on the same
task code without Ray: tests/test_pipeline.py.)  Held tolerance for "same seed, same numbers" between a run on a local agent and the same run as a Ray task:
tracker positions and headings bit for bit (the same simulation core, the same codec rounding, the same
noise key), times and time-derived metrics to 1e-9 relative (the agent's clock starts earlier: its times
are the same durations shifted, and a difference of shifted floats rounds differently).
"""

from __future__ import annotations

import math
import os
import signal
import socket
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from servers import Process, wait_for

JOBS = [
    {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fmm",
     "modes": ["sim"], "repetitions": 2, "seed": 42, "jitter": {"xy_m": 0.01, "theta_rad": 0.05}},
    {"environment": "blocks", "start": [0.2, 1.6, 0.0], "goal": [1.6, 0.2, 0.0], "planner": "fm2",
     "modes": ["sim"], "repetitions": 1, "seed": 7, "controller": "regulated_pure_pursuit"},
    # a field-robot variant (noise study): a task in the worker pool there, on Ray here
    {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fmm",
     "modes": ["twb"], "repetitions": 1, "seed": 5, "profile_overrides": {"tracker_noise_xy_m": 0.002}},
    # a multi-robot job: compute.fleet_job in the worker pool there, a Ray task here (poses with the robot column)
    {"environment": "swap", "planner": "prioritized", "modes": ["sim"], "repetitions": 1, "seed": 1,
     "robots": [{"start": [0.3, 0.3], "goal": [1.5, 1.5]}, {"start": [1.5, 1.5], "goal": [0.3, 0.3]}]},
]


def _run_all(p: Process) -> list[list[tuple[dict, np.ndarray]]]:
    """Each job's runs with their poses (t, x, y, theta), in submission order."""
    out = []
    with p.client() as c:
        ids = [c.post("/api/v1/experiments", json=job).json()["id"] for job in JOBS]
        for i in ids:
            exp = wait_for(c, i, timeout=120)
            out.append([(r, np.array(c.get(f"/api/v1/runs/{r['id']}/poses").json()["poses"], dtype=float))
                        for r in sorted(exp["runs"], key=lambda r: r["repetition"])])
    return out


def _close(a: object, b: object, key: str = "") -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        assert set(a) == set(b), key
        for k in a:
            if k != "planning_time_s":
                _close(a[k], b[k], f"{key}.{k}")
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), key
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{key}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12), (key, a, b)
    else:
        assert a == b, (key, a, b)


@pytest.mark.slow
def test_a_run_on_ray_equals_the_same_run_on_a_local_agent(ray, postgres, tmp_path):
    """Local agents on SQLite against Ray tasks on PostgreSQL: the same outcomes, poses and metrics."""
    local = Process(["up", "--time-scale", "max", "--sim-robots", "1"], tmp_path / "local")
    try:
        mine = _run_all(local)
    finally:
        local.stop()
    on_ray = Process(["up", "--time-scale", "max", "--sim-engine", "ray", "--ray-cpus", "2",
                      "--database-url", postgres.database()], tmp_path / "ray", timeout=120)
    try:
        theirs = _run_all(on_ray)
        assert "Simulation runs: Ray tasks on a local Ray cluster, 2 CPUs, 6 runs at once." in on_ray.output()
    finally:
        assert on_ray.stop() == 0, on_ray.output()
    assert "Traceback" not in on_ray.output(), on_ray.output()
    statuses = [[r["status"] for r, _ in runs] for runs in theirs]
    assert statuses == [["completed", "completed"], ["completed"], ["completed"], ["completed"]]
    for job, runs_a, runs_b in zip(JOBS, mine, theirs):
        for (ra, pa), (rb, pb) in zip(runs_a, runs_b):
            if job["modes"] == ["twb"]:
                assert ra["robot_id"].startswith("field-") and rb["robot_id"].startswith("field-")
            else:
                assert rb["robot_id"].startswith("ray-") and ra["robot_id"] == "sim-1"
            for k in ("status", "failure", "stopped_at", "error"):
                assert ra.get(k) == rb.get(k), k
            pa = pa[pa[:, 0] >= ra["t_start"] - 1e-9]  # the agent logs the robot standing before the path too
            assert pa.shape == pb.shape and np.array_equal(pa[:, 1:], pb[:, 1:])
            assert np.allclose(pa[:, 0] - ra["t_start"], pb[:, 0] - rb["t_start"], rtol=0, atol=1e-9)
            assert math.isclose(ra["t_end"] - ra["t_start"], rb["t_end"] - rb["t_start"], abs_tol=1e-9)
            _close(ra["metrics"], rb["metrics"])


def _processes_of_group(pgid: int) -> list[int]:
    found = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if fields[0] != "Z" and int(fields[2]) == pgid:
                found.append(int(d.name))
    return found


def _pids_named(prefix: str) -> list[int]:
    found = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if cmd.startswith(prefix):
                found.append(int(d.name))
    return found


def _head_of(server_pid: int) -> int:
    """The process leading the local Ray cluster of the testbed ``server_pid``."""
    heads = [pid for pid in _pids_named(f"{sys.executable} -m server.pipeline.ray_head --server-pid {server_pid} ")]
    assert len(heads) == 1, heads
    return heads[0]


@pytest.fixture(scope="module")
def paused_ray(ray, tmp_path_factory):
    """`twb server` with a local Ray cluster of one CPU whose simulation tasks pause 3 s before simulating
    (TWB_FAULT_SIM_PAUSE_S), so that a test can kill a worker in the middle of a run."""
    p = Process(["server", "--time-scale", "max", "--sim-engine", "ray", "--ray-cpus", "1"],
                tmp_path_factory.mktemp("paused-ray"), timeout=120, env={"TWB_FAULT_SIM_PAUSE_S": "3"})
    yield p
    p.stop()


@pytest.mark.slow
def test_a_killed_ray_worker_ends_the_run_error_and_it_is_retried_once(paused_ray):
    with paused_ray.client() as c:
        exp = c.post("/api/v1/experiments", json={**JOBS[0], "repetitions": 1}).json()
        deadline = time.monotonic() + 60
        while not (busy := _pids_named("ray::simulate_job")):
            assert time.monotonic() < deadline, paused_ray.output()
            time.sleep(0.05)
        os.kill(busy[0], signal.SIGKILL)
        done = wait_for(c, exp["id"], timeout=120)
    run = done["runs"][0]
    assert done["status"] == "completed" and run["status"] == "completed", done
    assert "Ray lost the task (WorkerCrashedError)" in run["error"], run["error"]  # the first try, kept
    assert run["robot_id"].startswith("ray-") and run["metrics"]["execution_time_s"] > 0


@pytest.mark.slow
def test_the_local_ray_cluster_ends_with_a_killed_server(paused_ray):
    pgid = _head_of(paused_ray.proc.pid)
    assert len(_processes_of_group(pgid)) >= 3  # the head, Ray's GCS and raylet at least
    paused_ray.proc.kill()
    paused_ray.proc.wait()
    deadline = time.monotonic() + 30
    while left := _processes_of_group(pgid):
        assert time.monotonic() < deadline, f"Ray processes outlived the server: {left}"
        time.sleep(0.2)


def test_an_unreachable_ray_address_is_one_clear_line(ray, twb, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = twb("server", "--port", "0", "--data-dir", str(tmp_path), "--ray-address", f"127.0.0.1:{port}", timeout=60)
    assert out.returncode == 2 and out.stderr.count("\n") == 1, out.stderr
    assert out.stderr.strip() == \
        (f"twb: error: cannot reach the Ray cluster at 127.0.0.1:{port}: Connection refused (is `ray start --head` "
         "running there, and is its GCS port open to this machine?)"), out.stderr
    bad = twb("server", "--port", "0", "--data-dir", str(tmp_path), "--ray-address", "nowhere", timeout=60)
    assert bad.returncode == 2 and "expected host:port of the Ray head" in bad.stderr


@pytest.mark.slow
def test_without_ray_the_server_says_how_to_install_it(tmp_path):
    import subprocess

    code = ("import sys; sys.modules['ray'] = None; from twb.main import main; "
            f"sys.argv = ['twb', 'server', '--port', '0', '--data-dir', {str(tmp_path)!r}, '--sim-engine', 'ray']; "
            "sys.exit(main())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and out.stderr.count("\n") == 1, out.stderr
    assert out.stderr.strip() == (
        "twb: error: --sim-engine ray needs Ray, which is not installed: pip install 'teleworkbench[ray]' "
        "(in this checkout: uv pip install -e '.[ray]')"), out.stderr
