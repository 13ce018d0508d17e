"""`twb study` on a reduced matrix against a real testbed: every file, real figures, OMPL database, errors."""

from __future__ import annotations

import json
import math
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
from servers import STANDARD
from sdk_helpers import invoke, study_process

SMALL = {"name": "small", "environments": ["room"], "plans": ["A"], "planners": ["fmm", "fm2"],
         "repetitions": 1, "modes": ["sim", "twb"], "seed": 2}


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


@pytest.fixture(scope="module")
def study_dir(testbed, tmp_path_factory):
    d = tmp_path_factory.mktemp("study")
    r, out = study_process(testbed, SMALL, d, "--ompl", str(d / "out" / "study.db"))
    assert r.returncode == 0, r.stderr
    assert "study small: 4/4 runs completed" in r.stdout
    return out


def test_study_writes_every_file(study_dir):
    for name in ("runs.csv", "direct.csv", "study.json", "summary.md", "report.html", "study.db", "outcomes.csv",
                 "comparisons.csv",
                 *(f"{f}.{e}" for f in ("fig5_outcomes", "fig6_metrics", "fig7_ratios", "fig8_paths")
                   for e in ("png", "svg"))):
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
    assert "| fmm | sim | 1 of 1 |" in summary and "| fm2 | twb | 1 of 1 |" in summary and "Direct comparison ST" in summary
    assert "| fm2 | twb | 1 | 1 | 0 | 0 | 0 | 0 | 1/1 (95% CI 21–100 %) |" in summary  # outcomes, Wilson interval
    assert summary.index("## Which planner is better?") < summary.index("## Outcomes per configuration")
    assert row["outcome"] == "success" and row["configuration"] == row["planner"] and row["stopped_at_x"] is None
    html = (study_dir / "report.html").read_text()
    assert all(f"src='{f}.png'" in html for f in ("fig5_outcomes", "fig6_metrics", "fig7_ratios", "fig8_paths"))
    # nothing failed: no crashed path in Fig. 8
    assert orange_pixels(study_dir / "fig8_paths.png") == 0


CRASH_RGB = (0xFF, 0x7F, 0x0E)  # Fig. 8's failed runs and their cross (client_sdk.study._figures.COLORS["failed"])


def orange_pixels(png, tol: int = 30) -> int:
    import numpy as np

    with Image.open(png) as im:
        a = np.asarray(im.convert("RGB")).astype(int)
    return int((np.abs(a - CRASH_RGB).max(axis=2) <= tol).sum())


def test_fig8_draws_the_moving_obstacles_exact_tracks_over_each_panels_longest_run(study_dir):
    """A study among moving obstacles: each Fig. 8 panel draws them on their exact tracks (obstacle time 0 to the
    panel's longest run), labelled so, a disc where each starts; a study without them draws none."""
    import copy

    import numpy as np

    from client_sdk.study._figures import figure_paths
    from client_sdk.study._obstacle_paths import EXACT
    from planners import parse_environment
    from planners.moving import positions

    data = load_study(study_dir)
    assert not [line for ax in figure_paths(data).axes for line in ax.get_lines() if line.get_label() == EXACT]
    env = copy.deepcopy(data.environments["room"])
    env["moving_obstacles"] = [{"radius": 0.05, "waypoints": [[0.4, 1.2], [1.4, 1.2]], "speed": 0.1,
                                "repeat": "pingpong"}]
    data.environments["room"] = env
    fig = figure_paths(data)
    for ax, exp in zip(fig.axes, data.experiments):
        (track,) = [line for line in ax.get_lines() if line.get_label() == EXACT]
        runs = [r for r in data.rows if r["run_id"] in exp["runs"]]
        longest = max(r["t_end"] - r["t_start"] for r in runs)
        expected = positions(parse_environment(env).moving_obstacles, np.linspace(0.0, longest, 200))[0]
        assert np.allclose(track.get_xydata(), expected), ax.get_title()
        assert [(tuple(p.center), p.radius) for p in ax.patches if hasattr(p, "center")] == [((0.4, 1.2), 0.05)]
    assert EXACT in {t.get_text() for t in fig.legends[0].get_texts()}


def test_an_obstacle_robot_the_tracker_never_saw_keeps_its_place_and_radius(study_dir, tmp_path):
    """obstacles/run-<id>.csv of a field run whose first and last obstacle robots the tracker never saw: read
    back, every obstacle keeps its index and radius (they were dropped, or their radius was NaN), and the figure
    draws the one it saw, labelled as tracked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from client_sdk import ObstacleTracks
    from client_sdk.study._obstacle_paths import TRACKED, draw_obstacles

    data = load_study(study_dir)
    run_id = data.rows[0]["run_id"]
    seen = np.array([[1.0, 0.4, 1.2, 0.0], [1.1, 0.5, 1.2, 0.0], [1.2, 0.6, 1.2, 0.0]])
    data.add_obstacles(run_id, ObstacleTracks(run_id, False, [np.empty((0, 4)), seen, np.empty((0, 4))],
                                              [0.04, 0.05, 0.06]))
    data.save(tmp_path / "copy")
    back = load_study(tmp_path / "copy").obstacles(run_id)
    assert not back.exact and back.radii == [0.04, 0.05, 0.06]
    assert [tr.shape for tr in back.tracks] == [(0, 4), (3, 4), (0, 4)] and np.array_equal(back.tracks[1], seen)

    env = {"size": [1.8, 1.8], "blocks": [], "moving_obstacles": [
        {"radius": 0.04, "waypoints": [[0.3, 0.3], [0.6, 0.3]], "speed": 0.1}] * 3}
    fig, ax = plt.subplots()
    try:
        assert draw_obstacles(ax, env, 5.0, back) == TRACKED
        assert [line.get_label() for line in ax.get_lines()] == [TRACKED]
        assert [(tuple(p.center), p.radius) for p in ax.patches] == [((0.4, 1.2), 0.05)]
    finally:
        plt.close(fig)


def test_figures_are_real_images_with_the_expected_panels(study_dir):
    for name in ("fig5_outcomes", "fig6_metrics", "fig7_ratios", "fig8_paths"):
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



@pytest.mark.parametrize("name", ["small", "two planners compared on my own environment with walls"])
def test_every_figure_title_and_legend_fits_its_figure(study_dir, name):
    """Fig. 8 of two planners is 6.2 in wide: its one-row legend and its title ran off both sides."""
    import dataclasses

    data = load_study(study_dir)
    data.spec = dataclasses.replace(data.spec, name=name)
    for key, fig in make_figures(data).items():
        width = fig.bbox.width
        legend, title = fig.legends[0], fig.get_suptitle()
        assert name in title.replace("\n", " ") and legend.get_texts()
        for artist in (legend, fig._suptitle):
            box = artist.get_window_extent()
            assert 0 <= box.x0 and box.x1 <= width, (key, type(artist).__name__, box, width)

def test_ompl_database_is_readable(study_dir, tmp_path):
    con = sqlite3.connect(study_dir / "study.db")
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert {"experiments", "plannerConfigs", "enums", "runs", "progress"} <= tables
    assert con.execute("SELECT name, runcount, version FROM experiments").fetchall() == [
        ("room-A", 1, "Teleworkbench 0.1.0")]
    assert sorted(r[0] for r in con.execute("SELECT name FROM plannerConfigs")) == [
        "fm2_sim", "fm2_twb", "fmm_sim", "fmm_twb"]
    cols = {r[1]: r[2] for r in con.execute("PRAGMA table_info(runs)")}
    assert cols["time"] == "REAL" and cols["solved"] == "BOOLEAN" and cols["status"] == "ENUM"
    assert cols["twb_outcome"] == "ENUM" and cols["twb_length_m"] == "REAL" and cols["twb_goal_reached"] == "BOOLEAN"
    rows = con.execute("SELECT p.name, r.solved, r.status, r.twb_length_m, r.solution_length, r.time, "
                       "r.solution_smoothness, r.solution_clearance, r.twb_planned_length_m FROM runs r "
                       "JOIN plannerConfigs p ON r.plannerid = p.id").fetchall()
    assert len(rows) == 4
    for _, solved, status, length, sol, t, smooth, clear, planned in rows:
        assert solved == 1 and status == 6 and length > 1.5 and sol == planned > 1.5 and t > 0  # OMPL: exact
        assert smooth >= 0 and 0 < clear < 0.9  # PathGeometric's, of the planned path
    assert con.execute("SELECT count(*) FROM progress").fetchone()[0] == 0  # the planners are not anytime
    assert con.execute("SELECT description FROM enums WHERE name='status' AND value=6").fetchone() == ("Exact solution",)
    assert con.execute("SELECT description FROM enums WHERE name='twb_outcome' AND value=0").fetchone() == ("success",)
    con.close()
    done = export_ompl(load_study(study_dir), tmp_path / "again.db")
    assert done["runs"] == 4 and done["progress"] == 0


def test_export_ompl_command(capsys, monkeypatch, study_dir, tmp_path):
    r = invoke(capsys, monkeypatch, "export-ompl", str(study_dir), "--out", str(tmp_path / "x.db"))
    assert r.returncode == 0, r.stderr
    assert "1 experiments (room-A), 4 planner configurations, 4 runs added; version 'Teleworkbench 0.1.0'" in r.stdout
    r = invoke(capsys, monkeypatch, "export-ompl", str(study_dir))  # study.db is there: kept
    assert r.returncode == 2 and "study.db exists: --append adds the runs to it" in r.stderr
    r = invoke(capsys, monkeypatch, "export-ompl", str(study_dir), "--out", str(tmp_path / "x.db"), "--replace")
    assert r.returncode == 0 and "4 runs added;" in r.stdout
    r = invoke(capsys, monkeypatch, "export-ompl", str(tmp_path))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "is not a study directory" in r.stderr


def test_twb_study_keeps_an_existing_ompl_database(capsys, monkeypatch, testbed, tmp_path):
    db = tmp_path / "ompl.db"
    db.write_text("someone's benchmark\n")
    spec = tmp_path / "tiny.json"
    spec.write_text(json.dumps({**SMALL, "name": "tiny", "planners": ["fmm"], "modes": ["sim"]}))
    r = invoke(capsys, monkeypatch, "study", str(spec), "--out", str(tmp_path / "out"), "--ompl", str(db),
               "--url", testbed.url, "--token", testbed.token, "--no-progress")
    assert r.returncode == 2 and "ompl.db exists: --ompl-append adds the runs to it" in r.stderr
    r = invoke(capsys, monkeypatch, "study", str(spec), "--out", str(tmp_path / "out"), "--ompl", str(db),
               "--ompl-append", "--url", testbed.url, "--token", testbed.token, "--no-progress")
    assert r.returncode == 2 and "ompl.db is not an SQLite database" in r.stderr
    assert not (tmp_path / "out" / "runs.csv").exists()  # refused before anything ran
    assert db.read_text() == "someone's benchmark\n"


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


def test_every_experiment_keeps_the_study_seed_and_gets_its_own_planner_seed():
    """Common random numbers for the noise (every experiment the study's seed: repetition k of every
    configuration and problem drives with the same noise and start jitter), a planner seed of its own per
    configuration x problem (docs/study.md, "Seeds"), stable."""
    from client_sdk.study import study_planner_seed

    spec = paper_spec()
    envs = {n: Environment(n, [1.8, 1.8], [], [Plan("A", [0.1, 0.1], [1, 1]), Plan("B", [0.2, 0.2], [1, 1])])
            for n in ("room", "blocks")}
    jobs = plan_jobs(spec, envs)
    assert {j["body"]["seed"] for j in jobs} == {spec.seed}
    seeds = [j["body"]["planner_seed"] for j in jobs]
    assert len(set(seeds)) == len(jobs) and all(0 <= s < 2**63 for s in seeds)
    for j in jobs:
        assert j["body"]["planner_seed"] == study_planner_seed(spec.seed, j["configuration"], j["environment"],
                                                               j["plan"])
    assert seeds == [j["body"]["planner_seed"] for j in plan_jobs(spec, envs)]
    other = plan_jobs(StudySpec.from_json({**spec.to_json(), "seed": 1}), envs)
    assert not set(seeds) & {j["body"]["planner_seed"] for j in other}


def test_the_controller_study_crosses_every_builtin_with_one_planner():
    spec = load_spec("controllers")
    envs = {n: Environment(n, [1.8, 1.8], [], [Plan("A", [0.1, 0.1], [1, 1]), Plan("B", [0.2, 0.2], [1, 1])])
            for n in ("room", "blocks")}
    jobs = plan_jobs(spec, envs)
    assert len(jobs) == 16 and len(jobs) * spec.runs_per_experiment == 64 and spec.jitter is not None
    assert [j["configuration"] for j in jobs[:4]] == ["fmm/schema", "fmm/pure_pursuit", "fmm/regulated_pure_pursuit",
                                                       "fmm/kanayama"]
    assert jobs[1]["body"]["controller"] == "pure_pursuit" and jobs[1]["controller"] == "pure_pursuit"
    assert StudySpec.from_json(spec.to_json()) == spec
    assert "controller" not in plan_jobs(paper_spec(), envs)[0]["body"]  # studies without controllers: as before
    tuned = StudySpec.from_json({**SMALL, "controllers": [{"name": "pure_pursuit", "params": {"lookahead_m": 0.1}}]})
    assert tuned.configurations()[0][2] == "fmm/pure_pursuit(lookahead_m=0.1)"


def test_twb_study_controllers_groups_by_controller(testbed, tmp_path):
    import csv
    import os
    import subprocess
    import sys
    from pathlib import Path

    out = tmp_path / "controllers"
    twb = Path(sys.executable).with_name("twb")
    r = subprocess.run([str(twb), "study", "controllers", "--out", str(out), "--url", testbed.url, "--token",
                        testbed.token, "--no-progress"], capture_output=True, text=True, timeout=600,
                       env={k: v for k, v in os.environ.items() if k != "TWB_DEBUG"})
    assert r.returncode == 0, r.stderr
    assert "study controllers: 64/64 runs completed" in r.stdout
    rows = list(csv.DictReader((out / "runs.csv").open()))
    assert {row["controller"] for row in rows} == {"schema", "pure_pursuit", "regulated_pure_pursuit", "kanayama"}
    assert {row["configuration"] for row in rows} == {"fmm/schema", "fmm/pure_pursuit", "fmm/regulated_pure_pursuit",
                                                      "fmm/kanayama"}
    assert all(float(row["spl"]) > 0.9 and row["stop_count"] == "0" for row in rows)
    summary = (out / "summary.md").read_text()
    assert "## Which configuration is better?" in summary and "fmm/kanayama" in summary
    assert "mean cross-track error" in summary  # the controller metrics are compared too
    comparisons = {row["metric"] for row in csv.DictReader((out / "comparisons.csv").open())}
    assert {"cross_track_error_mean_m", "heading_error_rms_rad", "time_to_goal_s", "jerk_linear_rms_m_s3"} <= comparisons


def test_environment_files_are_read_relative_to_the_study_file(tmp_path):
    (tmp_path / "envs").mkdir()
    env = {"name": "narrow", "size": [1.8, 1.8], "blocks": []}
    (tmp_path / "envs" / "narrow.json").write_text(json.dumps(env))
    f = tmp_path / "s.json"
    f.write_text(json.dumps({"environments": ["room", "envs/narrow.json"], "planners": ["fmm"]}))
    assert load_spec(f).environments == ["room", env]
    f.write_text(json.dumps({"environments": ["missing.json"], "planners": ["fmm"]}))
    with pytest.raises(StudySpecError, match=r"environments\[0\]: cannot read environment file .*missing.json "
                                             r"\(paths are relative to the study file\)"):
        load_spec(f)


@pytest.mark.parametrize("content,message", [
    ("{not json", "invalid JSON"),
    ('{"environments": ["room"]}', "`planners` must be a non-empty list"),
    ('{"environments": ["room"], "planners": ["fmm"], "repetitons": 2}', "unknown key(s) repetitons"),
    ('{"environments": ["room"], "planners": ["fmm"], "modes": ["real"]}', "`modes` must be a list"),
    ('[1, 2]', "must be a JSON object"),
    ('{"environments": ["room"], "planners": ["fmm"], "controllers": []}', "`controllers` must be a non-empty list"),
    ('{"environments": ["room"], "planners": ["fmm"], "controllers": [{"name": "pure_pursuit", "gain": 1}]}',
     "unknown key(s) gain (allowed: label, name, params)"),
    ('{"environments": ["room"], "planners": ["fmm"], "controllers": ["kanayama", "kanayama"]}',
     "repeats controllers"),
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


@pytest.mark.slow
def test_embedded_study(twb, tmp_path):
    """An embedded study whose environment is a file next to the study file (issue 32: "unknown environment
    'narrow.json'"), run from another directory."""
    (tmp_path / "studies" / "envs").mkdir(parents=True)
    (tmp_path / "out-of-the-way").mkdir()
    (tmp_path / "studies" / "envs" / "narrow.json").write_text(json.dumps(
        {"name": "narrow", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.06, "h": 0.9}],
         "plans": [{"name": "A", "start": [0.3, 0.9, 0.0], "goal": [1.5, 0.9, 0.0]}]}))
    f = tmp_path / "studies" / "tiny.json"
    f.write_text(json.dumps({"name": "tiny", "environments": ["envs/narrow.json"], "plans": ["A"],
                             "planners": ["fmm"], "modes": ["sim"], "repetitions": 1}))
    r = twb("study", str(f), "--embedded", "--out", str(tmp_path / "out"), "--no-progress", timeout=180,
            cwd=str(tmp_path / "out-of-the-way"))
    assert r.returncode == 0, r.stderr
    assert "study tiny: 1/1 runs completed" in r.stdout
    assert (tmp_path / "out" / "fig8_paths.png").exists()
    log = (tmp_path / "out" / "testbed" / "stdout.log").read_text()
    assert "Teleworkbench is up" in log and "Traceback" not in log
    # before the kernels load, twb up says what it is waiting for (nothing else shows until the banner)
    assert 0 <= log.find("twb: starting the testbed (the first start after installing compiles the simulation "
                         "kernels") < log.find("Teleworkbench is up")


# ----------------------------------------------------------------------------- failures are results

#: a block in the middle; the explicit path turns 6 cm below it: the ideal robot follows it, the field robot
#: overshoots the corner into the block (docs/study.md, the worked example)
OVERSHOOT = {
    "name": "overshoot",
    "description": "A planner that only fails on the field",
    "environments": [{"name": "overshoot", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.3, "h": 0.3}],
                      "plans": [{"name": "A", "start": [0.9, 0.3, 1.5708], "goal": [1.5, 0.69, 0.0]}]}],
    "planners": ["fm2", {"name": "corner", "waypoints": [[0.9, 0.69]]}],
    "repetitions": 5, "modes": ["sim", "twb"], "seed": 0, "jitter": {"xy_m": 0.005, "theta_rad": 0.02},
}


@pytest.fixture(scope="module")
def overshoot_dir(testbed, tmp_path_factory):
    r, out = study_process(testbed, OVERSHOOT, tmp_path_factory.mktemp("overshoot"), "--no-progress")
    assert r.returncode == 0, r.stderr  # failed runs are results, not errors
    assert "study overshoot: 15/20 runs completed, 5 failed (collision 5)" in r.stdout, r.stdout
    return out


def test_failed_field_runs_are_in_runs_csv_with_outcome_and_where_they_stopped(overshoot_dir):
    data = load_study(overshoot_dir)
    crashed = [r for r in data.rows if r["configuration"] == "corner" and r["mode"] == "twb"]
    assert len(crashed) == 5
    for r in crashed:
        assert r["status"] == "failed" and r["outcome"] == "collision" and r["failure"] == "collision"
        if r["stopped_at_x"] is not None:  # (at --time-scale max the server occasionally misses it)
            assert 0.75 < r["stopped_at_x"] < 1.06 and 0.68 < r["stopped_at_y"] < 0.75  # at the block's lower face (x 0.75-1.05)
        assert r["length_m"] > 0.3 and r["collided"] is True  # its metrics are kept, flagged by the outcome
        assert data.poses(r["run_id"]).shape[0] > 10  # and its poses, up to where it stopped
    assert any(r["stopped_at_x"] is not None for r in crashed)
    assert all(r["outcome"] == "success" for r in data.rows if r not in crashed)
    header = (overshoot_dir / "runs.csv").read_text().splitlines()[0].split(",")
    assert header[:18] == ["study", "experiment_id", "run_id", "environment", "plan", "planner", "controller",
                           "configuration", "mode", "repetition", "seed", "planner_seed", "status", "outcome",
                           "failure", "error", "stopped_at_x", "stopped_at_y"]
    for k in ("planning_time_s", "planning_cpu_s", "planning_repeats", "planning_load", "planned_length_m"):
        assert k in header, k


def test_summary_says_which_planner_is_better_and_keeps_the_failures(overshoot_dir):
    summary = (overshoot_dir / "summary.md").read_text()
    answer = summary[summary.index("## Which planner is better?"):summary.index("## Outcomes per configuration")]
    assert "**On the field (Teleworkbench):** FM² is better than corner on the field on overshoot A: it reached the " \
           "goal significantly more often. (One problem: its answer says nothing about other problems.)" in answer
    assert "corner reached the goal in 0 of 5 runs (95% CI 0–43 %); collided 5 times." in answer
    assert "5/5 vs 0/5" in answer and "Fisher's exact p = 0.0079, Holm-adjusted p = 0.016" in answer
    assert "| corner | twb | 5 | 0 | 5 | 0 | 0 | 0 | 0/5 (95% CI 0–43 %) |" in summary
    assert "| corner | twb | 0 of 5 | no completed run |" in summary  # still in the table, not dropped
    assert "| overshoot | A | corner | 5/5 |" in summary and "0/5, collision 5" in summary
    html = (overshoot_dir / "report.html").read_text()
    assert html.index("id='which-is-better'") < html.index("<figure>")
    assert "it reached the goal significantly more often" in html and "collided 5 times" in html


def test_comparisons_csv_has_the_fisher_row(overshoot_dir):
    import csv

    with open(overshoot_dir / "comparisons.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0])[:14] == ["metric", "mode", "a", "b", "n_a", "n_b", "mean_a", "mean_b", "diff", "ci_low",
                                  "ci_high", "test", "p", "p_holm"]
    rate = next(r for r in rows if r["metric"] == "success_rate" and r["mode"] == "twb")
    assert (rate["a"], rate["b"], rate["n_a"], rate["n_b"], rate["test"]) == ("fm2", "corner", "5", "5", "fisher-exact")
    assert round(float(rate["p"]), 4) == 0.0079 and float(rate["diff"]) == 1.0 and float(rate["ci_low"]) > 0
    length = next(r for r in rows if r["metric"] == "length_m" and r["mode"] == "twb")
    assert length["p"] == "" and length["note"] == "no completed run of corner"
    sim = next(r for r in rows if r["metric"] == "length_m" and r["mode"] == "sim")
    assert sim["test"] == "paired-t" and sim["paired"] == "true" and float(sim["ci_low"]) < float(sim["diff"]) < 0


def test_the_sdk_gives_the_same_numbers(overshoot_dir):
    import csv

    data = load_study(overshoot_dir)
    comps = data.compare()
    c = comps.get("success_rate", "twb", "fm2", "corner")
    assert c.pvalue == pytest.approx(2 / 252) and c.statistic == math.inf  # odds ratio of 5/5 against 0/5
    with open(overshoot_dir / "comparisons.csv", newline="") as f:
        for row, comp in zip(csv.DictReader(f), comps):
            assert (row["metric"], row["mode"]) == (comp.metric, comp.mode)
            if row["ci_low"]:
                assert float(row["ci_low"]) == pytest.approx(comp.confidence_interval().low)
                assert float(row["p_holm"]) == pytest.approx(comp.pvalue_holm)


def test_figures_show_the_crashed_path_and_no_completed_run(overshoot_dir):
    assert orange_pixels(overshoot_dir / "fig8_paths.png") > 300  # five crashed paths and their crosses
    figs = make_figures(load_study(overshoot_dir))
    fig8 = figs["fig8_paths"]
    crashed = [ln for ax in fig8.axes for ln in ax.get_lines() if ln.get_color() == "#ff7f0e"]
    crosses = [x for ln in crashed if ln.get_marker() == "x" for x in ln.get_xdata()]  # one marker line a panel
    assert len(crosses) == 5 and all(0.75 < x < 1.06 for x in crosses)  # stopped_at, or the last pose
    paths = [c for ax in fig8.axes for c in ax.collections if c.get_label().startswith("failed run")]
    assert sum(len(c.get_segments()) for c in paths) == 5  # the five crashed paths, up to where they stopped
    assert all("failed" not in t.get_text() for ax in fig8.axes for t in ax.texts if t.get_text() == "failed")
    assert any("T: collision 5/5" in t.get_text() for ax in fig8.axes for t in ax.texts)
    fig6_texts = [t.get_text() for ax in figs["fig6_metrics"].axes for t in ax.texts]
    assert fig6_texts.count("no completed run") == 6  # one per metric panel: corner on the field
    ticks = [t.get_text() for t in figs["fig6_metrics"].axes[0].get_xticklabels()]
    assert ticks == ["FM²\nS 5/5 · T 5/5", "corner\nS 5/5 · T 0/5"]
    outcome_labels = [t.get_text() for t in figs["fig5_outcomes"].axes[0].texts]
    assert outcome_labels.count("0/5 succeeded") == 1 and outcome_labels.count("5/5 succeeded") == 3


def test_a_study_above_the_limits_is_refused_with_the_reason(capsys, monkeypatch, testbed, tmp_path):
    f = tmp_path / "big.json"
    f.write_text(json.dumps({**SMALL, "repetitions": 1000, "planners": ["fmm", "rrt"]}))
    with testbed.client() as c:
        before = c.get("/api/v1/experiments?limit=1").json()["count"]
    r = invoke(capsys, monkeypatch, "study", str(f), "--url", testbed.url, "--token", testbed.token, "--out",
               str(tmp_path / "o"), "--no-progress")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r
    assert r.stderr.startswith(f"twb: error: study 'small' refused by the testbed at {testbed.url}: planner 'rrt' "
                               "is not offered by this testbed (it offers "), r.stderr
    f.write_text(json.dumps({**SMALL, "repetitions": 1000, "planners": ["fmm", "rrt", {"name": "fm2",
                                                                                        "params": {"speed": 2}}]}))
    r = invoke(capsys, monkeypatch, "study", str(f), "--url", testbed.url, "--token", testbed.token, "--out",
               str(tmp_path / "o"), "--no-progress")
    assert r.returncode == 2, r  # every reason at once, one a line
    assert "twb: refused: planner 'rrt' is not offered" in r.stderr and "twb: refused: planner 'fm2' has no " \
        "parameter(s) speed" in r.stderr and r.stderr.splitlines()[-1].endswith("nothing was run (2 reasons above)")
    f.write_text(json.dumps({**SMALL, "repetitions": 1000}))
    r = invoke(capsys, monkeypatch, "study", str(f), "--url", testbed.url, "--token", testbed.token, "--out",
               str(tmp_path / "o"), "--no-progress")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r
    assert "repetitions 1000: the testbed allows at most 20 per experiment (repetitions must be at most 20)" \
        in r.stderr
    with testbed.client() as c:
        assert c.get("/api/v1/experiments?limit=1").json()["count"] == before  # nothing was submitted


def test_a_study_where_nothing_ran_exits_non_zero(capsys, monkeypatch, testbed, tmp_path):
    f = tmp_path / "walls.json"
    f.write_text(json.dumps({**SMALL, "plans": [{"name": "in-wall", "start": [0.9, 0.9], "goal": [1.5, 1.5]}],
                             "environments": [OVERSHOOT["environments"][0]], "modes": ["sim"]}))
    r = invoke(capsys, monkeypatch, "study", str(f), "--url", testbed.url, "--token", testbed.token, "--out",
               str(tmp_path / "o"), "--no-progress")
    assert r.returncode == 1, r
    refusals = [ln for ln in r.stderr.splitlines() if ln.startswith("twb: refused: overshoot in-wall")]
    assert len(refusals) == 2 and "inside an obstacle" in refusals[0]
    assert "2 job(s) refused (2 runs not submitted)" in r.stdout and "nothing ran" in r.stderr
    summary = (tmp_path / "o" / "summary.md").read_text()
    assert "| fmm | sim | 1 | 0 | 0 | 0 | 0 | 1 | no counted run |" in summary  # refused, still listed
