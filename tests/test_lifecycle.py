"""Processes the testbed starts end with it, and a stop (Ctrl-C) ends runs under way ``interrupted``."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest
from servers import Process, wait_for

ONE_BLOCK = {"name": "one-block", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.3, "h": 0.3}]}
SLOW_JOB = {"environment": "one-block", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 0.0], "planner": "fmm"}


def descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry.name))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.slow
def test_worker_processes_die_with_a_killed_server(tmp_path):
    p = Process(["up", "--time-scale", "max", "--sim-robots", "1"], tmp_path)
    try:
        deadline = time.monotonic() + 30
        while len(kids := descendants(p.proc.pid)) < 2:  # the planning workers (and their tracker)
            assert time.monotonic() < deadline, kids
            time.sleep(0.2)
        with p.client() as c:  # the workers work: a planned job completes
            exp = c.post("/api/v1/experiments", json={**SLOW_JOB, "environment": "room", "modes": ["sim"]}).json()
            assert wait_for(c, exp["id"], timeout=60)["status"] == "completed"
        kids = descendants(p.proc.pid)
    finally:
        p.stop(signal.SIGKILL)
    deadline = time.monotonic() + 20
    while left := [k for k in kids if alive(k)]:
        assert time.monotonic() < deadline, f"processes outlived their server: {left}"
        time.sleep(0.2)


@pytest.mark.slow
def test_ctrl_c_mid_run_ends_it_interrupted_and_retries_nothing(tmp_path):
    # time scale 1: each run drives ~8 s of wall time, so both are still driving at the stop even when one
    # starts seconds after the other on a loaded machine (at 2, one finished first once in a full suite run)
    p = Process(["up", "--time-scale", "1", "--sim-robots", "1"], tmp_path)
    try:
        with p.client() as c:
            assert c.post("/api/v1/environments", json=ONE_BLOCK).status_code == 201
            exp = c.post("/api/v1/experiments", json={**SLOW_JOB, "modes": ["twb"], "repetitions": 2}).json()
            deadline = time.monotonic() + 60
            while any(r["status"] != "running" for r in c.get(f"/api/v1/experiments/{exp['id']}").json()["runs"]):
                assert time.monotonic() < deadline, c.get(f"/api/v1/experiments/{exp['id']}").json()["runs"]
                time.sleep(0.1)
            time.sleep(1.0)  # it drives
    except BaseException:
        p.stop(signal.SIGKILL)
        raise
    assert p.stop(signal.SIGINT) == 0, p.output()
    assert "Traceback" not in p.output(), p.output()
    again = Process(["server"], tmp_path, env={"TWB_RESUME_INTERRUPTED": "0"})
    try:
        with again.client() as c:
            e = c.get(f"/api/v1/experiments/{exp['id']}").json()
            for run in e["runs"]:  # both ran at once, on two sub-fields
                assert run["status"] == "interrupted" and run["attempt"] == 1, run
                assert run["error"] == "the server stopped during this run", run
            twb = e["runs"][0]
            poses = c.get(f"/api/v1/runs/{twb['id']}/poses").json()
            messages = c.get(f"/api/v1/runs/{twb['id']}/messages").json()
            assert poses["count"] > 0 and messages["count"] > 3  # what it did until the stop is kept
    finally:
        again.stop()
    resumed = Process(["server"], tmp_path)  # by default the next start queues them again
    try:
        with resumed.client() as c:
            e = c.get(f"/api/v1/experiments/{exp['id']}").json()
            assert [r["status"] for r in e["runs"]] == ["queued", "queued"]
            assert c.get(f"/api/v1/runs/{e['runs'][0]['id']}/poses").json()["count"] > 0  # until it runs again
    finally:
        resumed.stop()


@pytest.mark.slow
def test_a_stopped_testbed_leaves_no_process_behind(tmp_path):
    p = Process(["up", "--time-scale", "max", "--sim-robots", "1"], tmp_path)
    kids = descendants(p.proc.pid)
    assert p.stop(signal.SIGINT) == 0
    deadline = time.monotonic() + 20
    while left := [k for k in kids if alive(k) and k != os.getpid()]:
        assert time.monotonic() < deadline, f"processes outlived their server: {left}"
        time.sleep(0.2)


@pytest.mark.slow
def test_a_testbed_started_by_a_program_ends_when_the_program_is_killed(tmp_path):
    """`twb study --embedded` (or a test) starts a testbed through LocalTestbed: kill -9 of the program
    must not leave the testbed, its robots or its workers behind."""
    import subprocess
    import sys

    code = ("import sys, time; from twb.launch import LocalTestbed; "
            "tb = LocalTestbed(sys.argv[1], '--time-scale', 'max', '--sim-robots', '1'); "
            "print(tb.proc.pid, flush=True); time.sleep(600)")
    program = subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        testbed = int(program.stdout.readline())
        kids = descendants(testbed) | {testbed}
    finally:
        program.kill()
        program.wait()
    deadline = time.monotonic() + 30
    while left := [k for k in kids if alive(k)]:
        assert time.monotonic() < deadline, f"processes outlived the program that started them: {left}"
        time.sleep(0.2)



@pytest.mark.slow
def test_an_agent_stops_on_ctrl_c_and_sigterm_even_when_started_with_ctrl_c_ignored():
    """A background job of a script starts with SIGINT ignored: `twb agent` must still stop on Ctrl-C (and on
    SIGTERM, flushing what it has), not hang until killed."""
    import re
    import subprocess

    from servers import TWB

    for sig in (signal.SIGINT, signal.SIGTERM):
        proc = subprocess.Popen([str(TWB), "agent", "--port", "0", "--backend", "ideal", "--time-scale", "max",
                                 "--robot-id", "bg"], stderr=subprocess.PIPE, text=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
        try:
            while not re.search(r"ports \[\d+", line := proc.stderr.readline()):
                assert line, f"twb agent exited early with {proc.poll()}"
            proc.send_signal(sig)
            assert proc.wait(timeout=20) == 0
        finally:
            proc.kill()
            proc.wait()


def _pool_workers(server_pid: int) -> list[int]:
    """The compute pool's worker processes of a server (spawned by multiprocessing; not its resource tracker)."""
    out = []
    for pid in descendants(server_pid):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if "multiprocessing.spawn" in cmd and "resource_tracker" not in cmd:
            out.append(pid)
    return out


@pytest.mark.slow
def test_a_killed_planning_worker_is_replaced_and_costs_one_retry(tmp_path):
    """SIGKILL one worker (what the out-of-memory killer does): the broken pool is replaced, the job that met
    it ends its try as a testbed error and is retried, and every later job plans as before."""
    p = Process(["up", "--time-scale", "max", "--sim-robots", "1"], tmp_path)
    try:
        with p.client() as c:
            deadline = time.monotonic() + 120
            while not c.get("/health").json()["compute"]["ready"]:
                assert time.monotonic() < deadline, p.output()
                time.sleep(0.2)
            workers = _pool_workers(p.proc.pid)
            assert workers, descendants(p.proc.pid)
            os.kill(workers[0], signal.SIGKILL)
            job = {**SLOW_JOB, "environment": "room", "modes": ["sim"]}
            first = wait_for(c, c.post("/api/v1/experiments", json=job).json()["id"], timeout=120)
            assert first["status"] == "completed", first
            run = first["runs"][0]  # the try it cost, and why (a completed second try keeps the note)
            assert "a worker process of the compute pool died" in (run["error"] or ""), run
            health = c.get("/health").json()
            assert health["compute"]["restarts"] == 1 and "terminated abruptly" in health["compute"]["last_failure"]
            later = wait_for(c, c.post("/api/v1/experiments", json={**job, "seed": 1}).json()["id"], timeout=120)
            assert later["status"] == "completed" and c.get("/health").json()["compute"]["restarts"] == 1
            assert workers[0] not in _pool_workers(p.proc.pid) and len(_pool_workers(p.proc.pid)) == len(workers)
    finally:
        p.stop()
    assert "Traceback" not in p.output(), p.output()


@pytest.mark.slow
def test_a_stop_during_start_up_ends_everything_at_once(tmp_path):
    """SIGTERM while the first start compiles the simulation kernels (a fresh kernel cache: the longest
    start-up there is, up to minutes on a busy machine): the process and its workers end at once instead of
    after the compile; nothing had run, so nothing is lost."""
    import subprocess
    import sys

    log = open(tmp_path / "out.log", "w")
    proc = subprocess.Popen([sys.executable, "-m", "twb", "up", "--time-scale", "max", "--port", "0", "--data-dir",
                             str(tmp_path / "data")], stdout=log, stderr=subprocess.STDOUT,
                            env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "kernels"), "PYTHONUNBUFFERED": "1"})
    try:
        deadline = time.monotonic() + 120
        while len(kids := descendants(proc.pid)) < 2:  # the compute workers are up: start-up is under way
            assert time.monotonic() < deadline and proc.poll() is None, (tmp_path / "out.log").read_text()
            time.sleep(0.1)
        time.sleep(1.0)
        assert "is up" not in (tmp_path / "out.log").read_text()  # still starting (compiling)
        kids = descendants(proc.pid)
        proc.send_signal(signal.SIGTERM)
        t0 = time.monotonic()
        assert proc.wait(60) == 0
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
        log.close()
    out = (tmp_path / "out.log").read_text()
    assert took < 10, f"stopping during start-up took {took:.1f} s: {out}"  # the compile alone takes longer
    assert "stopped during start-up" in out and "Traceback" not in out, out
    deadline = time.monotonic() + 10
    while left := [k for k in kids if alive(k)]:
        assert time.monotonic() < deadline, f"processes outlived their server: {left}"
        time.sleep(0.1)
