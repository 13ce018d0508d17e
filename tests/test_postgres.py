"""The testbed on PostgreSQL: end to end through `twb up`, the database going away and coming back, a wrong
database at start, and the concurrency that SQLite serialised (the server on a real PostgreSQL server
started by the test fixtures, tests/pg_support.py)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from servers import Process, wait_for

JOB = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fm2",
       "modes": ["sim", "twb"], "repetitions": 2, "seed": 1}
ONE_BLOCK = {"name": "one-block", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.3, "h": 0.3}]}
SLOW_JOB = {"environment": "one-block", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 0.0], "planner": "fmm"}


@pytest.mark.slow
def test_a_job_runs_end_to_end_on_postgresql(postgres, tmp_path):
    url = postgres.database()
    p = Process(["up", "--time-scale", "max", "--sim-robots", "2", "--database-url", url], tmp_path)
    try:
        with p.client() as c:
            done = wait_for(c, c.post("/api/v1/experiments", json=JOB).json()["id"], timeout=90)
            assert done["status"] == "completed", done
            twb = next(r for r in done["runs"] if r["mode"] == "twb")
            poses = c.get(f"/api/v1/runs/{twb['id']}/poses").json()
            assert poses["count"] > 100 and np.all(np.diff(np.array(poses["poses"])[:, 0]) >= 0)
            metrics = c.get(f"/api/v1/experiments/{done['id']}/metrics").json()
            assert metrics["outcomes"]["twb"]["success"]["rate"] == 1.0 and len(metrics["direct"]) == 2
            assert not (tmp_path / "twb.db").exists()  # the store is PostgreSQL, not a SQLite file
    finally:
        assert p.stop() == 0, p.output()


@pytest.mark.slow
def test_the_same_seed_gives_the_same_poses_on_sqlite_and_postgresql(postgres, tmp_path):
    job = {**JOB, "modes": ["twb"], "repetitions": 1, "seed": 42}
    found = {}
    for kind in ("sqlite", "postgresql"):
        extra = ["--database-url", postgres.database()] if kind == "postgresql" else []
        p = Process(["up", "--time-scale", "max", "--sim-robots", "1", *extra], tmp_path / kind)
        try:
            with p.client() as c:
                run = wait_for(c, c.post("/api/v1/experiments", json=job).json()["id"], timeout=90)["runs"][0]
                found[kind] = (np.array(c.get(f"/api/v1/runs/{run['id']}/poses").json()["poses"])[:, 1:],
                               run["metrics"])
        finally:
            p.stop()
    (a, ma), (b, mb) = found["sqlite"], found["postgresql"]
    assert a.shape == b.shape and np.array_equal(a, b)  # stored as sent: the same floats
    assert {k: v for k, v in ma.items() if k != "planning_time_s"} == \
        {k: v for k, v in mb.items() if k != "planning_time_s"}


@pytest.mark.slow
def test_the_database_going_away_mid_run_loses_nothing(postgres, tmp_path):
    """Kill PostgreSQL while runs drive: the API answers 503, the runs in flight are queued again once the
    database is back, and the experiment completes; nothing completed before is lost."""
    url = postgres.database()
    p = Process(["up", "--time-scale", "4", "--sim-robots", "1", "--database-url", url], tmp_path)
    try:
        with p.client() as c:
            assert c.post("/api/v1/environments", json=ONE_BLOCK).status_code == 201
            exp = c.post("/api/v1/experiments", json={**SLOW_JOB, "modes": ["sim"], "repetitions": 3}).json()
            deadline = time.monotonic() + 60
            while c.get(f"/api/v1/experiments/{exp['id']}").json()["runs"][0]["status"] != "running":
                assert time.monotonic() < deadline
                time.sleep(0.1)
            postgres.crash()
            try:
                time.sleep(2.0)
                r = c.get(f"/api/v1/experiments/{exp['id']}")
                assert r.status_code in (200, 503), r.text  # 200: a finished view from memory
                if r.status_code == 503:
                    assert r.json()["detail"] == "the database is unreachable; try again shortly"
                assert c.get("/health").status_code == 200  # the server itself lives on
                time.sleep(3.0)
            finally:
                postgres.start()
            done = wait_for(c, exp["id"], timeout=120)
            assert [r["status"] for r in done["runs"]] == ["completed"] * 3, done["runs"]
            assert all(r["metrics"]["goal_reached"] for r in done["runs"])
    finally:
        assert p.stop() == 0, p.output()
    assert "Traceback" not in p.output(), p.output()


def test_a_database_that_is_not_there_at_start_is_one_clear_line(postgres, twb, tmp_path):
    url = postgres.database().rsplit("/", 1)[0] + "/no_such_database"
    r = twb("server", "--port", "0", "--data-dir", str(tmp_path), "--database-url", url, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith("twb: error: cannot use the database at postgresql+psycopg://twb@")
    assert "no_such_database" in r.stderr and "Traceback" not in r.stderr


@pytest.fixture(scope="module")
def pg_server(postgres, tmp_path_factory):
    p = Process(["server", "--database-url", postgres.database("concurrency")], tmp_path_factory.mktemp("pgsrv"))
    yield p
    assert p.stop() == 0
    assert "Traceback" not in p.output(), p.output()


@pytest.mark.slow
def test_two_requests_cancelling_the_same_experiment(pg_server):
    with pg_server.client() as c:
        ids = [c.post("/api/v1/experiments", json={**JOB, "modes": ["sim"]}).json()["id"] for _ in range(6)]
    answers: list[tuple[int, int]] = []
    go = threading.Barrier(12)

    def cancel(eid: int) -> None:
        with pg_server.client() as c:
            go.wait()
            answers.append((eid, c.post(f"/api/v1/experiments/{eid}/cancel").status_code))

    threads = [threading.Thread(target=cancel, args=(eid,)) for eid in ids for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert len(answers) == 12 and all(code in (200, 409) for _, code in answers), answers
    with pg_server.client() as c:
        for eid in ids:
            e = c.get(f"/api/v1/experiments/{eid}").json()
            assert e["status"] == "cancelled" and {r["status"] for r in e["runs"]} == {"cancelled"}


@pytest.mark.slow
def test_tracker_batches_from_many_clients_at_once(pg_server):
    with pg_server.client() as admin:
        token = admin.post("/api/v1/users/admin/tokens", params={"kind": "agent"}).json()["token"]
    with pg_server.client(token) as agent:
        assert agent.post("/api/v1/robots", json={"robot_id": "pg-bot", "host": "127.0.0.1", "port": 9,
                                                  "backend": "ideal"}).status_code == 201
    codes: list[int] = []

    def post(i: int) -> None:
        with pg_server.client(token) as agent:
            rows = [[i + k / 100, 0.1, 0.1, 0.0] for k in range(500)]
            codes.append(agent.post("/api/v1/tracker/poses", json={"robot_id": "pg-bot", "poses": rows}).status_code)

    threads = [threading.Thread(target=post, args=(i,)) for i in range(16)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert codes == [200] * 16


def test_a_runs_log_goes_in_by_each_databases_bulk_path_and_reads_back_as_written(run_store):
    """COPY on PostgreSQL, executemany on SQLite: program output with tabs, newlines, backslashes, quotes and
    non-ASCII text, untimed lines and estimated times come back as they were, in order."""
    from sqlalchemy import select

    from server.models import Message
    from server.store.runs import add_messages

    sessions = run_store
    lines = [(">", "T,T,P,0.3,0.3,0;1.5,1.5,0", 0.02, False), ("o", "a\ttab\\back\nnew 'q' \"dq\" \\N", None, False),
             ("e", "Fehler: Größe ≠ 0 — ✓", 1.5, True), ("<", "EV,DONE,12.34", 12.34, False)]
    with sessions.begin() as s:
        add_messages(s, [{"run_id": 1, "t": t, "t_estimated": est, "direction": d, "line": line}
                         for d, line, t, est in lines])
    with sessions() as s:
        got = [(m.direction, m.line, m.t, m.t_estimated) for m in s.scalars(select(Message).order_by(Message.id))]
    assert got == lines


def test_a_failed_bulk_write_is_sqlalchemys_error_on_each_database(run_store):
    """The COPY paths use the driver directly; what the database refuses there (or a connection lost mid-COPY)
    comes out as SQLAlchemy's DBAPIError, as from every other statement: the callers that make an unreachable
    database a 503, a waiting run end or a queued-again run catch that, not psycopg's own errors."""
    from sqlalchemy import text
    from sqlalchemy.exc import DBAPIError

    from server.store.poses import add_obstacle_poses, add_poses
    from server.store.runs import add_messages

    writes = [lambda s: add_poses(s, 999, np.zeros((3, 4))),
              lambda s: add_obstacle_poses(s, 999, [np.zeros((2, 4))]),
              lambda s: add_messages(s, [{"run_id": 999, "t": 0.0, "t_estimated": False, "direction": ">",
                                          "line": "T,T,Q"}])]
    for write in writes:  # a read-only transaction: the database refuses the rows
        with pytest.raises(DBAPIError, match="read-only|readonly"):
            with run_store.begin() as s:
                sqlite = s.connection().dialect.name == "sqlite"
                s.execute(text("PRAGMA query_only = 1" if sqlite else "SET TRANSACTION READ ONLY"))
                try:
                    write(s)
                finally:
                    if sqlite:
                        s.execute(text("PRAGMA query_only = 0"))


def test_a_tracker_batch_cut_off_mid_copy_is_one_clear_error(postgres, monkeypatch, caplog):
    """The database drops the connection of a tracker batch's COPY (as when it goes away mid-run): the caller
    gets the database's own reason as SQLAlchemy's error, the pool drops that connection rather than reset it
    (the reset's traceback in the server's output, seen in CI), and the next batch goes in."""
    import logging

    import psycopg
    from sqlalchemy import text
    from sqlalchemy.exc import OperationalError

    from server.core.db import make_engine, migrate
    from server.store import poses

    url = postgres.database()
    engine = make_engine(url)
    migrate(engine)
    copy = poses._copy

    def cut_first(pg, *args):
        with psycopg.connect(url.replace("+psycopg", ""), autocommit=True) as admin:
            admin.execute("SELECT pg_terminate_backend(%s)", (pg.info.backend_pid,))
        monkeypatch.setattr(poses, "_copy", copy)
        return copy(pg, *args)

    monkeypatch.setattr(poses, "_copy", cut_first)
    lock = threading.Lock()
    try:
        with caplog.at_level(logging.DEBUG, logger="sqlalchemy.pool"):
            with pytest.raises(OperationalError, match="terminating connection"):
                poses.insert_poses(engine, 7, np.zeros((50, 4)), lock=lock)
            poses.insert_poses(engine, 7, np.ones((3, 4)), lock=lock)
        assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text
        with engine.connect() as conn:
            assert conn.execute(text("SELECT count(*) FROM poses WHERE run_id = 7")).scalar() == 3
    finally:
        engine.dispose()
