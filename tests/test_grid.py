import numpy as np
import pytest

from planners import config_space, distance_to_obstacles, grid_map, load_environment, parse_environment
from planners.geometry import signed_distance_to_blocks


@pytest.mark.parametrize("name", ["room", "blocks"])
def test_rasterisation_marks_exactly_the_cells_whose_centre_is_in_a_block(name):
    env = load_environment(name)
    g = grid_map(env, 0.01)
    ny, nx = g.shape
    assert (ny, nx) == (180, 180)
    iy, ix = np.mgrid[0:ny, 0:nx]
    centres = g.cell_centres(iy.ravel(), ix.ravel())
    inside = signed_distance_to_blocks(env, centres) <= 0
    assert np.array_equal(g.obstacle.ravel(), inside)


@pytest.mark.parametrize("res", [0.01, 0.02])
def test_clearance_is_the_exact_distance_within_one_cell(res):
    env = load_environment("blocks")
    g = grid_map(env, res)
    iy, ix = np.nonzero(~g.obstacle)
    exact = distance_to_obstacles(env, g.cell_centres(iy, ix))
    err = g.clearance[iy, ix] - exact
    assert np.abs(err).max() <= res
    assert np.abs(err).mean() <= res / 2
    assert g.clearance[g.obstacle].max() == 0


def test_config_space_dilates_by_the_radius_and_is_cached():
    env = load_environment("room")
    space = config_space(env, 0.045)
    assert config_space(env, 0.045) is space
    # a cell is free exactly when its centre is at least the radius from every obstacle
    for name in ("room", "blocks"):
        s = config_space(load_environment(name), 0.045)
        iy, ix = np.mgrid[0:180, 0:180]
        exact = distance_to_obstacles(s.env, s.grid.cell_centres(iy.ravel(), ix.ravel()))
        assert np.array_equal(s.free.ravel(), exact >= 0.045)
    with pytest.raises(ValueError, match="`robot_radius` must be a finite number >= 0"):
        config_space(env, float("nan"))
    with pytest.raises(ValueError, match="`resolution` must be a finite number > 0"):
        grid_map(env, 0.0)
    with pytest.raises(ValueError, match="at most"):
        grid_map(env, 1e-5)


def test_point_and_segment_queries():
    env = parse_environment({"name": "e", "size": [1, 1], "blocks": [{"x": 0.5, "y": 0.5, "w": 0.2, "h": 0.2}]})
    space = config_space(env, 0.05, 0.01)
    pts = np.array([[0.2, 0.2], [0.5, 0.5], [0.5, 0.36], [-0.1, 0.5], [np.nan, 0.5], [1.0, 0.2]])
    assert space.is_free(pts).tolist() == [True, False, False, False, False, False]
    a = np.array([[0.2, 0.2], [0.2, 0.2], [0.2, 0.5], [0.2, 0.2]])
    b = np.array([[0.8, 0.2], [0.8, 0.8], [0.8, 0.5], [1.5, 0.2]])
    assert space.segments_free(a, b).tolist() == [True, False, False, False]
    assert space.segments_free(np.zeros((0, 2)), np.zeros((0, 2))).shape == (0,)


def test_segments_free_is_exact_against_a_very_dense_check():
    env = load_environment("blocks")
    space = config_space(env, 0.045, 0.01)
    rng = np.random.default_rng(7)
    a = rng.random((600, 2)) * 1.8
    b = np.clip(a + rng.normal(0, 0.15, (600, 2)), 0, 1.8)
    keep = space.is_free(a) & space.is_free(b)
    a, b = a[keep], b[keep]
    got = space.segments_free(a, b)
    ref = []
    for p, q in zip(a, b):
        n = int(np.ceil(np.hypot(*(q - p)) / 1e-5)) + 1  # 0.01 mm: only exact corner grazes could differ
        ref.append(space.is_free(p + (q - p) * np.linspace(0, 1, n)[:, None]).all())
    assert got.tolist() == ref
    assert 0 < sum(ref) < len(ref)


def test_pieces_of_a_free_segment_are_free():
    space = config_space(load_environment("room"), 0.045, 0.01)
    rng = np.random.default_rng(3)
    a = rng.random((3000, 2)) * 1.8
    b = a + rng.normal(0, 0.3, (3000, 2))
    ok = space.segments_free(a, b)
    a, b = a[ok], b[ok]
    cuts = rng.random((len(a), 2))
    cuts.sort(axis=1)
    p, q = a + (b - a) * cuts[:, :1], a + (b - a) * cuts[:, 1:]
    assert space.segments_free(p, q).all()
    assert space.segments_free(a, p).all() and space.segments_free(q, b).all()


def test_diagonal_through_a_grid_vertex_does_not_touch_the_corner_cells():
    env = parse_environment({"name": "v", "size": [0.1, 0.1]})
    space = config_space(env, 0.0, 0.01)
    free = space.free.copy()
    free[5, 4] = free[4, 5] = False  # the two cells that only touch the vertex (0.05, 0.05)
    from planners.grid import ConfigSpace

    s = ConfigSpace(space.grid, 0.0, free)
    assert s.segments_free(np.array([[0.045, 0.045]]), np.array([[0.055, 0.055]])).tolist() == [True]
    assert s.segments_free(np.array([[0.045, 0.045]]), np.array([[0.055, 0.0551]])).tolist() == [False]
