import math

import numpy as np
import pytest

from planners import distance_to_obstacles, load_environment, parse_environment, signed_distance_to_blocks
from planners.geometry import block_corners


def brute_force_distance(env, pts, n=4000):
    """Distance to the densely sampled outline of every block and wall (outside points only)."""
    outline = []
    for c in block_corners(env):
        for a, b in zip(c, np.roll(c, -1, axis=0)):
            t = np.linspace(0, 1, n)[:, None]
            outline.append(a + (b - a) * t)
    w, h = env.size
    for a, b in (((0, 0), (w, 0)), ((w, 0), (w, h)), ((w, h), (0, h)), ((0, h), (0, 0))):
        a, b = np.array(a, float), np.array(b, float)
        outline.append(a + (b - a) * np.linspace(0, 1, n)[:, None])
    outline = np.vstack(outline)
    return np.min(np.hypot(pts[:, None, 0] - outline[None, :, 0], pts[:, None, 1] - outline[None, :, 1]), axis=1)


@pytest.mark.slow
def test_exact_distances_match_a_dense_outline_on_random_points():
    env = load_environment("blocks")  # includes a block turned 45 degrees
    rng = np.random.default_rng(1)
    pts = rng.random((300, 2)) * 1.8
    inside = signed_distance_to_blocks(env, pts) < 0
    d = distance_to_obstacles(env, pts)
    ref = brute_force_distance(env, pts)
    assert np.all(d[inside] == 0)
    np.testing.assert_allclose(d[~inside], ref[~inside], atol=1e-3)


def test_rotated_block_analytic_values():
    env = parse_environment({"name": "r", "size": [2, 2], "blocks": [{"x": 1, "y": 1, "w": 0.2, "h": 0.2, "angle": math.pi / 4}]})
    # the turned square's corner points along +x at distance 0.1*sqrt(2) from its centre
    corner_x = 1 + 0.1 * math.sqrt(2)
    pts = np.array([[corner_x + 0.3, 1.0], [1.0, 1.0], [1.0, 1.0 + 0.1 * math.sqrt(2) + 0.05]])
    sd = signed_distance_to_blocks(env, pts)
    assert sd[0] == pytest.approx(0.3)
    assert sd[1] == pytest.approx(-0.1)
    assert sd[2] == pytest.approx(0.05)
    # walls count: a point 0.02 m from the left wall
    assert distance_to_obstacles(env, np.array([[0.02, 1.0]]))[0] == pytest.approx(0.02)
    # outside the field is 0
    assert distance_to_obstacles(env, np.array([[-0.5, 1.0]]))[0] == 0


def test_empty_environment_and_bad_shapes():
    env = parse_environment({"name": "e", "size": [1, 2]})
    assert np.isinf(signed_distance_to_blocks(env, np.zeros((3, 2)) + 0.5)).all()
    assert distance_to_obstacles(env, np.array([[0.5, 1.0]]))[0] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="`points` must have shape"):
        distance_to_obstacles(env, np.zeros(3))
