"""Several robots' run as one function call: one shared world, one clock, no socket.

docs/server.md, "Multi-robot jobs", describes such runs.

The multi-robot sibling of :func:`robot_agent.engine.headless.simulate_run`.  ``N``
robots stand in ONE world of the environment's size (frame origin (0, 0) for
all of them), so they collide with the walls, the blocks, their moving
obstacles and each other (centres closer than two collision radii).  They
all start on the same step and each follows its own path with the same
compiled follower and controller as a single run; paths, placements, blocks
and moving obstacles go through the wire codec's rounding as over TCP.

**Holding at waypoints.**  ``T,T,P`` carries no times and the follower cannot
wait.  A fleet run is commanded by the testbed, though, which can hold a
robot: a path may come with departure times (``depart``, s on the fleet's
clock, NaN where there is no hold).  The path is then sent in *legs* split at
the held waypoints: the robot drives a leg to its end (it stops and turns
towards the next point), and the testbed sends the next leg once the clock
reached the waypoint's departure time -- at once if the robot is late.  Each
leg is a new path for the robot (a new noise key, ``path_key(seed, "robot-i",
leg)``, as an agent counts its paths), so a leg's moving obstacles are
re-sent with their clock shifted to the fleet's.  Events are reported per
robot as one path: one START, WP indices of the whole path, one DONE or FAIL.

**On the field** (backend ``field``) the moving obstacles are emulated robots
the testbed drives (:mod:`robot_agent.engine.movers`), one per obstacle, shared by
every robot of the fleet and driven on the fleet's clock from time 0; a robot
that hits one stops it for everyone.  What the tracker logged of them is in
:attr:`FleetRun.obstacles`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from contract.controller_specs import select
from contract.frames import FIELD_SIZE, MAX_ROBOTS
from contract.params import robot_params
from contract.protocol import (
    BuildCommand,
    MovingCommand,
    PathCommand,
    PlaceCommand,
    encode_build,
    encode_moving,
    encode_path,
    encode_place,
    parse_command,
)
from contract.robot_profile import DEFAULT_PROFILE

from .backends import make_backend
from .headless import HeadlessRun, PlacementRefused
from .movers import mover_tracks
from .noise import path_key
from .sim import SimCore, SimEvent
from .world import World

__all__ = ["FleetRun", "MAX_FLEET", "simulate_fleet"]

#: the most robots one fleet run takes: what the field's tracker follows
MAX_FLEET = MAX_ROBOTS
_CHUNK = 4096  # control steps per compiled call when no robot waits for a leg


@dataclass
class FleetRun:
    """What a fleet run gave: one :class:`~robot_agent.engine.headless.HeadlessRun` per robot (its tracker poses
    ``(N, 4)`` t s, x m, y m, theta rad on the fleet's clock, its events, start and end times), the
    ``holds`` each robot made (waypoint index, s held), ``dt`` (s, the control step) and, per hold, the
    robots it ``waited_for`` (executed by dependencies; empty: it waited for the plan's clock); on the field
    the tracker's poses of the obstacle robots, ``obstacles`` (per obstacle ``(T, 4)`` t s on the fleet's
    clock, x m, y m, theta rad; None: exact discs)."""

    runs: list[HeadlessRun]
    holds: list[list[tuple[int, float]]] = field(default_factory=list)
    dt: float = 0.02
    waited_for: list[list[list[int]]] = field(default_factory=list)
    obstacles: list[np.ndarray] | None = None

    @property
    def outcomes(self) -> list[str]:
        """Each robot's outcome: ``DONE``, the FAIL reason or ``TIMEOUT_SIM``."""
        return [r.outcome for r in self.runs]


def _legs(n_points: int, depart: np.ndarray | None) -> list[tuple[int, int, float]]:
    """``(first, last, release s)`` index ranges (inclusive) of a path of ``n_points`` split at its holds."""
    if depart is None:
        return [(0, n_points - 1, 0.0)]
    held = [k for k in range(n_points - 1) if math.isfinite(depart[k])]
    legs, first = [], 0
    release = float(depart[0]) if math.isfinite(depart[0]) else 0.0
    for k in held:
        if k == 0:
            continue
        legs.append((first, k, release))
        first, release = k + 1, float(depart[k])
    legs.append((first, n_points - 1, release))
    return legs


def simulate_fleet(paths: Sequence[Sequence[Sequence[float]] | np.ndarray], starts: Sequence[Sequence[float]], *,
                   seed: int, depart: Sequence[Sequence[float] | np.ndarray | None] | None = None,
                   blocks: Sequence[Sequence[float]] = (), moving: Sequence[tuple] = (), backend: str = "ideal",
                   profile: str | dict = DEFAULT_PROFILE, area: tuple[float, float] = FIELD_SIZE,
                   max_s: float = 3600.0, controller: str | None = None,
                   controller_params: dict[str, float] | None = None,
                   depends: Sequence[np.ndarray] | None = None) -> FleetRun:
    """Run robot ``i`` along ``paths[i]`` ``(N_i, 3)`` (m, m, rad) from ``starts[i]`` (x, y, theta) in one world
    of ``area`` (m) with ``blocks`` (cx, cy, w, h, angle: m, rad) and, for every robot, the ``moving``
    obstacles (params, waypoints, as :func:`~contract.protocol.encode_moving`; their time is the fleet's
    clock), all robots starting at time 0, until every robot ended its path or ``max_s`` (s) passed.

    ``depart[i]`` ``(N_i,)`` (optional): the time (s) robot ``i`` may leave waypoint ``k`` at the earliest
    (NaN: no hold); see the module's docstring.  ``depends[i]`` ``(N, N_i)`` (optional, int): execute by
    the plan's order of passage instead of the clock: robot ``i`` leaves waypoint ``k`` only once every
    robot ``h`` reached its waypoint ``depends[i][h, k]``
    (:func:`planners.dependencies.fleet_dependencies`; the departure times stay lower bounds).  The seed gives every robot's noise.
    A replanning controller (``replan`` = 1) replans each robot around the moving obstacles and the other
    robots where they stand (:mod:`robot_agent.engine.replan`), in uncoordinated fleets only (no ``depart`` or
    ``depends``).  Raises :class:`~robot_agent.engine.headless.PlacementRefused` naming the robot whose start is not
    free and ``ValueError`` for mismatched or too many robots or a coordinated fleet that would replan."""
    n = len(paths)
    if not 1 <= n <= MAX_FLEET:
        raise ValueError(f"a fleet has 1 to {MAX_FLEET} robots, got {n}")
    if len(starts) != n:
        raise ValueError(f"{n} paths but {len(starts)} starts")
    if depart is not None and len(depart) != n:
        raise ValueError(f"{n} paths but {len(depart)} departure lists")
    if depends is not None and len(depends) != n:
        raise ValueError(f"{n} paths but {len(depends)} dependency tables")
    chosen = select(controller, controller_params)
    if chosen.replans and (depends is not None or any(d is not None for d in depart or ())):
        raise ValueError("controller_params.replan: a coordinated fleet (departure times or dependencies) cannot "
                         "replan: a new path would break its coordination")
    params = robot_params(profile)
    size = (float(area[0]), float(area[1]))
    world = World(np.array([size]), np.zeros(n, dtype=np.int64), np.zeros((n, 2)), np.tile(size, (n, 1)),
                  params.collision_radius_m)
    core = SimCore(params, make_backend(backend, n, params), world, log_poses=True)
    built = parse_command(encode_build(blocks), field_size=size)
    movers = parse_command(encode_moving(moving), field_size=size)
    assert isinstance(built, BuildCommand) and isinstance(movers, MovingCommand)
    world.set_blocks(0, built.blocks)
    sent: list[np.ndarray] = []
    holds_at: list[np.ndarray | None] = []
    for i in range(n):
        p = parse_command(encode_path(paths[i]), field_size=size)
        assert isinstance(p, PathCommand)
        sent.append(np.asarray(p.points, dtype=float))
        d = None if depart is None or depart[i] is None else np.asarray(depart[i], dtype=float).reshape(-1)
        if d is not None and len(d) != len(sent[i]):
            raise ValueError(f"robot {i}: {len(sent[i])} path points but {len(d)} departure times")
        holds_at.append(d)
        if depends is not None and np.shape(depends[i]) != (n, len(sent[i])):
            raise ValueError(f"robot {i}: {len(sent[i])} path points but a dependency table of shape "
                             f"{np.shape(depends[i])}, not ({n}, {len(sent[i])})")
    xy = np.array([[float(v) for v in st[:2]] for st in starts]).reshape(n, 2)
    gap = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) + np.diag(np.full(n, np.inf))
    if n > 1 and gap.min() < 2 * world.radius:
        a, b = sorted(np.unravel_index(int(np.argmin(gap)), gap.shape))
        raise PlacementRefused(f"cannot place robot {b}: robot {a} stands {gap[a, b]:.3f} m from it, closer than "
                               f"two collision radii ({2 * world.radius:.3f} m)")
    away = np.full((n, 3), 1e6)  # the robots' mutual distances are checked above
    driven = world.driven is not None
    if driven:  # the field's obstacle robots: one each, for every robot, on the fleet's clock
        world.set_shared_moving(list(movers.obstacles), _obstacle_key(seed))
    for i in range(n):
        placed = parse_command(encode_place(starts[i]), field_size=size)
        assert isinstance(placed, PlaceCommand)
        if not driven:
            world.set_moving(i, list(movers.obstacles))
        why = world.place_conflict(i, placed.pose, away)
        if why:
            raise PlacementRefused(f"cannot place robot {i}: {why}")
        core.place(i, placed.pose)
    core.poses.drain()

    end_step = math.ceil(max_s / core.dt)
    job = _Job(core, world, sent, holds_at, [] if driven else list(movers.obstacles), seed, chosen, end_step)
    if depends is None:
        events, holds = _run_timed(job)
        waited: list[list[list[int]]] = [[[] for _ in h] for h in holds]
    else:
        events, holds, waited = _run_by_dependencies(job, [np.asarray(d, dtype=np.int64) for d in depends])
    logged = core.poses.drain()
    runs = []
    for i in range(n):
        ev = events[i]
        t_start = next((e.t for e in ev if e.kind == "START"), None)
        t_end = next((e.t for e in ev if e.kind in ("DONE", "FAIL")), None)
        runs.append(HeadlessRun(logged.get(i, np.zeros((0, 4))), ev, t_start, t_end))
    tracks = None
    if driven and movers.obstacles:
        tracks = mover_tracks(list(movers.obstacles), _obstacle_key(seed), params, core.step_count * core.dt,
                              world.halted(n))
    return FleetRun(runs, holds, core.dt, waited, tracks)


def _obstacle_key(seed: int) -> int:
    """The noise key a fleet's obstacle robots' keys derive from (:func:`robot_agent.engine.movers.mover_key`)."""
    return path_key(seed, "obstacles")


@dataclass
class _Job:
    """What a fleet run's loop works on: the core and world, each robot's path ``sent`` ``(N_i, 3)`` and
    departure times (or None), the moving obstacles (params, waypoints), the noise seed, the controller and
    the last control step."""

    core: SimCore
    world: World
    sent: list[np.ndarray]
    depart: list[np.ndarray | None]
    movers: list
    seed: int
    chosen: object
    end_step: int

    def send(self, i: int, first: int, last: int, leg: int) -> None:
        """Robot ``i`` follows its points ``first..last`` (inclusive) from the next step, as its leg ``leg``
        (noise key), with the moving obstacles re-sent on the fleet's clock."""
        now, dt = self.core.step_count, self.core.dt
        if self.movers:  # exact discs: re-sent with the leg, on the fleet's clock
            shifted = [(np.array([par[0], par[1], par[2], par[3] - now * dt]), pts) for par, pts in self.movers]
            self.world.set_moving(i, shifted)
        self.core.set_path(i, self.sent[i][first:last + 1], path_key(self.seed, f"robot-{i}", leg), self.chosen)


def _run_timed(job: _Job) -> tuple[list[list[SimEvent]], list[list[tuple[int, float]]]]:
    """Execution by the clock: legs split at the holds, each released at its waypoint's departure time (at
    once when the robot is late).  Returns each robot's events and holds (waypoint, s held)."""
    core, n = job.core, len(job.sent)
    sent, holds_at, end_step = job.sent, job.depart, job.end_step
    legs = [_legs(len(sent[i]), holds_at[i]) for i in range(n)]
    nxt = np.zeros(n, dtype=np.int64)  # each robot's next leg
    ready = np.ones(n, dtype=bool)  # its previous leg is done (or none began): it may take the next
    over = np.zeros(n, dtype=bool)  # finished its path or failed
    arrived_at = np.zeros(n)  # fleet time its last leg ended (s)
    events: list[list[SimEvent]] = [[] for _ in range(n)]
    holds: list[list[tuple[int, float]]] = [[] for _ in range(n)]
    dt = core.dt

    def send(i: int) -> None:
        first, last, _ = legs[i][nxt[i]]
        job.send(i, first, last, int(nxt[i]))
        ready[i] = False

    while core.step_count < end_step and not over.all():
        now = core.step_count
        release = np.full(n, np.inf)
        for i in np.flatnonzero(ready & ~over):
            r = int(math.ceil(legs[i][nxt[i]][2] / dt - 1e-9))
            if r <= now:
                if nxt[i] > 0:
                    holds[i].append((legs[i][nxt[i]][0] - 1, now * dt - arrived_at[i]))
                send(i)
            else:
                release[i] = r
        # a robot with legs to go must be seen the step its leg ends: then step one at a time
        legs_left = np.array([len(legs[i]) - 1 - nxt[i] for i in range(n)])
        step_to = int(min(end_step, release.min()))
        if core.busy():
            chunk = 1 if ((legs_left > 0) & ~over).any() else _CHUNK
            got = core.advance(max(1, min(chunk, step_to - now)))
        else:
            core.skip(max(1, step_to - now))
            got = []
        for e in got:
            i = e.robot
            first = legs[i][nxt[i]][0]
            last_leg = nxt[i] == len(legs[i]) - 1
            if e.kind == "START":
                if nxt[i] == 0:
                    events[i].append(e)
            elif e.kind == "WP":
                events[i].append(SimEvent(i, "WP", e.t, index=(e.index or 0) + first))
            elif e.kind == "REPLAN":  # only uncoordinated fleets replan: one leg, numbered as the robot does
                events[i].append(e)
            elif e.kind == "DONE":
                if last_leg:
                    events[i].append(e)
                    over[i] = True
                else:
                    nxt[i] += 1
                    ready[i] = True
                    arrived_at[i] = e.t
            else:
                events[i].append(e)
                over[i] = True
    return events, holds


def _run_by_dependencies(job: _Job, depends: list[np.ndarray]) -> tuple[
        list[list[SimEvent]], list[list[tuple[int, float]]], list[list[list[int]]]]:
    """Execution by the plan's order of passage: robot ``i`` leaves its waypoint ``k`` once every robot ``h``
    reached waypoint ``depends[i][h, k]`` (:func:`planners.dependencies.fleet_dependencies`) and the clock
    reached ``depart[i][k]`` (a planned wait, e.g. for a moving obstacle: a lower bound).  A robot is sent
    up to the first waypoint it may not leave yet and stops there; a leg is extended (re-sent from the next
    waypoint) as soon as that waypoint may be left.  Ends early when no robot moves and none can be
    released (a robot that failed holds up the ones behind it).  Returns each robot's events, holds
    (waypoint, s held) and, per hold, the robots it waited for (none: it waited for its planned time)."""
    core, n, dt = job.core, len(job.sent), job.core.dt
    size = np.array([len(p) for p in job.sent])
    reached = np.zeros(n, dtype=np.int64)  # the last waypoint each robot reached
    first = np.zeros(n, dtype=np.int64)  # the first waypoint of its current leg
    end = np.full(n, -1, dtype=np.int64)  # the last waypoint of its current leg (-1: standing)
    legs = np.zeros(n, dtype=np.int64)  # legs sent so far (noise keys)
    over = np.zeros(n, dtype=bool)
    stopped_at = np.zeros(n)  # fleet time it stopped at its waypoint (s)
    blockers: list[set[int]] = [set() for _ in range(n)]
    events: list[list[SimEvent]] = [[] for _ in range(n)]
    holds: list[list[tuple[int, float]]] = [[] for _ in range(n)]
    waited: list[list[list[int]]] = [[] for _ in range(n)]

    def time_release(i: int, k: int) -> int:
        """The step robot ``i`` may leave waypoint ``k`` by the plan's clock (0: no hold)."""
        d = job.depart[i]
        return int(math.ceil(d[k] / dt - 1e-9)) if d is not None and math.isfinite(d[k]) else 0

    def unmet(i: int, k: int) -> np.ndarray:
        return np.flatnonzero(reached < depends[i][:, k])

    def horizon(i: int, k: int, now: int) -> int:
        """The last waypoint after ``k`` robot ``i`` can drive to now: the first one it may not leave yet."""
        e = k + 1
        while e < size[i] - 1 and time_release(i, e) <= now and not len(unmet(i, e)):
            e += 1
        return e

    def send(i: int, start: int, now: int) -> None:
        end[i] = horizon(i, reached[i], now)
        first[i] = start
        job.send(i, start, int(end[i]), int(legs[i]))
        legs[i] += 1

    while core.step_count < job.end_step and not over.all():
        now = core.step_count
        release = np.full(n, np.inf)
        for i in np.flatnonzero(~over):
            k = int(reached[i])
            if end[i] < 0:  # standing at waypoint k
                blocked, r = unmet(i, k), time_release(i, k)
                blockers[i].update(int(h) for h in blocked)
                if len(blocked):
                    continue
                if r > now:
                    release[i] = r
                    continue
                held = now * dt - stopped_at[i]
                if held > 1e-9 or r > 0:
                    holds[i].append((k, held))
                    waited[i].append(sorted(blockers[i]))
                blockers[i].clear()
                send(i, 0 if legs[i] == 0 else k + 1, now)
            elif end[i] < size[i] - 1 and time_release(i, int(end[i])) <= now and not len(unmet(i, int(end[i]))):
                send(i, k + 1, now)  # the leg's end may be left now: drive on without stopping
        if not core.busy() and not np.isfinite(release).any() and (end < 0)[~over].all():
            break  # nobody moves and nobody can be released
        standing_only = core.busy() and not ((end >= 0) & (end < size - 1) & ~over).any() \
            and not ((end < 0) & ~over).any()
        step_to = int(min(job.end_step, release.min()))
        if core.busy():
            got = core.advance(max(1, min(_CHUNK if standing_only else 1, step_to - now)))
        else:
            core.skip(max(1, step_to - now))
            got = []
        for e in got:
            i = e.robot
            if e.kind == "START":
                if not events[i]:
                    events[i].append(e)
            elif e.kind == "WP":
                reached[i] = max(reached[i], (e.index or 0) + first[i])
                events[i].append(SimEvent(i, "WP", e.t, index=(e.index or 0) + first[i]))
            elif e.kind == "DONE":
                if end[i] == size[i] - 1:
                    events[i].append(e)
                    over[i] = True
                else:
                    reached[i] = end[i]
                    end[i] = -1
                    stopped_at[i] = e.t
            else:
                events[i].append(e)
                over[i] = True
    return events, holds, waited
