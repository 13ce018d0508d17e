"""Who can reach what on a real `twb server` (docs/security.md): agent tokens bound to their robots,
robot registrations validated, private files, rate-limited token guessing, the quota under concurrency,
what the live stream shows to whom.  Each of these was broken once (the hardening issue)."""

from __future__ import annotations

import socket
import stat
import threading
import time

import numpy as np
import pytest

from server.access import event_for
from server.core.security import Principal
from servers import Process, wait_for

JOB = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fm2",
       "modes": ["sim"], "repetitions": 1, "seed": 3}


@pytest.fixture(scope="module")
def server(testbeds):
    yield from testbeds.own("server")  # its own: the tests count its users' tokens and queued experiments


def agent_token(server, user: str) -> str:
    with server.client() as admin:
        admin.post("/api/v1/users", json={"name": user})
        return admin.post(f"/api/v1/users/{user}/tokens", params={"kind": "agent"}).json()["token"]


def robot(robot_id: str, host: str = "127.0.0.1", port: int = 9) -> dict:
    return {"robot_id": robot_id, "host": host, "port": port, "backend": "ideal", "area": [3.6, 3.6]}


def test_agent_tokens_are_bound_to_the_robots_they_registered(server):
    alice, bob = agent_token(server, "alice-agent"), agent_token(server, "bob-agent")
    batch = {"robot_id": "bound-1", "poses": [[0.0, 0.1, 0.1, 0.0]]}
    with server.client(alice) as a, server.client(bob) as b, server.client() as admin:
        assert a.post("/api/v1/robots", json=robot("bound-1")).status_code == 201
        assert a.post("/api/v1/robots", json=robot("bound-1", port=10)).status_code == 201  # its own again
        r = b.post("/api/v1/robots", json=robot("bound-1", port=11))
        assert r.status_code == 403 and "another token" in r.json()["detail"]
        r = b.post("/api/v1/tracker/poses", json=batch)
        assert r.status_code == 403 and "another token" in r.json()["detail"]
        assert a.post("/api/v1/tracker/poses", json=batch).status_code == 200
        assert admin.post("/api/v1/tracker/poses", json=batch).status_code == 200
        ports = {r["robot_id"]: r["port"] for r in admin.get("/api/v1/robots").json()["data"]}
        assert ports["bound-1"] == 10  # bob's registration changed nothing


@pytest.mark.parametrize("host, stored", [
    ("bücher.example", "xn--bcher-kva.example"), ("10.0.0.7", "10.0.0.7"), ("::1", "::1"), ("agent-1", "agent-1"),
])
def test_robot_host_names_are_stored_in_ascii(server, host, stored):
    with server.client() as admin:
        r = admin.post("/api/v1/robots", json=robot("named", host=host))
        assert r.status_code == 201 and r.json()["host"] == stored


@pytest.mark.parametrize("host", ["http://agent:5555", "agent:5555", "agent/x", "a b", "-agent", "", "x" * 254])
def test_robot_host_names_with_url_syntax_are_refused(server, host):
    with server.client() as admin:
        r = admin.post("/api/v1/robots", json=robot("badly-named", host=host))
        assert r.status_code == 422 and r.json()["detail"].startswith("host"), r.json()


def test_an_unreachable_robot_goes_offline_with_its_reason_and_nothing_sticks(server):
    closed = socket.socket()
    closed.bind(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()  # nobody listens there
    with server.client() as admin:
        assert admin.post("/api/v1/robots", json=robot("ghost", port=port)).status_code == 201
        exp = admin.post("/api/v1/experiments", json=JOB).json()
        # the other robots of this module are not there either: each is tried, goes offline with its reason,
        # and the run, which never began, waits queued without spending its retry
        deadline = time.monotonic() + 60
        while (robots := {r["robot_id"]: r for r in admin.get("/api/v1/robots").json()["data"]})["ghost"]["status"] \
                != "offline" or admin.get("/health").json()["running_runs"]:
            assert time.monotonic() < deadline, robots
            time.sleep(0.2)
        assert "cannot connect" in robots["ghost"]["status_reason"]
        run = admin.get(f"/api/v1/experiments/{exp['id']}").json()["runs"][0]
        assert run["status"] == "queued" and run["attempt"] == 1 and "cannot connect" in run["error"], run
        assert run["error"].startswith("resumed: robot ")
        assert admin.post(f"/api/v1/experiments/{exp['id']}/cancel").status_code == 200  # nothing sticks
        assert wait_for(admin, exp["id"], timeout=30)["status"] == "cancelled"


def test_the_data_directory_and_the_database_are_private(server):
    assert stat.S_IMODE(server.data_dir.stat().st_mode) == 0o700
    for name in ("twb.db", "token"):
        assert stat.S_IMODE((server.data_dir / name).stat().st_mode) == 0o600, name


def test_health_tells_a_stranger_only_that_it_lives(server):
    with server.client(token=None) as stranger, server.client("twb_wrong-token-for-health") as guesser:
        assert stranger.get("/health").json() == {"status": "ok", "version": "1"}
        assert guesser.get("/health").json() == {"status": "ok", "version": "1"}
    with server.client() as admin:
        assert {"queued_runs", "running_runs", "field_robots", "sim_robots"} <= set(admin.get("/health").json())


def test_a_malformed_body_is_answered_401_without_a_token(server):
    bodies = (b"{not json", b"\xff\xfe", b'{"environment": "r\xc3\x28"}')  # not JSON, UTF-16 garbage, not UTF-8
    with server.client(token=None) as stranger:
        for body in bodies:
            r = stranger.post("/api/v1/experiments", content=body, headers={"content-type": "application/json"})
            assert r.status_code == 401, r.text
    with server.client() as admin:
        for body in bodies:
            r = admin.post("/api/v1/experiments", content=body, headers={"content-type": "application/json"})
            assert r.status_code == 422 and r.json()["detail"].startswith("body is not valid JSON"), r.text


def test_numbers_beyond_64_bits_are_refused_not_crashed_on(server):
    with server.client() as admin:
        for path in ("/api/v1/experiments/9223372036854775808", "/api/v1/runs/99999999999999999999999",
                     "/api/v1/environments?offset=12081837017022664704"):
            r = admin.get(path)
            assert r.status_code == 422, (path, r.status_code, r.text)


@pytest.mark.slow
def test_the_quota_holds_under_concurrent_submissions(tmp_path):
    server = Process(["server"], tmp_path, env={"TWB_MAX_QUEUED_PER_USER": "3"})  # no robots: all stay queued
    try:
        with server.client() as admin:
            token = admin.post("/api/v1/users", json={"name": "hasty"}).json()["token"]
        codes: list[int] = []
        go = threading.Barrier(12)

        def submit() -> None:
            with server.client(token) as c:
                go.wait()
                codes.append(c.post("/api/v1/experiments", json=JOB).status_code)

        threads = [threading.Thread(target=submit) for _ in range(12)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        assert sorted(codes) == [202] * 3 + [429] * 9  # the limit is 3 queued experiments: never one more
    finally:
        server.stop()


def test_many_experiments_are_cancelled_in_one_request(server):
    with server.client() as admin:
        token = admin.post("/api/v1/users", json={"name": "canceller"}).json()["token"]
    with server.client(token) as c, server.client() as admin:
        ids = [c.post("/api/v1/experiments", json=JOB).json()["id"] for _ in range(3)]
        others = admin.post("/api/v1/experiments", json=JOB).json()["id"]  # not hers
        r = c.post("/api/v1/experiments/cancel", json={"ids": [*ids, others, 10**12]})
        assert r.status_code == 200
        assert r.json()["cancelled"] == ids
        assert r.json()["not_cancelled"] == [{"id": others, "reason": "not found"},
                                             {"id": 10**12, "reason": "not found"}]
        for i in ids:
            assert wait_for(c, i, timeout=10)["status"] == "cancelled"
        again = c.post("/api/v1/experiments/cancel", json={"ids": ids[:1]}).json()
        assert again == {"cancelled": [], "not_cancelled": [{"id": ids[0], "reason": "already cancelled"}]}
        admin.post(f"/api/v1/experiments/{others}/cancel")


@pytest.mark.slow
def test_unknown_tokens_are_limited_per_client(tmp_path):
    p = Process(["server"], tmp_path, env={"TWB_AUTH_FAILURES_PER_MINUTE": "5"})
    try:
        with p.client() as admin:  # a token in use keeps working (it is known)
            assert admin.get("/api/v1/users/me").status_code == 200
            for i in range(5):
                with p.client(f"twb_guess-number-{i:04d}-of-many") as guess:
                    assert guess.get("/api/v1/users/me").status_code == 401
            with p.client("twb_guess-number-0005-of-many") as guess:
                r = guess.get("/api/v1/users/me")
            assert r.status_code == 429 and int(r.headers["retry-after"]) > 0
            assert admin.get("/api/v1/users/me").status_code == 200
    finally:
        p.stop()


USER = Principal(id=7, name="u", is_admin=False, kind="user")
ADMIN = Principal(id=1, name="admin", is_admin=True, kind="admin")


@pytest.mark.parametrize("event, shown", [
    ({"type": "run", "owner_id": 7, "run": {"id": 1}}, {"type": "run", "owner_id": 7, "run": {"id": 1}}),
    ({"type": "run", "owner_id": 8, "run": {"id": 2}}, None),
    ({"type": "experiment", "owner_id": 8, "experiment": {"id": 2}}, None),
    ({"type": "pose", "robot_id": "f", "run_id": 3, "owner_id": 8, "x": 1.0}, None),
    ({"type": "pose", "robot_id": "f", "run_id": 3, "owner_id": 7, "x": 1.0},
     {"type": "pose", "robot_id": "f", "run_id": 3, "owner_id": 7, "x": 1.0}),
    ({"type": "pose", "robot_id": "f", "run_id": None, "owner_id": None, "x": 1.0},
     {"type": "pose", "robot_id": "f", "run_id": None, "x": 1.0}),
    ({"type": "subfield", "owner_id": 8, "subfield": {"id": 2, "run_id": 5}},
     {"type": "subfield", "subfield": {"id": 2, "run_id": None}}),
    ({"type": "subfield", "owner_id": 7, "subfield": {"id": 2, "run_id": 5}},
     {"type": "subfield", "subfield": {"id": 2, "run_id": 5}}),
    # the last run since the start: named only to its owner, whoever's run is there now
    ({"type": "subfield", "owner_id": None, "last_owner_id": 8, "subfield": {"id": 2, "run_id": None, "last_run_id": 4}},
     {"type": "subfield", "subfield": {"id": 2, "run_id": None, "last_run_id": None}}),
    ({"type": "subfield", "owner_id": None, "last_owner_id": 7, "subfield": {"id": 2, "run_id": None, "last_run_id": 4}},
     {"type": "subfield", "subfield": {"id": 2, "run_id": None, "last_run_id": 4}}),
    ({"type": "robot", "robot_id": "f"}, {"type": "robot", "robot_id": "f"}),
])
def test_the_live_stream_shows_a_user_only_what_is_theirs(event, shown):
    assert event_for(USER, event) == shown
    assert event_for(ADMIN, event) == event


@pytest.mark.parametrize("body, accepted, received", [
    (b'{"robot_id": "r", "poses": [[0, 1, 2, 3], [0.5, 1e-3, -2, 3.25]]}', 2, 2),
    (b'{"robot_id": "r", "poses": [[0, 1, 2, 3], [true, 1, 2, 3], [0, 1, 2, false]]}', 1, 3),
    (b'{"robot_id": "r", "poses": [[0, 1, 2, 3], ["1.0", 1, 2, 3], [0, 1, null, 3]]}', 1, 3),  # numpy takes "1.0"
    (b'{"poses": [[0, 1, 2, 3], [1, "2", 3, 4]], "robot_id": "r"}', 1, 2),  # the key order does not matter
    (b'{"robot_id": "r", "poses": [[0, 1, 2, 3], [1, 2, 3], [1, 2, 3, 4, 5], {}]}', 1, 4),
    (b'{"robot_id": "r", "poses": [[0, NaN, 2, 3], [0, 1, 2, Infinity], [1, 1, 1, 1]]}', 1, 3),
    (b'{"robot_id": "poses", "poses": [[true, 1, 2, 3]]}', 0, 1),
])
def test_tracker_rows_are_four_numbers_and_nothing_else(body, accepted, received):
    from server.tracking import parse_batch

    robot_id, rows, n = parse_batch(body)
    assert robot_id in ("r", "poses") and rows.shape == (accepted, 4) and n == received
    assert np.isfinite(rows).all()
