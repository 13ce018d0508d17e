"""The SDK against a real testbed process (`twb up --time-scale max`), sync and async; errors; send_path."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import httpx
import numpy as np
import pytest

import client_sdk
from client_sdk import (
    AsyncClient,
    Client,
    Conflict,
    Experiment,
    NotFound,
    RateLimited,
    TooLarge,
    TransportError,
    TwbError,
    Unauthorized,
    ValidationError,
    WaitTimeout,
    send_path,
)
from sdk_helpers import agent_process
from servers import STANDARD

JOB = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fm2",
       "modes": ["sim", "twb"], "repetitions": 1, "seed": 3}


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


@pytest.fixture(scope="module")
def done(testbed):
    """One completed sim + twb experiment, shared by the read-only tests."""
    with Client(testbed.url, testbed.token) as c:
        return c.wait(c.submit(JOB).id, timeout=120, progress=False)


def test_public_api_is_sorted_and_importable():
    assert client_sdk.__all__ == sorted(client_sdk.__all__)
    for name in client_sdk.__all__:
        assert hasattr(client_sdk, name), name


def test_sdk_imports_no_server_code():
    code = "import sys, client_sdk, client_sdk.study; print(sorted(m for m in sys.modules if m.split('.')[0] == 'server'))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_submit_wait_results_poses_messages(testbed, done):
    assert isinstance(done, Experiment) and done.status == "completed"
    assert done.runs_done == done.runs_total == 2
    assert done.planned_path.shape[1] == 3 and done.planned_path[0, :2].tolist() == [0.3, 0.3]
    with Client(testbed.url, testbed.token) as c:
        m = c.get_metrics(done.id)
        assert set(m.aggregates) == {"sim", "twb"}
        assert m.aggregates["twb"].metrics["length_m"].n == 1
        assert m.direct[0].repetition == 1 and m.direct[0].metrics["deviation_mean_m"] > 0
        assert m.planned["length_m"] > 1.5
        twb = next(r for r in done.runs if r.mode == "twb")
        run = c.get_run(twb.id)
        assert run.subfield is not None and run.metrics["goal_reached"] is True
        poses = c.get_poses(twb.id)
        assert poses.ndim == 2 and poses.shape[1] == 4 and len(poses) > 100
        assert np.all(np.diff(poses[:, 0]) >= 0)
        csv = c.get_poses(twb.id, "csv").splitlines()
        assert csv[0] == "t,x,y,theta" and len(csv) == len(poses) + 1
        np.testing.assert_allclose(np.loadtxt(csv[1:], delimiter=","), poses, atol=1e-4)
        msgs = c.get_messages(twb.id)
        assert msgs.count == len(msgs.data) and any(x.line.startswith("T,T,P,300,300,") for x in msgs)
        assert c.get_experiment(done.id).status == "completed"
        listed = c.list_experiments(status="completed")
        assert done.id in [e.id for e in listed] and listed.count >= 1
        with pytest.raises(Conflict, match="already completed"):
            c.cancel(done.id)


def test_testbed_views(testbed):
    with Client(testbed.url, testbed.token) as c:
        assert c.health()["status"] == "ok"
        robots = c.list_robots()
        assert sorted(r.robot_id for r in robots if r.pool == "field") == [f"field-{i}" for i in range(1, 5)]
        assert [s.id for s in c.list_subfields()] == [1, 2, 3, 4]
        envs = {e.name: e for e in c.list_environments()}
        assert {"room", "blocks"} <= set(envs)
        room = c.get_environment("room")
        assert room.plan("A").start[:2] == [0.3, 0.3] and room.size == [1.8, 1.8]
        with pytest.raises(KeyError, match="no plan 'Z'"):
            room.plan("Z")
        mine = {"name": "sdk-one-block", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.3, "h": 0.3}]}
        assert c.create_environment(mine).owner == "admin"
        with pytest.raises(Conflict, match="already have an environment named"):
            c.create_environment(mine)


async def test_async_client_runs_a_job(testbed):
    async with AsyncClient(testbed.url, testbed.token) as c:
        assert (await c.health())["status"] == "ok"
        exp = await c.submit("blocks", start=np.array([0.15, 0.15]), goal=[1.65, 1.65], planner="fmm", modes=["sim"])
        assert exp.status == "queued" and exp.modes == ["sim"]
        exp = await c.wait(exp.id, timeout=120, progress=True)
        assert exp.status == "completed"
        poses = await c.get_poses(exp.runs[0].id)
        assert poses.shape[1] == 4
        m = await c.get_metrics(exp.id)
        assert list(m.aggregates) == ["sim"] and m.direct == []
        with pytest.raises(NotFound):
            await c.get_run(10**9)
        assert len(await c.list_robots()) == 6


def test_errors_carry_the_servers_message(testbed):
    with Client(testbed.url, testbed.token) as c:
        with pytest.raises(NotFound) as e:
            c.get_experiment(10**9)
        assert e.value.status == 404 and e.value.detail == "Experiment not found"
        with pytest.raises(ValidationError, match="inside an obstacle") as e:
            c.submit("room", start=[0.9, 0.9], goal=[1.5, 1.5])
        assert e.value.status == 422
        with pytest.raises(ValidationError, match=r"repetitions: .*greater than or equal to 1"):
            c.submit({**JOB, "repetitions": 0})
        with pytest.raises(ValueError, match="needs an `environment`"):
            c.submit({"planner": "fmm"})
    with Client(testbed.url, "not-a-token") as bad, pytest.raises(Unauthorized, match="Invalid token"):
        bad.list_experiments()
    assert isinstance(Unauthorized(401, "x"), TwbError)


def test_no_server_is_a_transport_error():
    with Client("http://127.0.0.1:9", "t", timeout=5) as c, pytest.raises(TransportError) as e:
        c.health()
    assert "cannot reach the testbed at http://127.0.0.1:9" in str(e.value)
    assert isinstance(e.value.__cause__, httpx.TransportError)


def test_token_and_url_lookup(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("TWB_TOKEN", raising=False)
    monkeypatch.delenv("TWB_DATA_DIR", raising=False)
    monkeypatch.delenv("TWB_URL", raising=False)
    assert Client().token is None and Client().url == "http://127.0.0.1:8000"
    (tmp_path / "twb-data").mkdir()
    (tmp_path / "twb-data" / "token").write_text("from-file\n")
    assert Client().token == "from-file"
    monkeypatch.setenv("TWB_TOKEN", "from-env")
    monkeypatch.setenv("TWB_URL", "http://example.invalid:1/")
    assert Client().token == "from-env" and Client().url == "http://example.invalid:1"
    assert Client(token="arg").token == "arg"
    monkeypatch.delenv("TWB_TOKEN")
    other = tmp_path / "elsewhere"
    other.mkdir()
    (other / "token").write_text("data-dir")
    monkeypatch.setenv("TWB_DATA_DIR", str(other))
    assert Client().token == "data-dir"


def _mock(status: int, body: object, seen: list | None = None) -> httpx.MockTransport:
    def handler(request: httpx.Request) -> httpx.Response:
        if seen is not None:
            seen.append(request)
        return httpx.Response(status, json=body)

    return httpx.MockTransport(handler)


@pytest.mark.parametrize("status,cls", [(413, TooLarge), (429, RateLimited), (409, Conflict), (500, client_sdk.ApiError)])
def test_status_codes_map_to_one_exception_tree(status, cls):
    with Client("http://twb.test", "tok", transport=_mock(status, {"detail": "nope"})) as c:
        with pytest.raises(cls, match=f"^{status} .*: nope$"):
            c.list_robots()


def test_injected_transport_sees_auth_and_wait_times_out():
    seen: list[httpx.Request] = []
    running = {"id": 7, "status": "running", "environment": "room", "modes": ["sim"], "repetitions": 2,
               "runs": [{"id": 1, "experiment_id": 7, "mode": "sim", "repetition": 1, "status": "completed"},
                        {"id": 2, "experiment_id": 7, "mode": "sim", "repetition": 2, "status": "running"}]}
    with Client("http://twb.test", "tok", transport=_mock(200, running, seen)) as c:
        with pytest.raises(WaitTimeout, match=r"experiment 7 still running \(1/2 runs done\) after 0.3 s") as e:
            c.wait(7, timeout=0.3, interval=0.05, progress=False)
    assert isinstance(e.value, TimeoutError) and e.value.experiment.runs_done == 1
    assert seen[0].headers["authorization"] == "Bearer tok"
    assert seen[0].url.path == "/api/v1/experiments/7"


@pytest.fixture(scope="module")
def agent_port():
    with agent_process("sdk") as port:
        yield port


@pytest.mark.slow
def test_send_path_raw_tcp(agent_port):
    path = np.array([[0.1, 0.1], [0.5, 0.1], [0.5, 0.6]])
    r = send_path("127.0.0.1", agent_port, path, follow=True, timeout=10)
    assert r.ok and r.robot_id == "sdk" and r.points == 3 and r.reply == "OK,P,3"
    assert r.outcome == "DONE" and r.events[0].startswith("EV,START") and r.execution_time_s > 0
    assert r.line_sent.startswith("T,T,P,100,100,0;500,100,90;")
    bad = send_path("127.0.0.1", agent_port, "T,T,P,100,100,0;99999,100,0")
    assert not bad.ok and bad.error_code == "RANGE" and bad.outcome is None
    with pytest.raises(ValueError, match="finite"):
        send_path("127.0.0.1", agent_port, [[0, 0], [np.nan, 1]])


@pytest.mark.slow
def test_send_path_with_a_secret_to_a_robot_with_a_control_key():
    key = "sdk-control-key-0001"
    path = [[0.1, 0.1], [0.5, 0.1]]
    with agent_process("sdk-key", "--control-key", key) as port:
        refused = send_path("127.0.0.1", port, path)
        assert not refused.ok and refused.error_code == "AUTH"
        wrong = send_path("127.0.0.1", port, path, secret="not-the-control-key")
        assert not wrong.ok and wrong.error_code == "AUTH" and wrong.points is None
        r = send_path("127.0.0.1", port, path, secret=key, follow=True)
        assert r.ok and r.reply == "OK,P,2" and r.outcome == "DONE"
    with pytest.raises(ValueError, match="16 to 128"):
        send_path("127.0.0.1", 9, path, secret="short")


def test_send_path_no_agent():
    with pytest.raises(TransportError, match="cannot reach the robot agent at 127.0.0.1:9"):
        send_path("127.0.0.1", 9, [[0.1, 0.1], [0.2, 0.2]], timeout=5)


def test_sdk_quickstart_example(testbed, tmp_path):
    script = Path(__file__).resolve().parents[1] / "examples" / "sdk_quickstart.py"
    r = subprocess.run([sys.executable, str(script), "--url", testbed.url, "--token", testbed.token,
                        "--repetitions", "1", "--planner", "fmm", "--out", str(tmp_path / "poses")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "completed" in r.stdout and "sim: 1 runs, length" in r.stdout and "field vs simulation" in r.stdout
    files = sorted((tmp_path / "poses").glob("run-*.csv"))
    assert len(files) == 2 and files[0].read_text().startswith("t,x,y,theta\n")
