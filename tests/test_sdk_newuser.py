"""The SDK's answers to what a new user hit, without a server (``httpx.MockTransport``): the hint on a
missing token, making sure an environment exists, and what ``wait()`` reports where no terminal is."""

from __future__ import annotations

import asyncio
import io
import re

import httpx
import pytest

import client_sdk._progress as progress
from client_sdk import AsyncClient, Client, Conflict, Unauthorized
from client_sdk._progress import BuildEstimate, LineReporter, format_seconds

ROOM = {"name": "room", "size": [1.8, 1.8], "description": "four rooms",
        "blocks": [{"x": 0.9, "y": 0.15 + 0.3 * i, "w": 0.06, "h": 0.3, "angle": 0.0} for i in range(9)],
        "plans": [{"name": "A", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708]}]}
MINE = {"name": "mine", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.2, "h": 0.2}],
        "plans": [{"name": "A", "start": [0.3, 0.3], "goal": [1.5, 1.5]}]}


# --------------------------------------------------------------------------- the token hint


def test_a_missing_token_says_where_the_sdk_looked_and_how_to_pass_one(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("TWB_TOKEN", raising=False)
    monkeypatch.delenv("TWB_DATA_DIR", raising=False)
    refuse = httpx.MockTransport(lambda r: httpx.Response(401, json={"detail": "Missing bearer token"}))
    with Client("http://twb.test", transport=refuse) as c, pytest.raises(Unauthorized) as e:
        c.list_robots()
    text = str(e.value)
    assert text.startswith("401 Unauthorized: Missing bearer token (no token found")
    assert str(tmp_path / "twb-data" / "token") in text  # where it looked
    assert "token=" in text and "TWB_TOKEN" in text and "twb-data/token" in text and "TWB_DATA_DIR" in text
    assert e.value.detail == "Missing bearer token"  # the server's own words stay apart
    # with a token (a wrong one), the server's message alone: the SDK did find a token
    with Client("http://twb.test", "wrong", transport=refuse) as c, pytest.raises(Unauthorized) as e:
        c.list_robots()
    assert str(e.value) == "401 Unauthorized: Missing bearer token"


# --------------------------------------------------------------------------- ensure_environment


class FakeEnvironments:
    """``/api/v1/environments``: ``visible`` ones, plus names taken by someone else's (409 on creation)."""

    def __init__(self, visible: dict, hidden: tuple[str, ...] = ()) -> None:
        self.visible, self.hidden, self.created = dict(visible), hidden, []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        if request.method == "GET":
            name = request.url.path.rsplit("/", 1)[1]
            if name in self.visible:
                return httpx.Response(200, json={**self.visible[name], "builtin": False, "owner": "me"})
            return httpx.Response(404, json={"detail": "Environment not found"})
        import json

        body = json.loads(request.content)
        if body["name"] in self.visible or body["name"] in self.hidden:
            return httpx.Response(409, json={"detail": f"Environment {body['name']!r} already exists"})
        self.visible[body["name"]] = body
        self.created.append(body["name"])
        return httpx.Response(201, json={**body, "builtin": False, "owner": "me"})


def test_ensure_environment_creates_uses_or_refuses():
    server = FakeEnvironments({"room": ROOM})
    with Client("http://twb.test", "tok", transport=httpx.MockTransport(server)) as c:
        env, created = c.ensure_environment(MINE)
        assert created and env.name == "mine" and server.created == ["mine"]
        env, created = c.ensure_environment(MINE)  # the same again: used, not created
        assert not created and len(env.blocks) == 1 and server.created == ["mine"]
        # the same field with another description, explicit defaults: still the same
        same = {**ROOM, "description": "mine now", "blocks": [{k: v for k, v in b.items() if k != "angle"}
                                                              for b in ROOM["blocks"]]}
        assert c.ensure_environment(same)[1] is False
        moved = {**ROOM, "blocks": ROOM["blocks"][:-1]}
        with pytest.raises(Conflict, match="already has a different environment named 'room'.*another name"):
            c.ensure_environment(moved)
        # moving obstacles are part of the field: kept by the model, defaults filled, differences refused
        disc = {"radius": 0.04, "waypoints": [[0.2, 1.2], [0.8, 1.2]], "speed": 0.05}
        env, created = c.ensure_environment({**MINE, "name": "moving", "moving_obstacles": [disc]})
        assert created and env.moving_obstacles == [disc] and env.to_json()["moving_obstacles"] == [disc]
        server.visible["moving"]["moving_obstacles"] = [{**disc, "repeat": "once", "delay_s": 0.0}]  # as stored
        assert c.ensure_environment({**MINE, "name": "moving", "moving_obstacles": [disc]})[1] is False
        with pytest.raises(Conflict, match="different environment named 'moving'"):
            c.ensure_environment({**MINE, "name": "moving", "moving_obstacles": [{**disc, "speed": 0.1}]})
        with pytest.raises(Conflict, match="different environment named 'moving'"):
            c.ensure_environment({**MINE, "name": "moving"})


def test_ensure_environment_says_when_the_name_is_taken_by_an_invisible_one():
    server = FakeEnvironments({}, hidden=("theirs",))
    with Client("http://twb.test", "tok", transport=httpx.MockTransport(server)) as c:
        with pytest.raises(Conflict, match="taken by an environment you cannot see; give yours another name"):
            c.ensure_environment({**MINE, "name": "theirs"})
        with pytest.raises(ValueError, match="needs a `name`"):
            c.ensure_environment({"size": [1, 1]})


async def test_async_client_ensures_environments_the_same_way():
    server = FakeEnvironments({"room": ROOM})
    async with AsyncClient("http://twb.test", "tok", transport=httpx.MockTransport(server)) as c:
        assert (await c.ensure_environment(MINE))[1] is True
        assert (await c.ensure_environment(MINE))[1] is False
        with pytest.raises(Conflict):
            await c.ensure_environment({**ROOM, "size": [1.0, 1.0]})


# --------------------------------------------------------------------------- progress without a terminal


def _run(i: int, status: str, mode: str = "twb", subfield: int | None = 2) -> dict:
    return {"id": i, "experiment_id": 7, "mode": mode, "repetition": 1, "status": status, "subfield": subfield,
            "robot_id": "field-2" if mode == "twb" else "sim-1"}


STATES = [
    {"status": "queued", "estimated_start_s": 95.0, "runs": [_run(1, "queued", subfield=None), _run(2, "queued", "sim", None)]},
    {"status": "building", "runs": [_run(1, "building"), _run(2, "completed", "sim", None)]},
    {"status": "building", "runs": [_run(1, "building"), _run(2, "completed", "sim", None)]},
    {"status": "running", "runs": [_run(1, "running"), _run(2, "completed", "sim", None)]},
    {"status": "completed", "runs": [_run(1, "completed"), _run(2, "completed", "sim", None)]},
]


class FakeTestbed:
    """An experiment going through ``STATES`` (one per poll), the robots, the sub-fields and environments."""

    def __init__(self, time_scale: float | None = 1.0, profile: str = "bebot") -> None:
        self.polls, self.time_scale, self.profile, self.paths = 0, time_scale, profile, []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        path = request.url.path
        self.paths.append(path)
        if path == "/api/v1/experiments/7":
            state = STATES[min(self.polls, len(STATES) - 1)]
            self.polls += 1
            return httpx.Response(200, json={"id": 7, "environment": "room", "modes": ["twb", "sim"], "repetitions": 1,
                                             "error": "", **state})
        if path == "/health":
            return httpx.Response(200, json={"status": "ok", "time_scale": self.time_scale})
        if path == "/api/v1/robots":
            return httpx.Response(200, json={"count": 1, "data": [
                {"robot_id": "field-2", "host": "h", "port": 1, "backend": "field", "pool": "field",
                 "status": "busy", "profile": self.profile}]})
        if path == "/api/v1/subfields":
            return httpx.Response(200, json={"count": 1, "data": [{"id": 2, "state": "building", "environment": "blocks"}]})
        if path == "/api/v1/environments/room":
            return httpx.Response(200, json=ROOM)
        if path == "/api/v1/environments/blocks":
            return httpx.Response(200, json={**ROOM, "name": "blocks"})
        return httpx.Response(404, json={"detail": "Not found"})


def test_wait_prints_status_lines_and_the_gripper_estimate_when_not_a_terminal(capsys):
    bed = FakeTestbed()
    with Client("http://twb.test", "tok", transport=httpx.MockTransport(bed)) as c:
        exp = c.wait(7, progress=True, interval=0.01)
    assert exp.status == "completed"
    err = capsys.readouterr().err
    assert "\x1b" not in err and "\r" not in err  # no terminal control codes
    lines = err.splitlines()
    assert [re.sub(r"^\[[^]]*\] ", "", ln).split(",")[0] for ln in lines] == [
        "experiment 7: queued", "experiment 7: building", "experiment 7: running", "experiment 7: completed"]
    assert lines[0].endswith("experiment 7: queued, 0/2 runs done; estimated start in 1 min 35 s")
    # 9 blocks of the old environment removed, 9 placed, 8 s each (bebot), at time scale 1: 144 s
    assert lines[1].endswith("1/2 runs done; run 1 on sub-field 2: building the environment "
                             "(9 blocks placed, 9 removed): about 2 min 24 s at time scale 1")
    assert lines[3].endswith("completed, 2/2 runs done")
    # what the estimate needed was asked once, not at every poll
    assert bed.paths.count("/health") == 1 and bed.paths.count("/api/v1/robots") == 1
    assert bed.paths.count("/api/v1/environments/room") == 1


def test_without_the_profile_the_blocks_are_still_told(capsys):
    bed = FakeTestbed(time_scale=20.0, profile="a-robot-unknown-here")
    with Client("http://twb.test", "tok", transport=httpx.MockTransport(bed)) as c:
        c.wait(7, progress=True, interval=0.01)
    err = capsys.readouterr().err
    assert "run 1 on sub-field 2: building the environment (9 blocks placed, 9 removed)\n" in err


def test_the_default_stays_quiet_without_a_terminal_and_async_reports_too(capsys):
    with Client("http://twb.test", "tok", transport=httpx.MockTransport(FakeTestbed())) as c:
        c.wait(7, interval=0.01)  # progress=None: a bar on a terminal, nothing in a log
    assert capsys.readouterr().err == ""

    async def main() -> None:
        async with AsyncClient("http://twb.test", "tok", transport=httpx.MockTransport(FakeTestbed(None))) as c:
            await c.wait(7, progress=True, interval=0.01)

    asyncio.run(main())
    assert "building the environment (9 blocks placed, 9 removed): moments at time scale max" in capsys.readouterr().err


def test_periodic_lines_when_nothing_changes(monkeypatch):
    out = io.StringIO()
    monkeypatch.setattr(progress, "REPORT_EVERY_S", 0.0)
    from client_sdk import Experiment

    exp = Experiment.from_json({"id": 3, "status": "running", "environment": "room", "modes": ["sim"],
                                "repetitions": 1, "runs": [_run(5, "running", "sim", None)]})
    rep = LineReporter(out)
    rep.update(exp, {})
    rep.update(exp, {})
    assert out.getvalue().count("experiment 3: running, 0/1 runs done") == 2
    quiet = LineReporter(io.StringIO(), every=60)
    quiet.update(exp, {})
    quiet.update(exp, {})
    assert quiet._stream.getvalue().count("\n") == 1


def test_build_estimate_words():
    assert format_seconds(59.6) == "1 min 00 s" and format_seconds(3725) == "1 h 02 min"
    assert BuildEstimate(9, 0, 8.0, 1.0, True).describe() == \
        "building the environment (9 blocks): about 1 min 12 s at time scale 1"
    assert BuildEstimate(9, None, 8.0, 1.0, False).describe() == "building the environment (9 blocks)"
