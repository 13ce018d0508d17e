"""A run as a function call (robot_agent.headless) equals the same run sent to an agent over TCP."""

from __future__ import annotations

import math

import numpy as np
import pytest
from agent_support import LineClient, densify, CORNERS, running_agents

from robot_agent.frames import FIELD_SIZE
from robot_agent.headless import PlacementRefused, simulate_run
from robot_agent.protocol import encode_build, encode_path, encode_place, format_event

BLOCKS = [(0.9, 0.55, 0.3, 0.1, 0.2)]


async def over_tcp(path: np.ndarray, start, seed: int, blocks) -> tuple[np.ndarray, list[str]]:
    async with running_agents(backend="ideal", world="separate", area=FIELD_SIZE) as agents:
        c = await LineClient.connect(agents.ports[0])
        await c.ask(encode_build(blocks))
        await c.ask(encode_place(start))
        agents.set_path_seed(agents.robots[0].robot_id, seed)
        await c.ask(encode_path(path))
        lines = await c.until("EV,DONE", "EV,FAIL", timeout=60)
        await agents.flush_tracker()
        poses = agents.sink.poses(agents.robots[0].robot_id)
        await c.close()
    return poses, [line for line in c.stash + lines if line.startswith("EV,")]


@pytest.mark.parametrize("blocks", [[], BLOCKS])
async def test_a_headless_run_equals_the_same_run_over_tcp(blocks):
    path = densify(CORNERS)
    start = (0.3, 0.3, 0.0)
    tcp_poses, tcp_events = await over_tcp(path, start, 7, blocks)
    run = simulate_run(path, start, seed=7, blocks=blocks)
    t0_tcp = float(next(line for line in tcp_events if line.startswith("EV,START")).split(",")[-1])
    assert run.t_start == 0.0 or math.isclose(run.t_start, run.poses[0, 0], abs_tol=1e-9)
    mine = run.poses[:, 1:]
    theirs = tcp_poses[tcp_poses[:, 0] >= t0_tcp - 1e-9][:, 1:]
    assert mine.shape == theirs.shape and np.abs(mine - theirs).max() < 1e-12
    shift = t0_tcp - run.t_start
    assert [format_event(e.kind, 0.0, index=e.index, reason=e.reason).rsplit(",", 1)[0] for e in run.events] == \
        [line.rsplit(",", 1)[0] for line in tcp_events]
    assert [round(e.t + shift, 6) for e in run.events] == [round(float(line.split(",")[-1]), 6) for line in tcp_events]
    assert run.outcome == ("DONE" if not blocks else run.outcome)


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
