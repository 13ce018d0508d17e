"""Studies of generated world sets (issue 36): a study file takes a world set's split, and the report relates each
world's success to its difficulty (Spearman over the worlds)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import spearmanr

from client_sdk.study import (DIFFICULTY_METRICS, StudyData, StudySpec, StudySpecError, difficulty_correlations,
                              load_spec, load_study, write_report)
from sdk_helpers import study_process
from servers import STANDARD


@pytest.fixture(scope="module")
def world_dir(tmp_path_factory):
    """Six cave worlds (seed 5), half of them held out as "test"."""
    d = tmp_path_factory.mktemp("worlds")
    from twb.main import main

    assert main(["worlds", "generate", "--count", "6", "--seed", "5", "--out", str(d / "w"),
                 "--test-fraction", "0.5"]) == 0
    return d


def index(world_dir) -> list[dict]:
    return json.loads((world_dir / "w" / "index.json").read_text())["worlds"]


def test_a_study_file_takes_a_world_sets_split(world_dir):
    worlds = index(world_dir)
    f = world_dir / "s.json"
    for split in ("test", "train", "all"):
        others = ["room"] if split == "all" else []  # environments of its own beside the worlds
        f.write_text(json.dumps({"worlds": {"index": "w/index.json", "split": split}, "planners": ["fmm"],
                                 **({"environments": others} if others else {})}))
        spec = load_spec(f)
        want = [w["name"] for w in worlds if split == "all" or w["split"] == split]
        assert spec.environment_names() == others + want
        assert list(spec.worlds["worlds"]) == want and spec.worlds["split"] == split
        assert all(spec.worlds["worlds"][w["name"]]["difficulty"] == w["difficulty"] for w in worlds if w["name"] in want)
        # the spec as study.json keeps it reads back the same
        assert StudySpec.from_json(spec.to_json()) == spec
    assert len([w for w in worlds if w["split"] == "test"]) == 3
    f.write_text(json.dumps({"worlds": "w/index.json", "planners": ["fmm"]}))  # a path alone: every world
    assert len(load_spec(f).environments) == 6


@pytest.mark.parametrize("worlds, message", [
    ({"index": "w/index.json", "split": "dev"}, "split must be one of train, test, all, got 'dev'"),
    ("nowhere/index.json", "cannot read .*nowhere/index.json \\(paths are relative to the study file"),
    ({"index": "w/index.json", "seed": 3}, "must be a world set's index.json path"),
    ("w/cave-5-000.json", "is not a world set's index.json"),
])
def test_bad_world_sets_are_refused_clearly(world_dir, worlds, message):
    f = world_dir / "bad.json"
    f.write_text(json.dumps({"worlds": worlds, "planners": ["fmm"]}))
    with pytest.raises(StudySpecError, match=message):
        load_spec(f)


def test_a_world_set_in_memory_is_refused_with_the_way_out():
    with pytest.raises(StudySpecError, match="only a study file can"):
        StudySpec.from_json({"worlds": "w/index.json", "planners": ["fmm"]})


def synthetic(success: dict[str, list[str]], tortuosity: dict[str, float]) -> StudyData:
    """A study of fmm on the field over worlds ``w0``... whose runs ended as ``success[world]`` says (statuses or
    outcomes: ``success``, ``collision``, ``error``)."""
    worlds = {w: {"split": "test", "difficulty": {**{m: 1.0 + i for i, m in enumerate(DIFFICULTY_METRICS)},
                                                   "tortuosity": tortuosity[w]}} for w in success}
    spec = StudySpec.from_json({"environments": list(success), "planners": ["fmm"], "modes": ["twb"],
                                "worlds": {"index": "w/index.json", "split": "test", "worlds": worlds}})
    rows, run_id = [], 0
    for k, (w, ends) in enumerate(success.items(), 1):
        for rep, end in enumerate(ends, 1):
            run_id += 1
            status = {"success": "completed", "collision": "failed", "error": "error"}[end]
            rows.append({"experiment_id": k, "run_id": run_id, "environment": w, "plan": "A", "planner": "fmm",
                         "configuration": "fmm", "controller": "schema", "mode": "twb", "repetition": rep,
                         "status": status, "outcome": end, "failure": "collision" if end == "collision" else None})
    experiments = [{"experiment_id": k, "environment": w, "plan": "A", "planner": "fmm", "configuration": "fmm",
                    "controller": "schema", "status": "completed", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 0.0],
                    "planned_path": None, "runs": []} for k, w in enumerate(success, 1)]
    envs = {w: {"name": w, "size": [1.8, 1.8], "blocks": []} for w in success}
    return StudyData(spec, envs, experiments, rows, [])


def test_success_against_difficulty_is_spearman_over_the_worlds(tmp_path):
    """Each world's success rate over its counted runs (a testbed error is not counted) against its metric;
    success falling as tortuosity rises ranks perfectly (rho -1); the figure and the report's table."""
    ends = {"w0": ["success"] * 4, "w1": ["success"] * 3 + ["collision"], "w2": ["success", "success", "collision",
            "error"], "w3": ["collision"] * 3 + ["success"], "w4": ["collision", "collision", "error", "error"]}
    tort = {"w0": 1.0, "w1": 1.2, "w2": 1.5, "w3": 1.9, "w4": 2.4}
    data = synthetic(ends, tort)
    cors = {c.metric: c for c in difficulty_correlations(data)}
    t = cors["tortuosity"]
    # success rates 1, 0.75, 0.667 (the error not counted: 2 of 3), 0.25, 0: strictly falling
    assert t.rho == pytest.approx(-1.0) and t.worlds == 5 and t.runs == 17
    assert t.p == pytest.approx(spearmanr([1.0, 1.2, 1.5, 1.9, 2.4], [1, 0.75, 2 / 3, 0.25, 0]).pvalue)
    assert cors["visibility_m"].rho is None and "equal in every world" in cors["visibility_m"].note
    paths = write_report(data, tmp_path)
    assert tmp_path / "fig9_difficulty.png" in paths
    summary = (tmp_path / "summary.md").read_text()
    assert "Success against difficulty" in summary and "| fmm | twb | 5 / 17 | 53% | " in summary and "-1.00 (p" in summary
    flat = synthetic({w: ["success"] * 2 for w in ends}, tort)
    assert all(c.rho is None and "success 100% in every world" in c.note for c in difficulty_correlations(flat))
    few = synthetic({"w0": ["success"], "w1": ["collision"]}, tort)
    assert all("fewer than 3 worlds counted" in c.note for c in difficulty_correlations(few))


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


def test_twb_study_of_a_world_sets_test_split(testbed, world_dir):
    """End to end: `twb worlds generate`, a study file naming its test split, `twb study`: the held-out worlds
    only, and the report relates success to difficulty."""
    spec = {"name": "caves", "worlds": {"index": "w/index.json", "split": "test"}, "planners": ["fmm", "prm"],
            "modes": ["sim"], "repetitions": 2, "seed": 1}
    r, out = study_process(testbed, spec, world_dir)
    assert r.returncode == 0, r.stderr
    data = load_study(out)
    test = [w["name"] for w in index(world_dir) if w["split"] == "test"]
    assert sorted({row["environment"] for row in data.rows}) == sorted(test)
    assert len(data.rows) == 3 * 2 * 2 and data.spec.worlds["split"] == "test"
    assert (out / "fig9_difficulty.png").exists()
    summary = (out / "summary.md").read_text()
    assert "Success against difficulty" in summary and f"split test, {len(test)} worlds" in summary
    got = {(c.configuration, c.metric): c for c in difficulty_correlations(data)}
    assert set(got) == {(p, m) for p in ("fmm", "prm") for m in DIFFICULTY_METRICS}
    assert all(c.worlds == 3 and c.runs == 6 for c in got.values())
    assert np.isfinite([c.rho for c in got.values() if c.rho is not None]).all()
