"""`twb study` on a reduced matrix against a real testbed: every file, real figures, OMPL database, errors."""

from __future__ import annotations

import json
import sqlite3

import pytest
from PIL import Image

from client_sdk.study import (
    PAPER,
    StudySpec,
    StudySpecError,
    export_ompl,
    load_spec,
    load_study,
    make_figures,
    paper_spec,
    plan_jobs,
)
from client_sdk import Environment, Plan
from servers import Process
from sdk_helpers import invoke

SMALL = {"name": "small", "environments": ["room"], "plans": ["A"], "planners": ["fmm", "fm2"],
         "repetitions": 1, "modes": ["sim", "twb"], "seed": 2}


@pytest.fixture(scope="module")
def testbed(tmp_path_factory):
    p = Process(["up", "--time-scale", "max", "--sim-robots", "2"], tmp_path_factory.mktemp("study-tb"))
    yield p
    assert p.stop() == 0, p.output()


@pytest.fixture(scope="module")
def study_dir(testbed, tmp_path_factory):
    import os
    import subprocess
    import sys
    from pathlib import Path

    d = tmp_path_factory.mktemp("study")
    spec = d / "small.json"
    spec.write_text(json.dumps(SMALL))
    out = d / "out"
    twb = Path(sys.executable).with_name("twb")
    r = subprocess.run([str(twb), "study", str(spec), "--out", str(out), "--url", testbed.url, "--token",
                        testbed.token, "--ompl", str(out / "study.db")], capture_output=True, text=True, timeout=300,
                       env={k: v for k, v in os.environ.items() if k != "TWB_DEBUG"})
    assert r.returncode == 0, r.stderr
    assert "study small: 4/4 runs completed" in r.stdout
    return out


def test_study_writes_every_file(study_dir):
    for name in ("runs.csv", "direct.csv", "study.json", "summary.md", "report.html", "study.db",
                 *(f"{f}.{e}" for f in ("fig6_metrics", "fig7_ratios", "fig8_paths") for e in ("png", "svg"))):
        assert (study_dir / name).stat().st_size > 0, name
    data = load_study(study_dir)
    assert len(data.rows) == 4 and all(r["status"] == "completed" for r in data.rows)
    assert {(r["planner"], r["mode"]) for r in data.rows} == {(p, m) for p in ("fmm", "fm2") for m in ("sim", "twb")}
    row = data.rows[0]
    for key in ("length_m", "smoothness_rad", "clearance_min_m", "execution_time_s", "average_speed_m_s",
                "deviation_mean_m", "deviation_max_m", "length_ratio", "smoothness_ratio", "clearance_ratio",
                "hausdorff_m", "frechet_m", "aol_rad_per_m", "goal_reached", "collided", "planning_time_s",
                "planned_length_m", "st_deviation_mean_m"):
        assert key in row, key
    assert row["goal_reached"] is True and isinstance(row["length_m"], float)
    assert len(data.direct) == 2 and all(d["deviation_mean_m"] > 0 for d in data.direct)
    assert len(list((study_dir / "poses").glob("run-*.csv"))) == 4
    assert data.poses(row["run_id"]).shape[1] == 4
    summary = (study_dir / "summary.md").read_text()
    assert "| fmm | sim | 1/1 |" in summary and "| fm2 | twb | 1/1 |" in summary and "Direct comparison ST" in summary
    html = (study_dir / "report.html").read_text()
    assert all(f"src='{f}.png'" in html for f in ("fig6_metrics", "fig7_ratios", "fig8_paths"))


def test_figures_are_real_images_with_the_expected_panels(study_dir):
    for name in ("fig6_metrics", "fig7_ratios", "fig8_paths"):
        with Image.open(study_dir / f"{name}.png") as im:
            assert im.format == "PNG" and im.size[0] > 400 and im.size[1] > 300
        assert (study_dir / f"{name}.svg").read_text().lstrip().startswith("<?xml")
    figs = make_figures(load_study(study_dir))
    assert len(figs["fig6_metrics"].axes) == 6
    assert len(figs["fig7_ratios"].axes) == 3
    assert len(figs["fig8_paths"].axes) == 1 * 2  # problems x planners
    titles = [ax.get_title() for ax in figs["fig8_paths"].axes]
    assert titles == ["room A · fmm", "room A · fm2"]
    fig6 = figs["fig6_metrics"].axes[5]
    assert fig6.get_title() == "mean deviation (m)"
    assert {t.get_text() for t in figs["fig6_metrics"].legends[0].get_texts()} >= {
        "simulation (S)", "Teleworkbench (T)", "direct comparison (ST)"}


def test_ompl_database_is_readable(study_dir, tmp_path):
    con = sqlite3.connect(study_dir / "study.db")
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert {"experiments", "plannerConfigs", "enums", "runs", "progress"} <= tables
    assert con.execute("SELECT name, runcount FROM experiments").fetchall() == [("room-A", 1)]
    assert sorted(r[0] for r in con.execute("SELECT name FROM plannerConfigs")) == [
        "fm2_sim", "fm2_twb", "fmm_sim", "fmm_twb"]
    cols = {r[1]: r[2] for r in con.execute("PRAGMA table_info(runs)")}
    assert cols["time"] == "REAL" and cols["solved"] == "BOOLEAN" and cols["status"] == "ENUM"
    assert cols["length_m"] == "REAL" and cols["goal_reached"] == "BOOLEAN"
    rows = con.execute("SELECT p.name, r.solved, r.length_m, r.solution_length FROM runs r "
                       "JOIN plannerConfigs p ON r.plannerid = p.id").fetchall()
    assert len(rows) == 4 and all(solved == 1 and length > 1.5 and sol > 1.5 for _, solved, length, sol in rows)
    assert con.execute("SELECT count(*) FROM progress").fetchone()[0] > 4
    assert con.execute("SELECT description FROM enums WHERE name='status' AND value=0").fetchone() == ("completed",)
    con.close()
    counts = export_ompl(load_study(study_dir), tmp_path / "again.db", progress=False)
    assert counts["runs"] == 4 and counts["progress"] == 0


def test_export_ompl_command(capsys, monkeypatch, study_dir, tmp_path):
    r = invoke(capsys, monkeypatch, "export-ompl", str(study_dir), "--out", str(tmp_path / "x.db"))
    assert r.returncode == 0, r.stderr
    assert "1 experiments, 4 planner configurations, 4 runs" in r.stdout
    r = invoke(capsys, monkeypatch, "export-ompl", str(tmp_path))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "is not a study directory" in r.stderr


def test_paper_spec_is_48_runs():
    spec = paper_spec()
    envs = {n: Environment(n, [1.8, 1.8], [], [Plan("A", [0.1, 0.1], [1, 1]), Plan("B", [0.2, 0.2], [1, 1])])
            for n in ("room", "blocks")}
    jobs = plan_jobs(spec, envs)
    assert len(jobs) == 12 and len(jobs) * spec.runs_per_experiment == 48
    assert {j["planner"] for j in jobs} == {"fmm", "fm2", "prm"}
    assert jobs[0]["body"]["modes"] == ["sim", "twb"] and jobs[0]["body"]["repetitions"] == 2
    assert StudySpec.from_json(spec.to_json()) == spec
    assert load_spec("paper") == StudySpec.from_json(PAPER)


@pytest.mark.parametrize("content,message", [
    ("{not json", "invalid JSON"),
    ('{"environments": ["room"]}', "`planners` must be a non-empty list"),
    ('{"environments": ["room"], "planners": ["fmm"], "repetitons": 2}', "unknown key(s) repetitons"),
    ('{"environments": ["room"], "planners": ["fmm"], "modes": ["real"]}', "`modes` must be a list"),
    ('[1, 2]', "must be a JSON object"),
])
def test_bad_study_files(tmp_path, content, message):
    f = tmp_path / "bad.json"
    f.write_text(content)
    with pytest.raises(StudySpecError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_spec(f)


def test_study_errors_are_one_line(capsys, monkeypatch, testbed, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"environments": ["room"], "planners": []}')
    cases = [
        (("study", str(bad), "--url", testbed.url), "`planners` must be a non-empty list"),
        (("study", str(tmp_path / "missing.json")), "cannot read study file"),
        (("study", "paper", "--url", "http://127.0.0.1:9", "--token", "x", "--out", str(tmp_path / "o")),
         "cannot reach the testbed at http://127.0.0.1:9"),
        (("study", "paper", "--url", testbed.url, "--token", "wrong", "--out", str(tmp_path / "o")),
         "refused the request: Invalid token"),
    ]
    for args, message in cases:
        r = invoke(capsys, monkeypatch, *args, env={"TWB_TOKEN": None, "TWB_URL": None})
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert r.stderr.startswith("twb: error: ") and r.stderr.count("\n") == 1, r.stderr
        assert message in r.stderr, r.stderr


def test_unknown_environment_in_a_study(capsys, monkeypatch, testbed, tmp_path):
    f = tmp_path / "s.json"
    f.write_text(json.dumps({**SMALL, "environments": ["atlantis"]}))
    r = invoke(capsys, monkeypatch, "study", str(f), "--url", testbed.url, "--token", testbed.token, "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "unknown environment 'atlantis'" in r.stderr and r.stderr.count("\n") == 1


def test_embedded_study(twb, tmp_path):
    f = tmp_path / "tiny.json"
    f.write_text(json.dumps({"name": "tiny", "environments": ["blocks"], "plans": ["A"], "planners": ["fmm"],
                             "modes": ["sim"], "repetitions": 1}))
    r = twb("study", str(f), "--embedded", "--out", str(tmp_path / "out"), "--no-progress", timeout=180)
    assert r.returncode == 0, r.stderr
    assert "study tiny: 1/1 runs completed" in r.stdout
    assert (tmp_path / "out" / "fig8_paths.png").exists()
    log = (tmp_path / "out" / "testbed" / "stdout.log").read_text()
    assert "Teleworkbench is up" in log and "Traceback" not in log
