"""A run as a function call (robot_agent.engine.headless) equals the same run sent to an agent over TCP."""

from __future__ import annotations

import math

import numpy as np
import pytest
from agent_support import LineClient, densify, CORNERS, running_agents

from contract.frames import FIELD_SIZE
from robot_agent.engine.headless import PlacementRefused, simulate_run
from contract.protocol import encode_build, encode_moving, encode_path, encode_place, format_event

BLOCKS = [(0.9, 0.55, 0.3, 0.1, 0.2)]
#: a disc crossing the first leg of CORNERS (0.3, 0.3) -> (1.5, 0.3) when the robot gets there: it is hit
CROSSING = [((0.04, 0.1, 2, 0.5), [(0.8, 0.05), (0.8, 0.9)])]


async def over_tcp(path: np.ndarray, start, seed: int, blocks, moving=()) -> tuple[np.ndarray, list[str]]:
    async with running_agents(backend="ideal", world="separate", area=FIELD_SIZE) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_build(blocks))
        if moving:
            await c.ask(encode_moving(moving))
        await c.ask(encode_place(start))
        agents.set_path_seed(agents.robots[0].robot_id, seed)
        await c.ask(encode_path(path))
        lines = await c.until("EV,DONE", "EV,FAIL", timeout=60)
        await agents.flush_tracker()
        poses = agents.sink.poses(agents.robots[0].robot_id)
        await c.close()
    return poses, [line for line in c.stash + lines if line.startswith("EV,")]


@pytest.mark.parametrize("blocks, moving", [([], ()), (BLOCKS, ()), ([], CROSSING)])
async def test_a_headless_run_equals_the_same_run_over_tcp(blocks, moving):
    path = densify(CORNERS)
    start = (0.3, 0.3, 0.0)
    tcp_poses, tcp_events = await over_tcp(path, start, 7, blocks, moving)
    run = simulate_run(path, start, seed=7, blocks=blocks, moving=moving)
    t0_tcp = float(next(line for line in tcp_events if line.startswith("EV,START")).split(",")[-1])
    assert run.t_start == 0.0 or math.isclose(run.t_start, run.poses[0, 0], abs_tol=1e-9)
    mine = run.poses[:, 1:]
    theirs = tcp_poses[tcp_poses[:, 0] >= t0_tcp - 1e-9][:, 1:]
    assert mine.shape == theirs.shape and np.abs(mine - theirs).max() < 1e-12
    shift = t0_tcp - run.t_start
    assert [format_event(e.kind, 0.0, index=e.index, reason=e.reason).rsplit(",", 1)[0] for e in run.events] == \
        [line.rsplit(",", 1)[0] for line in tcp_events]
    assert [round(e.t + shift, 6) for e in run.events] == [round(float(line.split(",")[-1]), 6) for line in tcp_events]
    assert run.outcome == ("DONE" if not blocks and not moving else run.outcome)
    if moving:  # the obstacle's time runs from the path start on both: the same hit at the same time
        assert run.outcome == "COLLISION" and run.obstacle == 0 and tcp_events[-1].startswith("EV,FAIL,COLLISION,OBSTACLE,0,")


def test_a_moving_obstacle_is_hit_where_it_is_at_that_time_and_named():
    from planners.moving import MovingObstacle

    run = simulate_run(densify(CORNERS), (0.3, 0.3, 0.0), seed=1, moving=CROSSING)
    assert run.outcome == "COLLISION" and run.obstacle == 0
    ob = MovingObstacle(0.04, ((0.8, 0.05), (0.8, 0.9)), 0.1, "pingpong", 0.5)
    (cx, cy), = ob.position(np.array([run.t_end - run.t_start]))
    x, y = run.poses[-1, 1:3]
    assert math.hypot(x - cx, y - cy) < 0.04 + 0.04 + 0.01  # touching (the last logged pose is a step earlier)
    # a path that waits nowhere near the obstacle's track is not hit; the same seed replays exactly
    clear = simulate_run([[0.3, 0.3, 0.0], [0.3, 1.5, 1.5708]], (0.3, 0.3, 1.5708), seed=1, moving=CROSSING)
    assert clear.outcome == "DONE" and clear.obstacle is None
    again = simulate_run(densify(CORNERS), (0.3, 0.3, 0.0), seed=1, moving=CROSSING)
    assert np.array_equal(again.poses, run.poses) and again.events == run.events


def test_the_compiled_obstacle_track_is_the_planners_position_function():
    from planners.moving import MovingObstacle
    from contract.frames import field_layout
    from robot_agent.engine.world import World
    from robot_agent.engine.contact import obstacle_position

    obs = [MovingObstacle(0.03, ((0.2, 0.2), (0.6, 0.2), (0.6, 0.7)), 0.07, mode, 0.5)
           for mode in ("once", "loop", "pingpong")]
    sizes, world_of, origin, area = field_layout(1, "separate", FIELD_SIZE)
    world = World(sizes, world_of, origin, area, 0.04)
    codes = {"once": 0, "loop": 1, "pingpong": 2}
    world.set_moving(0, [((o.radius, o.speed, codes[o.repeat], o.delay_s), o.waypoints) for o in obs])
    t = np.linspace(0.0, 80.0, 801)
    for m, o in enumerate(obs):
        compiled = np.array([obstacle_position(m, tt, world.mo_par, world.mo_pts, world.mo_cum, world.mo_n) for tt in t])
        assert np.abs(compiled - o.position(t)).max() < 1e-12, o.repeat

def test_a_path_into_a_block_ends_in_a_collision():
    run = simulate_run([[0.3, 0.55, 0.0], [1.5, 0.55, 0.0]], (0.3, 0.55, 0.0), seed=1, blocks=BLOCKS)
    assert run.outcome == "COLLISION" and run.t_end > run.t_start
    assert 0.6 < run.poses[-1, 1] < 0.8  # it stopped at the block


def test_max_s_ends_a_run_that_goes_on():
    run = simulate_run(densify(CORNERS), (0.3, 0.3, 0.0), seed=1, max_s=2.0)
    assert run.outcome == "TIMEOUT_SIM" and run.t_end is None and run.poses[-1, 0] <= 2.0 + 1e-9


def test_a_start_touching_a_block_is_refused_as_an_agent_refuses_it():
    with pytest.raises(PlacementRefused, match="touch a block"):
        simulate_run([[0.9, 0.55, 0.0], [1.5, 0.3, 0.0]], (0.86, 0.55, 0.0), seed=1, blocks=BLOCKS)
