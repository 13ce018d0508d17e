"""AgentHost: N robots in one asyncio process — TCP servers, the simulation loop, tracker output.

The Python API the testbed server embeds::

    async with AgentHost(robots=4, backend="field", time_scale=100.0,
                         tracker_sink=MemoryTrackerSink()) as agents:
        agents.ports                   # bound TCP ports, robot i on ports[i]
        agents.set_path_seed("robot-1", 42)   # the next T,T,P of robot-1 replays seed 42
        ...

or ``host = await start_agents(...)`` / ``await host.stop()``.

Time: the simulation advances in fixed control steps (``1 / control_rate_hz``
of experiment time).  With ``time_scale`` S it keeps experiment time at S x
wall time (``math.inf``: as fast as possible, yielding to the event loop
every few milliseconds; experiment time then stands still while nothing
moves).  While no robot moves, time jumps instead of stepping.  All times
reported (EV, ST, tracker) are experiment time.  A closed-loop controller in
lockstep (``clock="lockstep"``, the default; :mod:`.lockstep`) holds the clock
at every pose it is sent until it answers: experiment time then runs at most
S x wall time, and as fast as the controllers answer.

Localisation (``T,T,O,1``): every subscribed robot's tracker poses at the
tracker's rate, moving or standing, as ``PO`` lines.

Seeds: each path's noise key is ``path_key(seed, robot_id, path_count)``
from the host's ``seed``, or ``path_key(s)`` when :meth:`set_path_seed` gave
the next path a seed ``s`` (the same ``s`` replays the same run on any robot).

Robot ports: registered with a testbed server, each robot has the control
key the server derives from the token (:mod:`contract.auth`); with an
explicit ``control_key`` all robots have that one.  Then only authenticated
connections move robots or change the world; a standalone agent (no server,
no key) lets every connection, as in the paper.  Connections are bounded in number,
per peer address and in idle time (:class:`robot_agent.host.connection.Limits`).
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import logging
import math
import socket
import time
from typing import Callable

import numpy as np

from contract import auth
from contract.frames import field_layout
from contract.params import RobotParams, robot_params
from contract.protocol import (CLOCKS, MAX_LINE_BYTES, ErrorCode, VelocityCommand, check_secret, format_error,
                               format_localisations)
from contract.robot_profile import DEFAULT_PROFILE
from robot_agent.engine.backends import make_backend
from robot_agent.engine.noise import path_key
from robot_agent.engine.sim import SimCore, SimEvent, kernels_ready, warm_up
from robot_agent.engine.world import World

from .connection import TOO_MANY, Connection, Limits
from .lockstep import Lockstep, Pending
from .robot import WATCHDOG_S, Robot, RobotServices
from .server_link import ServerLink
from .sinks import TrackerSink

__all__ = ["AgentHost", "EventListener", "start_agents"]

log = logging.getLogger("robot_agent.host")

EventListener = Callable[[str, str], None]
_SLICE_S = 0.004  # longest run of simulation steps between yields to the event loop
_CHUNK_ROBOT_STEPS = 4096  # robot-steps per call of the compiled loop (~1 ms) between checks of the slice
_MAX_LAG_S = 0.5  # wall seconds behind schedule before the clock gives up catching up
_TIMER_SLACK_S = 0.001  # wall seconds added to every wait of the simulation loop (timer resolution)
_STANDING_SPAN = 250  # control steps of standing frames made at most at once (after a long stall of the loop)


class AgentHost:
    """``robots`` emulated robots served on consecutive TCP ports (see the module docstring).

    Parameters (SI units): ``backend`` ``ideal`` or ``field``; ``profile`` a
    shipped profile name or dict; ``host``/``port`` where to listen (``port``
    0: every robot gets a free port); ``time_scale`` experiment seconds per
    wall second (``math.inf`` = as fast as possible); ``seed`` the agent seed;
    ``robot_id`` a base name (``robot`` gives ``robot-1`` ...) or
    ``robot_ids`` one per robot; ``world``, ``area`` (one or per robot), ``origins`` the layout
    (:func:`contract.frames.field_layout`); ``tracker_sink`` where logged
    poses go; ``server_url`` + ``token`` register the robots with the testbed
    server and, without another sink, post the poses there.  ``clock`` is how the clock treats a
    closed-loop connection that subscribes without naming one (``T,T,O,1``): ``lockstep`` (wait for its
    answer to every pose; :mod:`.lockstep`) or ``free``; ``lockstep_wait_s`` the wall seconds the clock waits
    for one answer before it goes on without it.
    """

    def __init__(
        self,
        *,
        robots: int = 1,
        backend: str = "ideal",
        profile: str | dict = DEFAULT_PROFILE,
        host: str = "127.0.0.1",
        port: int = 0,
        time_scale: float = 1.0,
        seed: int = 0,
        robot_id: str | None = None,
        robot_ids: list[str] | None = None,
        world: str = "auto",
        area: tuple[float, float] | list[tuple[float, float]] | None = None,
        origins: list[tuple[float, float]] | None = None,
        tracker_sink: TrackerSink | None = None,
        server_url: str | None = None,
        token: str | None = None,
        advertise_host: str | None = None,
        max_connections: int = 256,
        flush_interval_s: float = 0.25,
        control_key: str | None = None,
        derive_control_key: bool | None = None,
        max_connections_per_peer: int = 32,
        max_probation_connections: int = 16,
        idle_timeout_s: float = 300.0,
        line_timeout_s: float = 30.0,
        probation_s: float = 5.0,
        clock: str = "lockstep",
        lockstep_wait_s: float = 3.0,
    ) -> None:
        if clock not in CLOCKS:
            raise ValueError(f"`clock` must be one of {', '.join(CLOCKS)}, got {clock!r}")
        if not lockstep_wait_s > 0:
            raise ValueError(f"`lockstep_wait_s` must be > 0 seconds, got {lockstep_wait_s}")
        if not (time_scale > 0):  # also refuses NaN
            raise ValueError(f"`time_scale` must be > 0 (math.inf: as fast as possible), got {time_scale}")
        if not 0 <= port <= 65535 or (port and port + robots - 1 > 65535):
            raise ValueError(f"`port` must be 0..65535 (and leave room for {robots} robots), got {port}")
        if server_url and not token:
            raise ValueError("`server_url` needs a `token`")
        if derive_control_key and not (server_url and token):
            raise ValueError("`derive_control_key` needs `server_url` and `token`")
        if derive_control_key is None:  # registered with a server: the server drives with the derived keys
            derive_control_key = bool(server_url and token) and control_key is None
        if control_key is not None:
            try:
                check_secret(control_key)
            except ValueError as exc:
                raise ValueError(f"`control_key`: {exc}") from None
        self.limits = Limits(max_connections=max_connections, max_per_peer=max_connections_per_peer,
                             max_probation=max_probation_connections, idle_timeout_s=idle_timeout_s,
                             line_timeout_s=line_timeout_s, probation_s=probation_s)
        self.params: RobotParams = robot_params(profile)
        self.backend_name = backend
        self.time_scale = float(time_scale)
        self.clock = clock
        self.seed = int(seed)
        self.bind_host, self.base_port = host, port
        self.advertise_host = advertise_host or (socket.gethostname() if host in ("", "0.0.0.0", "::") else host)
        self.flush_interval_s = flush_interval_s
        sizes, world_of, origin, areas = field_layout(robots, world, area, origins)
        self.world = World(sizes, world_of, origin, areas, self.params.collision_radius_m)
        self.link = ServerLink(server_url, token or "") if server_url else None
        self.sink: TrackerSink | None = tracker_sink if tracker_sink is not None else self.link
        self._shipping = asyncio.Lock()  # one tracker shipment at a time (see _ship_poses)
        self.core = SimCore(self.params, make_backend(backend, robots, self.params), self.world,
                            log_poses=self.sink is not None)
        self.core.inline_replan = False  # replans are planned in a worker thread (_replan)
        self._chunk = max(1, _CHUNK_ROBOT_STEPS // robots)  # steps per compiled call when running ahead
        # localisation lines (T,T,O): the tracker's poses, due after the mode's latency; a heap of
        # (due time, sequence, robot index, line)
        self._po_queue: list[tuple[float, int, int, str]] = []
        self._po_seq = itertools.count()
        self._po_robots = np.zeros(robots, dtype=bool)  # robots with a subscribed connection
        self._po_list: list[int] = []  # ... their indices
        self._po_any = False
        self._po_latency = self.core.backend.latency_steps * self.core.dt
        self.core.poses.listener = self._on_poses
        self._stand_next = np.zeros(robots, dtype=np.int64)  # next global step of a standing robot's frames
        self.lockstep = Lockstep(robots, self.core.dt, lockstep_wait_s)
        if robot_ids is None:
            base = robot_id or "robot"
            robot_ids = [robot_id] if (robot_id and robots == 1) else [f"{base}-{i + 1}" for i in range(robots)]
        if len(robot_ids) != robots or len(set(robot_ids)) != robots:
            raise ValueError(f"`robot_ids` must be {robots} distinct names")
        token_hash = auth.token_hash(token) if derive_control_key and token else None
        services = RobotServices(self.core, self.world, self.params, self.seed, self.backend_name, self.advertise_host,
                                 self.sync_clock, self.wake, self.sleep, self.event_hook, self.localisation_changed,
                                 self.answer, self.path_started)
        self.robots = [
            Robot(services, i, rid, control_key=control_key if control_key is not None or token_hash is None
                  else auth.control_key(token_hash, rid))
            for i, rid in enumerate(robot_ids)
        ]
        homes: dict[tuple, int] = {}
        for r in self.robots:
            r.hello()  # validates the id (ASCII, no separators)
            # parked near the area's lower-left corner, side by side when areas share an origin
            key = (int(self.world.world_of[r.index]), *self.world.origin[r.index].round(6))
            k = homes[key] = homes.get(key, -1) + 1
            self.core.place(r.index, (0.1 + 0.15 * k, 0.1, 0.0))
        self._by_id = {r.robot_id: r for r in self.robots}
        # the noise of the frames the tracker takes of each robot outside its paths (a stream of its own)
        self._stand_keys = [path_key(self.seed ^ 0x57A9D1, r.robot_id) for r in self.robots]
        self._listeners: list[EventListener] = []
        self._servers: list[asyncio.base_events.Server] = []
        self._tasks: list[asyncio.Task] = []
        self._conn_tasks: set[asyncio.Task] = set()
        self._timers: list[tuple[int, int, asyncio.Future]] = []
        self._seq = itertools.count()
        self._wake = asyncio.Event()
        self._wall0 = 0.0
        self._step0 = 0
        self._last_lag_warning = -math.inf
        self._running = False

    # ------------------------------------------------------------------ API

    @property
    def ports(self) -> list[int]:
        """The bound TCP port of each robot (after :meth:`start`)."""
        return [r.port for r in self.robots]

    def robot(self, robot_id: str) -> Robot:
        """The robot called ``robot_id`` (``KeyError`` if unknown)."""
        return self._by_id[robot_id]

    def now(self) -> float:
        """Experiment time (s)."""
        return self.core.t

    def set_path_seed(self, robot_id: str, seed: int | None) -> None:
        """Seed the noise of ``robot_id``'s next path (one-shot); None returns to the default derivation."""
        self.robot(robot_id).next_seed = None if seed is None else int(seed)

    def add_event_listener(self, fn: EventListener) -> None:
        """Call ``fn(robot_id, line)`` for every EV line (also when no client is left to receive it)."""
        self._listeners.append(fn)

    def event_hook(self, robot: Robot, line: str) -> None:
        if line.startswith(("EV,FAIL", "EV,DONE")):
            self.lockstep.clear(robot.index)  # its velocity mode (or path) ended: no answer is awaited any more
        for fn in self._listeners:
            try:
                fn(robot.robot_id, line)
            except Exception:  # noqa: BLE001 - a listener's bug must not stop the robots
                log.exception("event listener failed")

    async def start(self) -> "AgentHost":
        """Bind the servers, start the simulation and register with the server (if any)."""
        if self._running:
            return self
        loop = asyncio.get_running_loop()
        if not kernels_ready():
            log.info("loading the simulation kernels (the first start after installing compiles them, ~12 s)")
            await asyncio.to_thread(warm_up)
        try:
            for r in self.robots:
                port = self.base_port + r.index if self.base_port else 0
                server = await asyncio.start_server(
                    lambda rd, wr, robot=r: self._accept(robot, rd, wr), self.bind_host, port, limit=MAX_LINE_BYTES
                )
                self._servers.append(server)
                r.port = server.sockets[0].getsockname()[1]
        except OSError:
            for s in self._servers:
                s.close()
            self._servers.clear()
            raise
        self._running = True
        self._reanchor()
        self._tasks.append(loop.create_task(self._sim_loop(), name="twb-sim"))
        if self.sink is not None:
            self._tasks.append(loop.create_task(self._flush_loop(), name="twb-tracker-flush"))
        if self.link is not None:
            for r in self.robots:
                self.link.register(r.info())
        log.info("%d %s robot(s) (%s) on %s ports %s, time scale %s, seed %d", len(self.robots), self.backend_name,
                 self.params.name, self.bind_host, self.ports, self.time_scale, self.seed)
        return self

    async def stop(self) -> None:
        """Close every connection and server, flush the tracker and stop the simulation."""
        if not self._running:
            return
        self._running = False
        for s in self._servers:
            s.close()
        for r in self.robots:
            for c in list(r.connections):
                c.close()
        if self._conn_tasks:
            _, pending = await asyncio.wait(self._conn_tasks, timeout=2.0)
            for t in pending:
                t.cancel()
        for t in self._tasks:
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()
        for _, _, fut in self._timers:
            fut.cancel()
        await self.flush_tracker(wait=False)
        if self.sink is not None:
            await self.sink.aclose()  # a ServerLink delivers for at most a second more
        if self.link is not None and self.link is not self.sink:
            await self.link.aclose()
        for s in self._servers:
            await s.wait_closed()
        self._servers.clear()

    async def __aenter__(self) -> "AgentHost":
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def flush_tracker(self, *, wait: bool = True, timeout_s: float = 5.0) -> None:
        """Hand every logged pose to the sink now; with ``wait``, also wait (at most ``timeout_s``)
        until a server sink delivered them."""
        if self.sink is None:
            return
        await self._ship_poses()
        if wait and isinstance(self.sink, ServerLink):
            await self.sink.flush(timeout_s)

    # ------------------------------------------------------------------ clock

    def wake(self) -> None:
        """Something changed: the simulation loop re-plans now."""
        self._wake.set()

    def _reanchor(self) -> None:
        self._wall0 = time.monotonic()
        self._step0 = self.core.step_count

    def _due(self) -> float:
        """The step count experiment time should have reached by now."""
        if math.isinf(self.time_scale):
            return math.inf
        return self._step0 + (time.monotonic() - self._wall0) * self.time_scale / self.core.dt

    def sync_clock(self) -> None:
        """While nothing moves, bring experiment time up to date (before applying a command)."""
        if self._running and not self.core.busy():
            self._advance_idle()

    def _advance_idle(self) -> None:
        due = self._due()
        if math.isinf(due):
            target = self._timers[0][0] if self._timers else self.core.step_count
        else:
            target = int(due)
        if target > self.core.step_count:
            self.core.skip(target - self.core.step_count)
        if self._po_any:
            self._standing()
        if self._po_queue:
            self._send_localisation()
        self._fire_timers()

    def _fire_timers(self) -> None:
        while self._timers and self._timers[0][0] <= self.core.step_count:
            _, _, fut = heapq.heappop(self._timers)
            if not fut.done():
                fut.set_result(None)

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of experiment time."""
        steps = math.ceil(seconds / self.core.dt - 1e-9)
        if steps <= 0:
            return
        self.sync_clock()
        fut = asyncio.get_running_loop().create_future()
        heapq.heappush(self._timers, (self.core.step_count + steps, next(self._seq), fut))
        self.wake()
        await fut

    async def _wait(self, timeout: float | None) -> None:
        """Until :meth:`wake` or ``timeout`` wall seconds (None: no limit), a little late rather than early:
        a loop whose timers have millisecond resolution (uvloop) would otherwise wake before the next
        step is due and spin."""
        try:
            async with asyncio.timeout(None if timeout is None else timeout + _TIMER_SLACK_S):
                await self._wake.wait()
        except TimeoutError:
            pass
        self._wake.clear()

    async def _sim_loop(self) -> None:
        core = self.core
        steps_per_s = self.time_scale / core.dt
        while True:
            if not core.busy():
                self._advance_idle()
                if core.busy():
                    continue
                await self._idle(steps_per_s)
                continue
            lock = self._po_any and self._lockstep_step()
            if lock and self._held():
                await self._await_answer()
                continue
            due = self._due()
            if due - core.step_count > _MAX_LAG_S * steps_per_s:
                now = time.monotonic()
                if now - self._last_lag_warning > 10.0:
                    log.warning("simulation cannot keep up with time scale %s; experiment time runs slower",
                                self.time_scale)
                    self._last_lag_warning = now
                self._reanchor()
                due = self._due()
            end = time.perf_counter() + _SLICE_S
            while core.step_count + 1 <= due:
                # one step at a time while poses are sent: each goes out in the step it is due, and a lockstep
                # controller's answer applies in its step (lockstep.py)
                steps = 1 if self._po_any else min(due - core.step_count, self._chunk)
                if self._timers:
                    steps = min(steps, self._timers[0][0] - core.step_count)
                events = core.advance(max(int(steps), 1))
                if self._po_any:
                    self._standing()
                if self._po_queue:
                    self._send_localisation()
                if events:
                    self._dispatch(events)
                if self._timers and self._timers[0][0] <= core.step_count:
                    self._fire_timers()
                if not core.busy() or time.perf_counter() > end or core.replan_pending():
                    break
                if self._po_any and self._lockstep_step() and self._held():
                    break
            if core.replan_pending():
                await self._replan()
                continue
            if self._po_any and self._held():
                continue  # the top of the loop waits for the answer
            if not core.busy() or core.step_count + 1 <= self._due():
                await asyncio.sleep(0)
            else:
                await self._wait((core.step_count + 1 - self._due()) / steps_per_s)

    async def _idle(self, steps_per_s: float) -> None:
        """Nothing moves: wait until something is due (a timer, a localisation line, a standing robot's next
        frame) or :meth:`wake`."""
        core = self.core
        if math.isinf(steps_per_s):  # time stands still while nothing moves: only timers move it
            if self._timers:
                await asyncio.sleep(0)
            else:
                await self._wait(None)
            return
        nxt = math.inf
        if self._timers:
            nxt = self._timers[0][0]
        if self._po_queue:
            nxt = min(nxt, math.ceil(self._po_queue[0][0] / core.dt - 1e-9))
        if self._po_any:  # standing subscribed robots: their frames
            nxt = min(nxt, core.step_count + 1)
        if math.isinf(nxt):
            await self._wait(1.0)
        else:
            await self._wait(min(max(0.0, (nxt - self._due()) / steps_per_s), 1.0))

    # ------------------------------------------------------------------ lockstep

    def _driver(self, i: int) -> Connection | None:
        """Robot ``i``'s lockstep controller: the connection driving it in velocity mode, subscribed to its
        poses in lockstep; None when there is none."""
        conn = self.robots[i].owner
        if conn is None or not conn.localisation or (conn.clock or self.clock) != "lockstep" \
                or not self.core.driving(i):
            return None
        return conn  # type: ignore[return-value]

    def _lockstep_step(self) -> bool:
        """Before the next control step: apply the answers due in it, send a free controller the pose withheld
        meanwhile, forget robots without a lockstep controller.  Whether any robot has one."""
        ls, core = self.lockstep, self.core
        lock = False
        for i in self._po_list:
            driver = self._driver(i)
            if driver is None:
                if ls.active(i):
                    ls.clear(i)
                continue
            lock = True
            p = ls.pending.get(i)
            if p is not None and p.step <= core.step_count:
                del ls.pending[i]
                core.drive(i, p.v, p.w, 0, WATCHDOG_S)
            w = ls.withheld.get(i)
            if w is not None and not ls.busy(i, core.step_count):
                del ls.withheld[i]
                ls.deliver(i, max(w[0], core.t), time.monotonic())
                driver.send(w[1])
        return lock

    def _held(self) -> bool:
        """Whether the next control step waits for a lockstep controller's answer."""
        limit = self.lockstep.limit()
        return limit is not None and limit <= self.core.step_count

    async def _await_answer(self) -> None:
        """Wait for the answer the clock needs (at most the controller's ``wait_s`` since its pose was sent;
        then it lapses and the clock goes on without it)."""
        ls = self.lockstep
        i = ls.oldest_awaited()
        if i is None:
            return
        left = ls.sent[i] + ls.wait_s - time.monotonic()
        if left <= 0:
            ls.lapse(i)
            log.warning("%s: its lockstep controller did not answer a pose within %g s; the clock goes on "
                        "without it", self.robots[i].robot_id, ls.wait_s)
            return
        await self._wait(left)
        if not math.isinf(self.time_scale) and self._due() > self.core.step_count + 1:
            # the time spent waiting is not made up: the next step is due now, the time scale holds from there
            self._wall0 = time.monotonic()
            self._step0 = self.core.step_count + 1

    def answer(self, robot: Robot, conn: Connection, cmd: VelocityCommand) -> bool:
        """A ``T,T,V`` of ``conn`` on a robot in velocity mode: True when it answers the pose its lockstep
        controller was sent (then it applies in its control step, :mod:`.lockstep`); False: it applies now."""
        i, ls = robot.index, self.lockstep
        if conn is not self._driver(i):
            return False
        if i in ls.lapsed:  # it answers again: in lockstep from its next pose
            ls.lapsed.discard(i)
            return False
        if ls.hold[i] < 0:  # a line of its own, answering no pose
            return False
        step = ls.answer(i, cmd.compute_s or 0.0)
        if step <= self.core.step_count:
            self.core.drive(i, cmd.v, cmd.w, 0, WATCHDOG_S)
        else:
            ls.pending[i] = Pending(step, cmd.v, cmd.w)
        self.wake()
        return True

    async def _replan(self) -> None:
        """The replanning checks due now (:mod:`robot_agent.engine.replan`): the blocked robots' new paths are planned
        in a worker thread while the simulation waits (so a run replans the same at every time scale); the
        event loop serves the connections meanwhile, and a path that changed meanwhile drops its replan."""
        from robot_agent.engine.replan import solve

        for req in self.core.replan_requests():
            res = await asyncio.to_thread(solve, req)
            ev = self.core.apply_replan(req, res)
            if ev is not None:
                self._dispatch([ev])

    def localisation_changed(self) -> None:
        """A connection subscribed to ``PO`` lines or left: which robots have subscribers now.  A robot that
        gets its first subscriber sends the frames the tracker has in flight and the newest one that already
        arrived: its first ``PO`` line comes at once."""
        before = self._po_robots.copy()
        self._po_robots[:] = [any(c.localisation for c in r.connections) for r in self.robots]
        self._po_list = np.flatnonzero(self._po_robots).tolist()
        self._po_any = bool(self._po_robots.any())
        if self._po_any:
            self.core.log_poses = True  # a host without a tracker sink logs poses for its subscribers
        for i in np.flatnonzero(before & ~self._po_robots).tolist():
            self.lockstep.clear(i)
        if self._running:
            for i in np.flatnonzero(self._po_robots & ~before).tolist():
                self._first_frames(i)
            self.wake()

    def _first_frames(self, i: int) -> None:
        """Robot ``i`` just got a subscriber: queue the tracker's newest frame that has arrived by now and those
        in flight (taken within its latency)."""
        core, b = self.core, self.core.backend
        lat = b.latency_steps
        if not core.moving(i):  # standing: from its newest good frame that has arrived
            f = core.step_count - lat
            while f > core.step_count - lat - 4 * core.params.controller.control_rate_hz \
                    and not b.measure(i, f, self._stand_keys[i])[0]:
                f -= 1
            self._stand_next[i] = f
            self._standing()
        elif lat > 0:  # on a path: the measurements in its tracker's ring (Emulated backends)
            ring, ok, pos = getattr(b, "ring", None), getattr(b, "ring_ok", None), getattr(b, "ring_pos", None)
            if ring is None:
                return
            slots = ring.shape[1]
            t, rows = [], []
            for p in range(int(pos[i]) - slots, int(pos[i])):
                if p >= 0 and ok[i, p % slots]:
                    t.append((core.step_count - int(pos[i]) + p) * core.dt)
                    rows.append(ring[i, p % slots].copy())
            if t:
                self._queue_lines(i, np.array(t), np.array(rows))

    def _standing(self) -> None:
        """The tracker's frames of subscribed robots outside a path (standing, or coasting after one), up to
        this control step; a moving robot's come from its path (:meth:`_on_poses`)."""
        core, b = self.core, self.core.backend
        now = core.step_count
        for i in self._po_list:
            if core.moving(i):
                self._stand_next[i] = now + 1
                continue
            start = max(int(self._stand_next[i]), now - _STANDING_SPAN)
            if start > now:
                continue
            t, rows = [], []
            for f in range(start, now + 1):
                ok, meas = b.measure(i, f, self._stand_keys[i])
                if ok:
                    t.append(f * core.dt)
                    rows.append(meas)
            self._stand_next[i] = now + 1
            if t:
                self._queue_lines(i, np.array(t), np.array(rows))

    def path_started(self, robot: Robot) -> None:
        """A path or velocity mode of ``robot`` starts: the frames of it in flight (taken before) are dropped, so
        that its ``PO`` lines from now on are its run's alone (the same in every replay of the run)."""
        self.lockstep.clear(robot.index)
        if any(e[2] == robot.index for e in self._po_queue):
            self._po_queue = [e for e in self._po_queue if e[2] != robot.index]
            heapq.heapify(self._po_queue)

    def _queue_lines(self, i: int, t: np.ndarray, poses: np.ndarray) -> None:
        """Queue ``PO`` lines of robot ``i``: poses ``(K, 3)`` measured at ``t`` ``(K,)``, due after the latency."""
        for tt, line in zip(t.tolist(), format_localisations(t, poses)):
            heapq.heappush(self._po_queue, (tt + self._po_latency, next(self._po_seq), i, line))

    def _on_poses(self, t: np.ndarray, robots: np.ndarray, poses: np.ndarray) -> None:
        """Tracker poses just logged (``t`` s, robot indices, ``(K, 3)`` m/rad): queue a ``PO`` line of each
        subscribed robot's, due after the latency."""
        if not self._po_any:
            return
        keep = np.flatnonzero(self._po_robots[robots])
        if len(keep):
            lines = format_localisations(t[keep], poses[keep])
            for tt, i, line in zip((t[keep] + self._po_latency).tolist(), robots[keep].tolist(), lines):
                heapq.heappush(self._po_queue, (tt, next(self._po_seq), i, line))

    def _send_localisation(self) -> None:
        """Send the ``PO`` lines that are due by now to their robot's subscribed connections; a lockstep
        controller gets its robot's line only when it is free (:mod:`.lockstep`)."""
        now = self.core.t + 1e-9
        q, ls, step = self._po_queue, self.lockstep, self.core.step_count
        while q and q[0][0] <= now:
            due, _, i, line = heapq.heappop(q)
            driver = self._driver(i)
            for conn in self.robots[i].connections:
                if not conn.localisation:
                    continue
                if conn is driver and i not in ls.lapsed:
                    if ls.busy(i, step):
                        ls.withheld[i] = (due, line)
                        continue
                    ls.deliver(i, max(due, self.core.t), time.monotonic())  # sent now (due may lie in this step)
                conn.send(line)
        if self.sink is None and self.core.poses.count:
            self.core.poses.clear()  # nobody else wants them

    def _dispatch(self, events: list[SimEvent]) -> None:
        for ev in events:
            self.robots[ev.robot].on_event(ev)

    async def _ship_poses(self) -> None:
        """Hand the logged poses to the sink, one shipment at a time: a flush returns only once a shipment
        already under way (the periodic one, its poses drained but not yet delivered) has been delivered too."""
        async with self._shipping:
            for idx, rows in self.core.poses.drain().items():
                await self.sink.send(self.robots[idx].robot_id, rows)  # type: ignore[union-attr]

    async def _flush_loop(self) -> None:
        while True:
            await asyncio.sleep(self.flush_interval_s)
            try:
                await self._ship_poses()
            except Exception:  # noqa: BLE001 - a failing sink must not stop the robots
                log.exception("tracker sink failed")

    # ------------------------------------------------------------------ connections

    async def _accept(self, robot: Robot, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        probation = False
        full = self._full(robot, writer)
        if full or not self._running:
            if robot.control_key is None or not self._running:
                await _refuse(writer, full or TOO_MANY)
                return
            probation = True  # the robot's controller must always get in: it authenticates at once
            self._make_room_on_probation(robot)
        conn = Connection(reader, writer, robot, limits=self.limits, probation=probation)
        robot.connected(conn)
        if task is not None:
            self._conn_tasks.add(task)
        try:
            await conn.run()
        except asyncio.CancelledError:
            # the agent stops (a gripper wait cancelled, or the task itself): end quietly; Python 3.11's
            # stream callback would report a cancelled connection task as an unhandled exception
            pass
        except Exception:  # noqa: BLE001 - one client's trouble never reaches the others
            log.exception("%r failed", conn)
        finally:
            if task is not None:
                self._conn_tasks.discard(task)

    def _full(self, robot: Robot, writer: asyncio.StreamWriter) -> str | None:
        """Why ``robot`` has no regular place for a new connection from ``writer``'s peer, or None."""
        regular = [c for c in robot.connections if not c.probation]
        if len(regular) >= self.limits.max_connections:
            return TOO_MANY
        peer = writer.get_extra_info("peername")
        host = str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)
        if sum(1 for c in regular if c.peer_host == host) >= self.limits.max_per_peer:
            return f"{TOO_MANY} from {host}"
        return None

    def _make_room_on_probation(self, robot: Robot) -> None:
        """Drop the oldest connections on probation until a new one fits."""
        waiting = sorted((c for c in robot.connections if c.probation and not c.closed), key=lambda c: c.opened)
        for c in waiting[: max(0, len(waiting) - self.limits.max_probation + 1)]:
            c.refuse(TOO_MANY)


async def _refuse(writer: asyncio.StreamWriter, reason: str) -> None:
    """Answer a connection that gets no place with ``ERR,STATE,<reason>`` and close it."""
    writer.write((format_error(ErrorCode.STATE, reason) + "\n").encode())
    try:
        await writer.drain()
    except (ConnectionError, OSError):
        pass
    finally:
        writer.close()


async def start_agents(**kwargs: object) -> AgentHost:
    """Create and start an :class:`AgentHost` (same keyword arguments); ``await host.stop()`` ends it."""
    return await AgentHost(**kwargs).start()  # type: ignore[arg-type]

