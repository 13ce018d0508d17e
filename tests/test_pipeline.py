"""The run pipeline in-process: a real testbed's services, real robot agents on 127.0.0.1 sockets, a real
SQLite file; no server process.  Each test points at the step that decides the outcome."""

from __future__ import annotations

import asyncio
import contextlib
import math
from pathlib import Path
from typing import AsyncIterator

import numpy as np
import pytest
from sqlalchemy import select

from server.core.settings import Settings
from server.embedded import EmbeddedField
from server.errors import FailureKind, RunFailed
from server.models import Experiment, Message, Pose, Run, User
from server.pipeline.runner import RunEnd, execute_run, store_end
from server.scheduler import Assignment
from server.schemas import ExperimentCreate
from server.status import RunStatus
from server.store.experiments import create_experiment
from server.testbed import Testbed
from server.validation import Preflight

from planners import get_planner, parse_environment
from contract.controller_specs import select as select_controller

ONE_BLOCK = {"name": "one-block", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.3, "h": 0.3}]}


@contextlib.asynccontextmanager
async def running(tmp_path: Path, *, time_scale: float = math.inf, robots_time_scale: float | None = None,
                  **settings) -> AsyncIterator[Testbed]:
    """A testbed in this process; ``robots_time_scale``: its robots run at another speed than it believes."""
    tb = Testbed(Settings(data_dir=tmp_path / "data", time_scale=time_scale, planning_workers=1, **settings),
                 embedded=EmbeddedField(sim_robots=1, time_scale=robots_time_scale or time_scale))
    await asyncio.to_thread(tb.prepare)
    await tb.start()
    try:
        yield tb
    finally:
        await tb.stop()


def add_experiment(tb: Testbed, *, env: dict = ONE_BLOCK, start=(0.3, 0.3, 0.0), goal=(1.5, 1.5, 0.0),
                   planner: str | None = "fmm", params: dict | None = None, mode: str = "twb",
                   planned_path: list | None = None, jitter: dict | None = None, seed: int = 3,
                   controller: str = "schema", controller_params: dict | None = None) -> tuple[int, int]:
    """An experiment with one run of ``mode`` straight into the store (no pre-flight: tests choose the fault)."""
    with tb.sessions.begin() as s:
        admin = s.scalar(select(User).where(User.name == "admin"))
        body = ExperimentCreate(environment=env["name"], start=list(start), goal=list(goal), planner=planner,
                                planner_params=params or {}, modes=[mode], repetitions=1, seed=seed, jitter=jitter,
                                controller=controller)
        checked = Preflight(parse_environment(env), list(start), list(goal), params or {}, None,
                            select_controller(controller, controller_params).params,
                            stochastic=planner is not None and get_planner(planner).stochastic)
        exp = create_experiment(s, owner=admin, body=body, checked=checked, robot_radius=0.045,
                                planning_margin=0.02)
        exp.planned_path = planned_path
        return exp.id, exp.runs[0].id


def assignment(tb: Testbed, run_id: int, mode: str = "twb") -> Assignment:
    robot = "field-2" if mode == "twb" else "sim-1"
    return Assignment(run_id, robot, (2,) if mode == "twb" else ())


async def run_and_store(tb: Testbed, a: Assignment, *, stopping) -> RunEnd:  # type: ignore[no-untyped-def]
    """One run through the pipeline, its end stored as the dispatcher stores it."""
    end = await execute_run(a, tb.services, stopping=stopping)
    await store_end(tb.services.recorder, a.run_id, end)
    return end


def run_row(tb: Testbed, run_id: int) -> tuple[Run, int, int]:
    with tb.sessions() as s:
        run = s.get(Run, run_id)
        poses = len(s.scalars(select(Pose.id).where(Pose.run_id == run_id)).all())
        messages = len(s.scalars(select(Message.id).where(Message.run_id == run_id)).all())
        return run, poses, messages


async def test_a_run_goes_through_every_step_to_completed(tmp_path, database_url):
    async with running(tmp_path, database_url=database_url) as tb:
        exp_id, run_id = add_experiment(tb)
        end = await run_and_store(tb, assignment(tb, run_id), stopping=lambda: False)
        assert end.status is RunStatus.COMPLETED and end.error == "", end
        run, poses, messages = run_row(tb, run_id)
        assert run.status == "completed" and run.finished_at is not None
        assert run.robot_id == "field-2" and run.subfield == 2 and run.t_end > run.t_start
        assert run.metrics["goal_reached"] is True and run.metrics["collided"] is False
        assert run.metrics["planning_time_s"] == run.planning_time_s > 0  # its own planning, timed
        assert run.planning_cpu_s > 0 and run.planning_repeats >= 1 and run.planned_path[0][:2] == [0.3, 0.3]
        assert poses > 50 and messages > 5
        assert tb.field.built["field-2"] == "one-block"
        with tb.sessions() as s:
            assert s.get(Experiment, exp_id).planned_path[0][:2] == [0.3, 0.3]


async def test_a_collision_fails_the_run_and_it_is_still_measured(tmp_path, database_url):
    async with running(tmp_path, database_url=database_url) as tb:
        through = [[0.3, 0.9, 0.0], [0.9, 0.9, 0.0], [1.5, 0.9, 0.0]]  # straight through the block
        _, run_id = add_experiment(tb, start=(0.3, 0.9, 0.0), goal=(1.5, 0.9, 0.0), planned_path=through)
        end = await run_and_store(tb, assignment(tb, run_id), stopping=lambda: False)
        assert end.status is RunStatus.FAILED and end.error.startswith("collision"), end
        assert end.failure is FailureKind.COLLISION and not end.whole_experiment and end.robot_fault is None
        run, poses, _ = run_row(tb, run_id)
        assert run.metrics["collided"] is True and poses > 2  # what it drove until the contact is data
        x, y = run.stopped_at  # just before the block (0.75..1.05 x 0.75..1.05)
        assert 0.6 < x < 0.76 and 0.8 < y < 1.0, run.stopped_at


#: a wall across the whole field: nothing gets from its left half to its right
WALL = {"name": "wall", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.06, "h": 1.8}]}


@pytest.mark.slow
async def test_no_path_of_a_deterministic_planner_fails_the_whole_experiment_and_is_not_planned_twice(tmp_path):
    async with running(tmp_path) as tb:
        exp_id, run_id = add_experiment(tb, env=WALL, goal=(1.5, 0.3, 0.0), mode="sim")
        end = await run_and_store(tb, assignment(tb, run_id, "sim"), stopping=lambda: False)
        assert end.status is RunStatus.FAILED and end.whole_experiment
        assert end.error.startswith("planning failed: the goal (1.5, 0.3) cannot be reached")
        for rep in (1, 2):  # the remembered failure, for every repetition: not a second planning
            with pytest.raises(RunFailed) as exc:
                await tb.services.paths.path_for(exp_id, rep)
            assert str(exc.value) == end.error and exc.value.whole_experiment


async def test_no_path_of_a_randomised_planner_fails_its_repetition_only(tmp_path):
    """Fixed-sample PRM with two samples finds no path around the block with repetition 1's planner seed: that
    repetition fails (remembered for it), the experiment does not; other seeds are tried (docs/study.md, "Seeds")."""
    async with running(tmp_path) as tb:
        exp_id, run_id = add_experiment(tb, planner="prm", params={"samples": 2, "k": 1, "grow": False}, mode="sim",
                                        seed=1)
        with tb.sessions() as s:
            assert s.get(Experiment, exp_id).planner_stochastic
        end = await run_and_store(tb, assignment(tb, run_id, "sim"), stopping=lambda: False)
        assert end.status is RunStatus.FAILED and not end.whole_experiment and end.failure is FailureKind.PLANNING
        assert end.error.startswith("planning failed: PRM found no path")
        with pytest.raises(RunFailed) as exc:  # the sibling of the repetition gets the remembered failure
            await tb.services.paths.path_for(exp_id, 1)
        assert str(exc.value) == end.error and not exc.value.whole_experiment
        plan = await tb.services.paths.path_for(exp_id, 2)  # repetition 2's seed finds one
        assert plan.path[0][:2] == [0.3, 0.3] and plan.planning_time_s > 0 and plan.planning_repeats >= 1


async def test_a_robot_that_dies_mid_run_is_the_testbeds_fault(tmp_path):
    async with running(tmp_path, time_scale=5.0) as tb:
        _, run_id = add_experiment(tb, mode="sim")
        task = asyncio.create_task(run_and_store(tb, assignment(tb, run_id, "sim"), stopping=lambda: False))
        for _ in range(300):
            if run_row(tb, run_id)[0].status == "running":
                break
            await asyncio.sleep(0.05)
        await tb.embedded.stop()
        end = await asyncio.wait_for(task, 30)
        assert end.status is RunStatus.ERROR and end.robot_fault == "sim-1", end
        assert end.error.startswith("robot sim-1: "), end


async def test_too_few_tracker_poses_is_the_testbeds_fault(tmp_path):
    async with running(tmp_path, tracker_grace_s=0.0) as tb:
        _, run_id = add_experiment(tb, mode="sim")
        tb.tracker.open = lambda *a: None  # no pose window: the tracker stores nothing for the run
        end = await run_and_store(tb, assignment(tb, run_id, "sim"), stopping=lambda: False)
        assert end.status is RunStatus.ERROR and end.error.startswith("cannot compute metrics: only 0 pose(s)")


@pytest.mark.slow
@pytest.mark.parametrize("stopping", [False, True])
async def test_a_cancelled_run_ends_cancelled_or_interrupted_and_keeps_its_log(tmp_path, stopping):
    async with running(tmp_path, time_scale=2.0) as tb:
        _, run_id = add_experiment(tb, mode="sim")
        task = asyncio.create_task(run_and_store(tb, assignment(tb, run_id, "sim"),
                                               stopping=lambda: stopping))
        for _ in range(300):
            if run_row(tb, run_id)[0].status == "running":
                break
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.3)
        task.cancel()
        end = await asyncio.wait_for(task, 30)
        assert end.status is (RunStatus.INTERRUPTED if stopping else RunStatus.CANCELLED)
        assert run_row(tb, run_id)[2] > 3  # the protocol log up to the cut is kept


async def test_the_run_timeout_counts_the_robots_time_not_the_testbeds(tmp_path):
    """The testbed expects the robot 1000x faster than it runs (as when the machine falls behind): the
    wall-clock budget is spent long before the robot's own time is, and the run completes."""
    async with running(tmp_path, time_scale=1000.0, robots_time_scale=5.0, run_slack_s=0.3,
                       run_timeout_min_s=30.0) as tb:
        _, run_id = add_experiment(tb, mode="sim")
        end = await run_and_store(tb, assignment(tb, run_id, "sim"), stopping=lambda: False)
        assert end.status is RunStatus.COMPLETED, end
        with tb.sessions() as s:
            queries = s.scalars(select(Message.line).where(Message.run_id == run_id, Message.line == "T,T,Q")).all()
        assert len(queries) > 3  # it asked the robot's clock again and again, and waited


async def test_a_robot_whose_own_time_runs_out_is_stopped_and_the_run_fails(tmp_path, monkeypatch):
    from robot_agent.engine import run_data

    monkeypatch.setattr(run_data, "expected_duration_s", lambda *a, **k: 0.5)  # the run's budget: 1 s of its time
    async with running(tmp_path, time_scale=5.0, run_slack_s=0.3, run_timeout_min_s=1.0) as tb:
        _, run_id = add_experiment(tb, mode="sim")
        end = await run_and_store(tb, assignment(tb, run_id, "sim"), stopping=lambda: False)
        assert end.status is RunStatus.FAILED and end.error.startswith("timeout: the robot did not finish"), end
        with tb.sessions() as s:
            lines = s.scalars(select(Message.line).where(Message.run_id == run_id)).all()
        assert "T,T,S" in lines


async def test_start_pose_jitter_is_seeded_and_small(tmp_path):
    from robot_agent.engine.run_data import jittered
    from server.store.poses import run_poses

    jitter = {"xy_m": 0.01, "theta_rad": 0.05}
    async with running(tmp_path) as tb:
        firsts = []
        for seed in (1, 1, 2):
            _, run_id = add_experiment(tb, mode="sim", jitter=jitter, seed=seed)
            end = await run_and_store(tb, assignment(tb, run_id, "sim"), stopping=lambda: False)
            assert end.status is RunStatus.COMPLETED, end
            with tb.sessions() as s:
                first, run_seed = run_poses(s, run_id)[0], s.get(Run, run_id).seed
            assert first[1:3] == pytest.approx(jittered([0.3, 0.3, 0.0], jitter, run_seed)[:2], abs=1e-5)  # 0.01 mm
            firsts.append(first[1:3])
        assert firsts[0] == firsts[1] and firsts[0] != firsts[2]  # the run's seed decides
        for x, y in firsts:
            assert 1e-4 < math.hypot(x - 0.3, y - 0.3) < 0.05


#: ONE_BLOCK with a disc crossing the straight way from (0.3, 0.3) to (1.5, 0.3) when the robot gets there
MOVING = {**ONE_BLOCK, "name": "one-block-moving",
          "moving_obstacles": [{"radius": 0.04, "waypoints": [[0.8, 0.05], [0.8, 0.6]], "speed": 0.1,
                                "repeat": "pingpong", "delay_s": 0.5}]}


@pytest.mark.parametrize("through, controller", [("", "schema"), ("block", "schema"), ("obstacle", "schema"),
                                                ("", "kanayama"), ("", "regulated_pure_pursuit")])
@pytest.mark.slow
async def test_a_run_as_an_engine_task_gives_what_an_agent_gives(tmp_path, through, controller):
    """The same run on the agent's robot and as one compute task (the Ray pool's code path, here on the
    worker processes): the same outcome, where it stopped, poses (bit for bit) and metrics (1e-9); with any
    controller (which reaches the agent as a T,T,C line)."""
    async with running(tmp_path) as tb:
        tb.field.add_engine_slots("engine", 1)
        through_block = bool(through)
        kw = dict(start=(0.3, 0.9, 0.0), goal=(1.5, 0.9, 0.0), planner=None,
                  planned_path=[[0.3, 0.9, 0.0], [0.9, 0.9, 0.0], [1.5, 0.9, 0.0]]) if through == "block" else \
            dict(env=MOVING, start=(0.3, 0.3, 0.0), goal=(1.5, 0.3, 0.0), planner=None,
                 planned_path=[[0.3, 0.3, 0.0], [0.9, 0.3, 0.0], [1.5, 0.3, 0.0]]) if through == "obstacle" else \
            dict(jitter={"xy_m": 0.01, "theta_rad": 0.05}, controller=controller)
        found = []
        for robot in ("sim-1", "engine-1"):
            _, run_id = add_experiment(tb, mode="sim", **kw)
            end = await run_and_store(tb, Assignment(run_id, robot, ()), stopping=lambda: False)
            with tb.sessions() as s:
                run = s.get(Run, run_id)
                poses = np.array([[p.t, p.x, p.y, p.theta] for p in
                                  s.scalars(select(Pose).where(Pose.run_id == run_id).order_by(Pose.id))])
                found.append((end, run.robot_id, run.metrics, run.stopped_at, run.t_start, run.t_end, poses))
        (ea, ra, ma, sa, t0a, t1a, pa), (eb, rb, mb, sb, t0b, t1b, pb) = found
        assert (ra, rb) == ("sim-1", "engine-1")
        assert (ea.status, ea.failure, ea.error) == (eb.status, eb.failure, eb.error)
        assert eb.robot_fault is None
        assert ea.status is (RunStatus.FAILED if through_block else RunStatus.COMPLETED)
        assert sa == sb and (sa is not None) == through_block
        pa = pa[pa[:, 0] >= t0a - 1e-9]
        assert pa.shape == pb.shape and np.array_equal(pa[:, 1:], pb[:, 1:])
        assert math.isclose(t1a - t0a, t1b - t0b, abs_tol=1e-9)
        with tb.sessions() as s:
            sent = [m.line for m in s.scalars(select(Message).where(Message.direction == ">"))]
        chosen = [line for line in sent if line.startswith("T,T,C")]
        assert len(chosen) == (0 if controller == "schema" else 2)  # the agent's run and the task's log
        assert all(line.startswith(f"T,T,C,{controller},") for line in chosen)
        assert ma.keys() == mb.keys()
        for k in ma:
            if isinstance(ma[k], float) and k != "planning_time_s":
                assert math.isclose(ma[k], mb[k], rel_tol=1e-9, abs_tol=1e-12), k
            elif k != "planning_time_s":
                assert ma[k] == mb[k], k
        assert (ma["collisions_block"], ma["collisions_obstacle"]) == {
            "": (0, 0), "block": (1, 0), "obstacle": (0, 1)}[through]
        assert ("obstacle_distance_min_m" in ma) == (through == "obstacle")
        if through == "obstacle":  # it touched the disc: the gap of its chassis (0.045 m) is about zero
            assert -0.01 < ma["obstacle_distance_min_m"] < 0.01 and ma["obstacle_time_within_s"] > 0
            assert ea.error == "collision: the robot hit moving obstacle 0 (the environment's moving_obstacles[0])"


@pytest.mark.slow
@pytest.mark.parametrize("planner", ["fmm", "st_astar"])
async def test_the_crossing_disc_fails_an_uncoordinated_run_and_not_a_space_time_one(tmp_path, planner):
    """Moving obstacles (docs/planners.md, "Moving obstacles"): plan A of the built-in `crossing` on the agent's
    robot, planned by the testbed; fmm's path meets the disc that crosses it (a collision naming it, counted as one),
    st_astar's does not."""
    from planners import load_environment

    crossing = load_environment("crossing").to_dict()
    async with running(tmp_path) as tb:
        _, run_id = add_experiment(tb, env=crossing, start=(0.3, 0.3, 0.0), goal=(1.5, 1.5, 1.5708),
                                   planner=planner, mode="sim")
        end = await run_and_store(tb, assignment(tb, run_id, "sim"), stopping=lambda: False)
        run, poses, _ = run_row(tb, run_id)
        if planner == "fmm":
            assert end.status is RunStatus.FAILED and end.failure is FailureKind.COLLISION, end
            assert end.error == "collision: the robot hit moving obstacle 0 (the environment's moving_obstacles[0])"
            assert (run.metrics["collisions_obstacle"], run.metrics["collisions_block"]) == (1, 0)
        else:
            assert end.status is RunStatus.COMPLETED, end
            assert (run.metrics["collisions_obstacle"], run.metrics["collisions_block"]) == (0, 0)
            assert run.metrics["goal_reached"] and run.metrics["obstacle_distance_min_m"] > 0.02
        assert "sim-1" in tb.field.moving  # the agent's world has the discs until an environment clears them
        _, later = add_experiment(tb, mode="sim")  # one-block: no discs; building it clears them
        end = await run_and_store(tb, assignment(tb, later, "sim"), stopping=lambda: False)
        assert end.status is RunStatus.COMPLETED and "sim-1" not in tb.field.moving
        with tb.sessions() as s:
            sent = s.scalars(select(Message.line).where(Message.run_id == later, Message.direction == ">")).all()
        assert "T,T,M" in sent



@pytest.mark.slow
async def test_a_replanning_run_counts_its_replans_on_the_agent_and_as_a_task(tmp_path):
    """Replanning (docs/controllers.md, "Replanning"): fmm's path of `crossing` A with regulated pure pursuit
    replanning, on the agent's robot and as an engine task: both reach the goal around the disc, log the EV,REPLAN
    lines and count them in the same metrics (``replans``; ``replan_time_s`` is the machine's)."""
    from planners import load_environment

    crossing = load_environment("crossing").to_dict()
    async with running(tmp_path) as tb:
        tb.field.add_engine_slots("engine", 1)
        found = []
        for robot in ("sim-1", "engine-1"):
            _, run_id = add_experiment(tb, env=crossing, start=(0.3, 0.3, 0.0), goal=(1.5, 1.5, 1.5708),
                                       mode="sim", controller="regulated_pure_pursuit",
                                       controller_params={"replan": 1})
            end = await run_and_store(tb, Assignment(run_id, robot, ()), stopping=lambda: False)
            assert end.status is RunStatus.COMPLETED, end
            run, _, _ = run_row(tb, run_id)
            with tb.sessions() as s:
                got = s.scalars(select(Message.line).where(Message.run_id == run_id, Message.direction == "<")).all()
            replans = [line for line in got if line.startswith("EV,REPLAN,")]
            assert len(replans) == run.metrics["replans"] >= 1 and run.metrics["replan_failures"] == 0
            assert run.metrics["replan_time_s"] > 0 and run.metrics["collisions_obstacle"] == 0
            found.append((run.metrics["replans"], [line.split(",")[2] for line in replans]))
        assert found[0] == found[1]
