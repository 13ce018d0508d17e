"""Noise studies: profile overrides checked at the study file and by the server, applied to the field robot,
the same numbers as the robot itself when they change nothing, and a study grouped by variant."""

from __future__ import annotations

import csv
import json

import pytest

from client_sdk.study import StudySpecError, load_spec, noise_spec
from contract.overrides import OverrideError, apply_overrides, check_overrides
from contract.robot_profile import load_profile
from servers import STANDARD, wait_for
from sdk_helpers import invoke

PROBLEM = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fmm",
           "modes": ["twb"], "repetitions": 2, "seed": 3}


@pytest.mark.parametrize("overrides, message", [
    ({"tracker_noise_xy_m": -0.001}, "profile_overrides.tracker_noise_xy_m must be a number in [0, 0.05] (m), got -0.001"),
    ({"tracker_latency_s": 1.5}, "profile_overrides.tracker_latency_s must be a number in [0, 1] (s), got 1.5"),
    ({"tracker_nosie_xy_m": 0.001}, "unknown field parameter 'tracker_nosie_xy_m' (did you mean tracker_noise_xy_m?)"),
    ({"wheel_gain_mean": True}, "profile_overrides.wheel_gain_mean must be a number in [0.1, 2]"),
    ({"motor_time_constant_s": float("nan")}, "profile_overrides.motor_time_constant_s must be a number"),
    ([0.1], "profile_overrides must be an object of field parameters"),
])
def test_overrides_outside_physics_are_refused_naming_the_field(overrides, message):
    with pytest.raises(OverrideError) as exc:
        check_overrides(overrides)
    assert message in str(exc.value)


def test_apply_overrides_changes_only_the_field_section():
    shipped = load_profile("bebot")
    changed = apply_overrides(shipped, {"tracker_noise_xy_m": 0.003})
    assert changed["field"]["tracker_noise_xy_m"] == 0.003 and shipped["field"]["tracker_noise_xy_m"] == 0.0003
    assert {k: v for k, v in changed["field"].items() if k != "tracker_noise_xy_m"} == \
        {k: v for k, v in shipped["field"].items() if k != "tracker_noise_xy_m"}


@pytest.mark.parametrize("profiles, message", [
    ([{"label": "x", "tracker_latency_s": 2}], "my.json: profiles[0].tracker_latency_s must be a number in [0, 1] (s)"),
    ([{}, {"tracker_noise_xy": 0.1}], "my.json: profiles[1]: unknown field parameter 'tracker_noise_xy' "
                                      "(did you mean tracker_noise_xy_m?)"),
    ([{"wheel_noise_rel": 0.1}, {"label": "wheel_noise_rel=0.1"}], "my.json: profiles[1] has the label of profiles[0]"),
    ([], "my.json: `profiles` must be a non-empty list"),
    ([{"label": ""}], "my.json: profiles[0].label must be a non-empty string"),
])
def test_bad_profiles_in_a_study_file(tmp_path, profiles, message):
    f = tmp_path / "my.json"
    f.write_text(json.dumps({"environments": ["room"], "planners": ["fmm"], "profiles": profiles}))
    with pytest.raises(StudySpecError) as exc:
        load_spec(f)
    assert message.replace("my.json", str(f)) in str(exc.value)


def test_profiles_need_the_field_mode():
    with pytest.raises(StudySpecError, match="`profiles` vary the field robot: `modes` must include \"twb\""):
        load_spec_json({"environments": ["room"], "planners": ["fmm"], "modes": ["sim"], "profiles": [{}]})


def load_spec_json(data):  # type: ignore[no-untyped-def]
    from client_sdk.study import StudySpec

    return StudySpec.from_json(data, "s.json")


def test_the_noise_study_labels_default_to_the_overrides():
    spec = load_spec_json({"environments": ["room"], "planners": ["fmm"], "profiles": [
        {}, {"tracker_noise_xy_m": 0.003, "motor_time_constant_s": 0.2}]})
    assert [p.label for p in spec.profiles] == ["shipped", "motor_time_constant_s=0.2,tracker_noise_xy_m=0.003"]
    noise = noise_spec()
    assert noise.modes == ["twb"] and len(noise.profiles) == 4 and noise.runs_per_experiment == 5


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)  # the shared one: its second simulated robot changes nothing here


@pytest.mark.parametrize("overrides, modes, message", [
    ({"tracker_latency_s": 1.5}, ["twb"], "profile_overrides.tracker_latency_s must be a number in [0, 1] (s), got 1.5"),
    ({"wheel_noise": 0.1}, ["twb"], "did you mean wheel_noise_rel?"),
    ({"wheel_noise_rel": 0.1}, ["sim"], "profile_overrides change the emulated field robot: they need mode \"twb\""),
])
def test_the_server_refuses_overrides_outside_physics(testbed, overrides, modes, message):
    """The detail names the field first, without pydantic's "Value error, " in front or the field twice."""
    with testbed.client() as c:
        r = c.post("/api/v1/experiments", json={**PROBLEM, "modes": modes, "profile_overrides": overrides})
    assert r.status_code == 422 and message in r.json()["detail"], r.text
    assert r.json()["detail"].startswith(("profile_overrides", "unknown")) and "Value error" not in r.json()["detail"]


def _runs(c, body):  # type: ignore[no-untyped-def]
    exp = wait_for(c, c.post("/api/v1/experiments", json=body).json()["id"], timeout=120)
    assert exp["status"] == "completed", exp
    return exp, {r["repetition"]: r for r in exp["runs"]}


def test_overrides_reach_the_field_robot_and_change_nothing_else(testbed):
    """A field run with overrides is the emulated robot with them, computed as a task; with the shipped values
    it gives the robot's own numbers (same seed, same numbers), with more tracker noise a longer logged path."""
    shipped = load_profile("bebot")["field"]
    with testbed.client() as c:
        plain, by_robot = _runs(c, PROBLEM)
        same, as_task = _runs(c, {**PROBLEM, "profile_overrides": {"tracker_noise_xy_m": shipped["tracker_noise_xy_m"]}})
        noisy, noisy_runs = _runs(c, {**PROBLEM, "profile_overrides": {"tracker_noise_xy_m": 0.003}})
        poses = [c.get(f"/api/v1/runs/{runs[1]['id']}/poses").json() for runs in (by_robot, as_task)]
        lines = c.get(f"/api/v1/runs/{as_task[1]['id']}/messages").json()
    assert plain["profile_overrides"] is None
    assert same["profile_overrides"] == {"tracker_noise_xy_m": shipped["tracker_noise_xy_m"]}
    assert noisy["profile_overrides"] == {"tracker_noise_xy_m": 0.003}
    for rep in (1, 2):
        a, b = by_robot[rep], as_task[rep]
        assert a["seed"] == b["seed"]
        assert a["subfield"] is not None and b["subfield"] is not None and b["robot_id"].startswith("field-")
        for k in ("length_m", "execution_time_s", "deviation_mean_m", "hausdorff_m", "smoothness_rad"):
            assert a["metrics"][k] == pytest.approx(b["metrics"][k], rel=1e-6, abs=1e-6), (rep, k)
        assert noisy_runs[rep]["metrics"]["length_ratio"] > a["metrics"]["length_ratio"] + 0.1
    assert len(poses[0]) == len(poses[1])
    text = json.dumps(lines)
    assert "profile overrides" in text and "T,T,P" in text


def test_a_study_groups_by_variant(capsys, monkeypatch, testbed, tmp_path):
    spec = {"name": "variants", "environments": ["room"], "plans": ["A"], "planners": ["fmm"], "repetitions": 2,
            "modes": ["twb"], "seed": 1,
            "profiles": [{"label": "noiseless", "tracker_noise_xy_m": 0, "tracker_bias_xy_m": 0},
                         {"tracker_noise_xy_m": 0.003}]}
    f = tmp_path / "variants.json"
    f.write_text(json.dumps(spec))
    out = tmp_path / "out"
    r = invoke(capsys, monkeypatch, "study", f, "--out", out, "--url", testbed.url, "--token", testbed.token,
               "--no-progress")
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader((out / "runs.csv").open()))
    assert [(row["configuration"], row["profile"]) for row in rows] == \
        [("fmm · noiseless", "noiseless")] * 2 + [("fmm · tracker_noise_xy_m=0.003", "tracker_noise_xy_m=0.003")] * 2
    comps = [c for c in csv.DictReader((out / "comparisons.csv").open()) if c["metric"] == "length_m"]
    assert comps and comps[0]["a"] == "fmm · noiseless" and comps[0]["b"] == "fmm · tracker_noise_xy_m=0.003"
    study = json.loads((out / "study.json").read_text())
    assert [e["profile_overrides"] for e in study["experiments"]] == \
        [{"tracker_noise_xy_m": 0.0, "tracker_bias_xy_m": 0.0}, {"tracker_noise_xy_m": 0.003}]
    assert "fmm · noiseless" in (out / "summary.md").read_text()
