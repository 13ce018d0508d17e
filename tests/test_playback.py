"""A run computed as a task, played out at the time scale, so fleets are shown live while they run.

docs/server.md, "Multi-robot jobs" (live and in time), describes it.

The bookkeeping (:class:`server.pipeline.playback.Playback`) without a clock; :func:`play` cancelled part way;
then a real `twb up` at time scale 4: a field fleet's robots are published live one after the other as their
poses come due (not once at the end), each shown where it stopped, and a cancelled fleet run keeps the poses
played until then and no more.
"""

from __future__ import annotations

import asyncio
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest

from server.pipeline.playback import Playback, play
from servers import EventListener, submit_watched, wait_for

ROOT = Path(__file__).resolve().parents[1]


def track(t0: float, t1: float, n: int, x: float = 0.0) -> np.ndarray:
    t = np.linspace(t0, t1, n)
    return np.column_stack([t, np.full(n, x), t, np.zeros(n)])


def test_rows_and_lines_come_due_by_experiment_time():
    a, b = track(1.0, 3.0, 5), track(2.0, 4.0, 3, x=1.0)  # a at 1, 1.5 .. 3; b at 2, 3, 4
    lines = [("s", "before", None), (">", "T,T,P", 1.0), ("<", "EV,START", 1.2), ("s", "untimed", None),
             ("<", "b done", 4.0), ("<", "a done", 3.0)]
    pb = Playback([a, b], lines)
    assert (pb.t_first, pb.t_last) == (1.0, 4.0)
    rows, due = pb.advance(1.0)
    assert [(k, len(r)) for k, r in rows] == [(0, 1)] and [d[1] for d in due] == ["before", "T,T,P"]
    rows, due = pb.advance(2.0)
    assert [(k, r[:, 0].tolist()) for k, r in rows] == [(0, [1.5, 2.0]), (1, [2.0])]
    assert [d[1] for d in due] == ["EV,START", "untimed"]  # an untimed line keeps its place after the one before
    rows, due = pb.advance(1.5)  # time does not go back
    assert rows == [] and due == [] and pb.t == 2.0
    rows, due = pb.advance(3.0)
    assert [d[1] for d in due] == ["a done"] and pb.ended(0) and not pb.ended(1) and not pb.done
    np.testing.assert_array_equal(pb.played(0), a)
    np.testing.assert_array_equal(pb.played(1), b[:2])
    obstacle = track(0.0, 10.0, 11)  # a field run's obstacle robot on the same clock: cut where playing got to
    np.testing.assert_array_equal(pb.until_played([obstacle])[0], obstacle[:4])
    assert pb.until_played(None) is None
    rows, due = pb.advance(math.inf)
    assert [d[1] for d in due] == ["b done"] and pb.done


def test_playing_at_once_releases_everything_in_one_go():
    shown, logged = [], []
    pb = Playback([track(0.0, 9.0, 10), track(0.0, 2.0, 3)], [("<", "x", 5.0)])
    asyncio.run(play(pb, math.inf, lambda k, r, last: shown.append((k, len(r), last)), logged.append))
    assert shown == [(0, 10, True), (1, 3, True)] and logged == [("<", "x", 5.0)]


def test_a_cancelled_playback_keeps_what_was_released_and_no_more():
    tracks = [track(0.0, 60.0, 601), track(0.0, 60.0, 601, x=1.0)]
    pb, shown = Playback(tracks), []

    async def cancel_soon() -> float:
        task = asyncio.create_task(play(pb, 1.0, lambda k, r, last: shown.append((k, r[-1, 0], last)), print))
        began = time.monotonic()
        await asyncio.sleep(0.35)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        return time.monotonic() - began

    elapsed = asyncio.run(cancel_soon())
    for k in range(2):
        played = pb.played(k)
        assert 1 <= len(played) < len(tracks[k])
        np.testing.assert_array_equal(played, tracks[k][:len(played)])
        assert played[-1, 0] <= elapsed  # released by the clock at time scale 1, never ahead of it
    assert {k for k, _, _ in shown} == {0, 1} and not any(last for _, _, last in shown)
    times = [t for k, t, _ in shown if k == 0]
    assert times == sorted(times) and len(times) >= 2  # shown as it came due, tick by tick


TWO = {"environment": "swap", "planner": "prioritized", "modes": ["twb"], "field": "sub", "seed": 3,
       "robots": [{"start": [0.3, 0.3, 0.0], "goal": [1.5, 0.3, 0.0]},
                  {"start": [0.3, 1.5, 0.0], "goal": [1.5, 1.5, 0.0]}]}


@pytest.fixture(scope="module")
def testbed(testbeds):  # its own: at four times live speed, the playback's timing is measured
    yield from testbeds.own("up", "--time-scale", "4", "--sim-robots", "1")


@pytest.fixture(scope="module")
def client(testbed):
    with testbed.client() as c:
        yield c


def stored(client, run_id: int, robot: int) -> np.ndarray:
    body = client.get(f"/api/v1/runs/{run_id}/poses", params={"robot": robot}).json()
    return np.array(body["poses"], dtype=float).reshape(-1, len(body["columns"]))


def test_a_field_fleet_is_shown_live_as_it_drives(testbed, client):
    exp, seen = submit_watched(testbed, client, TWO)
    run = exp["runs"][0]
    assert exp["status"] == "completed", exp
    live = [e for e in seen if e["event"] == "pose" and e["run_id"] == run["id"]]
    span = run["t_end"] - run["t_start"]
    assert span > 2.0, run  # several seconds of experiment time: at time scale 4, many ticks
    for k in range(2):
        mine = [e for e in live if e.get("robot") == k]
        times = [e["t"] for e in mine]
        assert len(mine) >= 5 and times == sorted(times), times  # as it drove, not once at the end
        assert times[-1] == stored(client, run["id"], k)[-1, 0]  # and shown where it stopped
    order = [e["robot"] for e in live]
    assert order.index(1) < len(order) - 1 - order[::-1].index(0)  # the robots interleave: one clock for both
    log = [m["line"] for m in client.get(f"/api/v1/runs/{run['id']}/messages", params={"limit": 5000}).json()["data"]]
    starts = [i for i, line in enumerate(log) if "EV,START" in line]
    dones = [i for i, line in enumerate(log) if "EV,DONE" in line]
    assert len(starts) == 2 and len(dones) == 2 and max(starts) < min(dones)  # the log in time order, not robot by robot


def test_a_cancelled_field_fleet_keeps_the_poses_it_drove_until_then(testbed, client):
    full = wait_for(client, client.post("/api/v1/experiments", json=TWO).json()["id"], timeout=120)["runs"][0]
    submitted: dict = {}
    listener = EventListener(testbed.url, testbed.token,
                             until=lambda e: e["event"] == "pose" and e.get("run_id") is not None
                             and e.get("robot") == 0 and e["t"] > full["t_start"] + 1.0
                             and e["run_id"] != full["id"])
    submitted.update(client.post("/api/v1/experiments", json=TWO).json())
    listener.join(60)
    listener.stop()
    resp = client.post(f"/api/v1/experiments/{submitted['id']}/cancel")
    assert resp.status_code == 200, resp.text
    exp = wait_for(client, submitted["id"], timeout=60)
    run = exp["runs"][0]
    assert run["status"] == "cancelled", exp
    assert not run.get("metrics"), run  # nothing measured over what was never driven
    for k in range(2):
        part, whole = stored(client, run["id"], k), stored(client, full["id"], k)
        assert 1 <= len(part) < len(whole)  # what was played, and less than the whole run
        np.testing.assert_array_equal(part, whole[:len(part)])  # the same seed: the start of the same run
