"""Plug-in planners through the real entry-point mechanism (a distribution on sys.path)."""

import json
import re
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from planners import PlanningError, UnknownPlanner, available_planners, get_planner, plan_path, register_planner
from planners import registry
from contract import controller_specs

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

    class Creep:
        """A controller plug-in: towards the next waypoint at a crawl."""

        description = "creeps along"

        def __init__(self):
            from contract.controller_specs import Param

            self.params = (Param("speed_m_s", "m/s", 0.08, 0.01, 0.2),)

        def command(self, pose, path, progress, params, dt):
            import math

            j = min(progress[0] + 1, len(path) - 1)
            err = math.remainder(math.atan2(path[j, 1] - pose[1], path[j, 0] - pose[0]) - pose[2], math.tau)
            return params["speed_m_s"] * max(math.cos(err), 0.0), 3.0 * err
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
        "[teleworkbench.controllers]\n"
        "creep = twb_test_plugin:Creep\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in ("straight", "through_walls", "broken"):
        registry._instances.pop(name, None)
    controller_specs._plugins.pop("creep", None)
    sys.modules.pop("twb_test_plugin", None)


def test_entry_point_controller_runs_in_python_like_a_builtin(plugin_dist):
    from robot_agent.engine.headless import simulate_run

    assert "creep" in controller_specs.available_controllers()
    spec = controller_specs.select("creep").spec
    assert not spec.compiled and spec.to_dict()["parameters"][0]["default"] == 0.08
    run = simulate_run([[0.3, 0.3, 0.0], [0.6, 0.3, 0.0]], (0.3, 0.3, 0.0), seed=1, controller="creep")
    assert run.outcome == "DONE" and run.t_end > 0.28 / 0.08  # its crawl, to the goal tolerance


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


# --------------------------------------------------------------------------- twb plugins


EXAMPLE_PLUGIN = Path(__file__).resolve().parents[1] / "examples" / "planner_plugin"


@pytest.fixture
def scratch_venv(tmp_path):
    """A virtualenv without pip that sees this project's environment through a .pth file: `twb plugins install`
    run with its Python must install there, not into the project's .venv."""
    import subprocess
    import sysconfig

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (Path(site) / "_project_env.pth").write_text(f"import site; site.addsitedir({sysconfig.get_path('purelib')!r})\n")
    return python


def _twb_with(python: Path, *args: str, env: dict | None = None):
    import os
    import subprocess

    return subprocess.run([str(python), "-m", "twb", *args], capture_output=True, text=True, timeout=300,
                          env={**os.environ, **(env or {})})


def test_plugins_install_goes_into_the_interpreter_running_twb(scratch_venv, twb):
    import shutil

    if shutil.which("uv") is None:
        pytest.skip("uv is not on PATH (the scratch virtualenv has no pip either)")
    r = _twb_with(scratch_venv, "plugins", "list")
    assert r.returncode == 0 and "none" in r.stdout and str(scratch_venv.parents[1]) in r.stdout
    r = _twb_with(scratch_venv, "plugins", "install", "-e", str(EXAMPLE_PLUGIN), "--no-deps")
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"into {scratch_venv.parents[1]} (Python" in r.stderr and "with uv" in r.stderr
    assert re.search(r"shortcut +twb_shortcut_planner:ShortcutPlanner +\[twb-shortcut-planner 0\.1\.0\] +ok", r.stdout)
    assert "restart a running testbed" in r.stdout
    r = _twb_with(scratch_venv, "plan", "--env", "room", "--plan", "A", "--planner", "shortcut")
    assert r.returncode == 0 and json.loads(r.stdout)["planner"] == "shortcut", r.stderr
    # the project's own environment did not change
    assert "shortcut" not in twb("planners").stdout


def test_without_uv_or_pip_install_says_what_to_do(scratch_venv, tmp_path):
    import os

    no_uv = os.pathsep.join(p for p in os.environ.get("PATH", "").split(os.pathsep)
                            if not (Path(p) / "uv").exists())
    r = _twb_with(scratch_venv, "plugins", "install", str(EXAMPLE_PLUGIN), env={"PATH": no_uv})
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "uv is not on PATH and this Python has no pip" in r.stderr and "ensurepip" in r.stderr


def test_plugins_list_names_the_ones_that_fail_and_says_to_restart(plugin_dist, twb):
    r = twb("plugins", "list", env={"PYTHONPATH": str(plugin_dist)})
    assert r.returncode == 1
    assert re.search(r"straight +twb_test_plugin:StraightLine +\[twb-test-plugin 0\.1\] +ok", r.stdout), r.stdout
    broken = next(line for line in r.stdout.splitlines() if line.strip().startswith("broken"))
    assert "FAILED to load: No module named 'twb_test_plugin_missing'" in broken
    assert "restart the testbed" in broken
    assert re.search(r"creep +twb_test_plugin:Creep +ok", r.stdout), r.stdout


def test_a_plugin_that_fails_to_load_says_to_restart_the_testbed(plugin_dist):
    with pytest.raises(UnknownPlanner, match=r"failed to load: .*installed it while the testbed was running, "
                                             r"restart the testbed"):
        get_planner("broken")
