"""``twb metrics`` through the real console script (docs/design.md, "Command line"): JSON out, one-line errors."""

import json
import math
import subprocess
import sys

import pytest

from planners.control_metrics import CONTROL_KEYS
from planners.metrics import COMPARISON_KEYS, PATH_KEYS, RATIO_KEYS

PLANNED = "t,x,y,theta\n,0.2,0.2,0\n,1.6,0.2,1.57\n,1.6,1.6,1.57\n"
# out along y = 0.21, round the corner, up x = 1.59; 20 s from first to last sample
EXECUTED = "t,x,y,theta\n2.0,0.2,0.21,0\n8.0,1.0,0.21,0\n12.0,1.59,0.25,1.5\n16.0,1.59,1.0,1.57\n22.0,1.58,1.6,1.57\n"


@pytest.fixture
def files(tmp_path):
    def write(name: str, text: str | bytes) -> str:
        p = tmp_path / name
        p.write_bytes(text if isinstance(text, bytes) else text.encode())
        return str(p)

    write.planned = write("planned.csv", PLANNED)
    write.executed = write("executed.csv", EXECUTED)
    return write


def test_metrics_json_with_environment(twb, files):
    r = twb("metrics", "--planned", files.planned, "--executed", files.executed, "--env", "room")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    keys = set(PATH_KEYS) | set(COMPARISON_KEYS) | set(RATIO_KEYS) | set(CONTROL_KEYS)  # t and theta: a controller's
    assert keys | {"environment", "planning_time_s", "planned", "parameters"} == set(doc)
    assert set(doc["planned"]) == set(PATH_KEYS)
    assert doc["environment"] == "room"
    assert doc["planned"]["length_m"] == pytest.approx(2.8)
    length = 0.8 + math.hypot(0.59, 0.04) + 0.75 + math.hypot(0.01, 0.6)
    assert doc["length_m"] == pytest.approx(length)
    assert doc["execution_time_s"] == pytest.approx(20.0)
    assert doc["average_speed_m_s"] == pytest.approx(length / 20.0)
    assert doc["length_ratio"] == pytest.approx(length / 2.8)
    assert isinstance(doc["clearance_min_m"], float) and isinstance(doc["collided"], bool)
    assert doc["goal_reached"] is True and doc["planned"]["execution_time_s"] is None
    assert doc["parameters"] == {"samples": 200, "segments": None, "segment_length_m": 0.05,
                                 "robot_radius_m": 0.045, "goal_tolerance_m": 0.05, "obstacle_safety_m": 0.1,
                                 "collision_radius_m": 0.04, "max_speed_m_s": 0.2, "rate_hz": 10.0,
                                 "stop_speed_m_s": 0.01, "stop_turn_rate_rad_s": 0.05}
    assert doc["collision_count"] == 0 and doc["cross_track_error_max_m"] <= doc["deviation_max_m"] + 0.05
    assert doc["spl"] == 1.0 and doc["time_to_goal_s"] is not None  # performed shorter than planned: SPL 1


def test_metrics_without_environment_and_with_options(twb, files):
    square = files("square.csv", "x,y\n0,0\n1,0\n1,1\n0,1\n0,0\n")  # t and theta are optional
    r = twb("metrics", "--planned", square, "--executed", square, "--segments", "4", "--samples", "50")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["environment"] is None
    assert doc["clearance_min_m"] is None and doc["clearance_ratio"] is None and doc["collided"] is None
    assert doc["execution_time_s"] is None and doc["average_speed_m_s"] is None
    assert doc["smoothness_rad"] == pytest.approx(math.pi / 2)
    assert doc["deviation_max_m"] == 0 and doc["frechet_m"] == 0 and doc["smoothness_ratio"] == 1
    assert doc["parameters"]["samples"] == 50 and doc["parameters"]["segments"] == 4


def test_python_dash_m_twb_works_too(files):
    r = subprocess.run([sys.executable, "-m", "twb", "metrics", "--planned", files.planned, "--executed",
                        files.executed], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["execution_time_s"] == pytest.approx(20.0)


BAD = {
    "missing_column": ("t,x,theta\n0,1,0\n1,2,0\n", r"no 'y' column"),
    "nan": ("t,x,y,theta\n0,0.1,0.1,0\n1,nan,0.2,0\n2,0.3,0.3,0\n", r"line 3: x must be a finite number, got 'nan'"),
    "text": ("t,x,y,theta\n0,0.1,0.1,0\n1,0.2,abc,0\n", r"line 3: y must be a finite number, got 'abc'"),
    "one_point": ("t,x,y,theta\n0,0.1,0.1,0\n", r"at least 2 points, got 1"),
    "empty": ("", r"is empty"),
    "fields": ("t,x,y,theta\n0,0.1,0.1,0\n1,0.2,0.2\n", r"line 3: 3 fields, the header has 4"),
    "partial_t": ("t,x,y,theta\n0,0.1,0.1,0\n,0.2,0.2,0\n", r"line 3: t is empty; give t on every line or on none"),
    "backwards_t": ("t,x,y,theta\n1,0.1,0.1,0\n0.5,0.2,0.2,0\n", r"line 3: t goes back in time"),
    "binary": (b"\xff\xfe\x00garbage\x00\xff", r"cannot read --executed"),
}


def assert_one_line_error(code, stdout, stderr, pattern):
    import re

    assert code != 0
    assert stdout == ""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("twb: error: ") and "Traceback" not in stderr
    assert re.search(pattern, lines[0]), lines[0]


@pytest.mark.parametrize("case", ["nan", "missing_column"])
def test_bad_executed_files_give_one_clear_line(twb, files, case):
    text, pattern = BAD[case]
    r = twb("metrics", "--planned", files.planned, "--executed", files(f"{case}.csv", text))
    assert_one_line_error(r.returncode, r.stdout, r.stderr, pattern)


def test_unknown_environment_gives_one_clear_line(twb, files):
    r = twb("metrics", "--planned", files.planned, "--executed", files.executed, "--env", "nowhere")
    assert_one_line_error(r.returncode, r.stdout, r.stderr, r"unknown environment 'nowhere'")


# The remaining cases run the same entry point in-process (twb.main.main), to keep the suite fast.


def run_in_process(capsys, *args):
    from twb.main import main

    code = main(["metrics", *args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("case", sorted(BAD))
def test_every_bad_file_case_in_process(capsys, files, case):
    text, pattern = BAD[case]
    for role in ("--planned", "--executed"):
        base = {"--planned": files.planned, "--executed": files.executed, role: files(f"{case}.csv", text)}
        code, out, err = run_in_process(capsys, *[x for kv in base.items() for x in kv])
        assert_one_line_error(code, out, err, pattern.replace("--executed", role))


@pytest.mark.parametrize(
    "args, pattern",
    [
        (["--planned", "/nonexistent/p.csv"], r"--planned /nonexistent/p.csv: no such file"),
        (["--planned", "."], r"cannot read --planned \."),
        (["--samples", "1"], r"--samples must be an integer >= 2"),
        (["--segments", "1"], r"--segments must be an integer >= 2"),
        (["--robot-radius", "-1"], r"--robot-radius must be a finite number >= 0"),
        (["--goal-tolerance", "nan"], r"--goal-tolerance must be a finite number >= 0"),
    ],
)
def test_bad_options_give_one_clear_line(capsys, files, args, pattern):
    base = {"--planned": files.planned, "--executed": files.executed}
    for i in range(0, len(args), 2):
        base[args[i]] = args[i + 1]
    assert_one_line_error(*run_in_process(capsys, *[x for kv in base.items() for x in kv]), pattern)


def test_missing_files_option_gives_one_clear_line(capsys, files):
    assert_one_line_error(*run_in_process(capsys, "--planned", files.planned), r"--executed FILE are both required")


def test_comment_and_blank_lines_and_extra_columns_are_accepted(capsys, files):
    text = "# logged by the tracker\nquality,t,x,y\n\n1,0,0.2,0.2\n1,1,0.4,0.2\n\n1,2,0.6,0.2\n"
    code, out, err = run_in_process(capsys, "--planned", files.planned, "--executed", files("c.csv", text))
    assert code == 0, err
    doc = json.loads(out)
    assert doc["length_m"] == pytest.approx(0.4) and doc["execution_time_s"] == 2.0
