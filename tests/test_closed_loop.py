"""Closed-loop programs over TCP: localisation lines (T,T,O) in, body velocities (T,T,V) out, a watchdog."""

from __future__ import annotations

import asyncio
import math
from itertools import pairwise

import pytest
from agent_support import OK_I, LineClient, running_agents

from contract.protocol import ProtocolError, VelocityCommand, encode_path, encode_place, parse_command

GOAL = (0.9, 0.6)  # m, the robot's frame


async def drive_to_goal(c: LineClient, goal: tuple[float, float]) -> tuple[list[str], tuple[float, float]]:
    """A raw-socket program: a P-controller on each PO line until within 3 cm, then T,T,S.  Returns the
    lines the robot sent and the last PO position (m)."""
    assert await c.ask("T,T,O,1") == "OK,O"
    assert await c.ask("T,T,V,0,0") == "OK,V"
    seen: list[str] = []
    x = y = math.nan
    while True:
        line = c.stash.pop(0) if c.stash else await c.recv(timeout=30)
        seen.append(line)
        if line.startswith("EV,FAIL") or line.startswith("ERR"):
            raise AssertionError(f"the robot ended the drive: {line}")
        if not line.startswith("PO,"):
            continue
        _, xs, ys, a, _t = line.split(",")
        x, y, th = float(xs) / 1000, float(ys) / 1000, math.radians(float(a))
        d = math.hypot(goal[0] - x, goal[1] - y)
        if d < 0.03:
            break
        err = math.remainder(math.atan2(goal[1] - y, goal[0] - x) - th, math.tau)
        v = min(150.0, 1500.0 * d) * max(math.cos(err), 0.0)  # mm/s
        w = math.degrees(max(-2.5, min(2.5, 4.0 * err)))  # deg/s
        await c.send(f"T,T,V,{v:.1f},{w:.1f}")
    await c.send("T,T,S")
    return seen + await c.until("OK,S", timeout=10), (x, y)


@pytest.mark.parametrize("backend", ["ideal", "field"])
async def test_a_raw_socket_program_drives_the_robot_to_a_goal(backend):
    async with running_agents(backend=backend, time_scale=5.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_place((0.3, 0.3, 0.0)))
        lines, (x, y) = await drive_to_goal(c, GOAL)
        await c.close()
        q = agents.core.belief(0)
    assert math.hypot(x - GOAL[0], y - GOAL[1]) < 0.03 and math.hypot(q[0] - GOAL[0], q[1] - GOAL[1]) < 0.06
    assert lines[0].startswith("OK,V") or any(line.startswith("EV,START") for line in lines)
    assert "EV,FAIL,STOPPED" in " ".join(lines)  # T,T,S ends velocity mode
    assert sum(line.startswith("PO,") for line in lines) > 10


async def test_the_watchdog_stops_a_robot_without_new_commands():
    async with running_agents(backend="ideal", time_scale=5.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_place((0.3, 0.3, 0.0)))
        assert await c.ask("T,T,V,100,0") == "OK,V"
        lines = await c.until("EV,FAIL", timeout=30)
        assert lines[-1].startswith("EV,FAIL,WATCHDOG,")
        t_start = next(float(x.split(",")[-1]) for x in c.stash + lines if x.startswith("EV,START"))
        assert float(lines[-1].split(",")[-1]) - t_start == pytest.approx(0.5, abs=0.021)  # experiment time
        await c.close()


async def test_velocity_commands_during_a_path_are_refused_and_parsed_strictly():
    async with running_agents(backend="ideal", time_scale=1.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_place((0.3, 0.3, 0.0)))
        assert (await c.ask(encode_path([[0.3, 0.3, 0.0], [1.2, 0.3, 0.0]]))).startswith("OK,P")
        assert (await c.ask("T,T,V,50,0")).startswith("ERR,STATE,a path is in progress")
        assert (await c.ask("T,T,O,2")).startswith("ERR,SYNTAX")
        await c.close()


async def test_the_gripper_refuses_a_robot_in_velocity_mode_saying_so():
    async with running_agents(backend="ideal", time_scale=1.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_place((0.3, 0.3, 0.0)))
        assert await c.ask("T,T,V,50,0") == "OK,V"
        for line in (encode_place((0.5, 0.5, 0.0)), "T,T,B,900,900,100,100,0", "T,T,M"):
            assert await c.ask(line) == "ERR,STATE,the robot is driving in velocity mode (send T,T,S first)", line
        assert await c.ask("T,T,S") == "OK,S"
        await c.until("EV,FAIL,STOPPED", timeout=10)
        assert (await c.ask(encode_path([[0.3, 0.3, 0.0], [1.2, 0.3, 0.0]]))).startswith("OK,P")
        assert (await c.ask("T,T,B,900,900,100,100,0")) == "ERR,STATE,the robot is following a path (send T,T,S first)"
        await c.close()
    assert parse_command("T,T,V,100,90") == VelocityCommand(0.1, math.pi / 2)
    assert parse_command("T,T,V,100,90,2.5") == VelocityCommand(0.1, math.pi / 2, 0.0025)  # compute time, ms
    for bad in ("T,T,V", "T,T,V,1", "T,T,V,1,2,-3", "T,T,V,1,2,3,4", "T,T,V,1,x", "T,T,V,1,2,x"):
        with pytest.raises(ProtocolError):
            parse_command(bad)


async def test_sixteen_robots_of_one_host_each_close_their_own_loop_at_once():
    """Many robots in one host (a world each): placed side by side (every gripper works at once, not one
    robot after the other), each connection gets its own robot's PO lines and steers it to its own goal."""
    n = 16
    async with running_agents(robots=n, backend="field", time_scale=5.0, area=(1.8, 1.8)) as agents:
        clients = [await LineClient.connect(p) for p in agents.ports]
        t0 = agents.now()
        placed = await asyncio.gather(*(c.ask(encode_place((0.9, 0.9, 0.0))) for c in clients))
        assert placed == [OK_I] * n
        assert agents.now() - t0 < 2 * agents.params.gripper.seconds_per_placement  # side by side
        goals = [(0.9 + 0.35 * math.cos(k * math.tau / n), 0.9 + 0.35 * math.sin(k * math.tau / n)) for k in range(n)]
        ends = await asyncio.gather(*(drive_to_goal(c, g) for c, g in zip(clients, goals)))
        for k, ((lines, (x, y)), goal) in enumerate(zip(ends, goals)):
            assert math.hypot(x - goal[0], y - goal[1]) < 0.03, k
            assert sum(line.startswith("PO,") for line in lines) > 10, k
            q = agents.core.belief(k)
            assert math.hypot(q[0] - goal[0], q[1] - goal[1]) < 0.06, k
        for c in clients:
            await c.close()


async def lockstep_drive(c: LineClient, goal: tuple[float, float], compute_ms: float | None = None) -> list[str]:
    """A lockstep P-controller from the robot's standing pose: subscribe, wait for the first pose, start velocity
    mode, then answer every ``PO`` line of the drive with one ``T,T,V`` (stating ``compute_ms`` when given) until
    within 3 cm; returns the drive's ``PO`` lines with their times made relative to the first."""
    assert await c.ask("T,T,O,1") == "OK,O"
    first = c.stash.pop(0) if c.stash else await c.recv(timeout=30)
    assert first.startswith("PO,"), first  # a standing robot is localised too
    assert await c.ask("T,T,V,0,0") == "OK,V"
    c.stash = [line for line in c.stash if not line.startswith("PO,")]  # standing frames sent before the drive
    poses: list[str] = []
    suffix = "" if compute_ms is None else f",{compute_ms:g}"
    while True:
        line = c.stash.pop(0) if c.stash else await c.recv(timeout=30)
        if line.startswith(("EV,FAIL", "ERR")):
            raise AssertionError(f"the robot ended the drive: {line}")
        if not line.startswith("PO,"):
            continue
        poses.append(line)
        _, xs, ys, a, _t = line.split(",")
        x, y, th = float(xs) / 1000, float(ys) / 1000, math.radians(float(a))
        d = math.hypot(goal[0] - x, goal[1] - y)
        if d < 0.03:
            break
        err = math.remainder(math.atan2(goal[1] - y, goal[0] - x) - th, math.tau)
        v = min(150.0, 1500.0 * d) * max(math.cos(err), 0.0)
        w = math.degrees(max(-2.5, min(2.5, 4.0 * err)))
        await c.send(f"T,T,V,{v:.1f},{w:.1f}{suffix}")
    await c.send("T,T,S")
    await c.until("OK,S", timeout=10)
    assert await c.ask("T,T,O,0") == "OK,O"
    t0 = float(poses[0].split(",")[4])
    return [",".join((*p.split(",")[:4], f"{float(p.split(',')[4]) - t0:.3f}")) for p in poses]


@pytest.mark.parametrize("backend", ["ideal", "field"])
async def test_lockstep_gives_the_same_poses_at_every_time_scale(backend):
    """The robot's clock waits for the controller's answer to every pose: the same seed and controller give the
    same poses at time scale 1, 5 and as fast as possible (docs/protocol.md, "Lockstep")."""
    runs = []
    for scale in (1.0, 5.0, math.inf):
        async with running_agents(backend=backend, time_scale=scale, seed=7) as agents:
            c = await LineClient.connect(agents.ports[0])
            runs.append(await lockstep_drive(c, (0.4, 0.3)))
            await c.close()
            assert agents.lockstep.lapsed == set()
    assert len(runs[0]) > 20
    assert runs[1] == runs[0] and runs[2] == runs[0]


async def test_a_stated_compute_time_delays_the_answer_by_whole_control_periods():
    """``T,T,V,v,w,c``: the answer applies from the first control step at or after its pose's delivery + c; the
    controller gets no pose meanwhile (one pose at a time).  40 ms on 20 ms steps: a pose every other step."""
    async with running_agents(backend="ideal", time_scale=math.inf, seed=7) as agents:
        c = await LineClient.connect(agents.ports[0])
        fast = await lockstep_drive(c, (0.4, 0.3))
        slow = await lockstep_drive(c, (0.7, 0.3), compute_ms=40.0)
        await c.close()
    dt = 1.0 / agents.params.controller.control_rate_hz
    gaps = {round(float(b.split(",")[4]) - float(a.split(",")[4]), 3) for a, b in pairwise(slow)}
    assert gaps == {round(2 * dt, 3)}
    assert {round(float(b.split(",")[4]) - float(a.split(",")[4]), 3) for a, b in pairwise(fast)} \
        == {round(dt, 3)}


async def test_a_silent_lockstep_controller_lapses_after_the_configured_wait(caplog):
    """``lockstep_wait_s`` (``twb up/agent --lockstep-wait``, ``TWB_LOCKSTEP_WAIT_S``): a controller that stops
    answering holds its robot's clock that many wall seconds, no fewer, then lapses; the watchdog stops the
    robot."""
    import logging
    import time

    caplog.set_level(logging.WARNING, logger="robot_agent.host")
    async with running_agents(backend="ideal", lockstep_wait_s=0.4) as agents:
        c = await LineClient.connect(agents.ports[0])
        assert await c.ask("T,T,O,1,lockstep") == "OK,O"
        assert await c.ask("T,T,V,100,0") == "OK,V"
        answered = time.monotonic()  # from here on the controller is silent
        lines = await c.until("EV,FAIL", timeout=30)
        waited = time.monotonic() - answered
        assert lines[-1].startswith("EV,FAIL,WATCHDOG,"), lines[-3:]
        await c.close()
    assert waited >= 0.4
    assert any("did not answer a pose within 0.4 s" in r.getMessage() for r in caplog.records), caplog.text


async def test_free_running_controllers_keep_the_wall_clock():
    """``T,T,O,1,free``: the clock does not wait for the answers (a controller that does not answer loses its robot
    to the watchdog after 0.5 s of experiment time, as before)."""
    async with running_agents(backend="ideal", time_scale=5.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        assert await c.ask("T,T,O,1,free") == "OK,O"
        assert await c.ask("T,T,V,100,0") == "OK,V"
        lines = await c.until("EV,FAIL", timeout=30)
        assert lines[-1].startswith("EV,FAIL,WATCHDOG,")
        await c.close()


@pytest.mark.parametrize("backend", ["ideal", "field"])
async def test_a_standing_robot_sends_poses_at_the_trackers_rate(backend):
    """``T,T,O,1`` on a robot that does not move: its first pose at once (the newest frame that has arrived), then
    one per tracker frame (50 Hz ideal, 30 Hz camera on the field, a few dropped)."""
    async with running_agents(backend=backend, time_scale=5.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        t_sub = float((await c.ask("T,T,Q")).split(",")[-1])
        assert await c.ask("T,T,O,1") == "OK,O"
        poses = [line for line in await c.until("PO,", timeout=30) if line.startswith("PO,")]
        while len(poses) < 40:
            line = await c.recv(timeout=30)
            if line.startswith("PO,"):
                poses.append(line)
        await c.close()
    field = agents.params.field
    period = 1.0 / (field.camera_rate_hz if backend == "field" else agents.params.controller.control_rate_hz)
    latency = field.tracker_latency_s if backend == "field" else 0.0
    t = [float(p.split(",")[4]) for p in poses]
    assert t[0] >= t_sub - latency - period - 1e-6  # the newest frame that had arrived when it subscribed
    gaps = [b - a for a, b in pairwise(t)]
    assert min(gaps) > 0.5 * period and sorted(gaps)[len(gaps) // 2] == pytest.approx(period, abs=0.021)
    assert all(abs(float(p.split(",")[1]) - 100.0) < 5 and abs(float(p.split(",")[2]) - 100.0) < 5 for p in poses)
