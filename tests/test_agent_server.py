"""The agent's TCP protocol server over real sockets on 127.0.0.1: commands, events, bad input, faults."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
from agent_support import OK_I, OK_S, LineClient, running_agents

from contract.protocol import MAX_LINE_BYTES, MAX_POINTS, ErrorCode, encode_build, encode_path, encode_place, format_ok, parse_reply

SQUARE = np.array([[0.3, 0.3, 0.0], [0.8, 0.3, 0.0], [0.8, 0.8, math.pi / 2]])


def err(code: ErrorCode) -> str:
    return f"ERR,{code.value},"


async def test_greeting_query_and_path_to_done():
    async with running_agents(backend="ideal") as agents:
        c = await LineClient.connect(agents.ports[0])
        st = parse_reply(await c.ask("T,T,Q"))
        assert st.kind == "ST" and st.fields[0] == "IDLE"
        assert await c.ask(encode_place(SQUARE[0])) == OK_I
        assert await c.ask(encode_path(SQUARE)) == format_ok("P", 3)
        lines = await c.until("EV,DONE", "EV,FAIL")
        kinds = [parse_reply(x).fields[:2] for x in lines]
        assert kinds[0] == ("START", kinds[0][1]) and lines[-1].startswith("EV,DONE")
        assert [f[1] for f in kinds if f[0] == "WP"] == ["0", "1", "2"]
        st = parse_reply(await c.ask("T,T,Q"))
        assert st.fields[0] == "DONE"
        x, y, a = (float(v) for v in st.fields[1:4])
        assert math.hypot(x - 800, y - 800) < 20 and abs(a - 90) < 5
        assert float(st.fields[4]) >= parse_reply(lines[-1]).time > parse_reply(lines[0]).time
        await c.close()


async def test_stop_and_path_replacement():
    async with running_agents(backend="field", time_scale=20.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        long_path = np.array([[0.1, 0.1, 0], [1.7, 0.1, 0], [1.7, 1.7, 0]])
        await c.ask(encode_path(long_path))
        await c.until("EV,START")
        assert parse_reply(await c.ask("T,T,Q")).fields[0] == "MOVING"
        # a new path replaces the old one: FAIL,STOPPED for the old one, then OK,P
        await c.send(encode_path(long_path[1:]))
        lines = await c.until("OK,P")
        assert any(x.startswith("EV,FAIL,STOPPED") for x in lines)
        await c.until("EV,START")
        await c.send("T,T,S")
        lines = await c.until(OK_S)
        assert lines[-2].startswith("EV,FAIL,STOPPED")
        assert parse_reply(await c.ask("T,T,Q")).fields[0] == "FAILED"
        assert await c.ask("T,T,S") == OK_S  # nothing to stop: still OK
        await c.close()


async def test_place_and_build_refused_while_moving():
    async with running_agents(backend="ideal", time_scale=20.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_path(np.array([[0.1, 0.1, 0], [1.7, 0.1, 0]])))
        await c.until("EV,START")
        assert (await c.ask("T,T,I,500,500,0")).startswith(err(ErrorCode.STATE))
        assert (await c.ask("T,T,B,500,500,100,100,0")).startswith(err(ErrorCode.STATE))
        await c.close()


async def test_bad_lines_get_errors_and_leave_robot_and_others_untouched():
    async with running_agents(backend="ideal") as agents:
        bad = await LineClient.connect(agents.ports[0])
        good = await LineClient.connect(agents.ports[0])
        before = await good.ask("T,T,Q")
        cases = [
            (b"", ErrorCode.SYNTAX),
            (b"   ", ErrorCode.SYNTAX),
            (b"\xff\xfe garbage \x00", ErrorCode.SYNTAX),
            ("h\u00e9llo".encode(), ErrorCode.SYNTAX),
            (b"T,T,P,100,100", ErrorCode.SYNTAX),
            (b"T,T,P,100,100,0,5", ErrorCode.SYNTAX),
            (b"T,T,P", ErrorCode.SYNTAX),
            (b"T,T,P,nan,100,0", ErrorCode.SYNTAX),
            (b"T,T,P,100,inf,0", ErrorCode.SYNTAX),
            (b"T,T,P,1e999,100,0", ErrorCode.SYNTAX),
            (b"T,T,P,100,100,0;2000,100,0", ErrorCode.RANGE),
            (b"T,T,P,-1,100,0", ErrorCode.RANGE),
            (b"T,T,I,100,1900,0", ErrorCode.RANGE),
            (b"T,T,I,100,100", ErrorCode.SYNTAX),
            (b"T,T,Q,1", ErrorCode.SYNTAX),
            (b"T,T,X", ErrorCode.UNSUPPORTED),
            (b"HELLO", ErrorCode.SYNTAX),
            (b"T,T,B,100,100,0,10,0", ErrorCode.RANGE),
            (("T,T,P," + ";".join(["100,100,0"] * (MAX_POINTS + 1))).encode(), ErrorCode.RANGE),
        ]
        for line, code in cases:
            reply = await bad.ask(line)
            assert reply.startswith(err(code)), (line[:40], reply)
            assert await good.ask("T,T,Q") == before  # the other client is served; the robot did not move
        await bad.close()
        await good.close()


async def test_max_points_is_accepted():
    async with running_agents(backend="ideal") as agents:
        c = await LineClient.connect(agents.ports[0])
        xs = np.linspace(0.1, 1.7, MAX_POINTS)
        path = np.column_stack([xs, np.full_like(xs, 0.1), np.zeros_like(xs)])
        assert await c.ask(encode_path(path)) == format_ok("P", MAX_POINTS)
        assert await c.ask("T,T,S") != ""
        await c.close()


async def test_over_long_line_is_refused_and_connection_still_works():
    async with running_agents(backend="ideal") as agents:
        c = await LineClient.connect(agents.ports[0])
        other = await LineClient.connect(agents.ports[0])
        big = b"T,T,P," + b"1" * (MAX_LINE_BYTES + 10)
        c.writer.write(big[: MAX_LINE_BYTES // 2])
        await c.writer.drain()
        assert (await other.ask("T,T,Q")).startswith("ST,")  # served while a huge line arrives
        c.writer.write(big[MAX_LINE_BYTES // 2 :] + b"\n")
        assert (await c.recv()).startswith(err(ErrorCode.TOOLONG))
        assert (await c.ask("T,T,Q")).startswith("ST,IDLE")
        # exactly at the limit (terminator included) is a normal line; one more byte is TOOLONG
        filler = b"T,T,Q" + b" " * (MAX_LINE_BYTES - 6)
        assert (await c.ask(filler)).startswith("ST,")
        assert (await c.ask(filler + b" ")).startswith(err(ErrorCode.TOOLONG))
        assert (await c.ask("T,T,Q")).startswith("ST,")
        await c.close()
        await other.close()


async def test_half_a_line_then_disconnect_and_crlf():
    async with running_agents(backend="ideal") as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.send(b"T,T,P,100,100,0;500,", end=b"")
        await c.close()
        d = await LineClient.connect(agents.ports[0])
        await d.send("T,T,Q", end=b"\r\n")
        assert parse_reply(await d.recv()).fields[0] == "IDLE"
        await d.close()


async def test_disconnect_mid_path_stops_the_robot():
    seen: list[tuple[str, str]] = []
    async with running_agents(backend="field", time_scale=20.0) as agents:
        agents.add_event_listener(lambda rid, line: seen.append((rid, line)))
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_path(np.array([[0.1, 0.1, 0], [1.7, 0.1, 0], [1.7, 1.7, 0]])))
        await c.until("EV,START")
        await c.close()
        watcher = await LineClient.connect(agents.ports[0])
        for _ in range(100):
            st = parse_reply(await watcher.ask("T,T,Q"))
            if st.fields[0] != "MOVING":
                break
            await asyncio.sleep(0.01)
        assert st.fields[0] == "FAILED"
        assert any(line.startswith("EV,FAIL,STOPPED") for _, line in seen)
        # the robot comes to rest and stays there
        await asyncio.sleep(0.2)
        a = parse_reply(await watcher.ask("T,T,Q")).fields[1:3]
        await asyncio.sleep(0.1)
        assert parse_reply(await watcher.ask("T,T,Q")).fields[1:3] == a
        await watcher.close()


async def test_events_go_only_to_the_sender():
    async with running_agents(backend="ideal") as agents:
        sender = await LineClient.connect(agents.ports[0])
        other = await LineClient.connect(agents.ports[0])
        await sender.ask(encode_path(SQUARE))
        await sender.until("EV,DONE")
        assert parse_reply(await other.ask("T,T,Q")).fields[0] == "DONE"  # no EV lines came first
        await sender.close()
        await other.close()


async def test_hundred_concurrent_clients_and_an_idle_one():
    async with running_agents(backend="ideal", robots=4, time_scale=50.0) as agents:
        idle = await LineClient.connect(agents.ports[0])  # connects and never reads nor writes
        clients = await asyncio.gather(*(LineClient.connect(agents.ports[i % 4]) for i in range(100)))

        async def chat(i: int, c: LineClient) -> None:
            for _ in range(5):
                assert (await c.ask("T,T,Q")).startswith("ST,")
            if i < 4:  # one driver per robot
                assert await c.ask(encode_path(SQUARE)) == format_ok("P", 3)
                await c.until("EV,DONE")

        await asyncio.gather(*(chat(i, c) for i, c in enumerate(clients)))
        for c in clients:
            await c.close()
        await idle.close()


async def test_a_client_that_never_reads_does_not_stall_the_robot():
    async with running_agents(backend="ideal") as agents:
        hog = await LineClient.connect(agents.ports[0])
        flood = b"T,T,Q\n" * 20000  # many replies it will not read
        hog.writer.write(flood)
        c = await LineClient.connect(agents.ports[0])
        assert await c.ask(encode_path(SQUARE)) == format_ok("P", 3)
        assert (await c.until("EV,DONE", "EV,FAIL"))[-1].startswith("EV,DONE")  # the robot drove on
        assert (await c.ask("T,T,Q")).startswith("ST,DONE,")
        hog.writer.transport.abort()
        await c.close()


async def test_stopping_the_agent_mid_build_ends_the_connection_quietly():
    """A connection waiting for the gripper when the agent stops ends without an unhandled exception."""
    reported: list[dict] = []
    loop = asyncio.get_running_loop()
    loop.set_exception_handler(lambda _loop, ctx: reported.append(ctx))
    async with running_agents(backend="field", time_scale=1.0) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.send(encode_build([(0.9, 0.9, 0.1, 0.1, 0.0)]))  # the gripper takes seconds
        await asyncio.sleep(0.2)
    await asyncio.sleep(0.2)
    loop.set_exception_handler(None)
    assert reported == []


@pytest.mark.parametrize("backend", ["field", "ideal"])
async def test_gripper_builds_and_places_in_experiment_time(backend):
    """The field gripper takes time per block and placement; in the ideal simulator worlds appear at once."""
    async with running_agents(backend=backend, time_scale=math.inf) as agents:
        c = await LineClient.connect(agents.ports[0])
        t0 = parse_reply(await c.ask("T,T,Q")).time
        blocks = [(0.9, 0.9, 0.1, 0.1, 0.0), (1.2, 0.9, 0.1, 0.1, 0.3)]
        assert await c.ask(encode_build(blocks)) == format_ok("B", 2)
        t1 = parse_reply(await c.ask("T,T,Q")).time
        field = backend == "field"
        assert t1 - t0 == pytest.approx(2 * agents.params.gripper.seconds_per_block if field else 0.0, abs=0.05)
        assert await c.ask(encode_place((0.5, 0.5, 0.0))) == OK_I
        t2 = parse_reply(await c.ask("T,T,Q")).time
        assert t2 - t1 == pytest.approx(agents.params.gripper.seconds_per_placement if field else 0.0, abs=0.05)
        assert (await c.ask(encode_place((0.9, 0.9, 0.0)))).startswith(err(ErrorCode.RANGE))  # on a block
        assert await c.ask("T,T,B") == format_ok("B", 0)  # clears (removing takes time too)
        np.testing.assert_array_equal(agents.world.blocks_local(0).shape, (0, 5))
        await c.close()


@pytest.mark.parametrize("n", [2])
async def test_robots_on_consecutive_ports_with_their_own_ids(n):
    async with running_agents(backend="ideal", robots=n, robot_id="bot") as agents:
        for r in agents.robots:
            c = await LineClient.connect(r.port, hello=f"HELLO,{r.robot_id},BeBot,1")
            await c.close()
        assert [r.robot_id for r in agents.robots] == ["bot-1", "bot-2"]
        assert [r.origin for r in agents.robots] == [(0.0, 0.0), (1.8, 0.0)]
