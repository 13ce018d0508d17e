"""Replanning in the built-in controllers (docs/controllers.md, "Replanning"): the path-ahead check, the replan around
the moving obstacles' known tracks, its events, its determinism, and that a run without it is the run it was."""

from __future__ import annotations

import math

import numpy as np
import pytest
from agent_support import LineClient, running_agents

from planners import DEFAULT_PLANNING_MARGIN, load_environment, plan_path
from planners.metrics import obstacle_gaps
from planners.moving import MovingObstacle
from contract.controller_specs import ControllerError, select
from robot_agent.engine.headless import simulate_run
from contract.protocol import encode_build, encode_controller, encode_moving, encode_path, encode_place
from robot_agent.engine.replan import blocked, path_ahead
from robot_agent.engine.jobs import simulate_job
from robot_agent.engine.run_data import block_tuples, moving_tuples

CROSSING = load_environment("crossing")
DATA = CROSSING.to_dict()
PLAN = CROSSING.plan("A")
RPP = "regulated_pure_pursuit"


@pytest.fixture(scope="module")
def fmm_path() -> np.ndarray:
    """Plan A of `crossing` by fmm, as the testbed plans it: its shortest way meets disc 0."""
    return plan_path(CROSSING, PLAN.start, PLAN.goal, "fmm", planning_margin=DEFAULT_PLANNING_MARGIN).path


def drive(path: np.ndarray, backend: str = "ideal", seed: int = 5, controller: str = RPP, **params):
    return simulate_run(path, PLAN.start, seed=seed, blocks=block_tuples(DATA), moving=moving_tuples(DATA),
                        area=CROSSING.size, backend=backend, controller=controller, controller_params=params)


@pytest.mark.parametrize("controller", [RPP, "pure_pursuit", "kanayama", "schema"])
@pytest.mark.parametrize("backend", ["ideal", "field"])
def test_without_replanning_a_robot_hits_the_disc_and_with_it_reaches_the_goal(fmm_path, backend, controller):
    """Every built-in controller replans (the schema, which keeps no projection on the path, from the robot's
    projection on the leg it drives)."""
    hit = drive(fmm_path, backend, controller=controller)
    assert hit.outcome == "COLLISION" and hit.obstacle == 0
    assert not [e for e in hit.events if e.kind == "REPLAN"]
    run = drive(fmm_path, backend, controller=controller, replan=1)
    replans = [e for e in run.events if e.kind == "REPLAN"]
    assert run.outcome == "DONE" and run.obstacle is None
    # the first replan comes while it drives the planned path; a later one may come on a new path's first leg,
    # where the disc crosses it again (the skid-steered field robot turning slower: RPP replans 5 times)
    assert replans and replans[0].index > 1 and all(e.seconds > 0 for e in replans)
    assert np.hypot(*(run.poses[-1, 1:3] - PLAN.goal[:2])) < 0.05
    gaps = obstacle_gaps(CROSSING, run.poses[:, 1:3], run.poses[:, 0] - run.t_start, 0.04)
    assert gaps.min() > 0.0
    # before the first replan it drove the planned path, as without replanning; then another way
    first = replans[0].t
    before = run.poses[:, 0] <= first
    np.testing.assert_array_equal(run.poses[before], hit.poses[hit.poses[:, 0] <= first])
    # the REPLAN comes before the collision would have been, and its WP indices start again from 0
    assert first < hit.t_end
    after = [e.index for e in run.events if e.kind == "WP" and e.t >= first]
    assert after[0] == 0


def test_a_replanning_run_replays_exactly(fmm_path):
    a, b = drive(fmm_path, "field", seed=9, replan=1), drive(fmm_path, "field", seed=9, replan=1)
    assert np.array_equal(a.poses, b.poses) and a.events == b.events
    assert [e.line.rsplit(",", 2)[0] for e in a.events] == [e.line.rsplit(",", 2)[0] for e in b.events]


def test_replan_off_gives_mains_poses_bit_for_bit(fmm_path):
    """Replanning is off by default: the same run as before it existed (main at f65a5cb gave these numbers for
    the ideal robot: 333 tracker poses, the collision at 6.64 s), and on the field the same as ``replan`` = 0
    given explicitly (the field's numbers changed since with the obstacle robots, tests/test_field_movers.py)."""
    run = drive(fmm_path, "ideal")
    assert len(run.poses) == 333 and run.outcome == "COLLISION"
    assert [round(v, 9) for v in run.poses[-1]] == [6.64, 0.754505274, 1.195764155, 0.788659044]
    assert round(float(run.poses[:, 1].sum()), 6) == 162.423903
    for backend in ("ideal", "field"):
        default = drive(fmm_path, backend)
        off = drive(fmm_path, backend, replan=0, replan_horizon_s=5.0)
        assert np.array_equal(off.poses, default.poses) and off.events == default.events


def test_checking_without_anything_in_the_way_changes_nothing():
    """A replanning robot whose way nothing crosses checks 5 times a second and never replans: the compiled
    loop split at its checks gives the same poses as one run without them."""
    room = load_environment("room")
    p = room.plan("A")
    path = plan_path(room, p.start, p.goal, "fmm", planning_margin=DEFAULT_PLANNING_MARGIN).path
    runs = [simulate_run(path, p.start, seed=3, blocks=block_tuples(room.to_dict()), area=room.size,
                         backend="field", controller=RPP, controller_params={"replan": on}) for on in (0, 1)]
    assert runs[0].outcome == "DONE" and not [e for e in runs[1].events if e.kind == "REPLAN"]
    assert np.array_equal(runs[0].poses, runs[1].poses) and runs[0].events == runs[1].events


def test_the_check_sees_a_disc_where_it_will_be_and_a_robot_where_it_is():
    path = np.array([[0.2, 0.5, 0.0], [1.2, 0.5, 0.0]])
    pts, dist = path_ahead(path, 0, 0.1, 0.6)  # from x = 0.3, 0.6 m ahead, every 2 cm
    assert np.allclose(pts[[0, -1]], [[0.3, 0.5], [0.9, 0.5]]) and np.allclose(np.diff(dist), 0.02)
    times = dist / 0.2  # driving at 0.2 m/s: at x = 0.7 after 2 s
    # a disc crossing x = 0.7 at obstacle time 12 s: blocking when now is 10 s, not when now is 0 s
    disc = MovingObstacle(0.04, ((0.7, 0.0), (0.7, 1.0)), 0.1, "once", 7.0)
    assert blocked(pts, times, (disc,), 10.0, np.zeros((0, 2)), 0.04)
    assert not blocked(pts, times, (disc,), 0.0, np.zeros((0, 2)), 0.04)
    assert not blocked(pts, times, (disc,), 20.0, np.zeros((0, 2)), 0.04)  # long gone
    # a robot standing on the way blocks it; one 0.2 m beside it does not
    assert blocked(pts, times, (), 0.0, np.array([[0.8, 0.52]]), 0.04)
    assert not blocked(pts, times, (), 0.0, np.array([[0.8, 0.7]]), 0.04)
    # brute force: the nearest approach of the disc to any sample, in the +-1 s window, decides
    t = np.linspace(-1.0, 1.0, 5)
    centres = disc.position((10.0 + times[:, None] + t[None]).ravel()).reshape(len(pts), 5, 2)
    gap = np.hypot(*(centres - pts[:, None]).transpose(2, 0, 1)).min()
    assert gap < 0.04 + 0.04 + 0.02


@pytest.mark.parametrize("params, field", [({"replan": 2}, "replan"), ({"replan": 0.5}, "replan"),
                                           ({"replan": True}, "replan"), ({"replan_horizon_s": 0.1},
                                                                            "replan_horizon_s"),
                                           ({"replan_min_interval_s": float("nan")}, "replan_min_interval_s")])
def test_bad_replanning_parameters_name_the_field(params, field):
    with pytest.raises(ControllerError) as err:
        select(RPP, params)
    assert err.value.field == f"controller_params.{field}" and f"controller_params.{field}" in str(err.value)


def test_the_replanning_parameters_stay_out_of_the_compiled_row():
    on, off = select(RPP, {"replan": 1, "replan_horizon_s": 5.0}), select(RPP)
    assert on.replans and not off.replans
    assert np.array_equal(on.row, off.row) and on.row[7] == 0.03  # min_speed_m_s is still the 8th
    listed = {p["name"]: p for p in on.spec.to_dict()["parameters"]}
    assert listed["replan"]["integer"] and listed["replan"]["range"] == [0, 1] and listed["replan"]["default"] == 0
    assert "integer" not in listed["replan_horizon_s"]


async def test_an_agent_replans_as_the_headless_run_and_says_so(fmm_path):
    """Over TCP the robot replans in a worker thread while its simulation waits: the same poses and events
    as headless, each replan an ``EV,REPLAN,<points>,<ms>,<t>`` line to the path's sender."""
    params = {"replan": 1}
    async with running_agents(backend="ideal", world="separate", area=CROSSING.size) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_build(block_tuples(DATA)))
        await c.ask(encode_moving(moving_tuples(DATA)))
        await c.ask(encode_place(PLAN.start))
        assert await c.ask(encode_controller(RPP, params)) == "OK,C"
        agents.set_path_seed(agents.robots[0].robot_id, 5)
        await c.ask(encode_path(fmm_path))
        lines = await c.until("EV,DONE", "EV,FAIL", timeout=60)
        await agents.flush_tracker()
        poses = agents.sink.poses(agents.robots[0].robot_id)
        await c.close()
    events = [line for line in c.stash + lines if line.startswith("EV,")]
    run = drive(fmm_path, **params)
    replans = [line.split(",") for line in events if line.startswith("EV,REPLAN,")]
    assert replans and events[-1].startswith("EV,DONE")
    assert all(int(r[2]) > 1 and float(r[3]) > 0 for r in replans)
    t0 = float(events[0].split(",")[-1])
    shift = t0 - run.t_start
    # the same events (the planning time aside, which is the machine's) at the same times
    strip = [line.split(",") for line in events]
    mine = [e.line.split(",") for e in run.events]
    assert [f[:3] if f[1] == "REPLAN" else f[:-1] for f in strip] == [f[:3] if f[1] == "REPLAN" else f[:-1]
                                                                     for f in mine]
    assert [round(float(f[-1]) - shift, 6) for f in strip] == [round(float(f[-1]), 6) for f in mine]
    theirs = poses[poses[:, 0] >= t0 - 1e-9][:, 1:]
    assert theirs.shape == run.poses[:, 1:].shape and np.abs(theirs - run.poses[:, 1:]).max() < 1e-12


def test_an_engine_task_counts_the_replans_in_the_metrics(fmm_path):
    path = np.round(fmm_path, 6).tolist()
    params = select(RPP, {"replan": 1}).params
    out = simulate_job(DATA, path, [list(PLAN.start)], 5, 120.0, list(PLAN.goal), 0.045, 0.01,
                       controller=RPP, controller_params=params)
    m = out["metrics"]
    assert out["outcome"] == "DONE" and m["replans"] >= 1 and m["replan_failures"] == 0
    assert 0 < m["replan_time_s"] < 5 and m["goal_reached"]
    assert m["length_ratio"] > 1.0  # it drove around the disc: longer than the planned path
    assert any(line[1].startswith("EV,REPLAN,") for line in out["lines"])
    off = simulate_job(DATA, path, [list(PLAN.start)], 5, 120.0, list(PLAN.goal), 0.045, 0.01,
                       controller=RPP, controller_params=select(RPP).params)
    assert off["outcome"] == "COLLISION" and "replans" not in off["metrics"]
