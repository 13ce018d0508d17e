"""Plug-in planners and controllers through the real entry-point mechanism (a distribution on sys.path): selected
like built-ins, their parameters declared once (contract.parameters.Param) and checked, and the ones that do not
load listed with the reason as data (contract.plugins.LoadError) by the server, `twb plugins list` and the SDK."""

import json
import re
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from contract import controller_specs
from contract.parameters import Param, ParamError
from contract.plugins import LoadError
from planners import (Planner, PlanningError, UnknownPlanner, available_planners, get_planner, plan_path,
                      register_planner)
from planners import registry
from servers import TOKEN

PLUGIN = textwrap.dedent(
    '''
    import numpy as np
    from contract.parameters import Param
    from planners import NoPathFound, Planner

    class StraightLine(Planner):
        """Straight segment from start to goal; fails if it is blocked."""
        name = "straight"
        description = "straight segment"
        parameters = (Param("extra", "m", 0.0, 0.0, 1.0, "an unused margin"),)

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

    class Unconfigurable(Planner):
        """A planner whose configure step fails: it needs a file that is not there."""
        name = "unconfigurable"

        def configure(self):
            raise FileNotFoundError("the roadmap file /nonexistent/roadmap.npz is missing")

        def solve(self, space, start, goal, params, seed):
            raise AssertionError("never called")

    class Grumpy:
        """A controller whose constructor fails."""

        def __init__(self):
            raise ValueError("no gains configured")

        def command(self, pose, path, progress, params, dt):
            return 0.0, 0.0

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


def write_plugin_dist(directory: Path) -> Path:
    """A tiny distribution ``twb-test-plugin 0.1`` in ``directory`` (to go on sys.path): its module and its
    entry points, two of each kind that load and two of each that do not."""
    (directory / "twb_test_plugin.py").write_text(PLUGIN)
    info = directory / "twb_test_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: twb-test-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[teleworkbench.planners]\n"
        "straight = twb_test_plugin:StraightLine\n"
        "through_walls = twb_test_plugin:through_walls\n"
        "broken = twb_test_plugin_missing:thing\n"
        "unconfigurable = twb_test_plugin:Unconfigurable\n"
        "[teleworkbench.controllers]\n"
        "creep = twb_test_plugin:Creep\n"
        "grumpy = twb_test_plugin:Grumpy\n"
        "missing = twb_test_plugin_missing:Controller\n"
    )
    return directory


@pytest.fixture
def plugin_dist(tmp_path, monkeypatch):
    """Install a tiny distribution declaring planners and controllers in the entry-point groups."""
    write_plugin_dist(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in ("straight", "through_walls", "broken", "unconfigurable"):
        registry.unregister_planner(name)
    for name in ("creep", "grumpy", "missing"):
        controller_specs.unregister_controller(name)
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


@pytest.mark.slow
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
        registry.unregister_planner("diag")


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


@pytest.mark.slow
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


@pytest.mark.slow
def test_without_uv_or_pip_install_says_what_to_do(scratch_venv, tmp_path):
    import os

    no_uv = os.pathsep.join(p for p in os.environ.get("PATH", "").split(os.pathsep)
                            if not (Path(p) / "uv").exists())
    r = _twb_with(scratch_venv, "plugins", "install", str(EXAMPLE_PLUGIN), env={"PATH": no_uv})
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "uv is not on PATH and this Python has no pip" in r.stderr and "ensurepip" in r.stderr


@pytest.mark.slow
def test_plugins_list_names_the_ones_that_fail_and_says_to_restart(plugin_dist, twb):
    r = twb("plugins", "list", env={"PYTHONPATH": str(plugin_dist)})
    assert r.returncode == 1
    assert re.search(r"straight +twb_test_plugin:StraightLine +\[twb-test-plugin 0\.1\] +ok", r.stdout), r.stdout
    broken = next(line for line in r.stdout.splitlines() if line.strip().startswith("broken"))
    assert "FAILED to load: No module named 'twb_test_plugin_missing' [ModuleNotFoundError]" in broken
    assert "restart the testbed" in broken
    unconfigurable = next(line for line in r.stdout.splitlines() if line.strip().startswith("unconfigurable"))
    assert "FAILED to load: the roadmap file /nonexistent/roadmap.npz is missing [FileNotFoundError]" in unconfigurable
    grumpy = next(line for line in r.stdout.splitlines() if line.strip().startswith("grumpy"))
    assert re.search(r"twb_test_plugin:Grumpy +\[twb-test-plugin 0\.1\] +FAILED to load: no gains configured "
                     r"\[ValueError\]", grumpy), grumpy
    assert re.search(r"creep +twb_test_plugin:Creep +\[twb-test-plugin 0\.1\] +ok", r.stdout), r.stdout


def test_a_plugin_that_fails_to_load_says_to_restart_the_testbed(plugin_dist):
    with pytest.raises(UnknownPlanner, match=r"failed to load: .*installed it while the testbed was running, "
                                             r"restart the testbed"):
        get_planner("broken")


# --------------------------------------------------------------------------- load errors as data, one parameter model


def test_a_plugin_raising_in_configure_or_its_constructor_is_a_load_error_as_data(plugin_dist):
    report = {p.name: p for p in (*registry.plugin_report(), *controller_specs.controller_report())}
    assert report["straight"].loaded and report["creep"].loaded
    assert report["unconfigurable"].error == LoadError(
        "unconfigurable", "planner", "twb_test_plugin:Unconfigurable", "FileNotFoundError",
        "the roadmap file /nonexistent/roadmap.npz is missing", "twb-test-plugin 0.1")
    assert report["grumpy"].error == LoadError("grumpy", "controller", "twb_test_plugin:Grumpy", "ValueError",
                                               "no gains configured", "twb-test-plugin 0.1")
    assert report["missing"].error == LoadError("missing", "controller", "twb_test_plugin_missing:Controller",
                                                "ModuleNotFoundError", "No module named 'twb_test_plugin_missing'",
                                                "twb-test-plugin 0.1")
    # selecting one raises the kind's error, carrying the same data
    with pytest.raises(UnknownPlanner, match=r"plug-in planner 'unconfigurable' .* failed to load: the roadmap") as exc:
        get_planner("unconfigurable")
    assert exc.value.load_error == report["unconfigurable"].error
    with pytest.raises(controller_specs.ControllerError, match="plug-in controller 'grumpy'") as exc:
        controller_specs.select("grumpy")
    assert exc.value.field == "controller" and exc.value.load_error == report["grumpy"].error
    assert "grumpy" not in {p.name for p in controller_specs.controller_report() if p.loaded}


def test_configure_runs_once_before_use_and_cleanup_when_the_plugin_is_dropped():
    from contract.controller_specs import Controller, register_controller, select, unregister_controller

    events = []

    class Counted(Planner):
        parameters = (Param("reach_m", "m", 0.5, 0.1, 2.0, "how far it looks"),)

        def configure(self):
            events.append("planner configure")

        def cleanup(self):
            events.append("planner cleanup")

        def solve(self, space, start, goal, params, seed):
            return np.array([start, goal])

    class Still(Controller):
        parameters = (Param("gain_1_s", "1/s", 1.0, 0.0, 5.0, "how hard it turns"),)

        def configure(self):
            events.append("controller configure")

        def cleanup(self):
            events.append("controller cleanup")

        def command(self, pose, path, progress, params, dt):
            return 0.0, 0.0

    try:
        planner = register_planner("counted", Counted)
        register_controller("still", Still)
        assert events == ["planner configure", "controller configure"]
        assert get_planner("counted") is planner
        assert plan_path("room", (0.3, 0.3), (0.5, 0.5), "counted").planner == "counted"
        assert select("still", {"gain_1_s": 2}).params == {"gain_1_s": 2.0}
        assert events == ["planner configure", "controller configure"]
    finally:
        registry.unregister_planner("counted")
        unregister_controller("still")
    assert events[2:] == ["planner cleanup", "controller cleanup"]
    with pytest.raises(UnknownPlanner, match="unknown planner 'counted'"):
        get_planner("counted")


def test_the_older_defaults_dict_declares_the_same_params():
    class Legacy(Planner):
        name = "legacy"
        defaults = {"n": 3, "fast": True, "mode": "a", "gain": 0.5}

    assert [(p.name, p.type, p.default) for p in Legacy.parameters] == [
        ("n", "integer", 3), ("fast", "boolean", True), ("mode", "string", "a"), ("gain", "number", 0.5)]
    assert Legacy.defaults == {"n": 3, "fast": True, "mode": "a", "gain": 0.5}
    assert Legacy().validate_params({"n": 4.0, "gain": 1}) == {"n": 4, "fast": True, "mode": "a", "gain": 1.0}
    for bad, message in (({"n": 2.5}, "parameter legacy.n must be an integer, got 2.5"),
                         ({"fast": 1}, "parameter legacy.fast must be true or false, got 1"),
                         ({"mode": 1}, "parameter legacy.mode must be a string, got 1"),
                         ({"gain": float("nan")}, "parameter legacy.gain must be finite, got nan"),
                         ({"m": 1}, "planner 'legacy' has no parameter 'm' (parameters: fast, gain, mode, n)")):
        with pytest.raises(ParamError) as exc:
            Legacy().validate_params(bad)
        assert str(exc.value) == message


# --------------------------------------------------------------------------- the same through a real server


@pytest.fixture(scope="module")
def plugin_server(testbeds, tmp_path_factory):
    """`twb server` whose Python sees the test distribution (PYTHONPATH), as after installing it (its own)."""
    dist = write_plugin_dist(tmp_path_factory.mktemp("dist"))
    yield from testbeds.own("server", env={"PYTHONPATH": str(dist)})


def test_the_listings_show_each_plugin_that_does_not_load_with_its_error(plugin_server):
    with plugin_server.client() as c:
        planners = c.get("/api/v1/planners").json()
        controllers = c.get("/api/v1/controllers").json()
    names = [p["name"] for p in planners["data"]]
    assert names[:5] == ["fmm", "fm2", "prm", "astar", "st_astar"] and {"straight", "through_walls"} <= set(names)
    assert not {"broken", "unconfigurable"} & set(names) and planners["count"] == len(names)
    assert planners["load_errors"] == [
        {"name": "broken", "kind": "planner", "source": "twb_test_plugin_missing:thing",
         "error_type": "ModuleNotFoundError", "message": "No module named 'twb_test_plugin_missing'",
         "distribution": "twb-test-plugin 0.1"},
        {"name": "unconfigurable", "kind": "planner", "source": "twb_test_plugin:Unconfigurable",
         "error_type": "FileNotFoundError", "message": "the roadmap file /nonexistent/roadmap.npz is missing",
         "distribution": "twb-test-plugin 0.1"}]
    assert "creep" in [c["name"] for c in controllers["data"]]
    assert [(e["name"], e["kind"], e["error_type"], e["message"]) for e in controllers["load_errors"]] == [
        ("grumpy", "controller", "ValueError", "no gains configured"),
        ("missing", "controller", "ModuleNotFoundError", "No module named 'twb_test_plugin_missing'")]


def test_the_sdk_shows_the_load_errors(plugin_server):
    from client_sdk import Client

    with Client(plugin_server.url, TOKEN) as twb:
        errors = twb.plugin_load_errors()
        assert "straight" in [p["name"] for p in twb.list_planners()]
    assert [(e.kind, e.name, e.error_type) for e in errors] == [
        ("planner", "broken", "ModuleNotFoundError"), ("planner", "unconfigurable", "FileNotFoundError"),
        ("controller", "grumpy", "ValueError"), ("controller", "missing", "ModuleNotFoundError")]
    assert errors[1] == LoadError("unconfigurable", "planner", "twb_test_plugin:Unconfigurable", "FileNotFoundError",
                                  "the roadmap file /nonexistent/roadmap.npz is missing", "twb-test-plugin 0.1")


def test_a_planner_and_a_controller_declare_parameters_alike_and_bad_values_get_a_clear_422(plugin_server):
    job = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [0.6, 0.5, 0.0], "planner": "straight",
           "modes": ["sim"]}
    with plugin_server.client() as c:
        straight = next(p for p in c.get("/api/v1/planners").json()["data"] if p["name"] == "straight")
        creep = next(p for p in c.get("/api/v1/controllers").json()["data"] if p["name"] == "creep")
        assert straight["parameters"] == [{"name": "extra", "unit": "m", "default": 0.0, "range": [0.0, 1.0],
                                           "description": "an unused margin"}]
        assert straight["defaults"] == {"extra": 0.0}
        assert creep["parameters"] == [{"name": "speed_m_s", "unit": "m/s", "default": 0.08, "range": [0.01, 0.2],
                                        "description": ""}]
        refused = {
            "parameter straight.extra must be a number in [0, 1] (m), got 'far'": {"planner_params": {"extra": "far"}},
            "parameter straight.extra must be a number in [0, 1] (m), got 2": {"planner_params": {"extra": 2}},
            "planner 'straight' has no parameter 'gain' (parameters: extra)": {"planner_params": {"gain": 1}},
            "controller_params.speed_m_s must be a number in [0.01, 0.2] (m/s), got 5.0":  # the schema made it a float
                {"controller": "creep", "controller_params": {"speed_m_s": 5}},
            "controller_params.gain: controller 'creep' has no parameter 'gain' (parameters: speed_m_s)":
                {"controller": "creep", "controller_params": {"gain": 1}},
        }
        for detail, change in refused.items():
            r = c.post("/api/v1/experiments", json={**job, **change})
            assert r.status_code == 422 and r.json()["detail"] == detail, r.text
        r = c.post("/api/v1/experiments", json={**job, "planner": "unconfigurable"})
        assert r.status_code == 422 and r.json()["detail"].startswith(
            "plug-in planner 'unconfigurable' (twb_test_plugin:Unconfigurable) failed to load: the roadmap file "
            "/nonexistent/roadmap.npz is missing [FileNotFoundError] (if you installed it while the testbed was "
            "running"), r.text
        r = c.post("/api/v1/experiments", json={**job, "controller": "creep", "controller_params": {"speed_m_s": 0.1},
                                                "planner_params": {"extra": 0.5}})
        assert r.status_code == 202, r.text
        assert r.json()["controller_params"] == {"speed_m_s": 0.1} and r.json()["planner_params"] == {"extra": 0.5}
