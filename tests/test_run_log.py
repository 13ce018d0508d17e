"""A run's protocol log is capped (TWB_RUN_LOG_LINES) and a controller program's relayed lines have a share of
their own; the last line says how many were dropped and why.  The whole run on a real testbed:
tests/test_controller_flood.py."""

from __future__ import annotations

from types import SimpleNamespace

from server.pipeline.closed_loop import RELAY_LOGGED_LINES, ControllerRelay
from server.pipeline.context import RunContext


def context(log_lines: int) -> RunContext:
    assignment = SimpleNamespace(run_id=7, subfields=(1,))
    return RunContext(assignment, SimpleNamespace(engine=None), 1.0, log_lines=log_lines)  # type: ignore[arg-type]


def test_the_log_keeps_its_first_lines_and_says_how_many_it_dropped():
    ctx = context(100)
    for i in range(150):
        ctx.on_line(">", f"T,T,Q #{i}", None, False)
    ctx.finish_log()
    lines = [m["line"] for m in ctx.take_messages()]
    assert len(lines) == 101 and lines[99] == "T,T,Q #99"
    assert lines[-1] == "50 lines dropped: 50 lines beyond the 100 a run's log keeps"
    ctx.finish_log()  # said once
    assert ctx.take_messages() == []


def test_a_log_with_room_has_no_dropped_line():
    ctx = context(100)
    ctx.on_line("<", "OK,Q", None, False)
    ctx.finish_log()
    assert [m["line"] for m in ctx.take_messages()] == ["OK,Q"]


async def test_the_relay_logs_its_share_and_leaves_room_for_the_rest():
    ctx = context(RELAY_LOGGED_LINES + 50)
    link = SimpleNamespace(on_pose=None, on_line=ctx.on_line)
    relay = ControllerRelay(link, ctx, (1.0, 1.0), 0.05)  # type: ignore[arg-type]
    for i in range(RELAY_LOGGED_LINES + 30):
        link.on_line(">", f"T,T,V,{i},0", None, False)
    for i in range(20):  # the program's own report after the relay's lines still fits
        ctx.on_line("e", f"stderr {i}", None, False)
    relay.abort("program flooded its robot port: ...")
    relay.abort("said once")
    ctx.finish_log()
    lines = [m["line"] for m in ctx.take_messages()]
    assert lines.count("relay: program flooded its robot port: ...") == 1 and "relay: said once" not in lines
    assert sum(line.startswith("T,T,V") for line in lines) == RELAY_LOGGED_LINES and "stderr 19" in lines
    assert lines[-1] == (f"30 lines dropped: 30 relayed lines of the controller program beyond its first "
                         f"{RELAY_LOGGED_LINES}")
    assert relay.fault == "program flooded its robot port: ..."
