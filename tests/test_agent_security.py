"""Hardening of the robot ports over real sockets on 127.0.0.1: hostile lines, authentication and
leases, blocks bounded by the area, idle and line deadlines, connection limits and probation."""

from __future__ import annotations

import asyncio
import contextlib
import math
import random

import numpy as np
import pytest
from agent_support import OK_I, OK_S, LineClient, running_agents

from contract.auth import control_key, token_hash
from robot_agent.host import AgentHost
from contract.protocol import ErrorCode, encode_path, encode_place, format_error, format_ok, parse_reply

LIVENESS_S = 5.0  # generous: these tests check that answers come, never how fast
KEY = "control-key-0123456789"
LEASE = "lease-for-a-user-program-1"
SQUARE = np.array([[0.3, 0.3, 0.0], [0.8, 0.3, 0.0], [0.8, 0.8, math.pi / 2]])
LONG = np.array([[0.1, 0.1, 0.0], [1.7, 0.1, 0.0], [1.7, 1.7, 0.0]])
OK_A, OK_L = format_ok("A"), format_ok("L")
TOO_MANY = format_error(ErrorCode.STATE, "too many connections")


def err(code: ErrorCode) -> str:
    return f"ERR,{code.value},"


async def closed_by_agent(c: LineClient) -> bool:
    """Whether the agent closes ``c`` (end of stream within the liveness timeout; lines before it ignored)."""
    try:
        while True:
            await c.recv(timeout=LIVENESS_S)
    except ConnectionError:
        return True
    except asyncio.TimeoutError:
        return False


# --------------------------------------------------------------------------- hostile lines


async def test_a_long_digit_run_is_refused_while_other_connections_are_served():
    """The number regex used to take ~35 s on 40,000 digits, freezing every robot of the process."""
    async with running_agents(backend="ideal") as agents:
        bad = await LineClient.connect(agents.ports[0])
        other = await LineClient.connect(agents.ports[0])
        for line in (b"T,T,P," + b"1" * 40_000 + b"x", b"T,T,P," + b"1" * 60_000, b"T,T,B," + b"1" * 40_000 + b"x"):
            await bad.send(line)
            assert (await asyncio.wait_for(other.ask("T,T,Q"), LIVENESS_S)).startswith("ST,IDLE")
            assert (await bad.recv(timeout=LIVENESS_S)).startswith(err(ErrorCode.SYNTAX))
        assert (await bad.ask("T,T,Q")).startswith("ST,IDLE")
        await bad.close()
        await other.close()


async def test_every_control_character_in_a_number_is_refused_and_the_connection_kept():
    async with running_agents(backend="ideal") as agents:
        c = await LineClient.connect(agents.ports[0])
        for code in [x for x in range(0x20) if x != 0x0A] + [0x7F]:
            reply = await c.ask(b"T,T,P,1" + bytes([code]) + b"00,100,0")
            assert reply.startswith(err(ErrorCode.SYNTAX)) and f"0x{code:02X}" in reply and "column 8" in reply, reply
        assert (await c.ask("T,T,Q")).startswith("ST,IDLE")  # nothing moved, the connection still works
        await c.close()


def _fuzz_line(rng: random.Random) -> bytes:
    seeds = [b"T,T,P,100,100,0;500,100,90", b"T,T,B,900,450,60,300,0", b"T,T,I,300,300,0", b"T,T,Q", b"T,T,S",
             b"T,T,A,0123456789abcdef", b"T,T,L,0123456789abcdef", b"T,T,P,1e3,2E2,-4.5;.5,5.,+6"]
    alphabet = b"0123456789+-.eE ,;TPSQIBAL\t\r\x00\x1c\x7f\x80\xff"
    kind = rng.randrange(3)
    if kind == 0:
        line = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 50)))
    elif kind == 1:
        line = bytes(rng.choice(alphabet) for _ in range(rng.randrange(0, 80)))
    else:
        buf = bytearray(rng.choice(seeds))
        for _ in range(rng.randrange(0, 4)):
            buf.insert(rng.randrange(len(buf) + 1), rng.choice(alphabet))
        line = bytes(buf)
    return line.replace(b"\n", b"")


async def test_fuzzed_lines_each_get_exactly_one_reply_and_never_kill_the_connection():
    rng = random.Random(20261123)
    lines = [_fuzz_line(rng) for _ in range(3000)]
    async with running_agents(backend="ideal") as agents:
        c = await LineClient.connect(agents.ports[0])
        for start in range(0, len(lines), 100):
            batch = lines[start : start + 100]
            c.writer.write(b"".join(line + b"\n" for line in batch))
            await c.writer.drain()
            for line in batch:
                reply = await c.recv(timeout=LIVENESS_S)
                while reply.startswith("EV,"):  # events of a path the fuzz happened to send
                    reply = await c.recv(timeout=LIVENESS_S)
                assert reply.split(",")[0] in ("OK", "ST", "ERR"), (line, reply)
        assert (await c.ask("T,T,Q")).startswith("ST,")
        await c.close()


# --------------------------------------------------------------------------- authentication


async def test_with_a_control_key_only_authenticated_connections_move_the_robot():
    async with running_agents(backend="ideal", control_key=KEY) as agents:
        c = await LineClient.connect(agents.ports[0])
        for line in (encode_path(SQUARE), "T,T,S", encode_place(SQUARE[0]), "T,T,B,900,900,100,100,0", "T,T,B",
                     "T,T,L," + LEASE):
            assert (await c.ask(line)).startswith(err(ErrorCode.AUTH)), line
        assert (await c.ask("T,T,Q")).startswith("ST,IDLE")  # the query stays open
        assert await c.ask("T,T,A," + KEY) == OK_A
        assert await c.ask(encode_place(SQUARE[0])) == OK_I
        assert await c.ask("T,T,B,1500,300,100,100,0") == format_ok("B", 1)
        assert await c.ask(encode_path(SQUARE)) == format_ok("P", 3)
        assert (await c.until("EV,DONE", "EV,FAIL"))[-1].startswith("EV,DONE")
        other = await LineClient.connect(agents.ports[0])  # authentication is per connection
        assert (await other.ask("T,T,S")).startswith(err(ErrorCode.AUTH))
        await other.close()
        await c.close()


async def test_five_wrong_secrets_close_the_connection():
    async with running_agents(backend="ideal", control_key=KEY) as agents:
        c = await LineClient.connect(agents.ports[0])
        for left in (4, 3, 2, 1):  # the count left, in words that agree with it
            attempts = "attempt" if left == 1 else "attempts"
            assert await c.ask("T,T,A,not-the-control-key") == f"{err(ErrorCode.AUTH)}wrong secret ({left} {attempts} left)"
        assert (await c.ask("T,T,A,malformed")).startswith(err(ErrorCode.SYNTAX))  # cannot be a secret: not counted
        assert await c.ask("T,T,A," + KEY) == OK_A  # the right key after four wrong ones
        assert (await c.ask("T,T,A,not-the-control-key")).startswith(err(ErrorCode.AUTH))
        assert await closed_by_agent(c)
        again = await LineClient.connect(agents.ports[0])  # the agent and the robot carry on
        assert (await again.ask("T,T,Q")).startswith("ST,IDLE")
        await again.close()


async def test_leases_are_granted_revoked_and_end_with_their_granter():
    async with running_agents(backend="ideal", control_key=KEY) as agents:
        server = await LineClient.connect(agents.ports[0])
        user = await LineClient.connect(agents.ports[0])
        assert (await user.ask("T,T,A," + LEASE)).startswith(err(ErrorCode.AUTH))  # no lease granted yet
        assert await server.ask("T,T,A," + KEY) == OK_A
        assert (await server.ask("T,T,L," + KEY)).startswith(err(ErrorCode.RANGE))  # never the key itself
        assert await server.ask("T,T,L," + LEASE) == OK_L
        assert await user.ask("T,T,A," + LEASE) == OK_A
        assert (await user.ask("T,T,L,a-lease-of-my-own-1")).startswith(err(ErrorCode.AUTH))  # key holders only
        assert await user.ask(encode_path(SQUARE)) == format_ok("P", 3)
        assert (await user.until("EV,DONE", "EV,FAIL"))[-1].startswith("EV,DONE")
        assert await server.ask("T,T,L") == OK_L  # revoked: the user's authentication ends with it
        assert (await user.ask("T,T,S")).startswith(err(ErrorCode.AUTH))
        assert (await user.ask("T,T,A," + LEASE)).startswith(err(ErrorCode.AUTH))
        second, third = "second-lease-000001", "third-lease-0000001"
        assert await server.ask("T,T,L," + second) == OK_L
        assert await user.ask("T,T,A," + second) == OK_A
        assert await user.ask("T,T,S") == OK_S
        assert await server.ask("T,T,L," + third) == OK_L  # one lease at a time: the new one replaces it
        assert (await user.ask("T,T,S")).startswith(err(ErrorCode.AUTH))
        assert await user.ask("T,T,A," + third) == OK_A
        assert await user.ask("T,T,S") == OK_S
        await server.close()  # the granter leaves: its lease ends
        for _ in range(100):
            reply = await user.ask("T,T,S")
            if reply != OK_S:
                break
            await asyncio.sleep(0.05)
        assert reply.startswith(err(ErrorCode.AUTH))
        assert (await user.ask("T,T,A," + third)).startswith(err(ErrorCode.AUTH))
        await user.close()


async def test_without_a_control_key_the_robot_is_open_as_before():
    async with running_agents(backend="ideal") as agents:
        c = await LineClient.connect(agents.ports[0])
        assert await c.ask(encode_path(SQUARE)) == format_ok("P", 3)
        assert (await c.until("EV,DONE", "EV,FAIL"))[-1].startswith("EV,DONE")
        assert await c.ask("T,T,A,any-well-formed-secret") == OK_A  # nothing to check
        assert await c.ask("T,T,L," + LEASE) == OK_L and await c.ask("T,T,L") == OK_L
        assert await c.ask("T,T,S") == OK_S
        await c.close()


def test_the_derived_key_is_hmac_sha256_of_the_robot_id_keyed_with_the_token_hash():
    # a known answer, computed independently with: openssl dgst -sha256 -hmac "$(sha256 of the token)"
    assert token_hash("twb_example-token") == "0677ca373439d05cf3f3ae37888b2c4acedab17d2625eafef0b6eb840e23ccf4"
    assert control_key(token_hash("twb_example-token"), "field-1") == (
        "f5e3549f3a4392a502c01ce4beb70d0994047b39ce7e83bcb94420ce4cd48769")
    with pytest.raises(ValueError, match="token_hash"):
        control_key("twb_example-token", "field-1")  # the token itself, not its hash


async def test_agents_registered_with_a_server_derive_a_key_per_robot():
    token = "twb_a-token-for-the-derived-keys"
    server = {"server_url": "http://127.0.0.1:9", "token": token}  # nobody listens: registration just retries
    async with running_agents(backend="ideal", robots=2, **server) as agents:
        keys = [control_key(token_hash(token), r.robot_id) for r in agents.robots]
        assert [r.control_key for r in agents.robots] == keys and keys[0] != keys[1]
        c = await LineClient.connect(agents.ports[1])
        assert (await c.ask("T,T,S")).startswith(err(ErrorCode.AUTH))
        assert (await c.ask("T,T,A," + keys[0])).startswith(err(ErrorCode.AUTH))  # robot 1's key
        assert await c.ask("T,T,A," + keys[1]) == OK_A
        assert await c.ask("T,T,S") == OK_S
        await c.close()
    async with running_agents(backend="ideal", derive_control_key=False, **server) as agents:  # asked not to
        assert agents.robots[0].control_key is None
    async with running_agents(backend="ideal") as agents:  # standalone: open, as in the paper
        assert agents.robots[0].control_key is None
    async with running_agents(backend="ideal", control_key=KEY, **server) as agents:
        assert agents.robots[0].control_key == KEY  # an explicit key wins


def test_key_options_are_checked():
    with pytest.raises(ValueError, match="derive_control_key"):
        AgentHost(derive_control_key=True)
    with pytest.raises(ValueError, match="control_key.*16 to 128"):
        AgentHost(control_key="short")
    with pytest.raises(ValueError, match="idle_timeout_s"):
        AgentHost(idle_timeout_s=0)


# --------------------------------------------------------------------------- the world


async def test_a_block_beyond_the_area_is_refused_and_the_neighbour_drives_on():
    async with running_agents(backend="ideal", robots=2) as agents:  # one field, robot 2 on the next sub-field
        one = await LineClient.connect(agents.ports[0])
        two = await LineClient.connect(agents.ports[1])
        assert (await one.ask("T,T,B,900,900,100000000,100000000,0")).startswith(err(ErrorCode.RANGE))
        assert (await one.ask("T,T,B,1700,900,400,100,0")).startswith(err(ErrorCode.RANGE))  # 100 mm too far
        assert agents.world.blocks_local(0).shape == (0, 5)
        assert await two.ask(encode_path(SQUARE)) == format_ok("P", 3)
        assert (await two.until("EV,DONE", "EV,FAIL"))[-1].startswith("EV,DONE")
        await one.close()
        await two.close()


# --------------------------------------------------------------------------- deadlines and limits


async def test_idle_connections_are_closed_with_a_last_line():
    async with running_agents(backend="ideal", idle_timeout_s=0.5) as agents:

        async def busy() -> None:  # accepted lines keep a connection open well past the timeout
            c = await LineClient.connect(agents.ports[0])
            for _ in range(30):
                assert (await c.ask("T,T,Q")).startswith("ST,")
                await asyncio.sleep(0.05)
            await c.close()

        async def chatty() -> str:  # refused lines do not
            c = await LineClient.connect(agents.ports[0])
            for _ in range(100):
                reply = await c.ask("garbage")
                if not reply.startswith(err(ErrorCode.SYNTAX)):
                    break
                await asyncio.sleep(0.05)
            assert await closed_by_agent(c)
            return reply

        async def idle() -> str:
            c = await LineClient.connect(agents.ports[0])
            line = await c.recv(timeout=LIVENESS_S)
            assert await closed_by_agent(c)
            return line

        _, refused, silent = await asyncio.gather(busy(), chatty(), idle())
        assert refused == silent == format_error(ErrorCode.STATE, "idle timeout")


async def test_who_drives_or_has_authenticated_is_not_idle_closed_while_the_robot_moves():
    async with running_agents(backend="field", time_scale=1.0, idle_timeout_s=0.5, control_key=KEY) as agents:
        driver = await LineClient.connect(agents.ports[0])
        watcher = await LineClient.connect(agents.ports[0])
        stranger = await LineClient.connect(agents.ports[0])
        assert await driver.ask("T,T,A," + KEY) == OK_A
        assert await watcher.ask("T,T,A," + KEY) == OK_A
        assert await driver.ask(encode_path(LONG)) == format_ok("P", 3)  # several seconds of driving
        assert await stranger.recv(timeout=LIVENESS_S) == format_error(ErrorCode.STATE, "idle timeout")
        await asyncio.sleep(1.5)  # three idle timeouts, nothing said
        assert parse_reply(await watcher.ask("T,T,Q")).fields[0] == "MOVING"
        assert parse_reply(await driver.ask("T,T,Q")).fields[0] == "MOVING"
        assert not any(x.startswith("ERR") for x in driver.stash)
        await driver.send("T,T,S")
        await driver.until(OK_S)
        await driver.close()
        await watcher.close()


async def test_a_line_must_be_completed_in_time():
    async with running_agents(backend="ideal", line_timeout_s=0.5) as agents:
        slow = await LineClient.connect(agents.ports[0])
        other = await LineClient.connect(agents.ports[0])

        async def dribble() -> None:
            with contextlib.suppress(ConnectionError, OSError):
                for byte in b"T,T,Q" * 20:
                    slow.writer.write(bytes([byte]))
                    await slow.writer.drain()
                    await asyncio.sleep(0.05)

        task = asyncio.create_task(dribble())
        assert await slow.recv(timeout=LIVENESS_S) == format_error(ErrorCode.STATE, "line timeout")
        assert await closed_by_agent(slow)
        assert (await other.ask("T,T,Q")).startswith("ST,")
        task.cancel()
        await other.close()


async def test_deadlines_are_kept_from_the_right_moment():
    """The idle deadline counts from the last accepted line, the line deadline from the line's first byte
    (a line started late in an idle wait still gets its whole line timeout), neither ends early."""
    loop = asyncio.get_running_loop()
    async with running_agents(backend="ideal", idle_timeout_s=0.6, line_timeout_s=0.5) as agents:
        idle = await LineClient.connect(agents.ports[0])
        t_accepted = loop.time()  # at the latest when the agent accepts the line
        assert (await idle.ask("T,T,Q")).startswith("ST,")
        assert await idle.recv(timeout=LIVENESS_S) == format_error(ErrorCode.STATE, "idle timeout")
        assert 0.6 <= loop.time() - t_accepted < 0.6 + LIVENESS_S

        slow = await LineClient.connect(agents.ports[0])
        await asyncio.sleep(0.4)  # most of a line timeout into the idle wait
        await slow.send(b"T,T,", end=b"")
        t_first = loop.time()
        assert await slow.recv(timeout=LIVENESS_S) == format_error(ErrorCode.STATE, "line timeout")
        assert 0.5 <= loop.time() - t_first < 0.5 + LIVENESS_S


async def test_connections_are_bounded_per_peer_and_in_all():
    async with running_agents(backend="ideal", max_connections_per_peer=3, max_connections=5) as agents:
        port = agents.ports[0]
        clients = [await LineClient.connect(port) for _ in range(3)]
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        line = await asyncio.wait_for(reader.readline(), LIVENESS_S)
        assert line.decode().rstrip() == format_error(ErrorCode.STATE, "too many connections from 127.0.0.1")
        assert await asyncio.wait_for(reader.read(), LIVENESS_S) == b""
        writer.close()
        await clients.pop().close()
        for _ in range(100):  # its place is free again once the agent noticed
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            line = await asyncio.wait_for(reader.readline(), LIVENESS_S)
            writer.close()
            if line.startswith(b"HELLO,"):
                break
            await asyncio.sleep(0.05)
        assert line.startswith(b"HELLO,")
        for c in clients:
            await c.close()
    async with running_agents(backend="ideal", max_connections=2) as agents:  # the total, without a key
        clients = [await LineClient.connect(agents.ports[0]) for _ in range(2)]
        reader, writer = await asyncio.open_connection("127.0.0.1", agents.ports[0])
        assert (await asyncio.wait_for(reader.readline(), LIVENESS_S)).decode().rstrip() == TOO_MANY
        writer.close()
        for c in clients:
            await c.close()


async def test_at_the_cap_a_connection_that_authenticates_first_still_gets_in():
    async with running_agents(backend="ideal", control_key=KEY, max_connections=4, max_probation_connections=2,
                              probation_s=2.0) as agents:
        port = agents.ports[0]
        hogs = [await LineClient.connect(port) for _ in range(4)]  # idle, unauthenticated: the robot is full
        rude = await LineClient.connect(port)  # greeted on probation ...
        assert await rude.ask("T,T,Q") == TOO_MANY  # ... but its first line must authenticate
        assert await closed_by_agent(rude)
        wrong = await LineClient.connect(port)
        assert await wrong.ask("T,T,A,not-the-control-key") == TOO_MANY
        assert await closed_by_agent(wrong)
        silent = await LineClient.connect(port)
        assert await silent.recv(timeout=LIVENESS_S) == TOO_MANY  # after probation_s
        assert await closed_by_agent(silent)
        first, second = await LineClient.connect(port), await LineClient.connect(port)
        controller = await LineClient.connect(port)  # probation is full: the oldest makes room
        assert await first.recv(timeout=LIVENESS_S) == TOO_MANY
        assert await controller.ask("T,T,A," + KEY) == OK_A
        assert await controller.ask(encode_path(SQUARE)) == format_ok("P", 3)
        assert (await controller.until("EV,DONE", "EV,FAIL"))[-1].startswith("EV,DONE")
        for c in (*hogs, second, controller):
            await c.close()
