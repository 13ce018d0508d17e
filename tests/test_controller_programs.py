"""Uploaded controller programs on a real `twb up --enable-uploads --time-scale 2`: the planned path in,
T,T,V out over the sandbox's robot port; good ones complete, bad ones fail with the reason.

Every program is uploaded and submitted at once, so the bad ones run side by side with the good ones.
"""

from __future__ import annotations

import base64
import os
import random
import shutil
import subprocess
from pathlib import Path

import pytest

from servers import TOKEN, TWB, wait_for

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples" / "controllers"
START, GOAL = [0.3, 0.3, 0.0], [1.5, 0.6, 0.0]
UID_BASE = 3_100_000 + random.randrange(0, 800) * 1000
LIMITS = {"TWB_SANDBOX_WALL_S": "60", "TWB_SANDBOX_CPU_S": "20", "TWB_SANDBOX_WORKERS": "8",
          "TWB_SANDBOX_UID_BASE": str(UID_BASE)}

CONNECT = """
import os, socket, sys, time
s = socket.create_connection((os.environ["TWB_ROBOT_HOST"], int(os.environ["TWB_ROBOT_PORT"])))
f = s.makefile("rw", newline="\\n")
print(f.readline().strip())
"""
SILENT = CONNECT + "time.sleep(50)\n"
GARBAGE = CONNECT + """
for line in ("hello robot", "T,T,V,fast,0", "T,T,P,300,300,0;1500,600,0", "T,T,X"):
    f.write(line + "\\n"); f.flush()
    print(f.readline().strip())
time.sleep(50)
"""
CRASH = CONNECT + "f.write('T,T,O,1\\n'); f.flush(); raise SystemExit(3)\n"
INTO_THE_WALL = CONNECT + """
f.write("T,T,O,1\\n"); f.flush()
for line in f:
    if line.startswith("EV,FAIL"):
        print(line.strip()); break
    if line.startswith("PO,"):
        f.write("T,T,V,-150,0\\n"); f.flush()  # backwards, out of the field
"""


def b64(data: str | bytes) -> str:
    return base64.b64encode(data.encode() if isinstance(data, str) else data).decode()


@pytest.fixture(scope="module")
def testbed(testbeds):  # its own: uploads, eight simulated robots at twice live speed, the programs' limits
    yield from testbeds.own("up", "--time-scale", "2", "--sim-robots", "8", "--enable-uploads", env=LIMITS)


@pytest.fixture(scope="module")
def client(testbed):
    with testbed.client() as c:
        assert c.post("/api/v1/environments", json={"name": "open", "size": [1.8, 1.8], "blocks": []}).status_code == 201
        yield c


def upload(client, name: str, content: str | bytes, kind: str = "python") -> int:
    r = client.post("/api/v1/programs", json={"name": name, "kind": kind, "content_base64": b64(content)})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def submit(client, program: int, modes: tuple[str, ...] = ("sim",), **extra) -> int:
    r = client.post("/api/v1/experiments", json={"environment": "open", "start": START, "goal": GOAL,
                                                 "controller_program": program, "modes": list(modes), **extra})
    assert r.status_code == 202, r.text
    return r.json()["id"]


def runs(client, exp_id: int) -> list[dict]:
    return client.get(f"/api/v1/experiments/{exp_id}").json()["runs"]


def log(client, run_id: int) -> str:
    return "\n".join(m["line"] for m in client.get(f"/api/v1/runs/{run_id}/messages?limit=5000").json()["data"])


def c_controller(out: Path) -> bytes:
    """examples/controllers/p_controller.c built with the machine's cc (static where the C library allows)."""
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler (cc) on this machine to build examples/controllers/p_controller.c")
    src, exe = str(EXAMPLES / "p_controller.c"), str(out / "p_controller")
    if subprocess.run([cc, "-O2", "-static", "-o", exe, src, "-lm"], capture_output=True).returncode != 0:
        subprocess.run([cc, "-O2", "-o", exe, src, "-lm"], check=True)
    return Path(exe).read_bytes()


def test_controller_programs_drive_or_fail_with_the_reason(client):
    python = upload(client, "p_controller.py", (EXAMPLES / "p_controller.py").read_text())
    bad = {name: upload(client, name, src) for name, src in
           (("silent", SILENT), ("garbage", GARBAGE), ("crash", CRASH), ("wall", INTO_THE_WALL))}
    good = submit(client, python, modes=("sim", "twb"))
    failing = {name: submit(client, pid) for name, pid in bad.items()}

    exp = wait_for(client, good, timeout=240)
    assert exp["status"] == "completed", (exp, [(r["error"], log(client, r["id"])[-3000:]) for r in runs(client, good)])
    assert exp["controller_program"] == python and exp["controller"] == "schema"
    for run in runs(client, good):
        assert run["status"] == "completed" and run["metrics"]["goal_reached"], run
        m = run["metrics"]  # the program's compute cost per control step
        assert m["controller_steps"] > 10 and m["controller_cpu_s"] > 0, m
        assert m["controller_cpu_per_step_ms"] == pytest.approx(1000 * m["controller_cpu_s"] / m["controller_steps"],
                                                                rel=1e-3)
        assert 0 < m["controller_response_ms_median"] <= m["controller_response_ms_p95"]
        # the sandbox's report (the program may still be reading when the run ends and the sandbox ends it)
        assert m["controller_program"]["id"] == python and m["controller_program"]["wall_s"] > 0, m
        text = log(client, run["id"])
        assert "robot port < T,T,O,1" in text and "T,T,V," in text and "T,T,P" not in text.split("program")[-1]

    reasons = {}
    for name, exp_id in failing.items():
        exp = wait_for(client, exp_id, timeout=240)
        (run,) = runs(client, exp_id)
        assert exp["status"] == "failed" and run["status"] == "failed", (name, run)
        reasons[name] = (run["failure"], run["error"], log(client, run["id"]))
    assert reasons["silent"][:2] == ("program", "watchdog: the controller program sent no T,T,V for 0.5 s of "
                                                "experiment time (the robot stopped)")
    assert reasons["garbage"][1].startswith("watchdog:")
    for refusal in ("ERR,SYNTAX", "ERR,UNSUPPORTED,a controller program drives with T,T,V"):
        assert refusal in reasons["garbage"][2]
    assert reasons["crash"][:2] == ("program", "program crashed: exit code 3")
    silent = runs(client, failing["silent"])[0]["metrics"]  # a failed run is measured too: it never answered
    assert silent["controller_steps"] == 0 and silent["controller_response_ms_median"] is None
    assert reasons["wall"][0] == "collision", reasons["wall"][:2]


def test_a_c_controller_completes_a_job(client, tmp_path):
    binary = c_controller(tmp_path)
    program = upload(client, "p_controller", binary, kind="executable")
    exp = wait_for(client, submit(client, program), timeout=240)
    assert exp["status"] == "completed", [(r["error"], log(client, r["id"])[-3000:]) for r in runs(client, exp["id"])]


def test_bad_controller_program_requests_name_the_field(client):
    python = upload(client, "p_controller.py", (EXAMPLES / "p_controller.py").read_text())
    body = {"environment": "open", "start": START, "goal": GOAL, "modes": ["sim"]}
    r = client.post("/api/v1/experiments", json={**body, "controller_program": python, "controller": "pure_pursuit"})
    assert r.status_code == 422 and "controller_program" in r.text, r.text
    r = client.post("/api/v1/experiments", json={**body, "controller_program": 99999})
    assert r.status_code == 422 and "controller_program: unknown program 99999" in r.text, r.text


def test_the_sdk_and_the_cli_name_a_controller_program(testbed, client):
    from client_sdk import Client

    with Client(testbed.url, TOKEN) as twb:
        prog = twb.upload_program(EXAMPLES / "p_controller.py")
        exp = twb.wait(twb.submit("open", START, GOAL, modes=["sim"], controller_program=prog.id).id, timeout=240)
    assert exp.status == "completed" and exp.controller_program == prog.id
    env = {**os.environ, "TWB_URL": testbed.url, "TWB_TOKEN": TOKEN}
    out = subprocess.run([str(TWB), "submit", "--env", "open", "--start", "0.3,0.3,0", "--goal", "1.5,0.6,0",
                          "--modes", "sim", "--controller-program", str(prog.id), "--wait"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0 and "completed (1/1 runs completed)" in out.stderr, out.stdout + out.stderr
    exp = client.get(f"/api/v1/experiments/{int(out.stdout)}").json()
    assert exp["status"] == "completed" and exp["controller_program"] == prog.id


#: two obstacle robots away from the way from START to GOAL (neither meets the robot)
MOVERS = {"name": "program-movers", "size": [1.8, 1.8], "blocks": [], "moving_obstacles": [
    {"radius": 0.04, "waypoints": [[1.1, 1.1], [1.5, 1.1], [1.5, 1.5]], "speed": 0.1, "repeat": "pingpong"},
    {"radius": 0.05, "waypoints": [[0.3, 1.5], [0.3, 1.1]], "speed": 0.08, "delay_s": 1.0}]}


def test_a_programs_field_run_is_seeded_and_stores_its_obstacle_robots(client):
    """The robot's velocity mode takes the job's noise seed as a path does, so the server replays the obstacle
    robots the emulated field drove for the program's run: they are stored with the run (not the exact tracks),
    equal to the replay of its seed bit for bit, and the log does not claim they could not be replayed."""
    import numpy as np

    from robot_agent.engine import jobs

    assert client.post("/api/v1/environments", json=MOVERS).status_code == 201
    python = upload(client, "p_controller.py", (EXAMPLES / "p_controller.py").read_text())
    r = client.post("/api/v1/experiments", json={"environment": MOVERS["name"], "start": START, "goal": GOAL,
                                                 "controller_program": python, "modes": ["twb"], "seed": 7})
    assert r.status_code == 202, r.text
    exp = wait_for(client, r.json()["id"], timeout=240)
    (run,) = runs(client, exp["id"])
    assert run["status"] == "completed", (run, log(client, run["id"])[-3000:])
    assert "cannot be replayed" not in log(client, run["id"])
    got = client.get(f"/api/v1/runs/{run['id']}/obstacles").json()
    assert got["exact"] is False and [o["index"] for o in got["obstacles"]] == [0, 1], got
    replay = jobs.field_obstacle_tracks(MOVERS, run["seed"], "BeBot", run["t_start"], run["t_end"])
    for o, tr in zip(got["obstacles"], replay):
        assert o["count"] > 50 and np.array_equal(np.array(o["poses"]), tr), o["index"]
    assert run["metrics"]["obstacle_distance_min_m"] > 0.3
