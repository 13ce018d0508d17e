"""``twb up``, ``twb server`` and ``twb users``: run the testbed and manage its users."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import math
import os
import signal
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from .datadir import make_data_dir
from .errors import fail
from .event_loop import run as run_loop
from .poses import parse_time_scale
from .sdk_support import TokenOpt, UrlOpt, sdk_client

users_app = typer.Typer(help="Manage testbed users (needs the admin token).", no_args_is_help=True)


#: seconds a stop may take from the signal to the end of the process: the testbed's own stop (runs end
#: ``interrupted``, robots stop, workers end) normally takes well under one; what does not answer in time is
#: killed, as ``kill -9`` would (nothing is lost: a run left ``running`` is marked interrupted at the next start)
STOP_GRACE_S = 3.0


def _exit_now(testbed, why: str, code: int = 0) -> None:  # type: ignore[no-untyped-def]
    """End the process at once: the compute workers killed, the rest with the process (no thread joined)."""
    print(f"twb: {why}", file=sys.stderr, flush=True)
    try:
        testbed.pool.kill()
    finally:
        sys.stdout.flush()
        os._exit(code)


async def _serve(settings, testbed, host: str, port: int, on_ready):  # type: ignore[no-untyped-def]
    """Run uvicorn on the current loop until a signal; ``on_ready(url)`` is awaited once it listens.

    A signal during start-up (the first start compiles the simulation kernels in a thread that cannot be
    interrupted) ends the process at once: nothing has run that a hard stop would lose.  After start-up the
    testbed stops in order, within :data:`STOP_GRACE_S` — or is ended like a ``kill -9``; a second signal
    ends it at once."""
    import threading

    import uvicorn

    from server.app import create_app

    app = create_app(settings, testbed)
    config = uvicorn.Config(app, host=host, port=port, log_level="warning", lifespan="on",
                            timeout_graceful_shutdown=1, http=_guarded_http(settings, testbed), ws="none",
                            timeout_keep_alive=settings.http_keep_alive_s)
    server = uvicorn.Server(config)
    # the signals are ours (below), not uvicorn's: it would hold them until its start-up ends, then raise them again
    server.capture_signals = contextlib.nullcontext  # type: ignore[method-assign]
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()

    def on_signal() -> None:
        if stop.is_set():
            _exit_now(testbed, "stopped (second signal)", 130)
        stop.set()
        deadline = threading.Timer(STOP_GRACE_S, _exit_now, (testbed, f"stopped: what did not end within "
                                                             f"{STOP_GRACE_S:g} s was killed"))
        deadline.daemon = True
        deadline.start()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal)
    if os.environ.get("TWB_EXIT_WITH_PARENT") == "1":  # started by a program (twb study --embedded, tests)
        from server.core.lifeline import exit_with_parent

        exit_with_parent(action=lambda: os.kill(os.getpid(), signal.SIGTERM))
    serving = asyncio.create_task(server.serve())
    while not server.started:
        if stop.is_set():
            _exit_now(testbed, "stopped during start-up")
        if serving.done():
            serving.result()
            fail(f"the server could not start on {host}:{port}")
        await asyncio.sleep(0.05)
    bound = server.servers[0].sockets[0].getsockname()[1]
    url = f"http://{host}:{bound}"
    await on_ready(url)
    # Start-up objects (the numerical stack, the app) live for the whole process: keep the
    # collector from walking them again and again, which showed as 50-100 ms latency spikes.
    gc.collect()
    gc.freeze()
    try:
        await stop.wait()
    finally:
        print("twb: stopping...", file=sys.stderr, flush=True)
        # the lifespan stops the testbed in order: runs end interrupted, then the robots stop
        server.should_exit = True
        await asyncio.shield(serving)


def _guarded_http(settings, testbed) -> type:  # type: ignore[no-untyped-def]
    """uvicorn's HTTP protocol with the API's deadlines and connection caps (docs/security.md), the caps within
    this process's open-file limit (raised toward its hard limit first) beside the embedded robots' budget."""
    from server.api.connections import HttpLimits, connection_budget, guarded_protocol, raise_open_files_limit

    open_files = raise_open_files_limit()
    robots = testbed.embedded.descriptors() if testbed.embedded is not None else 0
    budget = connection_budget(settings.http_max_connections, robots, open_files)
    if budget < settings.http_max_connections:
        print(f"twb: the open-file limit ({open_files}) leaves the API {budget} HTTP connections "
              f"(TWB_HTTP_MAX_CONNECTIONS is {settings.http_max_connections}); raise it with `ulimit -n`",
              file=sys.stderr, flush=True)
    return guarded_protocol(HttpLimits(
        header_timeout_s=settings.http_header_timeout_s, body_timeout_s=settings.http_body_timeout_s,
        max_header_bytes=settings.http_max_header_bytes, max_connections=budget,
        max_per_peer=min(settings.http_max_connections_per_peer, budget)))


def _settings(data_dir: Path, token: Optional[str], time_scale: float, **extra):  # type: ignore[no-untyped-def]
    from server.core.settings import Settings

    try:
        make_data_dir(data_dir)
    except OSError as exc:
        fail(f"--data-dir {data_dir}: cannot create it: {exc.strerror or exc}")
    kwargs = {"data_dir": data_dir, "time_scale": time_scale, **extra}
    if token:
        kwargs["admin_token"] = token
    return Settings(**kwargs)


UPLOADS_HELP = ("Accept uploaded planner programs and run them sandboxed (docs/uploads.md); "
                "also TWB_UPLOADS_ENABLED=1.")


DATABASE_HELP = ("SQLAlchemy URL of the store, e.g. postgresql+psycopg://user:pass@host/db "
                 "(default: SQLite in --data-dir; also TWB_DATABASE_URL).")


def _database(url: Optional[str]) -> dict:
    """Settings for --database-url; without it TWB_DATABASE_URL (or SQLite in the data dir) decides."""
    return {"database_url": url} if url else {}


def _open(settings, **kwargs):  # type: ignore[no-untyped-def]
    """The testbed, its store migrated: (testbed, admin token); one clear line when the store is unusable."""
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError, OperationalError
    from sqlalchemy.engine import make_url

    from server.pipeline.ray_pool import EngineUnavailable
    from server.testbed import Testbed

    try:
        url = make_url(settings.database_url)
    except ArgumentError:
        fail(f"--database-url: not a database URL: {settings.database_url!r}")
    shown = url.render_as_string(hide_password=True)
    if url.get_backend_name() not in ("sqlite", "postgresql"):
        fail(f"--database-url {shown}: the testbed's store is SQLite or PostgreSQL (postgresql+psycopg://...)")
    try:
        testbed = Testbed(settings, **kwargs)
        return testbed, testbed.prepare()
    except EngineUnavailable as exc:
        fail(str(exc))
    except NoSuchModuleError as exc:
        fail(f"--database-url {shown}: {exc}")
    except OperationalError as exc:
        reason = " ".join(str(exc.orig).split()) if exc.orig is not None else str(exc)
        fail(f"cannot use the database at {shown}: {reason}")


SIM_ENGINE_HELP = ("Where simulation runs go: 'local' (robot agents) or 'ray' (Ray tasks; a local Ray cluster "
                   "unless --ray-address; docs/scale-out.md). Also TWB_SIM_ENGINE.")
RAY_ADDRESS_HELP = "host:port of an existing Ray cluster's head (implies --sim-engine ray; also TWB_RAY_ADDRESS)."
RAY_CPUS_HELP = "CPUs of the local Ray cluster (default: this machine's)."


def _engine(sim_engine: Optional[str], ray_address: Optional[str], ray_cpus: Optional[int]) -> dict:
    """Settings for --sim-engine/--ray-address/--ray-cpus; without them the TWB_* variables decide."""
    out: dict = {}
    if sim_engine:
        if sim_engine not in ("local", "ray"):
            fail(f"--sim-engine {sim_engine!r}: expected 'local' or 'ray'")
        out["sim_engine"] = sim_engine
    if ray_address:
        out["ray_address"] = ray_address
    if ray_cpus:
        out["ray_cpus"] = ray_cpus
    return out


def _engine_line(testbed) -> str:  # type: ignore[no-untyped-def]
    """How simulation runs are carried out, for the start-up lines."""
    pool = testbed.pool
    return f"Simulation runs: Ray tasks on {pool.description}." if getattr(pool, "engine", "") else ""


CLOCK_HELP = ("How robots' clocks treat closed-loop controllers: 'lockstep' (wait for the answer to every pose; the "
              "default) or 'free' (run on at the time scale); docs/protocol.md, \"Lockstep\". Also TWB_CLOCK.")


def _clock(clock: Optional[str]) -> dict:
    """Settings for --clock; without it TWB_CLOCK (or lockstep) decides."""
    if clock is None:
        return {}
    if clock not in ("lockstep", "free"):
        fail(f"--clock {clock!r}: expected 'lockstep' or 'free'")
    return {"clock": clock}


LOCKSTEP_WAIT_HELP = ("Wall seconds a lockstep clock waits for a closed-loop controller's answer before it runs on "
                      "without it (default 3; also TWB_LOCKSTEP_WAIT_S).")


def _uploads(enable: bool) -> dict:
    """Settings for --enable-uploads; without the flag TWB_UPLOADS_ENABLED decides."""
    return {"uploads_enabled": True} if enable else {}


async def _print_uploads(testbed) -> None:  # type: ignore[no-untyped-def]
    """One line on how uploaded programs are isolated here (only when uploads are enabled)."""
    if not testbed.settings.uploads_enabled:
        return
    iso = await testbed.sandbox.probe()
    ns = "+".join(iso["namespaces"]) or "none"
    box = f" in a {iso['sandbox']} sandbox" if iso.get("sandbox", "none") != "none" else ""
    print(f"Uploads: enabled; programs run as {iso['runs_as']}{box}, namespaces {ns}, network {iso['network']}"
          + (", seccomp allowlist" if iso.get("seccomp") else "")
          + (f" ({iso['note']})" if iso["note"] else ""), flush=True)


def up(
    port: Annotated[int, typer.Option(help="HTTP port of the API and dashboard (0: any free port).")] = 8000,
    host: Annotated[str, typer.Option(help="Interface to listen on.")] = "127.0.0.1",
    data_dir: Annotated[Path, typer.Option(help="Database, token file and logs.")] = Path("twb-data"),
    time_scale: Annotated[str, typer.Option(help="Experiment seconds per wall second (1 = live; 'max').")] = "1",
    token: Annotated[Optional[str], typer.Option(help="Fix the admin token instead of generating one.")] = None,
    sim_robots: Annotated[int, typer.Option(help="Size of the simulation pool (ideal robots).", min=1, max=1000)] = 4,
    seed: Annotated[int, typer.Option(help="Agent seed (runs are seeded from their job's seed).", min=0)] = 0,
    enable_uploads: Annotated[bool, typer.Option("--enable-uploads", help=UPLOADS_HELP)] = False,
    database_url: Annotated[Optional[str], typer.Option(help=DATABASE_HELP)] = None,
    sim_engine: Annotated[Optional[str], typer.Option(help=SIM_ENGINE_HELP)] = None,
    ray_address: Annotated[Optional[str], typer.Option(help=RAY_ADDRESS_HELP)] = None,
    ray_cpus: Annotated[Optional[int], typer.Option(help=RAY_CPUS_HELP, min=1)] = None,
    clock: Annotated[Optional[str], typer.Option(help=CLOCK_HELP)] = None,
    lockstep_wait: Annotated[Optional[float], typer.Option(help=LOCKSTEP_WAIT_HELP, min=0.01, max=600)] = None,
) -> None:
    """The whole testbed on this machine: server (on SQLite unless told), four field robots, a simulation pool."""
    from server.embedded import EmbeddedField

    scale = parse_time_scale(time_scale)
    settings = _settings(data_dir, token, scale, **_uploads(enable_uploads), **_database(database_url),
                         **_engine(sim_engine, ray_address, ray_cpus), **_clock(clock),
                         **({"lockstep_wait_s": lockstep_wait} if lockstep_wait is not None else {}))
    on_ray = settings.sim_engine == "ray"
    # nothing else shows until the banner: the robots' kernels load first (numba compiles them once)
    typer.echo("twb: starting the testbed (the first start after installing compiles the simulation kernels: "
               "about 12 s, up to a minute on a busy machine)", err=True)
    testbed, admin = _open(settings, embedded=EmbeddedField(sim_robots=0 if on_ray else sim_robots, seed=seed,
                                                            time_scale=scale, clock=settings.clock,
                                                            lockstep_wait_s=settings.lockstep_wait_s))

    async def ready(url: str):  # type: ignore[no-untyped-def]
        shown = "max" if math.isinf(scale) else f"{scale:g}x"
        print(f"Teleworkbench is up: {url}  (dashboard {url}/ , API docs {url}/docs)", flush=True)
        print(f"Admin token: {admin}  (also in {settings.token_file})", flush=True)
        sims = "simulation runs on Ray" if on_ray else f"{sim_robots} simulated"
        print(f"Robots: 4 field robots (sub-fields 1-4), {sims}; time scale {shown}, {settings.clock} clock. "
              "Ctrl-C stops everything.", flush=True)
        if on_ray:
            print(_engine_line(testbed), flush=True)
        await _print_uploads(testbed)
        return None

    run_loop(_serve(settings, testbed, host, port, ready))


def server(
    port: Annotated[int, typer.Option(help="HTTP port (0: any free port).")] = 8000,
    host: Annotated[str, typer.Option(help="Interface to listen on.")] = "127.0.0.1",
    data_dir: Annotated[Path, typer.Option(help="Database, token file and logs.")] = Path("twb-data"),
    time_scale: Annotated[str, typer.Option(help="Time scale the agents run at (for timeouts).")] = "1",
    token: Annotated[Optional[str], typer.Option(help="Fix the admin token instead of generating one.")] = None,
    enable_uploads: Annotated[bool, typer.Option("--enable-uploads", help=UPLOADS_HELP)] = False,
    database_url: Annotated[Optional[str], typer.Option(help=DATABASE_HELP)] = None,
    sim_engine: Annotated[Optional[str], typer.Option(help=SIM_ENGINE_HELP)] = None,
    ray_address: Annotated[Optional[str], typer.Option(help=RAY_ADDRESS_HELP)] = None,
    ray_cpus: Annotated[Optional[int], typer.Option(help=RAY_CPUS_HELP, min=1)] = None,
    clock: Annotated[Optional[str], typer.Option(help=CLOCK_HELP)] = None,
) -> None:
    """The server alone; robots join with `twb agent --server URL --token T`."""
    settings = _settings(data_dir, token, parse_time_scale(time_scale), **_uploads(enable_uploads),
                         **_database(database_url), **_engine(sim_engine, ray_address, ray_cpus), **_clock(clock))
    testbed, admin = _open(settings)

    async def ready(url: str):  # type: ignore[no-untyped-def]
        print(f"Teleworkbench server: {url}  (API docs {url}/docs)", flush=True)
        print(f"Admin token: {admin}  (also in {settings.token_file})", flush=True)
        if settings.sim_engine == "ray":
            print(_engine_line(testbed), flush=True)
        await _print_uploads(testbed)
        return None

    run_loop(_serve(settings, testbed, host, port, ready))


@users_app.command("create")
def users_create(
    name: Annotated[str, typer.Argument(help="User name (letters, digits, _ . -).")],
    admin: Annotated[bool, typer.Option(help="Give the user admin rights.")] = False,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Create a user and print its token (shown once); needs the admin token."""
    with sdk_client(url, token) as c:
        typer.echo(c.create_user(name, is_admin=admin).token)


@users_app.command("list")
def users_list(url: UrlOpt = None, token: TokenOpt = None) -> None:
    """List users; needs the admin token."""
    with sdk_client(url, token) as c:
        for u in c.list_users():
            typer.echo(f"{u.name}{' (admin)' if u.is_admin else ''}")
