import numpy as np
import pytest

from planners import config_space, parse_environment
from planners.postprocess import headings, postprocess, simplify, trim


def point_to_polyline(p, poly):
    a, b = poly[:-1], poly[1:]
    ab = b - a
    t = np.clip(((p[:, None] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1), 0, 1)
    proj = a[None] + t[..., None] * ab[None]
    return np.hypot(*(p[:, None] - proj).transpose(2, 0, 1)).min(axis=1)


def test_simplify_keeps_every_point_within_tolerance_and_the_ends():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, 500)
    raw = np.column_stack([t, np.sin(t) * 0.5]) + rng.normal(0, 0.0005, (500, 2))
    idx = simplify(raw, 0.005)
    assert idx[0] == 0 and idx[-1] == 499
    assert 8 < len(idx) < 100
    assert point_to_polyline(raw, raw[idx]).max() <= 0.005 + 1e-12


def test_collinear_points_collapse_to_the_ends():
    raw = np.column_stack([np.linspace(0, 1, 50), np.zeros(50)])
    assert simplify(raw, 0.001).tolist() == [0, 49]


def test_collision_aware_simplification_does_not_cut_corners():
    env = parse_environment({"name": "c", "size": [1, 1], "blocks": [{"x": 0.5, "y": 0.5, "w": 0.3, "h": 0.3}]})
    space = config_space(env, 0.0, 0.01)
    # a path around the block's lower-right corner with a small dent that a large tolerance would cut
    raw = np.array([[0.1, 0.3], [0.66, 0.34], [0.7, 0.9]])
    assert not space.segments_free(raw[:1], raw[2:])[0]
    assert simplify(raw, 10.0).tolist() == [0, 2]
    assert simplify(raw, 10.0, space).tolist() == [0, 1, 2]


def test_trim_keeps_corners_and_bounds_spacing():
    corners = np.array([[0, 0], [1, 0], [1, 0.25], [1, 0.25], [0.3, 0.25]])
    out = trim(corners, 0.1)
    steps = np.hypot(*np.diff(out, axis=0).T)
    assert steps.max() <= 0.1 + 1e-12
    assert steps.min() > 0  # the repeated corner is dropped
    for c in corners:
        assert np.hypot(*(out - c).T).min() == 0
    # spacing is uniform on each segment: 1 m in 10 pieces, 0.25 m in 3, 0.7 m in 7
    assert len(out) == 10 + 3 + 7 + 1
    with pytest.raises(ValueError, match="`max_spacing` must be"):
        trim(corners, 0)


def test_headings_face_the_next_point_and_end_at_the_goal_heading():
    p = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    h = headings(p, final_heading=3.0)
    assert h[:, 2].tolist() == pytest.approx([0, np.pi / 2, np.pi, 3.0])
    assert headings(p)[-1, 2] == pytest.approx(np.pi)
    assert headings(p[:1], 1.0)[0, 2] == 1.0


def test_postprocess_pipeline():
    raw = np.column_stack([np.linspace(0, 1, 101), np.zeros(101)])
    out = postprocess(raw, space=None, max_spacing=0.25, final_heading=1.0)
    assert out.shape == (5, 3)
    assert out[:, 0].tolist() == pytest.approx([0, 0.25, 0.5, 0.75, 1.0])
    assert out[-1, 2] == 1.0
