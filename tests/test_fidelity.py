"""Field fidelity: the paper's findings on a reduced study and on synthetic data, the field robot's
localisation (latency compensation, dead reckoning, the pose it steers by), its tracker's error model,
and its corners (docs/fidelity.md)."""

from __future__ import annotations

import csv
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from agent_support import CORNERS, densify

from client_sdk.study import FINDINGS, StudyData, StudySpec, findings_markdown, paper_findings, write_findings
from planners.metrics import path_length, smoothness
from robot_agent.engine.backends import FieldBackend, make_backend
from robot_agent.engine.cores import layout_core
from robot_agent.engine.kinematics import tracks_to_body, unicycle_step
from robot_agent.engine.noise import path_key
from contract.params import robot_params
from robot_agent.engine.physics import tracker_bias
from contract.robot_profile import load_profile
from robot_agent.engine.sim import SimCore, State

P = robot_params()
ROOT = Path(__file__).resolve().parent.parent

# ---------------------------------------------------------------- the findings on a reduced study

REDUCED = {"name": "reduced", "environments": ["room"], "plans": ["A", "B"], "planners": ["fmm", "fm2", "prm"],
           "repetitions": 1, "modes": ["sim", "twb"]}


@pytest.mark.slow
def test_a_reduced_study_checks_every_claim_as_the_offline_runs_do(twb, tmp_path):
    """Room A and B, FMM, FM² and PRM, one repetition (12 runs) on an embedded testbed at maximum speed.

    Twelve runs are too few for every claim (one run per planner and mode): on seed 0, 16 of the 18 hold —
    FMM's field run deviates 7 mm more than its simulated one, PRM's 3 mm (not "almost constant"), and PRM's
    field length ratio is 0.996.  bench/fidelity.py runs the paper's study (48 runs) offline for seeds 0-19:
    every claim holds in at least 18 (docs/fidelity.md); :func:`test_the_paper_study_holds_every_claim`."""
    spec = tmp_path / "reduced.json"
    spec.write_text(json.dumps(REDUCED))
    out = tmp_path / "out"
    r = twb("study", str(spec), "--embedded", "--out", str(out), "--no-progress", "--seed", "0", timeout=300)
    assert r.returncode == 0, r.stderr
    assert "study reduced: 12/12 runs completed" in r.stdout
    n = len(FINDINGS)
    assert f"The paper's findings on this study: {n - 2} of {n} held" in r.stdout
    assert "Sim-to-field predictivity, 3 configurations" in r.stdout
    assert (out / "predictivity.md").is_file() and (out / "predictivity.png").is_file()
    doc = json.loads((out / "findings.json").read_text())
    assert [f["key"] for f in doc["findings"]] == list(FINDINGS)
    assert doc["applicable"] == n and doc["held"] == n - 2
    assert [f["key"] for f in doc["findings"] if not f["held"]] == ["deviation_gap_constant", "field_length_ratio_above_1"]
    assert json.loads((out / "study.json").read_text())["spec"]["seed"] == 0
    md = (out / "findings.md").read_text()
    assert md.count("| held |") == n - 2 and "Path length deviation shows similar results" in md
    # bench/fidelity.py's offline runs are these runs: the same metrics, run for run
    offline = {_run_key(r): r for r in _bench().study_data(StudySpec.from_json(REDUCED, "reduced")).rows}
    with open(out / "runs.csv", newline="") as f:
        online = list(csv.DictReader(f))
    assert len(online) == len(offline) == 12
    for row in online:
        mine = offline[_run_key(row)]
        for key in ("length_m", "smoothness_rad", "deviation_mean_m", "clearance_min_m", "execution_time_s"):
            assert float(row[key]) == pytest.approx(mine[key], rel=1e-4, abs=1e-6), (_run_key(row), key)


def test_the_paper_study_holds_every_claim_on_seed_0_and_seed_2_misses_one():
    """The paper's study (48 runs) offline: with seed 0 all 18 checks hold, as measured for docs/fidelity.md
    (each claim holds in at least 18 of the seeds 0-19). Seed 2 misses one, claim 12, by a hair: the field
    changes FMM's κ' ratio by 0.068 and PRM's by 0.069, so PRM's is not the least difference."""
    found = paper_findings(_bench().paper(0))
    assert len(found) == len(FINDINGS)
    assert not {f.key: f.detail for f in found if not f.held}
    missed = {f.key: f.detail for f in paper_findings(_bench().paper(2)) if not f.held}
    assert set(missed) == {"prm_least_smoothness_difference"}, missed


def _run_key(row: dict) -> tuple:
    return row["environment"], row["plan"], row["planner"], row["mode"], int(row["repetition"])


def _bench():
    """bench/fidelity.py as a module (bench/ is not an installed package)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import bench.fidelity

    return bench.fidelity


def test_offline_a_planning_failure_fails_the_experiment_as_the_testbed_does():
    """A deterministic planner that finds no path fails the whole experiment, every run of it."""
    wall = {"name": "wall", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.06, "h": 1.8}]}
    spec = StudySpec.from_json({**REDUCED, "environments": [wall], "repetitions": 2, "planners": ["fmm"],
                                "plans": [{"name": "across", "start": [0.3, 0.9], "goal": [1.5, 0.9]}]}, "tiny")
    data = _bench().study_data(spec)
    (exp,) = data.experiments
    assert exp["status"] == "failed" and exp["error"].startswith("planning failed: ") and exp["planned_path"] is None
    assert [(r["mode"], r["status"], r["error"]) for r in data.rows] == [("sim", "failed", exp["error"]),
                                                                         ("twb", "failed", exp["error"])] * 2
    assert [f.held for f in paper_findings(data)] == [None] * len(FINDINGS)
    # the bench counts the failed runs by reason, per planner and mode, and sums them over seeds
    kinds = {"fmm/sim": {exp["error"]: 2}, "fmm/twb": {exp["error"]: 2}}
    assert _bench().failures(data) == kinds
    seed = {"seed": 0, "runs": len(data.rows), "held": {}, "details": {}, "means": {}, "corners": {}, "failures": kinds}
    summary = _bench().summarize([seed, {**seed, "seed": 1}])
    assert summary["failed_runs"] == {"fmm/sim": {exp["error"]: 4}, "fmm/twb": {exp["error"]: 4}}
    assert summary["runs_per_seed"] == [4, 4]


def test_offline_a_randomised_planner_fails_the_repetitions_its_seeds_find_no_path_for():
    """PRM with ten samples plans each repetition with its own planner seed, as the testbed does: the
    repetitions whose seed finds no path fail (both modes), the others are driven."""
    from planners import PlanningError, load_environment, plan_path
    from server.store.experiments import planner_seed

    fid = _bench()
    spec = StudySpec.from_json({**REDUCED, "plans": ["A"], "repetitions": 6,
                                "planners": [{"name": "prm", "params": {"samples": 10, "grow": False}}]}, "tiny")
    data = fid.study_data(spec)
    (exp,) = data.experiments
    start, goal = load_environment("room").plan("A").start, load_environment("room").plan("A").goal
    base = fid.study_planner_seed(0, spec.planners[0].configuration, "room", "A")
    found = {}
    for rep in range(1, 7):
        try:
            plan_path("room", start, goal, "prm", robot_radius=fid.ROBOT_RADIUS + fid.PLANNING_MARGIN,
                      params={"samples": 10, "grow": False}, seed=planner_seed(base, rep))
            found[rep] = True
        except PlanningError:
            found[rep] = False
    assert set(found.values()) == {True, False}, found  # both kinds (a fixed property of this study)
    for r in data.rows:
        assert (r["error"].startswith("planning failed: PRM found no path") and r["status"] == "failed") \
            is not found[r["repetition"]], r
    assert exp["status"] == "failed" and set(exp["repetition_paths"]) == {str(k) for k, v in found.items() if v}


def test_offline_varied_environments_and_their_random_problems():
    fid = _bench()
    for env in fid.varied_environments():
        plans = fid.random_plans(env, 5, seed=3)
        assert plans == fid.random_plans(env, 5, seed=3)  # seeded
        for plan in plans:
            assert math.dist(plan["start"][:2], plan["goal"][:2]) >= 0.9
    assert [e["name"] for e in fid.varied_environments()] == ["corridors", "clutter", "open", "zigzag"]
    # more pairs per environment (bench/fidelity.py --plans) keep the first ones: a larger study adds problems
    env = fid.generated_environments(4)[0]
    assert fid.random_plans(env, 6, seed=7)[:3] == fid.random_plans(env, 3, seed=7)


def test_fidelity_bench_takes_the_number_of_problems_per_environment():
    """``--plans`` reaches the study (one start/goal pair per generated environment: 2 problems x 3 planners x 2
    repetitions x 2 modes = 24 runs), and so does ``--planner`` (FM²'s corners not cut: its computed paths' corners
    differ from those of the same study at FM²'s defaults, the other planners' do not); a number of plans below 1 and a
    planner parameter the planner does not have are refused before anything runs."""
    import subprocess

    script = [sys.executable, str(Path(__file__).resolve().parents[1] / "bench" / "fidelity.py"), "generated"]
    out = subprocess.run([*script, "--seeds", "3", "--plans", "1", "--workers", "1", "--planner", "fm2.round=0"],
                         capture_output=True, text=True, check=True)
    summary = json.loads(out.stdout)
    assert summary["seeds"] == [3] and summary["runs_per_seed"] == [24] and set(summary["held"]) == set(FINDINGS)
    assert summary["planner_params"] == {"fm2": {"round": 0}}
    plain = {p: {k: round(v, 2) for k, v in c.items()}
             for p, c in _bench().corners(_bench().generated(3, plans_per_env=1)).items()}
    assert summary["computed_paths"]["fm2"] != plain["fm2"]
    assert {p: summary["computed_paths"][p] for p in ("fmm", "prm")} == {p: plain[p] for p in ("fmm", "prm")}
    bad = subprocess.run([*script, "--plans", "0"], capture_output=True, text=True)
    assert bad.returncode == 2 and "--plans must be at least 1" in bad.stderr
    bad = subprocess.run([*script, "--planner", "fm2.rounds=3"], capture_output=True, text=True)
    assert bad.returncode == 2 and "planner 'fm2' has no parameter 'rounds'" in bad.stderr


# ---------------------------------------------------------------- the checks, on synthetic data

#: per planner: computed length, clearance, κ'; per mode: length ratio, κ' ratio (PRM's on the field: its own),
#: deviation, maximum deviation, seconds per planned metre, speed, clearance drop
_PLANNED = {"fmm": (1.9, 0.07, 0.14), "fm2": (2.4, 0.15, 0.13), "prm": (2.1, 0.07, 0.25)}
_MODES = {"sim": dict(length_ratio=0.99, smooth=0.95, deviation_mean_m=0.003, deviation_max_m=0.02, s_per_m=6.0,
                      average_speed_m_s=0.17, clearance_drop=0.0),
          "twb": dict(length_ratio=1.01, smooth=1.05, deviation_mean_m=0.007, deviation_max_m=0.025, s_per_m=7.0,
                      average_speed_m_s=0.15, clearance_drop=0.004)}
_PRM_FIELD_SMOOTH = 0.9  # PRM's T κ' ratio: below 1, below S's 0.95, and closer to S than the others' 1.05


def _study(change=None) -> StudyData:
    """Two experiments per planner, one run per mode each, with numbers that make every finding hold;
    ``change(planner, mode, row)`` edits a row (mode "planned" for the computed path's numbers)."""
    rows, direct, experiments = [], [], []
    rid = 0
    for eid, (planner, plan) in enumerate([(p, x) for p in _PLANNED for x in "AB"], 1):
        length, clearance, kappa = _PLANNED[planner]
        planned = {"planned_length_m": length, "planned_clearance_min_m": clearance, "planned_smoothness_rad": kappa}
        if change:
            change(planner, "planned", planned)
        experiments.append({"experiment_id": eid, "environment": "room", "plan": plan, "planner": planner})
        for mode, m in _MODES.items():
            rid += 1
            smooth = _PRM_FIELD_SMOOTH if planner == "prm" and mode == "twb" else m["smooth"]
            clear = planned["planned_clearance_min_m"] - m["clearance_drop"]
            row = {"experiment_id": eid, "run_id": rid, "environment": "room", "plan": plan, "planner": planner,
                   "mode": mode, "repetition": 1, "status": "completed", **planned,
                   "length_ratio": m["length_ratio"], "length_m": m["length_ratio"] * planned["planned_length_m"],
                   "smoothness_rad": smooth * planned["planned_smoothness_rad"],
                   "deviation_mean_m": m["deviation_mean_m"], "deviation_max_m": m["deviation_max_m"],
                   "execution_time_s": m["s_per_m"] * planned["planned_length_m"],
                   "average_speed_m_s": m["average_speed_m_s"], "clearance_min_m": clear,
                   "clearance_ratio": clear / planned["planned_clearance_min_m"]}
            if change:
                change(planner, mode, row)
            rows.append(row)
        direct.append({"experiment_id": eid, "planner": planner, "repetition": 1, "deviation_mean_m": 0.005})
    spec = StudySpec.from_json({"name": "synthetic", "environments": ["room"], "planners": list(_PLANNED)})
    return StudyData(spec, {}, experiments, rows, direct)


def _held(data: StudyData) -> dict:
    return {f.key: f.held for f in paper_findings(data)}


def test_every_finding_holds_on_data_made_to_hold_them():
    found = paper_findings(_study())
    assert [f.key for f in found] == list(FINDINGS)
    assert all(f.held is True for f in found), [(f.key, f.detail) for f in found if not f.held]
    by = {f.key: f for f in found}
    assert by["length_similar"].numbers == {"fmm_sim_length_ratio": 0.99, "fmm_twb_length_ratio": 1.01,
                                            "fm2_sim_length_ratio": 0.99, "fm2_twb_length_ratio": 1.01,
                                            "prm_sim_length_ratio": 0.99, "prm_twb_length_ratio": 1.01}
    assert by["prm_smoother_on_field"].numbers["prm_twb_smoothness_ratio"] == pytest.approx(0.9)
    assert by["field_less_clearance"].numbers["prm_twb_clearance_min_m"] == pytest.approx(0.066)
    assert by["field_length_ratio_above_1"].numbers == {"fmm_twb_length_ratio": 1.01, "fm2_twb_length_ratio": 1.01,
                                                        "prm_twb_length_ratio": 1.01}
    assert by["deviations_differ_across_planners"].numbers["differ_in"] == ["clearance_min_m", "smoothness_rad"]


def _set(planner_or_all, mode, **values):
    def change(planner, m, row):
        if m == mode and planner_or_all in (planner, "all"):
            row.update(values)
    return change


def _both(*changes):
    def change(planner, m, row):
        for c in changes:
            c(planner, m, row)
    return change


@pytest.mark.parametrize("keys, change", [
    ("fmm_shortest", _set("prm", "planned", planned_length_m=1.8)),
    ("fm2_safest", _set("fmm", "planned", planned_clearance_min_m=0.15)),
    ("prm_sharpest", _set("fm2", "planned", planned_smoothness_rad=0.3)),
    # the simulated robot drives longer than its plan: also no longer shorter than the field robot (Fig. 7)
    (("sim_follows_plan", "field_ratios_worse"), _set("fm2", "sim", length_ratio=1.04)),
    ("sim_follows_plan", _both(_set("prm", "sim", deviation_mean_m=0.011), _set("prm", "twb", deviation_mean_m=0.015))),
    ("field_slower", _set("fmm", "twb", execution_time_s=11.0)),
    ("field_slower", _set("prm", "twb", average_speed_m_s=0.18)),
    ("slowdown_differs", _both(_set("fmm", "twb", execution_time_s=13.4), _set("fm2", "twb", execution_time_s=16.4),
                               _set("prm", "twb", execution_time_s=14.6))),  # 2 s slower each
    # a planner whose field robot deviates less cannot have an almost constant gap with the others
    (("field_deviates_more", "deviation_gap_constant"), _set("fm2", "twb", deviation_mean_m=0.002)),
    ("deviation_gap_constant", _set("prm", "twb", deviation_mean_m=0.012)),  # gaps 4, 4, 9 mm
    ("field_less_clearance", _set("prm", "twb", clearance_min_m=0.07)),  # one planner's is enough
    ("length_similar", _both(_set("prm", "twb", length_ratio=1.05), _set("prm", "sim", length_ratio=0.98))),
    ("smoothness_not_reproduced", _both(_set("fm2", "twb", smoothness_rad=0.13),  # FM²'s ratio 1: reproduced
                                        _set("prm", "twb", smoothness_rad=0.25 * 0.93))),
    ("prm_least_smoothness_difference", _set("fmm", "sim", smoothness_rad=0.14 * 1.04)),  # FMM's 0.01 apart
    ("field_length_ratio_above_1", _set("prm", "twb", length_ratio=0.995)),  # the failure on main
    ("prm_smoother_on_field", _both(_set("prm", "sim", smoothness_rad=0.25 * 1.1),  # T 1.05 < S 1.1, not < 1
                                    _set("prm", "twb", smoothness_rad=0.25 * 1.05))),
    # FM²'s T ratio below PRM's: then also below 1 and below its S ratio
    (("prm_smoother_on_field", "smoothness_not_reproduced", "field_ratios_worse"),
     _set("fm2", "twb", smoothness_rad=0.13 * 0.85)),
    ("field_overshoots_more", _set("fm2", "twb", deviation_max_m=0.019)),
    ("field_paths_longer", _set("prm", "twb", length_m=2.0)),
])
def test_each_finding_fails_when_its_comparison_does(keys, change):
    keys = (keys,) if isinstance(keys, str) else keys
    held = _held(_study(change))
    assert all(held[k] is False for k in keys), held
    assert all(v for k, v in held.items() if k not in keys), held


def test_a_field_that_changes_every_planner_alike_fails_the_planner_dependence():
    """A field whose metrics are the simulation's times one factor, the same for every planner, except PRM's κ'
    (which goes the other way): one metric whose gaps differ is not enough, finding 18 fails; the data made to
    hold every finding (its clearance drop, 4 mm, a different share of each planner's clearance) holds it."""
    def alike(planner, mode, row):
        if mode == "twb":
            factor = {"smoothness_rad": 1.05 / 0.95, "clearance_min_m": 0.95, "execution_time_s": 7 / 6}
            for k, f in factor.items():
                row[k] = row[k] * f if k != "clearance_min_m" else row["planned_clearance_min_m"] * f
    held = _held(_study(alike))
    assert held["deviations_differ_across_planners"] is False
    assert _held(_study())["deviations_differ_across_planners"] is True


def test_length_similar_just_inside_the_threshold():
    assert _held(_study(_set("prm", "twb", length_ratio=1.035)))["length_similar"] is True  # 0.045 apart


def test_findings_need_their_planners_and_modes():
    no_prm = _study()
    no_prm.rows = [r for r in no_prm.rows if r["planner"] != "prm"]
    held = _held(no_prm)
    assert held["fmm_shortest"] is held["prm_sharpest"] is held["prm_smoother_on_field"] is None
    assert held["length_similar"] is True and held["field_length_ratio_above_1"] is True
    assert held["prm_least_smoothness_difference"] is None
    sim_only = _study()
    sim_only.rows = [r for r in sim_only.rows if r["mode"] == "sim"]
    held = _held(sim_only)
    assert held["sim_follows_plan"] is True and held["fm2_safest"] is True
    for key in FINDINGS:
        if key not in ("fmm_shortest", "fm2_safest", "prm_sharpest", "sim_follows_plan"):
            assert held[key] is None, key
    failed = _study()
    for r in failed.rows:
        r["status"] = "failed"
    assert all(v is None for v in _held(failed).values())


def test_findings_compare_the_modes_on_the_same_paths():
    """PRM's experiment B has a second repetition with a much longer path (a randomised planner plans each its own)
    whose field run failed: its simulated run is left out too, so the field's mean path is not the shorter for
    having lost a long path (unpaired, T 2.121 m < S 2.771 m and claim 17 would fail)."""
    data = _study()
    twins = [dict(r, run_id=100 + r["run_id"], repetition=2, planned_length_m=4.2,
                  length_m=r["length_ratio"] * 4.2) for r in data.rows if r["planner"] == "prm" and r["plan"] == "B"]
    for r in twins:
        if r["mode"] == "twb":
            r["status"] = "failed"
    data.rows += twins
    by = {f.key: f for f in paper_findings(data)}
    assert by["field_paths_longer"].held is True
    assert by["field_paths_longer"].numbers["prm_twb_length_m"] == pytest.approx(2.1 * 1.01)
    assert by["field_paths_longer"].numbers["prm_sim_length_m"] == pytest.approx(2.1 * 0.99)
    assert all(f.held for f in by.values()), [(f.key, f.detail) for f in by.values() if not f.held]


def test_findings_files(tmp_path):
    data = _study(_set("prm", "twb", length_ratio=1.17))
    found = write_findings(data, tmp_path)
    doc = json.loads((tmp_path / "findings.json").read_text())
    n = len(FINDINGS)
    assert doc["held"] == n - 1 and doc["applicable"] == n
    i = list(FINDINGS).index("length_similar")
    assert doc["findings"][i]["key"] == "length_similar" and doc["findings"][i]["held"] is False
    assert doc["findings"][i]["numbers"]["prm_twb_length_ratio"] == 1.17
    md = (tmp_path / "findings.md").read_text()
    assert md == findings_markdown(found)
    assert f"{n - 1} of {n} applicable findings held" in md and md.count("| NOT held |") == 1
    assert "prm S 0.990 T 1.170" in md


# ---------------------------------------------------------------- the field robot's localisation


def _exact_profile(**field) -> dict:
    """The BeBot whose tracks do exactly what its odometry model says (unit gains, no slip noise, no skid)
    and whose tracker is exact: only the latency, the lag and the acceleration limit are left."""
    prof = load_profile("bebot")
    prof["field"].update(wheel_gain_mean=1.0, wheel_bias_sigma=0.0, wheel_noise_rel=0.0, wheel_noise_abs_m_s=0.0,
                         tracker_noise_xy_m=0.0, tracker_noise_theta_rad=0.0, tracker_bias_xy_m=0.0,
                         track_width_factor=1.0, **field)
    return prof


def _commands(steps: int) -> np.ndarray:
    """Speeds and turn rates that keep changing (m/s, rad/s)."""
    t = np.arange(steps) * P.dt
    return np.column_stack([0.12 + 0.08 * np.sin(1.3 * t), 2.0 * np.sin(0.9 * t) * np.cos(2.1 * t)])


def _track_belief(prof: dict, steps: int = 400) -> tuple[np.ndarray, np.ndarray, np.ndarray, FieldBackend]:
    """Drive one field robot through :func:`_commands`; per step the true pose at sensing, the belief,
    and the pose the controller steers by."""
    params = robot_params(prof)
    b = make_backend("field", 1, params)
    b.place(0, (0.5, 0.5, 0.3))
    b.begin_path(np.array([True]), np.array([path_key(3)], dtype=np.uint64), np.array([True]))
    truth, belief, ctl = [], [], []
    for k, cmd in enumerate(_commands(steps)):
        steer, _, _ = b.sense(np.array([k]), np.array([True]))
        truth.append(b.pose[0].copy())
        belief.append(b.belief[0].copy())
        ctl.append(steer[0].copy())
        b.actuate(cmd[None, :])
    return np.array(truth), np.array(belief), np.array(ctl), b


def test_latency_compensation_predicts_the_pose_exactly_when_the_odometry_model_is_right():
    truth, belief, _, b = _track_belief(_exact_profile(tracker_dropout_prob=0.0))
    assert b.fg.delay == b.fg.predict == 5  # 0.1 s at 50 Hz
    np.testing.assert_allclose(belief, truth, rtol=0, atol=1e-12)


def test_dead_reckoning_bridges_dropped_frames():
    truth, belief, _, _ = _track_belief(_exact_profile(tracker_dropout_prob=0.6))
    np.testing.assert_allclose(belief, truth, rtol=0, atol=1e-12)


def test_without_compensation_the_robot_acts_on_the_old_pose():
    truth, belief, _, _ = _track_belief(_exact_profile(latency_compensation_s=0.0, control_lead_s=0.0))
    lag = np.hypot(*(belief[:, :2] - truth[:, :2]).T)
    assert lag.max() > 0.015  # about speed x 0.1 s, plus the hold between frames


def test_the_controller_steers_by_the_pose_predicted_its_lead_ahead():
    """The lead is the motor time constant the controller was tuned for (0.12 s); the shipped motors lag more
    (0.25 s: the field robot overshoots corners, docs/fidelity.md)."""
    _, belief, ctl, b = _track_belief(_exact_profile(), steps=60)
    assert b.fg.lead == P.field.control_lead_s == 0.12 < P.field.motor_time_constant_s
    # the last step's odometry: the modelled tracks after the command of step 58
    v, w = tracks_to_body(b.odo[0, 0], b.odo[0, 1], P.wheel_base_m)
    steer = b.sense(np.array([60]), np.array([True]))[0][0]
    np.testing.assert_allclose(steer, unicycle_step(*b.belief[0], v, w, b.fg.lead), rtol=0, atol=1e-12)
    ahead = np.hypot(*(ctl[10:, :2] - belief[10:, :2]).T)
    assert 0.005 < np.median(ahead) < 0.03  # 0.12 s at 0.04-0.2 m/s


def test_odometry_is_the_track_model_without_gain_error_or_noise():
    prof = _exact_profile()
    _, _, _, b = _track_belief(prof, steps=50)
    np.testing.assert_allclose(b.odo, b.tracks, rtol=0, atol=1e-12)  # the tracks are exact here
    _, _, _, real = _track_belief(load_profile("bebot"), steps=50)
    assert np.abs(real.odo - real.tracks).max() > 0.005  # the per-run gains and the slip are not in the model


def test_with_every_error_the_belief_stays_within_millimetres():
    truth, belief, _, _ = _track_belief(load_profile("bebot"), steps=1000)
    err = np.hypot(*(belief[:, :2] - truth[:, :2]).T)
    assert np.median(err) < 0.003 and err.max() < 0.01


# ---------------------------------------------------------------- the tracker's error model


def test_tracker_bias_is_a_smooth_field_of_about_a_millimetre():
    b = FieldBackend(1, P)
    b.place(0, (0.9, 0.9, 0.0))
    pts = np.array([[0.9, 0.9], [0.902, 0.9], [0.9, 1.9], [0.3, 0.4]])
    values = []
    for key in range(400):
        b.begin_path(np.array([True]), np.array([path_key(key)], dtype=np.uint64), np.array([True]))
        values.append([tracker_bias(0, x, y, b.bias, b.fg) for x, y in pts])
    v = np.array(values)  # (keys, points, 2)
    sigma = P.field.tracker_bias_xy_m
    assert v[:, 0].std(axis=0) == pytest.approx([sigma, sigma], rel=0.15)
    assert abs(v[:, 0].mean()) < 0.2 * sigma
    for axis in (0, 1):
        assert np.corrcoef(v[:, 0, axis], v[:, 1, axis])[0, 1] > 0.99  # 2 mm apart: the same error
        assert abs(np.corrcoef(v[:, 0, axis], v[:, 2, axis])[0, 1]) < 0.2  # 1 m apart: independent
    assert abs(np.corrcoef(v[:, 0, 0], v[:, 0, 1])[0, 1]) < 0.2  # x and y errors independent


def test_a_robot_at_rest_is_measured_with_a_fixed_error_and_a_small_jitter():
    b = FieldBackend(1, P)
    b.place(0, (0.6, 1.1, 0.4))
    b.begin_path(np.array([True]), np.array([path_key(8)], dtype=np.uint64), np.array([True]))
    meas = []
    for k in range(1, 3001):
        seen, m = b.sense(np.array([k]), np.array([True]))[1:]
        if seen[0]:
            meas.append(m[0].copy())
        b.actuate(np.zeros((1, 2)))
    m = np.array(meas)
    assert len(m) == pytest.approx(3000 * 30 / 50 * (1 - P.field.tracker_dropout_prob), rel=0.05)
    offset = m[:, :2].mean(axis=0) - b.pose[0, :2]
    np.testing.assert_allclose(offset, tracker_bias(0, 0.6, 1.1, b.bias, b.fg), atol=3e-5)
    jitter = np.diff(m[:, :2], axis=0).std(axis=0) / math.sqrt(2)
    assert jitter == pytest.approx([P.field.tracker_noise_xy_m] * 2, rel=0.1)
    # a logged polyline of a robot at rest grows by about 1.8 sigma per frame, not 1.8 mm
    assert path_length(m[:, :2]) / (len(m) - 1) < 2.5 * P.field.tracker_noise_xy_m


# ---------------------------------------------------------------- corners


def _core(backend: str) -> SimCore:
    return layout_core(P, backend)


def _drive(backend: str, path: np.ndarray, seed: int) -> np.ndarray:
    """The logged poses (t, x, y, theta) from EV,START to the end of ``path`` (driven from its start)."""
    core = _core(backend)
    core.place(0, tuple(path[0]))
    core.set_path(0, path, path_key(seed))
    events = []
    while core.state[0] == State.MOVING:
        events += core.advance(10_000)
    assert events[-1].kind == "DONE", events[-1]
    return core.poses.drain()[0]


def _zigzag(corners: int = 6, leg: float = 0.2, turn_deg: float = 60.0) -> np.ndarray:
    """A PRM-like path: legs of ``leg`` m turning by ``turn_deg`` alternately, points every 0.1 m."""
    half = math.radians(turn_deg) / 2
    pts, sign = [(0.2, 0.9)], 1
    for _ in range(corners + 1):
        for _ in range(round(leg / 0.1)):
            pts.append((pts[-1][0] + 0.1 * math.cos(sign * half), pts[-1][1] + 0.1 * math.sin(sign * half)))
        sign = -sign
    p = np.array(pts)
    heading = np.r_[np.arctan2(np.diff(p[:, 1]), np.diff(p[:, 0])), 0.0]
    return np.column_stack([p, heading])


def test_the_field_robot_cannot_follow_sharp_corners_and_overshoots_them():
    """On 60° corners both robots drive smoother than the path (κ' 0.49); the field robot, whose motors lag
    0.25 s behind a lead tuned for 0.12 s, whose tracks accelerate at 0.3 m/s² and skid (it turns 1 / 1.15 as fast
    as its tracks say), overshoots each corner: seeds 0-3 drive a path 4-6 % longer than the ideal robot's, κ'
    within 4-8 % of it (without the skid: 1.5-4 % longer, as smooth; before issue 33 it cut them: 5 % smoother,
    as long)."""
    path = _zigzag()
    ideal = _drive("ideal", path, 0)[:, 1:3]
    assert smoothness(ideal) < 0.7 * smoothness(path[:, :2])  # the follower's switch radius cuts corners
    for seed in range(4):
        field = _drive("field", path, seed)[:, 1:3]
        assert smoothness(field) < 0.8 * smoothness(path[:, :2]), seed
        assert abs(smoothness(field) / smoothness(ideal) - 1) < 0.1, seed
        assert 1.03 < path_length(field) / path_length(ideal) < 1.08, seed


def test_the_ideal_robot_is_unchanged():
    """What the ideal robot drove on the corners path before the field robot's localisation changed
    (measured on e2c6fc3; the ideal backend ignores the seed)."""
    poses = _drive("ideal", densify(CORNERS), 5)
    assert path_length(poses[:, 1:3]) == pytest.approx(3.7834871228910356, abs=1e-12)
    assert poses[-1, 0] - poses[0, 0] == pytest.approx(21.48, abs=1e-9)
    np.testing.assert_allclose(poses[-1, 1:], [1.4862867051862572, 1.4945410611811738, 1.5237346088975923],
                               rtol=0, atol=1e-12)
