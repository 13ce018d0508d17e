"""On the emulated field moving obstacles are robots the testbed drives (docs/protocol.md, "Moving obstacles"): they
lag behind their exact tracks but stay close, replay exactly, collide as robots, stop when hit, are measured where
they were, and count toward the field's robots; in simulation nothing changed."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest
from sqlalchemy import select

from planners.moving import MovingObstacle, positions
from robot_agent.engine.fleet import simulate_fleet
from robot_agent.engine.headless import simulate_run
from robot_agent.engine.movers import mover_tracks
from contract.params import robot_params
from contract.robot_profile import load_profile
from server.models import Experiment, Message, Run
from server.schemas import ExperimentCreate
from server.validation import PreflightError, preflight

from test_pipeline import add_experiment, run_and_store, running
from server.scheduler import Assignment
from server.status import RunStatus

P = robot_params()
#: an L-shaped track, once, after a 1 s delay (m, m/s, s)
L_TRACK = [[0.3, 0.3], [1.5, 0.3], [1.5, 1.2]]
#: a disc crossing the straight way from (0.2, 0.5) to (1.6, 0.5) at x = 0.9 when the robot gets there
CROSSING = [([0.04, 0.1, 0.0, 0.0], [[0.9, 0.9], [0.9, 0.1]])]
STRAIGHT = np.array([[0.2, 0.5, 0.0], [1.6, 0.5, 0.0]])


@pytest.mark.parametrize("repeat, code", [("once", 0), ("loop", 1), ("pingpong", 2)])
def test_an_obstacle_robot_lags_its_exact_track_but_stays_close_and_replays_exactly(repeat, code):
    obstacles = [([0.04, 0.1, float(code), 1.0], L_TRACK)]
    got = mover_tracks(obstacles, 12345, P, 40.0)[0]
    exact = positions([MovingObstacle(0.04, tuple(map(tuple, L_TRACK)), 0.1, repeat, 1.0)], got[:, 0])[0]
    off = np.hypot(*(got[:, 1:3] - exact).T)
    # lag, corners: a few cm; up to 8 cm where pingpong turns back (the tracks reverse at 0.3 m/s², lagging 0.25 s,
    # and skid slows the turn: 7 cm without it)
    assert 0.003 < off.mean() < 0.03 and off.max() < 0.09, (off.mean(), off.max())
    assert len(got) > 0.9 * 40 * P.field.camera_rate_hz  # the tracker's poses at its rate, a few dropped
    again = mover_tracks(obstacles, 12345, P, 40.0)[0]
    assert np.array_equal(got, again)
    other = mover_tracks(obstacles, 54321, P, 40.0)[0]
    assert not np.array_equal(got[:, 1:3], other[:, 1:3]) and np.abs(got[-1, 1:3] - other[-1, 1:3]).max() < 0.1
    assert np.array_equal(mover_tracks(obstacles, 12345, P, 20.0)[0], got[got[:, 0] < 20.0 - 1e-9])


def test_a_robot_run_into_by_an_obstacle_robot_collides_and_the_failure_names_it():
    sim = simulate_run(STRAIGHT, STRAIGHT[0], seed=3, moving=CROSSING, backend="ideal", area=(1.8, 1.8))
    field = simulate_run(STRAIGHT, STRAIGHT[0], seed=3, moving=CROSSING, backend="field", area=(1.8, 1.8))
    assert (sim.outcome, sim.obstacle, sim.obstacles) == ("COLLISION", 0, None)
    assert (field.outcome, field.obstacle) == ("COLLISION", 0)
    assert field.t_end != sim.t_end  # a robot of the field, not the disc
    track = field.obstacles[0]
    j = np.searchsorted(track[:, 0], field.t_end)
    centres = np.hypot(*(track[j - 1, 1:3] - field.poses[-1, 1:3]))
    assert centres < 2 * P.collision_radius_m + 0.02  # robot-robot contact: two collision radii between centres
    assert track[-1, 0] <= field.t_end + 1e-9  # logged while the run lasted
    again = simulate_run(STRAIGHT, STRAIGHT[0], seed=3, moving=CROSSING, backend="field", area=(1.8, 1.8))
    assert np.array_equal(again.poses, field.poses) and np.array_equal(again.obstacles[0], track)


def test_a_fleets_obstacle_robots_are_shared_stopped_for_all_when_hit_and_replay_exactly():
    paths = [STRAIGHT, np.array([[0.2, 1.2, 0.0], [1.6, 1.2, 0.0]])]
    starts = [p[0] for p in paths]
    run = simulate_fleet(paths, starts, seed=3, moving=CROSSING, backend="field", area=(1.8, 1.8))
    assert run.outcomes == ["COLLISION", "DONE"] and run.runs[0].obstacle == 0
    (track,) = run.obstacles
    stopped = track[track[:, 0] > run.runs[0].t_end + 0.1]
    assert np.ptp(stopped[:, 1:3], axis=0).max() < 0.005 and stopped[-1, 0] > run.runs[1].t_end - 0.1
    again = simulate_fleet(paths, starts, seed=3, moving=CROSSING, backend="field", area=(1.8, 1.8))
    assert np.array_equal(again.obstacles[0], track)
    assert all(np.array_equal(a.poses, b.poses) for a, b in zip(run.runs, again.runs))


def _digest(runs) -> str:  # type: ignore[no-untyped-def]
    h = hashlib.sha256()
    for r in runs:
        h.update(np.ascontiguousarray(r.poses).tobytes())
        h.update(repr([(e.kind, e.t, e.index, e.reason) for e in r.events]).encode())
    return h.hexdigest()[:16]


def test_simulation_is_unchanged_bit_for_bit():
    """The exact discs of a simulation, and field runs without moving obstacles, give main's numbers before
    obstacle robots came (digests taken there, same seeds).  The field run is the BeBot of then (issue 33 made
    its motors lag 0.25 s, its tracks accelerate at 0.3 m/s², its slip correlated over 0.1 s, its tracks skid):
    with those four values back, the field code gives the same poses bit for bit (white slip is
    ``wheel_noise_corr_s`` 0, no skid ``track_width_factor`` 1)."""
    then = load_profile("bebot")
    then["max_accel_m_s2"] = 0.4
    then["field"].update(motor_time_constant_s=0.12, wheel_noise_corr_s=0.0, track_width_factor=1.0)
    moving = [([0.04, 0.1, 0.0, 0.0], [[0.9, 0.9], [0.9, 0.1]]),
              ([0.05, 0.15, 1.0, 0.5], [[0.3, 1.5], [1.5, 1.5], [1.5, 0.8]]),
              ([0.03, 0.05, 2.0, 1.0], [[0.2, 1.0], [1.6, 1.0]])]
    path = np.array([[0.2, 0.5, 0.0], [1.6, 0.5, 0.0], [1.6, 1.6, 1.57]])
    single = [simulate_run(path, (0.2, 0.5, 0.0), seed=5, moving=mv, backend=b, area=(1.8, 1.8),
                           profile=then if b == "field" else "bebot")
              for b, mv in (("ideal", moving), ("ideal", moving[1:]), ("field", []))]
    paths = [path, np.array([[0.2, 1.2, 0.0], [1.6, 1.2, 0.0]]), np.array([[1.6, 0.2, 3.14], [0.2, 0.2, 3.14]])]
    starts = [(0.2, 0.5, 0.0), (0.2, 1.2, 0.0), (1.6, 0.2, 3.14)]
    fleet = simulate_fleet(paths, starts, seed=7, moving=moving[1:], backend="ideal", area=(1.8, 1.8),
                           depart=[None, np.array([np.nan, 5.0]), None])
    assert [r.outcome for r in single] == ["COLLISION", "DONE", "DONE"]
    assert (_digest(single), _digest(fleet.runs)) == (SINGLE_DIGEST, FLEET_DIGEST)


SINGLE_DIGEST = "4e736cdba761a884"
FLEET_DIGEST = "70628eda3fd17e21"


def _body(n_obstacles: int, robots: int = 1, field: str = "sub", modes=("sim", "twb")) -> tuple:
    env = {"name": "many", "size": [1.8, 1.8], "blocks": [],
           "moving_obstacles": [{"radius": 0.04, "speed": 0.1, "waypoints": [[0.2 + 0.08 * k, 1.6], [0.2 + 0.08 * k, 1.2]]}
                                for k in range(n_obstacles)]}
    if robots == 1:
        body = ExperimentCreate(environment="many", start=[0.3, 0.3, 0.0], goal=[1.5, 0.3, 0.0], planner="fmm",
                                modes=list(modes), field=field)
    else:
        body = ExperimentCreate(environment="many", planner="fmm", modes=list(modes), field=field,
                                robots=[{"start": [0.2 + 0.1 * k, 0.2], "goal": [0.2 + 0.1 * k, 0.8]}
                                        for k in range(robots)])
    return body, env


def test_the_field_refuses_more_robots_and_obstacle_robots_than_it_holds():
    body, env = _body(16)
    with pytest.raises(PreflightError) as err:
        preflight(body, env, 0.045)
    assert str(err.value).startswith("moving_obstacles: 16 moving obstacles and 1 robot need 17 robots of the "
                                     "field (on the field each moving obstacle is a robot the testbed drives); a "
                                     "sub-field holds 16")
    body, env = _body(12, robots=6)
    with pytest.raises(PreflightError, match=r"^moving_obstacles: 12 moving obstacles and 6 robots need 18 robots "
                                             r"of the field .* a sub-field holds 16 \(use \"field\": \"full\""):
        preflight(body, env, 0.045)
    preflight(*_body(15), 0.045)  # 15 + 1 fit a sub-field
    preflight(*_body(16, modes=("sim",)), 0.045)  # in simulation they are exact discs: no robots of the field
    preflight(*_body(12, robots=6, field="full"), 0.045)


#: a disc crossing the straight way from (0.3, 0.3) to (1.5, 0.3) when the robot gets there (test_pipeline)
MOVING = {"name": "one-way-moving", "size": [1.8, 1.8], "blocks": [],
          "moving_obstacles": [{"radius": 0.06, "waypoints": [[0.8, 0.05], [0.8, 0.6]], "speed": 0.1,
                                "repeat": "pingpong", "delay_s": 0.5}]}


@pytest.mark.slow
async def test_a_field_agents_run_and_the_same_run_as_a_task_meet_the_same_obstacle_robot(tmp_path):
    """The agent's field robot drives its obstacle robot live; the server replays it for the metrics.  The same
    run computed as a task (profile overrides equal to the shipped values) gives the same collision, poses and
    obstacle metrics, measured against where the obstacle robot was (not the exact disc of radius 0.06 m);
    the log says the obstacle is a robot whose size is not the file's."""
    shipped = P.field.tracker_noise_xy_m
    async with running(tmp_path) as tb:
        found = []
        for overrides in (None, {"tracker_noise_xy_m": shipped}):
            _, run_id = add_experiment(tb, env=MOVING, start=(0.3, 0.3, 0.0), goal=(1.5, 0.3, 0.0), planner=None,
                                       planned_path=[[0.3, 0.3, 0.0], [0.9, 0.3, 0.0], [1.5, 0.3, 0.0]])
            with tb.sessions.begin() as s:
                s.get(Experiment, s.get(Run, run_id).experiment_id).profile_overrides = overrides
            end = await run_and_store(tb, Assignment(run_id, "field-2", (2,)), stopping=lambda: False)
            with tb.sessions() as s:
                run = s.get(Run, run_id)
                lines = " ".join(s.scalars(select(Message.line).where(Message.run_id == run_id)))
                found.append((end, run.metrics, run.t_end - run.t_start, lines))
        (ea, ma, da, la), (eb, mb, db, lb) = found
        for end in (ea, eb):
            assert end.status is RunStatus.FAILED and end.failure.name == "COLLISION", end
            assert end.error == "collision: the robot hit moving obstacle 0 (the environment's moving_obstacles[0])"
        assert math.isclose(da, db, abs_tol=1e-9)
        for k in ("obstacle_distance_min_m", "obstacle_time_within_s", "length_m", "deviation_mean_m"):
            assert math.isclose(ma[k], mb[k], rel_tol=1e-9, abs_tol=1e-12), k
        # the chassis (0.045 m) touched a robot of that size: about -0.01 (the contact is at 2 x 0.04 m)
        assert -0.03 < ma["obstacle_distance_min_m"] < 0.0
        for log in (la, lb):
            assert "the 1 moving obstacle(s) are emulated BeBot robots the testbed drives" in log
            assert "so the radius 0.06 m the environment gives does not apply on the field" in log


def test_obstacle_gaps_measure_against_where_the_obstacles_were():
    """With tracks, the gap is to the track interpolated at the robot's times (each obstacle of
    ``obstacle_radius``), against a brute-force reference; a bad track is refused naming it."""
    from planners import parse_environment
    from planners.metrics import obstacle_gaps

    env = parse_environment({"name": "g", "size": [1.8, 1.8], "moving_obstacles": [
        {"radius": 0.06, "speed": 0.1, "waypoints": [[0.2, 0.2], [1.2, 0.2]]},
        {"radius": 0.06, "speed": 0.1, "waypoints": [[0.2, 1.2], [1.2, 1.2]]}]})
    t = np.linspace(0.0, 8.0, 41)
    path = np.column_stack([np.linspace(0.3, 1.0, 41), np.full(41, 0.5)])
    tracks = [np.column_stack([np.arange(0.0, 9.0, 0.5), 0.2 + 0.09 * np.arange(0.0, 9.0, 0.5), np.full(18, y),
                               np.zeros(18)]) for y in (0.25, 1.2)]
    got = obstacle_gaps(env, path, t, 0.045, tracks, 0.045)
    want = np.min([np.hypot(np.interp(t, tr[:, 0], tr[:, 1]) - path[:, 0], np.interp(t, tr[:, 0], tr[:, 2]) - path[:, 1])
                   for tr in tracks], axis=0) - 0.09
    assert np.allclose(got, want, atol=1e-12)
    assert not np.allclose(got, obstacle_gaps(env, path, t, 0.045))  # not the exact discs
    with pytest.raises(ValueError, match=r"`tracks\[1\]` must be \(T >= 1, 3\+\) rows t, x, y"):
        obstacle_gaps(env, path, t, 0.045, [tracks[0], np.zeros((0, 4))])
    with pytest.raises(ValueError, match="one track per moving obstacle"):
        obstacle_gaps(env, path, t, 0.045, tracks[:1])
