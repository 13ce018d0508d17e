"""Which run goes where: the queue, the four sub-fields and the simulation pool (pure logic).

Policy (docs/design.md, "REST API", issue "Teleworkbench server"):

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

No I/O here: the runtime (:mod:`server.testbed`) feeds robots and runs in and
carries out the assignments.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from robot_agent.frames import FIELD_SIZE, SUBFIELD_SIZE
from robot_agent.frames import SUBFIELD_ORIGINS as _ORIGINS

__all__ = ["Assignment", "Pending", "RobotSlot", "Scheduler", "SubfieldSlot", "SUBFIELD_ORIGINS"]

#: origin of each sub-field 1..4 in the field frame (m)
SUBFIELD_ORIGINS = dict(enumerate(_ORIGINS, start=1))
FULL = FIELD_SIZE


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

    @property
    def pool(self) -> str:
        """``sim`` for ideal robots, ``field`` for emulated physical ones."""
        return "sim" if self.backend == "ideal" else "field"

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
    state: str = "idle"
    environment: Optional[str] = None
    run_id: Optional[int] = None


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


@dataclass
class Scheduler:
    robots: dict[str, RobotSlot] = field(default_factory=dict)
    subfields: dict[int, SubfieldSlot] = field(default_factory=lambda: {k: SubfieldSlot(k) for k in range(1, 5)})
    queue: list[Pending] = field(default_factory=list)

    # ------------------------------------------------------------------ bookkeeping

    def add(self, pending: Pending) -> None:
        self.queue.append(pending)

    def drop(self, run_id: int) -> bool:
        """Remove a queued run (cancel); True if it was queued."""
        n = len(self.queue)
        self.queue = [p for p in self.queue if p.run_id != run_id]
        return len(self.queue) != n

    def release(self, run_id: int, *, environment: Optional[str] = None) -> None:
        """A run ended: free its robot and sub-fields (``environment`` stays built on them)."""
        for r in self.robots.values():
            if r.run_id == run_id:
                r.run_id = None
        for s in self.subfields.values():
            if s.run_id == run_id:
                s.run_id = None
                s.state = "idle"

    def field_robot(self, subfield: int) -> Optional[RobotSlot]:
        for r in self.robots.values():
            if r.subfield == subfield:
                return r
        return None

    # ------------------------------------------------------------------ policy

    def assign(self) -> list[Assignment]:
        """Start what can start now; marks robots and sub-fields busy and removes the runs from the queue."""
        out: list[Assignment] = []
        twb_blocked = False
        for p in list(self.queue):
            a: Optional[Assignment] = None
            if p.mode == "sim":
                a = self._sim(p)
            elif not twb_blocked:
                a = self._twb_full(p) if p.field == "full" else self._twb_sub(p)
                if a is None and p.field == "full" and self._full_possible(p):
                    twb_blocked = True  # reserve the field for this job
            if a is None:
                continue
            self.queue.remove(p)
            self.robots[a.robot_id].run_id = p.run_id
            for k in a.subfields:
                self.subfields[k].run_id = p.run_id
                self.subfields[k].state = "reserved"
            out.append(a)
        return out

    def _sim(self, p: Pending) -> Optional[Assignment]:
        need = FULL if p.field == "full" else SUBFIELD_SIZE
        for r in sorted(self.robots.values(), key=lambda r: r.robot_id):
            if r.pool == "sim" and r.idle and r.robot_id not in p.exclude and \
                    r.area[0] >= need[0] - 1e-6 and r.area[1] >= need[1] - 1e-6:
                return Assignment(p.run_id, r.robot_id, ())
        return None

    def _twb_sub(self, p: Pending) -> Optional[Assignment]:
        options = []
        for k, s in self.subfields.items():
            robot = self.field_robot(k)
            if s.run_id is None and robot is not None and robot.idle and robot.robot_id not in p.exclude:
                options.append((s.environment != p.environment, k, robot.robot_id))
        if not options:
            return None
        _, k, rid = min(options)
        return Assignment(p.run_id, rid, (k,))

    def _full_possible(self, p: Pending) -> bool:
        return any(r.full_field and r.healthy and r.robot_id not in p.exclude for r in self.robots.values())

    def _twb_full(self, p: Pending) -> Optional[Assignment]:
        if any(s.run_id is not None for s in self.subfields.values()):
            return None
        for r in self.robots.values():
            if r.full_field and r.idle and r.robot_id not in p.exclude:
                others = [self.field_robot(k) for k in (2, 3, 4)]
                if all(o is None or o.idle for o in others):
                    return Assignment(p.run_id, r.robot_id, (1, 2, 3, 4))
        return None

    def can_ever_run(self, mode: str, field_kind: str) -> bool:
        """Whether some registered robot could serve this kind of run at all."""
        if mode == "sim":
            need = FULL if field_kind == "full" else SUBFIELD_SIZE
            return any(r.pool == "sim" and r.area[0] >= need[0] - 1e-6 and r.area[1] >= need[1] - 1e-6
                       for r in self.robots.values())
        if field_kind == "full":
            return any(r.full_field for r in self.robots.values())
        return any(r.subfield is not None for r in self.robots.values())

    # ------------------------------------------------------------------ estimates

    def estimate_starts(self, remaining_s: dict[int, float]) -> dict[int, float]:
        """Experiment seconds until each queued run would start, by simulating the policy.

        ``remaining_s`` maps each running run to its expected remaining time.
        Returns ``{run_id: seconds}`` for queued runs that can start at all.
        """
        sim = Scheduler(
            robots={k: RobotSlot(**{**vars(r)}) for k, r in self.robots.items()},
            subfields={k: SubfieldSlot(**vars(s)) for k, s in self.subfields.items()},
            queue=list(self.queue),
        )
        busy = {r.run_id for r in sim.robots.values() if r.run_id is not None}
        finish = {rid: max(remaining_s.get(rid, 0.0), 0.0) for rid in busy}
        durations = {p.run_id: p.expected_s for p in sim.queue}
        now, out = 0.0, {}
        while True:
            for a in sim.assign():
                out[a.run_id] = now
                finish[a.run_id] = now + durations[a.run_id]
            if not sim.queue or not finish:
                return out
            now = min(finish.values())
            for rid in [rid for rid, t in finish.items() if t <= now]:
                sim.release(rid)
                del finish[rid]
