"""Replays (client_sdk.study.replay_animation): every robot of a fleet and every moving obstacle is drawn where
it was at the frame's time, read back from the saved GIF's pixels (`twb replay`: docs/sdk.md, "Job commands")."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.animation import PillowWriter
from matplotlib.colors import to_rgb
from PIL import Image

from client_sdk.study import replay_animation
from planners import load_environment
from planners.moving import positions
from robot_agent.engine.fleet import simulate_fleet
from robot_agent.engine.run_data import block_tuples, moving_tuples

DPI = 60
CORNERS = [[0.3, 0.3, 0.0], [1.5, 0.3, np.pi / 2], [1.5, 1.5, np.pi], [0.3, 1.5, -np.pi / 2]]


def frames(anim, fig, path, fps: int) -> list[np.ndarray]:
    """The GIF's frames as RGB arrays."""
    anim.save(path, writer=PillowWriter(fps=fps), dpi=DPI)
    out = []
    with Image.open(path) as im:
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB"), dtype=float))
    return out


def pixel(fig, xy) -> tuple[int, int]:
    """The image row and column of world point ``xy`` (m) in a frame saved at DPI."""
    ax = fig.axes[0]
    px, py = ax.transData.transform(xy) * (DPI / fig.dpi)
    height = fig.get_size_inches()[1] * DPI
    return int(round(height - py)), int(round(px))


def near(img, rc, rgb, tol: float = 60.0, box: int = 2) -> bool:
    """Some pixel within ``box`` of ``rc`` is within ``tol`` of colour ``rgb`` (0-255)."""
    r, c = rc
    patch = img[max(r - box, 0):r + box + 1, max(c - box, 0):c + box + 1]
    return bool((np.abs(patch - np.asarray(rgb)).max(axis=-1) < tol).any())


def test_a_fleet_replay_draws_every_robot_in_its_own_colour_where_it_was(tmp_path):
    goals = [CORNERS[2], CORNERS[3], CORNERS[0], CORNERS[1]]
    paths = [np.array([s, [g[0], g[1], s[2]]]) for s, g in zip(CORNERS, goals)]
    fleet = simulate_fleet(paths, CORNERS, seed=3, area=(1.8, 1.8))  # uncoordinated: they meet in the middle
    env = {"name": "swap", "size": [1.8, 1.8], "blocks": []}
    poses = [r.poses for r in fleet.runs]
    fig, anim, n = replay_animation(env, poses, planned=paths, fps=5, speed=2.0, max_frames=12)
    imgs = frames(anim, fig, tmp_path / "fleet.gif", 5)
    assert n - 3 <= len(imgs) <= n  # the GIF merges the identical frames that hold the end
    alpha_mix = lambda c: 0.6 * np.array(to_rgb(c)) * 255 + 0.4 * 255  # noqa: E731 - a disc at alpha 0.6 on white
    for i, p in enumerate(poses):  # first frame: each robot's disc at its start, in its colour
        assert near(imgs[0], pixel(fig, p[0, 1:3]), alpha_mix(f"C{i}")), f"robot {i} not at its start"
        assert not near(imgs[0], pixel(fig, p[0, 1:3]), alpha_mix(f"C{(i + 1) % 4}"))
    for i, p in enumerate(poses):  # last frame: where each stopped
        assert near(imgs[-1], pixel(fig, p[-1, 1:3]), alpha_mix(f"C{i}"), box=3), f"robot {i} not where it stopped"


def test_a_replay_moves_the_obstacles_on_their_clock(tmp_path):
    env = load_environment("crossing")
    data = env.to_dict()
    plan = env.plan("A")
    start = [*plan.start[:2], 0.0]
    path = np.array([start, [plan.goal[0], plan.goal[1], 0.0]])
    run = simulate_fleet([path], [start], seed=1, blocks=block_tuples(data), moving=moving_tuples(data),
                         area=env.size).runs[0]
    fig, anim, n = replay_animation(data, run.poses, planned=path, fps=4, speed=2.0, max_frames=500,
                                    obstacle_t0=run.t_start)
    imgs = frames(anim, fig, tmp_path / "crossing.gif", 4)
    t0 = float(run.poses[0, 0])
    k = min(6, n - 3)
    t = t0 + k * 2.0 / 4  # frame k shows experiment time t0 + k * speed / fps
    centres = positions(env.moving_obstacles, np.array([t - run.t_start]))[:, 0]
    grey = 0.8 * np.array(to_rgb("#7f7f7f")) * 255 + 0.2 * 255
    for m, c in enumerate(centres):
        assert near(imgs[k], pixel(fig, c), grey, tol=50, box=3), f"obstacle {m} not at {c} in frame {k}"
    # and it moved: frame 0 has it elsewhere
    first = positions(env.moving_obstacles, np.array([t0 - run.t_start]))[:, 0]
    assert np.hypot(*(first[0] - centres[0])) > 0.05


def test_a_replay_of_nothing_is_refused():
    with pytest.raises(ValueError, match="no pose"):
        replay_animation({"name": "e", "size": [1.8, 1.8], "blocks": []}, [np.zeros((0, 4))])
