"""Plug-in planners through the real entry-point mechanism (a distribution on sys.path)."""

import json
import sys
import textwrap

import numpy as np
import pytest

from planners import PlanningError, UnknownPlanner, available_planners, get_planner, plan_path, register_planner
from planners import registry

PLUGIN = textwrap.dedent(
    '''
    import numpy as np
    from planners import NoPathFound, Planner

    class StraightLine(Planner):
        """Straight segment from start to goal; fails if it is blocked."""
        name = "straight"
        description = "straight segment"
        defaults = {"extra": 0.0}

        def solve(self, space, start, goal, params, seed):
            path = np.array([start, goal])
            if not space.path_free(path):
                raise NoPathFound("the straight segment is blocked")
            return path

    def through_walls(space, start, goal, params, seed):
        """A buggy planner that ignores obstacles."""
        return np.array([start, [0.9, 0.9], goal])

    def broken_import():
        raise RuntimeError("never called")
    '''
)


@pytest.fixture
def plugin_dist(tmp_path, monkeypatch):
    """Install a tiny distribution declaring three planners in the entry-point group."""
    (tmp_path / "twb_test_plugin.py").write_text(PLUGIN)
    info = tmp_path / "twb_test_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: twb-test-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[teleworkbench.planners]\n"
        "straight = twb_test_plugin:StraightLine\n"
        "through_walls = twb_test_plugin:through_walls\n"
        "broken = twb_test_plugin_missing:thing\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in ("straight", "through_walls", "broken"):
        registry._instances.pop(name, None)
    sys.modules.pop("twb_test_plugin", None)


def test_entry_point_planner_is_selected_by_name_like_a_builtin(plugin_dist):
    assert "straight" in available_planners()
    r = plan_path("room", (0.3, 0.3, 0), (0.6, 0.5, 0), "straight")
    assert r.planner == "straight"
    assert len(r.raw_path) == 2
    assert r.length_m == pytest.approx(np.hypot(0.3, 0.2))
    with pytest.raises(PlanningError, match="the straight segment is blocked"):
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "straight")
    with pytest.raises(PlanningError, match="has no parameter 'samples'"):
        plan_path("room", (0.3, 0.3), (0.6, 0.5), "straight", params={"samples": 3})


def test_a_plugin_path_through_an_obstacle_is_refused(plugin_dist):
    with pytest.raises(PlanningError, match=r"planner 'through_walls' returned a path whose segment 0 .* enters an obstacle"):
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "through_walls")


def test_a_broken_plugin_gives_a_clear_error(plugin_dist):
    with pytest.raises(UnknownPlanner, match=r"plug-in planner 'broken' .* failed to load: No module named"):
        get_planner("broken")


def test_plugin_from_the_command_line(plugin_dist, twb):
    env = {"PYTHONPATH": str(plugin_dist)}
    out = twb("plan", "--env", "room", "--start", "0.3,0.3", "--goal", "0.6,0.5", "--planner", "straight", env=env)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["planner"] == "straight"
    listing = twb("planners", env=env)
    assert "straight" in listing.stdout


def test_register_planner_in_process():
    def diagonal(space, start, goal, params, seed):
        return np.array([start, goal])

    try:
        register_planner("diag", diagonal)
        assert plan_path("room", (0.3, 0.3), (0.5, 0.5), "diag").planner == "diag"
        with pytest.raises(ValueError, match="built-in planner and cannot be replaced"):
            register_planner("fmm", diagonal)
    finally:
        registry._instances.pop("diag", None)
