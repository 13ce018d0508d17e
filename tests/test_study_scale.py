"""Studies at scale: results streamed to disk as experiments finish, progress with runs/s and the time left."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from client_sdk import Client
from client_sdk.study import StudySpec, load_study, run_study
from client_sdk.study._collect import _StudyProgress
from client_sdk.study._stream import StudySink
from servers import Process

SWEEP = {"name": "sweep", "environments": ["room", "blocks"], "planners": ["fmm", "astar"], "repetitions": 3,
         "modes": ["sim"], "seed": 3}


def test_the_sink_writes_rows_as_they_come_and_a_csv_with_every_column(tmp_path):
    sink = StudySink(tmp_path / "out")
    poses = np.array([[0.0, 0.3, 0.3, 0.0], [0.1, 0.31, 0.3, 0.01]])
    sink.add([{"study": "s", "run_id": 1, "status": "completed", "length_m": 1.5}], [], {1: poses})
    # written before the study ends: a killed client keeps what finished
    assert (tmp_path / "out" / "poses" / "run-1.csv").exists()
    assert json.loads((tmp_path / "out" / "runs.jsonl").read_text())["length_m"] == 1.5
    sink.add([{"study": "s", "run_id": 2, "status": "failed", "failure": "collision", "clearance_min_m": 0.01}],
             [{"study": "s", "repetition": 0, "hausdorff_m": 0.02}], {})
    spec = StudySpec.from_json({"name": "s", "environments": ["room"], "planners": ["fmm"], "modes": ["sim"]})
    data = sink.close(spec, {}, [], {"runs": 2})
    header = (tmp_path / "out" / "runs.csv").read_text().splitlines()[0].split(",")
    assert header[:3] == ["study", "experiment_id", "run_id"] and header[-2:] == ["length_m", "clearance_min_m"]
    assert not (tmp_path / "out" / "runs.jsonl").exists()
    assert [r["status"] for r in data.rows] == ["completed", "failed"]
    assert data.rows[0]["clearance_min_m"] is None and data.rows[1]["length_m"] is None
    assert data.direct[0]["hausdorff_m"] == 0.02
    assert np.allclose(data.poses(1), poses) and data.poses(2).shape == (0, 4)


def test_progress_gives_runs_per_second_and_the_time_left(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr("sys.stderr", err)
    p = _StudyProgress("sweep", 1000, True, every_s=0.0)
    assert p.rate(0, 100.0) == (None, None)
    per_s, left = p.rate(200, 110.0)
    assert per_s == pytest.approx(20.0) and left == pytest.approx(40.0)
    for t, done in ((120.0, 300), (130.0, 400), (140.0, 500), (150.0, 600)):
        per_s, left = p.rate(done, t)
    assert per_s == pytest.approx(10.0, rel=0.01)  # over the last 30 s, not since the start
    assert left == pytest.approx(40.0, rel=0.01)
    p.update(700, "completed 690 failed 10")
    line = err.getvalue().strip().splitlines()[-1]
    assert line.startswith("study sweep: 700/1000 runs, ") and "runs/s, ETA " in line and "failed 10" in line


@pytest.mark.slow
def test_a_sim_sweep_streams_its_results_to_disk_paced_by_the_queue_quota(tmp_path):
    """8 experiments through a testbed that lets a user queue 3: the study goes in as its experiments finish."""
    tb = Process(["up", "--time-scale", "max", "--sim-robots", "4"], tmp_path / "tb",
                 env={"TWB_MAX_QUEUED_PER_USER": "3"})
    try:
        with Client(tb.url, token=tb.token) as c:
            data = run_study(c, StudySpec.from_json(SWEEP), progress=True, out=tmp_path / "out")
    finally:
        assert tb.stop() == 0
    runs = 2 * 2 * 2 * 3  # environments x plans x planners x repetitions
    assert len(data.rows) == runs and data.directory == tmp_path / "out"
    assert {r["status"] for r in data.rows} == {"completed"}
    assert not data._poses  # nothing held in memory: every run's poses are read from disk when asked
    assert len(list((tmp_path / "out" / "poses").glob("run-*.csv"))) == runs
    assert data.poses(data.rows[0]["run_id"]).shape[1] == 4
    again = load_study(tmp_path / "out")
    assert [r["run_id"] for r in again.rows] == [r["run_id"] for r in data.rows]
    assert [e["status"] for e in again.experiments] == ["completed"] * 8
