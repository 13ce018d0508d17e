"""The Gymnasium environments (robot_agent/gym, docs/gymnasium.md): registration through the entry point,
Gymnasium's own checker, a seeded rollout equal to the engine's own run, reproducibility, the vector
environment equal to one environment per robot, the local occupancy against its definition, and the
scripted policy of examples/gym as Gymnasium policy and as a controller program on a robot port."""

from __future__ import annotations

import asyncio
import importlib.metadata
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

from gymnasium.utils.env_checker import check_env

from contract.params import robot_params
from contract.protocol import encode_build, encode_place
from planners.environment import load_environment
from robot_agent.engine.cores import layout_core
from robot_agent.gym import ENV_IDS, register_envs
from robot_agent.gym.envs import NavigationEnv, NavigationVectorEnv
from robot_agent.gym.maps import build_map

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "gym"
sys.path.insert(0, str(EXAMPLES))
from go_to_goal import GoToGoal, occupancy

# one block in the middle of an empty sub-field: the policy must go round it
ONE_BLOCK = {"name": "one-block", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.2, "h": 0.2, "angle": 0.3}]}


def random_actions(space: gymnasium.spaces.Box, steps: int, seed: int) -> list[np.ndarray]:
    space.seed(seed)
    return [space.sample() for _ in range(steps)]


# ---------------------------------------------------------------------------------------- registration, checker


def test_the_entry_point_registers_the_environments() -> None:
    eps = [ep for ep in importlib.metadata.entry_points(group="gymnasium.envs") if ep.name == "Teleworkbench"]
    assert len(eps) == 1 and eps[0].value == "robot_agent.gym:register_envs"
    eps[0].load()()  # what Gymnasium < 1.0 does on import; again is a no-op
    register_envs()
    for env_id in ENV_IDS:
        env = gymnasium.make(env_id)
        assert isinstance(env.unwrapped, NavigationEnv)
        env.close()
    vec = gymnasium.make_vec("Teleworkbench/NavigateIdeal-v0", num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(vec, NavigationVectorEnv) and vec.fleet.backend == "ideal"


@pytest.mark.parametrize("backend", ["field", "ideal"])
def test_check_env(backend: str) -> None:
    check_env(NavigationEnv(backend=backend), skip_render_check=True)


def test_bad_arguments_name_the_parameter() -> None:
    with pytest.raises(ValueError, match="`frame_skip` must be an integer >= 1"):
        NavigationEnv(frame_skip=0)
    with pytest.raises(ValueError, match="`occupancy_cell_m` must be > 0"):
        NavigationEnv(occupancy_cell_m=-1.0)
    with pytest.raises(ValueError, match="moving obstacles"):
        NavigationEnv(["crossing"])
    with pytest.raises(ValueError, match="unknown reset options"):
        NavigationEnv().reset(seed=0, options={"speed": 1})
    with pytest.raises(ValueError, match="`start` .* is not free"):
        NavigationEnv(["room"]).reset(seed=0, options={"start": [0.9, 0.45]})


# ---------------------------------------------------------------------------------------- the engine's own run


def engine_run(env: NavigationEnv, actions: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """The same episode run on a SimCore of its own, as a robot agent runs a T,T,V drive: blocks built,
    robot placed, one ``drive`` per step, ``frame_skip`` control steps each; (pose, belief, state) per step."""
    fleet = env.fleet
    nav = fleet.maps[int(fleet.map_of[0])]
    p = robot_params("bebot")
    core = layout_core(p, fleet.backend, 1, "separate", nav.size)
    core.world.set_blocks(0, nav.blocks)
    start = env.start
    core.place(0, (float(start[0]), float(start[1]), float(start[2])))
    out = []
    for a in actions:
        core.drive(0, float(a[0]), float(a[1]), int(fleet.keys[0]), 10.0)
        core.advance(fleet.config.frame_skip)
        out.append((core.backend.pose[0].copy(), core.backend.belief[0].copy(), int(core.state[0])))
    return out


@pytest.mark.parametrize("backend", ["field", "ideal"])
def test_a_seeded_rollout_is_the_engines_own_run(backend: str, monkeypatch: pytest.MonkeyPatch) -> None:
    env = NavigationEnv(["room"], backend=backend, max_episode_steps=10_000)
    starts = []
    real_reset = env.fleet.reset_robots

    def keep_start(rows, rngs, options=None):  # the drawn start, before the robot moves
        real_reset(rows, rngs, options)
        starts.append(env.fleet.core.backend.pose[0].copy())

    monkeypatch.setattr(env.fleet, "reset_robots", keep_start)
    env.reset(seed=11)
    env.start = starts[-1]
    actions = random_actions(env.action_space, 150, seed=5)
    ours = []
    for a in actions:
        obs, _, terminated, _, _info = env.step(a)
        ours.append((env.fleet.core.backend.pose[0].copy(), env.fleet.core.backend.belief[0].copy(),
                     int(env.fleet.core.state[0])))
        assert np.array_equal(obs["pose"][:2], env.fleet.core.backend.belief[0, :2].astype(np.float32))
        if terminated:
            break
    theirs = engine_run(env, actions[:len(ours)])
    for (p1, b1, s1), (p2, b2, s2) in zip(ours, theirs):
        assert np.array_equal(p1, p2) and np.array_equal(b1, b2) and s1 == s2
    assert not np.array_equal(ours[0][0], ours[-1][0])  # it moved


def test_a_collision_ends_the_episode_as_the_engine_fails_the_drive() -> None:
    env = NavigationEnv(["room"], backend="field", max_episode_steps=10_000)
    env.reset(seed=0, options={"start": [0.3, 0.6, 0.0], "goal": [1.5, 0.3]})  # facing the wall at x = 0.87
    for t in range(200):
        _obs, reward, terminated, _truncated, info = env.step(np.array([0.2, 0.0], dtype=np.float32))
        if terminated:
            break
    assert terminated and info["collided"] and not info["reached"] and reward < -9
    x = float(env.fleet.core.backend.pose[0, 0])
    assert abs(x - (0.87 - 0.04)) < 0.2 * 0.02 + 1e-9  # within a step's travel of the wall's collision radius


# ---------------------------------------------------------------------------------------- reproducibility


@pytest.mark.parametrize("backend", ["field", "ideal"])
def test_same_seed_same_episode_bit_for_bit(backend: str) -> None:
    def episode(seed: int) -> list:
        env = NavigationEnv(backend=backend, max_episode_steps=40)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for a in random_actions(env.action_space, 100, seed=1):
            obs, r, te, tr, _ = env.step(a)
            out.append((obs, r, te, tr))
            if te or tr:
                obs, _ = env.reset()  # the next episode from the same generator
                out.append(obs)
        return out

    a, b, c = episode(3), episode(3), episode(4)
    assert repr(a) == repr(b)
    assert repr(a) != repr(c)


def test_the_vector_env_runs_what_one_env_per_robot_runs() -> None:
    n, steps = 4, 120
    vec = NavigationVectorEnv(n, backend="field", max_episode_steps=25)  # episodes end: autoresets happen
    obs, _ = vec.reset(seed=20)
    rng = np.random.default_rng(2)
    actions = rng.uniform(-1, 1, (steps, n, 2)).astype(np.float32) * vec.single_action_space.high
    vec_obs, vec_rew, vec_end, vec_pose = [obs], [], [], []
    for a in actions:
        obs, r, te, tr, _ = vec.step(a)
        vec_pose.append(vec.fleet.core.backend.pose.copy())
        vec_obs.append(obs)
        vec_rew.append(r)
        vec_end.append(te | tr)
    assert np.array(vec_end).sum() >= n  # every robot had at least one episode end on average
    for i in range(n):
        env = NavigationEnv(backend="field", max_episode_steps=25)
        obs, _ = env.reset(seed=20 + i)
        for key in obs:
            assert np.array_equal(obs[key], vec_obs[0][key][i])
        ended = False
        for t, a in enumerate(actions):
            if ended:  # next-step autoreset: this step resets, its action is ignored
                obs, _ = env.reset()
                r, ended = 0.0, False
            else:
                obs, r, te, tr, info = env.step(a[i])
                ended = te or tr
            assert r == vec_rew[t][i] and ended == vec_end[t][i], (i, t)
            assert np.array_equal(env.fleet.core.backend.pose[0], vec_pose[t][i])
            if ended and info["collided"]:
                # the one difference: a robot that collided stands, and one robot alone stops the engine's
                # loop there, while the fleet's others keep its tracker (so its belief) going to the step's end
                continue
            for key in obs:
                assert np.array_equal(obs[key], vec_obs[t + 1][key][i]), (i, t, key)


def test_a_world_set_directory_is_its_environments(tmp_path: Path) -> None:
    from planners.worlds import generate_worlds

    for w in generate_worlds(2, 50):
        (tmp_path / f"{w.environment.name}.json").write_text(json.dumps(w.environment.to_dict()))
    (tmp_path / "index.json").write_text("{}")
    env = NavigationEnv(tmp_path, backend="ideal")
    assert [m.env.name for m in env.fleet.maps] == ["cave-50-000", "cave-50-001"]
    assert [m.env.name for m in NavigationEnv("room").fleet.maps] == ["room"]  # one name, not its letters


def test_the_vector_env_resets_a_mask() -> None:
    vec = NavigationVectorEnv(3, backend="ideal")
    obs0, _ = vec.reset(seed=1)
    obs1, _ = vec.reset(seed=9, options={"reset_mask": [False, True, False]})
    assert np.array_equal(obs0["goal"][0], obs1["goal"][0]) and not np.array_equal(obs0["goal"][1], obs1["goal"][1])


# ---------------------------------------------------------------------------------------- observation


def brute_occupancy(clearance: np.ndarray, res: float, size: tuple[float, float], pose: np.ndarray, k: int,
                    cell: float) -> np.ndarray:
    """The window by its definition, cell by cell in Python."""
    out = np.zeros((k, k), dtype=np.uint8)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    for a in range(k):
        for b in range(k):
            fx, fy = (a + 0.5 - k / 2) * cell, (b + 0.5 - k / 2) * cell
            wx, wy = pose[0] + c * fx - s * fy, pose[1] + s * fx + c * fy
            if not (0 <= wx < size[0] and 0 <= wy < size[1]):
                out[a, b] = 1
            else:
                out[a, b] = clearance[int(wy / res), int(wx / res)] < cell * math.sqrt(0.5)
    return out


def test_occupancy_is_the_window_of_its_definition() -> None:
    env = NavigationEnv(["blocks"], backend="ideal")
    nav = env.fleet.maps[0]
    rng = np.random.default_rng(0)
    mismatched = 0
    for _ in range(30):
        obs, _ = env.reset(seed=int(rng.integers(1000)))
        want = brute_occupancy(nav.clearance, nav.resolution, nav.size, obs["pose"].astype(float), 16, 0.05)
        mismatched += int((obs["occupancy"] != want).sum())  # float32 pose: a cell on a boundary may flip
    assert mismatched <= 3


def test_a_wall_ahead_fills_the_front_of_the_window() -> None:
    env = NavigationEnv([{"name": "empty", "size": [1.8, 1.8]}], backend="ideal")
    obs, _ = env.reset(seed=0, options={"start": [0.2, 0.9, math.pi], "goal": [1.5, 0.9]})  # 0.2 m from x = 0
    occ = obs["occupancy"]
    ahead = (np.arange(16) + 0.5 - 8) * 0.05  # cell centres along the heading
    assert occ[ahead > 0.2 + 0.036].all() and not occ[ahead < 0.2 - 0.036].any()
    # the policy's exact geometry agrees away from the cells the wall's edge passes through
    exact = np.array(occupancy(0.2, 0.9, math.pi, [], (1.8, 1.8)))
    assert np.array_equal(exact, occ)


def test_maps_draw_reachable_starts_and_goals() -> None:
    nav = build_map(load_environment("room"), clearance_m=0.07)
    rng = np.random.default_rng(0)
    from planners.grid import config_space

    space = config_space(load_environment("room"), 0.07, 0.02)
    for _ in range(20):
        a, b = nav.sample_pair(rng, 0.6)
        assert math.hypot(*(a[:2] - b[:2])) >= 0.6
        assert space.is_free(np.array([a[:2], b[:2]])).all()


# ---------------------------------------------------------------------------------------- the scripted policy


def test_the_scripted_policy_goes_round_a_block() -> None:
    env = NavigationEnv([ONE_BLOCK], backend="field")
    policy = GoToGoal()
    obs, _ = env.reset(seed=0, options={"start": [0.3, 0.9, 0.0], "goal": [1.5, 0.9]})
    for _ in range(600):
        obs, _, terminated, truncated, info = env.step(np.array(policy(obs), dtype=np.float32))
        if terminated or truncated:
            break
    assert info["reached"]


def test_the_policy_is_an_uploadable_controller_program(tmp_path: Path) -> None:
    """go_to_goal.py run as a controller program against an emulated robot on a TCP port (a standalone
    agent, as `twb agent` runs it): it drives the robot round the block to the goal with T,T,V."""
    from agent_support import LineClient, running_agents

    env_file = tmp_path / "env.json"
    env_file.write_text(json.dumps(ONE_BLOCK))

    async def main() -> tuple[float, float, str]:
        async with running_agents(backend="field", time_scale=4.0) as host:
            port = host.ports[0]
            setup = await LineClient.connect(port)
            b = ONE_BLOCK["blocks"][0]
            assert (await setup.ask(encode_build([(b["x"], b["y"], b["w"], b["h"], b["angle"])]))).startswith("OK")
            assert (await setup.ask(encode_place((0.3, 0.9, 0.0)))).startswith("OK")
            await setup.close()
            child = await asyncio.create_subprocess_exec(
                sys.executable, str(EXAMPLES / "go_to_goal.py"), stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.STDOUT,
                env={**os.environ, "TWB_ENV_FILE": str(env_file), "TWB_GOAL": "1.5,0.9",
                     "TWB_ROBOT_HOST": "127.0.0.1", "TWB_ROBOT_PORT": str(port)})
            core = host.core
            for _ in range(600):  # until it stands within the goal tolerance, 60 s at most
                await asyncio.sleep(0.1)
                x, y = (float(v) for v in core.backend.pose[0, :2])
                if math.hypot(x - 1.5, y - 0.9) < 0.05 and not core.backend.busy() and child.returncode is None \
                        and np.allclose(core.want[0], 0.0):
                    break
            if child.returncode is None:
                child.kill()
            said = (await child.stdout.read()).decode()  # type: ignore[union-attr]
            await child.wait()
            return x, y, said

    x, y, said = asyncio.run(main())
    assert math.hypot(x - 1.5, y - 0.9) < 0.05, said


# ---------------------------------------------------------------------------------------- the page's examples


def test_the_python_examples_of_docs_gymnasium_run(tmp_path: Path) -> None:
    """Every ``python`` block of docs/gymnasium.md, as written, in a directory with a small world set."""
    import re

    from planners.worlds import generate_worlds

    folder = tmp_path / "worlds-cave-0"
    folder.mkdir()
    index = []
    for i, w in enumerate(generate_worlds(3, 0)):
        (folder / f"{w.environment.name}.json").write_text(json.dumps(w.environment.to_dict()))
        index.append({"file": f"{w.environment.name}.json", "split": "test" if i == 2 else "train"})
    (folder / "index.json").write_text(json.dumps({"worlds": index}))
    page = (ROOT / "docs" / "gymnasium.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", page, flags=re.DOTALL)
    assert len(blocks) >= 3
    for code in blocks:
        run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, check=False, capture_output=True, text=True, timeout=600,
                             env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert run.returncode == 0, f"{code}\n{run.stderr}"


def test_parallel_observations_are_the_same() -> None:
    envs = [NavigationVectorEnv(16, backend="field", parallel=p) for p in (False, True)]
    outs = [e.reset(seed=3)[0] for e in envs]
    acts = np.random.default_rng(0).uniform(-1, 1, (30, 16, 2)).astype(np.float32) * envs[0].single_action_space.high
    for a in acts:
        outs = [e.step(a) for e in envs]
        for key in outs[0][0]:
            assert np.array_equal(outs[0][0][key], outs[1][0][key])
        assert np.array_equal(outs[0][1], outs[1][1])
