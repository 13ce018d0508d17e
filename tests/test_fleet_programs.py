"""Uploaded planner programs for multi-robot jobs (docs/uploads.md, "Multi-robot jobs: one T,T,P per robot port") on a
real `twb up --enable-uploads`: the program gets a robot port per robot, sends one T,T,P on each, and the robots drive
those paths; a missing or mismatched path fails the experiment naming the robot; the SDK, `twb submit` and
docs/uploads.md's commands.

(The single-robot contract and the sandbox's limits: tests/test_uploads.py, tests/test_sandbox.py.)
"""

from __future__ import annotations

import base64
import json
import random
import re
from pathlib import Path

import numpy as np
import pytest

from client_sdk import Client
from contract.params import robot_params
from server.sandbox.outcome import explain_fleet, robots_phrase
from servers import wait_for

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "uploads.md"
RADIUS = robot_params().collision_radius_m
UID_BASE = 3_100_000 + random.randrange(0, 800) * 1000  # this run's sandbox uids (other test runs use others)
LIMITS = {"TWB_SANDBOX_WALL_S": "5", "TWB_SANDBOX_WORKERS": "4", "TWB_SANDBOX_UID_BASE": str(UID_BASE)}
#: three robots in lanes, left to right (their straight lines never meet)
LANES = [{"start": [0.3, 0.3 + 0.5 * k], "goal": [1.5, 0.3 + 0.5 * k, 0.0]} for k in range(3)]
SWAP = json.loads((ROOT / "examples" / "fleet" / "swap-program.json").read_text())

#: a fleet program: straight lines from each start to its goal, robot k's path on port ``ORDER[k]``
#: (``None``: no path on that port); it reads the contract's variables and checks them
STRAIGHT = """
import os, socket
n = int(os.environ["TWB_ROBOTS"])
ports = [int(p) for p in os.environ["TWB_ROBOT_PORTS"].split(",")]
starts = [[float(v) for v in p.split(",")] for p in os.environ["TWB_STARTS"].split(";")]
goals = [[float(v) for v in p.split(",")] for p in os.environ["TWB_GOALS"].split(";")]
assert len(ports) == len(starts) == len(goals) == n and int(os.environ["TWB_ROBOT_PORT"]) == ports[0]
assert os.environ["TWB_START"] == os.environ["TWB_STARTS"].split(";")[0]
ORDER = {order}
for port, k in zip(ports, ORDER):
    if k is None:
        continue
    (x, y, a), (gx, gy) = starts[k], goals[k][:2]
    with socket.create_connection(("127.0.0.1", port)) as s:
        f = s.makefile("rw", newline="\\n")
        hello = f.readline().strip()
        f.write(f"T,T,P,{{x * 1000:.0f}},{{y * 1000:.0f}},0;{{gx * 1000:.0f}},{{gy * 1000:.0f}},0\\n")
        f.flush()
        print(port, hello, f.readline().strip())
"""


def b64(text: str) -> str:
    return base64.b64encode(text.encode()).decode()


@pytest.fixture(scope="module")
def testbed(testbeds):  # its own: uploads, four simulated robots, the programs' limits
    yield from testbeds.own("up", "--time-scale", "max", "--sim-robots", "4", "--enable-uploads", env=LIMITS)


@pytest.fixture(scope="module")
def client(testbed):
    with testbed.client() as c:
        yield c


def upload(client, name: str, content: str) -> int:
    r = client.post("/api/v1/programs", json={"name": name, "kind": "python", "content_base64": b64(content)})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def submit(client, program: int, robots: list[dict], **extra) -> dict:
    r = client.post("/api/v1/experiments", json={"environment": "swap", "robots": robots, "program": program,
                                                 "modes": ["sim"], **extra})
    assert r.status_code == 202, r.text
    return wait_for(client, r.json()["id"], timeout=120)


def poses(client, run_id: int, robot: int) -> np.ndarray:
    body = client.get(f"/api/v1/runs/{run_id}/poses", params={"robot": robot}).json()
    return np.array(body["poses"], dtype=float).reshape(-1, len(body["columns"]))


def lines(client, run_id: int) -> list[str]:
    return [m["line"] for m in client.get(f"/api/v1/runs/{run_id}/messages", params={"limit": 5000}).json()["data"]]


def test_a_program_sends_each_robot_its_path_on_its_port_and_each_robot_drives_its_own(client):
    exp = submit(client, upload(client, "lanes", STRAIGHT.format(order=[0, 1, 2])), LANES, modes=["sim", "twb"])
    assert exp["status"] == "completed", exp
    assert [r["status"] for r in exp["runs"]] == ["completed", "completed"]
    info = exp["planning_info"]
    assert [p["path_points"] for p in info["program"]["robot_ports"]] == [2, 2, 2]
    assert all(p["connected"] for p in info["program"]["robot_ports"])
    planned = [r["path"] for r in info["robots"]]
    for k, r in enumerate(LANES):  # the paths as sent: start -> goal, headings 0
        assert planned[k] == [[*r["start"], 0.0], [*r["goal"][:2], 0.0]]
    assert exp["planned_path"] == planned[0] and exp["planning_time_s"] > 0
    for run in exp["runs"]:  # both modes follow the one plan: ideal robots, emulated field robots
        assert run["metrics"]["success_rate"] == 1.0 and run["metrics"]["planning_time_s"] == exp["planning_time_s"]
        for k, r in enumerate(LANES):
            mine = poses(client, run["id"], k)
            assert len(mine) > 10 and set(mine[:, 4]) == {k}
            lane = 0.001 if run["mode"] == "sim" else 0.1  # the field: tracker noise, wheel bias (lanes 0.5 m apart)
            assert np.abs(mine[:, 2] - r["start"][1]).max() < lane, run["mode"]  # robot k keeps to its own lane
            assert np.hypot(*(mine[-1, 1:3] - r["goal"][:2])) < 0.02
    # the program ran once, in the log of the run that asked for the plan first (either mode: whichever got to it
    # first), each port's conversation named by that run's robot
    logs = {run["id"]: lines(client, run["id"]) for run in exp["runs"]}
    ran = [rid for rid, log in logs.items() if any(x.startswith("program 'lanes'") for x in log)]
    assert ran == [info["program"]["run_id"]]
    runner = next(run for run in exp["runs"] if run["id"] == ran[0])
    log = logs[ran[0]]
    for k in range(3):
        assert any(re.fullmatch(rf"robot {k} port > HELLO,{re.escape(runner['robot_id'])}/{k},\w+,1", x)
                   for x in log), log
        assert any(x.startswith(f"robot {k} port < T,T,P,") for x in log)
    assert any("paths received for robots 0, 1 and 2 of 3" in x for x in log)
    fleet = next(i for i, x in enumerate(log) if x.startswith("a multi-robot run of 3 "))
    assert fleet > max(i for i, x in enumerate(log) if x.startswith("robot 2 port"))  # planned, then driven
    assert any(x.startswith("robot 2: T,T,P,") for x in log[fleet:])


def test_a_program_that_leaves_ports_without_a_path_fails_naming_those_robots(client):
    exp = submit(client, upload(client, "partial", STRAIGHT.format(order=[0, None, None])), LANES)
    run = exp["runs"][0]
    assert exp["status"] == "failed" and run["status"] == "failed" and run["failure"] == "program", exp
    assert run["error"] == ("program sent no path for robots 1 and 2 (it never connected to the ports of "
                            "robots 1 and 2)"), run["error"]
    ports = exp["planning_info"]["program"]["robot_ports"]
    assert [(p["robot"], p["connected"], p["path_points"]) for p in ports] == [(0, True, 2), (1, False, None),
                                                                              (2, False, None)]
    assert exp["planned_path"] is None and not run["metrics"].get("robots")


def test_a_path_sent_on_another_robots_port_fails_naming_that_robot(client):
    # robot 0's path on robot 1's port too: robot 1's path does not begin at robot 1's start
    exp = submit(client, upload(client, "mixed", STRAIGHT.format(order=[0, 0, 2])), LANES)
    run = exp["runs"][0]
    assert exp["status"] == "failed" and run["failure"] == "program", exp
    assert run["error"].startswith("program's path for robot 1 is unusable: the path must begin at the start "
                                   "(0.3, 0.8) within 1 cm; it is 0.500 m away at (0.3, 0.3)"), run["error"]
    assert [p["path_points"] for p in exp["planning_info"]["program"]["robot_ports"]] == [2, 2, 2]
    assert any(x.startswith("program's path for robot 1 is unusable") for x in lines(client, run["id"]))


def test_bad_lines_time_limits_and_crashes_name_the_robots():
    limits = {"wall_s": 5, "memory_bytes": 256 << 20, "processes": 8, "cpu_s": 2, "file_bytes": 1 << 20}
    got = {"path": [[0.3, 0.3, 0.0], [1.5, 0.3, 0.0]], "connected": True, "refused": []}

    def ports(*rest: dict) -> list[dict]:
        return [got, *({"path": None, "connected": False, "refused": [], **r} for r in rest)]

    assert explain_fleet({"ports": ports()}, limits) is None
    assert explain_fleet({"ports": ports({"connected": True, "refused": ["ERR,SYNTAX,empty line"]}), "exit_code": 0},
                         limits) == ("program sent an invalid path for robot 1 (robot 1's port refused its last "
                                     "line: ERR,SYNTAX,empty line)")
    assert explain_fleet({"ports": ports({"connected": True}, {}), "timed_out": True}, limits) == (
        "program time limit: no path for robots 1 and 2 within 5 s (it never connected to robot 2's port; "
        "it sent no T,T,P line on robot 1's port)")
    assert explain_fleet({"ports": ports({}), "exit_code": 3, "stderr": "boom\n"}, limits) == (
        "program crashed: exit code 3 (boom); no path for robot 1 (it never connected to robot 1's port)")
    assert robots_phrase([4]) == "robot 4" and robots_phrase([0, 2, 3]) == "robots 0, 2 and 3"


def test_preflight_of_a_multi_robot_program_job(client):
    body = {"environment": "swap", "robots": LANES, "modes": ["sim"]}
    r = client.post("/api/v1/experiments", json={**body, "program": 999999})
    assert r.status_code == 422 and r.json()["detail"] == "unknown program 999999", r.text
    prog = upload(client, "unused", STRAIGHT.format(order=[0, 1, 2]))
    inside = [LANES[0], {"start": [1.5, 1.79], "goal": [0.3, 1.3]}]
    r = client.post("/api/v1/experiments", json={**body, "robots": inside, "program": prog})
    assert r.status_code == 422 and r.json()["detail"].startswith("robots[1].start: start"), r.text
    r = client.post("/api/v1/experiments", json={**body, "program": prog, "planner": "fmm"})
    assert r.status_code == 422 and "give either `planner` or `program`, not both" in r.text, r.text
    r = client.post("/api/v1/experiments", json={**body, "program": prog, "controller_program": prog})
    assert r.status_code == 422 and "controller_program: a controller program drives one robot" in r.text, r.text


def test_the_example_roundabout_passes_the_swap_through_the_sdk(testbed):
    with Client(testbed.url, testbed.token) as c:
        prog = c.upload_program(ROOT / "examples" / "fleet" / "roundabout.py")
        exp = c.wait(c.submit("swap", robots=SWAP["robots"], program=prog.id, modes=["sim"], seed=1).id,
                     timeout=120, progress=False)
        assert exp.status == "completed" and exp.program == prog.id, exp
        m = exp.runs[0].metrics
        assert m["success_rate"] == 1.0 and m["robot_distance_min_m"] > 2 * RADIUS and not m["collided"], m
        for k, r in enumerate(SWAP["robots"]):
            mine = c.get_poses(exp.runs[0].id, robot=k)
            assert np.hypot(*(mine[-1, 1:3] - r["goal"][:2])) < 0.02


def test_the_docs_commands_upload_and_submit_a_fleet_program(testbed, twb):
    """docs/uploads.md, "Multi-robot jobs": its console block, run as written from the checkout."""
    block = re.search(r"<!-- fleet-console -->\s*```console\n(.*?)```", DOCS.read_text(), re.S).group(1)
    commands = [ln[2:] for ln in block.splitlines() if ln.startswith("$ ")]
    assert commands[0] == "twb upload examples/fleet/roundabout.py"
    env = {"TWB_URL": testbed.url, "TWB_TOKEN": testbed.token}
    up = twb(*commands[0].split()[1:], env=env, cwd=ROOT)
    assert up.returncode == 0, up.stderr
    shown = re.search(r"Uploaded program (\d+): ", block).group(1)
    got = re.search(r"Uploaded program (\d+): roundabout\.py, python, \d+ bytes", up.stdout).group(1)
    submitted = twb(*commands[1].replace(shown, got).split()[1:], env=env, cwd=ROOT)
    assert submitted.returncode == 0, submitted.stderr
    assert re.search(r"experiment \d+: completed \(1/1 runs completed\)", submitted.stderr), submitted.stderr
