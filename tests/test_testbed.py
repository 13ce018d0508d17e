"""The whole testbed (`twb up`) as users run it: jobs through the REST API to robots and back."""

import signal
import time

import numpy as np
import pytest

from servers import STANDARD, EventListener, Process, wait_for

JOB = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fm2",
       "modes": ["sim", "twb"], "repetitions": 2, "seed": 1}


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


@pytest.fixture(scope="module")
def client(testbed):
    with testbed.client() as c:
        yield c


def test_robots_register_and_subfields_show_them(client):
    robots = client.get("/api/v1/robots").json()["data"]
    field = sorted(r["robot_id"] for r in robots if r["pool"] == "field")
    assert field == ["field-1", "field-2", "field-3", "field-4"]
    assert sum(r["pool"] == "sim" for r in robots) == 2
    subs = client.get("/api/v1/subfields").json()["data"]
    assert [s["robot_id"] for s in subs] == field
    assert [s["origin"] for s in subs] == [[0, 0], [1.8, 0], [0, 1.8], [1.8, 1.8]]


def test_a_job_runs_in_sim_and_on_the_field_with_metrics(client):
    # what each sub-field holds before (the worker's shared testbed may have built the room on some already)
    built_before = {s["robot_id"]: s["environment"] for s in client.get("/api/v1/subfields").json()["data"]}
    exp = client.post("/api/v1/experiments", json=JOB).json()
    done = wait_for(client, exp["id"], timeout=90)
    assert done["status"] == "completed", done
    assert done["planned_path"][0][:2] == [0.3, 0.3] and done["planning_time_s"] > 0
    runs = done["runs"]
    assert [r["status"] for r in runs] == ["completed"] * 4
    for r in runs:
        m = r["metrics"]
        assert m["goal_reached"] is True and m["collided"] is False
        assert m["execution_time_s"] > 5 and 0.05 < m["average_speed_m_s"] < 0.25
        assert 0 <= m["deviation_mean_m"] < 0.05
        assert r["t_end"] > r["t_start"]
        assert (r["subfield"] is None) == (r["mode"] == "sim")
    # the field is the emulated physical one: noisier and longer than the ideal simulation
    sim = [r["metrics"] for r in runs if r["mode"] == "sim"]
    twb = [r["metrics"] for r in runs if r["mode"] == "twb"]
    assert sim[0]["length_m"] == pytest.approx(sim[1]["length_m"], abs=1e-6)  # ideal: replayable
    assert min(m["length_m"] for m in twb) > max(m["length_m"] for m in sim)

    metrics = client.get(f"/api/v1/experiments/{exp['id']}/metrics").json()
    assert set(metrics["aggregates"]) == {"sim", "twb"}
    assert metrics["aggregates"]["twb"]["metrics"]["length_m"]["n"] == 2
    assert [d["repetition"] for d in metrics["direct"]] == [1, 2]
    assert metrics["direct"][0]["deviation_mean_m"] > 0
    assert metrics["planned"]["length_m"] > 1.5

    twb_run = next(r for r in runs if r["mode"] == "twb")
    poses = client.get(f"/api/v1/runs/{twb_run['id']}/poses").json()
    assert poses["count"] > 100
    arr = np.array(poses["poses"])
    assert np.all(np.diff(arr[:, 0]) >= 0)
    csv = client.get(f"/api/v1/runs/{twb_run['id']}/poses", params={"format": "csv"}).text.splitlines()
    assert csv[0] == "t,x,y,theta" and len(csv) == poses["count"] + 1
    lines = [m["line"] for m in client.get(f"/api/v1/runs/{twb_run['id']}/messages").json()["data"]]
    assert lines[0].startswith("HELLO,field-")
    # built once per sub-field: a twb run had the gripper build the room unless its sub-field already held it (from
    # an earlier run of this job, or of another module on the shared testbed)
    holds = {robot: env == JOB["environment"] for robot, env in built_before.items()}
    for r in sorted((r for r in runs if r["mode"] == "twb"), key=lambda r: r["started_at"]):
        built = any(m["line"].startswith("T,T,B,")
                    for m in client.get(f"/api/v1/runs/{r['id']}/messages").json()["data"])
        assert built == (not holds[r["robot_id"]]), (r["id"], r["robot_id"], built_before)
        holds[r["robot_id"]] = True
    assert any(line.startswith("T,T,P,300,300,") for line in lines)
    assert "OK,P," in " ".join(lines) and any(line.startswith("EV,DONE,") for line in lines)


def test_two_jobs_run_in_parallel_on_two_subfields_with_camera_rate_poses(testbeds):
    # its own testbed, at time scale 4: at the module's "max" the first job's run can end before the second job's
    # plan is ready (on a loaded machine), and the second then rightly takes the same sub-field
    for testbed in testbeds.own("up", "--time-scale", "4", "--sim-robots", "1"):
        with testbed.client() as client:
            _two_jobs_in_parallel(client)


def _two_jobs_in_parallel(client) -> None:  # type: ignore[no-untyped-def]
    job = {**JOB, "modes": ["twb"], "repetitions": 1}
    a = client.post("/api/v1/experiments", json=job).json()
    b = client.post("/api/v1/experiments", json={**job, "environment": "blocks", "start": [0.15, 0.15, 0.0],
                                                   "goal": [1.65, 1.65, 0.0]}).json()
    ra, rb = (wait_for(client, e["id"], timeout=180)["runs"][0] for e in (a, b))
    assert ra["status"] == rb["status"] == "completed"
    assert ra["subfield"] != rb["subfield"]
    assert ra["started_at"] < rb["finished_at"] and rb["started_at"] < ra["finished_at"]  # overlapping
    for r in (ra, rb):
        n = client.get(f"/api/v1/runs/{r['id']}/poses").json()["count"]
        rate = n / r["metrics"]["execution_time_s"]
        assert 25 <= rate <= 31, rate  # a 30 Hz camera, a few dropouts


def test_same_seed_replays_exactly(client):
    job = {**JOB, "modes": ["twb"], "repetitions": 1, "seed": 42}
    a = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=60)
    b = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=60)
    pa = client.get(f"/api/v1/runs/{a['runs'][0]['id']}/poses").json()["poses"]
    pb = client.get(f"/api/v1/runs/{b['runs'][0]['id']}/poses").json()["poses"]
    xa, xb = np.array(pa)[:, 1:], np.array(pb)[:, 1:]
    assert xa.shape == xb.shape and np.array_equal(xa, xb)
    other = wait_for(client, client.post("/api/v1/experiments", json={**job, "seed": 43}).json()["id"], timeout=60)
    pc = np.array(client.get(f"/api/v1/runs/{other['runs'][0]['id']}/poses").json()["poses"])[:, 1:]
    assert pc.shape != xa.shape or not np.array_equal(pc, xa)


def test_explicit_path_and_full_field_jobs(client):
    path = {"environment": "room", "path": [[0.3, 0.3], [0.45, 0.6], [0.45, 1.35], [1.5, 1.35], [1.5, 1.5]],
            "modes": ["sim", "twb"]}
    done = wait_for(client, client.post("/api/v1/experiments", json=path).json()["id"], timeout=60)
    assert done["status"] == "completed", done
    assert done["planned_path"][1][:2] == [0.45, 0.6]
    env = {"name": "full-open-field", "size": [3.6, 3.6], "blocks": [{"x": 1.8, "y": 1.8, "w": 0.4, "h": 0.4}]}
    assert client.post("/api/v1/environments", json=env).status_code == 201
    full = {"environment": "full-open-field", "start": [0.5, 1.8, 0.0], "goal": [3.1, 1.8, 0.0], "planner": "fmm",
            "modes": ["twb", "sim"], "field": "full"}
    done = wait_for(client, client.post("/api/v1/experiments", json=full).json()["id"], timeout=60)
    assert done["status"] == "completed", [(r["mode"], r["status"], r["error"]) for r in done["runs"]]
    twb = next(r for r in done["runs"] if r["mode"] == "twb")
    assert twb["robot_id"] == "field-1" and twb["subfield"] is None
    assert twb["metrics"]["length_m"] > 2.6
    sub = {**JOB, "environment": "full-open-field"}
    r = client.post("/api/v1/experiments", json=sub)
    assert r.status_code == 422 and 'use "field": "full"' in r.json()["detail"]


def test_a_path_grazing_a_block_collides_on_the_field_for_some_seeds(client):
    """Explicit paths need only the robot radius; at 5 cm from a corner the field robot's noise decides."""
    env = {"name": "graze", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.3, "h": 0.3}]}
    assert client.post("/api/v1/environments", json=env).status_code == 201
    path = [[0.3, 0.7], [1.1, 0.7], [1.1, 1.4]]  # 5 cm below the block, round its corner, 5 cm beside it
    outcomes = []
    for seed in range(8):
        e = client.post("/api/v1/experiments", json={"environment": "graze", "path": path, "modes": ["twb"],
                                                     "seed": seed}).json()
        done = wait_for(client, e["id"], timeout=60)
        run = done["runs"][0]
        outcomes.append(run["status"])
        m = run["metrics"]
        assert m["length_m"] > 0.2  # measured either way: a failed run's driving is data too
        if run["status"] == "failed":
            assert run["error"] == "collision: the robot hit an obstacle" and run["failure"] == "collision"
            # the robot's own verdict; its logged path ends at the tracker's last frame before the contact, up to
            # 0.1 s earlier (30 Hz, a dropped frame): within that much travel at 0.2 m/s of the collision radius
            assert m["collided"] is True and m["clearance_min_m"] < 0.04 + 0.2 * 0.1
            assert m["goal_reached"] is False
            x, y = run["stopped_at"]  # where it touched: at the block (0.75..1.05 x 0.75..1.05)
            gap = ((max(0.75 - x, 0, x - 1.05)) ** 2 + (max(0.75 - y, 0, y - 1.05)) ** 2) ** 0.5
            assert gap < 0.06, run["stopped_at"]
            assert done["error"] == f"1 of 1 runs failed: collision at ({x:.2f}, {y:.2f})"
            summary = client.get(f"/api/v1/experiments/{e['id']}/metrics").json()
            assert summary["outcomes"]["twb"]["counts"] == {"collision": 1}
            assert summary["outcomes"]["twb"]["success"]["rate"] == 0.0
            assert summary["runs"][0]["outcome"] == "collision" and summary["runs"][0]["metrics"]["collided"]
        else:
            assert run["status"] == "completed" and m["collided"] is False and m["goal_reached"] is True
            assert run["failure"] is None and run["stopped_at"] is None and done["error"] == ""
    assert "failed" in outcomes and "completed" in outcomes, outcomes


def test_planning_failure_fails_the_job_with_the_reason(client):
    job = {**JOB, "planner": "prm", "planner_params": {"samples": 2, "k": 1, "grow": False}}
    done = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=60)
    assert done["status"] == "failed"
    assert all(r["status"] == "failed" for r in done["runs"])
    assert "planning failed: PRM found no path" in done["runs"][0]["error"]
    assert "PRM found no path" in done["error"]


def test_live_event_stream(testbed, client):
    listener = EventListener(testbed.url, testbed.token,
                             until=lambda e: e["event"] == "experiment" and e["experiment"]["status"] == "completed")
    exp = client.post("/api/v1/experiments", json={**JOB, "modes": ["sim"], "repetitions": 1}).json()
    listener.join(60)
    seen = listener.seen
    kinds = {e["event"] for e in seen}
    assert {"run", "experiment", "pose"} <= kinds
    states = [e["run"]["status"] for e in seen if e["event"] == "run" and e["run"]["experiment_id"] == exp["id"]]
    assert states[:4] == ["building", "placing", "planning", "running"] and states[-1] == "completed"


ONE_BLOCK = {"name": "one-block", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.3, "h": 0.3}]}
SLOW_JOB = {"environment": "one-block", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 0.0], "planner": "fmm"}


@pytest.mark.slow
def test_cancel_a_running_job(tmp_path):
    p = Process(["up", "--time-scale", "5", "--sim-robots", "1"], tmp_path)
    try:
        with p.client() as c:
            assert c.post("/api/v1/environments", json=ONE_BLOCK).status_code == 201
            exp = c.post("/api/v1/experiments", json={**SLOW_JOB, "modes": ["twb"]}).json()
            wait_for(c, exp["id"], timeout=60, terminal={"running"})
            r = c.post(f"/api/v1/experiments/{exp['id']}/cancel")
            assert r.status_code == 200
            done = wait_for(c, exp["id"], timeout=30)
            assert done["status"] == "cancelled" and done["runs"][0]["status"] == "cancelled"
            lines = [m["line"] for m in c.get(f"/api/v1/runs/{done['runs'][0]['id']}/messages").json()["data"]]
            assert "EV,DONE" not in " ".join(lines)
            # the robot is free again: another job completes on it
            again = c.post("/api/v1/experiments", json={**SLOW_JOB, "modes": ["twb"], "goal": [0.6, 0.5]}).json()
            assert wait_for(c, again["id"], timeout=60)["status"] == "completed"
    finally:
        p.stop()


@pytest.mark.slow
def test_a_server_killed_mid_run_resumes_the_run_and_keeps_the_queue(tmp_path):
    p = Process(["up", "--time-scale", "2", "--sim-robots", "1"], tmp_path)
    with p.client() as c:
        assert c.post("/api/v1/environments", json=ONE_BLOCK).status_code == 201
        exp = c.post("/api/v1/experiments", json={**SLOW_JOB, "modes": ["sim"], "repetitions": 3}).json()
        first = wait_for(c, exp["id"], timeout=60, terminal={"running"})["runs"][0]["id"]
        deadline = time.monotonic() + 30
        while not c.get(f"/api/v1/runs/{first}/messages").json()["count"]:  # the path went out, logged
            assert time.monotonic() < deadline
            time.sleep(0.05)
    p.stop(signal.SIGKILL)
    again = Process(["server"], tmp_path)  # no robots: everything waits, nothing is lost
    try:
        with again.client() as c:
            e = c.get(f"/api/v1/experiments/{exp['id']}").json()
            assert [r["status"] for r in e["runs"]] == ["queued", "queued", "queued"]
            assert e["runs"][0]["error"] == "resumed: the testbed stopped during an earlier try"
            assert e["runs"][0]["attempt"] == 1  # not a retry: the robot was not at fault
            lines = [m["line"] for m in c.get(f"/api/v1/runs/{e['runs'][0]['id']}/messages").json()["data"]]
            assert any(line.startswith("T,T,P,") for line in lines)  # the interrupted try's log stays
    finally:
        again.stop()
    back = Process(["up", "--time-scale", "max", "--sim-robots", "1"], tmp_path)
    try:
        with back.client() as c:
            e = wait_for(c, exp["id"], timeout=60)
            assert [r["status"] for r in e["runs"]] == ["completed", "completed", "completed"]
            assert e["status"] == "completed"
    finally:
        back.stop()


@pytest.mark.slow
def test_without_resuming_interrupted_runs_stay_interrupted(tmp_path):
    p = Process(["up", "--time-scale", "2", "--sim-robots", "1"], tmp_path, env={"TWB_RESUME_INTERRUPTED": "0"})
    with p.client() as c:
        assert c.post("/api/v1/environments", json=ONE_BLOCK).status_code == 201
        exp = c.post("/api/v1/experiments", json={**SLOW_JOB, "modes": ["sim"], "repetitions": 2}).json()
        wait_for(c, exp["id"], timeout=60, terminal={"running"})
    p.stop(signal.SIGKILL)
    again = Process(["server"], tmp_path, env={"TWB_RESUME_INTERRUPTED": "0"})
    try:
        with again.client() as c:
            e = c.get(f"/api/v1/experiments/{exp['id']}").json()
            assert [r["status"] for r in e["runs"]] == ["interrupted", "queued"]
            assert "server stopped" in e["runs"][0]["error"] and e["status"] == "queued"
    finally:
        again.stop()


@pytest.mark.slow
def test_a_robot_dying_mid_run_is_an_error_retried_once_on_another_robot(tmp_path):
    import subprocess

    from servers import TOKEN, TWB

    server = Process(["server", "--time-scale", "5"], tmp_path / "server")
    agents = {}
    try:
        for name in ("solo-a", "solo-b"):
            agents[name] = subprocess.Popen(
                [str(TWB), "agent", "--port", "0", "--robot-id", name, "--backend", "ideal", "--time-scale", "5",
                 "--area", "3.6,3.6", "--server", server.url, "--token", TOKEN],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        with server.client() as c:
            deadline = time.monotonic() + 30
            while len(c.get("/api/v1/robots").json()["data"]) < 2:
                assert time.monotonic() < deadline, "agents did not register"
                time.sleep(0.2)
            exp = c.post("/api/v1/experiments", json={**JOB, "modes": ["sim"], "repetitions": 1}).json()
            running = wait_for(c, exp["id"], timeout=60, terminal={"running"})
            victim = running["runs"][0]["robot_id"]
            agents[victim].kill()
            done = wait_for(c, exp["id"], timeout=90)
            run = done["runs"][0]
            assert done["status"] == "completed", run
            assert run["attempt"] == 2 and run["robot_id"] != victim
            assert run["error"].startswith("attempt 1: robot " + victim)
            robots = {r["robot_id"]: r["status"] for r in c.get("/api/v1/robots").json()["data"]}
            assert robots[victim] == "offline"
            # with no working robot left the run waits, queued, for one to come back: nothing is lost; a robot
            # that cannot be connected to costs the run no try (it did not begin)
            agents[run["robot_id"]].kill()
            agents[run["robot_id"]].wait()  # its port is closed: connecting is refused
            exp2 = c.post("/api/v1/experiments", json={**JOB, "modes": ["sim"], "repetitions": 1}).json()
            deadline = time.monotonic() + 60
            while "cannot connect" not in (r2 := c.get(f"/api/v1/experiments/{exp2['id']}").json()["runs"][0])["error"]:
                assert time.monotonic() < deadline, r2
                time.sleep(0.2)
            assert r2["status"] == "queued" and r2["attempt"] == 1 and r2["error"].startswith("resumed: robot solo-")
            agents["solo-c"] = subprocess.Popen(
                [str(TWB), "agent", "--port", "0", "--robot-id", "solo-c", "--backend", "ideal", "--time-scale", "5",
                 "--area", "3.6,3.6", "--server", server.url, "--token", TOKEN],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            done2 = wait_for(c, exp2["id"], timeout=60)
            assert done2["status"] == "completed" and done2["runs"][0]["robot_id"] == "solo-c"
    finally:
        for a in agents.values():
            a.kill()
        server.stop()


def test_planners_robot_positions_and_incremental_poses(client):
    planners = {p["name"]: p for p in client.get("/api/v1/planners").json()["data"]}
    assert {"fmm", "fm2", "prm", "astar"} <= set(planners)
    assert planners["prm"]["defaults"] == {"samples": 500, "k": 10, "grow": True, "max_samples": 50_000,
                                           "time_budget_s": 0.5, "prm_star": False}
    job = {**JOB, "modes": ["twb"], "repetitions": 1, "seed": 5}
    run = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=60)["runs"][0]
    robot = next(r for r in client.get("/api/v1/robots").json()["data"] if r["robot_id"] == run["robot_id"])
    t, x, y, _ = robot["last_pose"]  # field coordinates: the sub-field's origin is added
    sub = client.get("/api/v1/subfields").json()["data"][run["subfield"] - 1]
    assert abs(x - (sub["origin"][0] + 1.5)) < 0.05 and abs(y - (sub["origin"][1] + 1.5)) < 0.05
    assert sub["state"] == "idle" and sub["run_id"] is None
    poses = client.get(f"/api/v1/runs/{run['id']}/poses").json()["poses"]
    middle = poses[len(poses) // 2][0]
    later = client.get(f"/api/v1/runs/{run['id']}/poses", params={"after_t": middle}).json()
    assert later["count"] == sum(p[0] > middle for p in poses) and later["poses"][0][0] > middle


def test_the_robots_ports_refuse_strangers(client):
    """Anyone on the machine can reach a robot's port; only the testbed moves the robot or builds."""
    import socket

    robots = {r["robot_id"]: r for r in client.get("/api/v1/robots").json()["data"]}
    for rid in ("field-2", "sim-1"):
        with socket.create_connection((robots[rid]["host"], robots[rid]["port"]), timeout=10) as sock:
            f = sock.makefile("rwb")
            assert f.readline().startswith(b"HELLO,")
            for line in (b"T,T,B,900,900,100000000,100000000,0", b"T,T,P,300,300,0", b"T,T,S", b"T,T,I,500,500,0",
                         b"T,T,A,not-the-key-of-this-robot"):
                f.write(line + b"\n")
                f.flush()
                assert f.readline().startswith(b"ERR,AUTH"), line
            f.write(b"T,T,Q\n")
            f.flush()
            assert f.readline().startswith(b"ST,")  # looking is allowed


def test_a_user_follows_only_their_own_runs_live(testbed, client):
    user = client.post("/api/v1/users", json={"name": "watcher"}).json()["token"]
    listener = EventListener(testbed.url, user)
    exp = client.post("/api/v1/experiments", json={**JOB, "repetitions": 1}).json()  # the admin's
    wait_for(client, exp["id"], timeout=60)
    listener.stop()
    listener.join(20)  # it returns at the next line: an event or the 15 s heartbeat
    seen = listener.seen
    assert any(e["event"] == "subfield" for e in seen)  # the field's own events do arrive
    assert not [e for e in seen if e["event"] in ("run", "experiment")]
    assert not [e for e in seen if e["event"] == "pose" and e["run_id"] is not None]
    assert not [e for e in seen if "owner_id" in e]
    assert all(e["subfield"]["run_id"] is None and e["subfield"]["last_run_id"] is None
               for e in seen if e["event"] == "subfield")
    with testbed.client(token=user) as c:
        assert all(s["run_id"] is None and s["last_run_id"] is None for s in c.get("/api/v1/subfields").json()["data"])
