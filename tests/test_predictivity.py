"""Sim-to-field predictivity (client_sdk/study/_predictivity.py) on studies with a known answer."""

from __future__ import annotations

import itertools
import json

import pytest
from scipy.stats import spearmanr

from client_sdk.study import (
    StudyData,
    StudySpec,
    predictivity,
    predictivity_markdown,
    write_predictivity,
)

PLANNERS = ("fmm", "fm2", "prm")
CONTROLLERS = ("schema", "pure_pursuit", "regulated_pure_pursuit", "kanayama")
PROBLEMS = (("room", "A"), ("room", "B"), ("blocks", "A"))


def _study(field_of, reps: int = 2) -> StudyData:
    """12 configurations (planner/controller) on 3 problems, ``reps`` runs per mode; each run's simulated
    ``length_m`` is a fixed value per configuration and problem, its field value ``field_of(sim, conf, problem)``;
    ``execution_time_s`` on the field is the simulated one reversed (a field that orders everything the other
    way round)."""
    rows, rid = [], 0
    confs = [f"{p}/{c}" for p, c in itertools.product(PLANNERS, CONTROLLERS)]
    for q, (env, plan) in enumerate(PROBLEMS):
        for j, conf in enumerate(confs):
            sim = 1.0 + 0.1 * q + 0.005 * j
            for rep in range(reps):
                for mode in ("sim", "twb"):
                    rid += 1
                    rows.append({"run_id": rid, "experiment_id": q * 100 + j, "environment": env, "plan": plan,
                                 "planner": conf.split("/")[0], "controller": conf.split("/")[1],
                                 "configuration": conf, "mode": mode, "repetition": rep + 1, "status": "completed",
                                 "length_m": sim if mode == "sim" else field_of(sim, j, q),
                                 "execution_time_s": sim if mode == "sim" else 10.0 - sim,
                                 "smoothness_rad": 0.2})
    spec = StudySpec.from_json({"name": "grid", "environments": ["room", "blocks"], "planners": list(PLANNERS),
                                "controllers": list(CONTROLLERS)})
    return StudyData(spec, {}, [], rows, [])


def _by(found):
    return {p.metric: p for p in found}


def test_a_field_that_keeps_every_order_is_predicted_perfectly():
    by = _by(predictivity(_study(lambda sim, j, q: 2.0 * sim + 0.3), ["length_m", "execution_time_s"]))
    length = by["length_m"]
    assert length.spearman == pytest.approx(1.0) and length.spearman_within == pytest.approx(1.0)
    assert length.flipped == 0.0
    assert length.configurations == 12 and length.problems == 3 and length.cells == 36
    assert length.pairs == 3 * 66  # 12 configurations: 66 pairs per problem
    time = by["execution_time_s"]  # the field reverses every order
    assert time.spearman == pytest.approx(-1.0) and time.flipped == 1.0


def test_flips_and_rank_correlation_against_a_brute_force_count():
    """Configurations 0 and 1 swap places on the field on every problem, and configuration 11 drops to the
    bottom on problem 0: the flips are counted pair by pair, ρ is SciPy's."""
    def field(sim, j, q):
        if j in (0, 1):
            return sim + (0.005 if j == 0 else -0.005)
        if j == 11 and q == 0:
            return 0.5
        return sim

    data = _study(field)
    p = _by(predictivity(data, ["length_m"]))["length_m"]
    confs = range(12)
    sims = {(q, j): 1.0 + 0.1 * q + 0.005 * j for q in range(3) for j in confs}
    fields = {k: field(v, k[1], k[0]) for k, v in sims.items()}
    flips = pairs = 0
    for q in range(3):
        for a, b in itertools.combinations(confs, 2):
            ds, df = sims[q, a] - sims[q, b], fields[q, a] - fields[q, b]
            if ds and df:
                pairs += 1
                flips += (ds > 0) != (df > 0)
    assert p.pairs == pairs and p.flipped == pytest.approx(flips / pairs)
    assert flips == 3 + 11  # the swapped pair on each problem; configuration 11 below all others on problem 0
    keys = sorted(sims)
    assert p.spearman == pytest.approx(spearmanr([sims[k] for k in keys], [fields[k] for k in keys]).statistic)


def test_a_metric_without_spread_or_a_single_configuration_has_no_answer():
    by = _by(predictivity(_study(lambda sim, j, q: sim), ["smoothness_rad"]))
    assert by["smoothness_rad"].spearman is None and by["smoothness_rad"].pairs == 0
    one = _study(lambda sim, j, q: sim)
    one.rows = [r for r in one.rows if r["configuration"] == "fmm/schema"]
    p = _by(predictivity(one, ["length_m"]))["length_m"]
    assert p.pairs == 0 and p.flipped is None and p.spearman_within is None


def test_predictivity_files(tmp_path):
    data = _study(lambda sim, j, q: 2.0 * sim)
    found = write_predictivity(data, tmp_path)
    assert found is not None
    doc = json.loads((tmp_path / "predictivity.json").read_text())
    length = next(m for m in doc["metrics"] if m["metric"] == "length_m")
    assert length["spearman"] == pytest.approx(1.0) and length["flipped"] == 0.0
    md = (tmp_path / "predictivity.md").read_text()
    assert md == predictivity_markdown(found) and "12 configurations on 3 problems" in md
    assert "| path length (m) | 1.00 | 1.00 | 0.00 | 198 |" in md
    assert (tmp_path / "predictivity.png").stat().st_size > 10_000
    sim_only = _study(lambda sim, j, q: sim)
    sim_only.rows = [r for r in sim_only.rows if r["mode"] == "sim"]
    assert write_predictivity(sim_only, tmp_path / "none") is None and not (tmp_path / "none").exists()
