"""`twb plan` through the installed console script, as users run it."""

import json
import math

import numpy as np
import pytest

from contract.protocol import decode_path


@pytest.mark.slow
def test_json_output_matches_the_contract(twb):
    out = twb("plan", "--env", "room", "--start", "0.3,0.3,0", "--goal", "1.5,1.5,90deg", "--planner", "fm2")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert {"path", "length_m", "planning_time_s"} <= doc.keys()
    path = np.array(doc["path"])
    assert path.shape[1] == 3
    assert path[0].tolist() == pytest.approx([0.3, 0.3, path[0, 2]])
    assert path[-1].tolist() == pytest.approx([1.5, 1.5, math.pi / 2])
    assert doc["length_m"] == pytest.approx(np.hypot(*np.diff(path[:, :2], axis=0).T).sum(), abs=1e-5)
    assert doc["planner"] == "fm2" and doc["robot_radius_m"] == 0.045


@pytest.mark.slow
def test_ttp_output_is_one_wire_line(twb):
    out = twb("plan", "--env", "blocks", "--plan", "A", "--planner", "prm", "--seed", "4", "--format", "ttp")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert len(lines) == 1 and lines[0].startswith("T,T,P,150,150,")
    path = decode_path(lines[0])
    assert path[-1].tolist() == pytest.approx([1.65, 1.65, math.pi / 2], abs=1e-4)
    again = twb("plan", "--env", "blocks", "--plan", "A", "--planner", "prm", "--seed", "4", "--format", "ttp")
    assert again.stdout == out.stdout


@pytest.mark.slow
def test_csv_output_feeds_twb_metrics(twb, tmp_path):
    env_file = tmp_path / "env.json"
    env_file.write_text(json.dumps({"name": "open", "size": [1.0, 1.0]}))
    out = twb("plan", "--env", str(env_file), "--start", "0.2,0.2", "--goal", "0.8,0.8", "--format", "csv",
              "--robot-radius", "0.1", "--resolution", "0.005")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "t,x,y,theta"
    rows = [line.split(",") for line in lines[1:]]
    assert all(r[0] == "" and len(r) == 4 for r in rows)
    assert [float(v) for v in rows[-1][1:3]] == [0.8, 0.8]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--env", "nowhere", "--start", "0.3,0.3", "--goal", "1,1"], "unknown environment 'nowhere'"),
        (["--env", "room", "--start", "0.3,0.3", "--goal", "1,1", "--planner", "rrt"], "unknown planner 'rrt'"),
        (["--env", "room", "--start", "0.9,0.5", "--goal", "1.5,1.5"], r"start \(0.9, 0.5\) is inside an obstacle"),
        (["--env", "room", "--start", "0.3,0.3", "--goal", "2.5,1"], r"goal \(2.5, 1\) is outside the field"),
        (["--env", "room", "--start", "0.3,inf", "--goal", "1,1"], "--start: 'inf' must be finite"),
        (["--env", "room", "--start", "0.3", "--goal", "1,1"], "--start must be X,Y or X,Y,A"),
        (["--env", "room"], "--start and --goal are required"),
        (["--env", "room", "--plan", "Z"], "environment 'room' has no plan 'Z'"),
        (["--env", "room", "--start", "0.3,0.3", "--goal", "1,1", "--resolution", "0"], "`resolution` must be"),
        (["--env", "room", "--start", "0.3,0.3", "--goal", "1,1", "-p", "x"], "--param must be NAME=VALUE"),
    ],
)
def test_bad_input_exits_non_zero_with_one_line(twb, args, message):
    out = twb("plan", *args)
    assert out.returncode == 2
    assert out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith("twb: error: ")
    import re

    assert re.search(message, lines[0]), lines[0]


@pytest.mark.slow
def test_unreachable_goal_and_invalid_file(twb, tmp_path):
    walled = tmp_path / "walled.json"
    walled.write_text(json.dumps({"name": "w", "size": [1, 1], "blocks": [{"x": 0.5, "y": 0.5, "w": 0.06, "h": 1}]}))
    out = twb("plan", "--env", str(walled), "--start", "0.2,0.5", "--goal", "0.8,0.5")
    assert out.returncode == 2 and "cannot be reached" in out.stderr and "Traceback" not in out.stderr
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    out = twb("plan", "--env", str(broken), "--start", "0.2,0.5", "--goal", "0.8,0.5")
    assert out.returncode == 2 and "is not valid JSON" in out.stderr


@pytest.mark.slow
def test_demo_plans_every_builtin_case(twb):
    out = twb("demo")
    assert out.returncode == 0, out.stderr
    rows = [line for line in out.stdout.splitlines() if line.startswith("│")]
    assert len(rows) == 2 * 2 * 4
    assert all(p in out.stdout for p in ("fmm", "fm2", "prm", "astar"))


def test_the_help_names_every_built_in_environment_and_planner(twb):
    """`twb plan --help` offers what the package ships (it once named two of four environments)."""
    from planners.environment import builtin_names
    from planners.registry import available_planners

    out = twb("plan", "--help", env={"COLUMNS": "400"})
    assert out.returncode == 0, out.stderr
    text = " ".join(out.stdout.split())
    for name in builtin_names():
        assert name in text.split("Built-in environment name")[1].split("or a JSON file")[0], name
    for name in available_planners():
        assert name in text.split("--planner")[1].split("or a plug-in name")[0], name
