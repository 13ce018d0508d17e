"""The scheduling policy, without robots or sockets.

The tests at the end drive the scheduler and a copy of its first implementation
(:class:`ReferenceScheduler`, O(n^2) estimates) with seeded random scenarios and
require the same assignments and the same estimated starts.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from typing import Optional

import pytest

from server.scheduler import FULL, SUBFIELD_SIZE, Assignment, Pending, RobotSlot, Scheduler, SubfieldSlot


def make_scheduler(sim_robots=2, full=True):
    s = Scheduler()
    for k, origin in {1: (0.0, 0.0), 2: (1.8, 0.0), 3: (0.0, 1.8), 4: (1.8, 1.8)}.items():
        area = (3.6, 3.6) if (k == 1 and full) else (1.8, 1.8)
        s.robots[f"f{k}"] = RobotSlot(f"f{k}", "127.0.0.1", 9000 + k, "field", origin=origin, area=area)
    for i in range(sim_robots):
        s.robots[f"s{i}"] = RobotSlot(f"s{i}", "127.0.0.1", 9100 + i, "ideal", area=(3.6, 3.6))
    return s


def P(run, mode="twb", field="sub", env="room", exp=None, dur=10.0):
    return Pending(run, exp or run, mode, field, env, dur)


def test_subfields_and_pool_are_used_in_parallel():
    s = make_scheduler()
    for i in range(1, 8):
        s.add(P(i, "twb" if i <= 5 else "sim"))
    a = {x.run_id: x for x in s.assign()}
    assert sorted(a) == [1, 2, 3, 4, 6, 7]  # run 5 waits for a sub-field
    assert sorted(x.subfields[0] for x in a.values() if x.subfields) == [1, 2, 3, 4]
    assert {a[6].robot_id, a[7].robot_id} == {"s0", "s1"}
    assert [p.run_id for p in s.queue] == [5]
    s.release(3)
    assert [x.run_id for x in s.assign()] == [5]


def test_prefers_a_subfield_already_built_with_the_environment():
    s = make_scheduler()
    s.subfields[3].environment = "blocks"
    s.add(P(1, env="blocks"))
    (a,) = s.assign()
    assert a.subfields == (3,) and a.robot_id == "f3"


def test_full_field_job_is_not_starved_by_later_small_jobs():
    s = make_scheduler()
    s.add(P(1))
    s.add(P(2))
    assert len(s.assign()) == 2
    s.add(P(3, field="full"))
    s.add(P(4))
    s.add(P(5, mode="sim"))
    started = [x.run_id for x in s.assign()]
    assert started == [5]  # two sub-fields are free, but the full job holds them; sim is not held back
    s.release(1)
    assert s.assign() == []
    s.release(2)
    (full,) = s.assign()
    assert full.run_id == 3 and full.subfields == (1, 2, 3, 4) and full.robot_id == "f1"
    assert s.assign() == []
    s.release(3)
    assert [x.run_id for x in s.assign()] == [4]


def test_without_a_full_field_robot_full_jobs_do_not_block_others():
    s = make_scheduler(full=False)
    s.add(P(1, field="full"))
    s.add(P(2))
    assert [x.run_id for x in s.assign()] == [2]
    assert not s.can_ever_run("twb", "full") and s.can_ever_run("twb", "sub")


def test_retry_avoids_the_robot_that_failed():
    s = make_scheduler(sim_robots=2)
    s.add(Pending(1, 1, "sim", "sub", "room", 10, exclude=frozenset({"s0"})))
    (a,) = s.assign()
    assert a.robot_id == "s1"


def test_unhealthy_robots_get_nothing():
    s = make_scheduler(sim_robots=1)
    s.robots["s0"].healthy = False
    s.add(P(1, mode="sim"))
    assert s.assign() == []


def test_estimates_follow_the_policy():
    s = make_scheduler(sim_robots=1)
    s.add(P(1, mode="sim", dur=10))
    s.add(P(2, mode="sim", dur=20))
    s.add(P(3, mode="sim", dur=5))
    for k in range(4):
        s.add(P(10 + k, dur=30))
    s.add(P(20, dur=7))
    est = s.estimate_starts({})
    assert est[1] == 0 and est[2] == 10 and est[3] == 30
    assert all(est[10 + k] == 0 for k in range(4)) and est[20] == 30
    # the estimate does not change the real state
    assert len(s.queue) == 8 and all(r.run_id is None for r in s.robots.values())
    (first, *_) = s.assign()
    est = s.estimate_starts({first.run_id: 4.0})
    assert est[2] == 4.0


def test_the_queue_is_a_read_only_view_in_arrival_order():
    s = make_scheduler()
    for i in (5, 3, 9):
        s.add(P(i, "sim" if i == 3 else "twb"))
    assert len(s.queue) == 3 and [p.run_id for p in s.queue] == [5, 3, 9]
    assert s.queue[0].run_id == 5 and s.queue[-1].run_id == 9 and [p.run_id for p in s.queue[1:]] == [3, 9]
    assert s.queue == list(s.queue) and bool(s.queue)
    assert not s.add(P(3)) and len(s.queue) == 3  # already queued: left where it is
    assert s.drop(3) and not s.drop(3) and [p.run_id for p in s.queue] == [5, 9]
    s.queue = [P(7), *s.queue]  # the old list attribute can still be replaced as a whole
    assert [p.run_id for p in s.queue] == [7, 5, 9]
    assert [p.run_id for p in Scheduler(queue=[P(2), P(1)]).queue] == [2, 1]
    with pytest.raises(IndexError):
        s.queue[3]


def test_assign_looks_at_a_class_of_runs_only_until_one_cannot_start(monkeypatch):
    """With one sub-field free, 10,000 queued sub-field runs cost two looks, not 10,000."""
    s = make_scheduler(sim_robots=0)
    for i in range(10_000):
        s.add(P(i))
    assert len(s.assign()) == 4
    s.release(2)
    looks = []
    real = Scheduler._twb_sub
    monkeypatch.setattr(Scheduler, "_twb_sub", lambda self, p, robots: looks.append(p.run_id) or real(self, p, robots))
    assert [a.run_id for a in s.assign()] == [4]
    assert looks == [4, 5]  # 5 cannot start: neither can any later run of its class
    looks.clear()
    assert s.assign() == [] and looks == []  # nothing free: no run is looked at


def test_a_run_blocked_for_its_own_reason_does_not_hold_back_its_kind():
    s = make_scheduler(sim_robots=2)
    s.add(Pending(1, 1, "sim", "sub", "room", 10, exclude=frozenset({"s0", "s1"})))
    s.add(Pending(2, 2, "sim", "sub", "room", 10, exclude=frozenset({"s0"})))
    s.add(P(3, mode="sim"))
    assert [(a.run_id, a.robot_id) for a in s.assign()] == [(2, "s1"), (3, "s0")]
    assert [p.run_id for p in s.queue] == [1]


# ---------------------------------------------------------------------- equivalence with the reference


@dataclass
class Scenario:
    """A fleet and a script of operations, applied alike to both implementations."""

    robots: list[dict]
    environments: dict[int, Optional[str]]
    ops: list[tuple] = field(default_factory=list)

    def build(self, cls):
        s = cls()
        for spec in self.robots:
            s.robots[spec["robot_id"]] = RobotSlot(**spec)
        for k, env in self.environments.items():
            s.subfields[k].environment = env
        return s


def twb_up_fleet(rng: random.Random) -> list[dict]:
    """`twb up`: four field robots (sub-field 1's covers the field), four simulated ones; some offline."""
    origins = {1: (0.0, 0.0), 2: (1.8, 0.0), 3: (0.0, 1.8), 4: (1.8, 1.8)}
    out = [dict(robot_id=f"field-{k}", host="h", port=k, backend="field", origin=o,
                area=FULL if k == 1 else SUBFIELD_SIZE, healthy=rng.random() > 0.1) for k, o in origins.items()]
    out += [dict(robot_id=f"sim-{i}", host="h", port=10 + i, backend="ideal", area=FULL, healthy=rng.random() > 0.1)
            for i in range(1, 5)]
    rng.shuffle(out)
    return out


def wild_fleet(rng: random.Random) -> list[dict]:
    """Any fleet: missing, doubled, offline, misplaced and second full-field robots, small pool robots."""
    origins = [(0.0, 0.0), (1.8, 0.0), (0.0, 1.8), (1.8, 1.8), (0.9, 0.9)]
    out = []
    for n in range(rng.randint(0, 7)):
        o = rng.choice(origins)
        area = FULL if o == (0.0, 0.0) and rng.random() < 0.6 else SUBFIELD_SIZE
        out.append(dict(robot_id=rng.choice("abfz") + str(n), host="h", port=n, backend="field", origin=o,
                        area=area, healthy=rng.random() > 0.2))
    for n in range(rng.randint(0, 5)):
        out.append(dict(robot_id=rng.choice("acsy") + str(n), host="h", port=100 + n, backend="ideal",
                        area=rng.choice([FULL, SUBFIELD_SIZE]), healthy=rng.random() > 0.2))
    rng.shuffle(out)
    return out


def random_scenario(seed: int) -> Scenario:
    rng = random.Random(seed)
    robots = twb_up_fleet(rng) if seed % 2 else wild_fleet(rng)
    ids = [r["robot_id"] for r in robots] + ["nobody"]
    envs = ["room", "blocks", "maze"]
    sc = Scenario(robots, {k: rng.choice([None, *envs]) for k in range(1, 5)})
    full_share = rng.choice([0.0, 0.05, 0.3])
    exclude_share = rng.choice([0.0, 0.0, 0.1, 0.4])
    next_run = 1
    for _ in range(rng.randint(5, 80)):
        u = rng.random()
        if u < 0.45:
            for _ in range(rng.choice([1, 1, 1, 3, 8])):
                exclude = frozenset()
                if rng.random() < exclude_share:
                    exclude = frozenset(rng.sample(ids, min(len(ids), rng.randint(1, 2))))
                dur = float(rng.randint(1, 6) * 10) if rng.random() < 0.6 else rng.uniform(0.0, 90.0)
                sc.ops.append(("add", Pending(next_run, 1 + next_run // 3, rng.choice(["sim", "twb"]),
                                              "full" if rng.random() < full_share else "sub", rng.choice(envs), dur,
                                              exclude)))
                next_run += 1
        elif u < 0.55:
            sc.ops.append(("drop", rng.randint(1, next_run)))
        elif u < 0.72:
            sc.ops.append(("assign",))
        elif u < 0.84:
            sc.ops.append(("release", rng.random()))
        elif u < 0.88:
            sc.ops.append(("health", rng.choice(ids), rng.random() < 0.6))
        elif u < 0.90:
            sc.ops.append(("environment", rng.randint(1, 4), rng.choice([None, *envs])))
        elif u < 0.92:
            sc.ops.append(("retry", rng.random(), rng.random()))
        elif u < 0.93:
            sc.ops.append(("register", rng.choice([*twb_up_fleet(rng), *wild_fleet(rng)])))
        elif u < 0.94:  # states the testbed does not make: a resource held by a queued or unknown run
            sc.ops.append(("hold", rng.random(), rng.random(), rng.randint(1, next_run + 3)))
        else:
            sc.ops.append(("estimate", rng.random(), rng.choice([0.0, 0.5, 1.0])))
    sc.ops.append(("estimate", 0.3, 1.0))
    return sc


def running(s) -> list[int]:
    return sorted({r.run_id for r in s.robots.values() if r.run_id is not None})


def pick(xs: list, u: float):
    return xs[min(int(u * len(xs)), len(xs) - 1)] if xs else None


def state(s) -> tuple:
    return ([p.run_id for p in s.queue], {k: r.run_id for k, r in s.robots.items()},
            {k: (v.run_id, v.state, v.environment) for k, v in s.subfields.items()})


def fleet_answers(s) -> tuple:
    robots = [s.field_robot(k) for k in range(6)]
    kinds = [s.can_ever_run(m, f) for m in ("sim", "twb") for f in ("sub", "full")]
    return [r and r.robot_id for r in robots], kinds


def apply(s, op: tuple, expected: dict[int, float], started: dict[int, Pending]):
    """One scripted operation; returns what the scheduler answered."""
    kind = op[0]
    if kind == "add":
        started.pop(op[1].run_id, None)
        s.add(op[1])
        return None
    if kind == "drop":
        return s.drop(op[1])
    if kind == "assign":
        return s.assign()
    if kind == "release":
        rid = pick(running(s), op[1])
        return rid is not None and s.release(rid, environment="room")
    if kind == "health":
        if op[1] in s.robots:
            s.robots[op[1]].healthy = op[2]
        return None
    if kind == "register":  # a robot (re)registers: a new slot object, the old one's run kept
        old = s.robots.get(op[1]["robot_id"])
        s.robots[op[1]["robot_id"]] = RobotSlot(**{**op[1], "run_id": old.run_id if old else None})
        return None
    if kind == "hold":
        slots = [*s.robots.values(), *s.subfields.values()]
        pick(slots, op[1]).run_id = op[3] if op[2] < 0.7 else None
        return None
    if kind == "environment":
        s.subfields[op[1]].environment = op[2]
        return None
    if kind == "retry":  # the testbed's retry_run: the robot failed, the run queues again avoiding it
        rid = pick(running(s), op[1])
        if rid is None or rid not in started:
            return None
        robot = next(r for r in s.robots.values() if r.run_id == rid)
        s.release(rid)
        if op[2] < 0.5:
            robot.healthy = False
        p = started.pop(rid)
        s.add(Pending(p.run_id, p.experiment_id, p.mode, p.field, p.environment, p.expected_s,
                      p.exclude | {robot.robot_id}))
        return None
    # estimate: some running runs have an expected remaining time, the others count as due now
    u, share = op[1], op[2]
    remaining = {rid: expected.get(rid, 30.0) * u for i, rid in enumerate(running(s)) if (i % 3) / 3 < share}
    before = state(s)
    out = s.estimate_starts(remaining)
    assert state(s) == before, "an estimate changed the scheduler"
    return out


def replay(sc: Scenario, paths: dict[str, int]) -> None:
    new, ref = sc.build(Scheduler), sc.build(ReferenceScheduler)
    expected = {op[1].run_id: op[1].expected_s for op in sc.ops if op[0] == "add"}
    started_new: dict[int, Pending] = {}
    started_ref: dict[int, Pending] = {}
    for i, op in enumerate(sc.ops):
        if op[0] == "add" and any(p.run_id == op[1].run_id for p in ref.queue):
            continue  # the reference would queue it twice; the scheduler refuses
        if op[0] == "estimate":
            paths["by kind" if new._kinds_apart() else "events"] += 1
        queued = {p.run_id: p for p in new.queue}
        got, want = apply(new, op, expected, started_new), apply(ref, op, expected, started_ref)
        if op[0] == "assign":
            for a in got:
                started_new[a.run_id] = started_ref[a.run_id] = queued[a.run_id]
        assert got == want, f"op {i} {op}: {got} != {want}"
        assert state(new) == state(ref), f"after op {i} {op}"
        if op[0] == "estimate":
            assert fleet_answers(new) == fleet_answers(ref)


@pytest.mark.slow
def test_same_assignments_and_estimates_as_the_reference_on_random_scenarios():
    paths = {"by kind": 0, "events": 0}
    for seed in range(400):
        replay(random_scenario(seed), paths)
    # both ways of estimating were exercised often
    assert paths["by kind"] > 1000 and paths["events"] > 150, paths


@pytest.mark.parametrize("seed", range(6))
def test_long_queues_on_the_twb_up_fleet_estimate_like_the_reference(seed):
    rng = random.Random(seed)
    sc = Scenario(twb_up_fleet(rng), {k: None for k in range(1, 5)})
    for i in range(1, 400):
        sc.ops.append(("add", Pending(i, i, rng.choice(["sim", "twb"]), "full" if rng.random() < 0.03 else "sub",
                                      rng.choice(["room", "blocks"]), rng.uniform(20.0, 120.0))))
    sc.ops += [("assign",), ("release", 0.5), ("estimate", 0.5, 1.0), ("assign",), ("estimate", 0.2, 0.5)]
    paths = {"by kind": 0, "events": 0}
    replay(sc, paths)
    assert paths["by kind"] == 2
    new = sc.build(Scheduler)
    for p in (op[1] for op in sc.ops if op[0] == "add"):
        new.add(p)
    new.assign()
    remaining = {rid: 7.0 for rid in running(new)}
    by_kind = new.estimate_starts(remaining)
    assert by_kind == new._estimate_events(dict(remaining)) and len(by_kind) > 150


# ---------------------------------------------------------------------- the reference


@dataclass
class ReferenceScheduler:
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
        sim = ReferenceScheduler(
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
