"""The scheduling policy, without robots or sockets."""

from server.scheduler import Pending, RobotSlot, Scheduler


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
