"""``twb agent``: run emulated robots speaking the wire protocol (docs/design.md, "Robot protocol" and "Command line")."""

from __future__ import annotations

import logging
import math
import signal
from enum import Enum
from typing import Annotated, Optional

import typer

from .errors import fail
from .event_loop import run as run_loop
from .poses import parse_time_scale


class BackendName(str, Enum):
    ideal = "ideal"
    field = "field"


class WorldMode(str, Enum):
    auto = "auto"
    shared = "shared"
    separate = "separate"


def _pair(text: str | None, what: str) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = [p.strip() for p in text.split(",")]
    try:
        w, h = (float(p) for p in parts)
    except ValueError:
        fail(f"--{what} must be two numbers W,H in metres, got {text!r}")
    if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
        fail(f"--{what} must be two finite numbers > 0, got {text!r}")
    return w, h


def agent(
    port: Annotated[int, typer.Option(help="TCP port of the first robot (0: any free port); robot i listens on PORT+i-1.")] = 5555,
    robot_id: Annotated[Optional[str], typer.Option(help="Robot name; with --robots N the names are ID-1..ID-N (default: robot-1..).")] = None,
    profile: Annotated[str, typer.Option(help="Robot profile: bebot or khepera3.")] = "bebot",
    backend: Annotated[BackendName, typer.Option(help="ideal (Player/Stage-like) or field (emulated physical robot).")] = BackendName.field,
    time_scale: Annotated[str, typer.Option(help="Experiment seconds per wall second (1 = live); 'max' runs as fast as possible.")] = "1",
    server: Annotated[Optional[str], typer.Option(help="Testbed server URL: register the robots and post tracker poses there.")] = None,
    token: Annotated[Optional[str], typer.Option(help="Bearer token for --server.", envvar="TWB_TOKEN")] = None,
    robots: Annotated[int, typer.Option(help="Number of robots on consecutive ports: up to 4 share the field (sub-fields 1-4); more get a world each.", min=1, max=1000)] = 1,
    seed: Annotated[int, typer.Option(help="Agent seed: each path's noise derives from (seed, robot id, path count).", envvar="TWB_AGENT_SEED")] = 0,
    tracker_csv: Annotated[Optional[str], typer.Option(help="Write tracker poses (t,x,y,theta) to this CSV file; {robot_id} or -<id> per robot.")] = None,
    area: Annotated[Optional[str], typer.Option(help="Working area W,H in metres, e.g. 3.6,3.6 for the whole field (default: 1.8,1.8, a sub-field).")] = None,
    world: Annotated[WorldMode, typer.Option(help="shared: one field for all robots; separate: a world each; auto: shared up to 4 robots on sub-fields, separate for more or for several whole-field robots (a simulation pool).")] = WorldMode.auto,
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    subfield: Annotated[Optional[int], typer.Option(help="Put a single robot on sub-field K (1-4) of the field: its frame's origin is that sub-field's lower-left corner.", min=1, max=4)] = None,
    advertise_host: Annotated[Optional[str], typer.Option(help="Host name the server should use to reach these robots (e.g. a container name) (default: --host).")] = None,
    control_key: Annotated[Optional[str], typer.Option(help="Robot-port control key of a standalone agent (16-128 printable ASCII characters, no , or ;): only connections that send T,T,A,KEY (or a lease it grants) may move the robots or build; T,T,Q stays open. Default: none, every connection may. With --server the key of each robot is the one the server derives from --token.", envvar="TWB_CONTROL_KEY")] = None,
    clock: Annotated[str, typer.Option(help="How the clock treats a closed-loop controller that subscribes with plain T,T,O,1: 'lockstep' waits for its answer to every pose (results independent of the time scale), 'free' runs on (docs/protocol.md, \"Lockstep\").", envvar="TWB_CLOCK")] = "lockstep",
    lockstep_wait: Annotated[float, typer.Option(help="Wall seconds a lockstep clock waits for a controller's answer before it runs on without it (the controller has lapsed; docs/protocol.md, \"Lockstep\").", envvar="TWB_LOCKSTEP_WAIT_S", min=0.01, max=600)] = 3.0,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log every path and event.")] = False,
) -> None:
    """Run emulated robots speaking the T,T,P line protocol until Ctrl-C (logs on stderr)."""
    import asyncio

    from contract.robot_profile import profile_names
    from robot_agent.host import AgentHost
    from robot_agent.host.sinks import CsvTrackerSink

    if profile not in profile_names():
        fail(f"unknown --profile {profile!r} (profiles: {', '.join(profile_names())})")
    scale = parse_time_scale(time_scale)
    if clock not in ("lockstep", "free"):
        fail(f"--clock {clock!r}: expected 'lockstep' or 'free'")
    if server and not token:
        fail("--server needs --token (or TWB_TOKEN)")
    if server and control_key:
        fail("--control-key is for standalone agents: with --server each robot's key derives from --token, "
             "so that the server can drive it")
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.getLogger("robot_agent.host").setLevel(logging.INFO)
    sink = CsvTrackerSink(tracker_csv, many=robots > 1) if tracker_csv else None
    origins = None
    if subfield is not None:
        if robots != 1:
            fail("--subfield places a single robot; use it with --robots 1")
        from contract.frames import SUBFIELD_ORIGINS

        origins, world = [SUBFIELD_ORIGINS[subfield - 1]], WorldMode.shared
    agents = AgentHost(
        robots=robots, backend=backend.value, profile=profile, host=host, port=port, time_scale=scale,
        seed=seed, robot_id=robot_id, world=world.value, area=_pair(area, "area"), origins=origins,
        tracker_sink=sink, server_url=server, token=token, advertise_host=advertise_host,
        control_key=control_key or None, clock=clock, lockstep_wait_s=lockstep_wait,
    )

    async def run() -> None:
        # Ctrl-C and SIGTERM stop the robots cleanly, also when this process was started with SIGINT ignored
        # (a background job of a script), where asyncio's own Ctrl-C handling stays off
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await agents.start()
        try:
            await stop.wait()
        finally:
            await agents.stop()
        logging.getLogger("robot_agent.host").warning("stopped")

    try:
        run_loop(run())
    except KeyboardInterrupt:
        logging.getLogger("robot_agent.host").warning("stopped")
