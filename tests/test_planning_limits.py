"""A planning worker's limits: its memory cap and the planning deadline end a job as the job's planning failure,
and the worker goes on; through a real server, a plan past the deadline fails its run ``planning``."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest
from servers import Process, wait_for

WORKER = textwrap.dedent("""
    import numpy as np
    from planners import PlanningError, plan_path
    from planners.fast_marching import warm_up
    from robot_agent.engine.limits import PlanningLimit, configure_worker, planning_limits

    warm_up()  # as the pool's workers do before their first job: the kernels' loading is not a plan's time
    configure_worker(memory_mb={memory}, deadline_s={deadline})
    try:
        with planning_limits():
            {job}
    except PlanningLimit as exc:
        print("LIMIT", exc)
    with planning_limits():  # the worker is still usable afterwards
        print("NEXT", round(plan_path("room", [0.3, 0.3], [1.5, 1.5], "fmm").length_m, 3))
""")


def _worker(job: str, memory: int = 0, deadline: float = 0.0) -> str:
    code = WORKER.format(memory=memory, deadline=deadline, job=job)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


@pytest.mark.slow
def test_an_allocation_past_the_memory_cap_is_the_jobs_failure():
    out = _worker("np.ones((4000, 40000))", memory=1024)  # 1.2 GB against a 1 GiB data segment
    assert "LIMIT the planning memory limit of 1024 MiB per worker was reached" in out, out
    assert "choose coarser planner parameters" in out and "NEXT " in out


@pytest.mark.slow
def test_a_plan_past_the_deadline_is_stopped_and_the_worker_goes_on():
    out = _worker("plan_path('room', [0.3, 0.3], [1.5, 1.5], 'prm', params={'samples': 200000, 'k': 100})",
                  deadline=0.3)
    assert "LIMIT the planning time limit of 0.3 s was reached" in out, out
    assert "NEXT " in out


@pytest.mark.slow
def test_the_server_fails_a_plan_past_its_deadline_as_planning(tmp_path):
    p = Process(["up", "--time-scale", "max", "--sim-robots", "1"], tmp_path, env={"TWB_PLANNING_TIMEOUT_S": "0.3"})
    try:
        with p.client() as c:
            job = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 0.0], "planner": "prm",
                   "planner_params": {"samples": 200000, "k": 100}, "modes": ["sim"], "repetitions": 1}
            exp = wait_for(c, c.post("/api/v1/experiments", json=job).json()["id"], timeout=180)
            run = exp["runs"][0]
            assert run["status"] == "failed" and run["failure"] == "planning", run
            assert "the planning time limit of 0.3 s was reached" in run["error"], run
            fast = wait_for(c, c.post("/api/v1/experiments", json={**job, "planner": "fmm",
                                                                   "planner_params": {}}).json()["id"], timeout=180)
            assert fast["status"] == "completed", fast  # the worker planned the next job
    finally:
        p.stop()
    assert "Traceback" not in p.output(), p.output()
