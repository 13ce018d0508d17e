"""Simulation behaviour seen through the protocol: sim vs field, collisions, replay, frames, faults."""

from __future__ import annotations

import asyncio
import math

import numpy as np
from agent_support import CORNERS, OK_I, LineClient, densify, running_agents

from planners.metrics import deviation, path_length
from robot_agent.host import AgentHost
from contract.protocol import ErrorCode, encode_build, encode_path, encode_place, format_ok, parse_reply
from contract.robot_profile import load_profile
from robot_agent.host.sinks import MemoryTrackerSink

SEEDS = list(range(6))
PATH = densify(CORNERS)


async def _drive(agents, robot_index: int, path: np.ndarray, start=None) -> tuple[list[str], np.ndarray]:
    """Place (optionally), send ``path``, wait for the end; returns the event lines and the tracker poses."""
    r = agents.robots[robot_index]
    c = await LineClient.connect(r.port)
    if start is not None:
        assert await c.ask(encode_place(start)) == OK_I
    await agents.flush_tracker()
    agents.sink.clear()
    assert await c.ask(encode_path(path)) == format_ok("P", len(path))
    lines = await c.until("EV,DONE", "EV,FAIL")
    await c.close()
    await agents.flush_tracker()
    return lines, agents.sink.poses(r.robot_id)


async def _runs(backend: str) -> list[dict[str, float]]:
    """One run per seed, all at once on separate robots (separate worlds)."""
    import asyncio

    async with running_agents(backend=backend, robots=len(SEEDS)) as agents:
        for i, seed in enumerate(SEEDS):
            agents.set_path_seed(agents.robots[i].robot_id, seed)
        results = await asyncio.gather(*(_drive(agents, i, PATH, start=PATH[0]) for i in range(len(SEEDS))))
    out = []
    for lines, poses in results:
        assert lines[-1].startswith("EV,DONE"), lines[-1]
        t_start = next(parse_reply(x).time for x in lines if x.startswith("EV,START"))
        t_done = parse_reply(lines[-1]).time
        xy = poses[:, 1:3]
        length = path_length(xy)
        out.append({
            "length": length,
            "deviation": float(deviation(PATH, xy).mean()),
            "speed": length / (t_done - t_start),
            "overshoot": _overshoot(xy),
        })
    return out


def _overshoot(xy: np.ndarray) -> float:
    """Mean over the path's 90-degree corners of how far (m) the robot went past the corner
    along the incoming direction (0 if it turned before it)."""
    c = np.array(CORNERS)
    out = []
    for a, b, d in zip(c[:-2], c[1:-1], c[2:]):
        u = (b - a) / np.linalg.norm(b - a)
        v = (d - b) / np.linalg.norm(d - b)
        if abs(u @ v) > 0.1:
            continue
        near = xy[np.hypot(*(xy - b).T) < 0.15]
        out.append(max(0.0, float(((near - b) @ u).max())) if len(near) else 0.0)
    return float(np.mean(out))


async def test_field_backend_is_worse_than_ideal_on_sharp_corners():
    ideal = await _runs("ideal")
    field = await _runs("field")
    # ideal runs are identical (no noise); every field seed must be worse, with a clear margin; the field
    # robot overshoots the corners, so it drives further (since issue 33, whose BeBot lags 0.25 s behind a
    # steering lead tuned for 0.12 s, accelerates at 0.3 m/s² and slips for 0.1 s at a time: about 3 %, before
    # up to 3 %), but it does not weave around the path (a weaving robot drove 5-10 % further; docs/fidelity.md)
    assert len({round(r["length"], 9) for r in ideal}) == 1
    base = ideal[0]
    for f in field:
        assert 1.005 * base["length"] < f["length"] < 1.045 * base["length"], (f, base)
        assert f["deviation"] > 1.3 * base["deviation"], (f, base)
        assert f["speed"] < 0.97 * base["speed"], (f, base)
        assert f["overshoot"] > base["overshoot"] + 0.003, (f, base)  # 4.4 mm on one seed; the margin was 5 mm before issue 33


async def test_collision_with_a_block():
    async with running_agents(backend="field") as agents:
        c = await LineClient.connect(agents.ports[0])
        assert await c.ask(encode_build([(0.9, 0.3, 0.1, 0.4, 0.0)])) == format_ok("B", 1)
        assert await c.ask(encode_place((0.3, 0.3, 0.0))) == OK_I
        await c.ask(encode_path(np.array([[0.3, 0.3, 0.0], [1.5, 0.3, 0.0]])))
        lines = await c.until("EV,DONE", "EV,FAIL")
        assert lines[-1].startswith("EV,FAIL,COLLISION")
        st = parse_reply(await c.ask("T,T,Q"))
        assert st.fields[0] == "FAILED"
        # stopped at the block's face (x = 850 mm) minus the collision radius; the belief lags a little
        assert 750 < float(st.fields[1]) < 850 - 1000 * agents.params.collision_radius_m + 5
        await c.close()


async def test_collision_between_robots_of_neighbouring_subfields():
    async with running_agents(backend="ideal", robots=2) as agents:
        one = await LineClient.connect(agents.ports[0])
        two = await LineClient.connect(agents.ports[1])
        assert await two.ask(encode_place((0.05, 0.5, 0.0))) == OK_I  # world x = 1.85
        assert await one.ask(encode_place((1.5, 0.5, 0.0))) == OK_I
        await one.ask(encode_path(np.array([[1.5, 0.5, 0.0], [1.8, 0.5, 0.0]])))
        assert (await one.until("EV,DONE", "EV,FAIL"))[-1].startswith("EV,FAIL,COLLISION")
        assert parse_reply(await two.ask("T,T,Q")).fields[0] == "IDLE"
        await one.close()
        await two.close()


async def test_same_seed_gives_identical_tracker_output_on_any_robot():
    async with running_agents(backend="field", robots=2) as agents:
        runs = []
        for robot in (0, 0, 1):
            agents.set_path_seed(agents.robots[robot].robot_id, 1234)
            lines, poses = await _drive(agents, robot, PATH[:20], start=PATH[0])
            runs.append((lines, poses))
        agents.set_path_seed(agents.robots[0].robot_id, 99)
        other = await _drive(agents, 0, PATH[:20], start=PATH[0])
    (l0, p0), (l1, p1), (l2, p2) = runs
    rel = [p[:, 0] - p[0, 0] for p in (p0, p1, p2)]
    np.testing.assert_array_equal(p0[:, 1:], p1[:, 1:])
    np.testing.assert_array_equal(p0[:, 1:], p2[:, 1:])
    np.testing.assert_allclose(rel[0], rel[1], atol=1e-9)
    np.testing.assert_allclose(rel[0], rel[2], atol=1e-9)
    assert [x.rsplit(",", 1)[0] for x in l0] == [x.rsplit(",", 1)[0] for x in l1]
    assert len(other[1]) != len(p0) or not np.array_equal(other[1][:, 1:], p0[:, 1:])


async def test_frames_robot_four_and_full_field_area():
    async with running_agents(backend="ideal", robots=4) as agents:
        assert agents.robots[3].origin == (1.8, 1.8)
        c = await LineClient.connect(agents.ports[3])
        assert (await c.ask("T,T,P,100,100,0;1900,100,0")).startswith(f"ERR,{ErrorCode.RANGE.value},")
        lines, poses = await _drive(agents, 3, np.array([[0.2, 0.2, 0.0], [0.6, 0.2, 0.0]]), start=(0.2, 0.2, 0.0))
        assert lines[-1].startswith("EV,DONE")
        assert poses[:, 1].max() < 0.7  # logged in the robot's own frame
        await c.close()
    async with running_agents(backend="ideal", area=(3.6, 3.6)) as agents:
        c = await LineClient.connect(agents.ports[0])
        assert (await c.ask("T,T,P,100,100,0;3000,100,0")) == format_ok("P", 2)
        await c.close()


async def test_timeout_and_stall():
    prof = load_profile("bebot")
    prof["controller"] = {**prof["controller"], "timeout_base_s": 0.5, "timeout_factor": 0.0}
    async with running_agents(backend="ideal", profile=prof) as agents:
        lines, _ = await _drive(agents, 0, np.array([[0.1, 0.1, 0.0], [1.5, 0.1, 0.0]]))
        assert lines[-1].startswith("EV,FAIL,TIMEOUT")
    prof = load_profile("bebot")
    prof["field"] = {**prof["field"], "dead_band_m_s": 10.0}  # tracks never overcome friction
    async with running_agents(backend="field", profile=prof) as agents:
        lines, _ = await _drive(agents, 0, np.array([[0.1, 0.1, 0.0], [1.5, 0.1, 0.0]]))
        assert lines[-1].startswith("EV,FAIL,STALLED")
        t = parse_reply(lines[-1]).time - parse_reply(lines[0]).time
        assert t >= prof["controller"]["stall_time_s"]


async def test_live_time_scale_runs_in_experiment_time():
    async with running_agents(backend="ideal", time_scale=200.0) as agents:
        lines, poses = await _drive(agents, 0, np.array([[0.1, 0.1, 0.0], [0.5, 0.1, 0.0]]), start=(0.1, 0.1, 0.0))
        assert lines[-1].startswith("EV,DONE")
        dt = np.diff(poses[:, 0])
        np.testing.assert_allclose(dt, agents.core.dt, atol=1e-9)  # ideal: ground truth at the control rate
        assert math.isclose(poses[0, 0], parse_reply(lines[0]).time)


class _HeldSink(MemoryTrackerSink):
    """Holds the first batch on its way until released: a delivery under way."""

    def __init__(self) -> None:
        super().__init__()
        self.holding, self.release = asyncio.Event(), asyncio.Event()

    async def send(self, robot_id: str, poses: np.ndarray) -> None:
        if not self.holding.is_set():
            self.holding.set()
            await self.release.wait()
        await super().send(robot_id, poses)


async def test_a_flush_returns_only_once_the_delivery_under_way_has_arrived():
    """At maximum speed a whole run fits in one batch of the periodic delivery; a flush (the testbed's,
    at DONE, before it closes the run's window) must not return while that batch is still on its way."""
    sink = _HeldSink()
    host = AgentHost(backend="ideal", time_scale=math.inf, tracker_sink=sink)  # not started: no periodic delivery
    host.core.poses.add(np.array([1.0, 1.02]), np.array([0, 0]), np.array([[0.1, 0.1, 0.0], [0.11, 0.1, 0.0]]))
    under_way = asyncio.create_task(host.flush_tracker())  # stands in for the periodic delivery
    await sink.holding.wait()
    flush = asyncio.create_task(host.flush_tracker())
    for _ in range(5):
        await asyncio.sleep(0)
    assert not flush.done() and len(sink.poses(host.robots[0].robot_id)) == 0
    sink.release.set()
    await asyncio.gather(under_way, flush)
    assert len(sink.poses(host.robots[0].robot_id)) == 2
