"""The REST API of a real `twb server` process (no robots needed for these)."""

import json

import pytest
from sqlalchemy import create_engine, text

from servers import Process

pytestmark = pytest.mark.slow  # every test here is against the real `twb server` of the module's fixture

JOB = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fm2",
       "modes": ["sim", "twb"], "repetitions": 2, "seed": 3}


@pytest.fixture(scope="module", params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def server(request, tmp_path_factory):
    """`twb server` on each store: its SQLite default, and PostgreSQL (the session's, a fresh database)."""
    data = tmp_path_factory.mktemp("server")
    url = f"sqlite:///{data / 'twb.db'}" if request.param == "sqlite" else request.getfixturevalue("postgres").database()
    p = Process(["server", "--database-url", url], data)
    p.store = create_engine(url)  # the tests look into the store itself
    yield p
    p.stop()
    p.store.dispose()


@pytest.fixture(scope="module")
def alice(server):
    with server.client() as admin:
        token = admin.post("/api/v1/users", json={"name": "alice"}).json()["token"]
    with server.client(token) as c:
        yield c


@pytest.fixture(scope="module")
def bob(server):
    with server.client() as admin:
        token = admin.post("/api/v1/users", json={"name": "bob"}).json()["token"]
    with server.client(token) as c:
        yield c


def test_health_is_open_and_the_token_file_is_written(server):
    with server.client(token=None) as c:
        assert c.get("/health").json()["status"] == "ok"
    assert (server.data_dir / "token").read_text().strip() == server.token
    with server.store.connect() as con:
        assert con.execute(text("select count(*) from users")).scalar() >= 1


def test_meta_serves_the_one_run_vocabulary_without_a_token(server):
    """The dashboard's statuses and outcomes come from here: the contract's own lists, in its order."""
    from contract.vocabulary import JOB_OUTCOMES, NOT_COUNTED, TERMINAL, FailureKind, Mode, RunStatus

    with server.client(token=None) as c:
        v = c.get("/api/v1/meta").json()["vocabulary"]
    assert v["modes"] == ["sim", "twb"] == [m.value for m in Mode]
    assert v["statuses"] == [s.value for s in RunStatus] and v["statuses"][0] == "queued"
    assert set(v["terminal"]) == set(TERMINAL) and v["judged"] == ["completed", "failed"]
    assert v["failure_kinds"] == [k.value for k in FailureKind]
    assert v["job_outcomes"] == list(JOB_OUTCOMES) and v["not_counted"] == list(NOT_COUNTED)


def test_auth_errors(server):
    with server.client(token=None) as c:
        r = c.get("/api/v1/experiments")
        assert r.status_code == 401 and r.json() == {"detail": "Missing bearer token"}
    with server.client(token="nope") as c:
        assert c.get("/api/v1/experiments").json() == {"detail": "Invalid token"}


def test_tokens_are_stored_hashed(server, alice):
    with server.store.connect() as con:
        hashes = [h for (h,) in con.execute(text("select token_hash from tokens"))]
    assert server.token not in hashes and all(len(h) == 64 for h in hashes)


def test_users_admin_only(server, alice):
    assert alice.get("/api/v1/users").status_code == 403
    assert alice.get("/api/v1/users/me").json()["name"] == "alice"
    with server.client() as admin:
        assert admin.post("/api/v1/users", json={"name": "alice"}).status_code == 409
        assert admin.post("/api/v1/users", json={"name": "a b"}).status_code == 422


def test_environments(alice, bob):
    names = [e["name"] for e in alice.get("/api/v1/environments").json()["data"]]
    assert {"room", "blocks"} <= set(names)
    room = alice.get("/api/v1/environments/room").json()
    assert room["builtin"] and len(room["plans"]) == 2
    mine = {"name": "alice-corridor", "size": [1.8, 1.8],
            "blocks": [{"x": 0.9, "y": 0.6, "w": 1.2, "h": 0.05, "angle": 0.0}]}
    r = alice.post("/api/v1/environments", json=mine)
    assert r.status_code == 201, r.text
    assert r.json()["owner"] == "alice"
    r = alice.post("/api/v1/environments", json=mine)
    assert r.status_code == 409 and r.json()["detail"] == "you already have an environment named 'alice-corridor'"
    assert bob.get("/api/v1/environments/alice-corridor").status_code == 404  # not his
    # bob may use the same name: nothing tells him that alice's exists, and each gets their own
    bobs = {**mine, "blocks": [{"x": 0.9, "y": 1.2, "w": 1.2, "h": 0.05, "angle": 0.0}]}
    assert bob.post("/api/v1/environments", json=bobs).status_code == 201
    assert bob.get("/api/v1/environments/alice-corridor").json()["blocks"][0]["y"] == 1.2
    assert alice.get("/api/v1/environments/alice-corridor").json()["blocks"][0]["y"] == 0.6
    r = bob.post("/api/v1/experiments", json={**JOB, "environment": "alice-corridor", "start": [0.3, 0.3],
                                              "goal": [1.5, 0.3], "modes": ["sim"], "repetitions": 1})
    assert r.status_code == 202 and r.json()["environment"] == "alice-corridor"
    assert r.json()["owner"] == "bob"
    bob.post(f"/api/v1/experiments/{r.json()['id']}/cancel")
    r = alice.post("/api/v1/environments", json={**mine, "name": "room"})
    assert r.status_code == 409 and "built-in" in r.json()["detail"]
    big = {"name": "too-big", "size": [5.0, 5.0], "blocks": []}
    r = alice.post("/api/v1/environments", json=big)
    assert r.status_code == 422 and r.json()["detail"].startswith("size: the environment is 5 x 5 m; the field is 3.6")
    for name in ("..", ".hidden", "-dash"):
        assert alice.post("/api/v1/environments", json={**mine, "name": name}).status_code == 422, name
    bad = {**mine, "name": "bad-env", "blocks": [{"x": 0.9, "y": 0.6, "w": -1, "h": 0.05}]}
    r = alice.post("/api/v1/environments", json=bad)
    assert r.status_code == 422 and r.json()["detail"] == "blocks[0].w: Input should be greater than 0"
    assert alice.get("/api/v1/environments/nowhere").status_code == 404


def test_submit_returns_202_with_runs_and_others_get_404(alice, bob):
    r = alice.post("/api/v1/experiments", json=JOB)
    assert r.status_code == 202, r.text
    exp = r.json()
    assert exp["status"] == "queued" and exp["owner"] == "alice"
    assert [(x["mode"], x["repetition"]) for x in exp["runs"]] == [("sim", 1), ("twb", 1), ("sim", 2), ("twb", 2)]
    assert len({x["seed"] for x in exp["runs"]}) == 4
    eid = exp["id"]
    assert alice.get(f"/api/v1/experiments/{eid}").json()["id"] == eid
    assert bob.get(f"/api/v1/experiments/{eid}").status_code == 404
    assert bob.post(f"/api/v1/experiments/{eid}/cancel").status_code == 404
    assert all(e["id"] != eid for e in bob.get("/api/v1/experiments").json()["data"])
    listed = alice.get("/api/v1/experiments", params={"status": "queued"}).json()
    assert listed["count"] >= 1 and listed["data"][0]["id"] == eid
    run_id = exp["runs"][0]["id"]
    assert bob.get(f"/api/v1/runs/{run_id}/poses").status_code == 404
    assert alice.get(f"/api/v1/runs/{run_id}/poses").json()["count"] == 0
    assert alice.get("/api/v1/runs/999999/poses").status_code == 404
    assert alice.get("/api/v1/experiments/999999").status_code == 404
    # cancel, then cancelling again is a state conflict
    c = alice.post(f"/api/v1/experiments/{eid}/cancel")
    assert c.status_code == 200 and c.json()["status"] == "cancelled"
    assert all(x["status"] == "cancelled" for x in c.json()["runs"])
    assert alice.post(f"/api/v1/experiments/{eid}/cancel").status_code == 409


@pytest.mark.parametrize(
    "change, status, message",
    [
        ({"environment": "nowhere"}, 422, "unknown environment 'nowhere'"),
        ({"start": [0.9, 0.5, 0.0]}, 422, r"start \(0.9, 0.5\) is inside an obstacle"),
        ({"goal": [2.5, 0.5]}, 422, r"goal \(2.5, 0.5\) is outside the field"),
        ({"planner": "rrt"}, 422, "unknown planner 'rrt'"),
        ({"planner_params": {"saturation": -1.0}}, 422, None),
        ({"planner_params": {"bogus": 1}}, 422, "has no parameter 'bogus'"),
        ({"modes": ["sim", "sim"]}, 422, "modes must not repeat"),
        ({"modes": ["real"]}, 422, "modes.0"),
        ({"repetitions": 0}, 422, "repetitions"),
        ({"repetitions": 1000}, 422, "repetitions must be at most"),
        ({"seed": -1}, 422, "seed"),
        ({"field": "half"}, 422, "field"),
        ({"start": [0.3]}, 422, r"must be \[x, y\] or \[x, y, theta\]"),
        ({"extra": 1}, 422, "extra"),
        ({"controller": "mpc"}, 422, "controller: unknown controller 'mpc'"),
        ({"controller": "pure_pursuit", "controller_params": {"lookahead_m": 9}}, 422,
         r"controller_params.lookahead_m must be a number in \[0.02, 1\] \(m\)"),
        ({"controller_params": {"gain": 1}}, 422, "controller_params.gain: controller 'schema' has no parameter"),
        ({"controller": "regulated_pure_pursuit", "controller_params": {"replan": 2}}, 422,
         r"controller_params.replan must be an integer in \[0, 1\] \(0\|1\), got 2"),
        ({"controller": "regulated_pure_pursuit", "controller_params": {"replan": 0.5}}, 422,
         r"controller_params.replan must be an integer in \[0, 1\] \(0\|1\), got 0.5"),
        ({"controller": "regulated_pure_pursuit", "controller_params": {"replan": 1, "replan_horizon_s": 99}}, 422,
         r"controller_params.replan_horizon_s must be a number in \[0.5, 30\] \(s\)"),
        ({"controller": "kanayama", "controller_params": {"replan": 1, "lookahead_m": 0.1}}, 422,
         "controller_params.lookahead_m: controller 'kanayama' has no parameter 'lookahead_m'"),
    ],
)
def test_preflight_refuses_bad_jobs_with_a_reason(alice, change, status, message):
    import re

    r = alice.post("/api/v1/experiments", json={**JOB, **change})
    assert r.status_code == status, r.text
    if message:
        assert re.search(message, r.json()["detail"]), r.json()["detail"]


def test_controllers_are_listed_chosen_stored_and_shown(alice):
    listed = alice.get("/api/v1/controllers").json()
    names = [c["name"] for c in listed["data"]]
    assert names[:4] == ["schema", "pure_pursuit", "regulated_pure_pursuit", "kanayama"]
    rpp = {p["name"]: p for p in listed["data"][2]["parameters"]}
    assert rpp["replan"]["default"] == 0 and rpp["replan"]["integer"] and rpp["replan_horizon_s"]["unit"] == "s"
    pp = listed["data"][1]
    assert pp["compiled"] and pp["parameters"][0] == {
        "name": "lookahead_m", "unit": "m", "default": 0.06, "range": [0.02, 1.0],
        "description": pp["parameters"][0]["description"]}
    r = alice.post("/api/v1/experiments", json={**JOB, "controller": "pure_pursuit",
                                               "controller_params": {"lookahead_m": 0.1}})
    assert r.status_code == 202, r.text
    exp = alice.get(f"/api/v1/experiments/{r.json()['id']}").json()
    assert exp["controller"] == "pure_pursuit"
    assert exp["controller_params"] == {"lookahead_m": 0.1, "speed_m_s": 0.2, "rotate_to_heading_rad": 1.2,
                                        "replan": 0, "replan_horizon_s": 3.0, "replan_min_interval_s": 1.0}
    listed = alice.get("/api/v1/experiments").json()["data"]
    assert next(e for e in listed if e["id"] == exp["id"])["controller"] == "pure_pursuit"
    default = alice.post("/api/v1/experiments", json=JOB).json()
    assert default["controller"] == "schema"  # the motor schema's gains are the profile's; its only parameters:
    assert default["controller_params"] == {"replan": 0, "replan_horizon_s": 3.0, "replan_min_interval_s": 1.0}
    for eid in (exp["id"], default["id"]):
        alice.post(f"/api/v1/experiments/{eid}/cancel")


def test_explicit_paths(alice):
    ok = {"environment": "room", "path": [[0.3, 0.3], [0.45, 0.6], [0.45, 1.35], [1.5, 1.35], [1.5, 1.5]],
          "modes": ["sim"]}
    r = alice.post("/api/v1/experiments", json=ok)
    assert r.status_code == 202, r.text
    assert r.json()["planner"] is None and r.json()["start"] == [0.3, 0.3]
    alice.post(f"/api/v1/experiments/{r.json()['id']}/cancel")
    through_wall = {"environment": "room", "path": [[0.3, 0.3], [1.5, 0.3]], "modes": ["sim"]}
    r = alice.post("/api/v1/experiments", json=through_wall)
    assert r.status_code == 422 and "path segment 0" in r.json()["detail"]
    both = {**ok, "planner": "fmm"}
    assert alice.post("/api/v1/experiments", json=both).status_code == 422


def test_invalid_json_nan_and_huge_bodies(alice):
    r = alice.post("/api/v1/experiments", content=b"{not json", headers={"content-type": "application/json"})
    assert r.status_code == 422
    nan = json.dumps({**JOB, "start": [0.3, 0.3, 0.0]}).replace("0.3, 0.3, 0.0", "NaN, 0.3, 0.0")
    r = alice.post("/api/v1/experiments", content=nan.encode(), headers={"content-type": "application/json"})
    assert r.status_code == 422 and "start" in r.json()["detail"]
    huge = b'{"environment": "' + b"x" * (13 << 20) + b'"}'
    r = alice.post("/api/v1/experiments", content=huge, headers={"content-type": "application/json"})
    assert r.status_code == 413 and "larger than" in r.json()["detail"]

    def chunks():
        yield b'{"environment": "'
        for _ in range(13):  # the body limit is 12 MiB
            yield b"x" * (1 << 20)
        yield b'"}'

    r = alice.post("/api/v1/experiments", content=chunks(), headers={"content-type": "application/json"})
    assert r.status_code == 413


def test_tracker_ingestion_needs_an_agent_token(server, alice):
    batch = {"robot_id": "r1", "poses": [[0.0, 0.1, 0.1, 0.0]]}
    assert alice.post("/api/v1/tracker/poses", json=batch).status_code == 403
    with server.client() as admin:
        r = admin.post("/api/v1/users/alice/tokens", params={"kind": "agent"})
        agent_token = r.json()["token"]
    robot = {"robot_id": "r1", "host": "127.0.0.1", "port": 9, "backend": "ideal"}
    with server.client(agent_token) as agent:
        r = agent.post("/api/v1/tracker/poses", json=batch)
        assert r.status_code == 404 and "register it" in r.json()["detail"]
        assert agent.post("/api/v1/robots", json=robot).status_code == 201
        r = agent.post("/api/v1/tracker/poses", json=batch)
        assert r.status_code == 200
        assert r.json() == {"received": 1, "accepted": 1, "rejected": 0, "stored": 0, "run_id": None}
        mixed = '{"robot_id": "r1", "poses": [[0.0, 0.1, 0.1, 0.0], [0.1, NaN, 0.1, 0.0], [0.2, 0.1], [0.3, 1, 1, 1]]}'
        r = agent.post("/api/v1/tracker/poses", content=mixed, headers={"content-type": "application/json"})
        assert r.status_code == 200 and (r.json()["accepted"], r.json()["rejected"]) == (2, 2)
        booleans = {"robot_id": "r1", "poses": [[True, 0.1, 0.1, 0.0], [0.3, 1, 1, False], [0.4, 1, 1, 1]]}
        r = agent.post("/api/v1/tracker/poses", json=booleans)  # true is not 1.0
        assert r.status_code == 200 and (r.json()["accepted"], r.json()["rejected"]) == (1, 2)
        bad = agent.post("/api/v1/tracker/poses", json={"robot_id": "r1", "poses": "nope"})
        assert bad.status_code == 422 and "poses" in bad.json()["detail"]
        # agent tokens are for agents only
        assert agent.get("/api/v1/experiments").status_code == 403


def test_quota(server, tmp_path):
    with server.client() as admin:
        token = admin.post("/api/v1/users", json={"name": "greedy"}).json()["token"]
    with server.client(token) as c:
        codes = [c.post("/api/v1/experiments", json={**JOB, "modes": ["sim"]}).status_code for _ in range(3)]
    assert codes == [202, 202, 202]  # the server's limit is 200; this checks the counting path only


def test_twb_users_commands(server, twb):
    env = {"TWB_URL": server.url, "TWB_TOKEN": server.token}
    out = twb("users", "create", "carol", env=env)
    assert out.returncode == 0, out.stderr
    token = out.stdout.strip()
    with server.client(token) as c:
        assert c.get("/api/v1/users/me").json()["name"] == "carol"
    listing = twb("users", "list", env=env)
    assert "carol" in listing.stdout.split() and "admin (admin)" in listing.stdout
    again = twb("users", "create", "carol", env=env)
    assert again.returncode == 2 and "already exists" in again.stderr
    refused = twb("users", "list", env={"TWB_URL": server.url, "TWB_TOKEN": token})
    assert refused.returncode == 2 and "Admin only" in refused.stderr


def test_environments_with_moving_obstacles_round_trip_and_bad_ones_are_422(alice):
    ob = {"radius": 0.04, "waypoints": [[0.2, 1.2], [0.8, 1.2]], "speed": 0.05, "repeat": "pingpong", "delay_s": 1.5}
    walk = {"radius": 0.03, "speed": 0.1, "repeat": "loop",
            "random_walk": {"seed": 7, "start": [0.5, 0.5], "steps": 4, "step_m": 0.2}}
    env = {"name": "alice-moving", "size": [1.8, 1.8], "blocks": [], "moving_obstacles": [ob, walk]}
    r = alice.post("/api/v1/environments", json=env)
    assert r.status_code == 201, r.text
    got = alice.get("/api/v1/environments/alice-moving").json()
    assert got["moving_obstacles"] == [ob, {**walk, "delay_s": 0.0}]  # stored normalised: defaults spelt out
    for bad, detail in (({**ob, "speed": 5.0}, "moving_obstacles[0].speed must be in (0, 0.3] m/s"),
                        ({**ob, "waypoints": [[0.2, 1.2], [1.9, 1.2]]}, "moving_obstacles[0].waypoints[1]"),
                        ({**ob, "radius": 0}, "moving_obstacles[0].radius must be in (0, 0.25] m"),
                        ({**ob, "colour": "red"}, "moving_obstacles[0] has unknown key 'colour'")):
        r = alice.post("/api/v1/environments", json={**env, "name": "alice-bad", "moving_obstacles": [bad]})
        assert r.status_code == 422 and r.json()["detail"].startswith(detail), r.text
    assert alice.get("/api/v1/environments/room").json()["moving_obstacles"] == []
    crossing = alice.get("/api/v1/environments/crossing").json()
    assert crossing["builtin"] and len(crossing["moving_obstacles"]) == 2
    # a start where a disc stands when the path begins is the job's mistake, refused before any run
    r = alice.post("/api/v1/experiments", json={**JOB, "environment": "crossing", "start": [0.22, 1.2],
                                               "goal": [1.5, 1.5], "planner": "st_astar"})
    assert r.status_code == 422, r.text
    assert r.json()["detail"] == ("start (0.22, 1.2) is closer than the robot radius 0.045 m to moving obstacle 0 "
                                  "(moving_obstacles[0]) when the path starts")
