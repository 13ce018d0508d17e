"""`twb submit/status/wait/results/cancel/envs/replay` against a real testbed; errors are one line."""

from __future__ import annotations

import csv
import io
import json
import math
import re

import pytest
from PIL import Image

from servers import STANDARD
from sdk_helpers import invoke


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


@pytest.fixture
def run(testbed, capsys, monkeypatch):
    """``twb ARGS`` in-process with TWB_URL/TWB_TOKEN set to the testbed's (``env=`` overrides)."""
    def call(*args: str, env: dict | None = None):
        return invoke(capsys, monkeypatch, *args,
                      env={"TWB_URL": testbed.url, "TWB_TOKEN": testbed.token, "TWB_DATA_DIR": None, **(env or {})})

    return call


@pytest.fixture(scope="module")
def finished(testbed):
    """The id of a completed sim + twb experiment, submitted with `twb submit --wait` (a real process)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    twb = Path(sys.executable).with_name("twb")
    env = {**os.environ, "TWB_URL": testbed.url, "TWB_TOKEN": testbed.token}
    r = subprocess.run([str(twb), "submit", "--env", "room", "--plan", "B", "--planner", "fmm", "--seed", "4",
                        "--wait", "--timeout", "120"], capture_output=True, text=True, env=env, timeout=180)
    assert r.returncode == 0, r.stderr
    exp_id = int(r.stdout.strip())
    assert f"experiment {exp_id}: completed (2/2 runs completed)" in r.stderr
    return exp_id


def test_envs(run):
    r = run("envs")
    assert r.returncode == 0 and "room" in r.stdout and "blocks" in r.stdout and "built-in" in r.stdout
    r = run("envs", "room")
    doc = json.loads(r.stdout)
    assert doc["name"] == "room" and doc["size"] == [1.8, 1.8] and doc["plans"][0]["name"] == "A"


def test_status_results_and_wait(run, finished):
    r = run("status", str(finished))
    assert r.returncode == 0 and f"experiment {finished}: completed" in r.stdout and "field-" in r.stdout
    r = run("status")
    assert r.returncode == 0 and str(finished) in r.stdout
    doc = json.loads(run("status", str(finished), "--json").stdout)
    assert doc["status"] == "completed" and len(doc["runs"]) == 2
    r = run("results", str(finished))
    assert r.returncode == 0 and "mean" in r.stdout and "direct comparison ST" in r.stdout
    assert "clock: lockstep at time scale max" in r.stdout  # how its runs' clocks ran (stored per run)
    assert {(x["clock"], x["time_scale"]) for x in doc["runs"]} == {("lockstep", None)}
    m = json.loads(run("results", str(finished), "--json").stdout)
    assert set(m["aggregates"]) == {"sim", "twb"} and m["direct"][0]["deviation_mean_m"] > 0
    rows = list(csv.DictReader(io.StringIO(run("results", str(finished), "--csv").stdout)))
    assert [r["mode"] for r in rows] == ["sim", "twb"] and float(rows[1]["length_m"]) > 1.5
    assert "planned_length_m" in rows[0]
    r = run("wait", str(finished))
    assert r.returncode == 0 and "completed" in r.stderr


def test_table_cells_cut_after_whole_words_and_clock_lines():
    from types import SimpleNamespace as R

    from twb.jobs_cmd import clip, clock_line

    text = "program stopped the robot 0.412 m from the goal (tolerance 0.05 m)"
    assert clip(text, 30, wide=False) == "program stopped the robot…"
    assert clip(text, 30, wide=True) == text and clip("short", 30, wide=False) == "short"
    assert clip("x" * 40, 10, wide=False) == "x" * 9 + "…"
    assert clock_line([R(id=1, clock="lockstep", time_scale=5.0), R(id=2, clock="lockstep", time_scale=5.0)]) \
        == "clock: lockstep at time scale 5x"
    assert clock_line([R(id=1, clock="lockstep", time_scale=None), R(id=2, clock="free", time_scale=1.0)]) \
        == "clock: lockstep at time scale max (runs 1); free at time scale 1x (runs 2)"
    assert clock_line([R(id=1, clock=None, time_scale=None)]) == ""


def test_submit_from_a_job_file_and_a_path_file(run, tmp_path):
    job = tmp_path / "job.json"
    job.write_text(json.dumps({"environment": "blocks", "start": [0.15, 0.15], "goal": [1.65, 1.65],
                               "planner": "fm2", "modes": ["sim"]}))
    r = run("submit", str(job), "--repetitions", "2", "--wait")
    assert r.returncode == 0, r.stderr
    assert "completed (2/2 runs completed)" in r.stderr
    planned = run("plan", "--env", "room", "--plan", "A", "--planner", "fmm", "--format", "csv").stdout
    (tmp_path / "p.csv").write_text(planned)
    r = run("submit", "--env", "room", "--path", str(tmp_path / "p.csv"), "--modes", "sim", "--wait")
    assert r.returncode == 0, r.stderr
    doc = json.loads(run("status", r.stdout.strip(), "--json").stdout)
    assert doc["planner"] is None and doc["planned_path"][0][:2] == [0.3, 0.3]


def test_a_failed_job_exits_1_with_the_reason(run):
    r = run("submit", "--env", "room", "--plan", "A", "--planner", "prm", "-p", "samples=2", "-p", "k=1", "-p", "grow=false",
            "--modes", "sim", "--wait")
    assert r.returncode == 1
    assert "failed" in r.stderr and "PRM found no path" in r.stderr


def test_replay_writes_an_animated_gif(run, finished, tmp_path):
    doc = json.loads(run("status", str(finished), "--json").stdout)
    twb_run = next(r["id"] for r in doc["runs"] if r["mode"] == "twb")
    out = tmp_path / "run.gif"
    r = run("replay", str(twb_run), "--out", str(out), "--max-frames", "20", "--dpi", "40")
    assert r.returncode == 0, r.stderr
    with Image.open(out) as im:
        assert im.format == "GIF" and im.n_frames > 5 and im.size[0] > 100
    r = run("replay", str(twb_run), "--out", str(tmp_path / "run.mp4"))
    assert r.returncode == 2 and "must be a .gif" in r.stderr


def test_token_file_fallback(run, testbed):
    r = run("envs", env={"TWB_TOKEN": None, "TWB_DATA_DIR": str(testbed.data_dir)})
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("args,message", [
    (("status", "999999"), "Experiment not found"),
    (("cancel", "999999"), "Experiment not found"),
    (("results", "999999"), "Experiment not found"),
    (("replay", "999999"), "Run not found"),
    (("envs", "atlantis"), "Environment not found"),
    (("submit", "--env", "room", "--start", "0.9,0.9", "--goal", "1.5,1.5"), "inside an obstacle"),
    (("submit", "--env", "room", "--plan", "Z"), "has no plan 'Z'"),
    (("submit", "--planner", "fmm"), "give --env NAME"),
    (("submit", "--env", "room", "--start", "x,1", "--goal", "1,1"), "--start: 'x' is not a number"),
])
def test_errors_are_one_line(run, args, message):
    r = run(*args)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert r.stderr.startswith("twb: error: ") and r.stderr.count("\n") == 1, r.stderr
    assert message in r.stderr


def test_cancel_finished_is_a_conflict(run, finished):
    r = run("cancel", str(finished))
    assert r.returncode == 2 and "409 Conflict: Experiment already completed" in r.stderr


def test_bad_token_and_no_server(run, tmp_path):
    r = run("status", "--token", "wrong")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Invalid token" in r.stderr
    r = run("status", env={"TWB_TOKEN": None, "TWB_DATA_DIR": str(tmp_path)})
    assert r.returncode == 2 and "Missing bearer token" in r.stderr and "TWB_TOKEN" in r.stderr
    r = run("envs", "--url", "http://127.0.0.1:9", "--token", "x")
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "cannot reach the testbed at http://127.0.0.1:9" in r.stderr and "twb up" in r.stderr


# --------------------------------------------------------------------------- what a new user hit


def _twb_process(testbed, *args: str, cwd=None, timeout: float = 180):
    """``twb ARGS`` as a real process (stdout and stderr are pipes, not a terminal)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    env = {**os.environ, "TWB_URL": testbed.url, "TWB_TOKEN": testbed.token}
    env.pop("TWB_DEBUG", None)
    return subprocess.run([str(Path(sys.executable).with_name("twb")), *args], capture_output=True, text=True,
                          env=env, timeout=timeout, cwd=cwd)


def test_offline_and_online_plans_agree(run, testbed):
    """`twb plan` plans in the testbed's configuration space (robot radius + planning margin)."""
    offline = json.loads(run("plan", "--env", "room", "--plan", "A", "--planner", "fm2").stdout)
    assert offline["robot_radius_m"] == 0.045 and offline["planning_margin_m"] == 0.02
    r = run("submit", "--env", "room", "--plan", "A", "--planner", "fm2", "--modes", "sim", "--wait")
    assert r.returncode == 0, r.stderr
    online = json.loads(run("status", r.stdout.strip(), "--json").stdout)
    assert (online["robot_radius"], online["planning_margin"]) == (0.045, 0.02)
    path = online["planned_path"]
    length = sum(math.dist(a[:2], b[:2]) for a, b in zip(path, path[1:]))
    assert length == pytest.approx(offline["length_m"], abs=1e-5)
    assert offline["length_m"] == pytest.approx(1.959, abs=1e-3)  # 1.983 before FM² cut its corners (round 3)
    assert len(path) == len(offline["path"])
    assert max(math.dist(a[:2], b[:2]) for a, b in zip(path, offline["path"])) < 1e-5
    # without the margin the path is another one (9 mm shorter, up to 1.3 cm away; more than 1 cm shorter before FM²
    # cut its corners): the default is what makes them agree to the micrometre
    bare = json.loads(run("plan", "--env", "room", "--plan", "A", "--planner", "fm2", "--planning-margin", "0").stdout)
    assert bare["planning_margin_m"] == 0 and abs(bare["length_m"] - length) > 0.005


def test_envs_create_and_submit_with_an_environment_file(run, tmp_path):
    env = {"name": "newuser-corridor", "size": [1.8, 1.8],
           "blocks": [{"x": 0.9, "y": 0.6, "w": 0.06, "h": 1.2}],
           "plans": [{"name": "A", "start": [0.3, 0.3, 0], "goal": [1.5, 0.3, 0]}]}
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**env, "blocks": [{"x": 0.9, "y": 0.6, "w": -0.1, "h": 1.2}]}))
    r = run("envs", "create", str(bad))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "blocks[0].w must be > 0" in r.stderr
    r = run("envs", "create", str(tmp_path / "missing.json"))
    assert r.returncode == 2 and "no such environment file" in r.stderr
    good = tmp_path / "corridor.json"
    good.write_text(json.dumps(env))
    r = run("envs", "create", str(good))
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("Created environment 'newuser-corridor': 1.8 x 1.8 m, 1 blocks, plans: A.")
    r = run("envs", "create", str(good))
    assert r.returncode == 2 and "the name 'newuser-corridor' is taken on the testbed" in r.stderr
    assert json.loads(run("envs", "newuser-corridor").stdout)["blocks"][0]["h"] == 1.2  # `twb envs NAME` as before
    # `twb submit --env FILE`: an identical environment is used ...
    r = run("submit", "--env", str(good), "--plan", "A", "--planner", "astar", "--modes", "sim", "--wait")
    assert r.returncode == 0, r.stderr
    assert "using the testbed's identical environment 'newuser-corridor'" in r.stderr
    # ... a new one is created first ...
    fresh = tmp_path / "fresh.json"
    fresh.write_text(json.dumps({**env, "name": "newuser-fresh"}))
    r = run("submit", "--env", str(fresh), "--start", "0.3,0.3", "--goal", "1.5,0.3", "--modes", "sim", "--wait")
    assert r.returncode == 0, r.stderr
    assert "created environment 'newuser-fresh'" in r.stderr
    assert json.loads(run("status", r.stdout.strip(), "--json").stdout)["environment"] == "newuser-fresh"
    # ... and a different one with a taken name is refused, nothing submitted
    other = tmp_path / "other.json"
    other.write_text(json.dumps({**env, "blocks": []}))
    r = run("submit", "--env", str(other), "--plan", "A", "--modes", "sim")
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1
    assert "already has a different environment named 'newuser-corridor'" in r.stderr


def test_submit_wait_prints_status_lines_when_not_a_terminal(testbed):
    r = _twb_process(testbed, "submit", "--env", "blocks", "--plan", "A", "--planner", "fmm", "--wait")
    assert r.returncode == 0, r.stderr
    exp_id = int(r.stdout.strip())
    lines = r.stderr.splitlines()
    status = [ln for ln in lines if re.match(rf"^\[\d+ s\] experiment {exp_id}: \w+, \d/2 runs done", ln)]
    assert len(status) >= 2 and status[-1].endswith(f"experiment {exp_id}: completed, 2/2 runs done"), r.stderr
    assert "\x1b" not in r.stderr and "\r" not in r.stderr
    assert lines[-1] == f"experiment {exp_id}: completed (2/2 runs completed)"
    r = _twb_process(testbed, "wait", str(exp_id))
    assert r.returncode == 0 and f"experiment {exp_id}: completed, 2/2 runs done" in r.stderr
    assert _twb_process(testbed, "wait", str(exp_id), "-q").stderr == f"experiment {exp_id}: completed (2/2 runs completed)\n"


def test_results_fit_the_terminal_and_wide_shows_everything(run, finished):
    narrow = run("results", str(finished), env={"COLUMNS": "80"})
    assert narrow.returncode == 0, narrow.stderr
    assert max(len(line) for line in narrow.stdout.splitlines()) <= 80, narrow.stdout
    assert "left out to fit 80 characters" in narrow.stdout and "--wide shows every column" in narrow.stdout
    assert "mean" in narrow.stdout and "length" in narrow.stdout
    wide = run("results", str(finished), "--wide", env={"COLUMNS": "80"})
    assert "left out" not in wide.stdout and "κ'" in wide.stdout and "speed" in wide.stdout
    assert max(len(line) for line in wide.stdout.splitlines()) > 80
    roomy = run("results", str(finished), env={"COLUMNS": "160"})
    assert "left out" not in roomy.stdout
    status = run("status", str(finished), env={"COLUMNS": "80"})
    assert max(len(line) for line in status.stdout.splitlines()) <= 80 and "field-" in status.stdout


def test_the_sdk_says_where_it_looked_for_a_token(testbed, tmp_path):
    import os
    import subprocess
    import sys

    code = ("from client_sdk import Client, Unauthorized\n"
            "try:\n    Client().list_robots()\nexcept Unauthorized as e:\n    print(e)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("TWB_TOKEN", "TWB_DATA_DIR")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=60,
                         env={**env, "TWB_URL": testbed.url}).stdout
    assert out.startswith("401 Unauthorized: Missing bearer token (no token found"), out
    assert str(tmp_path / "twb-data" / "token") in out and "TWB_TOKEN" in out and "token=" in out


def test_submit_with_a_controller_runs_it_in_both_modes(run):
    r = run("submit", "--env", "blocks", "--plan", "B", "--controller", "pure_pursuit",
            "--controller-param", "lookahead_m=0.05", "--wait")
    assert r.returncode == 0, r.stderr
    assert "completed (2/2 runs completed)" in r.stderr
    doc = json.loads(run("status", r.stdout.strip(), "--json").stdout)
    assert doc["controller"] == "pure_pursuit" and doc["controller_params"]["lookahead_m"] == 0.05
    r = run("submit", "--env", "room", "--plan", "A", "--controller", "mpc")
    assert r.returncode != 0 and "unknown controller 'mpc'" in r.stderr and "Traceback" not in r.stderr
    r = run("submit", "--env", "room", "--plan", "A", "--controller", "kanayama", "--controller-param", "k_x_1_s")
    assert r.returncode != 0 and "--controller-param must be NAME=VALUE" in r.stderr
    r = run("submit", "--env", "room", "--plan", "A", "--controller", "kanayama", "--controller-param", "k_x_1_s=-1")
    assert r.returncode != 0 and "controller_params.k_x_1_s must be a number in [0, 50] (1/s)" in r.stderr
