"""Which run goes where: the queue, the four sub-fields and the simulation pool (pure logic).

Policy (docs/server.md, "A job, from submission to metrics", step 3, Scheduling):

- ``sim`` runs go to any idle robot of the simulation pool; ``twb`` runs need
  a free sub-field with its field robot; a full-field ``twb`` run needs all
  four sub-fields and the full-field robot (the robot of sub-field 1 whose
  area covers the whole field).
- The queue is first-come first-served per resource kind.  A full-field job
  at the head of the ``twb`` queue that cannot start yet *reserves* the
  field: no later ``twb`` run takes a sub-field that frees up, so full-field
  jobs are never starved by a stream of small ones.  ``sim`` runs are not
  held back by it.
- Among idle sub-fields, one already built with the job's environment is
  preferred (no gripper time).
- Estimated start times come from simulating this policy forward with each
  run's expected duration.

How it stays cheap with thousands of queued runs: queued runs are kept in
*classes* — same kind (``sim``/``twb``), same field kind (sub-field/full) and
same excluded robots — each a FIFO keyed by arrival number.  Whether a run can
start depends only on its class and on the free resources, which only shrink
while :meth:`Scheduler.assign` hands them out; so a class whose head cannot
start is skipped as a whole, and :meth:`~Scheduler.assign` merges the class
heads in arrival order and stops a kind when its classes are exhausted.
``add`` and ``drop`` are O(1); ``assign`` costs O((s + c) log c) for s started
runs and c classes (a handful: the excludes of retried runs make new ones),
plus O(robots) to read the fleet.  ``estimate_starts`` replays the policy for
each resource kind on its own — the pool's robots, the four sub-fields with
their robots — as bit-numbered units and a heap of finish times, O(n log n);
when all runs of a kind may use the same units, which unit a run takes changes
no start time, and the replay reduces to a heap of the units' free times.

No I/O here: the runtime (:mod:`server.testbed`) feeds robots and runs in and
carries out the assignments.
"""

from __future__ import annotations

import heapq
import math
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from itertools import count, islice, repeat
from operator import attrgetter, itemgetter
from typing import Callable, Optional, Union, overload

from contract.frames import FIELD_SIZE, SUBFIELD_SIZE
from contract.frames import SUBFIELD_ORIGINS as _ORIGINS
from contract.vocabulary import Mode

from .status import SubfieldState

__all__ = ["Assignment", "Pending", "QueueView", "RobotSlot", "Scheduler", "SubfieldSlot", "SUBFIELD_ORIGINS"]

#: origin of each sub-field 1..4 in the field frame (m)
SUBFIELD_ORIGINS = dict(enumerate(_ORIGINS, start=1))
FULL = FIELD_SIZE
_ALL_SUBFIELDS = (1, 2, 3, 4)  # what a full-field run occupies
_OTHER_SUBFIELDS = (2, 3, 4)  # whose robots must be idle (parked) for a full-field run


@dataclass
class RobotSlot:
    """A registered robot: where to reach it and what it can serve."""

    robot_id: str
    host: str
    port: int
    backend: str
    profile: str = "bebot"
    platform: str = ""
    origin: tuple[float, float] = (0.0, 0.0)
    area: tuple[float, float] = SUBFIELD_SIZE
    run_id: Optional[int] = None
    healthy: bool = True
    #: a slot of a compute engine (``ray``), not a robot agent: its runs are tasks, there is nothing to reach
    engine: str = ""

    @property
    def pool(self) -> str:
        """``sim`` for ideal robots, ``field`` for emulated physical ones."""
        return Mode.SIM if self.backend == "ideal" else "field"

    @property
    def subfield(self) -> Optional[int]:
        """The sub-field this field robot stands on (by its frame's origin), else None."""
        if self.pool != "field":
            return None
        for k, o in SUBFIELD_ORIGINS.items():
            if abs(o[0] - self.origin[0]) < 1e-6 and abs(o[1] - self.origin[1]) < 1e-6:
                return k
        return None

    @property
    def full_field(self) -> bool:
        """Whether its area covers the whole 3.6 m field (it can serve full-field jobs)."""
        return self.pool == "field" and self.origin == (0.0, 0.0) and self.area[0] >= FULL[0] - 1e-6 and self.area[1] >= FULL[1] - 1e-6

    @property
    def idle(self) -> bool:
        return self.run_id is None and self.healthy


@dataclass
class SubfieldSlot:
    id: int
    state: str = SubfieldState.IDLE
    environment: Optional[str] = None
    run_id: Optional[int] = None
    #: the last run that drove on it since the testbed started
    last_run_id: Optional[int] = None


@dataclass
class Pending:
    """A queued run as the scheduler sees it; ``expected_s`` is its expected experiment duration."""

    run_id: int
    experiment_id: int
    mode: str
    field: str
    environment: str
    expected_s: float = 60.0
    exclude: frozenset[str] = frozenset()  # robots that already failed this run


@dataclass(frozen=True)
class Assignment:
    run_id: int
    robot_id: str
    subfields: tuple[int, ...]


# ---------------------------------------------------------------------- helpers

#: a class of queued runs: (kind ``sim``/``twb``, field kind ``sub``/``full``, excluded robots)
_Class = tuple[str, str, frozenset[str]]
#: what a chooser answers for one run: where it starts, None (this class cannot start), or _BLOCKED
_Choice = Union[Assignment, None, object]
_BLOCKED = object()  # no later run of this kind may start in this pass


def _class_of(p: Pending) -> _Class:
    return (Mode.SIM if p.mode == Mode.SIM else Mode.TWB, "full" if p.field == "full" else "sub", frozenset(p.exclude))


def _need(field_kind: str) -> tuple[float, float]:
    """The area (m) a simulated robot needs for a run on this field kind."""
    return FULL if field_kind == "full" else SUBFIELD_SIZE


def _fits(r: RobotSlot, need: tuple[float, float]) -> bool:
    return r.area[0] >= need[0] - 1e-6 and r.area[1] >= need[1] - 1e-6


_robot_id = attrgetter("robot_id")
#: a queued run with its arrival number and its class
_Entry = tuple[Pending, int, _Class]
_run_of = itemgetter(0)


class QueueView(Sequence[Pending]):
    """The queued runs in arrival order: a live, read-only view (``len`` is O(1), iteration O(n))."""

    __slots__ = ("_entries",)

    def __init__(self, entries: OrderedDict[int, _Entry]) -> None:
        self._entries = entries

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[Pending]:
        return map(_run_of, self._entries.values())

    @overload
    def __getitem__(self, i: int) -> Pending: ...

    @overload
    def __getitem__(self, i: slice) -> list[Pending]: ...

    def __getitem__(self, i: Union[int, slice]) -> Union[Pending, list[Pending]]:
        """O(i): the queue is not stored as a list."""
        if isinstance(i, slice):
            return list(self)[i]
        n = len(self._entries)
        j = i + n if i < 0 else i
        if not 0 <= j < n:
            raise IndexError("queue index out of range")
        return next(islice(self, j, None))

    def __eq__(self, other: object) -> bool:
        if isinstance(other, (QueueView, list, tuple)):
            return list(self) == list(other)
        return NotImplemented

    def __repr__(self) -> str:
        return f"QueueView({list(self)!r})"


_FULL_FIELD = -1  # the mask of a full-field run in _Field.queued: it needs every unit at once
_EVERY_SUBFIELD = 0b1111


@dataclass
class _Units:
    """One resource kind as the estimate sees it: units numbered by bit, and the runs queued for them.

    A subclass says which units a class of runs may use (:meth:`mask`) and
    which free ones a run takes (:meth:`take`).
    """

    robots: Sequence[Optional[RobotSlot]]  # the robot of each unit, by bit
    idle: int = 0  # units free now
    frees: list[tuple[float, int]] = field(default_factory=list)  # (time, units) when held units free up
    queued: list[tuple[int, int, Pending]] = field(default_factory=list)  # (arrival number, mask, run)
    masks: set[int] = field(default_factory=set)  # the masks in ``queued``

    def enqueue(self, runs: OrderedDict[int, Pending], mask: int) -> None:
        """Add a class of runs (arrival number -> run) that may use the units of ``mask`` (if any);
        :meth:`starts` wants them sorted by arrival afterwards."""
        if mask:
            self.queued += zip(runs.keys(), repeat(mask), runs.values())
            self.masks.add(mask)

    def mask(self, key: _Class) -> int:
        """The units runs of this class may use (0: none, ever)."""
        raise NotImplementedError

    def take(self, p: Pending, mask: int, idle: int) -> int:
        """The free units ``p`` takes now (0: it waits, holding back the rest of its kind)."""
        raise NotImplementedError

    def starts(self, out: dict[int, float]) -> None:
        """Put the start time of each queued run that ever starts into ``out``."""
        self.queued.sort(key=itemgetter(0))  # a merge of the classes' runs: each is in arrival order
        if len(self.masks - {_FULL_FIELD}) <= 1:
            self._starts_interchangeable(out)
        else:
            self._starts_by_events(out)

    def _free_times(self) -> list[float]:
        """When each unit is first free: 0 (now), the end of what holds it, or inf (never)."""
        times = [0.0 if self.idle >> i & 1 else math.inf for i in range(len(self.robots))]
        for t, bit in self.frees:  # one unit each before the replay
            times[bit.bit_length() - 1] = t
        return times

    def _starts_interchangeable(self, out: dict[int, float]) -> None:
        """All runs but the full-field ones may use the same units, so which of them a run takes does
        not matter: it starts when the first of them frees (a heap of free times); a full-field run when
        all four are free, and everything queued after it later still.  O(n log u) for u units.
        """
        (mask,) = self.masks - {_FULL_FIELD} or {0}
        times = self._free_times()
        usable = [t for i, t in enumerate(times) if mask >> i & 1]  # a heap
        rest = [t for i, t in enumerate(times) if not mask >> i & 1]
        heapq.heapify(usable)
        for _, m, p in self.queued:
            if m == _FULL_FIELD:
                t = max(*usable, *rest)
                if t == math.inf:
                    break  # it waits for ever, and so does every later run of this kind
                usable, rest = [t + p.expected_s] * len(usable), [t + p.expected_s] * len(rest)
            else:
                t = usable[0]
                if t == math.inf:
                    continue
                heapq.heapreplace(usable, t + p.expected_s)
            out[p.run_id] = t

    def _starts_by_events(self, out: dict[int, float]) -> None:
        """The policy replayed moment by moment, for runs that may use different units.

        At each moment something frees up, the earliest-queued run that has a
        free unit it may use (or a full-field run, which waits holding back
        the rest) takes what :meth:`take` gives it; the next moment is popped
        from a heap of finish times.  O(n (g + log n)) for g different masks.
        """
        by_mask: dict[int, list[tuple[int, Pending]]] = {}
        for seq, m, p in self.queued:
            by_mask.setdefault(m, []).append((seq, p))
        masks = list(by_mask)
        runs = [by_mask[m] for m in masks]
        first = [0] * len(masks)  # per group: the first waiting run
        heads: list[float] = [group[0][0] for group in runs]  # per group: its arrival number (inf: none left)
        waiting, idle, frees, now = len(self.queued), self.idle, list(self.frees), 0.0
        heapq.heapify(frees)
        while True:
            while waiting and idle:  # with nothing free, nothing starts (a full-field run would wait)
                best, best_seq = -1, math.inf
                for j, m in enumerate(masks):
                    if heads[j] < best_seq and (m == _FULL_FIELD or idle & m):
                        best, best_seq = j, heads[j]
                if best < 0:
                    break
                i = first[best]
                p = runs[best][i][1]
                got = self.take(p, masks[best], idle)
                if not got:
                    break  # a full-field run waits and reserves the field
                idle &= ~got
                first[best] = i + 1
                heads[best] = runs[best][i + 1][0] if i + 1 < len(runs[best]) else math.inf
                waiting -= 1
                out[p.run_id] = now
                heapq.heappush(frees, (now + p.expected_s, got))
            if not waiting or not frees:
                return
            now = frees[0][0]
            while frees and frees[0][0] <= now:
                idle |= heapq.heappop(frees)[1]


@dataclass
class _Pool(_Units):
    """The healthy simulation robots, bit i for the i-th by robot id."""

    def mask(self, key: _Class) -> int:
        need, exclude = _need(key[1]), key[2]
        return sum(1 << i for i, r in enumerate(self.robots)
                   if r is not None and r.robot_id not in exclude and _fits(r, need))

    def take(self, p: Pending, mask: int, idle: int) -> int:
        """The free robot with the lowest id."""
        free = idle & mask
        return free & -free


@dataclass
class _Field(_Units):
    """Sub-field k with its robot as bit k-1."""

    environments: list[Optional[str]] = field(default_factory=list)  # built on each sub-field, by bit

    def __post_init__(self) -> None:
        self._built: dict[Optional[str], int] = {}  # environment -> the sub-fields it is built on
        for i, env in enumerate(self.environments):
            self._built[env] = self._built.get(env, 0) | 1 << i

    def mask(self, key: _Class) -> int:
        exclude = key[2]
        if key[1] == "full":
            first = self.robots[0]
            able = first is not None and first.full_field and first.healthy and first.robot_id not in exclude
            return _FULL_FIELD if able else 0
        return sum(1 << i for i, r in enumerate(self.robots)
                   if r is not None and r.healthy and r.robot_id not in exclude)

    def take(self, p: Pending, mask: int, idle: int) -> int:
        """All four for a full-field run (none while any is busy), else the lowest-numbered free
        sub-field, one with the run's environment built first."""
        if mask == _FULL_FIELD:
            return _EVERY_SUBFIELD if idle & _EVERY_SUBFIELD == _EVERY_SUBFIELD else 0
        free = idle & mask
        built = free & self._built.get(p.environment, 0)
        return built & -built or free & -free


# ---------------------------------------------------------------------- the scheduler


class Scheduler:
    """The queue and the testbed's resources; :meth:`assign` applies the policy.

    ``robots`` and ``subfields`` are plain dicts the runtime may change
    directly (health, registration, a sub-field's environment); the queue is
    changed only through :meth:`add` and :meth:`drop` and read through
    :attr:`queue`.
    """

    def __init__(self, robots: Optional[dict[str, RobotSlot]] = None,
                 subfields: Optional[dict[int, SubfieldSlot]] = None,
                 queue: Iterable[Pending] = ()) -> None:
        self.robots: dict[str, RobotSlot] = {} if robots is None else robots
        self.subfields: dict[int, SubfieldSlot] = \
            {k: SubfieldSlot(k) for k in range(1, 5)} if subfields is None else subfields
        self._entries: OrderedDict[int, _Entry] = OrderedDict()  # run id -> (run, arrival number, class)
        self._classes: dict[_Class, OrderedDict[int, Pending]] = {}  # class -> arrival number -> run
        self._arrivals = count()
        self.queue = queue

    def __repr__(self) -> str:
        return f"Scheduler(robots={self.robots!r}, subfields={self.subfields!r}, queue={list(self.queue)!r})"

    @property
    def queue(self) -> QueueView:
        """The queued runs in arrival order (read-only; change it with :meth:`add` and :meth:`drop`)."""
        return QueueView(self._entries)

    @queue.setter
    def queue(self, runs: Iterable[Pending]) -> None:
        """Replace the whole queue (O(n))."""
        runs = list(runs)  # the new queue may be a view of this one
        self._entries.clear()
        self._classes.clear()
        for p in runs:
            self.add(p)

    # ------------------------------------------------------------------ bookkeeping

    def add(self, pending: Pending) -> bool:
        """Queue a run at the tail, O(1); False (and nothing changes) if its id is already queued."""
        if pending.run_id in self._entries:
            return False
        seq, key = next(self._arrivals), _class_of(pending)
        self._entries[pending.run_id] = (pending, seq, key)
        self._classes.setdefault(key, OrderedDict())[seq] = pending
        return True

    def drop(self, run_id: int) -> bool:
        """Remove a queued run (cancel), O(1); True if it was queued."""
        entry = self._entries.pop(run_id, None)
        if entry is None:
            return False
        _, seq, key = entry
        runs = self._classes[key]
        del runs[seq]
        if not runs:
            del self._classes[key]
        return True

    def release(self, run_id: int, *, environment: Optional[str] = None) -> None:
        """A run ended: free its robot and sub-fields (``environment`` stays built on them)."""
        self._release(run_id)

    def _release(self, run_id: int) -> set[str]:
        """Free what ``run_id`` holds; returns the kinds (``sim``/``twb``) whose resources were freed."""
        kinds = set()
        for r in self.robots.values():
            if r.run_id == run_id:
                r.run_id = None
                kinds.add(Mode.SIM if r.pool == Mode.SIM else Mode.TWB)
        for s in self.subfields.values():
            if s.run_id == run_id:
                s.run_id = None
                s.state = SubfieldState.IDLE
                kinds.add(Mode.TWB)
        return kinds

    def field_robot(self, subfield: int) -> Optional[RobotSlot]:
        """The robot standing on ``subfield`` (the first registered one), else None."""
        for r in self.robots.values():
            if r.subfield == subfield:
                return r
        return None

    def _field_robots(self) -> dict[int, RobotSlot]:
        """:meth:`field_robot` of every sub-field at once (one pass over the robots)."""
        out: dict[int, RobotSlot] = {}
        for r in self.robots.values():
            k = r.subfield
            if k is not None and k not in out:
                out[k] = r
        return out

    # ------------------------------------------------------------------ policy

    def assign(self) -> list[Assignment]:
        """Start what can start now; marks robots and sub-fields busy and removes the runs from the queue.

        The assignments come in queue order.
        """
        return self._assign((Mode.SIM, Mode.TWB))

    def _assign(self, kinds: Iterable[str]) -> list[Assignment]:
        started: list[tuple[int, Assignment]] = []
        for kind in kinds:
            choose = self._sim_chooser() if kind == Mode.SIM else self._twb_chooser()
            if choose is not None:
                started += self._start_in_order(kind, choose)
        started.sort(key=itemgetter(0))
        return [a for _, a in started]

    def _start_in_order(self, kind: str, choose: Callable[[Pending], _Choice]) -> list[tuple[int, Assignment]]:
        """Offer the runs of ``kind`` to ``choose`` in arrival order, skipping a class once its head fails."""
        heads = [(next(iter(runs)), key) for key, runs in self._classes.items() if key[0] == kind]
        heapq.heapify(heads)
        started: list[tuple[int, Assignment]] = []
        while heads:
            seq, key = heads[0]
            runs = self._classes[key]
            p = runs[seq]
            a = choose(p)
            if a is _BLOCKED:
                break
            if not isinstance(a, Assignment):  # None: nothing of this class starts before something frees
                heapq.heappop(heads)
                continue
            self._start(p, a)
            started.append((seq, a))
            if runs:
                heapq.heapreplace(heads, (next(iter(runs)), key))
            else:
                heapq.heappop(heads)
        return started

    def _start(self, p: Pending, a: Assignment) -> None:
        self.drop(p.run_id)
        self.robots[a.robot_id].run_id = p.run_id
        for k in a.subfields:
            self.subfields[k].run_id = p.run_id
            self.subfields[k].state = SubfieldState.RESERVED

    def _sim_chooser(self) -> Optional[Callable[[Pending], _Choice]]:
        """For sim runs: the lowest-id idle pool robot big enough and not excluded; None if none is idle."""
        idle = [r for r in sorted(self.robots.values(), key=_robot_id) if r.pool == Mode.SIM and r.idle]
        if not idle:
            return None

        def choose(p: Pending) -> _Choice:
            if not idle:
                return _BLOCKED
            need = _need(p.field)
            for i, r in enumerate(idle):
                if r.robot_id not in p.exclude and _fits(r, need):
                    del idle[i]
                    return Assignment(p.run_id, r.robot_id, ())
            return None

        return choose

    def _twb_chooser(self) -> Optional[Callable[[Pending], _Choice]]:
        """For twb runs: a sub-field, or the full field (a full-field run that waits blocks the rest);
        None if no sub-field is free."""
        if all(s.run_id is not None for s in self.subfields.values()):
            return None
        robots = self._field_robots()

        def choose(p: Pending) -> _Choice:
            if p.field != "full":
                return self._twb_sub(p, robots)
            a = self._twb_full(p, robots)
            if a is None and self._full_possible(p):
                return _BLOCKED  # reserve the field for this job
            return a

        return choose

    def _twb_sub(self, p: Pending, robots: dict[int, RobotSlot]) -> Optional[Assignment]:
        options = []
        for k, s in self.subfields.items():
            robot = robots.get(k)
            if s.run_id is None and robot is not None and robot.idle and robot.robot_id not in p.exclude:
                options.append((s.environment != p.environment, k, robot.robot_id))
        if not options:
            return None
        _, k, rid = min(options)
        return Assignment(p.run_id, rid, (k,))

    def _full_possible(self, p: Pending) -> bool:
        return any(r.full_field and r.healthy and r.robot_id not in p.exclude for r in self.robots.values())

    def _twb_full(self, p: Pending, robots: dict[int, RobotSlot]) -> Optional[Assignment]:
        if any(s.run_id is not None for s in self.subfields.values()):
            return None
        if not all(robots.get(k) is None or robots[k].idle for k in _OTHER_SUBFIELDS):
            return None
        for r in self.robots.values():
            if r.full_field and r.idle and r.robot_id not in p.exclude:
                return Assignment(p.run_id, r.robot_id, _ALL_SUBFIELDS)
        return None

    def can_ever_run(self, mode: str, field_kind: str) -> bool:
        """Whether some registered robot could serve this kind of run at all."""
        if mode == Mode.SIM:
            need = _need(field_kind)
            return any(r.pool == Mode.SIM and _fits(r, need) for r in self.robots.values())
        if field_kind == "full":
            return any(r.full_field for r in self.robots.values())
        return any(r.subfield is not None for r in self.robots.values())

    # ------------------------------------------------------------------ estimates

    def estimate_starts(self, remaining_s: dict[int, float]) -> dict[int, float]:
        """Experiment seconds until each queued run would start, by simulating the policy.

        ``remaining_s`` maps each running run to its expected remaining time.
        Returns ``{run_id: seconds}`` for queued runs that can start at all.
        O(n log n) in queued runs; the real state is not changed.
        """
        finish = {r.run_id: max(remaining_s.get(r.run_id, 0.0), 0.0)
                  for r in self.robots.values() if r.run_id is not None}
        if not self._kinds_apart():
            return self._estimate_events(finish)
        pool, field_ = self._pool_units(finish), self._field_units(finish)
        for key, runs in self._classes.items():
            units = pool if key[0] == Mode.SIM else field_
            units.enqueue(runs, units.mask(key))
        out: dict[int, float] = {}
        pool.starts(out)
        field_.starts(out)
        return out

    def _kinds_apart(self) -> bool:
        """Whether each kind can be simulated on its own, on numbered units (:class:`_Units`).

        True for every state the testbed makes; False for a second healthy
        full-field robot, a queued run id that also holds a resource, and
        dict keys that are not the robot ids or the sub-fields 1..4.
        """
        if set(self.subfields) != set(_ALL_SUBFIELDS) or any(k != r.robot_id for k, r in self.robots.items()):
            return False
        held = {r.run_id for r in self.robots.values()} | {s.run_id for s in self.subfields.values()}
        if any(rid in self._entries for rid in held if rid is not None):
            return False
        first = self._field_robots().get(1)
        return all(r is first for r in self.robots.values() if r.full_field and r.healthy)

    def _pool_units(self, finish: dict[int, float]) -> _Pool:
        """The healthy simulation robots, bit i for the i-th by robot id (the order :meth:`_sim_chooser` tries)."""
        robots = [r for r in sorted(self.robots.values(), key=_robot_id) if r.pool == Mode.SIM and r.healthy]
        units = _Pool(robots)
        for i, r in enumerate(robots):
            if r.run_id is None:
                units.idle |= 1 << i
            else:
                units.frees.append((finish[r.run_id], 1 << i))
        return units

    def _field_units(self, finish: dict[int, float]) -> _Field:
        """Sub-field k with its robot as bit k-1: free when both are (never with an offline robot)."""
        robots = self._field_robots()
        units = _Field([robots.get(k) for k in _ALL_SUBFIELDS],
                       environments=[self.subfields[k].environment for k in _ALL_SUBFIELDS])
        for k, robot in zip(_ALL_SUBFIELDS, units.robots):
            held = [rid for rid in (self.subfields[k].run_id, robot and robot.run_id) if rid is not None]
            if robot is not None and not robot.healthy:
                continue
            if not held:
                units.idle |= 1 << (k - 1)
            elif (t := max(finish.get(rid, math.inf) for rid in held)) < math.inf:
                units.frees.append((t, 1 << (k - 1)))  # a sub-field no robot's run holds never frees
        return units

    def _estimate_events(self, finish: dict[int, float]) -> dict[int, float]:
        """The general case: replay the policy event by event on a copy (heap of finish times).

        After a pass nothing more can start until something is released, and a
        release only wakes the kinds whose resources it freed.
        """
        twin = self._copy()
        durations = {p.run_id: p.expected_s for p in twin.queue}
        events = [(t, rid) for rid, t in finish.items()]
        heapq.heapify(events)
        now, out, kinds = 0.0, {}, {Mode.SIM, Mode.TWB}
        while True:
            for a in twin._assign(sorted(kinds)):
                out[a.run_id] = now
                finish[a.run_id] = t = now + durations[a.run_id]
                heapq.heappush(events, (t, a.run_id))
            if not twin._entries or not finish:
                return out
            while finish.get(events[0][1]) != events[0][0]:
                heapq.heappop(events)  # superseded: that run id started again in the simulation
            now, kinds = events[0][0], set()
            while events and events[0][0] <= now:
                t, rid = heapq.heappop(events)
                if finish.get(rid) == t:
                    del finish[rid]
                    kinds |= twin._release(rid)

    def _copy(self) -> Scheduler:
        """An independent copy of the robots, sub-fields and queue (O(n))."""
        twin = Scheduler({k: replace(r) for k, r in self.robots.items()},
                         {k: replace(s) for k, s in self.subfields.items()})
        twin._entries = OrderedDict(self._entries)
        twin._classes = {key: OrderedDict(runs) for key, runs in self._classes.items()}
        return twin
