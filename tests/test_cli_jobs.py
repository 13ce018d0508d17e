"""`twb submit/status/wait/results/cancel/envs/replay` against a real testbed; errors are one line."""

from __future__ import annotations

import csv
import io
import json

import pytest
from PIL import Image

from servers import Process
from sdk_helpers import invoke


@pytest.fixture(scope="module")
def testbed(tmp_path_factory):
    p = Process(["up", "--time-scale", "max", "--sim-robots", "2"], tmp_path_factory.mktemp("cli-jobs"))
    yield p
    assert p.stop() == 0, p.output()


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
    m = json.loads(run("results", str(finished), "--json").stdout)
    assert set(m["aggregates"]) == {"sim", "twb"} and m["direct"][0]["deviation_mean_m"] > 0
    rows = list(csv.DictReader(io.StringIO(run("results", str(finished), "--csv").stdout)))
    assert [r["mode"] for r in rows] == ["sim", "twb"] and float(rows[1]["length_m"]) > 1.5
    assert "planned_length_m" in rows[0]
    r = run("wait", str(finished))
    assert r.returncode == 0 and "completed" in r.stderr


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
    r = run("submit", "--env", "room", "--plan", "A", "--planner", "prm", "-p", "samples=2", "-p", "k=1",
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
