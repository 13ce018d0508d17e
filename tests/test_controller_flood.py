"""A controller program that floods its robot port with T,T,V lines, on a real `twb up --enable-uploads`
(the hardening issue, wave three, item 4): its run fails as the program's fault within its wall limit, is
not retried, its stored log stays within the cap and ends saying how many lines were dropped, and the
robot and the sandbox slot are free for the next job.  A program as fast as the robot answers (lock-step)
is no flood.

One simulation robot and one sandbox slot, so the job after the flood can only run if both were freed;
the run log keeps 1,000 lines here (TWB_RUN_LOG_LINES), so that the flood's log overflows it.
"""

from __future__ import annotations

import random
import re
import time
from datetime import datetime

import pytest
from servers import serve, wait_for
from test_controller_programs import CONNECT, EXAMPLES, GOAL, START, b64

WALL_S = 30
LOG_LINES = 1000
ENV = {"TWB_SANDBOX_WALL_S": str(WALL_S), "TWB_SANDBOX_CPU_S": "20", "TWB_SANDBOX_WORKERS": "1",
       "TWB_SANDBOX_UID_BASE": str(3_900_000 + random.randrange(0, 90) * 1000), "TWB_RUN_LOG_LINES": str(LOG_LINES)}

FLOOD = CONNECT + """
f.write("T,T,O,1\\n"); f.flush()
burst = "T,T,V,100,0\\n" * 2000
while True:  # never reads a reply
    f.write(burst); f.flush()
"""
LOCKSTEP = CONNECT + """
f.write("T,T,O,1\\n"); f.flush()
sent = 0
while sent < 1200:  # as fast as the robot answers, one line at a time (a count, not a time: any host's speed)
    f.write("T,T,V,0,0\\n"); f.flush(); sent += 1
    while not f.readline().startswith(("OK,V", "ERR")):
        pass
print("sent", sent)
"""


@pytest.mark.slow
def test_a_flooding_controller_program_fails_as_its_own_fault_and_frees_the_robot(tmp_path_factory):
    for testbed in serve(["up", "--time-scale", "2", "--sim-robots", "1", "--enable-uploads"],
                         tmp_path_factory.mktemp("flood"), env=ENV):
        with testbed.client() as c:
            assert c.post("/api/v1/environments", json={"name": "open", "size": [1.8, 1.8], "blocks": []}).status_code == 201
            ids = {}
            for name, src in (("flood", FLOOD), ("lockstep", LOCKSTEP),
                              ("p_controller", (EXAMPLES / "p_controller.py").read_text())):
                r = c.post("/api/v1/programs", json={"name": name, "kind": "python", "content_base64": b64(src)})
                assert r.status_code == 201, r.text
                ids[name] = r.json()["id"]

            def run_of(program: str) -> tuple[dict, list[dict], float]:
                t0 = time.monotonic()
                r = c.post("/api/v1/experiments", json={"environment": "open", "start": START, "goal": GOAL,
                                                        "controller_program": ids[program], "modes": ["sim"]})
                assert r.status_code == 202, r.text
                exp = wait_for(c, r.json()["id"], timeout=240)
                took = time.monotonic() - t0
                (run,) = c.get(f"/api/v1/experiments/{exp['id']}").json()["runs"]
                messages = c.get(f"/api/v1/runs/{run['id']}/messages?limit=10000").json()
                assert messages["count"] == len(messages["data"])
                return run, messages["data"], took

            run, log, took = run_of("flood")
            ran = (datetime.fromisoformat(run["finished_at"]) - datetime.fromisoformat(run["started_at"])).total_seconds()
            last = log[-1]["line"]
            print(f"\nflood: {run['status']} ({run['failure']}) in {ran:.2f} s of its {WALL_S} s wall limit "
                  f"({took:.1f} s from submission): {run['error']}\n  log: {len(log)} lines stored (cap {LOG_LINES}), "
                  f"the last: {last}")
            assert run["status"] == "failed" and run["failure"] == "program", run
            assert run["error"].startswith("program flooded its robot port: more than 1000 of its lines were waiting")
            assert run["attempt"] == 1 and ran < WALL_S  # no retry, no testbed error, within the wall limit
            assert len(log) <= LOG_LINES + 1 and re.fullmatch(r"\d+ lines dropped: .*", last), last
            assert int(last.split()[0]) > 0 and f"beyond the {LOG_LINES} a run's log keeps" in last
            assert any(m["line"].startswith("relay: program flooded its robot port") for m in log)

            run, log, took = run_of("lockstep")  # as fast as the robot answers: no flood, the log capped
            print(f"lock-step: {run['status']} ({run['failure']}): {run['error']}; "
                  f"{run['metrics'].get('controller_steps')} T,T,V lines; log {len(log)} lines, the last: "
                  f"{log[-1]['line']}")
            assert not run["error"].startswith("program flooded"), run
            assert run["failure"] == "program" and run["error"].startswith("program stopped the robot"), run
            assert run["metrics"]["controller_steps"] > LOG_LINES and "lines dropped" in log[-1]["line"]

            run, log, took = run_of("p_controller")  # the one robot and the one sandbox slot are free again
            print(f"p_controller after them: {run['status']} in {took:.1f} s")
            assert run["status"] == "completed" and run["attempt"] == 1, (run, [m["line"] for m in log[-20:]])
