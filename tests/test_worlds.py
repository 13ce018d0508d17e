"""Generated world sets (planners/worlds.py, `twb worlds generate`): every world solvable by FMM, the same
seed the same world, the grid's blocks the grid, the automaton's rule, and the difficulty metrics on maps
whose values are known."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from planners.api import plan_path
from planners.environment import load_environment, parse_environment
from planners.worlds import (
    GOAL,
    START,
    block_grid,
    cave_grid,
    difficulty,
    generate_world,
    generate_worlds,
    grid_blocks,
    point_metrics,
)

# a corridor 0.3 m wide along x at y = 0.9, from wall to wall
CORRIDOR = parse_environment({"name": "corridor", "size": [1.8, 1.8], "blocks": [
    {"x": 0.9, "y": 0.375, "w": 1.8, "h": 0.75, "angle": 0.0},
    {"x": 0.9, "y": 1.425, "w": 1.8, "h": 0.75, "angle": 0.0}]})


@pytest.mark.parametrize("kind", ["cave", "blocks"])
def test_generated_worlds_are_solvable_by_fmm(kind: str) -> None:
    worlds = generate_worlds(3, 100, kind=kind)
    for w in worlds:
        env = w.environment
        assert env.blocks and env.plan("A").start == pytest.approx(START) and env.plan("A").goal == pytest.approx(GOAL)
        again = load_environment(json.loads(json.dumps(env.to_dict())))  # as the stored file gives it back
        plan = plan_path(again, START, GOAL, "fmm", robot_radius=0.045, planning_margin=0.02)
        assert plan.length_m >= math.dist(START[:2], GOAL[:2]) - 1e-9
        assert w.difficulty.tortuosity >= 1.0 and w.difficulty.distance_to_obstacle_m > 0.045 + 0.02 - 0.01
    assert len({json.dumps(w.environment.to_dict()["blocks"]) for w in worlds}) == 3


def test_the_same_seed_gives_the_same_world() -> None:
    a, b, c = generate_world(7), generate_world(7), generate_world(8)
    assert a.environment.to_dict() == b.environment.to_dict() and a.difficulty == b.difficulty
    assert a.environment.to_dict()["blocks"] != c.environment.to_dict()["blocks"]


def test_grid_blocks_cover_exactly_the_grid() -> None:
    grid = block_grid(np.random.default_rng(3), 30, 25)
    env = parse_environment({"name": "g", "size": [1.8, 1.8], "blocks": grid_blocks(grid, 0.06)})
    centres = (np.arange(30) + 0.5) * 0.06
    xx, yy = np.meshgrid(centres, centres)
    from planners.geometry import distance_to_obstacles

    inside = distance_to_obstacles(env, np.column_stack([xx.ravel(), yy.ravel()])).reshape(30, 30) == 0.0
    assert np.array_equal(inside, grid)
    assert len(env.blocks) < grid.sum()  # runs merged


def test_the_automaton_follows_the_4_5_rule() -> None:
    rng = np.random.default_rng(0)
    assert not cave_grid(rng, 10, 0.0, 3).any() and cave_grid(rng, 10, 1.0, 3)[1:-1, 1:-1].all()
    lone = np.zeros((10, 10), dtype=bool)
    lone[5, 5] = True

    class Fixed:  # a generator that draws the lone cell
        def random(self, shape):
            return np.where(lone, 0.0, 1.0)

    assert not cave_grid(Fixed(), 10, 0.5, 1).any()  # no neighbours: emptied
    assert np.array_equal(cave_grid(Fixed(), 10, 0.5, 0), lone)


def test_metrics_of_a_point_in_a_corridor() -> None:
    m = point_metrics(CORRIDOR, np.array([[0.9, 0.9]]), rays=32, ray_range=0.6, resolution=0.01)
    assert m["distance_to_obstacle_m"][0] == pytest.approx(0.15)
    assert m["characteristic_dimension_m"][0] == pytest.approx(0.30, abs=0.02)  # across the corridor
    ang = 2 * math.pi * np.arange(32) / 32
    with np.errstate(divide="ignore"):
        exact = np.minimum(0.6, 0.15 / np.abs(np.sin(ang)))
    assert m["visibility_m"][0] == pytest.approx(exact.mean(), abs=0.011)
    assert m["dispersion"][0] == 4  # two openings: along the corridor both ways


def test_metrics_of_a_point_in_the_open_and_at_a_wall() -> None:
    empty = parse_environment({"name": "empty", "size": [1.8, 1.8]})
    m = point_metrics(empty, np.array([[0.9, 0.9], [0.05, 0.9]]), ray_range=0.6)
    assert m["distance_to_obstacle_m"] == pytest.approx([0.9, 0.05])
    assert m["visibility_m"][0] == pytest.approx(0.6) and m["dispersion"][0] == 0
    assert m["characteristic_dimension_m"][0] == pytest.approx(1.2)
    assert m["dispersion"][1] == 2  # one opening: away from the wall
    assert m["characteristic_dimension_m"][1] == pytest.approx(0.05 + 0.6, abs=0.011)


def test_tortuosity_of_straight_and_bent_paths() -> None:
    straight = np.array([[0.2, 0.9], [1.6, 0.9]])
    d = difficulty(CORRIDOR, straight)
    assert d.tortuosity == pytest.approx(1.0) and d.distance_to_obstacle_m == pytest.approx(0.15)
    empty = parse_environment({"name": "empty", "size": [1.8, 1.8]})
    bent = np.array([[0.3, 0.3], [1.5, 0.3], [1.5, 1.5]])
    assert difficulty(empty, bent).tortuosity == pytest.approx(2.4 / math.hypot(1.2, 1.2))


def test_bad_arguments_name_the_parameter() -> None:
    with pytest.raises(ValueError, match="`kind` must be one of cave, blocks"):
        generate_world(0, kind="maze")
    with pytest.raises(ValueError, match="`count` must be an integer in"):
        generate_worlds(0, 0)
    with pytest.raises(ValueError, match="`rays` must be an even integer"):
        point_metrics(CORRIDOR, np.zeros((1, 2)), rays=5)


def test_twb_worlds_generate(tmp_path: Path) -> None:
    out = tmp_path / "set"
    run = subprocess.run([sys.executable, "-m", "twb", "worlds", "generate", "--count", "2", "--seed", "4",
                          "--test-fraction", "0.5", "--out", str(out)], check=False, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    index = json.loads((out / "index.json").read_text())
    assert [w["name"] for w in index["worlds"]] == ["cave-4-000", "cave-4-001"]
    assert sorted(w["split"] for w in index["worlds"]) == ["test", "train"]
    for w in index["worlds"]:
        env = load_environment(out / w["file"])
        assert env.name == w["name"] and set(w["difficulty"]) == {
            "distance_to_obstacle_m", "visibility_m", "dispersion", "characteristic_dimension_m", "tortuosity"}
        assert env.to_dict()["blocks"] == generate_world(w["seed"], name=w["name"]).environment.to_dict()["blocks"]
    bad = subprocess.run([sys.executable, "-m", "twb", "worlds", "generate", "--count", "0"], check=False, capture_output=True,
                         text=True, timeout=120)
    assert bad.returncode != 0 and "--count must be in [1, 10000]" in bad.stderr and "Traceback" not in bad.stderr
